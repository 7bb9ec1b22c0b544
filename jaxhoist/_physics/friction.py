"""Friction laws of the ground contact (paper eq. 3.3): the interface and the regularised Coulomb and
bristle laws."""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._typing import Scalar
from .checks import check_value, f64, plausible
from .paths import unit

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

    regularisation_velocity: Scalar = eqx.field(
        metadata=unit("m/s")
        | plausible(1e-7, 0.1, "beyond 0.1 m/s friction is viscous at working speeds; below 1e-7 too stiff")
    )
    state_size: ClassVar[int] = 0

    def __init__(self, regularisation_velocity=1e-3):
        self.regularisation_velocity = f64(regularisation_velocity)

    def force(self, mu, normal, velocity, state):
        eps = self.regularisation_velocity
        speed = jnp.sqrt(jnp.sum(velocity**2, axis=-1) + eps**2)
        return -(mu * normal / speed)[:, None] * velocity

    def state_rate(self, velocity, state, contact):
        return state

    def check(self):
        check_value(
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

    deflection: Scalar = eqx.field(
        metadata=unit("m") | plausible(1e-7, 0.1, "a contact's elastic pre-sliding: micrometres to mm")
    )
    breakaway_ratio: Scalar = eqx.field(metadata=unit("-"))
    relaxation_time: Scalar = eqx.field(
        metadata=unit("s") | plausible(1e-5, 100.0, "a lifted corner's bristle relaxes within the lift")
    )
    state_size: ClassVar[int] = 2

    def __init__(self, deflection=1e-3, breakaway_ratio=0.5, relaxation_time=0.01):
        self.deflection = f64(deflection)
        self.breakaway_ratio = f64(breakaway_ratio)
        self.relaxation_time = f64(relaxation_time)

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
        check_value(
            "foundation.friction.deflection", self.deflection, unit="m", low=0.0, low_open=True, symbol="δ"
        )
        check_value(
            "foundation.friction.breakaway_ratio",
            self.breakaway_ratio,
            unit="-",
            low=0.0,
            high=1.0,
            high_open=True,
            symbol="r_b",
        )
        check_value(
            "foundation.friction.relaxation_time",
            self.relaxation_time,
            unit="s",
            low=0.0,
            low_open=True,
            symbol="τ",
        )
