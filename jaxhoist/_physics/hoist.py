"""Hoist laws: how the rope is reeled in over time (constant speed, ramped, a given profile)."""

from __future__ import annotations

import abc
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import ScenarioError
from .._typing import Scalar
from .checks import check_value, concrete, f64, plausible, show
from .paths import unit


class AbstractHoistLaw(eqx.Module):
    """How much rope the hoist has taken in: l(t) = l0 - s(t), with s(0) = 0."""

    @abc.abstractmethod
    def shortening(self, t: Scalar) -> Scalar:
        """s(t) [m]."""

    def rate(self, t: Scalar) -> Scalar:
        """ds/dt [m/s] (by forward-mode differentiation unless a law overrides it)."""
        return jax.jvp(self.shortening, (t,), (jnp.ones_like(t),))[1]

    def check(self) -> None:
        pass


class ConstantSpeedHoist(AbstractHoistLaw):
    """l(t) = l0 - v_l t, the paper's law (§2.3).

    - `speed`: v_l [m/s].
    """

    speed: Scalar = eqx.field(metadata=unit("m/s") | plausible(0.0, 20.0, "crane hoists run at up to ~3 m/s"))

    def __init__(self, speed):
        self.speed = f64(speed)

    def shortening(self, t):
        return self.speed * t

    def rate(self, t):
        return self.speed * jnp.ones_like(t)

    def check(self):
        check_value("hoist.speed", self.speed, unit="m/s", low=0.0, symbol="v_l")


class RampedHoist(AbstractHoistLaw):
    """Hoist speed rising smoothly (C¹, smoothstep) from 0 to v_l over `ramp_time`, then falling to 0
    so that the hoist stops after taking in `travel` metres of rope.

    - `speed`: v_l, the cruising speed [m/s].
    - `ramp_time`: duration of the speed-up and of the slow-down [s] (0 gives a step in speed).
    - `travel`: total rope taken in [m] (`inf`: never stops); needs travel >= v_l ramp_time.
    """

    speed: Scalar = eqx.field(metadata=unit("m/s") | plausible(0.0, 20.0, "crane hoists run at up to ~3 m/s"))
    ramp_time: Scalar = eqx.field(
        metadata=unit("s") | plausible(0.0, 1e3, "hoists reach their speed in seconds")
    )
    travel: Scalar = eqx.field(
        metadata=unit("m") | plausible(0.0, 1e4, "no hoist holds 10 km of rope", infinite=True)
    )

    def __init__(self, speed, ramp_time=0.0, travel=float("inf")):
        self.speed = f64(speed)
        self.ramp_time = f64(ramp_time)
        self.travel = f64(travel)

    def _g(self, t):
        # ∫_0^t smoothstep(τ/T) dτ, which is T (x³ - x⁴/2) on the ramp and T/2 + (t - T) after it.
        T = jnp.maximum(self.ramp_time, 1e-12)
        x = jnp.clip(t / T, 0.0, 1.0)
        return T * (x**3 - 0.5 * x**4) + jnp.maximum(t - T, 0.0)

    def _stop_time(self):
        return jnp.where(jnp.isinf(self.travel), jnp.inf, self.travel / jnp.maximum(self.speed, 1e-300))

    def shortening(self, t):
        t_stop = self._stop_time()
        late = jnp.where(jnp.isinf(t_stop), 0.0, self._g(t - jnp.where(jnp.isinf(t_stop), 0.0, t_stop)))
        return self.speed * (self._g(t) - late)

    def check(self):
        check_value("hoist.speed", self.speed, unit="m/s", low=0.0, symbol="v_l")
        check_value("hoist.ramp_time", self.ramp_time, unit="s", low=0.0)
        check_value("hoist.travel", self.travel, unit="m", low=0.0, allow_posinf=True)
        v, T, L = (concrete(x) for x in (self.speed, self.ramp_time, self.travel))
        if v is not None and T is not None and L is not None and np.any(L < v * T):
            raise ScenarioError(
                f"hoist.travel must be >= speed * ramp_time = {show(v * T)} m, got {show(L)} m"
            )


class ProfileHoist(AbstractHoistLaw):
    """A user-supplied smooth shortening profile s(t) [m] (a JAX-traceable function with s(0) = 0).

    - `profile`: callable t [s] -> s(t) [m]; its rate comes from forward-mode differentiation.
    """

    profile: Callable = eqx.field(static=True)

    def shortening(self, t):
        return self.profile(t)
