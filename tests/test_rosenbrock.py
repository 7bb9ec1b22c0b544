"""The default integrator: the Rosenbrock-W method (ROS34PW2) with the model's structured linearisation.

Checked here: its order on a smooth problem for exact *and* deliberately wrong Jacobians (the W property the
solver relies on), the structured linearisation against the model's own derivatives, agreement with a tight
Tsit5 reference on the preset, transforms (vmap, jacfwd, grad), and a member stiff enough to stall an explicit
solver.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import N_SAVE, SOLVE_OPTIONS, TSIT5_CAPPED, stiff_member

import jaxhoist as jh
from jaxhoist._numerics import persistent_cache as pc
from jaxhoist._numerics.rosenbrock import ROS34PW2, RosenbrockW, w_step
from jaxhoist._physics import kinematics
from jaxhoist._physics.elastic import vector_field
from jaxhoist._physics.equilibrium import initial_state
from jaxhoist._physics.linearise import BAND_ENTRY_WIDTH, band_entry_slope, linearise, linearise_exact_slope

MU = "foundation.friction_coefficient"
T1 = 2.0
TS = np.linspace(0.0, T1, N_SAVE)


class _DenseW(eqx.Module):
    """A dense W for a flat state: (I/(hγ) - W) u = r by LU."""

    W: jax.Array

    def factor(self, hg):
        return jax.scipy.linalg.lu_factor(jnp.eye(self.W.shape[0]) / hg - self.W)

    def solve(self, lu, r, hg):
        return jax.scipy.linalg.lu_solve(lu, r)


def _smooth_rhs(t, y, args):
    # A stiff-ish, nonlinear, non-autonomous test problem with a known smooth solution structure.
    return jnp.array([-50.0 * (y[0] - jnp.cos(t)) + y[1] ** 2, -y[1] + 0.5 * jnp.sin(y[0])])


def _fixed_solve(W_of, h, T=1.0, time_derivative=False):
    n = round(T / h)
    y = jnp.array([1.0, 0.5])

    def body(i, y):
        lin = lambda t, y, a: _DenseW(W_of(t, y))  # noqa: E731
        return w_step(_smooth_rhs, lin, ROS34PW2, i * h, y, h, None, time_derivative=time_derivative)[0]

    return jax.lax.fori_loop(0, n, body, y)


@pytest.mark.parametrize(
    "which, time_derivative",
    [("exact", False), ("wrong", False), ("exact", True), ("wrong", True)],
)
def test_order_three_for_exact_and_wrong_jacobians(which, time_derivative):
    """Halving the step divides the error by ~2^3 whether W is the true Jacobian or a wrong one (only its
    diagonal, scaled by 0.7): the W-method keeps its order, which is what licenses the structured
    linearisation of the model; with and without the ∂f/∂t term in the stages."""

    def jac(t, y):
        J = jax.jacfwd(lambda yy: _smooth_rhs(t, yy, None))(y)
        return J if which == "exact" else 0.7 * jnp.diag(jnp.diag(J))

    ref = _fixed_solve(jac, 1.0 / 4096, time_derivative=time_derivative)
    errs = [
        float(jnp.max(jnp.abs(_fixed_solve(jac, h, time_derivative=time_derivative) - ref)))
        for h in (1 / 64, 1 / 128, 1 / 256)
    ]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 2.7), (errs, orders)


def test_looped_stages_equal_the_unrolled_ones():
    """`w_step(stage_loop=True)` (the stages after the first in a `fori_loop`, the forward sensitivities'
    augmented system) is the same step as the unrolled stages: on a pytree state (the smooth problem and a
    copy of it scaled by 2, as a tuple) with a wrong W and the ∂f/∂t term, y1, the error and f1 agree to
    rounding (the sums run in another order)."""

    def rhs(t, y, args):
        return (_smooth_rhs(t, y[0], args), 2.0 * _smooth_rhs(t, 0.5 * y[1], args))

    def lin(t, y, a):
        J = jax.jacfwd(lambda yy: _smooth_rhs(t, yy, None))(y[0])
        d = _DenseW(0.7 * jnp.diag(jnp.diag(J)))
        return _TupleW(d)

    y0 = (jnp.array([1.0, 0.5]), jnp.array([2.0, 1.0]))
    t, h = jnp.asarray(0.3), 0.05
    unrolled = w_step(rhs, lin, ROS34PW2, t, y0, h, None, time_derivative=True)
    looped = w_step(rhs, lin, ROS34PW2, t, y0, h, None, time_derivative=True, stage_loop=True)
    for a, b in zip(jax.tree_util.tree_leaves(unrolled), jax.tree_util.tree_leaves(looped), strict=True):
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-13, atol=1e-15)
    # the step is a real one: it moved the state, and its error estimate is not zero
    assert float(jnp.abs(unrolled[0][0] - y0[0]).max()) > 1e-3 and float(jnp.abs(unrolled[1][0]).max()) > 0


class _TupleW(eqx.Module):
    """The same W on both blocks of a (y, y') tuple state."""

    inner: _DenseW

    def factor(self, hg):
        return self.inner.factor(hg)

    def solve(self, lu, r, hg):
        return (self.inner.solve(lu, r[0], hg), self.inner.solve(lu, r[1], hg))


def test_time_derivative_on_a_ramped_stiff_system():
    """y' = λ (y - c t), λ = -1e6 1/s (a stiff spring pulled at a constant rate, like the hoisted rope), from
    its particular solution y_p = c t + c/λ, five steps with |hλ| = 1e4. With the exact W the steps stay on
    y_p to rounding with and without γ_i h ∂f/∂t in the stages. With W off by ±30 % (the structured W of the
    model is not the Jacobian either) they leave it, and the ∂f/∂t term, the time column of the autonomous
    system's W, more than halves the error (measured 2.3x at 0.7 λ, 4.3x at 1.3 λ)."""
    lam, c, h = -1e6, 0.3, 1e-2

    def rhs(t, y, args):
        return lam * (y - c * t)

    def error(w_factor, with_t):
        y, t = jnp.array([c / lam]), 0.0
        lin = lambda t, y, a: _DenseW(jnp.array([[w_factor * lam]]))  # noqa: E731
        for _ in range(5):
            y = w_step(rhs, lin, ROS34PW2, t, y, h, None, time_derivative=with_t)[0]
            t += h
        return abs(float(y[0]) - (c * t + c / lam))

    assert error(1.0, True) < 1e-15 and error(1.0, False) < 1e-15
    for w_factor in (0.7, 1.3):
        with_t, without = error(w_factor, True), error(w_factor, False)
        assert without > 1e-6, without  # the inexact W's error is real (3e-3 and 2e-4)
        assert with_t < 0.5 * without, (w_factor, with_t, without)


def _sliding_state(sc):
    """A state of paper-4.2 with every corner pressed in and sliding slowly (inside the friction
    regularisation for two corners), the rope taut."""
    y0, c = initial_state(sc)
    y = eqx.tree_at(
        lambda s: (s.velocity, s.angular_velocity),
        y0,
        (jnp.array([2e-4, -1e-4, -1e-3]), jnp.array([1e-4, -2e-4, 3e-4])),
    )
    return y, (sc, c)


def _turning_state(sc):
    """A state of paper-4.2 with every corner pressed in and the box turning at ω = (0.3, -0.4, 0.2) rad/s
    (body axes) about corner D, which sticks (zero velocity, inside the friction regularisation) while the
    others slide at ~1 m/s: the orientation moves the corner velocities at fixed V through the friction
    slope μN/ε, the stiffest term in δθ."""
    y0, c = initial_state(sc)
    omega = jnp.array([0.3, -0.4, 0.2])
    R = kinematics.quat_to_matrix(y0.quaternion)
    v_c = -R @ jnp.cross(omega, c.corners_rel[0])
    y = eqx.tree_at(lambda s: (s.velocity, s.angular_velocity), y0, (v_c, omega))
    return y, (sc, c)


@eqx.filter_jit
def _linearisation_and_derivatives(y, args):
    """`(M⁻¹D, ∂a/∂V, M⁻¹K, ∂a/∂X)` at the state `y`: the approximations from `linearise_exact_slope` (the
    linearisation with the friction law's exact slope, without the band-entry slope) and the true
    derivatives of the model's accelerations a [m/s², rad/s²] with respect to the generalised velocities V
    and displacements X, by jacfwd of `vector_field`. One compiled program for both parametrised states
    (evaluated op by op, the first state took 23 s)."""
    t0 = jnp.asarray(0.0)
    lin = linearise_exact_slope(t0, y, args)
    M, D, K = lin.dense()

    def accel_of_V(V):
        yy = eqx.tree_at(
            lambda s: (s.velocity, s.angular_velocity, s.tip_velocity), y, (V[:3], V[3:6], V[6:])
        )
        f = vector_field(t0, yy, args)
        return jnp.concatenate([f.velocity, f.angular_velocity, f.tip_velocity])

    def accel_of_X(X):
        dq = jnp.concatenate([jnp.ones(1), 0.5 * X[3:6]])  # small rotation δθ in body axes
        q = y.quaternion
        w1, x1, y1, z1 = q
        w2, x2, y2, z2 = dq
        qn = jnp.array(
            [
                w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            ]
        )
        yy = eqx.tree_at(
            lambda s: (s.position, s.quaternion, s.tip_position),
            y,
            (y.position + X[:3], qn, y.tip_position + X[6:]),
        )
        f = vector_field(t0, yy, args)
        return jnp.concatenate([f.velocity, f.angular_velocity, f.tip_velocity])

    V0 = jnp.concatenate([y.velocity, y.angular_velocity, y.tip_velocity])
    A_true = jax.jacfwd(accel_of_V)(V0)
    B_true = jax.jacfwd(accel_of_X)(jnp.zeros(9))
    Minv = jnp.linalg.inv(M)
    return Minv @ D, A_true, Minv @ K, B_true


@pytest.mark.parametrize("state", [_sliding_state, _turning_state], ids=["sliding", "turning"])
def test_linearisation_matches_the_model_derivatives(paper42, state):
    """M⁻¹D and M⁻¹K of `linearise` equal the derivatives of the model's accelerations with respect to the
    generalised velocities and displacements, up to the slow terms it leaves out (gyroscopic, the rotation
    of the force lever arms at fixed force, transverse rope stiffness): 1e-3 of the largest entry. In the
    turning state the largest entries of ∂(accelerations)/∂θ come from the corner velocities turning with the
    body (`linearise`'s G_turn): without that term the check failed there (964 against 1e-3 x 1e4 1/s²).
    Checked with the exact friction slope: the band-entry slope, which W takes instead near the band on
    purpose (the sliding state's corners slide at < 2ε), is checked in
    `test_band_entry_slope_adds_damping_in_the_linearisation`."""
    y, args = state(paper42)
    MD, A_true, MK, B_true = _linearisation_and_derivatives(y, args)
    for approx, true in ((MD, A_true), (MK, B_true)):
        scale = float(jnp.max(jnp.abs(true)))
        assert scale > 100.0  # stiff: the check is not vacuous
        assert float(jnp.max(jnp.abs(approx - true))) < 1e-3 * scale, (
            float(jnp.max(jnp.abs(approx - true))) / scale
        )


def test_band_entry_slope_raises_the_along_slope_only_near_the_band():
    """W's friction slope (`band_entry_slope`) for ε = 1e-4 m/s, μ = 0.5, N = 1e5 N: a corner sliding at 2ε
    gets at least 0.25 μN/ε along its direction (the exact slope there is μN/(5^1.5 ε) = 0.089 μN/ε; the
    blend gives 0.27 μN/ε), the slope across it stays exact, a corner at 50ε keeps its exact slope to 1 %,
    a sticking corner (u = 0) keeps μN/ε I, and the bristle law, which has no band, is left alone."""
    eps, mu = 1e-4, 0.5
    law = jh.RegularisedCoulomb(eps)
    n = jnp.full(4, 1e5)
    d = jnp.array([0.6, -0.8])
    u = jnp.stack([2 * eps * d, 50 * eps * d, jnp.zeros(2), -0.5 * eps * d])
    e = lambda i: jnp.zeros((4, 2)).at[:, i].set(1.0)  # noqa: E731
    f = lambda v: law.force(mu, n, v, jnp.zeros((4, 0)))  # noqa: E731
    cx, cy = jax.jvp(f, (u,), (e(0),))[1], jax.jvp(f, (u,), (e(1),))[1]
    bx, by = band_entry_slope(law, jnp.asarray(mu), n, u, cx, cy)

    def slopes(cx, cy, i):  # -d·C d and -p·C p, p ⊥ d, for corner i [N s/m]
        C = jnp.stack([cx[i], cy[i]], -1)
        p = jnp.array([0.8, 0.6])
        return float(-d @ C @ d), float(-p @ C @ p)

    mun_eps = mu * 1e5 / eps
    along_exact, across_exact = slopes(cx, cy, 0)
    along, across = slopes(bx, by, 0)
    assert along_exact < 0.1 * mun_eps  # the exact slope just outside the band is small ...
    assert along > 0.25 * mun_eps  # ... and W's is raised towards the secant μN/s = 0.45 μN/ε
    np.testing.assert_allclose(across, across_exact, rtol=1e-12)
    along_exact, _ = slopes(cx, cy, 1)
    assert slopes(bx, by, 1)[0] < 1.01 * along_exact
    np.testing.assert_allclose(slopes(bx, by, 2), (mun_eps, mun_eps), rtol=1e-12)
    assert slopes(bx, by, 3)[0] > slopes(cx, cy, 3)[0]
    assert BAND_ENTRY_WIDTH == 2.0  # the width measured in band_entry_slope's docstring
    bristle = jh.BristleFriction()
    bx, by = band_entry_slope(bristle, jnp.asarray(mu), n, u, cx, cy)
    assert bx is cx and by is cy


def test_band_entry_slope_adds_damping_in_the_linearisation(paper42):
    """In the sliding state (every corner at < 2ε = 2 mm/s) the band-entry slope adds damping to D: D with it
    minus D with the exact slope is symmetric and negative semi-definite
    (Σ_i -w_i μN_i/s_i³ (G_iᵀu_i)(G_iᵀu_i)ᵀ over the corners), and not zero (its largest eigenvalue
    magnitude over 1 % of that of D's)."""
    y, args = _sliding_state(paper42)
    t0 = jnp.asarray(0.0)
    D_band = linearise(t0, y, args).dense()[1]
    D_exact = linearise_exact_slope(t0, y, args).dense()[1]
    diff = np.asarray(D_band - D_exact)
    scale = float(np.max(np.abs(np.linalg.eigvals(np.asarray(D_exact)))))
    np.testing.assert_allclose(diff, diff.T, atol=1e-9 * scale)
    ev = np.linalg.eigvalsh(0.5 * (diff + diff.T))
    assert ev.max() < 1e-9 * scale
    assert ev.min() < -0.01 * scale


def test_band_entry_slope_keeps_small_eps_cheap(paper42):
    """ε = 1e-4 m/s (10x below the preset) at μ = 0.6 over 5 s: the default solver takes fewer than 1 800
    steps (measured 1 063 + 304 rejected; with the exact friction slope in W, where every step carrying a
    sliding corner into the band was rejected down to a tiny h, 1 495 + 940). The saved times have
    default_run's shape, so the compiled core is shared."""
    sc = paper42.replace(**{MU: 0.6})
    sc = eqx.tree_at(lambda s: s.foundation.friction, sc, jh.RegularisedCoulomb(1e-4))
    r = jh.simulate(sc, jh.Times(ts=jnp.asarray(np.linspace(0.0, 5.0, N_SAVE))))
    assert int(r.status) == 0
    assert int(r.num_accepted_steps + r.num_rejected_steps) < 1_800


def test_solve_satisfies_the_dense_system(paper42):
    """`factor` + `solve` (LU of the body block, Sherman-Morrison for the rope, the right-hand side and
    the update as matrix products) give velocities u_V with S u_V = hγ (M r_V + hγ K r_X), S = M - hγ D -
    (hγ)² K from `dense()`, and positions that follow them, to 1e-12 of the right-hand side."""
    y, args = _sliding_state(paper42)
    lin = linearise(jnp.asarray(0.0), y, args)
    M, D, K = lin.dense()
    leaves, tree = jax.tree_util.tree_flatten(y)
    keys = jax.random.split(jax.random.PRNGKey(3), len(leaves))
    r = jax.tree_util.tree_unflatten(tree, [jax.random.normal(k, x.shape) for k, x in zip(keys, leaves)])
    for hg in (jnp.asarray(1e-4 * ROS34PW2.gamma), jnp.asarray(4e-3 * ROS34PW2.gamma)):
        u = lin.solve(lin.factor(hg), r, hg)
        q = y.quaternion
        xi = jnp.array([[-q[1], -q[2], -q[3]], [q[0], -q[3], q[2]], [q[3], q[0], -q[1]], [-q[2], q[1], q[0]]])
        r_V = jnp.concatenate([r.velocity, r.angular_velocity, r.tip_velocity])
        r_X = jnp.concatenate([r.position, 2.0 * xi.T @ r.quaternion / (q @ q), r.tip_position])
        u_V = jnp.concatenate([u.velocity, u.angular_velocity, u.tip_velocity])
        rhs = hg * (M @ r_V + hg * K @ r_X)
        S = M - hg * D - hg * hg * K
        assert float(jnp.max(jnp.abs(S @ u_V - rhs))) < 1e-12 * float(jnp.max(jnp.abs(rhs)))
        np.testing.assert_allclose(u.position, hg * (r.position + u.velocity), rtol=1e-14)
        np.testing.assert_allclose(u.tip_position, hg * (r.tip_position + u.tip_velocity), rtol=1e-14)
        np.testing.assert_allclose(
            u.quaternion, hg * (r.quaternion + 0.5 * xi @ u.angular_velocity), rtol=1e-14
        )


@pytest.fixture(scope="module")
def default_run(paper42):
    return jh.simulate(paper42, jh.Times(ts=TS))


def test_default_solver_is_rosenbrock_w():
    opts = jh.SolverOptions()
    assert isinstance(opts.solver, RosenbrockW)
    assert opts.solver.time_derivative
    ctrl = opts.stepsize_controller
    assert isinstance(ctrl, diffrax.PIDController)
    assert (ctrl.rtol, ctrl.atol, ctrl.pcoeff, ctrl.icoeff) == (5e-4, 1e-5, 0.3, 0.3)
    # tolerances alone keep the solver's PI coefficients; another solver gets diffrax's integral controller
    assert jh.SolverOptions(rtol=1e-6).stepsize_controller.pcoeff == 0.3  # pyright: ignore[reportAttributeAccessIssue]
    tsit5 = jh.SolverOptions(diffrax.Tsit5()).stepsize_controller
    assert (tsit5.rtol, tsit5.pcoeff, tsit5.icoeff) == (1e-6, 0, 1)  # pyright: ignore[reportAttributeAccessIssue]


def test_default_agrees_with_tight_reference(paper42, default_run):
    """The default solve of paper-4.2 over 2 s (corner lift, drag) is within 0.1 mm and 1e-4 rad of Tsit5 at
    rtol 1e-8, and within 0.1 % of its rope tension, at every saved time."""
    ref = jh.simulate(paper42, jh.Times(ts=TS), options=SOLVE_OPTIONS)
    assert int(default_run.status) == 0
    assert float(jnp.max(jnp.abs(default_run.position - ref.position))) < 1e-4
    assert float(jnp.max(jnp.abs(default_run.euler - ref.euler))) < 1e-4
    s_max = float(jnp.max(ref.rope_tension))
    assert float(jnp.max(jnp.abs(default_run.rope_tension - ref.rope_tension))) < 1e-3 * s_max
    # The energy balance closes to 5e-4 of the hoist work: the energy integrals are second-order trapezoidal
    # sums over the steps (w_step's `quadrature`), ~1e-4 of the hoist work at the default tolerance; through
    # the stages the damper loss alone was 3x too large (1.2 % of the hoist work over 25 s).
    hoist = float(default_run.hoist_work[-1])
    assert hoist > 1e4
    assert float(jnp.max(jnp.abs(default_run.energy_residual()))) < 5e-4 * hoist


def test_vmap_equals_single_solves(paper42):
    mus = jnp.array([0.2, 0.3, 0.45])
    # N_SAVE saved times over 1 s, as in test_stiff_member_solves: the single solves share default_run's
    # compiled core (the saved times' values may change, their number not; with its cubic Hermite dense
    # output the solver's steps do not depend on the saved times)
    ts = jnp.asarray(np.linspace(0.0, 1.0, N_SAVE))

    def final(mu):
        sc = eqx.tree_at(lambda s: s.foundation.friction_coefficient, paper42, mu)
        return jh.simulate(sc, jh.Times(ts=ts)).position[-1]

    batched = jax.vmap(final)(mus)
    # The vmapped and the single solves are different compiled programs, which round differently (1e-14 m
    # per step); at the default rtol 1e-3 that can change a step's acceptance, so the two agree to round-off
    # amplified by the step-size control (measured 2e-8 m after 1 s), not bit for bit: 1e-6 m is still
    # 1000x below what the tolerance allows.
    for k, mu in enumerate(mus):
        np.testing.assert_allclose(batched[k], final(mu), rtol=0, atol=1e-6)


# Forward mode at rtol 1e-7 over 0.5 s on 11 saved times, with tangents on μ and on the saved times: one
# compiled jvp program serves the derivative in μ (tangents (1, 0), with its primal the solve for the central
# differences) and the derivative in the saved times (tangents (0, 1)).
TS_HALF = jnp.asarray(np.linspace(0.0, 0.5, 11))
OPTS_F = jh.SolverOptions(rtol=1e-7, atol=1e-9, adjoint=diffrax.ForwardMode())


def _forward(paper42, mu, d_mu, d_ts, options=OPTS_F):
    """The solve of paper-4.2 at μ = `mu` on `TS_HALF` and its forward derivative along (d_mu, d_ts)."""

    def traj(m, ts):
        sc = eqx.tree_at(lambda s: s.foundation.friction_coefficient, paper42, m)
        return jh.simulate(sc, jh.Times(ts=ts), options=options)

    return jax.jvp(traj, (mu, TS_HALF), (d_mu, d_ts))


def test_forward_and_reverse_derivatives_match_central_differences(paper42):
    """d x_C(0.5 s)/dμ, forward (jacfwd: the sensitivity ODE) and reverse (grad: through the Rosenbrock-W
    steps), against central differences of the same solver at a tight tolerance (so both sides are smooth
    in μ).

    Reverse mode keeps every step (`checkpoints` >= the steps taken): with fewer checkpoints diffrax
    recomputes steps in the backward pass, in a differently compiled program whose rounding differs at
    1e-13; one step's acceptance can then flip (seen at t = 0.1169 s here) and the gradient belongs to
    another step sequence than the solution's (4.9e-3 relative off, where all-step checkpoints or
    `DirectAdjoint` agree with forward mode to 4e-8). See RosenbrockW's docstring."""
    opts_r = jh.SolverOptions(
        rtol=1e-7, atol=1e-9, max_steps=4096, adjoint=diffrax.RecursiveCheckpointAdjoint(checkpoints=4096)
    )

    def x_end(mu):
        sc = eqx.tree_at(lambda s: s.foundation.friction_coefficient, paper42, mu)
        return jh.simulate(sc, jh.Times(ts=TS_HALF), options=opts_r).position[-1, 0]

    def fwd(mu):
        # one jvp along dμ = 1 is the derivative (jacfwd of a scalar, which compiled a batched program: 49 s
        # against 19 s); its primal is the plain solve's (test_forward_sensitivities_through_stick_slip)
        traj, d_traj = _forward(paper42, mu, jnp.ones_like(mu), jnp.zeros_like(TS_HALF))
        return traj.position[-1, 0], d_traj.position[-1, 0]

    mu0 = jnp.asarray(0.3)
    x0_fwd, d_fwd = fwd(mu0)
    x0_rev, d_rev = jax.value_and_grad(x_end)(mu0)
    # The forward derivative's program is jaxhoist's own (`compile_cache.program`, compiled with its
    # compiler options); `jax.grad`'s is the caller's, compiled with XLA's defaults, which round some fused
    # operations otherwise (`xla_options`): the two solves take the same steps but for an acceptance or two
    # flipped by rounding, so their primals agree to the local error at rtol 1e-7 (measured 5.9e-10 m), not
    # bit for bit. Both derivatives are checked against central differences of the forward program's
    # primals (measured: forward 3.0e-5 relative off, reverse 9.8e-5; against differences of the caller's
    # own `jax.jit` of the solve, reverse 1.1e-4): a gradient of the wrong step sequence, the failure above,
    # was 4.9e-3 off.
    assert abs(float(x0_fwd) - float(x0_rev)) <= 1e-8 * abs(float(x0_rev))
    dm = 1e-4
    d_fd = float((fwd(mu0 + dm)[0] - fwd(mu0 - dm)[0]) / (2 * dm))
    d_fwd, d_rev = float(d_fwd), float(d_rev)
    assert abs(d_fd) > 1e-4
    assert abs(d_fwd - d_fd) < 1e-3 * abs(d_fd)
    assert abs(d_rev - d_fd) < 1e-3 * abs(d_fd)


def test_forward_sensitivities_through_stick_slip(paper42):
    """Forward-mode d x_C/dμ at the default tolerances over 12 s at μ = 0.55, through stick-slip: the
    sensitivity is solved as its own error-controlled ODE (`_numerics/sensitivity.py`), so it stays the
    derivative of the solution. Differentiating the steps instead gave |dx_C/dμ| = 3.2 m against 0.77 m by
    central differences at 12.5 s, and 1e125 m at 19 s (docs/performance.md). Reference: central differences
    of Tsit5 at the shared SOLVE_OPTIONS' rtol 1e-8 (smooth in μ to far below the tolerance here: within
    1e-5 relative of those at rtol 1e-9, measured), the program of
    `test_default_agrees_with_tight_reference`'s reference solve."""
    # N_SAVE saved times (their number does not change the steps of either solver, whose dense output is
    # their own): the plain solve below is then default_run's compiled core
    ts = jnp.asarray(np.linspace(0.0, 12.0, N_SAVE))
    opts_f = jh.SolverOptions(adjoint=diffrax.ForwardMode())

    def x_end(mu, opts):
        sc = eqx.tree_at(lambda s: s.foundation.friction_coefficient, paper42, mu)
        return jh.simulate(sc, jh.Times(ts=ts), options=opts).position[-1]

    mu0 = jnp.asarray(0.55)
    # one jvp along dμ = 1 is the derivative (jacfwd of a scalar), and its primal must be the plain solve's
    # (default options, reverse adjoint: default_run's compiled core), bit for bit
    primal, d_fwd = jax.jvp(lambda m: x_end(m, opts_f), (mu0,), (jnp.ones_like(mu0),))
    d_fwd = np.asarray(d_fwd)
    dm = 1e-4
    d_fd = np.asarray((x_end(mu0 + dm, SOLVE_OPTIONS) - x_end(mu0 - dm, SOLVE_OPTIONS)) / (2 * dm))
    assert np.linalg.norm(d_fd) > 0.1
    np.testing.assert_array_equal(np.asarray(primal), np.asarray(x_end(mu0, jh.SolverOptions())))
    assert np.linalg.norm(d_fwd - d_fd) < 0.1 * np.linalg.norm(d_fd)


def test_forward_derivative_in_the_saved_times_is_the_rate(paper42):
    """Moving the saved times moves the saved state at its rate: the forward-mode derivative of the solve
    along dt_k = 1 (no parameter moved: dμ = 0) is f(t_k, y_k), so the positions' tangent is the velocity
    and the Euler angles' stays finite. The tangent solve adds the rate only when the saved times carry a
    tangent. The jvp program is `test_forward_and_reverse_derivatives_match_central_differences`'s (rtol
    1e-7, tangents on μ and the saved times)."""
    mu = jnp.asarray(paper42.foundation.friction_coefficient, dtype=jnp.float64)
    traj, dtraj = _forward(paper42, mu, jnp.zeros_like(mu), jnp.ones_like(TS_HALF))
    assert int(traj.status) == 0
    v = np.asarray(traj.velocity)
    assert np.max(np.abs(v)) > 0.01
    # the tangent is evaluated on the sensitivity solve's own steps (its W has the exact friction slope),
    # the velocity on the plain solve's: they agree to the solver's tolerance, not bit for bit
    np.testing.assert_allclose(np.asarray(dtraj.position), v, rtol=0, atol=1e-3 * np.max(np.abs(v)))
    assert np.all(np.isfinite(np.asarray(dtraj.euler)))


def test_forward_derivatives_at_other_tolerances_compile_nothing(paper42, monkeypatch):
    """The tangent solve takes the step-size controller's tolerances as inputs, as the plain solve does
    (`sensitivity.solve_forward`, `SolverOptions.traced_tolerances`): `_forward`'s jvp program (rtol 1e-7,
    the tests above) runs at rtol 1e-5, atol 1e-7 without compiling, under those tolerances (fewer steps,
    a derivative within 1e-3 of the tight one's largest component, not equal to it). The library's cache is
    off meanwhile: a program of its own for the loose tolerances would be compiled here, not loaded."""
    monkeypatch.setattr(pc, "_ENABLED", [None])
    mu, one = jnp.asarray(paper42.foundation.friction_coefficient, dtype=jnp.float64), jnp.asarray(1.0)
    tight, d_tight = _forward(paper42, mu, one, jnp.zeros_like(TS_HALF))  # compiled here, or by a test above
    compiled = []

    def listener(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled.append(kw.get("fun_name"))

    loose_options = jh.SolverOptions(rtol=1e-5, atol=1e-7, adjoint=diffrax.ForwardMode())
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        loose, d_loose = _forward(paper42, mu, one, jnp.zeros_like(TS_HALF), loose_options)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert not [name for name in compiled if "solve" in str(name)], compiled
    assert int(loose.status) == 0 and int(loose.num_accepted_steps) < int(tight.num_accepted_steps)
    a, b = np.asarray(d_loose.position), np.asarray(d_tight.position)
    assert not np.array_equal(a, b)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-3 * np.max(np.abs(b)))


def test_joint_solve_keeps_the_tangent_and_the_values(paper42):
    """`solve_joint`, what a scan with derivatives differentiates: one augmented solve gives the values and
    their sensitivities. Under `jax.jvp` its tangent is the two-solve route's (`jh.simulate`'s jvp: the plain
    solve for the values, the augmented solve for the tangent), and its values are the augmented solve's own
    state: the plain solve's to the solver's tolerance, not bit for bit, since the step-size control also
    watches the sensitivities. Same set-up as `_forward` (rtol 1e-7, 0.5 s, tangent dμ = 1)."""
    from jaxhoist._numerics.solve import as_float64_leaves, solve_joint

    mu = jnp.asarray(paper42.foundation.friction_coefficient, dtype=jnp.float64)
    two, d_two = _forward(paper42, mu, jnp.ones_like(mu), jnp.zeros_like(TS_HALF))
    sc = as_float64_leaves(paper42).unlabelled()

    @jax.jit
    def joint(m):
        def run(mm):
            moved = eqx.tree_at(lambda s: s.foundation.friction_coefficient, sc, mm)
            return solve_joint(moved, TS_HALF, OPTS_F)

        return jax.jvp(run, (m,), (jnp.ones_like(m),))

    one, d_one = joint(mu)
    assert int(one.status) == int(two.status) == 0
    # The tangent: the same augmented solve, compiled in another program, whose rounding differs in the last
    # bits and, through the step-size control, moves steps: measured up to 8.8e-8 of the largest (the rope
    # tension's; 9e-9 for the positions), at rtol 1e-7. A tangent that missed a term would be off by the
    # term itself.
    for name in ("position", "euler", "rope_tension"):
        a, b = np.asarray(getattr(d_one, name)), np.asarray(getattr(d_two, name))
        assert np.max(np.abs(b)) > 0
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-5 * np.max(np.abs(b)), err_msg=name)
    # The values: another step sequence at rtol 1e-7 (1 179 accepted steps against the plain solve's 1 253),
    # so they differ from the plain solve's by about its errors: measured 2.7e-9 m over 0.5 s.
    x1, x2 = np.asarray(one.position), np.asarray(two.position)  # two's: the plain solve's, bit for bit
    assert not np.array_equal(x1, x2)
    np.testing.assert_allclose(x1, x2, rtol=0, atol=1e-7)


def test_stiff_member_solves(paper42):
    """ε = 1e-5 m/s and k = 1.5e9 N/m (friction slope and foundation 100x stiffer than the preset): the
    default solver reaches 1 s in fewer than 4x the steps it takes at the preset's values, and in fewer than a
    tenth of the steps Tsit5 needs (measured: 387 + 203 rejected, against 11 976 + 1 274). Tsit5 runs with a
    budget of 10 000 steps (`TSIT5_CAPPED`, the program of test_transforms.py's max_steps test), which it
    uses up: a tenth of the budget is a lower bound of a tenth of what it needs."""
    stiff = stiff_member(paper42)
    ts = jnp.asarray(np.linspace(0.0, 1.0, N_SAVE))
    w = jh.simulate(
        stiff, jh.Times(ts=ts), throw=False
    )  # the default step budget: shares default_run's compiled solve
    assert int(w.status) == 0
    base = jh.simulate(paper42, jh.Times(ts=ts))
    steps_w = int(w.num_accepted_steps + w.num_rejected_steps)
    assert steps_w < 4 * int(base.num_accepted_steps + base.num_rejected_steps)
    t5 = jh.simulate(stiff, jh.Times(ts=ts), options=TSIT5_CAPPED, throw=False)
    assert int(t5.status) == jh.SolveStatus.MAX_STEPS
    assert steps_w < 0.1 * int(t5.num_accepted_steps + t5.num_rejected_steps)


def test_sensitivity_solve_uses_the_exact_friction_slope():
    """The forward-mode sensitivity solve takes W with the exact friction slope (`linearise_exact_slope`):
    with the band-entry slope its error estimate let d x_C(25 s)/dμ at μ = 0.6 go 15 % off central
    differences instead of 1.9 % (`experiments/benchmarks/w_sensitivity.py`). A custom linearisation is
    kept as given."""
    from jaxhoist._numerics.sensitivity import augmented_solver

    def own(t, y, args):
        return linearise(t, y, args)

    for solver, want in ((RosenbrockW(), linearise_exact_slope), (RosenbrockW(linearise=own), own)):
        for many in (False, True):
            aug = augmented_solver(solver, many=many).linearise
            assert aug.__self__.linearise is want  # pyright: ignore[reportFunctionMemberAccess]
