"""The §2 rigid model's contact modes, phases, settings, corner loads and contact matrices (the definitions
that `dynamics` builds on). Use them through `physics.rigid`, which re-exports this module and
`dynamics` (see its docstring for the model)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ..._typing import CornerVecs, Rot33, Scalar, Vec3
from .. import forces, kinematics, statics
from ..elastic import Constants, State, constants, rope_pull
from ..params import Scenario

FREE, SLIDE, STICK = 0, 1, 2
MODE_NAMES = {FREE: "free", SLIDE: "slide", STICK: "stick"}
CORNERS = ("D", "E", "F", "H")
#: Rope modes (`Phase.rope`): the elastic rope (2.14), or the inextensible rope (2.15), taut or slack.
ROPE_ELASTIC, ROPE_TAUT, ROPE_SLACK = 0, 1, 2
ROPE_NAMES = {ROPE_ELASTIC: "elastic", ROPE_TAUT: "taut", ROPE_SLACK: "slack"}
#: Guards: 0-3 normal/touch-down per corner, 4-7 stick/slide per corner, 8 rest tip/lift, 9 rest slip,
#: 10 the inextensible rope's tension (taut), 11 its length reaching l(t) (slack).
N_GUARDS = 12
GUARD_NAMES = tuple(
    [f"normal:{c}" for c in CORNERS]
    + [f"tangential:{c}" for c in CORNERS]
    + ["rest:tip", "rest:slip", "rope:slack", "rope:taut"]
)


class Phase(eqx.Module):
    """The contact configuration of one phase. Arrays only, so that every phase (rest included: the
    branches are chosen by `lax.cond`) runs through one compiled solve.

    - `contact`: per corner D, E, F, H: `FREE` (0), `SLIDE` (1) or `STICK` (2).
    - `rest`: the load rests on all four corners and is held fixed (a boolean scalar).
    - `slip_hint`: per corner, a horizontal unit vector (world X, Y): the sliding direction at the start of
      the phase (needed when sliding starts from rest; otherwise the direction of the corner velocity).
    - `guard_offset`: added to each guard so that all guards start > 0 (a guard that starts at 0, such as
      the height of a corner that has just left the ground, must not end the phase at once).
    - `starting`: per corner, sliding started from rest in this phase (its guard watches the speed reach
      2 `Settings.stop_velocity`, or the corner turn back) rather than the slip dying out.
    - `free_on_ground`: per corner, a free corner lying on the ground while the other three carry the flat
      load: its guard watches the load the linear law (2.3) would give it (it takes load again when that
      becomes positive), instead of its height, which the other three keep at zero.
    - `rope`: the rope mode, an integer scalar: `ROPE_ELASTIC` (0, the rope law (2.14)), `ROPE_TAUT` (1, the
      inextensible rope (2.15) as a constraint |AB| = l(t) with unknown tension S >= 0) or `ROPE_SLACK`
      (2, inextensible and slack: S = 0, |AB| < l(t)). The rope *model* itself is the static `inextensible`
      argument of `contact_dynamics`, `raw_guards` and the solve's `args` (elastic: this field is unused).
    """

    contact: Int[Array, "4"]
    slip_hint: Float[Array, "4 2"]
    guard_offset: Float[Array, "12"]
    starting: Bool[Array, "4"]
    free_on_ground: Bool[Array, "4"]
    rest: Bool[Array, ""]
    rope: Int[Array, ""]


def make_phase(
    contact,
    rest=False,
    slip_hint=None,
    guard_offset=None,
    starting=None,
    free_on_ground=None,
    rope=ROPE_ELASTIC,
) -> Phase:
    """Build a `Phase` from Python values (host side)."""
    return Phase(
        contact=jnp.asarray(contact, dtype=jnp.int32),
        rest=jnp.asarray(bool(rest)),
        rope=jnp.asarray(rope, dtype=jnp.int32),
        slip_hint=jnp.zeros((4, 2)) if slip_hint is None else jnp.asarray(slip_hint, dtype=jnp.float64),
        guard_offset=jnp.zeros(N_GUARDS) if guard_offset is None else jnp.asarray(guard_offset, jnp.float64),
        starting=jnp.zeros(4, dtype=bool) if starting is None else jnp.asarray(starting, dtype=bool),
        free_on_ground=(
            jnp.zeros(4, dtype=bool) if free_on_ground is None else jnp.asarray(free_on_ground, dtype=bool)
        ),
    )


class Settings(eqx.Module):
    """Numerical constants of the rigid contact model.

    - `baumgarte`: β [1/s]; constrained corner accelerations are driven to -2β v - β² Z so that the
      drift of the contact constraints (integration error) decays instead of growing.
    - `slip_velocity`: ε_v [m/s]; the sliding direction is that of v_h + ε_v t̂_hint, so it follows the
      hint at the start of sliding from rest and the corner velocity once |v_h| >> ε_v.
    - `rcond`: relative cut-off of singular values in the minimum-norm contact-force solve [-].
    - `stop_velocity`: v_stop [m/s]; a sliding corner whose speed falls to v_stop ends its phase (it then
      sticks or slides on): Coulomb friction's direction is singular at zero slip, and following it down to
      zero would cost ever smaller steps. Sticking then removes the remaining slip (<= 2 v_stop) by a tiny
      velocity projection whose energy is booked with the impact losses.
    - `rest_velocity`: [m/s]; when an impact leaves the load flat on the ground with every corner slower
      than this, it is brought to rest (plastic impact of the whole bottom face). Without it a rocking load
      would need infinitely many ever smaller impacts (a Zeno sequence) to settle.
    """

    baumgarte: Scalar
    slip_velocity: Scalar
    rcond: Scalar
    stop_velocity: Scalar
    rest_velocity: Scalar

    def __init__(
        self, baumgarte=20.0, slip_velocity=1e-6, rcond=1e-9, stop_velocity=1e-4, rest_velocity=1e-3
    ):
        self.baumgarte = jnp.asarray(baumgarte, dtype=jnp.float64)
        self.slip_velocity = jnp.asarray(slip_velocity, dtype=jnp.float64)
        self.rcond = jnp.asarray(rcond, dtype=jnp.float64)
        self.stop_velocity = jnp.asarray(stop_velocity, dtype=jnp.float64)
        self.rest_velocity = jnp.asarray(rest_velocity, dtype=jnp.float64)


class Scales(eqx.Module):
    """Reference magnitudes of a scenario: weight G = m g [N], length L = |(a, b, c)| [m],
    velocity V = sqrt(g L) [m/s], acceleration g [m/s²]."""

    force: Scalar
    length: Scalar
    velocity: Scalar
    acceleration: Scalar


def scales(scenario: Scenario) -> Scales:
    g = scenario.gravity
    L = jnp.linalg.norm(scenario.load.size)
    return Scales(force=scenario.load.mass * g, length=L, velocity=jnp.sqrt(g * L), acceleration=g)


# ------------------------------------------------------------------------------------ initial state


def initial_state(scenario: Scenario) -> tuple[State, Constants]:
    """The load standing flat on the rigid ground with corner D at the origin and ψ = 0, at rest; the rope
    just taut (or slack by `rope.slack`), the boom tip at rest at A."""
    load = scenario.load
    position = load.mass_centre
    B = scenario.rope.attachment
    l0 = jnp.sqrt(jnp.sum((scenario.boom.tip_position - B) ** 2)) + scenario.rope.slack
    c = constants(scenario, l0)
    zero = jnp.zeros(())
    y0 = State(
        position=position,
        velocity=jnp.zeros(3),
        quaternion=jnp.array([1.0, 0.0, 0.0, 0.0]),
        angular_velocity=jnp.zeros(3),
        tip_position=scenario.boom.tip_position,
        tip_velocity=jnp.zeros(3),
        friction_state=jnp.zeros((4, 0)),
        hoist_work=zero,
        damping_loss=zero,
        friction_work=zero,
    )
    return y0, c


# ------------------------------------------------------------------------------------ loads


class Loads(eqx.Module):
    """Kinematics and the applied (non-contact) forces at one instant. World axes unless stated.

    - `rotation`: R (body -> world); `corners`, `corner_velocity`: D, E, F, H [m], [m/s].
    - `jacobians`: B_i (4, 3, 6) with v_i = B_i (v_C, ω_body); `bias`: R(ω×(ω×ρ_i)) [m/s²], the part of
      the corner acceleration not proportional to (dv_C/dt, dω/dt).
    - `generalised_force`: (F, M - ω×Jω) with F world [N] and M about C in body axes [N m]: rope + weight.
    - rope (2.14): `rope_point` B, `rope_tension` S, `rope_direction` (B -> A), `stretch` |AB| - l(t),
      `hoist_rate` ds/dt, `rope_loss` [W], `rope_spring` its elastic energy [J]; boom (2.13): `boom_force`
      on the tip [N], `boom_loss` [W]. For the inextensible rope (2.15) S, the loss and the energy are 0
      here: the tension is a constraint force, solved with the contact forces.
    - the inextensible rope's kinematics: `rope_generalised` (6), the generalised force of a unit pull at
      B towards A (e, ρ_B × Rᵀe); `rope_jacobian` J_B (3, 6) and `rope_bias` R(ω×(ω×ρ_B)) of B;
      `rope_rate_error` d|AB|/dt - dl/dt [m/s]; `rope_curvature` (|v_A - v_B|² - (d|AB|/dt)²)/|AB| [m/s²]
      (d²|AB|/dt² = e·(a_A - a_B) + this); `hoist_accel` d²s/dt² [m/s²].
    """

    rotation: Rot33
    corners: CornerVecs
    corner_velocity: CornerVecs
    jacobians: Float[Array, "4 3 6"]
    bias: CornerVecs
    generalised_force: Float[Array, "6"]
    rope_point: Vec3
    rope_tension: Scalar
    rope_direction: Vec3
    stretch: Scalar
    hoist_rate: Scalar
    rope_loss: Scalar
    rope_spring: Scalar
    boom_force: Vec3
    boom_loss: Scalar
    rope_generalised: Float[Array, "6"]
    rope_jacobian: Float[Array, "3 6"]
    rope_bias: Vec3
    rope_rate_error: Scalar
    rope_curvature: Scalar
    hoist_accel: Scalar


def loads(t: Scalar, y: State, scenario: Scenario, c: Constants, inextensible: bool = False) -> Loads:
    """Kinematics, rope, boom and weight at (t, y). With `inextensible` (a Python bool) the rope carries
    no force here (its tension is a constraint force, see `contact_dynamics`) and the rope's kinematics
    fields are filled (`inextensible_loads`); for the elastic rope they are 0 (unused)."""
    load, boom = scenario.load, scenario.boom
    R = kinematics.quat_to_matrix(y.quaternion)
    omega = y.angular_velocity
    corners = kinematics.points_world(y.position, R, c.corners_rel)
    corner_vel = y.velocity + jnp.cross(omega, c.corners_rel) @ R.T  # v_C + R (ω × ρ_i), cf. (2.17)
    jac = jax.vmap(lambda rho: jnp.concatenate([jnp.eye(3), -R @ kinematics.skew(rho)], axis=1))(
        c.corners_rel
    )
    bias = jnp.cross(omega, jnp.cross(omega, c.corners_rel)) @ R.T

    # Rope (2.14) with l(t) = l0 - s(t): the elastic model's rope, shared.
    B, e, stretch, s_dot, S, rope_loss = rope_pull(t, y, R, scenario, c)
    F_boom, boom_loss = forces.boom_force(
        y.tip_position - c.tip_rest, y.tip_velocity, boom.stiffness, boom.damping
    )

    F_rope = S * e
    z_hat = jnp.array([0.0, 0.0, 1.0])
    force = F_rope - load.mass * scenario.gravity * z_hat
    moment = jnp.cross(c.attachment_rel, R.T @ F_rope) - jnp.cross(omega, c.inertia @ omega)
    zero = jnp.zeros_like(stretch)
    ld = Loads(
        rotation=R,
        corners=corners,
        corner_velocity=corner_vel,
        jacobians=jac,
        bias=bias,
        generalised_force=jnp.concatenate([force, moment]),
        rope_point=B,
        rope_tension=S,
        rope_direction=e,
        stretch=stretch,
        hoist_rate=s_dot,
        rope_loss=rope_loss,
        rope_spring=0.5 * scenario.rope.stiffness * jnp.maximum(stretch, 0.0) ** 2,
        boom_force=F_boom,
        boom_loss=boom_loss,
        rope_generalised=jnp.zeros(6),
        rope_jacobian=jnp.zeros((3, 6)),
        rope_bias=jnp.zeros(3),
        rope_rate_error=zero,
        rope_curvature=zero,
        hoist_accel=zero,
    )
    return inextensible_loads(t, y, ld, scenario, c) if inextensible else ld


def inextensible_loads(t: Scalar, y: State, ld: Loads, scenario: Scenario, c: Constants) -> Loads:
    """The elastic rope's `ld` turned into the inextensible rope's: no rope force, loss or energy (the
    tension is a constraint force), and the kinematics of |AB| for the constraint (2.15)."""
    R, omega, e = ld.rotation, y.angular_velocity, ld.rope_direction
    zero = jnp.zeros_like(ld.stretch)
    force = -scenario.load.mass * scenario.gravity * jnp.array([0.0, 0.0, 1.0])
    moment = -jnp.cross(omega, c.inertia @ omega)
    rho_B = c.attachment_rel
    v_rel = y.tip_velocity - (y.velocity + R @ jnp.cross(omega, rho_B))
    L = forces.safe_norm(y.tip_position - ld.rope_point)
    L_dot = jnp.dot(v_rel, e)
    return eqx.tree_at(
        lambda x: (
            x.generalised_force,
            x.rope_tension,
            x.rope_loss,
            x.rope_spring,
            x.rope_generalised,
            x.rope_jacobian,
            x.rope_bias,
            x.rope_rate_error,
            x.rope_curvature,
            x.hoist_accel,
        ),
        ld,
        (
            jnp.concatenate([force, moment]),
            zero,
            zero,
            zero,
            jnp.concatenate([e, jnp.cross(rho_B, R.T @ e)]),
            jnp.concatenate([jnp.eye(3), -R @ kinematics.skew(rho_B)], axis=1),
            R @ jnp.cross(omega, jnp.cross(omega, rho_B)),
            L_dot + ld.hoist_rate,
            (jnp.sum(v_rel**2) - L_dot**2) / jnp.maximum(L, 1e-12),
            jax.jvp(scenario.hoist.rate, (t,), (jnp.ones_like(t),))[1],
        ),
    )


def with_tension(ld: Loads, S: Scalar, taut) -> Loads:
    """`ld` with the inextensible rope's constraint tension S [N] applied where `taut` (else unchanged,
    exactly: `ld` of a taut rope carries S = 0)."""
    return eqx.tree_at(
        lambda x: (x.rope_tension, x.generalised_force),
        ld,
        (
            jnp.where(taut, S, ld.rope_tension),
            jnp.where(taut, ld.generalised_force + S * ld.rope_generalised, ld.generalised_force),
        ),
    )


def rope_accel_target(ld: Loads, settings: Settings) -> Scalar:
    """d²|AB|/dt² that the taut inextensible rope must have: l'' - 2β (d|AB|/dt - l') - β² (|AB| - l)
    [m/s²] (Baumgarte stabilisation of the constraint (2.15), as for the contacts)."""
    beta = settings.baumgarte
    return -ld.hoist_accel - 2.0 * beta * ld.rope_rate_error - beta**2 * ld.stretch


def tip_free_accel(ld: Loads, scenario: Scenario) -> Vec3:
    """Boom-tip acceleration (2.13) without the rope force (inextensible rope: S = 0 in `ld`)."""
    g = scenario.gravity
    return (ld.boom_force - ld.rope_tension * ld.rope_direction) / scenario.boom.tip_mass - g * jnp.array(
        [0.0, 0.0, 1.0]
    )


def rest_rope_tension(ld: Loads, scenario: Scenario, settings: Settings) -> Scalar:
    """Tension S [N] of the taut inextensible rope while the load is held fixed: the constraint then fixes
    the tip's motion along the rope, e·a_A + curvature = target with m_0 a_A = boom force - S e - m_0 g."""
    e = ld.rope_direction
    m0 = scenario.boom.tip_mass
    return m0 * (
        jnp.dot(e, tip_free_accel(ld, scenario)) + ld.rope_curvature - rope_accel_target(ld, settings)
    )


def mass_inverse(scenario: Scenario, c: Constants) -> Float[Array, "6 6"]:
    m = scenario.load.mass
    z = jnp.zeros((3, 3))
    return jnp.block([[jnp.eye(3) / m, z], [z, c.inertia_inv]])


def slip_directions(corner_velocity: CornerVecs, slip_hint: Float[Array, "4 2"], eps: Scalar):
    """Unit sliding directions t̂_i (4, 2) from v_h + ε_v hint (zero if both vanish: frictionless)."""
    w = corner_velocity[:, :2] + eps * slip_hint
    n2 = jnp.sum(w**2, axis=1)
    pos = n2 > 0
    n = jnp.where(pos, jnp.sqrt(jnp.where(pos, n2, 1.0)), 1.0)
    return jnp.where(pos[:, None], w / n[:, None], 0.0)


def maps(contact: Int[Array, "4"], tdir: Float[Array, "4 2"], mu: Scalar):
    """Per corner: the force map P_i (world force = P_i λ_i) and the constrained-row selector S_i (3x3)."""
    stick = contact == STICK
    slide = contact == SLIDE
    P_slide = (
        jnp.zeros((4, 3, 3))
        .at[:, 2, 2]
        .set(1.0)
        .at[:, 0, 2]
        .set(-mu * tdir[:, 0])
        .at[:, 1, 2]
        .set(-mu * tdir[:, 1])
    )
    eye = jnp.broadcast_to(jnp.eye(3), (4, 3, 3))
    P = jnp.where(stick[:, None, None], eye, jnp.where(slide[:, None, None], P_slide, 0.0))
    s_rows = jnp.where(stick[:, None], 1.0, jnp.where(slide[:, None], jnp.array([0.0, 0.0, 1.0]), 0.0))
    return P, s_rows


def block_diag(blocks: Float[Array, "4 3 3"]) -> Float[Array, "12 12"]:
    out = jnp.zeros((12, 12))
    for i in range(4):
        out = out.at[3 * i : 3 * i + 3, 3 * i : 3 * i + 3].set(blocks[i])
    return out


def solve_contact_system(jacobians, Minv, P, s_rows, target, mass, rcond):
    """λ (12) of: for every constrained row k, (B M⁻¹ Bᵀ P λ)_k = target_k; unconstrained rows λ_k = 0.

    Redundant contacts leave a family of solutions. With all four corners on the ground their normal
    forces are fixed by the paper's linear law (2.3), N_i = A_0 + A_1 ξ_i + A_2 η_i, i.e. Σ w_i N_i = 0 with
    w = (1, -1, 1, -1) (the rigid limit of the elastic foundation, where the flat bottom compresses the
    springs linearly); with sliding corners this differs from the unweighted minimum norm because friction
    scales with N_i. What is left (tangential forces shared by sticking corners) takes the minimum norm.
    The system is scaled by the load's mass so that its entries are O(1); the identity rows of the
    unconstrained components decouple, so the pseudo-inverse gives λ = 0 there.
    """
    Bbig = jacobians.reshape(12, 6)
    K = Bbig @ Minv @ Bbig.T
    s = s_rows.reshape(12)
    A = mass * (s[:, None] * K @ block_diag(P)) + jnp.diag(1.0 - s)
    rhs = mass * s * target.reshape(12)
    four = jnp.all(s_rows[:, 2] > 0)
    w_row = jnp.zeros(12).at[jnp.array([2, 5, 8, 11])].set(jnp.asarray(statics._W))
    w_row = w_row * four.astype(w_row.dtype)  # bool -> 0.0/1.0: strict dtype promotion
    A = jnp.concatenate([A, w_row[None, :]], axis=0)
    rhs = jnp.concatenate([rhs, jnp.zeros(1)])
    return jnp.linalg.pinv(A, rtol=rcond) @ rhs


def solve_rope_contact_system(jacobians, Minv, P, s_rows, target, g_rope, m0, rhs_rope, mass, rcond):
    """`solve_contact_system` extended by the taut inextensible rope's force S along the generalised
    direction `g_rope` (6) (a unit pull at B towards A) and one more row, the rope's:

        corner rows:  B M⁻¹ (Bᵀ P λ + g S) = target;
        rope row:     gᵀ M⁻¹ Bᵀ P λ + (gᵀ M⁻¹ g + 1/m_0) S = rhs_rope,

    where rhs_rope is the rate at which the free motion (S = 0) would separate A from B beyond what the
    rope allows (accelerations; or velocities for the rope jerk). Same treatment of redundant contacts.

    **Returns** `(λ (12), S)`.
    """
    Bbig = jacobians.reshape(12, 6)
    s = s_rows.reshape(12)
    PB = block_diag(P)
    A_cc = s[:, None] * (Bbig @ Minv @ Bbig.T @ PB) + jnp.diag(1.0 - s)
    A_cs = s * (Bbig @ Minv @ g_rope)
    A_sc = g_rope @ Minv @ Bbig.T @ PB
    A_ss = g_rope @ Minv @ g_rope + 1.0 / m0
    A = jnp.concatenate(
        [jnp.concatenate([A_cc, A_cs[:, None]], axis=1), jnp.concatenate([A_sc, A_ss[None]])[None, :]], axis=0
    )
    rhs = jnp.concatenate([s * target.reshape(12), jnp.reshape(rhs_rope, (1,))])
    four = jnp.all(s_rows[:, 2] > 0)
    w_row = jnp.zeros(13).at[jnp.array([2, 5, 8, 11])].set(jnp.asarray(statics._W))
    w_row = w_row * four.astype(w_row.dtype)  # bool -> 0.0/1.0: strict dtype promotion
    A = jnp.concatenate([mass * A, w_row[None, :]], axis=0)
    rhs = jnp.concatenate([mass * rhs, jnp.zeros(1)])
    x = jnp.linalg.pinv(A, rtol=rcond) @ rhs
    return x[:12], x[12]


class ContactMatrices(eqx.Module):
    """The data of the contact problem at one instant, for host-side analysis (`numerics.rigid.solve`).

    - `mass`: M = diag(m I, J) (6, 6); `force`: generalised applied force (6) (see `Loads`);
    - `jacobians` B_i (4, 3, 6), `bias` (4, 3), `corner_velocity` (4, 3), `corners` (4, 3);
    - `target`: the Baumgarte-stabilised acceleration a constrained corner must have (4, 3).
    - `rope_row`, `rope_rhs`: None, or with the taut inextensible rope: the coordinates are extended by the
      boom tip's, (dv_C/dt, dω/dt, a_A) (9: `mass` diag(m I, J, m_0 I), `force` with the boom force and
      the tip's weight, `jacobians` padded with zeros), and the rope is one more equality constraint
      `rope_row`·(dv_C/dt, dω/dt, a_A) = `rope_rhs` (d²|AB|/dt² = its Baumgarte target).
    """

    mass: Float[Array, "n n"]
    force: Float[Array, " n"]
    jacobians: Float[Array, "4 3 n"]
    bias: CornerVecs
    corner_velocity: CornerVecs
    corners: CornerVecs
    target: CornerVecs
    rope_row: Float[Array, " n"] | None = None
    rope_rhs: Scalar | None = None


def contact_matrices(
    t: Scalar, y: State, scenario: Scenario, c: Constants, settings: Settings, rope: int = ROPE_ELASTIC
) -> ContactMatrices:
    """The contact problem at (t, y) for the rope mode `rope` (a Python int: it sets the shapes)."""
    ld = loads(t, y, scenario, c, inextensible=rope != ROPE_ELASTIC)
    m = scenario.load.mass
    z = jnp.zeros((3, 3))
    M = jnp.block([[m * jnp.eye(3), z], [z, c.inertia]])
    beta = settings.baumgarte
    target = -2.0 * beta * ld.corner_velocity - beta**2 * ld.corners[:, 2:3] * jnp.array([0.0, 0.0, 1.0])
    if rope != ROPE_TAUT:
        return ContactMatrices(
            mass=M,
            force=ld.generalised_force,
            jacobians=ld.jacobians,
            bias=ld.bias,
            corner_velocity=ld.corner_velocity,
            corners=ld.corners,
            target=target,
        )
    m0 = scenario.boom.tip_mass
    e = ld.rope_direction
    M9 = jnp.zeros((9, 9)).at[:6, :6].set(M).at[6:, 6:].set(m0 * jnp.eye(3))
    f9 = jnp.concatenate([ld.generalised_force, m0 * tip_free_accel(ld, scenario)])
    jac9 = jnp.concatenate([ld.jacobians, jnp.zeros((4, 3, 3))], axis=2)
    # d²|AB|/dt² = e·(a_A - J_B u̇ - bias_B) + curvature = target.
    row = jnp.concatenate([-e @ ld.rope_jacobian, e])
    rhs = rope_accel_target(ld, settings) - ld.rope_curvature + jnp.dot(e, ld.rope_bias)
    return ContactMatrices(
        mass=M9,
        force=f9,
        jacobians=jac9,
        bias=ld.bias,
        corner_velocity=ld.corner_velocity,
        corners=ld.corners,
        target=target,
        rope_row=row,
        rope_rhs=rhs,
    )
