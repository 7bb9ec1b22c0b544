"""The rigid model's dynamics in one phase (paper §2, pure JAX; `physics.rigid` holds the phase, the
settings, the loads and the contact matrices, and re-exports everything here): the contact forces of a
phase (`contact_dynamics`: rest, motion, the taut or slack inextensible rope), the vector field, the
guards that end a phase (`raw_guards`, `event_condition`), impulse responses of impacts and rope jerks,
energies and the saved outputs."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..._typing import CornerVecs, PerCorner, Scalar
from .. import kinematics, statics
from ..elastic import Constants, State
from ..energy import Energy
from ..params import Scenario
from .contact import (
    FREE,
    ROPE_SLACK,
    ROPE_TAUT,
    SLIDE,
    STICK,
    Loads,
    Phase,
    Settings,
    inextensible_loads,
    loads,
    maps,
    mass_inverse,
    rest_rope_tension,
    rope_accel_target,
    scales,
    slip_directions,
    solve_contact_system,
    solve_rope_contact_system,
    tip_free_accel,
    with_tension,
)


class Contact(eqx.Module):
    """The dynamics of one instant in a given `Phase`. World axes.

    - `accel`: (dv_C/dt, dω/dt) with dω/dt in body axes.
    - `force`: ground force on each corner (N_i ẑ + T_i) [N], (4, 3); for a rest phase the normal parts are
      the least-norm nonnegative loads (`statics.nonnegative_corner_loads`).
    - `corner_accel`: D, E, F, H accelerations [m/s²].
    - `slip_direction`: t̂_i used by sliding corners (4, 2).
    - `loads`: the `Loads` of the instant.
    """

    accel: Float[Array, "6"]
    force: CornerVecs
    corner_accel: CornerVecs
    slip_direction: Float[Array, "4 2"]
    loads: Loads


def rest_friction(ld: Loads, c: Constants, scenario: Scenario) -> Float[Array, "4 2"]:
    """Corner friction forces (world X, Y) [N] of a load resting on all four corners: the minimum-norm
    distribution balancing the rope's horizontal pull, T_i = -S_h/4 + α ẑ × (r_i - r̄), with α set by the
    moment of S_h about the corners' centroid r̄ (the statically indeterminate part takes the least norm)."""
    F = ld.rope_tension * ld.rope_direction
    r = ld.corners[:, :2]
    rbar = jnp.mean(r, axis=0)
    d = r - rbar
    arm = ld.rope_point[:2] - rbar
    M = arm[0] * F[1] - arm[1] * F[0]
    alpha = -M / jnp.sum(d**2)
    return -0.25 * F[None, :2] + alpha * jnp.stack([-d[:, 1], d[:, 0]], axis=1)


def rest_loads(ld: Loads, scenario: Scenario, phase: Phase, settings: Settings) -> Loads:
    """`ld` of a load held fixed, with the taut inextensible rope's tension (if any) applied."""
    taut = phase.rope == ROPE_TAUT
    return with_tension(ld, rest_rope_tension(ld, scenario, settings), taut)


def rest_contact_rope(
    ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings
) -> Contact:
    return rest_contact(rest_loads(ld, scenario, phase, settings), scenario, c, phase, settings)


def rest_contact(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings) -> Contact:
    # Held fixed: zero acceleration; the corner loads of the linear law (2.3), made nonnegative.
    S_body = ld.rotation.T @ (ld.rope_tension * ld.rope_direction)
    st = statics.rest_statics_loads(scenario, S_body)
    F = jnp.concatenate([rest_friction(ld, c, scenario), st[:, None]], axis=1)
    return Contact(
        accel=jnp.zeros(6),
        force=F,
        corner_accel=jnp.zeros((4, 3)),
        slip_direction=jnp.zeros((4, 2)),
        loads=ld,
    )


def motion_contact_rope(
    ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings
) -> Contact:
    return jax.lax.cond(
        phase.rope == ROPE_TAUT, motion_contact_taut, motion_contact_free, ld, scenario, c, phase, settings
    )


def contact_problem(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings):
    """M⁻¹, the sliding directions t̂_i, the force maps P_i and row selectors of `_maps`, and the corner
    accelerations the contact forces must add (Baumgarte target minus the unconstrained ones)."""
    Minv = mass_inverse(scenario, c)
    tdir = slip_directions(ld.corner_velocity, phase.slip_hint, settings.slip_velocity)
    P, s_rows = maps(phase.contact, tdir, scenario.foundation.friction_coefficient)
    beta = settings.baumgarte
    z_only = jnp.array([0.0, 0.0, 1.0])
    a_free = jnp.einsum("kij,j->ki", ld.jacobians, Minv @ ld.generalised_force) + ld.bias
    a_target = -2.0 * beta * ld.corner_velocity - beta**2 * ld.corners[:, 2:3] * z_only
    return Minv, tdir, P, s_rows, a_target - a_free


def contact_from_multipliers(ld: Loads, Minv, tdir, P, lam) -> Contact:
    """Corner forces F_i = P_i λ_i and the resulting body and corner accelerations."""
    F = jnp.einsum("kij,kj->ki", P, lam.reshape(4, 3))
    accel = Minv @ (ld.generalised_force + jnp.einsum("kij,ki->j", ld.jacobians, F))
    corner_accel = jnp.einsum("kij,j->ki", ld.jacobians, accel) + ld.bias
    return Contact(accel=accel, force=F, corner_accel=corner_accel, slip_direction=tdir, loads=ld)


def motion_contact_free(
    ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings
) -> Contact:
    Minv, tdir, P, s_rows, target = contact_problem(ld, scenario, c, phase, settings)
    lam = solve_contact_system(ld.jacobians, Minv, P, s_rows, target, scenario.load.mass, settings.rcond)
    return contact_from_multipliers(ld, Minv, tdir, P, lam)


def motion_contact_taut(
    ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings
) -> Contact:
    """The moving load with a taut inextensible rope: unknowns λ (12) and the tension S, from "constrained
    corner accelerations vanish" (Baumgarte-stabilised) and d²|AB|/dt² = `rope_accel_target`, with the
    boom tip's acceleration (2.13) m_0 a_A = boom force - S e - m_0 g."""
    Minv, tdir, P, s_rows, target = contact_problem(ld, scenario, c, phase, settings)
    e = ld.rope_direction
    a_B_free = ld.rope_jacobian @ (Minv @ ld.generalised_force) + ld.rope_bias
    rhs_s = (
        jnp.dot(e, tip_free_accel(ld, scenario))
        - jnp.dot(e, a_B_free)
        + ld.rope_curvature
        - rope_accel_target(ld, settings)
    )
    lam, S = solve_rope_contact_system(
        ld.jacobians,
        Minv,
        P,
        s_rows,
        target,
        ld.rope_generalised,
        scenario.boom.tip_mass,
        rhs_s,
        scenario.load.mass,
        settings.rcond,
    )
    return contact_from_multipliers(with_tension(ld, S, True), Minv, tdir, P, lam)


def contact_dynamics(
    t: Scalar,
    y: State,
    scenario: Scenario,
    c: Constants,
    phase: Phase,
    settings: Settings,
    inextensible: bool = False,
) -> Contact:
    """Contact forces and accelerations of the load in the contact configuration `phase`. With
    `inextensible` (a Python bool: the rope model, fixed for a whole solve) the rope is the constraint
    (2.15), taut or slack by `phase.rope`, and a taut rope's tension is solved together with the contact
    forces (`Contact.loads` carries it); without, the elastic rope (2.14)."""
    ld = loads(t, y, scenario, c)
    if inextensible:
        return contact_rope(t, y, ld, scenario, c, phase, settings)
    return contact_elastic(t, y, ld, scenario, c, phase, settings)


def contact_elastic(t, y, ld, scenario, c, phase, settings) -> Contact:
    return jax.lax.cond(phase.rest, rest_contact, motion_contact_free, ld, scenario, c, phase, settings)


def contact_rope(t, y, ld, scenario, c, phase, settings) -> Contact:
    ld = inextensible_loads(t, y, ld, scenario, c)
    return jax.lax.cond(phase.rest, rest_contact_rope, motion_contact_rope, ld, scenario, c, phase, settings)


def unpack(args):
    """`args = (scenario, constants, phase, settings[, inextensible])` -> the five, inextensible a bool."""
    scenario, c, phase, settings, *rest = args
    return scenario, c, phase, settings, bool(rest[0]) if rest else False


def vector_field(t: Scalar, y: State, args) -> State:
    """dy/dt of the rigid model in the phase `args = (scenario, constants, phase, settings[, inextensible])`
    (`inextensible`: a Python bool, the rope model of the solve, default False: the elastic rope)."""
    scenario, c, phase, settings, inextensible = unpack(args)
    boom, g = scenario.boom, scenario.gravity
    ct = contact_dynamics(t, y, scenario, c, phase, settings, inextensible)
    ld = ct.loads
    moving = jnp.logical_not(phase.rest)  # a resting load is held fixed: only the boom tip moves
    body = dict(
        position=jnp.where(moving, y.velocity, 0.0),
        velocity=ct.accel[:3],
        quaternion=jnp.where(moving, kinematics.quat_rate(y.quaternion, y.angular_velocity), 0.0),
        angular_velocity=ct.accel[3:],
        friction_work=jnp.where(moving, -jnp.sum(ct.force[:, :2] * ld.corner_velocity[:, :2]), 0.0),
    )
    F_rope = ld.rope_tension * ld.rope_direction
    tip_acc = (ld.boom_force - F_rope) / boom.tip_mass - g * jnp.array([0.0, 0.0, 1.0])
    return State(
        tip_position=y.tip_velocity,
        tip_velocity=tip_acc,
        friction_state=y.friction_state,
        hoist_work=ld.rope_tension * ld.hoist_rate,
        damping_loss=ld.rope_loss + ld.boom_loss,
        **body,
    )


# ------------------------------------------------------------------------------------------ guards


def rest_conditions(ld: Loads, scenario: Scenario, c: Constants):
    """For a load resting flat: `(tip_margin, rho)`, tip margin = min(N/G, distance of R from the edges / L)
    (> 0 while it neither lifts nor tips) and the exact friction utilisation ρ* (<= 1 while it can rest).
    Uses `statics.rest_statics` with the rope force in body axes (the load may have turned about Z)."""
    S_body = ld.rotation.T @ (ld.rope_tension * ld.rope_direction)
    st = statics.rest_statics(scenario, S_body)
    return jnp.minimum(st.margins[0], st.margins[3]), st.friction_utilisation


def raw_guards(
    t: Scalar,
    y: State,
    scenario: Scenario,
    c: Constants,
    phase: Phase,
    settings: Settings,
    inextensible: bool = False,
) -> Float[Array, "12"]:
    """The guards of `phase` without offsets, dimensionless (forces / G, heights / L, speeds / V); the
    phase is valid while all are > 0. Guards that do not apply (to a corner's mode, or to rest, or to the
    rope model and mode) are +1. `inextensible`: the rope model (see `contact_dynamics`)."""
    ld = loads(t, y, scenario, c, inextensible=inextensible)
    if inextensible:
        return jax.lax.cond(
            phase.rest, rest_guards_rope, motion_guards_rope, ld, scenario, c, phase, settings
        )
    g = jax.lax.cond(phase.rest, rest_guards, motion_guards, ld, scenario, c, phase, settings)
    return jnp.concatenate([g, jnp.ones(2)])


def rope_guards(ld: Loads, scenario: Scenario, phase: Phase) -> Float[Array, "2"]:
    """The inextensible rope: while taut, its tension S / G (it goes slack at 0); while slack,
    (l(t) - |AB|) / L (it becomes taut again at 0). +1 otherwise."""
    sc = scales(scenario)
    slack = jnp.where(phase.rope == ROPE_TAUT, ld.rope_tension / sc.force, 1.0)
    taut = jnp.where(phase.rope == ROPE_SLACK, -ld.stretch / sc.length, 1.0)
    return jnp.stack([slack, taut])


def rest_guards(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings):
    tip, rho = rest_conditions(ld, scenario, c)
    return jnp.concatenate([jnp.ones(8), jnp.stack([tip, 1.0 - rho])])


def rest_guards_rope(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings):
    ld = rest_loads(ld, scenario, phase, settings)
    g = rest_guards(ld, scenario, c, phase, settings)
    return jnp.concatenate([g, rope_guards(ld, scenario, phase)])


def motion_guards_rope(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings):
    ct = motion_contact_rope(ld, scenario, c, phase, settings)
    g = motion_guards(ld, scenario, c, phase, settings, ct)
    return jnp.concatenate([g, rope_guards(ct.loads, scenario, phase)])


def motion_guards(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings, ct=None):
    sc = scales(scenario)
    ct = motion_contact_free(ld, scenario, c, phase, settings) if ct is None else ct
    ld = ct.loads
    mu = scenario.foundation.friction_coefficient
    N = ct.force[:, 2]
    T = jnp.sqrt(jnp.sum(ct.force[:, :2] ** 2, axis=1))
    contact = phase.contact
    # Linear-law (2.3) loads equivalent to the present ones: N + t w with t making them orthogonal to w.
    w = jnp.asarray(statics._W)
    N_lin = N - (jnp.dot(w, N) / 4.0) * w
    g_free = jnp.where(phase.free_on_ground, -N_lin / sc.force, ld.corners[:, 2] / sc.length)
    g_normal = jnp.where(contact != FREE, N / sc.force, g_free)
    vh = ld.corner_velocity[:, :2]
    speed = jnp.sqrt(jnp.sum(vh**2, axis=1))
    v_stop = settings.stop_velocity
    # A slip that started from rest: once its speed reaches 2 v_stop the phase is restarted as an ordinary
    # slide, and if it turns back by more than v_stop / 20 against its starting direction its direction is
    # re-anchored (bookkeeping events: nothing changes physically; a corner near the instantaneous centre of
    # rotation may creep back and forth through zero slip without events). An ordinary slide ends when
    # its speed falls to v_stop.
    g_start = (
        jnp.minimum(jnp.sum(vh * phase.slip_hint, axis=1) + 0.05 * v_stop, 2.0 * v_stop - speed) / sc.velocity
    )
    g_slide = jnp.where(phase.starting, g_start, (speed - v_stop) / sc.velocity)
    g_tan = jnp.where(contact == STICK, (mu * N - T) / sc.force, jnp.where(contact == SLIDE, g_slide, 1.0))
    return jnp.concatenate([g_normal, g_tan, jnp.ones(2)])


def event_condition(t, y, args, **kwargs) -> Scalar:
    """min over the guards (+ offsets): > 0 while the phase is valid; its zero ends the phase."""
    scenario, c, phase, settings, inextensible = unpack(args)
    return jnp.min(raw_guards(t, y, scenario, c, phase, settings, inextensible) + phase.guard_offset)


# ------------------------------------------------------------------------------------------ impacts


def impulse_response(
    y: State,
    scenario: Scenario,
    c: Constants,
    modes: Int[Array, "4"],
    slip_dirs: Float[Array, "4 2"],
    normal_target: PerCorner,
    rcond,
) -> tuple:
    """Velocity jump of an impact with the ground: minimum-norm impulses P_i at the corners in `modes`
    (`STICK`: all three post-impact velocity components prescribed, tangential ones 0; `SLIDE`: normal only,
    with a tangential impulse -μ P_n t̂_i along `slip_dirs`; `FREE`: no impulse), such that the post-impact
    normal velocity of each involved corner equals `normal_target` (Newton's law: -e times the pre-impact
    one for the striking corner, 0 for persistent contacts).

    **Returns** `(velocity, angular_velocity, impulses (4, 3), corner_velocity_after (4, 3))`.
    """
    R = kinematics.quat_to_matrix(y.quaternion)
    Minv = mass_inverse(scenario, c)
    jac = jax.vmap(lambda rho: jnp.concatenate([jnp.eye(3), -R @ kinematics.skew(rho)], axis=1))(
        c.corners_rel
    )
    u = jnp.concatenate([y.velocity, y.angular_velocity])
    v = jnp.einsum("kij,j->ki", jac, u)
    P, s_rows = maps(modes, slip_dirs, scenario.foundation.friction_coefficient)
    target = jnp.concatenate([jnp.zeros((4, 2)), normal_target[:, None]], axis=1)
    lam = solve_contact_system(jac, Minv, P, s_rows, target - v, scenario.load.mass, rcond)
    imp = jnp.einsum("kij,kj->ki", P, lam.reshape(4, 3))
    du = Minv @ jnp.einsum("kij,ki->j", jac, imp)
    u1 = u + du
    return u1[:3], u1[3:], imp, jnp.einsum("kij,j->ki", jac, u1)


def rope_impulse_response(
    t: Scalar,
    y: State,
    scenario: Scenario,
    c: Constants,
    modes: Int[Array, "4"],
    slip_dirs: Float[Array, "4 2"],
    normal_target: PerCorner,
    rcond,
) -> tuple:
    """The jerk of the inextensible rope: a plastic impulse P >= 0 along the rope that sets the rate
    d|AB|/dt to the hoist's dl/dt = -ds/dt, shared by the boom tip (-P e) and the load (+P e at B), with
    the corners in `modes` taking impulses as in `impulse_response` (post-jerk normal velocity
    `normal_target`; sticking corners do not slip; sliding ones take -μ P_n along `slip_dirs`). The same
    system serves a corner impact while the rope is taut (the rope keeps its rate).

    **Returns** `(velocity, angular_velocity, tip_velocity, corner impulses (4, 3), P, corner_velocity_after
    (4, 3))`.
    """
    ld = loads(t, y, scenario, c, inextensible=True)
    Minv = mass_inverse(scenario, c)
    u = jnp.concatenate([y.velocity, y.angular_velocity])
    v = jnp.einsum("kij,j->ki", ld.jacobians, u)
    P, s_rows = maps(modes, slip_dirs, scenario.foundation.friction_coefficient)
    m0 = scenario.boom.tip_mass
    target = jnp.concatenate([jnp.zeros((4, 2)), normal_target[:, None]], axis=1)
    lam, P_rope = solve_rope_contact_system(
        ld.jacobians,
        Minv,
        P,
        s_rows,
        target - v,
        ld.rope_generalised,
        m0,
        ld.rope_rate_error,
        scenario.load.mass,
        rcond,
    )
    imp = jnp.einsum("kij,kj->ki", P, lam.reshape(4, 3))
    u1 = u + Minv @ (jnp.einsum("kij,ki->j", ld.jacobians, imp) + P_rope * ld.rope_generalised)
    tip1 = y.tip_velocity - P_rope * ld.rope_direction / m0
    return u1[:3], u1[3:], tip1, imp, P_rope, jnp.einsum("kij,j->ki", ld.jacobians, u1)


# ------------------------------------------------------------------------------------------ outputs


def kinetic_energy(y: State, scenario: Scenario, c: Constants) -> Scalar:
    """½ m |v_C|² + ½ ωᵀJω of the load [J] (without the boom tip)."""
    w = y.angular_velocity
    return 0.5 * scenario.load.mass * jnp.sum(y.velocity**2) + 0.5 * w @ c.inertia @ w


def energy(y: State, ld: Loads, scenario: Scenario, c: Constants) -> Energy:
    """Energy terms [J] (`ground_spring` is 0: the ground is rigid)."""
    load, boom, g = scenario.load, scenario.boom, scenario.gravity
    dx = y.tip_position - c.tip_rest
    return Energy(
        kinetic=kinetic_energy(y, scenario, c) + 0.5 * boom.tip_mass * jnp.sum(y.tip_velocity**2),
        potential=g * (load.mass * y.position[2] + boom.tip_mass * y.tip_position[2]),
        ground_spring=jnp.zeros(()),
        rope_spring=ld.rope_spring,
        boom_spring=0.5 * jnp.sum(boom.stiffness * dx**2),
    )


class Output(eqx.Module):
    """What the trajectory reports at one saved instant (see `numerics.rigid.solve.RigidTrajectory`)."""

    corners: CornerVecs
    normal: PerCorner
    friction: CornerVecs
    rope_tension: Scalar
    energy: Energy
    euler: Float[Array, "3"]


def output(
    t: Scalar,
    y: State,
    scenario: Scenario,
    c: Constants,
    phase: Phase,
    settings: Settings,
    inextensible: bool = False,
) -> Output:
    ct = contact_dynamics(t, y, scenario, c, phase, settings, inextensible)
    ld = ct.loads
    return Output(
        corners=ld.corners,
        normal=ct.force[:, 2],
        friction=ct.force.at[:, 2].set(0.0),
        rope_tension=ld.rope_tension,
        energy=energy(y, ld, scenario, c),
        euler=kinematics.matrix_to_euler(ld.rotation),
    )
