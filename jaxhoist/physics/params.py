"""Model parameters as `eqx.Module` pytrees: every physical number is a float64 array leaf, in SI units.

Frames (paper Fig. 1, eqs. 2.1-2.8): world X, Y horizontal, Z up, ground at Z = 0. Body axes ξηζ run along
the box edges a, b, c from the bottom corner D. At t = 0 the bottom corners D, E, F, H stand near
(0, 0), (a, 0), (a, b), (0, b). Corner order is always D, E, F, H.

Host-side checks (`check()`) run on concrete values only, so the modules stay transparent to
`jax.jit`, `jax.vmap` and `jax.grad`; `simulate` re-checks a scenario before compiling, because
`eqx.tree_at` does not run `__init__`.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import ScenarioError, require_x64
from .._typing import Rot33, Scalar, Vec3


def _f64(x) -> Array:
    return jnp.asarray(x, dtype=jnp.float64)


def _concrete(x) -> np.ndarray | None:
    """The value of a leaf as numpy, or None if it is a tracer (inside jit/vmap/grad)."""
    if isinstance(x, jax.core.Tracer):  # pyright: ignore[reportAttributeAccessIssue]  # jax.core is a lazily loaded submodule
        return None
    return np.asarray(x)


PLAUSIBLE_MAGNITUDE = (1e-100, 1e100)
"""Plausibility check: every nonzero finite parameter (and the derived mass) must have a magnitude in this
range, in SI units. Outside it, float64 products in the forces and energies (m g z, k p², ρabc) overflow or
lose the value entirely, and a solve "succeeds" with absurd states (C_z ≈ -1e295 m)."""


def _show(v):
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
            f"{label} = {_show(v)}{unit_s} is not plausible: nonzero values must have a magnitude between "
            f"{lo:g} and {hi:g} in SI units (beyond that, forces and energies overflow float64)"
        )


def _check(
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
    v = _concrete(value)
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
            raise ScenarioError(f"{label} must be finite, got {_show(v)}")
    unit_s = f" {unit}" if unit and unit != "-" else ""
    if low is not None:
        bad = v <= low if low_open else v < low
        if np.any(bad):
            rel = ">" if low_open else ">="
            raise ScenarioError(f"{label} must be {rel} {low}{unit_s}, got {_show(v)}")
    if high is not None:
        bad = v >= high if high_open else v > high
        if np.any(bad):
            rel = "<" if high_open else "<="
            raise ScenarioError(f"{label} must be {rel} {high}{unit_s}, got {_show(v)}")
    if plausible:
        _check_plausible(label, v, unit_s)


# --------------------------------------------------------------------------------------------- load


class Load(eqx.Module):
    """The lifted load: a rigid box a×b×c with an eccentric mass centre (paper §2, Fig. 1).

    - `size`: (a, b, c), edge lengths along ξ, η, ζ [m].
    - `mass`: m [kg] (give `mass` or `density` ρ [kg/m³] to the constructor; m = ρabc, computed once:
      replacing `size` later keeps the mass, so change both if you mean a bigger box of the same material).
    - `mass_centre`: C = (ξ_C, η_C, ζ_C) in the body frame, measured from corner D [m]; default the box
      centre.
    - `inertia`: J, the inertia tensor about C in body axes [kg m²] with the sign convention of (2.11)
      (off-diagonal entries are -J_ξη etc.), or None: then the uniform-box tensor about its centre,
      carried to C by the parallel-axis theorem (our choice; give J explicitly for a measured load).
    """

    size: Vec3
    mass: Scalar
    mass_centre: Vec3
    inertia: Rot33 | None

    def __init__(self, size, mass=None, *, density=None, mass_centre=None, inertia=None):
        size = _f64(size)
        if (mass is None) == (density is None):
            raise ScenarioError("load: give exactly one of `mass` [kg] or `density` [kg/m^3]")
        if density is not None:
            _check("load.density", _f64(density), unit="kg/m^3", low=0.0, low_open=True, symbol="ρ")
            mass = _f64(density) * size[0] * size[1] * size[2]
            m = _concrete(mass)
            if m is not None and (not np.all(np.isfinite(m)) or np.any(m > PLAUSIBLE_MAGNITUDE[1])):
                raise ScenarioError(
                    f"load.density (ρ) = {_show(np.asarray(density))} kg/m^3 is not plausible: the mass "
                    f"ρabc = {_show(m)} kg is beyond {PLAUSIBLE_MAGNITUDE[1]:g} kg"
                )
        self.size = size
        self.mass = _f64(mass)
        self.mass_centre = 0.5 * size if mass_centre is None else _f64(mass_centre)
        self.inertia = None if inertia is None else _f64(inertia)

    def inertia_tensor(self) -> Rot33:
        """J about C in body axes [kg m²] (the explicit `inertia`, or the parallel-axis default)."""
        if self.inertia is not None:
            return self.inertia
        a, b, c = self.size
        m = self.mass
        j_g = (m / 12.0) * jnp.diag(jnp.stack([b**2 + c**2, a**2 + c**2, a**2 + b**2]))
        d = self.mass_centre - 0.5 * self.size
        return j_g + m * (jnp.dot(d, d) * jnp.eye(3) - jnp.outer(d, d))

    def check(self) -> None:
        _check("load.size", self.size, unit="m", shape=(3,), low=0.0, low_open=True, symbol="a, b, c")
        _check("load.mass", self.mass, unit="kg", low=0.0, low_open=True, symbol="m")
        _check("load.mass_centre", self.mass_centre, unit="m", shape=(3,), symbol="ξ_C, η_C, ζ_C")
        s, c = _concrete(self.size), _concrete(self.mass_centre)
        if s is not None and c is not None and np.any((c <= 0) | (c >= s)):
            raise ScenarioError(
                f"load.mass_centre must lie strictly inside the box 0 < C < size = {_show(s)} m, "
                f"got {_show(c)} m"
            )
        if self.inertia is not None:
            _check("load.inertia", self.inertia, unit="kg m^2", shape=(3, 3), symbol="J")
            j = _concrete(self.inertia)
            if j is not None and j.ndim == 2:
                if not np.allclose(j, j.T, rtol=1e-12, atol=0.0):
                    raise ScenarioError("load.inertia (J) must be symmetric")
                ev = np.linalg.eigvalsh(j)
                if ev[0] <= 0 or ev[2] > ev[0] + ev[1] + 1e-9 * ev[2]:
                    raise ScenarioError(
                        f"load.inertia (J) must be positive definite with principal moments obeying the "
                        f"triangle inequality, got principal moments {ev.tolist()} kg m^2"
                    )


# ----------------------------------------------------------------------------------------- friction


class AbstractFrictionLaw(eqx.Module):
    """How a corner's tangential ground force follows its sliding velocity (paper eq. 3.3).

    A law may carry an internal state per corner, of shape `(4, state_size)`.
    """

    state_size: eqx.AbstractClassVar[int]

    @abc.abstractmethod
    def force(
        self, mu: Scalar, normal: Float[Array, "4"], velocity: Float[Array, "4 2"], state: Float[Array, "4 n"]
    ) -> Float[Array, "4 2"]:
        """Horizontal friction force on each corner [N], from μ, N_i [N], corner velocity [m/s]."""

    @abc.abstractmethod
    def state_rate(
        self, velocity: Float[Array, "4 2"], state: Float[Array, "4 n"], contact: Float[Array, "4"]
    ) -> Float[Array, "4 n"]:
        """Time derivative of the law's internal state. `contact` in [0, 1] is 0 off the ground and 1 once a
        corner is deeper than the foundation's `damping_onset` (continuous in between)."""

    def check(self) -> None:
        pass


class RegularisedCoulomb(AbstractFrictionLaw):
    """The paper's Coulomb law (2.18)/(3.3), T_i = -μ N_i v_i / sqrt(|v_i|² + ε²).

    - `regularisation_velocity`: ε [m/s]. Below ~ε the law acts as a steep viscous damper, so it creeps
      rather than sticks; small ε makes the ODE stiff (steps grow like 1/ε). The square root keeps the
      force and its gradient finite at v = 0.
    """

    regularisation_velocity: Scalar
    state_size: ClassVar[int] = 0

    def __init__(self, regularisation_velocity=1e-3):
        self.regularisation_velocity = _f64(regularisation_velocity)

    def force(self, mu, normal, velocity, state):
        eps = self.regularisation_velocity
        speed = jnp.sqrt(jnp.sum(velocity**2, axis=-1) + eps**2)
        return -(mu * normal / speed)[:, None] * velocity

    def state_rate(self, velocity, state, contact):
        return state

    def check(self):
        _check(
            "foundation.friction.regularisation_velocity",
            self.regularisation_velocity,
            unit="m/s",
            low=0.0,
            low_open=True,
            symbol="ε",
        )


class BristleFriction(AbstractFrictionLaw):
    """Elastic-plastic bristle friction that truly sticks (a 2-D Dahl / elasto-plastic law, our choice).

    Each corner carries a bristle deflection z_i [m] (2 horizontal components). The force is
    T_i = -μ N_i z_i / δ, i.e. a tangential stiffness μN_i/δ that scales with the load, so it never
    stiffens as N_i -> 0 at touch-down and lift-off. The deflection follows the corner velocity v_i,

        dz/dt = v - α(|z|/δ) (v·z)⁺ z / |z|²,   α(r) = ((r - r_b)⁺ / (1 - r_b))²,

    so below the break-away deflection r_b δ the contact is purely elastic (sticks, no drift); at
    |z| = δ the outward growth stops and the corner slides with |T_i| = μN_i opposite to its motion.

    - `deflection`: δ, the bristle deflection at full sliding [m].
    - `breakaway_ratio`: r_b in [0, 1), the fraction of δ below which there is no slip [-].
    - `relaxation_time`: τ, time constant with which an unloaded bristle (corner off the ground)
      relaxes to zero [s].
    """

    deflection: Scalar
    breakaway_ratio: Scalar
    relaxation_time: Scalar
    state_size: ClassVar[int] = 2

    def __init__(self, deflection=1e-3, breakaway_ratio=0.5, relaxation_time=0.01):
        self.deflection = _f64(deflection)
        self.breakaway_ratio = _f64(breakaway_ratio)
        self.relaxation_time = _f64(relaxation_time)

    def force(self, mu, normal, velocity, state):
        return -(mu * normal / self.deflection)[:, None] * state

    def state_rate(self, velocity, state, contact):
        delta, rb = self.deflection, self.breakaway_ratio
        z2 = jnp.sum(state**2, axis=-1)
        # |z| with a finite derivative at z = 0 (every bristle starts there): the two-`where` guard.
        r = jnp.where(z2 > 0.0, jnp.sqrt(jnp.where(z2 > 0.0, z2, 1.0)), 0.0) / delta
        alpha = (jnp.maximum(r - rb, 0.0) / (1.0 - rb)) ** 2
        # alpha is zero wherever |z| < r_b δ, so the division is guarded by a positive floor.
        beta = alpha / jnp.maximum(z2, (rb * delta) ** 2 + 1e-300)
        vz = jnp.maximum(jnp.sum(velocity * state, axis=-1), 0.0)
        rate = velocity - (beta * vz)[:, None] * state
        # Off the ground the bristles carry no load and relax: a corner lands with an unloaded bristle,
        # and a fast-moving free corner does not make the ODE stiff.
        w = contact[:, None]
        return w * rate - (1.0 - w) * state / self.relaxation_time

    def check(self):
        _check(
            "foundation.friction.deflection", self.deflection, unit="m", low=0.0, low_open=True, symbol="δ"
        )
        _check(
            "foundation.friction.breakaway_ratio",
            self.breakaway_ratio,
            unit="-",
            low=0.0,
            high=1.0,
            high_open=True,
            symbol="r_b",
        )
        _check(
            "foundation.friction.relaxation_time",
            self.relaxation_time,
            unit="s",
            low=0.0,
            low_open=True,
            symbol="τ",
        )


# ------------------------------------------------------------------------------- foundation, rope, boom


class Foundation(eqx.Module):
    """Elastic, damped ground under the four bottom corners (paper §3, eqs. 3.1-3.3).

    - `stiffness`: k, vertical spring per corner [N/m].
    - `damping`: h, vertical damper per corner [N s/m].
    - `friction_coefficient`: μ [-].
    - `friction`: the friction law (default `RegularisedCoulomb(1e-3)`, see README "Friction laws").
    - `damping_onset`: p_0, the penetration over which the damper builds up [m] (our addition; 0 gives
      the paper's (3.1) exactly, whose force jumps to h dp/dt at touch-down).

    N_i = max(0, k p_i + h min(p_i/p_0, 1) dp_i/dt) for a corner below the ground by p_i > 0, else 0: the
    ground pushes, never pulls, and the force is continuous at touch-down.
    """

    stiffness: Scalar
    damping: Scalar
    friction_coefficient: Scalar
    friction: AbstractFrictionLaw
    damping_onset: Scalar

    def __init__(self, stiffness, damping, friction_coefficient, friction=None, damping_onset=1e-4):
        self.stiffness = _f64(stiffness)
        self.damping = _f64(damping)
        self.friction_coefficient = _f64(friction_coefficient)
        self.friction = RegularisedCoulomb(1e-3) if friction is None else friction
        self.damping_onset = _f64(damping_onset)

    def check(self):
        _check("foundation.stiffness", self.stiffness, unit="N/m", low=0.0, low_open=True, symbol="k")
        _check("foundation.damping", self.damping, unit="N s/m", low=0.0, symbol="h")
        _check("foundation.friction_coefficient", self.friction_coefficient, unit="-", low=0.0, symbol="μ")
        _check("foundation.damping_onset", self.damping_onset, unit="m", low=0.0, symbol="p_0")
        self.friction.check()


class Rope(eqx.Module):
    """Elastic, damped hoist rope, eq. (2.14); a slack rope carries no force and the rope never pushes.

    - `stiffness`: c_l, tension per metre of stretch [N/m].
    - `damping`: b_l, tension per metre per second of stretch rate [N s/m].
    - `attachment`: point B in the body frame ξηζ, measured from corner D [m]; on or inside the box.
    - `slack`: rope length at t = 0 minus the distance |AB| [m]; 0 means just taut.
    - `damping_onset`: δ_0, the stretch over which the damper builds up [m] (our addition; 0: the
      damper acts in full as soon as the rope is taut, and S jumps when a slack rope snaps taut).

    S = max(0, c_l δ + b_l min(δ/δ_0, 1) dδ/dt) for stretch δ = |AB| - l(t) > 0, else 0.
    """

    stiffness: Scalar
    damping: Scalar
    attachment: Vec3
    slack: Scalar
    damping_onset: Scalar

    def __init__(self, stiffness, damping, attachment, slack=0.0, damping_onset=1e-4):
        self.stiffness = _f64(stiffness)
        self.damping = _f64(damping)
        self.attachment = _f64(attachment)
        self.slack = _f64(slack)
        self.damping_onset = _f64(damping_onset)

    def check(self):
        _check("rope.stiffness", self.stiffness, unit="N/m", low=0.0, low_open=True, symbol="c_l")
        _check("rope.damping", self.damping, unit="N s/m", low=0.0, symbol="b_l")
        _check("rope.attachment", self.attachment, unit="m", shape=(3,), symbol="B")
        _check("rope.slack", self.slack, unit="m", low=0.0)
        _check("rope.damping_onset", self.damping_onset, unit="m", low=0.0, symbol="δ_0")


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

    speed: Scalar

    def __init__(self, speed):
        self.speed = _f64(speed)

    def shortening(self, t):
        return self.speed * t

    def rate(self, t):
        return self.speed * jnp.ones_like(t)

    def check(self):
        _check("hoist.speed", self.speed, unit="m/s", low=0.0, symbol="v_l")


class RampedHoist(AbstractHoistLaw):
    """Hoist speed rising smoothly (C¹, smoothstep) from 0 to v_l over `ramp_time`, then falling to 0
    so that the hoist stops after taking in `travel` metres of rope.

    - `speed`: v_l, the cruising speed [m/s].
    - `ramp_time`: duration of the speed-up and of the slow-down [s] (0 gives a step in speed).
    - `travel`: total rope taken in [m] (`inf`: never stops); needs travel >= v_l ramp_time.
    """

    speed: Scalar
    ramp_time: Scalar
    travel: Scalar

    def __init__(self, speed, ramp_time=0.0, travel=float("inf")):
        self.speed = _f64(speed)
        self.ramp_time = _f64(ramp_time)
        self.travel = _f64(travel)

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
        _check("hoist.speed", self.speed, unit="m/s", low=0.0, symbol="v_l")
        _check("hoist.ramp_time", self.ramp_time, unit="s", low=0.0)
        _check("hoist.travel", self.travel, unit="m", low=0.0, allow_posinf=True)
        v, T, L = (_concrete(x) for x in (self.speed, self.ramp_time, self.travel))
        if v is not None and T is not None and L is not None and np.any(L < v * T):
            raise ScenarioError(
                f"hoist.travel must be >= speed * ramp_time = {_show(v * T)} m, got {_show(L)} m"
            )


class ProfileHoist(AbstractHoistLaw):
    """A user-supplied smooth shortening profile s(t) [m] (a JAX-traceable function with s(0) = 0).

    - `profile`: callable t [s] -> s(t) [m]; its rate comes from forward-mode differentiation.
    """

    profile: Callable = eqx.field(static=True)

    def shortening(self, t):
        return self.profile(t)


class Boom(eqx.Module):
    """The boom tip as a particle on three axis-aligned springs (paper eqs. 2.12-2.13).

    - `tip_position`: A, where the tip rests at t = 0 under its own weight with the rope slack [m].
    - `tip_mass`: m_0 [kg]; its weight G_0 = m_0 g acts on the tip.
    - `stiffness`: (k_X, k_Y, k_Z), equivalent boom stiffnesses [N/m].
    - `damping`: (c_X, c_Y, c_Z), equivalent boom damping [N s/m] (our addition; 0 is the paper's model).
    """

    tip_position: Vec3
    tip_mass: Scalar
    stiffness: Vec3
    damping: Vec3

    def __init__(self, tip_position, tip_mass, stiffness, damping=(0.0, 0.0, 0.0)):
        self.tip_position = _f64(tip_position)
        self.tip_mass = _f64(tip_mass)
        self.stiffness = _f64(stiffness) * jnp.ones(3)
        self.damping = _f64(damping) * jnp.ones(3)

    def check(self):
        _check("boom.tip_position", self.tip_position, unit="m", shape=(3,), symbol="A")
        _check("boom.tip_mass", self.tip_mass, unit="kg", low=0.0, low_open=True, symbol="m_0")
        _check(
            "boom.stiffness",
            self.stiffness,
            unit="N/m",
            shape=(3,),
            low=0.0,
            low_open=True,
            symbol="k_X, k_Y, k_Z",
        )
        _check("boom.damping", self.damping, unit="N s/m", shape=(3,), low=0.0)


# ---------------------------------------------------------------------------------------- scenario


class Scenario(eqx.Module):
    """Everything that defines one lift. A pytree: change a leaf with `eqx.tree_at` or `Scenario.replace`.

    - `load`, `foundation`, `rope`, `hoist`, `boom`: see their classes.
    - `gravity`: g [m/s²].
    - `name`: a label (static).
    - `t1`: default end time of a simulation [s] (static).
    - `description`: free text (static).
    """

    load: Load
    foundation: Foundation
    rope: Rope
    hoist: AbstractHoistLaw
    boom: Boom
    gravity: Scalar
    name: str = eqx.field(static=True)
    t1: float = eqx.field(static=True)
    description: str = eqx.field(static=True)

    def __init__(
        self, load, foundation, rope, hoist, boom, gravity=9.81, name="custom", t1=10.0, description=""
    ):
        require_x64()
        self.load = load
        self.foundation = foundation
        self.rope = rope
        self.hoist = hoist
        self.boom = boom
        self.gravity = _f64(gravity)
        self.name = name
        self.t1 = float(t1)
        self.description = str(description)

    def __check_init__(self):
        self.check()

    def check(self) -> None:
        """Raise `ScenarioError` naming the first invalid field (concrete leaves only).

        Besides each field's range, shape and dtype, the box geometry (C inside the box, B on or in it) and a
        plausibility check of physically absurd but finite values: every nonzero parameter within
        `PLAUSIBLE_MAGNITUDE` (1e-100 to 1e100 in SI units), and the static sinking of the ground under the
        load's weight, m g / (4 k), less than the box height c (else the initial static state is absurd:
        the box would rest below the ground).
        """
        self.load.check()
        self.foundation.check()
        self.rope.check()
        self.hoist.check()
        self.boom.check()
        _check("gravity", self.gravity, unit="m/s^2", low=0.0, symbol="g")
        if not (np.isfinite(self.t1) and self.t1 > 0):
            raise ScenarioError(f"t1 must be a positive finite time [s], got {self.t1}")
        s, b = _concrete(self.load.size), _concrete(self.rope.attachment)
        if s is not None and b is not None and np.any((b < -1e-12) | (b > s + 1e-12)):
            raise ScenarioError(
                f"rope.attachment (B) must lie on or inside the box 0 <= B <= size = {_show(s)} m, "
                f"got {_show(b)} m"
            )
        m, g, k = (_concrete(x) for x in (self.load.mass, self.gravity, self.foundation.stiffness))
        if s is not None and m is not None and g is not None and k is not None:
            with np.errstate(all="ignore"):
                sink = m * g / (4.0 * k)
            c = s[..., 2]
            if np.any(~np.isfinite(sink) | (sink >= c)):
                raise ScenarioError(
                    f"foundation.stiffness (k) = {_show(k)} N/m is not plausible for load.mass m = "
                    f"{_show(m)} kg: the load's weight would press the ground in by m g / (4 k) = "
                    f"{_show(sink)} m, at least the box height c = {_show(c)} m (stiffen the ground or "
                    f"lighten the load)"
                )

    def replace(self, **leaves) -> Scenario:
        """A copy with leaves replaced by dotted path.

        **Arguments**
        - `leaves`: `{dotted path: value}`, e.g. `replace(**{"foundation.friction_coefficient": 0.3})`;
          a value has the leaf's shape or broadcasts to it (a number for a 3-vector), in the leaf's unit.

        **Returns** the new `Scenario` (not checked: `simulate` and `check()` do that).

        **Raises** `ScenarioError` naming the path for a field that does not exist (with the closest
        field's name), a static setting (`t1`, `name`), a value that is not numeric or whose shape does
        not fit the leaf.
        """
        out = self
        for path, value in leaves.items():
            old = get_leaf(out, path)
            out = eqx.tree_at(leaf_getter(path), out, _leaf_value(path, value, np.shape(old)))
        return out


def _leaf_value(path: str, value, shape: tuple) -> Array:
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
    return jnp.broadcast_to(_f64(value), shape)


def leaf_getter(path: str) -> Callable[[Scenario], Array]:
    """`"rope.stiffness"` -> `lambda s: s.rope.stiffness`, checking that the path names a float leaf."""
    parts = path.split(".")

    def get(s):
        for p in parts:
            s = getattr(s, p)
        return s

    return get


_STATIC_HINTS = {
    "t1": "the scenario's end time, a static setting: give it with --t1 T on the command line or "
    "simulate(scenario, t1=T), or as t1 in the scenario file",
    "name": "a static label (the scenario file's name)",
    "description": "static free text (the scenario file's description)",
}


def get_leaf(scenario: Scenario, path: str) -> Array:
    """The float leaf at a dotted path such as `"rope.stiffness"`.

    **Arguments**
    - `scenario`: the scenario (or any of its parts).
    - `path`: dotted field names, e.g. `foundation.friction.regularisation_velocity`.

    **Returns** the leaf (an array).

    **Raises** `ScenarioError` naming the path if a part is no field of its parent (with the closest
    field's name), is a static setting (`t1`, `name`, `description`) or reaches past a leaf
    (`load.mass.real`), or if the path ends at a table rather than a float leaf.
    """
    import difflib

    obj = scenario
    parts = str(path).split(".")
    for i, p in enumerate(parts):
        where = ".".join(parts[:i]) or "scenario"
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
        obj = getattr(obj, p)
    if not isinstance(obj, jax.Array | np.ndarray):
        raise ScenarioError(f"{path!r} is not a float leaf (got {type(obj).__name__})")
    return obj  # pyright: ignore[reportReturnType]  # np.ndarray leaves (host arrays) are accepted too
