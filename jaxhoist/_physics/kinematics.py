"""Rigid-body kinematics: orientation, corners D, E, F, H, the rope point B, point velocities.

Orientation is a unit quaternion q = (w, x, y, z) taking body axes ξηζ to world axes XYZ (no gimbal lock).
Euler angles are reported in the paper's order (φ, ψ, ϑ) with our documented convention

    R = R_Z(ψ) R_Y(ϑ) R_X(φ):  ψ yaw about the vertical Z (the paper's ψ of §2.3, ω_ζ = dψ/dt on flat ground),
                               ϑ pitch about the once-turned η axis, φ roll about the body ξ axis.
"""

import jax.numpy as jnp
from jaxtyping import Array, Float

from .._typing import CornerVecs, Quat, Rot33, Vec3


def quat_to_matrix(q: Quat) -> Rot33:
    """Rotation matrix (body -> world) of a quaternion; q need not be normalised."""
    q = q / jnp.sqrt(jnp.sum(q**2))
    w, x, y, z = q
    return jnp.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_rate(q: Quat, omega_body: Vec3) -> Quat:
    """dq/dt = ½ q ⊗ (0, ω) for the angular velocity ω in body axes [rad/s]."""
    w, x, y, z = q
    p, r, s = omega_body
    return 0.5 * jnp.array(
        [
            -x * p - y * r - z * s,
            w * p + y * s - z * r,
            w * r + z * p - x * s,
            w * s + x * r - y * p,
        ]
    )


def euler_to_quat(phi, psi, theta) -> Quat:
    """Quaternion of R = R_Z(ψ) R_Y(ϑ) R_X(φ) [rad]."""
    cr, sr = jnp.cos(phi / 2), jnp.sin(phi / 2)
    cp, sp = jnp.cos(theta / 2), jnp.sin(theta / 2)
    cy, sy = jnp.cos(psi / 2), jnp.sin(psi / 2)
    return jnp.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def matrix_to_euler(R: Rot33) -> Float[Array, "3"]:
    """(φ, ψ, ϑ) [rad] of R = R_Z(ψ) R_Y(ϑ) R_X(φ); ϑ in [-π/2, π/2], φ and ψ in (-π, π].

    At gimbal lock (ϑ = ±π/2 to round-off: the box stands on an end) only φ ∓ ψ is defined; we return
    φ = 0 and put the whole turn into ψ, so the triple still reproduces R.
    """
    theta = jnp.arcsin(jnp.clip(-R[2, 0], -1.0, 1.0))
    lock = jnp.abs(R[2, 0]) > 1.0 - 1e-12
    phi = jnp.where(lock, 0.0, jnp.arctan2(R[2, 1], R[2, 2]))
    psi = jnp.where(lock, jnp.arctan2(-R[0, 1], R[1, 1]), jnp.arctan2(R[1, 0], R[0, 0]))
    return jnp.stack([phi, psi, theta])


def bottom_corners(size: Vec3) -> CornerVecs:
    """Body coordinates of the bottom corners D, E, F, H = (0,0,0), (a,0,0), (a,b,0), (0,b,0) [m]."""
    a, b = size[0], size[1]
    z = jnp.zeros_like(a)
    return jnp.stack(
        [
            jnp.stack([z, z, z]),
            jnp.stack([a, z, z]),
            jnp.stack([a, b, z]),
            jnp.stack([z, b, z]),
        ]
    )


def skew(v: Vec3) -> Rot33:
    """The matrix [v]x with [v]x u = v x u (the antisymmetric matrices of eq. 2.11)."""
    return jnp.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def points_world(r_c: Vec3, R: Rot33, rel_body: Float[Array, "n 3"]) -> Float[Array, "n 3"]:
    """World positions r_C + R ρ of points at body offsets ρ from the mass centre [m]."""
    return r_c + rel_body @ R.T


def points_velocity(
    v_c: Vec3, R: Rot33, omega_body: Vec3, rel_body: Float[Array, "n 3"]
) -> Float[Array, "n 3"]:
    """World velocities v_C + R (ω x ρ) of points at body offsets ρ from the mass centre [m/s] (cf. 2.17)."""
    return v_c + jnp.cross(omega_body, rel_body) @ R.T
