"""Static equilibrium: the elastic rest state (paper §3) and the linear corner-load law (2.3)/(2.8)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import N_SAVE, run
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxhoist as jh
from jaxhoist._physics import kinematics

G = 9.81


def n_d_paper(a, b, G, S, B, C):
    """N_D of the paper's eq. (2.8), typed in independently of `linear_corner_loads`:

    N_D = [3ab(G - S_z) + 2b(S_z x_B - G x_C - S_x z_B) + 2a(S_z y_B - G y_C - S_y z_B)] / (4ab).
    """
    Sx, Sy, Sz = S
    xB, yB, zB = B
    xC, yC = C[0], C[1]
    return (
        3 * a * b * (G - Sz) + 2 * b * (Sz * xB - G * xC - Sx * zB) + 2 * a * (Sz * yB - G * yC - Sy * zB)
    ) / (4 * a * b)


def corner_loads_paper(a, b, G, S, B, C):
    """N_D, N_E, N_F, N_H from (2.8) and mirror symmetry: mirroring the box in x -> a - x (which flips S_x)
    carries corner E onto D, mirroring in y -> b - y carries H onto D, and both carry F onto D."""
    S, B, C = np.asarray(S, float), np.asarray(B, float), np.asarray(C, float)

    def mirror(v, ax, length, flip_sign=False):
        v = v.copy()
        v[ax] = -v[ax] if flip_sign else length - v[ax]
        return v

    def mx(S, B, C):
        return mirror(S, 0, a, True), mirror(B, 0, a), mirror(C, 0, a)

    def my(S, B, C):
        return mirror(S, 1, b, True), mirror(B, 1, b), mirror(C, 1, b)

    return np.array(
        [
            n_d_paper(a, b, G, S, B, C),
            n_d_paper(a, b, G, *mx(S, B, C)),
            n_d_paper(a, b, G, *mx(*my(S, B, C))),
            n_d_paper(a, b, G, *my(S, B, C)),
        ]
    )


@pytest.fixture(scope="module")
def rest_state():
    """`initial_state`, jitted once; changing scenario leaf values reuses the compiled function."""
    return jax.jit(jh.initial_state)


def elastic_corner_forces(state_fn, scenario):
    """Corner forces k p_i [N] and world corner positions [m] of the elastic rest state."""
    y0, c = state_fn(scenario)
    R = kinematics.quat_to_matrix(y0.quaternion)
    corners = np.asarray(y0.position + c.corners_rel @ R.T)
    p = np.maximum(-corners[:, 2], 0.0)
    return float(scenario.foundation.stiffness) * p, corners, np.asarray(y0.position)


# ------------------------------------------------------------------------ the elastic rest state


def test_rest_state_balances_weight_and_moments(rest_state, paper42):
    """paper-4.2 (mass centre offset by (-0.25, -0.5, -0.25) m): Σ k p_i = m g and Σ (r_i - r_C) x N_i = 0.

    Newton's method runs to convergence (12 iterations, quadratic), so both residuals are at round-off:
    1e-10 relative to the weight, and to weight x box size for the moments."""
    N, corners, r_c = elastic_corner_forces(rest_state, paper42)
    W = float(paper42.load.mass) * G
    assert np.all(N > 0.0), "all four corners must carry load at rest"
    assert abs(N.sum() - W) < 1e-10 * W
    forces = np.zeros((4, 3))
    forces[:, 2] = N
    moment = np.cross(corners - r_c, forces).sum(axis=0)
    assert np.all(np.abs(moment) < 1e-10 * W * 6.0), moment
    # The offset mass centre loads corner D (nearest to C) most and F (farthest) least.
    assert np.argmax(N) == 0 and np.argmin(N) == 2


def test_rest_state_approaches_linear_law_like_one_over_k(rest_state, paper42):
    """On springs the box tilts, which shifts C sideways relative to the corners, so the corner loads
    differ from the rigid-ground linear law (2.8) by O(m g / (k c)) relative: the gap must be small and
    shrink tenfold when k grows tenfold (we accept a ratio of 8-12: the O(1/k²) remainder is ~1e-3)."""
    a, b, c = (float(x) for x in paper42.load.size)
    C = np.asarray(paper42.load.mass_centre)
    W = float(paper42.load.mass) * G
    n28 = corner_loads_paper(a, b, W, np.zeros(3), np.zeros(3), C)
    k = float(paper42.foundation.stiffness)
    gaps = []
    for kk in (k, 10 * k):
        N, _, _ = elastic_corner_forces(rest_state, paper42.replace(**{"foundation.stiffness": kk}))
        gaps.append(np.max(np.abs(N - n28)) / W)
    assert 1e-7 < gaps[0] < 1e-2, gaps  # a real gap, but a small one (the prototype saw 1e-4 to 2e-3)
    assert 8.0 < gaps[0] / gaps[1] < 12.0, gaps


def test_rest_state_is_still(centred42, paper42):
    """From `initial_state` with the hoist stopped the load must not move: the springs carry m g exactly,
    the rope is just taut (S = 0) and the boom tip rests under its own weight. Over 2 s the mass centre
    must stay within 1e-9 m and its speed below 1e-8 m/s (solver error at rtol 1e-8 on a state that does
    not change); a wrong rest state would move it by ~m g / k = 5 mm at once."""
    for sc in (paper42.replace(**{"hoist.speed": 0.0}), centred42):
        tr = run(sc, np.linspace(0.0, 2.0, N_SAVE))
        drift = np.abs(np.asarray(tr.position - tr.position[0])).max()
        speed = np.abs(np.asarray(tr.velocity)).max()
        omega = np.abs(np.asarray(tr.angular_velocity)).max()
        tip = np.abs(np.asarray(tr.tip_position - tr.tip_position[0])).max()
        assert drift < 1e-9 and speed < 1e-8 and omega < 1e-8 and tip < 1e-9, (drift, speed, omega, tip)
        assert np.abs(np.asarray(tr.rope_tension)).max() < 1e-3  # N, against a weight of 3e5 N
        W = float(sc.load.mass) * G
        # The ground reaction stays at m g up to k x drift + h x speed ~ 0.04 N; we allow 1e-6 W = 0.3 N.
        assert np.abs(np.asarray(tr.ground_reaction) - W).max() < 1e-6 * W


# --------------------------------------------------------------------- the linear law (2.8)

_finite = dict(allow_nan=False, allow_infinity=False)


@settings(max_examples=30, derandomize=True, deadline=None)
@given(
    size=st.tuples(*(st.floats(0.5, 8.0, **_finite),) * 3),
    c_frac=st.tuples(*(st.floats(0.05, 0.95, **_finite),) * 3),
    b_frac=st.tuples(*(st.floats(0.0, 1.0, **_finite),) * 3),
    S=st.tuples(*(st.floats(-2e4, 2e4, **_finite),) * 3),
)
def test_linear_corner_loads_match_paper_2_8(size, c_frac, b_frac, S):
    """`linear_corner_loads` equals (2.8) and its mirror images for any box, mass centre, rope point B and
    rope force S (all three components), to round-off (1e-9 of the weight)."""
    size, C, B = np.array(size), np.array(c_frac) * np.array(size), np.array(b_frac) * np.array(size)
    W = 1000.0 * G
    got = jh.linear_corner_loads(jnp.asarray(size), jnp.asarray(C), W, jnp.asarray(S), jnp.asarray(B))
    got = np.asarray(got)
    want = corner_loads_paper(size[0], size[1], W, S, B, C)
    assert np.allclose(got, want, rtol=0.0, atol=1e-9 * W), (got, want)
    # And they are in equilibrium: vertical forces and moments about D balance.
    Sx, Sy, Sz = S
    xs, ys = np.array([0, size[0], size[0], 0]), np.array([0, 0, size[1], size[1]])
    assert abs(got.sum() - (W - Sz)) < 1e-9 * W
    assert abs(got @ xs - (W * C[0] + B[2] * Sx - B[0] * Sz)) < 1e-9 * W * size[0]
    assert abs(got @ ys - (W * C[1] + B[2] * Sy - B[1] * Sz)) < 1e-9 * W * size[1]


def test_linear_corner_loads_centred_box_quarters():
    """A centred mass centre and no rope: each corner carries G/4 (the simplest case of (2.8))."""
    size = jnp.array([2.5, 6.0, 2.5])
    N = jh.linear_corner_loads(size, size / 2, 1.0e5, jnp.zeros(3), jnp.zeros(3))
    assert np.allclose(np.asarray(N), 2.5e4, rtol=1e-13)
