"""Statics of the load resting on the rigid ground (paper §2.1): corner loads (2.8), the reaction point R,
the conditions (2.9), the pull magnitudes at which they fail, and the exact friction utilisation."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize

import jaxhoist as jh
from jaxhoist._physics import statics

A_TIP = np.array([3.0, 4.0, 10.0])


@pytest.fixture(scope="module")
def p41():
    return jh.load_scenario("paper-4.1")


def _dir(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _paper_N_D(a, b, G, S, B, C):
    """Eq. (2.8) as printed in the paper."""
    Sx, Sy, Sz = S
    return (
        3 * a * b * (G - Sz)
        + 2 * b * (Sz * B[0] - G * C[0] - Sx * B[2])
        + 2 * a * (Sz * B[1] - G * C[1] - Sy * B[2])
    ) / (4 * a * b)


def test_corner_loads_match_paper_eq_2_8_and_balance(paper42):
    sc = paper42  # eccentric mass centre (1.0, 2.5, 1.0) in a 2.5 x 6 x 2.5 box
    a, b, _ = np.asarray(sc.load.size)
    C, B = np.asarray(sc.load.mass_centre), np.asarray(sc.rope.attachment)
    G = float(sc.load.mass * sc.gravity)
    S = np.array([0.05, 0.08, 0.3]) * G
    r = statics.rest_statics_jit(sc, jnp.asarray(S))
    N = np.asarray(r.corner_loads)
    assert N[0] == pytest.approx(_paper_N_D(a, b, G, S, B, C), rel=1e-12)
    # The other corners by the mirror maps x -> a - x (D <-> E) and y -> b - y (D <-> H), F by both.
    mx = lambda v: np.array([a - v[0], v[1], v[2]])  # noqa: E731
    my = lambda v: np.array([v[0], b - v[1], v[2]])  # noqa: E731
    sx, sy = np.array([-1, 1, 1]), np.array([1, -1, 1])
    assert N[1] == pytest.approx(_paper_N_D(a, b, G, S * sx, mx(B), mx(C)), rel=1e-12)
    assert N[3] == pytest.approx(_paper_N_D(a, b, G, S * sy, my(B), my(C)), rel=1e-12)
    assert N[2] == pytest.approx(_paper_N_D(a, b, G, S * sx * sy, mx(my(B)), mx(my(C))), rel=1e-12)
    # Vertical balance and the moments about the axes through D; R is where N acts.
    xy = np.array([[0, 0], [a, 0], [a, b], [0, b]])
    assert N.sum() == pytest.approx(G - S[2], rel=1e-12)
    assert float(r.normal) == pytest.approx(G - S[2], rel=1e-12)
    assert (N * xy[:, 0]).sum() == pytest.approx(G * C[0] + B[2] * S[0] - B[0] * S[2], rel=1e-12)
    np.testing.assert_allclose(np.asarray(r.reaction_point), (N @ xy) / N.sum(), rtol=1e-12)
    assert float(r.friction) == pytest.approx(math.hypot(S[0], S[1]), rel=1e-12)
    # Full moment balance about the vertical through R: rope horizontal force at B plus M_T vanish.
    xR, yR = np.asarray(r.reaction_point)
    moment = float(r.friction_moment) + (B[0] - xR) * S[1] - (B[1] - yR) * S[0]
    assert moment == pytest.approx(0.0, abs=1e-9 * G)
    assert r.holds() == {"lift": True, "slide": True, "twist": True, "tip": True}


def test_slide_threshold_closed_form(p41):
    """Pull along the paper's rope direction (B above D towards A = (3, 4, 10)): s = μG/(h + μ e_z)."""
    e = _dir(A_TIP - np.asarray(p41.rope.attachment))
    G, mu = float(p41.load.mass * p41.gravity), 0.15
    h = math.hypot(e[0], e[1])
    s = statics.slide_threshold(p41, e)
    assert s == pytest.approx(mu * G / (h + mu * e[2]), rel=1e-12)
    r = statics.rest_statics_jit(p41, jnp.asarray(s * e))
    assert float(r.friction) / (mu * float(r.normal)) == pytest.approx(1.0, rel=1e-9)
    # Just below it holds, just above it fails.
    assert statics.rest_statics_jit(p41, jnp.asarray(0.999 * s * e)).holds()["slide"]
    assert not statics.rest_statics_jit(p41, jnp.asarray(1.001 * s * e)).holds()["slide"]
    assert statics.slide_threshold(p41, [0.0, 0.0, 1.0]) == math.inf  # a vertical pull never slides


def test_tip_and_lift_thresholds_closed_form(p41):
    e = _dir(A_TIP - np.asarray(p41.rope.attachment))
    G = float(p41.load.mass * p41.gravity)
    a, b, _ = np.asarray(p41.load.size)
    C, B = np.asarray(p41.load.mass_centre), np.asarray(p41.rope.attachment)
    s_tip, kind, edges = statics.tip_threshold(p41, e)
    # Hand formulas: x_R = a at G (a - x_C) / (z_B e_x - (x_B - a) e_z), y_R = b likewise; the smaller wins.
    s_x = G * (a - C[0]) / (B[2] * e[0] - (B[0] - a) * e[2])
    s_y = G * (b - C[1]) / (B[2] * e[1] - (B[1] - b) * e[2])
    assert s_tip == pytest.approx(min(s_x, s_y), rel=1e-12)
    assert (kind, edges) == ("tip-edge", ("EF",))
    r = statics.rest_statics_jit(p41, jnp.asarray(s_tip * e))
    assert float(r.reaction_point[0]) == pytest.approx(a, rel=1e-10)
    # At the tipping pull the nonnegative corner loads leave the corners D, H of the opposite edge unloaded.
    nn = np.asarray(r.nonnegative_loads)
    assert abs(nn[0]) < 1e-8 * G and abs(nn[3]) < 1e-8 * G
    assert statics.lift_threshold(p41, e) == pytest.approx(G / e[2], rel=1e-12)
    # Ordering for the paper's data: slide first, then tip, then lift; first_failure names it.
    assert statics.slide_threshold(p41, e) < s_tip < statics.lift_threshold(p41, e)
    name, s = statics.first_failure(p41, e)
    assert name == "slide" and s == pytest.approx(statics.slide_threshold(p41, e), rel=1e-12)


def test_tip_corner_and_lift_first():
    """A centred box pulled from its top-face centre along the diagonal tips about corner F; a vertical
    pull through the mass centre lifts at S = G and never tips."""
    a, b, c = 2.0, 3.0, 4.0  # tall, so that it tips (at 0.42 G) before it slides (0.68 G)
    sc = jh.Scenario(
        load=jh.Load([a, b, c], 1000.0),
        foundation=jh.Foundation(1e7, 1e5, 0.8),
        rope=jh.Rope(1e7, 1e4, [a / 2, b / 2, c]),
        hoist=jh.ConstantSpeedHoist(0.1),
        boom=jh.Boom([a, b, 10.0], 500.0, 5e6),
    )
    G = 1000.0 * 9.81
    e = _dir([a, b, 1.0])
    s, kind, edges = statics.tip_threshold(sc, e)
    assert kind == "tip-corner" and set(edges) == {"EF", "FH"}
    assert s == pytest.approx(G * (a / 2) / (c * e[0] + (a / 2) * e[2]), rel=1e-12)
    assert statics.first_failure(sc, e)[0] == "tip-corner"
    name, s = statics.first_failure(sc, [0.0, 0.0, 1.0])
    assert name == "lift" and s == pytest.approx(G, rel=1e-12)


def test_twist_threshold_closed_form(paper42, p41):
    """A rope lug outside the footprint (x_B = -0.3 m) and a mass centre on the lug's side (x_C = 1.0 m of
    a = 2.5 m). For a pull along (0, 1, 1)/√2 the friction resultant runs along y, so M_T and the bound of
    (2.9) are x-distances from R: |x_B - x_R| = max(a - x_R, x_R) holds while x_R < (a + x_B)/2 = 1.1 m.
    x_R = (G x_C - s x_B e_z)/(G - s e_z) reaches 1.1 m at s = 0.1 G / (1.4 e_z)."""
    B = np.array([-0.3, 2.5, 2.0])
    e = _dir([0.0, 1.0, 1.0])
    G = float(paper42.load.mass * paper42.gravity)
    s = statics.twist_threshold(paper42, e, attachment=B)
    assert s == pytest.approx(0.1 * G / (1.4 * e[2]), rel=1e-9)
    r = statics.rest_statics_jit(paper42, jnp.asarray(s * e), attachment=jnp.asarray(B))
    assert float(r.reaction_point[0]) == pytest.approx(1.1, rel=1e-9)
    assert abs(float(r.friction_moment)) == pytest.approx(float(r.twist_limit), rel=1e-9)
    assert statics.rest_statics_jit(paper42, jnp.asarray(0.99 * s * e), attachment=jnp.asarray(B)).holds()[
        "twist"
    ]
    assert not statics.rest_statics_jit(
        paper42, jnp.asarray(1.01 * s * e), attachment=jnp.asarray(B)
    ).holds()["twist"]
    # A rope point on the box keeps the friction line inside the rectangle: twist never fails.
    assert statics.twist_threshold(p41, _dir(A_TIP - np.asarray(p41.rope.attachment))) == math.inf


def test_nonnegative_loads_feasible_iff_R_in_rectangle():
    a, b, N = 2.0, 4.0, 1000.0
    xy = np.array([[0, 0], [a, 0], [a, b], [0, b]])
    for xR, yR in [(1.0, 2.0), (1.9, 3.9), (0.05, 2.0), (1.5, 0.2), (2.1, 2.0), (1.0, -0.1), (1.9, 3.5)]:
        u, v = xR / a - 0.5, yR / b - 0.5
        lin = N * (0.25 + u * (2 * xy[:, 0] / a - 1) / 2 + v * (2 * xy[:, 1] / b - 1) / 2)
        nn, margin = statics.nonnegative_corner_loads(jnp.asarray(lin))
        nn = np.asarray(nn)
        assert float(margin) == pytest.approx(N / 4 * (1 - 2 * max(abs(u), abs(v))), rel=1e-12)
        inside = 0 < xR < a and 0 < yR < b
        assert (float(margin) > 0) == inside
        assert nn.sum() == pytest.approx(N) and nn @ xy == pytest.approx(N * np.array([xR, yR]))
        if inside:
            assert nn.min() >= -1e-9 * N
            if abs(u) + abs(v) <= 0.5:  # inside the central diamond the linear law itself is nonnegative
                np.testing.assert_allclose(nn, lin, rtol=1e-12)


def _socp_rho(F, M, pts, loads, mu):
    """min ρ s.t. |T_i| <= ρ μ N_i, Σ T_i = -F, Σ r_i × T_i = -M, by SLSQP (independent of the dual search),
    in units of μ Σ N_i."""
    sc = mu * loads.sum()
    F, M, w = F / sc, M / sc, mu * loads / sc

    def cons_eq(x):
        T = x[:8].reshape(4, 2)
        return np.concatenate([T.sum(0) + F, [np.sum(pts[:, 0] * T[:, 1] - pts[:, 1] * T[:, 0]) + M]])

    def cons_in(x):
        T = x[:8].reshape(4, 2)
        return x[8] * w - np.sqrt(np.sum(T**2, axis=1) + 1e-30)

    x0 = np.concatenate([np.tile(-F / 4, 4), [2.0]])
    res = minimize(
        lambda x: x[8],
        x0,
        constraints=[{"type": "eq", "fun": cons_eq}, {"type": "ineq", "fun": cons_in}],
        method="SLSQP",
        options={"ftol": 1e-13, "maxiter": 1000},
    )
    # SLSQP may stop with "positive directional derivative" at this tight ftol; accept a feasible point.
    assert np.max(np.abs(cons_eq(res.x))) < 1e-10 and np.min(cons_in(res.x)) > -1e-10
    return res.x[8]


def test_friction_utilisation_hand_cases_and_socp():
    a, b, mu = 2.0, 4.0, 0.5
    pts = jnp.array([[0, 0], [a, 0], [a, b], [0, b]], dtype=jnp.float64)
    jitted = jax.jit(statics.friction_utilisation)

    def fu(F, M, pts, loads, mu, scale):
        # every argument a float64 array, so that the three cases share one compiled program
        f64 = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
        return jitted(f64(F), f64(M), pts, f64(loads), f64(mu), f64(scale))

    eq = jnp.full(4, 250.0)
    # Pure translation through the friction centre: ρ = |F| / (μ N).
    F = jnp.array([60.0, -80.0])
    rho, tw = fu(F, a / 2 * F[1] - b / 2 * F[0], pts, eq, mu, 3.0)
    assert float(rho) == pytest.approx(100.0 / (mu * 1000.0), rel=1e-9)
    assert abs(float(tw[2])) < 1e-6  # no rotation at the onset
    # Pure moment about the centre: ρ = |M| / (μ Σ N_i d), d the half-diagonal.
    M = 300.0
    rho, tw = fu(jnp.zeros(2), M, pts, eq, mu, 3.0)
    assert float(rho) == pytest.approx(M / (mu * 1000.0 * math.hypot(a / 2, b / 2)), rel=1e-9)
    # Unequal loads and off-centre forces against the direct convex program.
    rng = np.random.default_rng(7)
    for _ in range(6):
        loads = rng.uniform(50.0, 400.0, 4)
        F = rng.normal(size=2) * 100.0
        M = rng.normal() * 200.0
        rho, _ = fu(jnp.asarray(F), M, pts, jnp.asarray(loads), mu, 3.0)
        assert float(rho) == pytest.approx(_socp_rho(F, M, np.asarray(pts), loads, mu), rel=1e-6)


def test_exact_slip_precedes_paper_slide(p41):
    """A rope force off the friction centre (here through corner D) needs a friction moment too, so the
    corners' friction discs saturate before T = μN: slip threshold < slide threshold, and ρ* = 1 there."""
    e = _dir(A_TIP - np.asarray(p41.rope.attachment))
    s_slip = statics.slip_threshold(p41, e)
    s_slide = statics.slide_threshold(p41, e)
    assert 0.8 * s_slide < s_slip < s_slide
    r = statics.rest_statics_jit(p41, jnp.asarray(s_slip * e))
    assert float(r.friction_utilisation) == pytest.approx(1.0, rel=1e-9)
    assert r.holds()["slide"]
