"""Result files: a `Trajectory` as `<stem>.npz` (plain numpy arrays, one per output, by a clear name) plus a
`<stem>.json` sidecar that says what each array is (unit, shape, meaning) and where it came from (jaxhoist
version, command line, scenario name and every scenario leaf by dotted path, solver options).

    from jaxhoist import save_trajectory, load_trajectory, load_metadata
    npz, meta = save_trajectory("out/run/trajectory", traj, scenario, command=sys.argv)
    arrays = load_trajectory("out/run/trajectory.npz")      # {"ts": ..., "position": ..., ...}
    units = load_metadata("out/run/trajectory.npz")["arrays"]["position"]["unit"]   # "m"

The npz needs nothing but numpy to read (`numpy.load`); `load_trajectory` returns a plain dict of arrays.
The sidecar holds the npz file's SHA-256 checksum (`data_sha256`): the readers here refuse an npz that is
not the one its sidecar describes (replaced, or written by a run that stopped between the two files) or
that is damaged, with a `ResultFileError` naming the file. Arrays keep any leading batch axis (a scan), so
the same functions serve single solves and batches.
`save_arrays` is the generic writer for other result kinds (scans, bifurcation maps).
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import io
import json
import os
import platform
import zipfile
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import ScenarioError

FORMAT = "jaxhoist-trajectory/1"


class ResultFileError(ScenarioError):
    """A result file that cannot be trusted: missing or unreadable, damaged (not a readable npz or JSON), or
    an npz that is not the one its JSON sidecar describes (its checksum differs). The command line prints
    it on one line and exits with code 2."""


# name -> (unit, meaning). The order is the order in the npz file.
TRAJECTORY_ARRAYS: dict[str, tuple[str, str]] = {
    "ts": ("s", "saved times t"),
    "position": ("m", "mass centre C in world axes (x, y, z); shape (n_t, 3)"),
    "velocity": ("m/s", "velocity of the mass centre C in world axes; shape (n_t, 3)"),
    "euler": (
        "rad",
        "Euler angles (phi, psi, theta), R = R_Z(psi) R_Y(theta) R_X(phi); "
        "phi, psi unwrapped along time; shape (n_t, 3)",
    ),
    "angular_velocity": ("rad/s", "angular velocity omega in body axes (xi, eta, zeta); shape (n_t, 3)"),
    "quaternion": ("-", "orientation quaternion (w, x, y, z), body -> world; shape (n_t, 4)"),
    "corners": ("m", "bottom corners D, E, F, H in world axes; shape (n_t, 4, 3)"),
    "normal_forces": ("N", "ground normal force N_i on corners D, E, F, H; shape (n_t, 4)"),
    "friction_forces": ("N", "friction force T_i on corners D, E, F, H in world axes; shape (n_t, 4, 3)"),
    "ground_reaction": ("N", "ground reaction R = sum of N_i; shape (n_t,)"),
    "rope_tension": ("N", "rope tension S; shape (n_t,)"),
    "tip_position": ("m", "boom tip A in world axes; shape (n_t, 3)"),
    "tip_velocity": ("m/s", "velocity of the boom tip A; shape (n_t, 3)"),
    "friction_state": (
        "m",
        "friction-law state per corner (bristle deflection; empty for Coulomb); shape (n_t, 4, n)",
    ),
    "energy_kinetic": ("J", "kinetic energy of load and boom tip"),
    "energy_potential": ("J", "potential energy m g Z_C + m_0 g Z_A"),
    "energy_ground_spring": ("J", "elastic energy of the foundation springs"),
    "energy_rope_spring": ("J", "elastic energy of the rope"),
    "energy_boom_spring": ("J", "elastic energy of the boom springs"),
    "energy_mechanical": ("J", "sum of the five energy terms above"),
    "hoist_work": ("J", "work done by the hoist on the rope, accumulated from t = 0"),
    "damping_loss": ("J", "energy lost in the ground, rope and boom dampers, accumulated"),
    "friction_work": ("J", "work taken out by friction (incl. bristle energy), accumulated"),
    "energy_residual": ("J", "E(t) - E(0) - [W_hoist - D_damping - W_friction](t); zero up to solver error"),
    "status": ("-", "SolveStatus code: 0 ok, 1 max_steps, 2 nonfinite, 3 solver failed, 4 energy_balance"),
    "num_accepted_steps": ("-", "accepted solver steps"),
    "num_rejected_steps": ("-", "rejected solver steps"),
}


def trajectory_arrays(traj) -> dict[str, np.ndarray]:
    """Every output of a `Trajectory` as a numpy array, under the names of `TRAJECTORY_ARRAYS`."""
    e = traj.energy
    # mechanical energy and balance residual in numpy: `Energy.mechanical` and `Trajectory.energy_residual`
    # are annotated for one solve, and a scan's trajectory carries a batch axis first.
    # After a solve that stopped early the saved times it did not reach hold inf (diffrax's fill value): their
    # residual is NaN, without numpy's "invalid value" warning (the status says the solve stopped).
    with np.errstate(invalid="ignore"):
        parts = (e.kinetic, e.potential, e.ground_spring, e.rope_spring, e.boom_spring)
        mech = sum(np.asarray(x) for x in parts)
        supplied = np.asarray(traj.hoist_work) - np.asarray(traj.damping_loss)
        supplied = supplied - np.asarray(traj.friction_work)
        if hasattr(traj, "impact_loss"):  # the rigid model loses energy in impacts too
            supplied = supplied - np.asarray(traj.impact_loss)
        residual = (mech - mech[..., :1]) - (supplied - supplied[..., :1])  # pyright: ignore[reportIndexIssue]  # mech is an array here
    out = {
        "ts": traj.ts,
        "position": traj.position,
        "velocity": traj.velocity,
        "euler": traj.euler,
        "angular_velocity": traj.angular_velocity,
        "quaternion": traj.states.quaternion,
        "corners": traj.corners,
        "normal_forces": traj.normal_forces,
        "friction_forces": traj.friction_forces,
        "ground_reaction": traj.ground_reaction,
        "rope_tension": traj.rope_tension,
        "tip_position": traj.tip_position,
        "tip_velocity": traj.states.tip_velocity,
        "friction_state": traj.states.friction_state,
        "energy_kinetic": e.kinetic,
        "energy_potential": e.potential,
        "energy_ground_spring": e.ground_spring,
        "energy_rope_spring": e.rope_spring,
        "energy_boom_spring": e.boom_spring,
        "energy_mechanical": mech,
        "hoist_work": traj.hoist_work,
        "damping_loss": traj.damping_loss,
        "friction_work": traj.friction_work,
        "energy_residual": residual,
        "status": traj.status,
        "num_accepted_steps": traj.num_accepted_steps,
        "num_rejected_steps": traj.num_rejected_steps,
    }
    assert list(out) == list(TRAJECTORY_ARRAYS)
    out = {k: np.asarray(v) for k, v in out.items()}
    if hasattr(traj, "phase_index"):  # a rigid-model trajectory: impact losses and the phase per saved time
        out["impact_loss"] = np.asarray(traj.impact_loss)
        out["phase_index"] = np.asarray(traj.phase_index)
    return out


# Arrays only a rigid-model (`simulate_rigid`) trajectory has; its phase log goes to the JSON sidecar.
RIGID_ARRAYS: dict[str, tuple[str, str]] = {
    "impact_loss": ("J", "kinetic energy lost in corner impacts (and rope jerks), accumulated"),
    "phase_index": ("-", "index into the sidecar's 'phases' list of the phase each saved time belongs to"),
}


def phase_name(contact: Sequence[str], rest: bool, rope: str = "elastic") -> str:
    """A short name of a rigid-model phase: "rest", "flight", or the contact mode of each touching corner,
    e.g. "D slide, E stick" (corners D, E, F, H; modes "free", "slide", "stick"); the inextensible rope's
    state is appended when it is not "elastic"."""
    if rest:
        name = "rest"
    elif all(m == "free" for m in contact):
        name = "flight"
    else:
        name = ", ".join(f"{c} {m}" for c, m in zip("DEFH", contact, strict=True) if m != "free")
    return name if rope == "elastic" else f"{name} (rope {rope})"


def phase_records(traj) -> list[dict[str, Any]]:
    """The phase log of a rigid-model trajectory as JSON-ready dicts (t_start, t_end [s], contact per corner,
    rest, end, rope, name); empty for a trajectory without one."""
    return [
        {
            "t_start": float(p.t_start),
            "t_end": float(p.t_end),
            "contact": list(p.contact),
            "rest": bool(p.rest),
            "end": p.end,
            "rope": p.rope,
            "name": phase_name(p.contact, p.rest, p.rope),
        }
        for p in getattr(traj, "phases", ())
    ]


def as_arrays(data) -> dict[str, np.ndarray]:
    """A `Trajectory`, or an already loaded dict of arrays, as a dict of numpy arrays."""
    if isinstance(data, Mapping):
        return {k: np.asarray(v) for k, v in data.items()}
    return trajectory_arrays(data)


# ------------------------------------------------------------------------------------------ scenario


def scenario_leaves(scenario) -> dict[str, Any]:
    """Every float leaf of a `Scenario` by dotted path (`"foundation.friction_coefficient": 0.25`), as
    plain Python numbers / nested lists (JSON-ready)."""
    import jax

    out = {}
    for path, leaf in jax.tree_util.tree_flatten_with_path(scenario)[0]:
        name = ".".join(str(getattr(k, "name", getattr(k, "key", getattr(k, "idx", k)))) for k in path)
        out[name] = np.asarray(leaf).tolist()
    return out


def scenario_types(scenario) -> dict[str, str]:
    """The class of every sub-module of a `Scenario` by dotted path, e.g. `"hoist": "ConstantSpeedHoist"`."""
    import equinox as eqx

    out = {}

    def walk(obj, prefix):
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name, None)
            if isinstance(v, eqx.Module):
                path = f"{prefix}{f.name}"
                out[path] = type(v).__name__
                walk(v, path + ".")

    walk(scenario, "")
    return out


def scenario_metadata(scenario) -> dict[str, Any]:
    """Name, default end time, model classes and leaf values of a `Scenario` (JSON-ready)."""
    return {
        "name": scenario.name,
        "t1": scenario.t1,
        "types": scenario_types(scenario),
        "leaves": scenario_leaves(scenario),
    }


# -------------------------------------------------------------------------------------- save / load


def _stem(path: str | Path) -> Path:
    """The stem of a result file: `path` without a `.npz`/`.json` suffix (any other dot stays part of the
    name: `out/paper-4.2` is a stem)."""
    p = Path(path)
    return p.with_suffix("") if p.suffix in (".npz", ".json") else p


def _read_stem(path: str | Path) -> Path:
    """The stem of a result file to read: as `_stem`, and a folder stands for `<folder>/trajectory` (the
    result of `jaxhoist simulate --out <folder>`)."""
    p = _stem(path)
    return p / "trajectory" if p.is_dir() else p


def _file(stem: Path, suffix: str) -> Path:
    """`stem` + `suffix` (`with_suffix` would replace the ".2" of "paper-4.2")."""
    return stem.with_name(stem.name + suffix)


def _versions() -> dict[str, str]:
    from importlib import metadata

    out = {"python": platform.python_version()}
    for pkg in ("jaxhoist", "jax", "diffrax", "equinox", "numpy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "unknown"
    return out


def _jsonable(x):
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray | np.generic):
        return x.tolist()
    if isinstance(x, float | int | str | bool) or x is None:
        return x
    return repr(x)


def save_arrays(
    path: str | Path,
    arrays: Mapping[str, Any],
    units: Mapping[str, tuple[str, str] | str],
    metadata: Mapping[str, Any] | None = None,
    *,
    kind: str = FORMAT,
) -> tuple[Path, Path]:
    """Write `arrays` to `<stem>.npz` and a JSON sidecar `<stem>.json` describing them.

    **Arguments**
    - `path`: the file stem, or a path ending in `.npz`/`.json`; parent folders are created.
    - `arrays`: name -> array-like.
    - `units`: name -> unit string, or (unit, meaning); every array needs an entry.
    - `metadata`: anything JSON-able to store under `"metadata"` (command line, scenario, options, ...).
    - `kind`: a format tag stored as `"format"`.

    **Returns** the paths of the npz and the json file.
    """
    stem = _stem(path)
    stem.parent.mkdir(parents=True, exist_ok=True)
    arrs = {k: np.asarray(v) for k, v in arrays.items()}
    missing = sorted(set(arrs) - set(units))
    if missing:
        raise ValueError(f"no unit given for arrays {missing}")
    described = {}
    for k, a in arrs.items():
        u = units[k]
        unit, meaning = (u, "") if isinstance(u, str) else u
        described[k] = {"unit": unit, "meaning": meaning, "shape": list(a.shape), "dtype": str(a.dtype)}
    npz_path, json_path = _file(stem, ".npz"), _file(stem, ".json")
    # atomically (temporary file, then rename): a run killed while saving leaves the old file or none,
    # never a truncated one
    tmp = npz_path.with_name(npz_path.name + ".tmp.npz")
    np.savez_compressed(tmp, **arrs)  # pyright: ignore[reportArgumentType]  # numpy's stubs read **arrs as the allow_pickle keyword
    checksum = hashlib.sha256(tmp.read_bytes()).hexdigest()
    os.replace(tmp, npz_path)
    sidecar = {
        "format": kind,
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "versions": _versions(),
        "data_file": npz_path.name,
        "data_sha256": checksum,
        "arrays": described,
        **_jsonable(dict(metadata or {})),  # pyright: ignore[reportGeneralTypeIssues]  # _jsonable returns the dict it was given
    }
    tmp = json_path.with_name(json_path.name + ".tmp")
    tmp.write_text(json.dumps(sidecar, indent=2, allow_nan=True) + "\n")
    os.replace(tmp, json_path)
    return npz_path, json_path


def save_trajectory(
    path: str | Path,
    traj,
    scenario=None,
    *,
    command: Sequence[str] | None = None,
    options: Mapping[str, Any] | None = None,
    extra: Mapping[str, Any] | None = None,
) -> tuple[Path, Path]:
    """Save a single (or batched) `Trajectory` as `<stem>.npz` + `<stem>.json`.

    **Arguments**
    - `path`: file stem or `.npz` path, e.g. `"out/paper-4.2/trajectory"`.
    - `traj`: the `Trajectory`.
    - `scenario`: the `Scenario` it was computed from (name, model classes, every leaf by dotted path).
    - `command`: the command line (e.g. `sys.argv`), stored verbatim.
    - `options`: solver settings to record (rtol, atol, max_steps, ...).
    - `extra`: any further JSON-able metadata (e.g. timings).

    **Returns** the paths of the npz and the json file.
    """
    from .._errors import SolveStatus

    arrays = trajectory_arrays(traj)
    status = np.asarray(arrays["status"])
    meta: dict[str, Any] = {
        "command": list(command) if command is not None else None,
        "scenario": scenario_metadata(scenario) if scenario is not None else None,
        "solver": dict(options or {}),
        "status": (
            [SolveStatus(int(s)).name.lower() for s in status.ravel()]
            if status.ndim
            else SolveStatus(int(status)).name.lower()
        ),
    }
    if hasattr(traj, "phases"):
        meta["phases"] = phase_records(traj)
    meta.update(extra or {})
    return save_arrays(path, arrays, {**TRAJECTORY_ARRAYS, **RIGID_ARRAYS}, meta)


def load_arrays(path: str | Path) -> dict[str, np.ndarray]:
    """The arrays of a `.npz` result file (give the `.npz`, the `.json`, the stem, or the folder of a
    `jaxhoist simulate` result, which holds `trajectory.npz`) as a dict.

    **Raises** `ResultFileError` naming the file where it is missing or unreadable, damaged, or not the npz
    that its sidecar's checksum names (a sidecar without a checksum, or none at all, is not compared)."""
    stem = _read_stem(path)
    sidecar = _file(stem, ".json")
    return _load_npz(stem, load_metadata(sidecar) if sidecar.exists() else {})


def load_result(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """`(load_arrays(path), load_metadata(path))`, the sidecar read once: the arrays, checked against the
    sidecar's checksum, and the sidecar. **Raises** `ResultFileError` as those two do."""
    stem = _read_stem(path)
    meta = load_metadata(stem)
    return _load_npz(stem, meta), meta


def _load_npz(stem: Path, meta: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The arrays of `<stem>.npz`, refused where they are not those whose checksum the sidecar `meta` holds
    (a sidecar without one, or none, `{}`, is not compared)."""
    npz, sidecar = _file(stem, ".npz"), _file(stem, ".json")
    try:
        data = npz.read_bytes()
    except OSError as e:
        raise ResultFileError(f"{npz}: cannot be read ({e.strerror or e})") from None
    want = meta.get("data_sha256")
    if want is not None and hashlib.sha256(data).hexdigest() != want:
        raise ResultFileError(
            f"{npz}: is not the file that {sidecar.name} beside it describes (its SHA-256 checksum "
            f"differs: replaced or changed since it was written, or a run stopped between the two)"
        )
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as f:
            return {k: f[k] for k in f.files}
    except (zipfile.BadZipFile, zlib.error, ValueError, EOFError, OSError, KeyError) as e:
        raise ResultFileError(f"{npz}: is damaged or not an npz file ({type(e).__name__}: {e})") from None


load_trajectory = load_arrays


def load_metadata(path: str | Path) -> dict[str, Any]:
    """The JSON sidecar of a result file (give the `.npz`, the `.json`, the stem or a result folder).

    **Raises** `ResultFileError` naming the file where it is missing, unreadable or not JSON."""
    sidecar = _file(_read_stem(path), ".json")
    try:
        meta = json.loads(sidecar.read_text(encoding="utf-8"))
    except OSError as e:
        raise ResultFileError(f"{sidecar}: cannot be read ({e.strerror or e})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ResultFileError(f"{sidecar}: is damaged or not a JSON file ({e})") from None
    if not isinstance(meta, dict):
        raise ResultFileError(
            f"{sidecar}: is not a result's sidecar (JSON {type(meta).__name__}, not an object)"
        )
    return meta


def units(path: str | Path) -> dict[str, str]:
    """Array name -> unit, from a result file's sidecar."""
    return {k: v["unit"] for k, v in load_metadata(path)["arrays"].items()}


# ------------------------------------------------------------------------------------------ summary


def liftoff_time(ts, normal_forces) -> float | None:
    """The first saved time [s] at which every corner's normal force N_i is zero, or None."""
    ts, n = np.asarray(ts), np.asarray(normal_forces)
    off = np.all(n <= 0.0, axis=-1)
    return float(ts[np.argmax(off)]) if off.any() else None


def corner_detach_times(ts, normal_forces) -> list[float | None]:
    """Per corner D, E, F, H: the first saved time [s] with N_i = 0, or None."""
    ts, n = np.asarray(ts), np.asarray(normal_forces)
    off = n <= 0.0
    return [float(ts[np.argmax(off[:, i])]) if off[:, i].any() else None for i in range(n.shape[-1])]


# ----------------------------------------------------------------------------------- CSV and netCDF


def trajectory_signals(data) -> dict[str, np.ndarray]:
    """Every scalar signal of `jaxhoist._io.measurement.SIGNALS` (position_x, euler_phi, corners_D_z,
    normal_forces_E, rope_tension, ...) of one trajectory, by name, in SI units; shape (n_t,) each."""
    from .measurement import SIGNALS

    d = as_arrays(data)
    return {name: d[s.field][(slice(None), *s.index)] for name, s in SIGNALS.items()}


def save_trajectory_csv(path: str | Path, data, *, digits: int = 12) -> Path:
    """Write one trajectory as a measurement CSV that `jaxhoist identify` (`read_measurement`) reads
    unchanged: a header `t [s],position_x [m],...,rope_tension [N]` (every signal of `SIGNALS`, SI units
    as in the units table `TRAJECTORY_ARRAYS`) and one row per saved time.

    **Arguments**
    - `path`: the CSV file; parent folders are created.
    - `data`: a `Trajectory` (or `RigidTrajectory`) or the dict of arrays of `load_trajectory`; one solve,
      not a batch.
    - `digits`: significant digits per value.

    **Returns** the path.

    **Raises** `ValueError` for a batched trajectory (a scan: write one member at a time).
    """
    import csv

    from .measurement import SIGNALS

    d = as_arrays(data)
    if d["ts"].ndim != 1:
        raise ValueError(f"save_trajectory_csv: one trajectory expected, got ts of shape {d['ts'].shape}")
    cols = {"t": d["ts"], **trajectory_signals(d)}
    header = ["t [s]"] + [f"{k} [{SIGNALS[k].unit}]" for k in cols if k != "t"]
    table = np.stack(list(cols.values()), axis=1)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for row in table:
            w.writerow([f"{x:.{digits}g}" for x in row])
    return path


def save_trajectory_netcdf(path: str | Path, data, metadata: Mapping[str, Any] | None = None) -> Path:
    """Write one trajectory as a classic netCDF file (`jaxhoist._io.netcdf`, numpy only): dimensions `time`,
    `corner` (D, E, F, H), `xyz`, `quat`; every array of the npz under its own name with `units` (those of
    the units table `TRAJECTORY_ARRAYS`) and `long_name` attributes; `corner_name` holds the corner letters.

    **Arguments**
    - `path`: the `.nc` file; parent folders are created.
    - `data`: a `Trajectory` (or `RigidTrajectory`) or the dict of arrays of `load_trajectory`; one solve.
    - `metadata`: JSON-able global metadata (command, scenario, ...), stored as the text attribute
      `metadata_json`.

    **Returns** the path.

    **Raises** `ValueError` for a batched trajectory.
    """
    from .netcdf import write_netcdf

    d = as_arrays(data)
    if d["ts"].ndim != 1:
        raise ValueError(f"save_trajectory_netcdf: one trajectory expected, got ts of shape {d['ts'].shape}")
    n_t = d["ts"].shape[0]
    dims: dict[str, int] = {"time": n_t, "corner": 4, "xyz": 3, "quat": 4, "name_strlen": 1}
    n_fs = d["friction_state"].shape[-1] if d["friction_state"].ndim == 3 else 0
    if n_fs:
        dims["friction_state_dim"] = n_fs
    by_shape = {
        (): (),
        (n_t,): ("time",),
        (n_t, 3): ("time", "xyz"),
        (n_t, 4): ("time", "corner"),
        (n_t, 4, 3): ("time", "corner", "xyz"),
        (n_t, 4, n_fs): ("time", "corner", "friction_state_dim"),
    }
    table = {**TRAJECTORY_ARRAYS, **RIGID_ARRAYS}
    variables = [
        (
            "corner_name",
            ("corner", "name_strlen"),
            np.array([[c] for c in "DEFH"], dtype="S1"),
            {"long_name": "corner label"},
        )
    ]
    for name, a in d.items():
        if name == "quaternion":
            vdims = ("time", "quat")
        elif name == "friction_state" and not n_fs:
            continue  # a friction law without state (Coulomb): nothing to store
        else:
            vdims = by_shape[a.shape]
        unit, meaning = table.get(name, ("-", ""))
        variables.append((name, vdims, a, {"units": unit if unit != "-" else "1", "long_name": meaning}))
    attrs = {"title": "jaxhoist trajectory", "format": FORMAT, "Conventions": "CF-1.8"}
    if metadata:
        attrs["metadata_json"] = json.dumps(_jsonable(dict(metadata)))
    return write_netcdf(path, dims, variables, attrs)
