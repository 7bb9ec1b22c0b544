"""Mechanical energy of the elastic model, for the balance

    E(t) - E(0) = W_hoist(t) - D_damping(t) - W_friction(t),

where the three integrals are carried in the state (`elastic.State`). With `BristleFriction`,
W_friction also holds the elastic energy stored in the bristles (at most ½ μ N_i δ per corner).
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._typing import Scalar
from .elastic import Constants, Snapshot, State
from .params import Scenario


class Energy(eqx.Module):
    """Energy terms at one instant [J].

    - `kinetic`: ½ m |v_C|² + ½ ωᵀ J ω + ½ m_0 |v_A|².
    - `potential`: m g Z_C + m_0 g Z_A.
    - `ground_spring`: ½ k Σ p_i² over corners below the ground.
    - `rope_spring`: ½ c_l δ² while the rope is stretched.
    - `boom_spring`: ½ Σ k_j ΔX_j² of the boom tip.
    """

    kinetic: Scalar
    potential: Scalar
    ground_spring: Scalar
    rope_spring: Scalar
    boom_spring: Scalar

    @property
    def mechanical(self) -> Float[Array, "*batch"]:
        return self.kinetic + self.potential + self.ground_spring + self.rope_spring + self.boom_spring


def energy(y: State, snap: Snapshot, scenario: Scenario, c: Constants) -> Energy:
    """The energy terms of state `y` (with its `Snapshot`)."""
    load, boom, g = scenario.load, scenario.boom, scenario.gravity
    w = y.angular_velocity
    p = jnp.maximum(-snap.corners[:, 2], 0.0)
    stretch = jnp.maximum(snap.stretch, 0.0)
    dx = y.tip_position - c.tip_rest
    return Energy(
        kinetic=0.5 * load.mass * jnp.sum(y.velocity**2)
        + 0.5 * w @ c.inertia @ w
        + 0.5 * boom.tip_mass * jnp.sum(y.tip_velocity**2),
        potential=g * (load.mass * y.position[2] + boom.tip_mass * y.tip_position[2]),
        ground_spring=0.5 * scenario.foundation.stiffness * jnp.sum(p**2),
        rope_spring=0.5 * scenario.rope.stiffness * stretch**2,
        boom_spring=0.5 * jnp.sum(boom.stiffness * dx**2),
    )


def balance_residual(e0: Energy, e1: Energy, y1: State, y0: State) -> Scalar:
    """[E(t1) - E(t0)] - [ΔW_hoist - ΔD_damping - ΔW_friction] [J]; zero up to solver error."""
    supplied = (
        (y1.hoist_work - y0.hoist_work)
        - (y1.damping_loss - y0.damping_loss)
        - (y1.friction_work - y0.friction_work)
    )
    return (e1.mechanical - e0.mechanical) - supplied
