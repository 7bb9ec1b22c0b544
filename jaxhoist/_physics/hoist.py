"""Hoist laws: how the rope is reeled in over time (constant speed, ramped, a speed profile through
knots, a given profile)."""

from __future__ import annotations

import abc
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

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


class KnotHoist(AbstractHoistLaw):
    """A hoist speed profile given by its values at knot times: v(t) is the monotone (shape-preserving)
    cubic Hermite curve through the knots, held at the last knot's speed after it, and the shortening
    s(t) = ∫_0^t v dτ is its integral in closed form. Every number is a float array leaf, so a knot's
    speed is a design path (`"hoist.speeds[1]"`) for `scan`, `lift_risk` and `optimise_lift`.

    The slopes of v at the knots are those of Fritsch and Butland's monotone interpolation (as
    `scipy.interpolate.PchipInterpolator` at interior knots): the weighted harmonic mean of the two
    neighbouring secants where they have one sign, else 0; and 0 at the first and the last knot. So v is
    C¹, never overshoots its knots (it stays within the range of the two knots around it, hence in
    [0, max(speeds)] and below `max_speed`), rises where the knots rise, and a ramp from 0 to v_l over
    [0, T] is the smoothstep of `RampedHoist(v_l, T)`. Where two neighbouring secants change sign, the
    slope switches to 0: the profile is continuous in the knot speeds, but differentiable in them only
    off those points (its gradient there is the one-sided limit of the branch taken).

    - `times`: knot times t_0 = 0 < t_1 < ... < t_{n-1} [s], n >= 2.
    - `speeds`: hoist speeds v_k >= 0 at the knots [m/s], as many as `times`.
    - `max_speed`: the hoist's maximum speed [m/s]; every knot speed must be at most this (`inf`: no
      limit stated).
    - `travel`: total rope taken in [m] (`inf`: never stops). On reaching it the hoist stops at once (a
      step of the speed to 0); for a smooth stop end the profile with a knot at speed 0 instead.
    """

    times: Float[Array, " n"] = eqx.field(
        metadata=unit("s") | plausible(0.0, 1e4, "a lift's hoist profile lasts seconds to minutes")
    )
    speeds: Float[Array, " n"] = eqx.field(
        metadata=unit("m/s") | plausible(0.0, 20.0, "crane hoists run at up to ~3 m/s")
    )
    max_speed: Scalar = eqx.field(
        metadata=unit("m/s") | plausible(1e-3, 20.0, "crane hoists run at up to ~3 m/s", infinite=True)
    )
    travel: Scalar = eqx.field(
        metadata=unit("m") | plausible(0.0, 1e4, "no hoist holds 10 km of rope", infinite=True)
    )

    def __init__(self, times, speeds, max_speed=float("inf"), travel=float("inf")):
        self.times = f64(times)
        self.speeds = f64(speeds)
        self.max_speed = f64(max_speed)
        self.travel = f64(travel)

    def _pieces(self, t):
        """Per interval k: (h_k, v_k, v_{k+1}, h_k m_k, h_k m_{k+1}, u_k = clip((t - t_k) / h_k, 0, 1))."""
        tk, v = self.times, self.speeds
        h = tk[1:] - tk[:-1]
        d = (v[1:] - v[:-1]) / h  # secants [m/s²]
        # interior slopes: weighted harmonic mean of the secants where they share a sign (two-where
        # guard: the branch not taken divides by 1, so its gradient stays finite), else 0
        same = d[:-1] * d[1:] > 0
        d0, d1 = jnp.where(same, d[:-1], 1.0), jnp.where(same, d[1:], 1.0)
        w1, w2 = 2.0 * h[1:] + h[:-1], h[1:] + 2.0 * h[:-1]
        m_in = jnp.where(same, (w1 + w2) / (w1 / d0 + w2 / d1), 0.0)
        zero = jnp.zeros((1,), dtype=m_in.dtype)
        m = jnp.concatenate([zero, m_in, zero])
        u = jnp.clip((t - tk[:-1]) / h, 0.0, 1.0)
        return h, v[:-1], v[1:], h * m[:-1], h * m[1:], u

    def speed_at(self, t):
        """v(t) [m/s] of the profile at times t [s] (any shape; before the travel limit, which `rate`
        applies)."""
        t = jnp.asarray(t, dtype=jnp.float64)
        _, va, vb, ma, mb, u = self._pieces(t[..., None])
        u2, u3 = u * u, u * u * u
        p = va * (2 * u3 - 3 * u2 + 1) + ma * (u3 - 2 * u2 + u) + vb * (3 * u2 - 2 * u3) + mb * (u3 - u2)
        # telescoping: an interval not reached adds p(0) - v_k = 0, a finished one v_{k+1} - v_k
        return self.speeds[0] + jnp.sum(p - va, axis=-1)

    def _profile(self, t):
        """∫_0^t v dτ [m], the Hermite basis integrated over each interval (before the travel limit)."""
        t = jnp.asarray(t, dtype=jnp.float64)
        h, va, vb, ma, mb, u = self._pieces(t[..., None])
        u2, u3, u4 = u * u, u * u * u, u * u * u * u
        s = h * (
            va * (u - u3 + 0.5 * u4)
            + ma * (0.5 * u2 - 2.0 * u3 / 3.0 + 0.25 * u4)
            + vb * (u3 - 0.5 * u4)
            + mb * (0.25 * u4 - u3 / 3.0)
        )
        return jnp.sum(s, axis=-1) + self.speeds[-1] * jnp.maximum(t - self.times[-1], 0.0)

    def shortening(self, t):
        return jnp.minimum(self._profile(t), self.travel)

    def rate(self, t):
        return jnp.where(self._profile(t) < self.travel, self.speed_at(t), 0.0)

    def check(self):
        check_value("hoist.times", self.times, unit="s", low=0.0)
        check_value("hoist.speeds", self.speeds, unit="m/s", low=0.0, symbol="v_k")
        check_value("hoist.max_speed", self.max_speed, unit="m/s", low=0.0, low_open=True, allow_posinf=True)
        check_value("hoist.travel", self.travel, unit="m", low=0.0, allow_posinf=True)
        tk, v, vmax = (concrete(x) for x in (self.times, self.speeds, self.max_speed))
        if tk is not None:
            if tk.ndim == 0 or tk.shape[-1] < 2:
                raise ScenarioError(f"hoist.times must hold at least 2 knot times [s], got {show(tk)}")
            if np.any(tk[..., 0] != 0.0):
                raise ScenarioError(f"hoist.times must start at 0 s, got times[0] = {show(tk[..., 0])} s")
            steps = np.diff(tk, axis=-1)
            if np.any(steps <= 0):
                k = int(np.argwhere(steps <= 0)[0][-1]) + 1
                raise ScenarioError(
                    f"hoist.times must increase strictly, got times[{k}] = {show(tk[..., k])} s "
                    f"after times[{k - 1}] = {show(tk[..., k - 1])} s"
                )
        if v is not None and tk is not None and (v.ndim == 0 or v.shape[-1] != tk.shape[-1]):
            raise ScenarioError(
                f"hoist.speeds must hold one speed per knot time ({tk.shape[-1]}), got shape {v.shape}"
            )
        if v is not None and vmax is not None:
            above = v > np.asarray(vmax)[..., None]
            if np.any(above):
                k = int(np.argwhere(above)[0][-1])
                raise ScenarioError(
                    f"hoist.speeds[{k}] = {show(v[..., k])} m/s is above hoist.max_speed = {show(vmax)} m/s"
                )
