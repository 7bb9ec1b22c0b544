"""Mechanical energy of the elastic model, for the balance

    E(t) - E(0) = W_hoist(t) - D_damping(t) - W_friction(t),

where the three integrals are carried in the state (`elastic.State`). With `BristleFriction`,
W_friction also holds the elastic energy stored in the bristles (at most ½ μ N_i δ per corner).
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

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


BALANCE_BOUND = 0.05
"""The a-posteriori energy check: a solve whose `relative_balance_residual` exceeds this bound gets the
status `SolveStatus.ENERGY_BALANCE`. Healthy solves stay well below it (measured with
`experiments/figures/energy_bound.py`: the default Rosenbrock-W solver at most 3.5e-4 on the presets and
2.8e-3 on 48 random plausible scenarios around paper-4.2; at rtol 1e-2 at most 7.3e-3 on the presets;
Tsit5 below 1e-7); a broken solve that "succeeds" with a rope that carries no load opens the balance by 0.91
(paper-4.2 with rope.stiffness = 1e16 N/m, the default solver)."""

BALANCE_FLOOR = 1e-9
"""The absolute floor of the check's scale, relative to the largest mechanical energy |E(t)| [-]: it
keeps a solve in which nothing moves (residual and scale both at round-off level) from tripping it."""


def relative_balance_residual(
    mechanical: Float[ArrayLike, "*batch n_t"],
    hoist_work: Float[ArrayLike, "*batch n_t"],
    damping_loss: Float[ArrayLike, "*batch n_t"],
    friction_work: Float[ArrayLike, "*batch n_t"],
    xp=jnp,
) -> Float[ArrayLike, "*batch"]:
    """The energy balance's residual relative to the energy that flowed, over the saved times:

        max_t |r(t)| / (max_t [|ΔE| + |ΔW_hoist| + |ΔD_damping| + |ΔW_friction|](t) + floor),

    r(t) = ΔE(t) - [ΔW_hoist - ΔD_damping - ΔW_friction](t), every Δ taken from the first saved time,
    floor = `BALANCE_FLOOR` max_t |E(t)|. It lies in [0, 1] (0: the balance closes; near 1: the solve
    created or lost energy of the size of everything that happened), NaN where a value is not finite.
    Cheap: it reads only the saved energies and the three integrals carried in the state.

    **Arguments**
    - `mechanical`: E(t) [J] at the saved times (last axis).
    - `hoist_work`, `damping_loss`, `friction_work`: the accumulated integrals [J].
    - `xp`: `jax.numpy` (inside a compiled solve) or `numpy`.

    **Returns** the relative residual [-], one per leading batch index.
    """
    terms = [xp.asarray(x) for x in (mechanical, hoist_work, damping_loss, friction_work)]
    d = [x - x[..., :1] for x in terms]
    residual = d[0] - (d[1] - d[2] - d[3])
    scale = xp.max(sum(xp.abs(x) for x in d), axis=-1)
    floor = BALANCE_FLOOR * xp.max(xp.abs(terms[0]), axis=-1)
    den = scale + floor
    num = xp.max(xp.abs(residual), axis=-1)
    # a solve in which no energy at all is present (den == 0) closes its balance trivially
    return xp.where(den > 0, num / xp.where(den > 0, den, 1.0), xp.where(num == 0, 0.0, xp.nan))
