"""The members of a scan as objects: `Sweep` (one parameter), `Grid` (every combination) and `Points`
(equally long lists zipped together), each a mapping of parameter path -> values checked on construction;
`parse_values` reads values from arrays or strings, `as_sweep` turns a plain mapping (and the command
line's `--mode`) into one of them, and `validate_members` checks every member on the host before anything
is compiled."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._errors import ScenarioError
from ..._physics.params import Scenario
from ..._physics.paths import get_leaf, leaf_getter, parse_path


def parse_values(spec) -> np.ndarray:
    """Values of a swept parameter: an array-like, or a string `"start:stop:num"` (inclusive, like
    `numpy.linspace`) or `"v1,v2,..."`."""
    if isinstance(spec, str):
        s = spec.strip()
        try:
            if ":" in s:
                a, b, n = s.split(":")
                if int(n) < 1:
                    raise ValueError
                return np.linspace(float(a), float(b), int(n))
            return np.array([float(x) for x in s.split(",") if x.strip()])
        except ValueError:
            raise ScenarioError(
                f"parameter values {spec!r}: expected 'start:stop:num' or 'v1,v2,...'"
            ) from None
    try:
        a = np.asarray(spec, dtype=np.float64)
    except (TypeError, ValueError):
        raise ScenarioError(f"parameter values must be numbers, got {spec!r}") from None
    if a.ndim == 0:
        a = a[None]
    if a.ndim != 1:
        raise ScenarioError(f"parameter values must be 1-D, got shape {a.shape}")
    return a


def _checked(kind: str, values) -> dict[str, np.ndarray]:
    """Parameter path -> 1-D float64 values, each checked; errors name the sweep type and the path."""
    if not isinstance(values, Mapping):
        raise ScenarioError(
            f"{kind} takes a mapping of parameter path -> values, got {type(values).__name__}"
        )
    if not values:
        raise ScenarioError(f"{kind} needs at least one parameter to sweep")
    out, named = {}, {}
    for path, spec in values.items():
        if not isinstance(path, str) or not path.strip():
            raise ScenarioError(
                f"{kind}: a parameter path must be a dotted name like 'hoist.speed', got {path!r}"
            )
        try:  # two spellings of one parameter ("hoist.speed" and " hoist.speed", "c[0]" and "c[00]")
            same = named.setdefault(parse_path(path), path)
        except ScenarioError:  # not a path: the scan's own check of the paths says so, with a hint
            same = path
        if same != path:
            raise ScenarioError(f"{kind}: {same!r} and {path!r} name the same parameter: give it once")
        try:
            v = parse_values(spec)
        except ScenarioError as e:
            raise ScenarioError(f"{kind}: {path!r}: {e}") from None
        if v.size == 0:
            raise ScenarioError(f"{kind}: {path!r} has no values")
        out[path] = v
    return out


class AbstractSweep(eqx.Module):
    """The members of a scan: parameter path -> values [SI unit of each field], laid out by the subclass.

    - `values`: path -> 1-D float64 array (a string `"start:stop:num"` or `"v1,v2,..."` is read on
      construction, see `parse_values`).
    - `params`: the paths in order; `shape`: the data axes of the result; `size`: the member count.
    """

    values: dict[str, np.ndarray]
    mode: ClassVar[str]

    @property
    def params(self) -> tuple[str, ...]:
        return tuple(self.values)

    @property
    def shape(self) -> tuple[int, ...]:
        raise NotImplementedError

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    def __len__(self) -> int:
        return self.size

    def members(self) -> np.ndarray:
        """Every member's values, shape (size, number of parameters), in the result's (row-major) order."""
        raise NotImplementedError


class Sweep(AbstractSweep):
    """One parameter swept over its values: `Sweep("foundation.friction_coefficient", np.linspace(0.1,
    0.6, 51))` (one data axis). **Raises** `ScenarioError` for a bad path or values."""

    mode: ClassVar[str] = "sweep"

    def __init__(self, path: str, values):
        self.values = _checked("Sweep", {path: values})

    @property
    def shape(self) -> tuple[int, ...]:
        return (next(iter(self.values.values())).size,)

    def members(self) -> np.ndarray:
        return next(iter(self.values.values()))[:, None]


class Grid(AbstractSweep):
    """Every combination of the parameters' values (an outer product):
    `Grid({"foundation.friction_coefficient": mus, "hoist.speed": speeds})` has `len(mus) * len(speeds)`
    members and one data axis per parameter, in the order given. **Raises** `ScenarioError` for a bad path
    or values."""

    mode: ClassVar[str] = "grid"

    def __init__(self, values: Any):  # a mapping path -> values; anything else is refused by `_checked`
        self.values = _checked("Grid", values)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(v.size for v in self.values.values())

    def members(self) -> np.ndarray:
        mesh = np.meshgrid(*self.values.values(), indexing="ij")
        return np.stack([m.ravel() for m in mesh], axis=1)


class Points(AbstractSweep):
    """Equally long value lists zipped together, member k taking the k-th value of every list:
    `Points({"load.mass": masses, "rope.stiffness": stiffnesses})` (one data axis). **Raises**
    `ScenarioError` for a bad path or values, or lists of different lengths."""

    mode: ClassVar[str] = "points"

    def __init__(self, values: Any):  # a mapping path -> values; anything else is refused by `_checked`
        checked = _checked("Points", values)
        lengths = {p: v.size for p, v in checked.items()}
        if len(set(lengths.values())) != 1:
            first = next(iter(lengths))
            odd = next(p for p, n in lengths.items() if n != lengths[first])
            raise ScenarioError(
                f"Points: {odd!r} has {lengths[odd]} values but {first!r} has {lengths[first]}: zipped value "
                f"lists must be equally long (every length: {lengths}; use Grid for every combination)"
            )
        self.values = checked

    @property
    def shape(self) -> tuple[int, ...]:
        return (next(iter(self.values.values())).size,)

    def members(self) -> np.ndarray:
        return np.stack(list(self.values.values()), axis=1)


_MODES = {"sweep": Sweep, "grid": Grid, "points": Points}


def as_sweep(sweep, mode: str | None = None) -> AbstractSweep:
    """The sweep object for `sweep`: an `AbstractSweep` as is, or a plain mapping path -> values laid out
    by `mode` ("sweep", "grid", "points"; default: `Sweep` for one parameter, `Grid` for several).

    **Raises** `ScenarioError` for an unknown mode, a mode with a sweep object, or bad paths and values.
    """
    if isinstance(sweep, AbstractSweep):
        if mode is not None and mode != sweep.mode:
            raise ScenarioError(f"mode={mode!r} contradicts the sweep object {type(sweep).__name__}")
        return sweep
    if not isinstance(sweep, Mapping):
        raise ScenarioError(
            f"sweep must be Sweep(path, values), Grid({{path: values}}), Points({{path: values}}) or a "
            f"mapping path -> values, got {type(sweep).__name__}"
        )
    if mode is not None and mode not in _MODES:
        raise ScenarioError(f"mode must be 'sweep', 'grid' or 'points', got {mode!r}")
    if mode is None:
        mode = "sweep" if len(sweep) == 1 else "grid"
    if mode == "sweep":
        if len(sweep) != 1:
            raise ScenarioError(
                f"mode='sweep' sweeps one parameter, got {len(sweep)}: use mode='grid' "
                f"(every combination) or mode='points' (zipped lists)"
            )
        ((path, values),) = sweep.items()
        return Sweep(path, values)
    return _MODES[mode](sweep)


def members(params, mode: str | None = None):
    """-> (mode, coords, shape, member values (n, P)) of `as_sweep(params, mode)`."""
    s = as_sweep(params, mode)
    return s.mode, dict(s.values), s.shape, s.members()


def validate_members(scenario: Scenario, paths: Sequence[str], members: np.ndarray) -> dict[int, str]:
    """Host-side check of every member's parameter values. Returns {member index: error message}."""

    def check(rows: np.ndarray) -> None:
        sc = scenario
        for k, p in enumerate(paths):
            dotted, index = parse_path(p)
            leaf = np.asarray(get_leaf(scenario, dotted))
            if index is None:
                new = rows[:, k]
            else:
                new = np.broadcast_to(leaf, (rows.shape[0], *leaf.shape)).copy()
                new[:, index] = rows[:, k]
            sc = eqx.tree_at(leaf_getter(dotted), sc, jnp.asarray(new))
        sc.check()

    bad: dict[int, str] = {}
    try:
        check(members)  # every member at once: the checks broadcast over a leading axis
        return bad
    except ScenarioError:
        pass
    for i in range(members.shape[0]):
        try:
            check(members[i : i + 1])
        except ScenarioError as e:
            bad[i] = str(e)
    return bad
