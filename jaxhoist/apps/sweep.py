"""The members of a scan: parameter values from arrays or strings (`parse_values`), laid out as one sweep,
a grid or zipped points (`members`), and checked on the host before anything is compiled
(`validate_members`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ScenarioError
from ..physics.params import Scenario
from ..physics.paths import get_leaf, leaf_getter, parse_path


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
    a = np.asarray(spec, dtype=np.float64)
    if a.ndim == 0:
        a = a[None]
    if a.ndim != 1:
        raise ScenarioError(f"parameter values must be 1-D, got shape {a.shape}")
    return a


def members(params: Mapping[str, Any], mode: str | None):
    """-> (mode, coords, shape, member values (n, P))."""
    names = list(params)
    if not names:
        raise ScenarioError("scan needs at least one parameter to sweep")
    vals = [parse_values(params[p]) for p in names]
    for p, v in zip(names, vals, strict=True):
        if v.size == 0:
            raise ScenarioError(f"scan parameter {p!r} has no values")
    if mode is None:
        mode = "sweep" if len(names) == 1 else None
    if mode == "sweep":
        if len(names) != 1:
            raise ScenarioError(
                f"mode='sweep' sweeps one parameter, got {len(names)}: use mode='grid' "
                f"(every combination) or mode='points' (zipped lists)"
            )
        return mode, {names[0]: vals[0]}, (vals[0].size,), vals[0][:, None]
    if mode == "grid":
        mesh = np.meshgrid(*vals, indexing="ij")
        return (
            mode,
            dict(zip(names, vals, strict=True)),
            tuple(v.size for v in vals),
            np.stack([m.ravel() for m in mesh], axis=1),
        )
    if mode == "points":
        n = {v.size for v in vals}
        if len(n) != 1:
            raise ScenarioError(
                f"mode='points' needs equally long value lists, got lengths "
                f"{dict(zip(names, [v.size for v in vals], strict=True))}"
            )
        return mode, dict(zip(names, vals, strict=True)), (vals[0].size,), np.stack(vals, axis=1)
    if mode is None:
        raise ScenarioError(
            "several parameters: say mode='grid' (every combination) or mode='points' (zipped)"
        )
    raise ScenarioError(f"mode must be 'sweep', 'grid' or 'points', got {mode!r}")


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
