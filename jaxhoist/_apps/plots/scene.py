"""The scene of the 3-D animation (`apps/animate.py`): the saved result rebuilt as box vertices, the rope's
attachment point B and the contact state per saved time (`Scene`, `scene_from_result`, `load_scene`).
Split off `apps/animate.py`, which re-exports these names; drawing and saving stay there."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..._errors import ScenarioError
from ..._io.results import load_result

CORNERS = ("D", "E", "F", "H")
CORNER_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red")
ARROW_CAP = 1.5  # longest drawn arrow, in units of the weight's arrow length
# faces of the box as indices into the 8 vertices: bottom D E F H (0-3), then the top corners above them (4-7)
FACES = ((0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))


def _rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (body -> world) of quaternions (w, x, y, z), shape (n, 4) -> (n, 3, 3)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


@dataclass(frozen=True)
class Scene:
    """What the frames draw, at every saved time (numpy, world axes, SI units).

    - `ts`: saved times [s], shape (n_t,).
    - `corners`: bottom corners D, E, F, H [m], (n_t, 4, 3); `top`: the corners above them [m], (n_t, 4, 3).
    - `rope_point`: the rope's attachment B [m], (n_t, 3); `tip`: the boom tip A [m], (n_t, 3).
    - `normal_forces`: N_i [N], (n_t, 4); `rope_tension`: S [N], (n_t,).
    - `weight`: m g [N]; `arrow_length`: the arrow length [m] of a force equal to the weight.
    - `state`: the contact state or rigid-model phase at each saved time (text), length n_t.
    - `model`: "elastic" or "rigid"; `name`: the scenario name.
    """

    ts: np.ndarray
    corners: np.ndarray
    top: np.ndarray
    rope_point: np.ndarray
    tip: np.ndarray
    normal_forces: np.ndarray
    rope_tension: np.ndarray
    weight: float
    arrow_length: float
    state: tuple[str, ...]
    model: str
    name: str

    def arrows(self, k: int) -> np.ndarray:
        """Vertical arrow lengths [m] of N_i at saved time `k`: N_i / (m g) * `arrow_length`, shape (4,),
        capped at `ARROW_CAP` times `arrow_length` (a force spike must not shrink every frame)."""
        n = np.maximum(self.normal_forces[k], 0.0) / self.weight
        return np.minimum(n, ARROW_CAP) * self.arrow_length

    def limits(self) -> np.ndarray:
        """Axis limits [[x0, x1], [y0, y1], [z0, z1]] [m] holding every drawn point of every frame, with a
        margin; z starts at the ground or below."""
        n_t = self.ts.shape[0]
        arrow_tails = self.corners - np.stack(
            [np.zeros((n_t, 4)), np.zeros((n_t, 4)), np.stack([self.arrows(k) for k in range(n_t)])], -1
        )
        pts = np.concatenate(
            [
                self.corners.reshape(-1, 3),
                self.top.reshape(-1, 3),
                self.tip,
                self.rope_point,
                arrow_tails.reshape(-1, 3),
            ]
        )
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        lo[2] = min(lo[2], 0.0)
        pad = 0.06 * max(float(np.max(hi - lo)), 1e-3)
        return np.stack([lo - pad, hi + pad], axis=1)


def _leaf(meta: dict, name: str, where: Path):
    leaves = ((meta.get("scenario") or {}).get("leaves")) or {}
    if name not in leaves:
        raise ScenarioError(
            f"{where}: the scenario leaf {name!r} is missing from the sidecar (the animation needs the box "
            f"size, mass, rope attachment and gravity; write results with save_trajectory(..., scenario))"
        )
    return np.asarray(leaves[name], dtype=float)


def contact_state(normal_forces: np.ndarray) -> str:
    """Which corners touch the ground (N_i > 0), e.g. "contact D, E, F, H", or "in the air"."""
    on = [c for c, n in zip(CORNERS, normal_forces, strict=True) if n > 0.0]
    return "contact " + ", ".join(on) if on else "in the air (no contact)"


def scene_from_result(
    arrays: dict[str, np.ndarray],
    meta: dict[str, Any],
    where: Path | str = "<result>",
    *,
    arrow_length: float | None = None,
) -> Scene:
    """Build the `Scene` of a saved result.

    **Arguments**
    - `arrays`: the arrays of `trajectory.npz` (`load_trajectory`); one solve, not a scan.
    - `meta`: the sidecar `trajectory.json` (`load_metadata`), with the scenario leaves `load.size`,
      `load.mass`, `rope.attachment`, `gravity`.
    - `where`: the result's path, for error messages.
    - `arrow_length`: arrow length [m] of a force equal to the weight m g (default: the longest box edge).

    **Returns** the `Scene`.

    **Raises** `ScenarioError` if an array or a scenario leaf is missing or the result is a batch.
    """
    where = Path(where)
    for k in ("ts", "corners", "quaternion", "tip_position", "normal_forces", "rope_tension"):
        if k not in arrays:
            raise ScenarioError(f"{where}: array {k!r} missing; not a jaxhoist trajectory result")
    ts = np.asarray(arrays["ts"], dtype=float)
    if ts.ndim != 1 or ts.size < 1:
        raise ScenarioError(
            f"{where}: one trajectory expected, got saved times of shape {ts.shape} (a scan?)"
        )
    size = _leaf(meta, "load.size", where)
    attach = _leaf(meta, "rope.attachment", where)
    weight = float(_leaf(meta, "load.mass", where)) * float(_leaf(meta, "gravity", where))
    R = _rotation(np.asarray(arrays["quaternion"], dtype=float))
    corners = np.asarray(arrays["corners"], dtype=float)
    top = corners + size[2] * R[:, None, :, 2]
    rope_point = corners[:, 0] + np.einsum("nij,j->ni", R, attach)
    n = np.asarray(arrays["normal_forces"], dtype=float)
    model = str((meta.get("solver") or {}).get("model", "rigid" if "phase_index" in arrays else "elastic"))
    phases = meta.get("phases") or []
    if "phase_index" in arrays and phases:
        idx = np.asarray(arrays["phase_index"]).astype(int)
        names = [p.get("name") or " ".join(p.get("contact", [])) for p in phases]
        state = tuple(f"phase {i + 1}/{len(phases)}: {names[i]}" for i in idx)
        model = "rigid"
    else:
        state = tuple(contact_state(row) for row in n)
    if arrow_length is None:
        arrow_length = float(np.max(size))
    if not (np.isfinite(arrow_length) and arrow_length > 0):
        raise ScenarioError(f"arrow_length must be a positive length [m], got {arrow_length}")
    name = str((meta.get("scenario") or {}).get("name", where.name))
    tip = np.asarray(arrays["tip_position"], dtype=float)
    tension = np.asarray(arrays["rope_tension"], dtype=float)
    return Scene(
        ts, corners, top, rope_point, tip, n, tension, weight, float(arrow_length), state, model, name
    )


def load_scene(result_dir: str | Path, *, arrow_length: float | None = None) -> Scene:
    """The `Scene` of `RESULT_DIR/trajectory.npz` + `trajectory.json` (see `scene_from_result`; `arrow_length`
    [m] as there).

    **Raises** `ScenarioError` if the folder holds no trajectory result.
    """
    d = Path(result_dir)
    npz = d / "trajectory.npz" if d.is_dir() else d
    if not npz.is_file() or not npz.with_suffix(".json").is_file():
        raise ScenarioError(
            f"{result_dir}: no trajectory.npz and trajectory.json here (write them with "
            f"`jaxhoist simulate ... --out {result_dir}`)"
        )
    # a damaged or mismatched pair of files: ResultFileError (a ScenarioError) naming the file
    return scene_from_result(*load_result(npz), npz, arrow_length=arrow_length)
