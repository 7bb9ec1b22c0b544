"""Dotted parameter paths of a scenario (`"foundation.friction_coefficient"`, `"load.mass_centre[0]"`): the
one implementation of parse, validate, get, set and unit, used by `Scenario.replace`, `scan`, the
bifurcation tools, `identify`, `--set` and scenario overrides.

- `parse_path`: `"load.mass_centre[0]"` -> `("load.mass_centre", 0)`.
- `get_leaf(scenario, dotted)`: the float leaf, or a `ScenarioError` naming the path ("did you mean").
- `check_path(scenario, path)`: a float scalar leaf or one component of a float vector leaf.
- `get_param` / `set_param`: a leaf or leaf component by path (`set_param` is traceable: jit, vmap, grad).
- `replace_leaves(scenario, {dotted: value})`: host-side replacement, values checked against the leaf's shape.
- `param_unit(scenario, path)`: the SI unit, from the field's metadata (`eqx.field(metadata=unit("N/m"))`).
"""

from __future__ import annotations

import dataclasses
import difflib
import re
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._errors import ScenarioError

if TYPE_CHECKING:
    from .params import Scenario

_PATH_RE = re.compile(r"^([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)(?:\[([0-9]{1,6})\])?$")

UNIT = "unit"
"""The key of a field's metadata that holds its SI unit (see `unit`)."""


def unit(si: str) -> dict[str, str]:
    """A field's metadata naming its SI unit: `stiffness: Scalar = eqx.field(metadata=unit("N/m"))`."""
    return {UNIT: si}


def parse_path(path: str) -> tuple[str, int | None]:
    """`"load.mass_centre[0]"` -> `("load.mass_centre", 0)`; `"hoist.speed"` -> `("hoist.speed", None)`."""
    m = _PATH_RE.match(path.strip())
    if not m:
        raise ScenarioError(
            f"{path!r} is not a parameter path: use dotted field names with an optional "
            f"component index, e.g. 'foundation.friction_coefficient' or 'load.mass_centre[0]'"
        )
    return m.group(1), (None if m.group(2) is None else int(m.group(2)))


def leaf_getter(dotted: str) -> Callable[[Any], Any]:
    """`"rope.stiffness"` -> `lambda s: s.rope.stiffness` (for `eqx.tree_at`)."""
    parts = dotted.split(".")

    def get(s):
        for p in parts:
            s = getattr(s, p)
        return s

    return get


_STATIC_HINTS = {
    "t1": "the scenario's end time, a static setting: give it with --t1 T on the command line or "
    "simulate(scenario, Times(T)), or as t1 in the scenario file",
    "name": "a static label (the scenario file's name)",
    "description": "static free text (the scenario file's description)",
}


def _field(obj, p: str, path: str, where: str) -> dataclasses.Field:
    """The dataclass field `p` of module `obj`, or a `ScenarioError` naming the path."""
    if not isinstance(obj, eqx.Module):
        raise ScenarioError(f"{path!r}: {where} is a value, not a table; it has no field {p!r}")
    fields = {f.name: f for f in dataclasses.fields(obj)}
    if p not in fields:
        close = difflib.get_close_matches(p, list(fields), n=1, cutoff=0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ScenarioError(f"{path!r}: {where} has no field {p!r}{hint}; fields are {list(fields)}")
    if fields[p].metadata.get("static", False):
        what = _STATIC_HINTS.get(p, "a static setting")
        raise ScenarioError(f"{path!r} is not a float leaf: it is {what}")
    return fields[p]


def get_leaf(scenario, path: str) -> Array:
    """The float leaf at a dotted path such as `"rope.stiffness"`.

    **Arguments**
    - `scenario`: the scenario (or any of its parts).
    - `path`: dotted field names, e.g. `foundation.friction.regularisation_velocity`.

    **Returns** the leaf (an array).

    **Raises** `ScenarioError` naming the path if a part is no field of its parent (with the closest
    field's name), is a static setting (`t1`, `name`, `description`) or reaches past a leaf
    (`load.mass.real`), or if the path ends at a table rather than a float leaf.
    """
    obj = scenario
    parts = str(path).split(".")
    for i, p in enumerate(parts):
        _field(obj, p, path, ".".join(parts[:i]) or "scenario")
        obj = getattr(obj, p)
    if not isinstance(obj, jax.Array | np.ndarray):
        raise ScenarioError(f"{path!r} is not a float leaf (got {type(obj).__name__})")
    return obj  # pyright: ignore[reportReturnType]  # host (numpy) leaves are accepted too


def check_path(scenario: Scenario, path: str) -> None:
    """Raise `ScenarioError` unless `path` names a float scalar leaf or one component of a float vector
    leaf."""
    dotted, index = parse_path(path)
    leaf = np.asarray(get_leaf(scenario, dotted))
    if not np.issubdtype(leaf.dtype, np.floating):
        raise ScenarioError(f"{path!r} is not a float leaf (dtype {leaf.dtype})")
    if index is None and leaf.ndim != 0:
        raise ScenarioError(
            f"{path!r} is a vector of shape {leaf.shape}: sweep one component, e.g. '{dotted}[0]'"
        )
    if index is not None and (leaf.ndim != 1 or not 0 <= index < leaf.shape[0]):
        raise ScenarioError(f"{path!r}: index {index} out of range for a leaf of shape {leaf.shape}")


def set_leaf(scenario: Scenario, dotted: str, index: int | None, value) -> Scenario:
    """A copy of `scenario` with the leaf at `dotted` (its component `index` unless None) set to `value`
    as float64 (traceable)."""
    where = leaf_getter(dotted)
    value = jnp.asarray(value, dtype=jnp.float64)
    if index is not None:
        value = where(scenario).at[index].set(value)
    return eqx.tree_at(where, scenario, value)


def set_param(scenario: Scenario, path: str, value) -> Scenario:
    """A copy of `scenario` with the leaf (or leaf component) at `path` set to `value` (traceable)."""
    dotted, index = parse_path(path)
    return set_leaf(scenario, dotted, index, value)


def get_param(scenario: Scenario, path: str):
    """The value of the leaf (or leaf component) at `path`, the counterpart of `set_param`."""
    check_path(scenario, path)
    dotted, index = parse_path(path)
    leaf = get_leaf(scenario, dotted)
    return leaf if index is None else leaf[index]


def leaf_value(path: str, value, shape: tuple) -> Array:
    """`value` as a float64 array of `shape` (broadcast), or a `ScenarioError` naming `path`."""
    if not isinstance(value, jax.core.Tracer):  # pyright: ignore[reportAttributeAccessIssue]  # jax.core is a lazily loaded submodule
        try:
            a = np.asarray(value)
        except (ValueError, TypeError, OverflowError):
            a = np.asarray(None)
        if a.dtype.kind not in "fiu":
            raise ScenarioError(f"{path} must be a number or an array of numbers, got {value!r:.60}")
        try:
            a = a.astype(np.float64)
        except OverflowError:
            raise ScenarioError(f"{path}: the integer {value!r:.40} is too large for a float") from None
    vshape = np.shape(value)
    try:
        ok = np.broadcast_shapes(vshape, shape) == tuple(shape)
    except ValueError:
        ok = False
    if not ok:
        want = "a number" if shape == () else f"shape {tuple(shape)}"
        raise ScenarioError(f"{path} must be {want}, got a value of shape {vshape}")
    return jnp.broadcast_to(jnp.asarray(value, dtype=jnp.float64), shape)


def replace_leaves(scenario, leaves: Mapping[str, Any]):
    """A copy with float leaves replaced by dotted path (values broadcast to the leaf's shape and checked:
    a bad path, a static setting, a non-numeric value or one of the wrong shape raise `ScenarioError`
    naming the path). Not re-validated: call `.check()` on the result."""
    out = scenario
    for path, value in leaves.items():
        old = get_leaf(out, path)
        out = eqx.tree_at(leaf_getter(path), out, leaf_value(path, value, np.shape(old)))
    return out


def param_unit(scenario: Scenario, path: str) -> str:
    """The SI unit of a parameter, from the metadata of the field that holds it ("?" if it has none)."""
    dotted, _ = parse_path(path)
    obj, field = scenario, None
    for p in dotted.split("."):
        field = _field(obj, p, path, "scenario")
        obj = getattr(obj, p)
    return "?" if field is None else field.metadata.get(UNIT, "?")
