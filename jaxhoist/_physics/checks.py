"""Host-side checks of parameter values (run on concrete values only, so the parameter Modules stay
transparent to jit, vmap and grad): finite, in range, float64; and the plausible range of each parameter,
kept in its field's metadata (`plausible`), which a scenario may opt out of (`allow_implausible`)."""

from __future__ import annotations

import dataclasses

import equinox as eqx
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


PLAUSIBLE = "plausible"
"""The field-metadata key of a parameter's plausible range (a `PlausibleRange`)."""

OPT_IN = (
    "if the value is meant, pass allow_implausible=True (load_scenario, scenario_from_dict, Scenario, "
    "Scenario.replace) or --allow-implausible on the command line"
)


@dataclasses.dataclass(frozen=True)
class PlausibleRange:
    """The values of a parameter that a real lift can have, with a wide margin: a value outside is almost
    certainly a typo (1e16 for 1e6) and is refused unless the scenario opts in with `allow_implausible`.

    - `low`, `high`: the range, in the field's SI unit (`high` may be inf).
    - `why`: the reason, for the message and the documentation.
    - `zero`: 0 is admitted besides the range (a switch-off: no damping, no slack).
    - `infinite`: +inf is admitted besides the range (a hoist that never stops).
    """

    low: float
    high: float
    why: str
    zero: bool = False
    infinite: bool = False

    def describe(self, unit: str) -> str:
        u = f" {unit}" if unit and unit != "-" else ""
        text = f"{self.low:g} to {self.high:g}{u}"
        return text + (" (or 0)" if self.zero else "") + (" (or inf)" if self.infinite else "")


def plausible(low: float, high: float, why: str, *, zero: bool = False, infinite: bool = False) -> dict:
    """Field metadata naming a parameter's plausible range (see `PlausibleRange`); combine with `unit`:
    `eqx.field(metadata=unit("N/m") | plausible(1e3, 1e12, "..."))`."""
    return {PLAUSIBLE: PlausibleRange(float(low), float(high), why, zero, infinite)}


def check_plausible(module, prefix: str = "") -> None:
    """Raise `ScenarioError` for the first float field of `module` (and of the Modules it holds, walked in
    field order) whose concrete value lies outside its `plausible` range, naming the field, the value, the
    range, the reason and the opt-in. Tracers are skipped.

    **Arguments**
    - `module`: an `eqx.Module` of parameters (a `Scenario` or one of its parts).
    - `prefix`: the dotted path of `module` inside the scenario (`"foundation."`).
    """
    from .paths import UNIT

    for f in dataclasses.fields(module):
        value = getattr(module, f.name, None)
        if isinstance(value, eqx.Module):
            check_plausible(value, f"{prefix}{f.name}.")
            continue
        rng = f.metadata.get(PLAUSIBLE)
        if rng is None or value is None:
            continue
        v = concrete(value)
        if v is None or v.dtype.kind != "f":
            continue
        inside = (v >= rng.low) & (v <= rng.high)
        if rng.zero:
            inside |= v == 0.0
        if rng.infinite:
            inside |= v == np.inf
        if not np.all(inside):
            unit = f.metadata.get(UNIT, "")
            u = f" {unit}" if unit and unit != "-" else ""
            raise ScenarioError(
                f"{prefix}{f.name} = {show(v)}{u} is "
                f"outside its plausible range {rng.describe(unit)} ({rng.why}); {OPT_IN}"
            )


def show(v):
    """A value for an error message: the list itself if short, else a summary (messages stay short)."""
    v = np.asarray(v)
    if v.size <= 6:
        return v.tolist()
    return f"<array of shape {v.shape}, from {np.nanmin(v):g} to {np.nanmax(v):g}>"


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
) -> None:
    """Raise `ScenarioError` naming `name` unless every element of `value` is finite and in range (the
    hard limits: a negative stiffness, a NaN; the plausible ranges are the fields' metadata, checked by
    `check_plausible`)."""
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
