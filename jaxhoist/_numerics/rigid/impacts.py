"""Impacts of the rigid model (paper §2): corner impacts with Newton's restitution law and Coulomb friction
impulses, and the plastic jerk of the inextensible rope (2.15), with their resolution rules
(docs/rigid-contact.md, "Resolution of contact choices and impacts"). Host side; `drv` is the phase
driver (`numerics.rigid.driver._Driver`)."""

from __future__ import annotations

import itertools

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._physics import rigid
from ..._physics.elastic import State
from ..._physics.rigid import FREE, SLIDE, STICK
from .compiled import (
    RopeWouldPush,
    as_numpy,
    eval_impulses,
    eval_rope_impulses,
    rope_direction_jit,
    rope_state,
)
from .records import RigidContactError, fmt


def impact(drv, t, y, striking: list[int], taut: bool = False, normal_only: bool = False):
    """Velocity jump at an impact of the `striking` corners (`drv`: the driver, `_Driver`); returns
    (y+, loss [J]). With the taut inextensible rope (`taut`) the rope takes an impulse too (it keeps its
    rate), unless that would need a push: then it goes slack in the impact. `normal_only`: no
    restitution (every involved corner ends with zero normal velocity; the tangential impact of `jam`).

    Resolution (docs/rigid-contact.md, "Resolution"), each step after the first recorded in `notes`:
    the consistent Coulomb impulse with the most contacts, then the most sticking corners, then the
    largest kinetic energy loss (maximal dissipation) where several remain; if none is consistent
    (a grazing touch, a Painlevé-type impact), the frictionless impulse ("friction dropped"); if that
    too fails, the M-orthogonal projection onto zero normal velocity of the involved corners."""
    corners, cv, ke0 = drv.kin(t, y)
    near = corners[:, 2] < drv.tol["z"] * drv.L
    involved = [i for i in range(4) if near[i] or i in striking]
    normal_target = np.zeros(4)
    for i in striking:
        if cv[i, 2] < -drv.tol["bounce"] * drv.V and not normal_only:
            normal_target[i] = -drv.e * cv[i, 2]
    if taut:
        try:
            y1, _, loss = rope_jerk(drv, t, y, striking, normal_target)
            return y1, loss
        except RopeWouldPush:
            drv.rope_taut = False
    vh = cv[:, :2]
    speed = np.linalg.norm(vh, axis=1)
    slipping = speed >= drv.tol["v"] * drv.V
    dirs = np.where(slipping[:, None], vh / np.maximum(speed, 1e-300)[:, None], 0.0)
    mask = np.isin(np.arange(4), involved)
    tP = drv.tol["force"] * drv.G * 1e-3  # impulses [N s]
    tV = drv.tol["v"] * drv.V

    def solve(sc, mu, combos):
        # Sliding impulses need a direction: the pre-impact slip, else the opposite of the sticking one.
        sticking = _modes([np.where(cb == SLIDE, STICK, cb) for cb in combos])
        _, _, imp0, _ = map(
            as_numpy,
            eval_impulses(
                y,
                sc,
                drv.c,
                jnp.asarray(sticking),
                jnp.asarray(np.zeros((81, 4, 2))),
                jnp.asarray(normal_target),
                drv.settings.rcond,
            ),
        )
        sd = _slide_directions(combos, slipping, dirs, imp0) if mu > 0 else np.zeros((81, 4, 2))
        out = map(
            as_numpy,
            eval_impulses(
                y,
                sc,
                drv.c,
                jnp.asarray(_modes(combos)),
                jnp.asarray(sd),
                jnp.asarray(normal_target),
                drv.settings.rcond,
            ),
        )
        v1, w1, imp, cv1 = out
        return v1, w1, _consistent_impulses(combos, imp, cv1, sd, mask, mu, tP, tV)

    combos = _impulse_combinations(mask)
    v1, w1, consistent = solve(drv.sc, drv.mu, combos)
    names = "".join(rigid.CORNERS[i] for i in involved)
    if not consistent:
        # A grazing touch or a Painlevé-type impact: the frictionless impulse (contacts FREE or SLIDE
        # with μ = 0), which a plastic impact always has.
        sc0 = eqx.tree_at(
            lambda s: s.foundation.friction_coefficient, drv.sc, jnp.zeros((), dtype=jnp.float64)
        )
        combos = [cb for cb in combos if not np.any(cb == STICK)]
        v1, w1, consistent = solve(sc0, 0.0, combos)
        if consistent:
            drv.notes.append(f"no Coulomb impulse at {names}: friction dropped")
    if not consistent:
        y1, _ = drv._project(t, y, np.zeros(4, dtype=bool), mask)
        drv.notes.append(f"no impulse at {names}: normal velocities projected out")
        v1, w1 = as_numpy(y1.velocity)[None], as_numpy(y1.angular_velocity)[None]
        consistent = [0]
    best = consistent[0]
    u_best = np.concatenate([v1[best], w1[best]])

    def counts(k):
        return int(np.sum(combos[k] != FREE)), int(np.sum(combos[k] == STICK))

    def differs(k):
        du = np.linalg.norm(np.concatenate([v1[k], w1[k]]) - u_best)
        return du > 1e-6 * (np.linalg.norm(u_best) + tV)

    def after(k):
        return eqx.tree_at(
            lambda s: (s.velocity, s.angular_velocity), y, (jnp.asarray(v1[k]), jnp.asarray(w1[k]))
        )

    tied = [k for k in consistent[1:] if counts(k) == counts(best) and differs(k)]
    if tied:
        # Newton's law is not unique for simultaneous multi-corner impacts: maximal dissipation.
        ke = {k: drv.kin(t, after(k))[2] for k in [best, *tied]}
        new = min(ke, key=lambda k: ke[k])
        drv.notes.append(f"{len(tied) + 1} consistent impulses: maximal dissipation, {fmt(combos[new])}")
        best = new
    y1 = eqx.tree_at(
        lambda s: (s.velocity, s.angular_velocity), y, (jnp.asarray(v1[best]), jnp.asarray(w1[best]))
    )
    _, _, ke1 = drv.kin(t, y1)
    loss = ke0 - ke1
    if loss < -1e-9 * max(ke0, 1.0):
        raise RigidContactError(
            f"t = {t:.9g} s: the impact of corner(s) {[rigid.CORNERS[i] for i in striking]} would gain "
            f"kinetic energy ({-loss:.4g} J) with restitution {drv.e} and friction μ = {drv.mu}: "
            "Newton's restitution law is not energy-consistent here; lower the restitution"
        )
    return y1, loss


def _impulse_combinations(involved: np.ndarray) -> list[np.ndarray]:
    """Every assignment of FREE / SLIDE / STICK to the `involved` corners (the others FREE)."""
    options = [[FREE, SLIDE, STICK] if involved[i] else [FREE] for i in range(4)]
    return [np.array(cb) for cb in itertools.product(*options)]


def _modes(combos) -> np.ndarray:
    """The combinations as a (81, 4) mode array (padded with FREE rows: one compiled evaluation serves
    every number of involved corners)."""
    out = np.zeros((81, 4), dtype=np.int32)
    out[: len(combos)] = combos
    return out


def _slide_directions(combos, slipping, dirs, sticking_impulses) -> np.ndarray:
    """Per combination and corner, the direction (4, 2) a sliding impulse opposes: the pre-impact slip
    `dirs` where the corner slips, else the opposite of its impulse in the all-sticking first pass
    (padded to 81 combinations like `_modes`)."""
    sd = np.zeros((81, 4, 2))
    for k, cb in enumerate(combos):
        for i in range(4):
            if cb[i] == SLIDE:
                if slipping[i]:
                    sd[k, i] = dirs[i]
                else:
                    p = -sticking_impulses[k, i, :2]
                    n = np.linalg.norm(p)
                    sd[k, i] = p / n if n > 0 else 0.0
    return sd


def _consistent_impulses(combos, imp, cv1, sd, involved, mu, tP, tV) -> list[int]:
    """The combinations whose impulses `imp` and post-impact corner velocities `cv1` are consistent with
    Coulomb's law: normal impulses >= 0, sticking ones inside the friction cone, sliding ones not reversing
    the slip (it would stick instead), free involved corners not driven into the ground; sorted with the
    most contacts first, then the most sticking ones."""
    consistent = []
    for k, cb in enumerate(combos):
        ok = True
        for i in range(4):
            Pz, Ph = imp[k, i, 2], np.linalg.norm(imp[k, i, :2])
            if (
                (cb[i] != FREE and Pz < -tP)
                or (cb[i] == STICK and Ph > mu * Pz + tP)
                or (cb[i] == SLIDE and float(cv1[k, i, :2] @ sd[k, i]) < -tV)
                or (cb[i] == FREE and involved[i] and cv1[k, i, 2] < -tV)
            ):
                ok = False
                break
        if ok:
            consistent.append(k)
    consistent.sort(key=lambda k: (-int(np.sum(combos[k] != FREE)), -int(np.sum(combos[k] == STICK))))
    return consistent


def _rope_impulses(drv, sc, tj, y: State, modes, sd, normal_target):
    """`_eval_rope_impulses` for every contact combination (`modes`, slide directions `sd`), on the host:
    (v+, ω+, tip v+, corner impulses, rope impulse P [N s], corner velocities+)."""
    out = eval_rope_impulses(
        tj,
        y,
        sc,
        drv.c,
        jnp.asarray(modes),
        jnp.asarray(sd),
        jnp.asarray(normal_target),
        drv.settings.rcond,
    )
    return tuple(map(as_numpy, out))


def _jerk_on_tip_alone(drv, tj, y: State, cv, cv1, s_dot, m0, striking, flat, tip_alone):
    """The rope jerk on the boom tip alone, or None where the load takes its share: `(y+, hoist work [J])`.

    Settling, as after corner impacts: a load flat on the ground that the jerk would move slower than
    Settings.rest_velocity stays at rest (the ground takes its share of the impulse) and the jerk acts on
    the boom tip alone. Without it, a resting load under a rope whose tip lags the hoist chatters: each
    small jerk lifts it, it falls back and the rope slackens, and the tip springs back into the next jerk.
    The same for a load sliding flat on the ground: a jerk that would change its corner velocities (`cv` to
    `cv1` [m/s]) by less than rest_velocity leaves them unchanged and jerks the tip alone, to d|AB|/dt =
    dl/dt (an inextensible rope over a sliding load chattered at ~3 kHz: jerk, the load tips onto one
    corner for 30 µs, falls back, the rope slackens; paper-2.3, μ = 0.1). `tip_alone`: no consistent jerk
    of the load at all."""
    rest = float(drv.settings.rest_velocity)
    if not striking and flat and float(np.max(np.linalg.norm(cv1, axis=1))) < rest:
        e = as_numpy(rope_direction_jit(tj, y, drv.sc, drv.c))
        v_A = as_numpy(y.tip_velocity)
        P_tip = m0 * (float(e @ v_A) + s_dot)  # tip alone: e·v_A+ = dl/dt = -ds/dt, load at rest
        work = P_tip * s_dot
        y1 = eqx.tree_at(
            lambda s: (s.velocity, s.angular_velocity, s.tip_velocity, s.hoist_work),
            y,
            (jnp.zeros(3), jnp.zeros(3), jnp.asarray(v_A - (P_tip / m0) * e), y.hoist_work + work),
        )
        return y1, work
    if tip_alone or (not striking and flat and float(np.max(np.linalg.norm(cv1 - cv, axis=1))) < rest):
        e = as_numpy(rope_direction_jit(tj, y, drv.sc, drv.c))
        _, rate_error, _ = map(float, rope_state(tj, y, drv.sc, drv.c))
        P_tip = m0 * rate_error  # e·(v_A+ - v_B) = -ds/dt
        work = P_tip * s_dot
        y1 = eqx.tree_at(
            lambda s: (s.tip_velocity, s.hoist_work),
            y,
            (jnp.asarray(as_numpy(y.tip_velocity) - (P_tip / m0) * e), y.hoist_work + work),
        )
        if not tip_alone:
            drv.notes.append("jerk on the tip alone")
        return y1, work
    return None


def rope_jerk(drv, t: float, y: State, striking=(), normal_target=None, t_rate=None, fallback: bool = False):
    """The inextensible rope snapping taut (or the hoist starting with a speed jump): a plastic jerk that
    sets d|AB|/dt = dl/dt, with the corners on the ground taking impulses as in `_Driver.impact` (every
    combination of free / slide / stick tried; consistent: P >= 0, normal impulses >= 0, sticking ones in
    the friction cone, sliding ones not reversing the slip, free corners on the ground not driven into
    it; the most contacts, then the most sticking win). With `striking` corners and their post-impact
    normal velocities `normal_target`, it is a corner impact while the rope is taut (the rope keeps its
    rate; P >= 0 is its impulse). `t_rate`: where to take dl/dt (the start uses t = 0+). `fallback`: where
    no Coulomb impulse is consistent, take the frictionless one, else jerk the boom tip alone (noted), instead
    of raising `_RopeWouldPush` (which a corner impact answers by letting the rope go slack).

    **Returns** `(y+, hoist work P ds/dt [J], loss [J])`: the hoist pays P ds/dt during the jerk (the drum
    runs at ds/dt), the kinetic energy of load and boom tip grows by less; the difference is the loss.
    """
    corners, cv, _ = drv.kin(t, y)
    near = (corners[:, 2] < drv.tol["z"] * drv.L) | np.isin(np.arange(4), list(striking))
    normal_target = np.zeros(4) if normal_target is None else np.asarray(normal_target)
    vh = cv[:, :2]
    speed = np.linalg.norm(vh, axis=1)
    slipping = speed >= drv.tol["v"] * drv.V
    dirs = np.where(slipping[:, None], vh / np.maximum(speed, 1e-300)[:, None], 0.0)
    combos = _impulse_combinations(near)
    # First pass: sticking impulses give the slide directions.
    sticking = _modes([np.where(cb == SLIDE, STICK, cb) for cb in combos])
    tj = jnp.asarray(t if t_rate is None else t_rate, dtype=jnp.float64)
    imp0 = _rope_impulses(drv, drv.sc, tj, y, sticking, np.zeros((81, 4, 2)), normal_target)[3]
    sd = _slide_directions(combos, slipping, dirs, imp0)
    v1, w1, tip1, imp, P, cv1 = _rope_impulses(drv, drv.sc, tj, y, _modes(combos), sd, normal_target)
    tP = drv.tol["force"] * drv.G * 1e-3  # impulses [N s]
    tV = drv.tol["v"] * drv.V
    consistent = [k for k in _consistent_impulses(combos, imp, cv1, sd, near, drv.mu, tP, tV) if P[k] >= -tP]
    tip_alone = False
    if not consistent and fallback:
        # As for corner impacts: the frictionless jerk (contacts FREE or SLIDE with μ = 0); if even that has
        # none, the jerk on the boom tip alone (below).
        sc0 = eqx.tree_at(
            lambda s: s.foundation.friction_coefficient, drv.sc, jnp.zeros((), dtype=jnp.float64)
        )
        combos = [cb for cb in combos if not np.any(cb == STICK)]
        sd = np.zeros((81, 4, 2))
        v1, w1, tip1, imp, P, cv1 = _rope_impulses(drv, sc0, tj, y, _modes(combos), sd, normal_target)
        consistent = [k for k in _consistent_impulses(combos, imp, cv1, sd, near, 0.0, tP, tV) if P[k] >= -tP]
        if consistent:
            drv.notes.append("no Coulomb jerk: friction dropped")
        else:
            consistent, tip_alone = [0], True
            drv.notes.append("no consistent jerk: on the tip alone")
    if not consistent:
        raise RopeWouldPush(
            f"t = {t:.9g} s: the jerk of the inextensible rope has no consistent impulse "
            "(Painlevé-type impact inconsistency)"
        )
    best = consistent[0]
    _, _, s_dot = map(float, rope_state(tj, y, drv.sc, drv.c))
    m0 = float(drv.sc.boom.tip_mass)

    def ke(yy):
        return drv.kin(t, yy)[2] + 0.5 * m0 * float(np.sum(as_numpy(yy.tip_velocity) ** 2))

    work = float(P[best]) * s_dot
    y1 = eqx.tree_at(
        lambda s: (s.velocity, s.angular_velocity, s.tip_velocity, s.hoist_work),
        y,
        (jnp.asarray(v1[best]), jnp.asarray(w1[best]), jnp.asarray(tip1[best]), y.hoist_work + work),
    )
    settled = _jerk_on_tip_alone(
        drv, tj, y, cv, cv1[best], s_dot, m0, bool(len(striking)), bool(np.all(near)), tip_alone
    )
    if settled is not None:
        y1, work = settled
    loss = work - (ke(y1) - ke(y))
    if loss < -1e-9 * max(abs(work), 1.0):
        raise RigidContactError(f"t = {t:.9g} s: the rope jerk would gain energy ({-loss:.4g} J)")
    return y1, work, loss
