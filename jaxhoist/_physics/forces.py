"""Force laws: one-sided ground spring-dampers (3.1)-(3.2), rope tension (2.14), boom-tip springs (2.13).

Each returns the force and the part of it that dissipates, so that `energy.py` can close the balance
dE/dt = hoist power - dissipation exactly.
"""

import jax.numpy as jnp

from .._typing import PerCorner, Scalar, Vec3


def onset_ramp(depth, onset):
    """min(depth / onset, 1) clipped at 0 [-]; a step at depth 0 when onset = 0.

    How much of a damper acts at a given penetration or stretch (our addition to (3.1) and (2.14)): the
    damper builds up over the first `onset` metres, so a contact force is continuous when a corner touches
    down or a slack rope snaps taut. A discontinuous force there would make the solution's parameter
    derivatives (forward and reverse mode) miss the jump of the sensitivities at that instant.
    """
    pos = onset > 0.0
    return jnp.where(
        pos, jnp.clip(depth / jnp.where(pos, onset, 1.0), 0.0, 1.0), jnp.where(depth > 0.0, 1.0, 0.0)
    )


def ground_normal(
    penetration: PerCorner, penetration_rate: PerCorner, k: Scalar, h: Scalar, onset: Scalar | float = 0.0
):
    """Normal forces N_i [N] of eqs. (3.1)-(3.2): N_i = max(0, k p_i + h w(p_i) dp_i/dt) for p_i > 0, else 0.

    p_i = -Z_i is how far corner i is below the ground [m]; w = `onset_ramp(p_i, onset)` (w = 1 beyond
    `onset` [m]; onset = 0 is the paper's law exactly). The clip at zero means the ground never pulls (a
    corner leaving the ground faster than the spring relaxes feels no force).

    **Returns** `(N, dissipation_rate)`: N_i [N] and the power lost in the dampers [W] (>= 0).
    """
    in_contact = penetration > 0.0
    elastic = k * jnp.where(in_contact, penetration, 0.0)
    damper = h * onset_ramp(penetration, onset) * penetration_rate
    normal = jnp.where(in_contact, jnp.maximum(elastic + damper, 0.0), 0.0)
    return normal, jnp.sum((normal - elastic) * penetration_rate)


def rope_tension(
    stretch: Scalar, stretch_rate: Scalar, c_l: Scalar, b_l: Scalar, onset: Scalar | float = 0.0
):
    """Rope tension S [N] of eq. (2.14) with damping: S = max(0, c_l δ + b_l w(δ) dδ/dt) for δ > 0, else 0,
    with w = `onset_ramp(δ, onset)` (onset = 0: the damper acts in full as soon as the rope is taut).

    **Returns** `(S, dissipation_rate)` with the damper's loss (S - c_l δ⁺) dδ/dt [W] (>= 0).
    """
    taut = stretch > 0.0
    elastic = c_l * jnp.where(taut, stretch, 0.0)
    tension = jnp.where(
        taut, jnp.maximum(elastic + b_l * onset_ramp(stretch, onset) * stretch_rate, 0.0), 0.0
    )
    return tension, (tension - elastic) * stretch_rate


def boom_force(displacement: Vec3, velocity: Vec3, k: Vec3, c: Vec3):
    """Boom restoring force -k ΔX_A - c dX_A/dt [N] of eq. (2.13) (damping is our addition).

    **Returns** `(force, dissipation_rate)`.
    """
    return -k * displacement - c * velocity, jnp.sum(c * velocity**2)


def safe_norm(v: Vec3) -> Scalar:
    """|v| with a finite gradient at v = 0 (the two-`where` guard)."""
    sq = jnp.sum(v**2)
    pos = sq > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)
