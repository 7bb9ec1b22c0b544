"""Static equilibrium: the paper's linear corner-load distribution (2.3)/(2.8) and the elastic model's
initial state (load at rest on its springs, rope just taut, boom tip at rest under its own weight).
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._typing import Vec3
from . import kinematics
from .elastic import Constants, State, constants
from .params import Scenario


def linear_corner_loads(
    size: Vec3, mass_centre: Vec3, weight, rope_force: Vec3, attachment: Vec3
) -> Float[Array, "4"]:
    """Corner normal forces N_D, N_E, F_F, N_H [N] of a box resting flat, eqs. (2.3) and (2.8).

    Solves the three equilibrium equations (vertical force, moments about the X and Y axes through D)
    for the four corner forces with the minimum-norm solution, which is exactly the linear law
    N_i = A_0 + A_1 x_i + A_2 y_i of (2.3). Horizontal ground forces act at Z = 0 and do not enter.

    **Arguments**: `weight` G = m g [N]; `rope_force` S in world axes [N] applied at `attachment` B
    (body = world axes at rest) [m]; `mass_centre` C [m].
    """
    xy = kinematics.bottom_corners(size)[:, :2]
    A = jnp.stack([jnp.ones(4), xy[:, 0], xy[:, 1]])
    Sx, Sy, Sz = rope_force
    xB, yB, zB = attachment
    b = jnp.stack(
        [
            weight - Sz,
            weight * mass_centre[0] + zB * Sx - xB * Sz,
            weight * mass_centre[1] + zB * Sy - yB * Sz,
        ]
    )
    return A.T @ jnp.linalg.solve(A @ A.T, b)


def _rest_residual(x: Float[Array, "3"], scenario: Scenario, corners_rel) -> Float[Array, "3"]:
    """Net vertical force and horizontal moments [N, N m] on the load resting on the springs at
    (Z_C, φ, ϑ) = x with ψ = 0 and the rope slack."""
    load, k = scenario.load, scenario.foundation.stiffness
    R = kinematics.quat_to_matrix(kinematics.euler_to_quat(x[1], 0.0, x[2]))
    arms = corners_rel @ R.T
    N = k * jnp.maximum(-(x[0] + arms[:, 2]), 0.0)
    fz = jnp.sum(N) - load.mass * scenario.gravity
    mx = jnp.sum(arms[:, 1] * N)
    my = -jnp.sum(arms[:, 0] * N)
    return jnp.stack([fz, mx, my])


def initial_state(scenario: Scenario, newton_iterations: int = 12) -> tuple[State, Constants]:
    """The load at rest in static equilibrium on the foundation, the rope just taut (S = 0, or slack by
    `rope.slack`), the boom tip at rest at A. Differentiable with respect to every scenario leaf.

    The mass centre stands at X = ξ_C, Y = η_C with yaw ψ = 0; Z_C and the small tilts φ, ϑ solve the
    spring equilibrium by Newton's method from the flat, linear-distribution guess. Tilting on the springs
    moves the mass centre sideways, so the corner loads differ from (2.8) by O(mg/(k c)) relative.
    """
    load = scenario.load
    corners_rel = kinematics.bottom_corners(load.size) - load.mass_centre
    flat = linear_corner_loads(
        load.size, load.mass_centre, load.mass * scenario.gravity, jnp.zeros(3), jnp.zeros(3)
    )
    # Start from the mean sinkage, flat; Newton converges quadratically on this smooth (piecewise linear) map.
    x0 = jnp.array([load.mass_centre[2] - jnp.mean(flat) / scenario.foundation.stiffness, 0.0, 0.0])

    def step(_, x):
        r = _rest_residual(x, scenario, corners_rel)
        Jx = jax.jacfwd(_rest_residual)(x, scenario, corners_rel)
        return x - jnp.linalg.solve(Jx, r)

    x = jax.lax.fori_loop(0, newton_iterations, step, x0)
    q = kinematics.euler_to_quat(x[1], 0.0, x[2])
    position = jnp.array([load.mass_centre[0], load.mass_centre[1], x[0]])
    R = kinematics.quat_to_matrix(q)
    B = kinematics.points_world(position, R, (scenario.rope.attachment - load.mass_centre)[None])[0]
    l0 = jnp.sqrt(jnp.sum((scenario.boom.tip_position - B) ** 2)) + scenario.rope.slack
    c = constants(scenario, l0)
    n = scenario.foundation.friction.state_size
    zero = jnp.zeros(())
    y0 = State(
        position=position,
        velocity=jnp.zeros(3),
        quaternion=q,
        angular_velocity=jnp.zeros(3),
        tip_position=scenario.boom.tip_position,
        tip_velocity=jnp.zeros(3),
        friction_state=jnp.zeros((4, n)),
        hoist_work=zero,
        damping_loss=zero,
        friction_work=zero,
    )
    return y0, c
