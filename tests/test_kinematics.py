"""Rigid-body kinematics: the Euler convention R = R_Z(ψ) R_Y(ϑ) R_X(φ), quaternion round trips, orthonormal
rotations, corner order and point velocities against finite differences of positions."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from jaxhoist._physics import kinematics as K

FEW = settings(max_examples=40, derandomize=True, deadline=None)
_f = dict(allow_nan=False, allow_infinity=False)
angle = st.floats(-np.pi + 1e-6, np.pi - 1e-6, **_f)
pitch = st.floats(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, **_f)  # away from gimbal lock, where φ and ψ merge
vec3 = st.tuples(*(st.floats(-3.0, 3.0, **_f),) * 3).map(np.array)
quat = st.tuples(*(st.floats(-1.0, 1.0, **_f),) * 4).map(np.array).filter(lambda q: np.linalg.norm(q) > 0.1)

euler_to_quat = jax.jit(K.euler_to_quat)
quat_to_matrix = jax.jit(K.quat_to_matrix)
matrix_to_euler = jax.jit(K.matrix_to_euler)


def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@FEW
@given(phi=angle, psi=angle, theta=pitch)
def test_euler_convention_and_round_trip(phi, psi, theta):
    """(φ, ψ, ϑ) -> quaternion -> R is the documented R_Z(ψ) R_Y(ϑ) R_X(φ) built from elementary rotations,
    and R -> (φ, ψ, ϑ) gives the angles back (1e-9 rad: arcsin near |ϑ| = π/2 - 1e-3 loses digits)."""
    q = euler_to_quat(phi, psi, theta)
    assert abs(float(jnp.linalg.norm(q)) - 1.0) < 1e-14
    R = np.asarray(quat_to_matrix(q))
    np.testing.assert_allclose(R, rz(psi) @ ry(theta) @ rx(phi), atol=1e-14)
    back = np.asarray(matrix_to_euler(jnp.asarray(R)))
    np.testing.assert_allclose(back, [phi, psi, theta], atol=1e-9)


@FEW
@given(q=quat)
def test_quaternion_round_trip_and_orthonormal(q):
    """Any non-zero quaternion gives an orthonormal R with det +1; R -> angles -> quaternion returns ±q/|q|
    (a quaternion and its negative are the same rotation). Exact gimbal lock is tested separately below."""
    R = np.asarray(quat_to_matrix(jnp.asarray(q)))
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
    assert abs(np.linalg.det(R) - 1.0) < 1e-14
    phi, psi, theta = np.asarray(matrix_to_euler(jnp.asarray(R)))
    assume(np.cos(theta) > 1e-6)
    q2 = np.asarray(euler_to_quat(phi, psi, theta))
    qn = q / np.linalg.norm(q)
    # Near gimbal lock (|ϑ| -> π/2) the angles lose accuracy like 1e-16 / cos ϑ: scale the tolerance.
    tol = 1e-13 / np.cos(theta)
    assert min(np.abs(q2 - qn).max(), np.abs(q2 + qn).max()) < tol


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_euler_at_gimbal_lock_reproduces_the_rotation(sign):
    """At ϑ = ±π/2 only φ ∓ ψ is defined, but the triple returned must still give back R."""
    ry = np.array([[0.0, 0.0, sign], [0.0, 1.0, 0.0], [-sign, 0.0, 0.0]])  # R_Y(±π/2), exactly
    R = rz(0.5) @ ry @ rx(0.3)
    e = np.asarray(matrix_to_euler(jnp.asarray(R)))
    np.testing.assert_allclose(np.asarray(quat_to_matrix(euler_to_quat(*e))), R, atol=1e-12)


def test_yaw_is_about_the_vertical():
    """ψ alone turns the body about world Z: the ξ axis goes to (cos ψ, sin ψ, 0)."""
    R = np.asarray(quat_to_matrix(euler_to_quat(0.0, 0.7, 0.0)))
    np.testing.assert_allclose(R[:, 0], [np.cos(0.7), np.sin(0.7), 0.0], atol=1e-15)
    np.testing.assert_allclose(R[:, 2], [0.0, 0.0, 1.0], atol=1e-15)


def test_bottom_corners_order():
    """D, E, F, H at (0,0), (a,0), (a,b), (0,b) on the bottom face ζ = 0."""
    c = np.asarray(K.bottom_corners(jnp.array([2.5, 6.0, 1.0])))
    np.testing.assert_array_equal(c, [[0, 0, 0], [2.5, 0, 0], [2.5, 6.0, 0], [0, 6.0, 0]])


@FEW
@given(v=vec3, u=vec3)
def test_skew_is_the_cross_product(v, u):
    np.testing.assert_allclose(np.asarray(K.skew(jnp.asarray(v))) @ u, np.cross(v, u), atol=1e-13)


@jax.jit
def _positions(r_c, q, rel):
    return K.points_world(r_c, K.quat_to_matrix(q), rel)


@jax.jit
def _velocities(v_c, q, omega, rel):
    return K.points_velocity(v_c, K.quat_to_matrix(q), omega, rel)


@FEW
@given(r_c=vec3, v_c=vec3, omega=vec3, q=quat, rel=st.lists(vec3, min_size=4, max_size=4).map(np.stack))
def test_point_velocities_match_finite_differences(r_c, v_c, omega, q, rel):
    """Move the body along its own kinematics, r_C' = v_C and q' = ½ q ⊗ (0, ω) with ω in body axes, and
    difference the world positions of four body points: the central difference (step 1e-5 s, truncation
    ~1e-10 |ω|³ |ρ|, round-off ~1e-11) must equal `points_velocity` to 1e-8 m/s. This checks the
    velocity formula, the body-axes convention of ω, and `quat_rate` against each other."""
    q = jnp.asarray(q / np.linalg.norm(q))
    h = 1e-5
    dq = K.quat_rate(q, jnp.asarray(omega))
    assert abs(float(jnp.dot(q, dq))) < 1e-14  # the rate keeps |q| = 1
    rel = jnp.asarray(rel)
    plus = _positions(jnp.asarray(r_c + h * v_c), q + h * dq, rel)
    minus = _positions(jnp.asarray(r_c - h * v_c), q - h * dq, rel)
    fd = np.asarray(plus - minus) / (2 * h)
    got = np.asarray(_velocities(jnp.asarray(v_c), q, jnp.asarray(omega), rel))
    np.testing.assert_allclose(got, fd, atol=1e-8)
