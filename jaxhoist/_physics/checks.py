"""Host-side checks of parameter values (run on concrete values only, so the parameter Modules stay
transparent to jit, vmap and grad): finite, in range, of plausible magnitude, float64."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._errors import ScenarioError


def f64(x) -> Array:
    return jnp.asarray(x, dtype=jnp.float64)


def concrete(x) -> np.ndarray | None:
    """The value of a leaf as numpy, or None if it is a tracer (inside jit/vmap/grad)."""
    if isinstance(x, jax.core.Tracer):  # pyright: ignore[reportAttributeAccessIssue]  # jax.core is a lazily loaded submodule
        return None
    return np.asarray(x)


PLAUSIBLE_MAGNITUDE = (1e-100, 1e100)
"""Plausibility check: every nonzero finite parameter (and the derived mass) must have a magnitude in this
range, in SI units. Outside it, float64 products in the forces and energies (m g z, k p², ρabc) overflow or
lose the value entirely, and a solve "succeeds" with absurd states (C_z ≈ -1e295 m)."""


def show(v):
    """A value for an error message: the list itself if short, else a summary (messages stay short)."""
    v = np.asarray(v)
    if v.size <= 6:
        return v.tolist()
    return f"<array of shape {v.shape}, from {np.nanmin(v):g} to {np.nanmax(v):g}>"


def _check_plausible(label: str, v: np.ndarray, unit_s: str) -> None:
    lo, hi = PLAUSIBLE_MAGNITUDE
    with np.errstate(invalid="ignore"):
        a = np.abs(np.where(np.isfinite(v), v, 0.0))
    bad = (a > hi) | ((a > 0) & (a < lo))
    if np.any(bad):
        raise ScenarioError(
            f"{label} = {show(v)}{unit_s} is not plausible: nonzero values must have a magnitude between "
            f"{lo:g} and {hi:g} in SI units (beyond that, forces and energies overflow float64)"
        )


def check_value(
    name: str,
    value,
    *,
    unit: str,
    shape: tuple | None = None,
    low=None,
    high=None,
    low_open=False,
    high_open=False,
    symbol: str = "",
    allow_posinf=False,
    plausible=True,
) -> None:
    """Raise `ScenarioError` naming `name` unless every element of `value` is finite and in range (and,
    with `plausible`, of a magnitude within `PLAUSIBLE_MAGNITUDE` unless zero)."""
    v = concrete(value)
    if v is None:
        return
    label = f"{name} ({symbol})" if symbol else name
    if v.dtype == np.float32:
        raise ScenarioError(
            f"{label} is float32. " + "jaxhoist needs float64: call "
            "`jax.config.update('jax_enable_x64', True)` before building a scenario."
        )
    if v.dtype.kind not in "fiu":
        raise ScenarioError(f"{label} must be a number or an array of numbers, got dtype {v.dtype}")
    if shape is not None and v.shape[v.ndim - len(shape) :] != shape:
        raise ScenarioError(f"{label} must have shape {shape}, got {v.shape}")
    if not np.all(np.isfinite(v)):
        if not allow_posinf or np.any(np.isnan(v) | np.isneginf(v)):
            raise ScenarioError(f"{label} must be finite, got {show(v)}")
    unit_s = f" {unit}" if unit and unit != "-" else ""
    if low is not None:
        bad = v <= low if low_open else v < low
        if np.any(bad):
            rel = ">" if low_open else ">="
            raise ScenarioError(f"{label} must be {rel} {low}{unit_s}, got {show(v)}")
    if high is not None:
        bad = v >= high if high_open else v > high
        if np.any(bad):
            rel = "<" if high_open else "<="
            raise ScenarioError(f"{label} must be {rel} {high}{unit_s}, got {show(v)}")
    if plausible:
        _check_plausible(label, v, unit_s)
