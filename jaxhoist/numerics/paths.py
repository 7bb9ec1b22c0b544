"""Dotted parameter paths of a scenario (`"foundation.friction_coefficient"`, `"load.mass_centre[0]"`):
parse, check, get, set (traceable) and the SI unit. Used by `scan`, the bifurcation tools and the command
line."""

from __future__ import annotations

import re

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ScenarioError
from ..physics.params import Scenario, get_leaf

_PATH_RE = re.compile(r"^([A-Za-z_][\w]*(?:\.[A-Za-z_][\w]*)*)(?:\[(\d+)\])?$")


def parse_path(path: str) -> tuple[str, int | None]:
    """`"load.mass_centre[0]"` -> `("load.mass_centre", 0)`; `"hoist.speed"` -> `("hoist.speed", None)`."""
    m = _PATH_RE.match(path.strip())
    if not m:
        raise ScenarioError(
            f"{path!r} is not a parameter path: use dotted field names with an optional "
            f"component index, e.g. 'foundation.friction_coefficient' or 'load.mass_centre[0]'"
        )
    return m.group(1), (None if m.group(2) is None else int(m.group(2)))


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


def _getter(dotted: str):
    parts = dotted.split(".")

    def where(s):
        for p in parts:
            s = getattr(s, p)
        return s

    return where


def set_param(scenario: Scenario, path: str, value) -> Scenario:
    """A copy of `scenario` with the leaf (or leaf component) at `path` set to `value` (traceable)."""
    dotted, index = parse_path(path)
    where = _getter(dotted)
    value = jnp.asarray(value, dtype=jnp.float64)
    if index is not None:
        value = where(scenario).at[index].set(value)  # pyright: ignore[reportAttributeAccessIssue]  # the leaf at a vector path is an array
    return eqx.tree_at(where, scenario, value)


def get_param(scenario: Scenario, path: str):
    """The value of the leaf (or leaf component) at `path`, the counterpart of `set_param`."""
    check_path(scenario, path)
    dotted, index = parse_path(path)
    leaf = get_leaf(scenario, dotted)
    return leaf if index is None else leaf[index]


def param_unit(scenario: Scenario, path: str) -> str:
    """The SI unit of a parameter, read from the docstring of the class that owns the field."""
    dotted, _ = parse_path(path)
    *owner_path, field = dotted.split(".")
    owner = scenario
    for p in owner_path:
        owner = getattr(owner, p)
    for cls in type(owner).__mro__:
        m = re.search(rf"`{re.escape(field)}`:[^\n]*?\[([^\]\n]+)\]", cls.__doc__ or "")
        if m:
            return m.group(1)
    return "?"
