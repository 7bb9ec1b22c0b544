"""The paper's §2 model: a rigid box on a rigid ground, pulled by an elastic rope from a sprung boom tip.

One mechanism serves every phase of the motion (rest, sliding, tipping about an edge or a corner, flight):
constrained Newton-Euler dynamics (2.10)-(2.11) for the current set of active contacts. Each bottom corner
D, E, F, H is in one of three contact modes, carried in `Phase.contact`:

- `FREE`: no ground force;
- `SLIDE`: on the ground (Z_i = 0 enforced), normal force N_i >= 0 and Coulomb friction -μ N_i t̂_i
  opposite to the sliding direction t̂_i (eq. 2.18), t̂_i = v_i,h / |v_i,h| blended with the phase's
  `slip_hint` below `slip_velocity` so that sliding can start from rest;
- `STICK`: the corner does not move (all three velocity components held at zero), ground force free.

The unknown contact forces λ (3 per corner) solve the small linear system "constrained corner accelerations
vanish" (with Baumgarte stabilisation of the drift); redundant contacts (four coplanar corners, or two
sticking corners sharing an edge) make it singular: four corners on the ground carry the paper's linear
distribution (2.3) (which at rest is the minimum-norm solution), and what remains indeterminate takes
the minimum norm (SVD pseudo-inverse). When the body is at rest on all
four corners (`Phase.rest`) it is held fixed and only the boom tip moves; the phase lasts while the load
can rest: N > 0, R inside the rectangle, and the exact corner friction utilisation ρ* <= 1 (`statics`).

A phase ends at the first zero of one of its guards (all positive while the phase is valid):
a contact's normal force reaching 0 (lift-off of that corner), a free corner reaching the ground
(touch-down or impact), a sticking corner's friction reaching μN_i (slip), a sliding corner's velocity
along its sliding direction reaching 0 (stop or turn), and for rest: R leaving the rectangle (tip) or
ρ* reaching 1 (slip). The choice of the next phase, impacts and the phase loop live in
`numerics.rigid_solve`.

The state is `elastic.State` (with an empty friction state, shape (4, 0)); the rope (2.14) and the boom
(2.13) are the force laws of `forces`. With `inextensible=True` the rope is instead the constraint (2.15)
|AB| = l(t) (taut or slack by `Phase.rope`): a taut rope's tension joins the contact forces as an unknown,
and the boom tip's acceleration joins the constrained accelerations. All functions are pure JAX.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .._typing import CornerVecs, PerCorner, Rot33, Scalar, Vec3
from . import forces, kinematics, statics
from .elastic import Constants, State, constants, rope_pull
from .energy import Energy
from .params import Scenario

FREE, SLIDE, STICK = 0, 1, 2
MODE_NAMES = {FREE: "free", SLIDE: "slide", STICK: "stick"}
CORNERS = ("D", "E", "F", "H")
#: Rope modes (`Phase.rope`): the elastic rope (2.14), or the inextensible rope (2.15), taut or slack.
ROPE_ELASTIC, ROPE_TAUT, ROPE_SLACK = 0, 1, 2
ROPE_NAMES = {ROPE_ELASTIC: "elastic", ROPE_TAUT: "taut", ROPE_SLACK: "slack"}
#: Guards: 0-3 normal/touch-down per corner, 4-7 stick/slide per corner, 8 rest tip/lift, 9 rest slip,
#: 10 the inextensible rope's tension (taut), 11 its length reaching l(t) (slack).
N_GUARDS = 12
GUARD_NAMES = tuple([f"normal:{c}" for c in CORNERS] + [f"tangential:{c}" for c in CORNERS]
                    + ["rest:tip", "rest:slip", "rope:slack", "rope:taut"])


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


def make_phase(contact, rest=False, slip_hint=None, guard_offset=None, starting=None,
               free_on_ground=None, rope=ROPE_ELASTIC) -> Phase:
    """Build a `Phase` from Python values (host side)."""
    return Phase(
        contact=jnp.asarray(contact, dtype=jnp.int32),
        rest=jnp.asarray(bool(rest)),
        rope=jnp.asarray(rope, dtype=jnp.int32),
        slip_hint=jnp.zeros((4, 2)) if slip_hint is None else jnp.asarray(slip_hint, dtype=jnp.float64),
        guard_offset=jnp.zeros(N_GUARDS) if guard_offset is None else jnp.asarray(guard_offset, jnp.float64),
        starting=jnp.zeros(4, dtype=bool) if starting is None else jnp.asarray(starting, dtype=bool),
        free_on_ground=(jnp.zeros(4, dtype=bool) if free_on_ground is None
                        else jnp.asarray(free_on_ground, dtype=bool)),
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

    def __init__(self, baumgarte=20.0, slip_velocity=1e-6, rcond=1e-9, stop_velocity=1e-4,
                 rest_velocity=1e-3):
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
    y0 = State(position=position, velocity=jnp.zeros(3), quaternion=jnp.array([1.0, 0.0, 0.0, 0.0]),
               angular_velocity=jnp.zeros(3), tip_position=scenario.boom.tip_position,
               tip_velocity=jnp.zeros(3), friction_state=jnp.zeros((4, 0)), hoist_work=zero,
               damping_loss=zero, friction_work=zero)
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
        c.corners_rel)
    bias = jnp.cross(omega, jnp.cross(omega, c.corners_rel)) @ R.T

    # Rope (2.14) with l(t) = l0 - s(t): the elastic model's rope, shared.
    B, e, stretch, s_dot, S, rope_loss = rope_pull(t, y, R, scenario, c)
    F_boom, boom_loss = forces.boom_force(y.tip_position - c.tip_rest, y.tip_velocity, boom.stiffness,
                                          boom.damping)

    F_rope = S * e
    z_hat = jnp.array([0.0, 0.0, 1.0])
    force = F_rope - load.mass * scenario.gravity * z_hat
    moment = jnp.cross(c.attachment_rel, R.T @ F_rope) - jnp.cross(omega, c.inertia @ omega)
    zero = jnp.zeros_like(stretch)
    ld = Loads(rotation=R, corners=corners, corner_velocity=corner_vel, jacobians=jac, bias=bias,
               generalised_force=jnp.concatenate([force, moment]), rope_point=B, rope_tension=S,
               rope_direction=e, stretch=stretch, hoist_rate=s_dot, rope_loss=rope_loss,
               rope_spring=0.5 * scenario.rope.stiffness * jnp.maximum(stretch, 0.0) ** 2, boom_force=F_boom,
               boom_loss=boom_loss, rope_generalised=jnp.zeros(6), rope_jacobian=jnp.zeros((3, 6)),
               rope_bias=jnp.zeros(3), rope_rate_error=zero, rope_curvature=zero, hoist_accel=zero)
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
        lambda x: (x.generalised_force, x.rope_tension, x.rope_loss, x.rope_spring, x.rope_generalised,
                   x.rope_jacobian, x.rope_bias, x.rope_rate_error, x.rope_curvature, x.hoist_accel),
        ld,
        (jnp.concatenate([force, moment]), zero, zero, zero, jnp.concatenate([e, jnp.cross(rho_B, R.T @ e)]),
         jnp.concatenate([jnp.eye(3), -R @ kinematics.skew(rho_B)], axis=1),
         R @ jnp.cross(omega, jnp.cross(omega, rho_B)), L_dot + ld.hoist_rate,
         (jnp.sum(v_rel**2) - L_dot**2) / jnp.maximum(L, 1e-12),
         jax.jvp(scenario.hoist.rate, (t,), (jnp.ones_like(t),))[1]))


def with_tension(ld: Loads, S: Scalar, taut) -> Loads:
    """`ld` with the inextensible rope's constraint tension S [N] applied where `taut` (else unchanged,
    exactly: `ld` of a taut rope carries S = 0)."""
    return eqx.tree_at(lambda x: (x.rope_tension, x.generalised_force), ld,
                       (jnp.where(taut, S, ld.rope_tension),
                        jnp.where(taut, ld.generalised_force + S * ld.rope_generalised,
                                  ld.generalised_force)))


def rope_accel_target(ld: Loads, settings: Settings) -> Scalar:
    """d²|AB|/dt² that the taut inextensible rope must have: l'' - 2β (d|AB|/dt - l') - β² (|AB| - l)
    [m/s²] (Baumgarte stabilisation of the constraint (2.15), as for the contacts)."""
    beta = settings.baumgarte
    return -ld.hoist_accel - 2.0 * beta * ld.rope_rate_error - beta**2 * ld.stretch


def _tip_free_accel(ld: Loads, scenario: Scenario) -> Vec3:
    """Boom-tip acceleration (2.13) without the rope force (inextensible rope: S = 0 in `ld`)."""
    g = scenario.gravity
    return (ld.boom_force - ld.rope_tension * ld.rope_direction) / scenario.boom.tip_mass - g * jnp.array(
        [0.0, 0.0, 1.0])


def rest_rope_tension(ld: Loads, scenario: Scenario, settings: Settings) -> Scalar:
    """Tension S [N] of the taut inextensible rope while the load is held fixed: the constraint then fixes
    the tip's motion along the rope, e·a_A + curvature = target with m_0 a_A = boom force - S e - m_0 g."""
    e = ld.rope_direction
    m0 = scenario.boom.tip_mass
    return m0 * (jnp.dot(e, _tip_free_accel(ld, scenario)) + ld.rope_curvature
                 - rope_accel_target(ld, settings))


def _mass_inverse(scenario: Scenario, c: Constants) -> Float[Array, "6 6"]:
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


def _maps(contact: Int[Array, "4"], tdir: Float[Array, "4 2"], mu: Scalar):
    """Per corner: the force map P_i (world force = P_i λ_i) and the constrained-row selector S_i (3x3)."""
    stick = contact == STICK
    slide = contact == SLIDE
    P_slide = jnp.zeros((4, 3, 3)).at[:, 2, 2].set(1.0).at[:, 0, 2].set(-mu * tdir[:, 0]).at[:, 1, 2].set(
        -mu * tdir[:, 1])
    eye = jnp.broadcast_to(jnp.eye(3), (4, 3, 3))
    P = jnp.where(stick[:, None, None], eye, jnp.where(slide[:, None, None], P_slide, 0.0))
    s_rows = jnp.where(stick[:, None], 1.0, jnp.where(slide[:, None], jnp.array([0.0, 0.0, 1.0]), 0.0))
    return P, s_rows


def _block_diag(blocks: Float[Array, "4 3 3"]) -> Float[Array, "12 12"]:
    out = jnp.zeros((12, 12))
    for i in range(4):
        out = out.at[3 * i:3 * i + 3, 3 * i:3 * i + 3].set(blocks[i])
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
    A = mass * (s[:, None] * K @ _block_diag(P)) + jnp.diag(1.0 - s)
    rhs = mass * s * target.reshape(12)
    four = jnp.all(s_rows[:, 2] > 0)
    w_row = jnp.zeros(12).at[jnp.array([2, 5, 8, 11])].set(jnp.asarray(statics._W)) * four
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
    PB = _block_diag(P)
    A_cc = s[:, None] * (Bbig @ Minv @ Bbig.T @ PB) + jnp.diag(1.0 - s)
    A_cs = s * (Bbig @ Minv @ g_rope)
    A_sc = g_rope @ Minv @ Bbig.T @ PB
    A_ss = g_rope @ Minv @ g_rope + 1.0 / m0
    A = jnp.concatenate([jnp.concatenate([A_cc, A_cs[:, None]], axis=1),
                         jnp.concatenate([A_sc, A_ss[None]])[None, :]], axis=0)
    rhs = jnp.concatenate([s * target.reshape(12), jnp.reshape(rhs_rope, (1,))])
    four = jnp.all(s_rows[:, 2] > 0)
    w_row = jnp.zeros(13).at[jnp.array([2, 5, 8, 11])].set(jnp.asarray(statics._W)) * four
    A = jnp.concatenate([mass * A, w_row[None, :]], axis=0)
    rhs = jnp.concatenate([mass * rhs, jnp.zeros(1)])
    x = jnp.linalg.pinv(A, rtol=rcond) @ rhs
    return x[:12], x[12]


class ContactMatrices(eqx.Module):
    """The data of the contact problem at one instant, for host-side analysis (`numerics.rigid_solve`).

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


def contact_matrices(t: Scalar, y: State, scenario: Scenario, c: Constants,
                     settings: Settings, rope: int = ROPE_ELASTIC) -> ContactMatrices:
    """The contact problem at (t, y) for the rope mode `rope` (a Python int: it sets the shapes)."""
    ld = loads(t, y, scenario, c, inextensible=rope != ROPE_ELASTIC)
    m = scenario.load.mass
    z = jnp.zeros((3, 3))
    M = jnp.block([[m * jnp.eye(3), z], [z, c.inertia]])
    beta = settings.baumgarte
    target = -2.0 * beta * ld.corner_velocity - beta**2 * ld.corners[:, 2:3] * jnp.array([0.0, 0.0, 1.0])
    if rope != ROPE_TAUT:
        return ContactMatrices(mass=M, force=ld.generalised_force, jacobians=ld.jacobians, bias=ld.bias,
                               corner_velocity=ld.corner_velocity, corners=ld.corners, target=target)
    m0 = scenario.boom.tip_mass
    e = ld.rope_direction
    M9 = jnp.zeros((9, 9)).at[:6, :6].set(M).at[6:, 6:].set(m0 * jnp.eye(3))
    f9 = jnp.concatenate([ld.generalised_force, m0 * _tip_free_accel(ld, scenario)])
    jac9 = jnp.concatenate([ld.jacobians, jnp.zeros((4, 3, 3))], axis=2)
    # d²|AB|/dt² = e·(a_A - J_B u̇ - bias_B) + curvature = target.
    row = jnp.concatenate([-e @ ld.rope_jacobian, e])
    rhs = rope_accel_target(ld, settings) - ld.rope_curvature + jnp.dot(e, ld.rope_bias)
    return ContactMatrices(mass=M9, force=f9, jacobians=jac9, bias=ld.bias,
                           corner_velocity=ld.corner_velocity, corners=ld.corners, target=target,
                           rope_row=row, rope_rhs=rhs)


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


def _rest_loads(ld: Loads, scenario: Scenario, phase: Phase, settings: Settings) -> Loads:
    """`ld` of a load held fixed, with the taut inextensible rope's tension (if any) applied."""
    taut = phase.rope == ROPE_TAUT
    return with_tension(ld, rest_rope_tension(ld, scenario, settings), taut)


def _rest_contact_rope(ld: Loads, scenario: Scenario, c: Constants, phase: Phase,
                       settings: Settings) -> Contact:
    return _rest_contact(_rest_loads(ld, scenario, phase, settings), scenario, c, phase, settings)


def _rest_contact(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings) -> Contact:
    # Held fixed: zero acceleration; the corner loads of the linear law (2.3), made nonnegative.
    S_body = ld.rotation.T @ (ld.rope_tension * ld.rope_direction)
    st = statics.rest_statics_loads(scenario, S_body)
    F = jnp.concatenate([rest_friction(ld, c, scenario), st[:, None]], axis=1)
    return Contact(accel=jnp.zeros(6), force=F, corner_accel=jnp.zeros((4, 3)),
                   slip_direction=jnp.zeros((4, 2)), loads=ld)


def _motion_contact_rope(ld: Loads, scenario: Scenario, c: Constants, phase: Phase,
                         settings: Settings) -> Contact:
    return jax.lax.cond(phase.rope == ROPE_TAUT, _motion_contact_taut, _motion_contact_free, ld, scenario, c,
                        phase, settings)


def _contact_problem(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings):
    """M⁻¹, the sliding directions t̂_i, the force maps P_i and row selectors of `_maps`, and the corner
    accelerations the contact forces must add (Baumgarte target minus the unconstrained ones)."""
    Minv = _mass_inverse(scenario, c)
    tdir = slip_directions(ld.corner_velocity, phase.slip_hint, settings.slip_velocity)
    P, s_rows = _maps(phase.contact, tdir, scenario.foundation.friction_coefficient)
    beta = settings.baumgarte
    z_only = jnp.array([0.0, 0.0, 1.0])
    a_free = jnp.einsum("kij,j->ki", ld.jacobians, Minv @ ld.generalised_force) + ld.bias
    a_target = -2.0 * beta * ld.corner_velocity - beta**2 * ld.corners[:, 2:3] * z_only
    return Minv, tdir, P, s_rows, a_target - a_free


def _contact_from_multipliers(ld: Loads, Minv, tdir, P, lam) -> Contact:
    """Corner forces F_i = P_i λ_i and the resulting body and corner accelerations."""
    F = jnp.einsum("kij,kj->ki", P, lam.reshape(4, 3))
    accel = Minv @ (ld.generalised_force + jnp.einsum("kij,ki->j", ld.jacobians, F))
    corner_accel = jnp.einsum("kij,j->ki", ld.jacobians, accel) + ld.bias
    return Contact(accel=accel, force=F, corner_accel=corner_accel, slip_direction=tdir, loads=ld)


def _motion_contact_free(ld: Loads, scenario: Scenario, c: Constants, phase: Phase,
                         settings: Settings) -> Contact:
    Minv, tdir, P, s_rows, target = _contact_problem(ld, scenario, c, phase, settings)
    lam = solve_contact_system(ld.jacobians, Minv, P, s_rows, target, scenario.load.mass, settings.rcond)
    return _contact_from_multipliers(ld, Minv, tdir, P, lam)


def _motion_contact_taut(ld: Loads, scenario: Scenario, c: Constants, phase: Phase,
                         settings: Settings) -> Contact:
    """The moving load with a taut inextensible rope: unknowns λ (12) and the tension S, from "constrained
    corner accelerations vanish" (Baumgarte-stabilised) and d²|AB|/dt² = `rope_accel_target`, with the
    boom tip's acceleration (2.13) m_0 a_A = boom force - S e - m_0 g."""
    Minv, tdir, P, s_rows, target = _contact_problem(ld, scenario, c, phase, settings)
    e = ld.rope_direction
    a_B_free = ld.rope_jacobian @ (Minv @ ld.generalised_force) + ld.rope_bias
    rhs_s = (jnp.dot(e, _tip_free_accel(ld, scenario)) - jnp.dot(e, a_B_free) + ld.rope_curvature
             - rope_accel_target(ld, settings))
    lam, S = solve_rope_contact_system(ld.jacobians, Minv, P, s_rows, target, ld.rope_generalised,
                                       scenario.boom.tip_mass, rhs_s, scenario.load.mass, settings.rcond)
    return _contact_from_multipliers(with_tension(ld, S, True), Minv, tdir, P, lam)


def contact_dynamics(t: Scalar, y: State, scenario: Scenario, c: Constants, phase: Phase,
                     settings: Settings, inextensible: bool = False) -> Contact:
    """Contact forces and accelerations of the load in the contact configuration `phase`. With
    `inextensible` (a Python bool: the rope model, fixed for a whole solve) the rope is the constraint
    (2.15), taut or slack by `phase.rope`, and a taut rope's tension is solved together with the contact
    forces (`Contact.loads` carries it); without, the elastic rope (2.14)."""
    ld = loads(t, y, scenario, c)
    if inextensible:
        return _contact_rope(t, y, ld, scenario, c, phase, settings)
    return _contact_elastic(t, y, ld, scenario, c, phase, settings)


def _contact_elastic(t, y, ld, scenario, c, phase, settings) -> Contact:
    return jax.lax.cond(phase.rest, _rest_contact, _motion_contact_free, ld, scenario, c, phase, settings)


def _contact_rope(t, y, ld, scenario, c, phase, settings) -> Contact:
    ld = inextensible_loads(t, y, ld, scenario, c)
    return jax.lax.cond(phase.rest, _rest_contact_rope, _motion_contact_rope, ld, scenario, c, phase,
                        settings)


def _unpack(args):
    """`args = (scenario, constants, phase, settings[, inextensible])` -> the five, inextensible a bool."""
    scenario, c, phase, settings, *rest = args
    return scenario, c, phase, settings, bool(rest[0]) if rest else False


def vector_field(t: Scalar, y: State, args) -> State:
    """dy/dt of the rigid model in the phase `args = (scenario, constants, phase, settings[, inextensible])`
    (`inextensible`: a Python bool, the rope model of the solve, default False: the elastic rope)."""
    scenario, c, phase, settings, inextensible = _unpack(args)
    boom, g = scenario.boom, scenario.gravity
    ct = contact_dynamics(t, y, scenario, c, phase, settings, inextensible)
    ld = ct.loads
    moving = jnp.logical_not(phase.rest)  # a resting load is held fixed: only the boom tip moves
    body = dict(position=jnp.where(moving, y.velocity, 0.0), velocity=ct.accel[:3],
                quaternion=jnp.where(moving, kinematics.quat_rate(y.quaternion, y.angular_velocity), 0.0),
                angular_velocity=ct.accel[3:],
                friction_work=jnp.where(moving, -jnp.sum(ct.force[:, :2] * ld.corner_velocity[:, :2]), 0.0))
    F_rope = ld.rope_tension * ld.rope_direction
    tip_acc = (ld.boom_force - F_rope) / boom.tip_mass - g * jnp.array([0.0, 0.0, 1.0])
    return State(tip_position=y.tip_velocity, tip_velocity=tip_acc, friction_state=y.friction_state,
                 hoist_work=ld.rope_tension * ld.hoist_rate, damping_loss=ld.rope_loss + ld.boom_loss, **body)


# ------------------------------------------------------------------------------------------ guards


def rest_conditions(ld: Loads, scenario: Scenario, c: Constants):
    """For a load resting flat: `(tip_margin, rho)`, tip margin = min(N/G, distance of R from the edges / L)
    (> 0 while it neither lifts nor tips) and the exact friction utilisation ρ* (<= 1 while it can rest).
    Uses `statics.rest_statics` with the rope force in body axes (the load may have turned about Z)."""
    S_body = ld.rotation.T @ (ld.rope_tension * ld.rope_direction)
    st = statics.rest_statics(scenario, S_body)
    return jnp.minimum(st.margins[0], st.margins[3]), st.friction_utilisation


def raw_guards(t: Scalar, y: State, scenario: Scenario, c: Constants, phase: Phase,
               settings: Settings, inextensible: bool = False) -> Float[Array, "12"]:
    """The guards of `phase` without offsets, dimensionless (forces / G, heights / L, speeds / V); the
    phase is valid while all are > 0. Guards that do not apply (to a corner's mode, or to rest, or to the
    rope model and mode) are +1. `inextensible`: the rope model (see `contact_dynamics`)."""
    ld = loads(t, y, scenario, c, inextensible=inextensible)
    if inextensible:
        return jax.lax.cond(phase.rest, _rest_guards_rope, _motion_guards_rope, ld, scenario, c, phase,
                            settings)
    g = jax.lax.cond(phase.rest, _rest_guards, _motion_guards, ld, scenario, c, phase, settings)
    return jnp.concatenate([g, jnp.ones(2)])


def _rope_guards(ld: Loads, scenario: Scenario, phase: Phase) -> Float[Array, "2"]:
    """The inextensible rope: while taut, its tension S / G (it goes slack at 0); while slack,
    (l(t) - |AB|) / L (it becomes taut again at 0). +1 otherwise."""
    sc = scales(scenario)
    slack = jnp.where(phase.rope == ROPE_TAUT, ld.rope_tension / sc.force, 1.0)
    taut = jnp.where(phase.rope == ROPE_SLACK, -ld.stretch / sc.length, 1.0)
    return jnp.stack([slack, taut])


def _rest_guards(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings):
    tip, rho = rest_conditions(ld, scenario, c)
    return jnp.concatenate([jnp.ones(8), jnp.stack([tip, 1.0 - rho])])


def _rest_guards_rope(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings):
    ld = _rest_loads(ld, scenario, phase, settings)
    g = _rest_guards(ld, scenario, c, phase, settings)
    return jnp.concatenate([g, _rope_guards(ld, scenario, phase)])


def _motion_guards_rope(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings):
    ct = _motion_contact_rope(ld, scenario, c, phase, settings)
    g = _motion_guards(ld, scenario, c, phase, settings, ct)
    return jnp.concatenate([g, _rope_guards(ct.loads, scenario, phase)])


def _motion_guards(ld: Loads, scenario: Scenario, c: Constants, phase: Phase, settings: Settings, ct=None):
    sc = scales(scenario)
    ct = _motion_contact_free(ld, scenario, c, phase, settings) if ct is None else ct
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
    g_start = jnp.minimum(jnp.sum(vh * phase.slip_hint, axis=1) + 0.05 * v_stop,
                          2.0 * v_stop - speed) / sc.velocity
    g_slide = jnp.where(phase.starting, g_start, (speed - v_stop) / sc.velocity)
    g_tan = jnp.where(contact == STICK, (mu * N - T) / sc.force, jnp.where(contact == SLIDE, g_slide, 1.0))
    return jnp.concatenate([g_normal, g_tan, jnp.ones(2)])


def event_condition(t, y, args, **kwargs) -> Scalar:
    """min over the guards (+ offsets): > 0 while the phase is valid; its zero ends the phase."""
    scenario, c, phase, settings, inextensible = _unpack(args)
    return jnp.min(raw_guards(t, y, scenario, c, phase, settings, inextensible) + phase.guard_offset)


# ------------------------------------------------------------------------------------------ impacts


def impulse_response(y: State, scenario: Scenario, c: Constants, modes: Int[Array, "4"],
                     slip_dirs: Float[Array, "4 2"], normal_target: PerCorner, rcond) -> tuple:
    """Velocity jump of an impact with the ground: minimum-norm impulses P_i at the corners in `modes`
    (`STICK`: all three post-impact velocity components prescribed, tangential ones 0; `SLIDE`: normal only,
    with a tangential impulse -μ P_n t̂_i along `slip_dirs`; `FREE`: no impulse), such that the post-impact
    normal velocity of each involved corner equals `normal_target` (Newton's law: -e times the pre-impact
    one for the striking corner, 0 for persistent contacts).

    **Returns** `(velocity, angular_velocity, impulses (4, 3), corner_velocity_after (4, 3))`.
    """
    R = kinematics.quat_to_matrix(y.quaternion)
    Minv = _mass_inverse(scenario, c)
    jac = jax.vmap(lambda rho: jnp.concatenate([jnp.eye(3), -R @ kinematics.skew(rho)], axis=1))(
        c.corners_rel)
    u = jnp.concatenate([y.velocity, y.angular_velocity])
    v = jnp.einsum("kij,j->ki", jac, u)
    P, s_rows = _maps(modes, slip_dirs, scenario.foundation.friction_coefficient)
    target = jnp.concatenate([jnp.zeros((4, 2)), normal_target[:, None]], axis=1)
    lam = solve_contact_system(jac, Minv, P, s_rows, target - v, scenario.load.mass, rcond)
    imp = jnp.einsum("kij,kj->ki", P, lam.reshape(4, 3))
    du = Minv @ jnp.einsum("kij,ki->j", jac, imp)
    u1 = u + du
    return u1[:3], u1[3:], imp, jnp.einsum("kij,j->ki", jac, u1)


def rope_impulse_response(t: Scalar, y: State, scenario: Scenario, c: Constants, modes: Int[Array, "4"],
                          slip_dirs: Float[Array, "4 2"], normal_target: PerCorner, rcond) -> tuple:
    """The jerk of the inextensible rope: a plastic impulse P >= 0 along the rope that sets the rate
    d|AB|/dt to the hoist's dl/dt = -ds/dt, shared by the boom tip (-P e) and the load (+P e at B), with
    the corners in `modes` taking impulses as in `impulse_response` (post-jerk normal velocity
    `normal_target`; sticking corners do not slip; sliding ones take -μ P_n along `slip_dirs`). The same
    system serves a corner impact while the rope is taut (the rope keeps its rate).

    **Returns** `(velocity, angular_velocity, tip_velocity, corner impulses (4, 3), P, corner_velocity_after
    (4, 3))`.
    """
    ld = loads(t, y, scenario, c, inextensible=True)
    Minv = _mass_inverse(scenario, c)
    u = jnp.concatenate([y.velocity, y.angular_velocity])
    v = jnp.einsum("kij,j->ki", ld.jacobians, u)
    P, s_rows = _maps(modes, slip_dirs, scenario.foundation.friction_coefficient)
    m0 = scenario.boom.tip_mass
    target = jnp.concatenate([jnp.zeros((4, 2)), normal_target[:, None]], axis=1)
    lam, P_rope = solve_rope_contact_system(ld.jacobians, Minv, P, s_rows, target - v, ld.rope_generalised,
                                            m0, ld.rope_rate_error, scenario.load.mass, rcond)
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
    """What the trajectory reports at one saved instant (see `numerics.rigid_solve.RigidTrajectory`)."""

    corners: CornerVecs
    normal: PerCorner
    friction: CornerVecs
    rope_tension: Scalar
    energy: Energy
    euler: Float[Array, "3"]


def output(t: Scalar, y: State, scenario: Scenario, c: Constants, phase: Phase, settings: Settings,
           inextensible: bool = False) -> Output:
    ct = contact_dynamics(t, y, scenario, c, phase, settings, inextensible)
    ld = ct.loads
    return Output(corners=ld.corners, normal=ct.force[:, 2],
                  friction=ct.force.at[:, 2].set(0.0), rope_tension=ld.rope_tension,
                  energy=energy(y, ld, scenario, c), euler=kinematics.matrix_to_euler(ld.rotation))

