"""`Trajectory`: the outputs of one solve at the saved times, the one result type of `simulate` (the
rigid-ground model's `RigidTrajectory` is a subclass with its impact losses and phase log)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._errors import SolveStatus
from .._physics.elastic import State
from .._physics.energy import Energy, relative_balance_residual


class Trajectory(eqx.Module):
    """The outputs of one solve at the saved times `ts` (leading axis n_t; in a vmap, a batch axis first).

    - `ts`: saved times [s].
    - `position`, `velocity`: mass centre C in world axes [m], [m/s].
    - `euler`: (φ, ψ, ϑ) [rad], R = R_Z(ψ) R_Y(ϑ) R_X(φ); φ and ψ unwrapped along time.
    - `angular_velocity`: ω in body axes ξηζ [rad/s].
    - `corners`: D, E, F, H in world axes [m], shape (n_t, 4, 3).
    - `normal_forces`: N_i [N], (n_t, 4); `friction_forces`: T_i in world axes [N], (n_t, 4, 3).
    - `ground_reaction`: R = Σ N_i [N]; `rope_tension`: S [N].
    - `tip_position`: boom tip A [m].
    - `energy`: `Energy` terms [J]; `hoist_work`, `damping_loss`, `friction_work`: accumulated [J].
    - `states`: the raw `State` at each saved time.
    - `status`: a `SolveStatus` code (0 = ok; `ENERGY_BALANCE` where the solver succeeded but the energy
      balance does not close, see `energy_check`); `num_accepted_steps`, `num_rejected_steps`.

    The rigid-ground model's `RigidTrajectory` is a `Trajectory` with the same fields and three more
    (`impact_loss`, `phase_index` and the phase log `phases`), so code written for a `Trajectory` (plots,
    observables, saving) reads either.
    """

    ts: Float[Array, " n_t"]
    position: Float[Array, "n_t 3"]
    velocity: Float[Array, "n_t 3"]
    euler: Float[Array, "n_t 3"]
    angular_velocity: Float[Array, "n_t 3"]
    corners: Float[Array, "n_t 4 3"]
    normal_forces: Float[Array, "n_t 4"]
    friction_forces: Float[Array, "n_t 4 3"]
    ground_reaction: Float[Array, " n_t"]
    rope_tension: Float[Array, " n_t"]
    tip_position: Float[Array, "n_t 3"]
    energy: Energy
    hoist_work: Float[Array, " n_t"]
    damping_loss: Float[Array, " n_t"]
    friction_work: Float[Array, " n_t"]
    states: State
    status: Int[Array, ""]
    num_accepted_steps: Int[Array, ""]
    num_rejected_steps: Int[Array, ""]

    @property
    def ok(self):
        """True where the solve reached t1 with a finite state and a closed energy balance."""
        return self.status == SolveStatus.OK

    def energy_residual(self) -> Float[Array, "*batch n_t"]:
        """E(t) - E(0) - [W_hoist - D_damping - W_friction](t) [J]: zero up to the solver error."""
        mech = self.energy.mechanical
        supplied = self.hoist_work - self.damping_loss - self.friction_work
        return (mech - mech[..., :1]) - (supplied - supplied[..., :1])

    def energy_check(self) -> Float[Array, "*batch"]:
        """The energy balance's largest residual relative to the energy that flowed [-]
        (`jaxhoist._physics.energy.relative_balance_residual`): what the solve compares with
        `BALANCE_BOUND` to set `SolveStatus.ENERGY_BALANCE`."""
        terms = (self.energy.mechanical, self.hoist_work, self.damping_loss, self.friction_work)
        return jnp.asarray(relative_balance_residual(*terms))
