"""The paper's §3 model: a rigid box on four vertical spring-dampers, pulled by an elastic rope from a
sprung boom tip. `vector_field(t, y, args)` is the pure right-hand side dy/dt; `ElasticFoundation` names the
model as a choice of `simulate` (`AbstractModel` is the base of both models).

Newton-Euler form of (2.10)-(2.13): translation of the mass centre C in world axes, rotation in body
axes (J dω/dt + ω x Jω = M_C), the boom tip as a particle. The paper derives the same equations by
Lagrange's method (3.4); Newton-Euler with a quaternion avoids the Euler-angle singularity.
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._typing import CornerVecs, Quat, Rot33, Scalar, Vec3
from . import forces, kinematics
from .params import Scenario


class State(eqx.Module):
    """The state y of the elastic model (all world-axis quantities in the fixed frame XYZ).

    - `position`, `velocity`: mass centre C [m], [m/s].
    - `quaternion`: orientation (w, x, y, z), body -> world [-].
    - `angular_velocity`: ω in body axes ξηζ [rad/s].
    - `tip_position`, `tip_velocity`: boom tip A [m], [m/s].
    - `friction_state`: the friction law's per-corner state, shape (4, n) (bristle deflection [m]).
    - `hoist_work`: ∫ S ds/dt dt, work done by the hoist [J].
    - `damping_loss`: energy lost in the ground, rope and boom dampers [J].
    - `friction_work`: -∫ Σ T_i·v_i dt, work taken out by friction [J].
    """

    position: Vec3
    velocity: Vec3
    quaternion: Quat
    angular_velocity: Vec3
    tip_position: Vec3
    tip_velocity: Vec3
    friction_state: Float[Array, "4 n"]
    hoist_work: Scalar
    damping_loss: Scalar
    friction_work: Scalar


class Constants(eqx.Module):
    """Quantities derived once per solve from the scenario and the initial state.

    - `rope_length`: l0 = l(0), the unstretched rope length at t = 0 [m].
    - `tip_rest`: where the boom springs are unstretched [m] (A raised by m_0 g / k).
    - `inertia`, `inertia_inv`: J about C in body axes [kg m²] and its inverse.
    - `corners_rel`, `attachment_rel`: body offsets of D, E, F, H and of B from C [m].
    """

    rope_length: Scalar
    tip_rest: Vec3
    inertia: Rot33
    inertia_inv: Rot33
    corners_rel: CornerVecs
    attachment_rel: Vec3


def constants(scenario: Scenario, rope_length: Scalar) -> Constants:
    """Build `Constants` for a scenario whose rope is l0 = `rope_length` long at t = 0."""
    load, boom = scenario.load, scenario.boom
    J = load.inertia_tensor()
    sag = boom.tip_mass * scenario.gravity / boom.stiffness[2]
    return Constants(
        rope_length=rope_length,
        tip_rest=boom.tip_position + jnp.array([0.0, 0.0, 1.0]) * sag,
        inertia=J,
        inertia_inv=jnp.linalg.inv(J),
        corners_rel=kinematics.bottom_corners(load.size) - load.mass_centre,
        attachment_rel=scenario.rope.attachment - load.mass_centre,
    )


class Snapshot(eqx.Module):
    """Every force and kinematic quantity of the model at one instant (what the vector field and the
    outputs share). World axes unless stated.

    - `rotation`: R, body -> world.
    - `corners`, `corner_velocity`: D, E, F, H [m], [m/s].
    - `normal`: N_i [N]; `friction`: T_i (horizontal, Z component 0) [N].
    - `rope_point`: B [m]; `rope_tension`: S [N]; `rope_direction`: unit vector from B towards A.
    - `stretch`: δ = |AB| - l(t) [m]; `hoist_rate`: ds/dt [m/s].
    - `damping_rate`, `friction_rate`, `hoist_power`: [W] (the energy integrands).
    """

    rotation: Rot33
    corners: CornerVecs
    corner_velocity: CornerVecs
    normal: Float[Array, "4"]
    friction: CornerVecs
    rope_point: Vec3
    rope_tension: Scalar
    rope_direction: Vec3
    stretch: Scalar
    hoist_rate: Scalar
    damping_rate: Scalar
    friction_rate: Scalar
    hoist_power: Scalar


def rope_pull(t: Scalar, y: State, R: Rot33, scenario: Scenario, c: Constants):
    """The rope, eq. (2.14) with l(t) = l0 - s(t), for any model whose state has the body's and the boom
    tip's motion (the elastic and the rigid model share it).

    **Returns** `(B, e, δ, ds/dt, S, loss)`: rope point B [m], unit vector e from B towards A, stretch
    δ = |AB| - l(t) [m], hoist rate [m/s], tension S [N] and the rope damper's loss [W].
    """
    rope = scenario.rope
    B = kinematics.points_world(y.position, R, c.attachment_rel[None])[0]
    v_B = kinematics.points_velocity(y.velocity, R, y.angular_velocity, c.attachment_rel[None])[0]
    AB = y.tip_position - B
    L = forces.safe_norm(AB)
    e = AB / jnp.maximum(L, 1e-12)
    L_dot = jnp.dot(y.tip_velocity - v_B, e)
    s_dot = scenario.hoist.rate(t)
    stretch = L - (c.rope_length - scenario.hoist.shortening(t))
    S, loss = forces.rope_tension(stretch, L_dot + s_dot, rope.stiffness, rope.damping, rope.damping_onset)
    return B, e, stretch, s_dot, S, loss


def snapshot(t: Scalar, y: State, scenario: Scenario, c: Constants) -> Snapshot:
    """Evaluate all contact, rope and boom forces at (t, y)."""
    fnd = scenario.foundation
    R = kinematics.quat_to_matrix(y.quaternion)
    omega = y.angular_velocity

    # Corners and the foundation, eqs. (3.1)-(3.3).
    corners = kinematics.points_world(y.position, R, c.corners_rel)
    corner_vel = kinematics.points_velocity(y.velocity, R, omega, c.corners_rel)
    N_i, ground_loss = forces.ground_normal(
        -corners[:, 2], -corner_vel[:, 2], fnd.stiffness, fnd.damping, fnd.damping_onset
    )
    T_h = fnd.friction.force(fnd.friction_coefficient, N_i, corner_vel[:, :2], y.friction_state)
    T_i = jnp.concatenate([T_h, jnp.zeros((4, 1))], axis=1)

    B, e, stretch, s_dot, S, rope_loss = rope_pull(t, y, R, scenario, c)

    _, boom_loss = forces.boom_force(
        y.tip_position - c.tip_rest, y.tip_velocity, scenario.boom.stiffness, scenario.boom.damping
    )
    return Snapshot(
        rotation=R,
        corners=corners,
        corner_velocity=corner_vel,
        normal=N_i,
        friction=T_i,
        rope_point=B,
        rope_tension=S,
        rope_direction=e,
        stretch=stretch,
        hoist_rate=s_dot,
        damping_rate=ground_loss + rope_loss + boom_loss,
        friction_rate=-jnp.sum(T_h * corner_vel[:, :2]),
        hoist_power=S * s_dot,
    )


def _sum_corners(x: Float[Array, "4 ..."]) -> Float[Array, "..."]:
    """Σ over the four corners, written out: in a vmapped scan XLA fuses these additions with their
    neighbours, where `jnp.sum(x, axis=0)` is a separate reduction kernel per evaluation (5-14 % of a
    fixed step, `experiments/benchmarks/bench_vector_field.py`; docs/performance.md)."""
    return x[0] + x[1] + x[2] + x[3]


def vector_field(t: Scalar, y: State, args: tuple[Scenario, Constants]) -> State:
    """dy/dt of the elastic-foundation model (pure; `args = (scenario, constants)`)."""
    scenario, c = args
    load, boom, g = scenario.load, scenario.boom, scenario.gravity
    snap = snapshot(t, y, scenario, c)
    R, omega = snap.rotation, y.angular_velocity
    z_hat = jnp.array([0.0, 0.0, 1.0])

    # Forces on the load, eq. (2.11): ground reactions at the corners, rope S at B, weight G at C.
    F_corner = snap.friction + snap.normal[:, None] * z_hat
    F_rope = snap.rope_tension * snap.rope_direction
    force = _sum_corners(F_corner) + F_rope - load.mass * g * z_hat
    # Moments about C in body axes: ρ x (Rᵀ F).
    moment = _sum_corners(jnp.cross(c.corners_rel, F_corner @ R)) + jnp.cross(c.attachment_rel, R.T @ F_rope)
    omega_dot = c.inertia_inv @ (moment - jnp.cross(omega, c.inertia @ omega))

    # Boom tip, eq. (2.13).
    F_boom, _ = forces.boom_force(y.tip_position - c.tip_rest, y.tip_velocity, boom.stiffness, boom.damping)
    tip_acc = (F_boom - F_rope) / boom.tip_mass - g * z_hat

    return State(
        position=y.velocity,
        velocity=force / load.mass,
        quaternion=kinematics.quat_rate(y.quaternion, omega),
        angular_velocity=omega_dot,
        tip_position=y.tip_velocity,
        tip_velocity=tip_acc,
        friction_state=scenario.foundation.friction.state_rate(
            snap.corner_velocity[:, :2],
            y.friction_state,
            forces.onset_ramp(-snap.corners[:, 2], scenario.foundation.damping_onset),
        ),
        hoist_work=snap.hoist_power,
        damping_loss=snap.damping_rate,
        friction_work=snap.friction_rate,
    )


# ------------------------------------------------------------------------------------------------ models


class AbstractModel(eqx.Module):
    """A model of the ground contact that `simulate` can solve."""


class ElasticFoundation(AbstractModel):
    """The paper's §3 model: the box on four one-sided corner spring-dampers with friction; solved by
    `diffrax.diffeqsolve` (differentiable, vmappable)."""
