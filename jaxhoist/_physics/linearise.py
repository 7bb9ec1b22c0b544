"""The stiff part of the §3 model, linearised: generalised mass, damping and stiffness matrices over the nine
generalised velocities V = (v_C, ω, v_A) (mass centre [m/s], body angular velocity [rad/s], boom tip [m/s]).

Every fast mode of the elastic model is a force that depends on a corner's, the rope's or the boom tip's
velocity or displacement (../shared/notes/stiffness.md): the regularised friction slope μN_i/ε (3.3), the
foundation dampers h and springs k (3.1)-(3.2), the rope damper b_l and spring c_l (2.14), the boom springs
and dampers (2.13). Each acts through a point whose velocity is linear in V, u = G V, so its contribution to
the generalised force Q = Σ Gᵀ F has the derivatives

    D = ∂Q/∂V = Σ Gᵀ (∂F/∂u) G,    K = ∂Q/∂X = Σ Gᵀ (∂F/∂x) G + Σ Gᵀ (∂F/∂u) G^ω,

with X the generalised displacement (δx_C, δθ in body axes, δx_A). The second term of K is the corner
velocities turning with the body at fixed V, u_i = v_C + R (ω x ρ_i), so δu_i = -R [ω x ρ_i]x δθ = G^ω_i X:
while a corner sticks, ∂F/∂u holds the friction slope μN/ε and this term is as stiff as the contact itself
(paper-4.2 at μ = 0.55 tips about one sticking corner for seconds; without it the W steps there were 10x
shorter). The 3x3 (corner) and scalar (rope) force derivatives come from forward-mode derivatives of the
force laws themselves (`forces.py`, the friction law of the scenario), so any friction law is covered; what
is left out is slow: gyroscopic terms, the turning of the lever arms G at fixed force (|F| |ρ|, no friction
slope in it), the rope's velocity turning with the body, its transverse (geometric) stiffness S/|AB|, and
the friction law's internal state (bristle deflection). One term is deliberately not the derivative: near
the friction band a corner's slope along its sliding direction is raised towards the secant |T|/|u|
(`band_entry_slope`), so that a step carrying a sliding corner into the band stays implicit.

`Linearisation.solve` then solves the linear system of a linearly implicit (Rosenbrock-W) step for the
approximate Jacobian J that these matrices define on the full state (positions driven by velocities, velocity
rates by M⁻¹(D ΔV + K ΔX), everything else explicit), reduced to one 9x9 system per member. A W-method keeps
its order for any such approximation; the approximation only decides which modes are treated implicitly.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._typing import Quat, Scalar
from . import forces, kinematics
from .elastic import Constants, State
from .friction import AbstractFrictionLaw, RegularisedCoulomb
from .params import Scenario

Mat9 = Float[Array, "9 9"]


def _skew(r):
    """[r]x, the matrix of the cross product r x ·."""
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    o = jnp.zeros_like(x)
    return jnp.stack([jnp.stack([o, -z, y], -1), jnp.stack([z, o, -x], -1), jnp.stack([-y, x, o], -1)], -2)


_bar = jax.lax.optimization_barrier


def _mm(A, B):
    """A @ B over the last two axes, written out as broadcast products and sums, for single small products
    whose result is read once. Under `vmap`, where a product feeds many kernels, use `@`: XLA's CPU backend
    fuses written-out sums into every kernel that reads them and recomputes them there, while a batched
    dot is one kernel whose result is stored (see `Linearisation.solve`)."""
    n = A.shape[-1]
    acc = A[..., :, 0, None] * B[..., None, 0, :]
    for k in range(1, n):
        acc = acc + A[..., :, k, None] * B[..., None, k, :]
    return acc


def _mv(A, x):
    """A @ x written out (see `_mm`)."""
    n = A.shape[-1]
    acc = A[..., :, 0] * x[..., 0, None]
    for k in range(1, n):
        acc = acc + A[..., :, k] * x[..., k, None]
    return acc


def _dot(a, b):
    """a · b written out in index order: no dot or reduce kernel, so the sum is formed in the same order
    whatever the batch layout (a batched dot may be blocked differently by XLA's CPU backend for other
    device counts, which changed scans at 1e-7)."""
    acc = a[..., 0] * b[..., 0]
    for k in range(1, a.shape[-1]):
        acc = acc + a[..., k] * b[..., k]
    return acc


def _quat_xi(q: Quat) -> Float[Array, "4 3"]:
    """Ξ(q) with dq/dt = ½ Ξ(q) ω (`kinematics.quat_rate`); ΞᵀΞ = |q|² I."""
    w, x, y, z = q
    return jnp.array([[-x, -y, -z], [w, -z, y], [z, w, -x], [-y, x, w]])


class Linearisation(eqx.Module):
    """The generalised matrices of the model's stiff forces at one state, kept in their block structure.

    Over V = (v_C, ω, v_A): M = blockdiag(M_b, m_0 I), D = blockdiag(D_b, -diag c_A) - s_v a aᵀ,
    K = blockdiag(K_b, -diag k_A) - s_x a aᵀ, where the 6x6 blocks over (v_C, ω) hold the corners' forces,
    the diagonal tip block the boom's (2.13), and the rank-one terms the rope (2.14), whose stretch rate is
    aᵀV + ds/dt.

    - `body_mass`: M_b = blockdiag(m I, J) [kg, kg m²]; `body_damping` D_b, `body_stiffness` K_b (corner
      forces; D_b negative semi-definite up to the small friction-normal coupling).
    - `tip_mass`: m_0 [kg]; `tip_damping`, `tip_stiffness`: the boom's c_A [N s/m], k_A [N/m].
    - `rope_direction`: a (9,); `rope_damping`: s_v = ∂S/∂(dδ/dt) [N s/m];
      `rope_stiffness`: s_x = ∂S/∂δ [N/m].
    - `quaternion`: the orientation at which it was taken (to map quaternion rates to rotations).
    """

    body_mass: Float[Array, "6 6"]
    body_damping: Float[Array, "6 6"]
    body_stiffness: Float[Array, "6 6"]
    tip_mass: Scalar
    tip_damping: Float[Array, "3"]
    tip_stiffness: Float[Array, "3"]
    rope_direction: Float[Array, "9"]
    rope_damping: Scalar
    rope_stiffness: Scalar
    quaternion: Quat

    def dense(self) -> tuple[Mat9, Mat9, Mat9]:
        """(M, D, K) as dense 9x9 matrices (for tests and inspection; `factor` uses M and K)."""
        a = self.rope_direction
        z = jnp.zeros((9, 9))
        M = z.at[:6, :6].set(self.body_mass).at[6:, 6:].set(self.tip_mass * jnp.eye(3))
        D = z.at[:6, :6].set(self.body_damping).at[6:, 6:].set(-jnp.diag(self.tip_damping))
        K = z.at[:6, :6].set(self.body_stiffness).at[6:, 6:].set(-jnp.diag(self.tip_stiffness))
        return M, D - self.rope_damping * jnp.outer(a, a), K - self.rope_stiffness * jnp.outer(a, a)

    def factor(self, hg: Scalar):
        """Factors of S = M - hγ D - (hγ)² K (see `solve`): the LU factors of the 6x6 body block
        S_b = M_b - hγ D_b - (hγ)² K_b, the diagonal tip block s_A = m_0 + hγ c_A + (hγ)² k_A, the
        Sherman-Morrison map T = I - σ w aᵀ for the rope's rank-one term β a aᵀ (β = hγ s_v + (hγ)² s_x >= 0,
        w = B⁻¹a with B the block-diagonal part, σ = β/(1 + β aᵀw)), so that S⁻¹ z = T B⁻¹z, and the body
        rows' right-hand-side maps hγ M_b, (hγ)² K_b - (hγ)² s_x a_b a_bᵀ (from the body's X) and
        -(hγ)² s_x a_b a_tᵀ (from the tip's displacement).

        The LU is taken without pivoting: S_b is M_b (positive definite) plus hγ times the dissipative
        part -D_b and (hγ)² times the restoring part -K_b, both positive semi-definite up to the small
        non-symmetric friction-normal coupling, so elimination in the natural order is stable. It is written
        out, so that a vmapped batch runs it as elementwise arithmetic over the members. The tip rows'
        right-hand side is diagonal and formed in `solve`: building the earlier 9x18 map [hγ M, (hγ)² K] of
        the whole right-hand side took a quarter of the linearisation's time (a profile of 256 vmapped
        members). Writing T out as z - σ w (aᵀz) instead of the product T z was tried and not kept: no faster
        (`bench_w_step.py --lanes 16,256 --kinds lin,w`: 0.92x-1.03x), and its rounding differed between
        the forward- and reverse-mode programs of one solve by 1e-11 relative (`tests/test_rosenbrock.py`
        asks for 1e-12)."""
        Sb = self.body_mass - hg * self.body_damping - hg * hg * self.body_stiffness
        lu = _lu(Sb)
        s_tip = self.tip_mass + hg * self.tip_damping + hg * hg * self.tip_stiffness
        a = self.rope_direction
        w = jnp.concatenate([_lu_solve(lu, a[:6]), a[6:] / s_tip])
        beta = hg * self.rope_damping + hg * hg * self.rope_stiffness
        T = jnp.eye(9) - (beta / (1.0 + beta * _dot(a, w))) * w[:, None] * a[None, :]
        # the right-hand side's maps from r_V and from X (the rope's -s_x a aᵀ included)
        hg2 = hg * hg
        a_b, a_t = a[:6], a[6:]
        sx = hg2 * self.rope_stiffness
        K_bb = hg2 * self.body_stiffness - sx * a_b[:, None] * a_b[None, :]
        K_bt = -sx * a_b[:, None] * a_t[None, :]
        return lu, s_tip, T, hg * self.body_mass, K_bb, K_bt

    def solve(self, factors, r: State, hg: Scalar) -> State:
        """u with (I/(hγ) - J) u = r, J the approximate Jacobian described in the module docstring.

        Positions follow their velocities, u_x = hγ (r_x + ∂ẋ/∂V u_V); the velocities solve
        S u_V = hγ (M r_V + hγ K P r_x) with P the map from the position part of the state to X
        (δθ = 2 Ξᵀ δq/|q|², so that P ∂ẋ/∂V = I); everything else is explicit, u = hγ r.

        The body block's products M_b r_V and K_b P r_x are batched matrix-vector products (`@`): on XLA's
        CPU backend each is one kernel whose result is stored, where written-out sums were fused into every
        kernel that reads them and recomputed there.
        """
        lu, s_tip, T, M_h, K_bb, K_bt = factors
        q = self.quaternion
        xi = _quat_xi(q)
        a = self.rope_direction
        r_V = jnp.concatenate([r.velocity, r.angular_velocity])
        r_X = jnp.concatenate([r.position, 2.0 * _mv(xi.T, r.quaternion) / _dot(q, q)])
        hg2 = hg * hg
        # the rope's stiffness -s_x a aᵀ acts on the whole X, the tip's displacement included
        rope = hg2 * self.rope_stiffness * ((a[:6] @ r_X) + _dot(a[6:], r.tip_position))
        rhs_b = M_h @ r_V + K_bb @ r_X + K_bt @ r.tip_position
        rhs_a = (hg * self.tip_mass) * r.tip_velocity - (hg2 * self.tip_stiffness) * r.tip_position
        z = jnp.concatenate([_lu_solve(lu, rhs_b), (rhs_a - rope * a[6:]) / s_tip])
        u_V = T @ z
        u_v, u_w, u_a = u_V[:3], u_V[3:6], u_V[6:]
        return State(
            position=hg * (r.position + u_v),
            velocity=u_v,
            quaternion=hg * (r.quaternion + 0.5 * _mv(xi, u_w)),
            angular_velocity=u_w,
            tip_position=hg * (r.tip_position + u_a),
            tip_velocity=u_a,
            friction_state=hg * r.friction_state,
            hoist_work=hg * r.hoist_work,
            damping_loss=hg * r.damping_loss,
            friction_work=hg * r.friction_work,
        )


def _lu(S):
    """Doolittle LU of a small square matrix without pivoting, unrolled: the factors as nested lists of
    scalars ((L - I) + U) and the reciprocal pivots."""
    n = S.shape[0]
    a = [[S[i, j] for j in range(n)] for i in range(n)]
    inv = []
    for k in range(n):
        p = 1.0 / a[k][k]
        inv.append(p)
        for i in range(k + 1, n):
            lik = a[i][k] * p
            a[i][k] = lik
            for j in range(k + 1, n):
                a[i][j] = a[i][j] - lik * a[k][j]
    return a, inv


def _lu_solve(lu, b):
    a, inv = lu
    n = len(inv)
    y = [b[i] for i in range(n)]
    for i in range(n):
        for k in range(i):
            y[i] = y[i] - a[i][k] * y[k]
    y = _bar(y)
    x = [None] * n
    for i in reversed(range(n)):
        acc = y[i]
        for k in range(i + 1, n):
            acc = acc - a[i][k] * x[k]
        x[i] = acc * inv[i]
    return jnp.stack(_bar(x))


BAND_ENTRY_WIDTH = 2.0
"""k of `band_entry_slope`: corners slower than about k ε [m/s] get the secant friction slope in W [-]."""


def band_entry_slope(
    law: AbstractFrictionLaw,
    mu: Scalar,
    normal: Float[Array, "4"],
    velocity: Float[Array, "4 2"],
    dT_dux: Float[Array, "4 2"],
    dT_duy: Float[Array, "4 2"],
) -> tuple[Float[Array, "4 2"], Float[Array, "4 2"]]:
    """W's friction slope for corners about to enter the regularisation band: the columns (∂T/∂u_x,
    ∂T/∂u_y) [N s/m] of each corner's friction slope, with the slope along the sliding direction raised
    towards the secant |T|/|u| for corners near the band.

    For `RegularisedCoulomb`, T = -μN u/s with s = sqrt(|u|² + ε²) (μ [-], N [N], u the corner's horizontal
    velocity [m/s], ε its `regularisation_velocity` [m/s]), the exact slope is μN/s across the sliding
    direction but only μN ε²/s³ along it: nearly nothing for a corner sliding at a few ε, while inside the
    band |u| < ε it is μN/ε. A step that carries a decelerating corner into the band so meets that slope
    explicitly and is rejected until h is tiny (at ε = 1e-4 m/s 31 % of the steps were rejected and the
    slowest member took 7x the steps of ε = 1e-3; a full-Jacobian W took as many). The secant μN/s is the
    slope of the chord from the corner's velocity to u = 0, where T vanishes too: with it in W the step
    decays the corner's velocity towards the band rather than through it. Every corner gets

        along = μN ε²/s³ + w (μN/s - μN ε²/s³) = μN ε²/s³ + w μN |u|²/s³,   w = 1/(1 + (|u|/(k ε))⁴),

    k = `BAND_ENTRY_WIDTH`, i.e. C' = C - (w μN/s³) u uᵀ (finite at u = 0, where C is already μN/ε I). Only
    slow corners: the secant for every corner halved the steps at ε = 1e-4 but its over-damped steps of fast
    sliding corners fooled the embedded error estimate (the worst final mass centre of paper-4.2 at
    ε = 1e-3 1.35 cm off instead of 0.11 cm). A W-method keeps its order for any W, and W is not
    differentiated (`rosenbrock.w_step`), so this changes only which steps are accepted.

    Measured with a script since removed (paper-4.2 over 25 s, μ evenly in [0.1, 0.6], 201 saved times,
    default tolerances; errors: final mass centre against Tsit5 at rtol 1e-9), without -> with (k = 2):

    - ε = 1e-4, 16 members: steps 191 635 -> 76 721 (max 32 123 -> 7 058, rejected 31 % -> 11 %), worst
      error 1.62 -> 0.42 cm; 1.17x the steps at ε = 1e-3 (65 718) instead of 2.9x;
    - ε = 1e-3, 32 members: steps 132 622 -> 131 104 (max 4 538 -> 4 448), worst error 0.12 -> 0.10 cm
      (median 0.030 -> 0.033 cm). k = 3 and 4 took 2 % and 7 % fewer steps at ε = 1e-4, but at ε = 1e-3
      k = 3 was 0.14 cm off, and k = 4 at atol 3e-5 0.62 cm (k = 2 there: 0.20 cm, exact slope 0.24 cm);
    - wall time of the 16-member vmapped solve (best of 5, after compilation): ε = 1e-4 0.54 s against
      0.34 s at ε = 1e-3, 1.6x (without: 2.3 s, 6.7x); the cost per step is unchanged (74-80 µs per
      lock-step of the 16 members at ε = 1e-3, with and without the term).

    Other friction laws keep their exact slope (`BristleFriction` has no band: its stiffness is μN/δ in
    its own state)."""
    if not isinstance(law, RegularisedCoulomb):
        return dT_dux, dT_duy
    # Barriers on the inputs and the result: without them XLA's CPU backend fused the corner velocities and
    # normal forces into these few elementwise operations and recomputed them there; a vmapped solve of
    # paper-4.2 (16 members, 25 s) took 93 instead of 74 µs per lock-step, with them 74 (as without the term).
    normal, velocity, dT_dux, dT_duy = _bar((normal, velocity, dT_dux, dT_duy))
    eps = law.regularisation_velocity
    u2 = jnp.sum(velocity * velocity, axis=-1)
    s2 = u2 + eps * eps
    width2 = (BAND_ENTRY_WIDTH * eps) ** 2
    w = 1.0 / (1.0 + (u2 / width2) ** 2)
    c = w * mu * normal / (s2 * jnp.sqrt(s2))
    dT_dux = dT_dux - (c * velocity[:, 0])[:, None] * velocity
    dT_duy = dT_duy - (c * velocity[:, 1])[:, None] * velocity
    return _bar((dT_dux, dT_duy))


def linearise(
    t: Scalar, y: State, args: tuple[Scenario, Constants], band_entry: bool = True
) -> Linearisation:
    """The `Linearisation` of the elastic model's stiff forces at (t, y) (pure; `args` as for
    `elastic.vector_field`). `band_entry`: W's friction slope near the band is the band-entry slope
    (`band_entry_slope`, the default of the state's solve); False: the exact slope
    (`linearise_exact_slope`)."""
    scenario, c = args
    fnd, rope, boom, load = scenario.foundation, scenario.rope, scenario.boom, scenario.load
    R = kinematics.quat_to_matrix(y.quaternion)
    omega = y.angular_velocity
    eye3 = jnp.eye(3)

    # Corners, eqs. (3.1)-(3.3): u_i = v_C + R (ω x ρ_i) = G_i (v_C, ω), G_i = [I, -R [ρ_i]x].
    G = jnp.concatenate([jnp.broadcast_to(eye3, (4, 3, 3)), -R[None] @ _skew(c.corners_rel)], axis=-1)
    corners = kinematics.points_world(y.position, R, c.corners_rel)
    corner_vel = kinematics.points_velocity(y.velocity, R, omega, c.corners_rel)
    p, p_dot = -corners[:, 2], -corner_vel[:, 2]
    u_h = corner_vel[:, :2]
    ones = jnp.ones(4)

    def normal(pp, pd):
        return forces.ground_normal(pp, pd, fnd.stiffness, fnd.damping, fnd.damping_onset)[0]

    N, dN_dp = jax.jvp(lambda pp: normal(pp, p_dot), (p,), (ones,))
    dN_dpd = jax.jvp(lambda pd: normal(p, pd), (p_dot,), (ones,))[1]

    def friction(n, u):
        return fnd.friction.force(fnd.friction_coefficient, n, u, y.friction_state)

    dT_dN = jax.jvp(lambda n: friction(n, u_h), (N,), (ones,))[1]  # (4, 2)
    dT_dux = jax.jvp(lambda u: friction(N, u), (u_h,), (jnp.stack([ones, 0 * ones], -1),))[1]
    dT_duy = jax.jvp(lambda u: friction(N, u), (u_h,), (jnp.stack([0 * ones, ones], -1),))[1]
    if band_entry:
        dT_dux, dT_duy = band_entry_slope(fnd.friction, fnd.friction_coefficient, N, u_h, dT_dux, dT_duy)
    # ∂F_i/∂u_i and ∂F_i/∂x_i in world axes (F = (T_x, T_y, N); Z_i = -p_i).
    dN_dz, dN_dw = -dN_dp, -dN_dpd
    zero = jnp.zeros(4)
    C = jnp.stack(
        [
            jnp.stack([dT_dux[:, 0], dT_duy[:, 0], dT_dN[:, 0] * dN_dw], -1),
            jnp.stack([dT_dux[:, 1], dT_duy[:, 1], dT_dN[:, 1] * dN_dw], -1),
            jnp.stack([zero, zero, dN_dw], -1),
        ],
        -2,
    )
    Kc = jnp.stack(
        [
            jnp.stack([zero, zero, dT_dN[:, 0] * dN_dz], -1),
            jnp.stack([zero, zero, dT_dN[:, 1] * dN_dz], -1),
            jnp.stack([zero, zero, dN_dz], -1),
        ],
        -2,
    )
    # D_b = Σ_i G_iᵀ C_i G_i, K_b = Σ_i G_iᵀ K_i G_i as batched matrix products: on XLA's CPU backend a
    # product is one kernel whose result is stored, where written-out sums are recomputed in every kernel
    # that reads them (here the unrolled LU of `factor`).
    # Turning the body at fixed V turns the corner velocities too: δu_i = R (δθ x (ω x ρ_i)) = G^ω_i δθ,
    # G^ω_i = -R [ω x ρ_i]x. Through ∂F_i/∂u_i that is a stiffness in δθ of size μN/ε |ω| |ρ| while a corner
    # sticks (~1e8 N/rad on paper-4.2 at μ = 0.55, tipping about one sticking corner); left out, the W step
    # met it explicitly and took 3x the steps over 25 s there (a script since removed).
    turn = -R[None] @ _skew(jnp.cross(omega, c.corners_rel))
    CG = _mm(C, G)
    # K_i G_i: K_i has only its z column k_i; C_i G^ω_i = [0, C_i turn_i]
    KG = Kc[:, :, 2, None] * G[:, None, 2, :] + jnp.pad(_mm(C, turn), ((0, 0), (0, 0), (3, 0)))
    DK = jnp.einsum("irk,irj->kj", G, jnp.concatenate([CG, KG], axis=-1))
    D_body, K_body = DK[:, :6], DK[:, 6:]

    # Rope, eq. (2.14): S(δ, dδ/dt) along e (from B towards A); dδ/dt = eᵀ(v_A - v_B) + ds/dt.
    G_B = jnp.concatenate([eye3, -_mm(R, _skew(c.attachment_rel))], axis=-1)
    B = kinematics.points_world(y.position, R, c.attachment_rel[None])[0]
    v_B = kinematics.points_velocity(y.velocity, R, omega, c.attachment_rel[None])[0]
    AB = y.tip_position - B
    L = forces.safe_norm(AB)
    e = AB / jnp.maximum(L, 1e-12)
    s_dot = scenario.hoist.rate(t)
    stretch = L - (c.rope_length - scenario.hoist.shortening(t))
    rate = _dot(y.tip_velocity - v_B, e) + s_dot

    def tension(d, dd):
        return forces.rope_tension(d, dd, rope.stiffness, rope.damping, rope.damping_onset)[0]

    dS_dd = jax.jvp(lambda d: tension(d, rate), (stretch,), (jnp.ones_like(stretch),))[1]
    dS_drate = jax.jvp(lambda dd: tension(stretch, dd), (rate,), (jnp.ones_like(rate),))[1]
    a = jnp.concatenate([-_mv(G_B.T, e), e])  # Qᵀe: the rope's relative velocity eᵀ(v_A - v_B) = aᵀV

    M_b = jnp.zeros((6, 6)).at[:3, :3].set(load.mass * eye3).at[3:, 3:].set(c.inertia)
    return Linearisation(
        body_mass=M_b,
        body_damping=D_body,
        body_stiffness=K_body,
        tip_mass=boom.tip_mass,
        tip_damping=boom.damping,
        tip_stiffness=boom.stiffness,
        rope_direction=a,
        rope_damping=dS_drate,
        rope_stiffness=dS_dd,
        quaternion=y.quaternion,
    )


def linearise_exact_slope(t: Scalar, y: State, args: tuple[Scenario, Constants]) -> Linearisation:
    """`linearise` with the friction law's exact slope everywhere (no band-entry slope): the W of the
    forward-mode sensitivity solve (`numerics.sensitivity`). There the band-entry slope's over-damped steps
    fooled the error estimate of the sensitivities: d(final mass centre)/dμ over 64 μ of paper-4.2, 25 s,
    against central differences of Tsit5 at rtol 1e-10 on 8 of them, was up to 15 % off with it (at
    μ = 0.6) and 1.9 % without, at about the same cost (12.2x and 10.2x the plain scan; `python
    experiments/benchmarks/w_sensitivity.py --n 64 --t1 25 --ref 8 --weights 0.1`)."""
    return linearise(t, y, args, band_entry=False)
