"""The rigid model's phase driver state and its choice of contact configurations (paper §2, host side):
`_Driver` holds the scenario, tolerances and counters of one `simulate_rigid` call, solves phases, projects
velocities onto a phase's constraints, and chooses the next contact configuration by consistency and the
resolution rule (`_Driver._rank`; docs/rigid-contact.md, "Resolution of contact choices and impacts")."""

from __future__ import annotations

import dataclasses
import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._physics import rigid
from ..._physics.elastic import Constants
from ..._physics.params import Scenario
from ..._physics.rigid import FREE, SLIDE, STICK, Phase
from . import impacts as rigid_impacts
from .compiled import (
    Jam,
    Options,
    RopeWouldPush,
    as_numpy,
    contact_matrices_jit,
    eval_candidates,
    forces,
    phase_solve_jit,
    raw_guards_jit,
    rope_state,
)
from .coulomb import coulomb_pattern
from .records import fmt


class Inconsistent(Exception):
    """No contact configuration is consistent and fallback 3 (the least-violating one as a regularised
    phase) is switched off (`_Driver.allow_regularised`, at the end of a compliant phase): the message
    names the least violation."""


@dataclasses.dataclass
class _Candidates:
    """The candidate configurations at one instant (`_Driver._candidates`): `combos` (modes per corner),
    `hints` (slip directions, padded to 16 rows), per candidate the contact `force` (4, 3) [N], corner
    accelerations `acc_c` (4, 3), body accelerations `accel` (6) and rope `tension` [N]; `n_ref`: the
    reference normal forces (every corner on the ground in contact) [N]; `mats`: the contact matrices."""

    combos: list
    hints: np.ndarray
    force: np.ndarray
    acc_c: np.ndarray
    accel: np.ndarray
    tension: np.ndarray
    n_ref: np.ndarray
    mats: object


class Driver:
    def __init__(
        self,
        scenario: Scenario,
        c: Constants,
        settings: rigid.Settings,
        options: Options,
        restitution: float,
        tol: dict,
    ):
        self.sc, self.c, self.settings, self.options = scenario, c, settings, options
        self.e = float(restitution)
        sc = rigid.scales(scenario)
        self.G, self.L, self.V, self.g = (
            float(sc.force),
            float(sc.length),
            float(sc.velocity),
            float(sc.acceleration),
        )
        self.mu = float(scenario.foundation.friction_coefficient)
        self.v_stop = float(settings.stop_velocity)
        self.tol = tol
        self.accepted = 0
        self.rejected = 0
        self.debug = False
        self.allow_jam = True  # fallback 2 of the configuration choice (off while choosing after a jam)
        # Fallback 3 (off at the end of a compliant phase: `_Inconsistent` instead), and its least violation
        # if the last `select` took it, else "" (`_Run` counts such choices in a row:
        # `ChatterRule.max_regularised`).
        self.allow_regularised = True
        self.regularised = ""
        self.exclude: np.ndarray | None = None  # contact modes not to choose again at once (`_transition`)
        self.notes: list[str] = []  # how ambiguous or inconsistent contact choices were resolved (phase log)
        self.inextensible = False
        self.rope_taut = False  # the inextensible rope is at its length (taut, or may be): try taut first

    # ---------------------------------------------------------------------------- helpers
    def take_notes(self) -> str:
        """The resolution notes gathered since the last call, as one string (and forget them)."""
        out, self.notes = "; ".join(dict.fromkeys(self.notes)), []
        return out

    def guards(self, t, y, phase) -> np.ndarray:
        return as_numpy(
            raw_guards_jit(jnp.asarray(t), y, self.sc, self.c, phase, self.settings, self.inextensible)
        )

    def matrices(self, t, y, rope: int = rigid.ROPE_ELASTIC):
        m = contact_matrices_jit(jnp.asarray(t), y, self.sc, self.c, self.settings, rope)
        return jax.tree_util.tree_map(as_numpy, m)

    def kin(self, t, y):
        """Corners [m], corner velocities [m/s] and the load's kinetic energy [J]."""
        m = self.matrices(t, y)
        u = np.concatenate([as_numpy(y.velocity), as_numpy(y.angular_velocity)])
        return m.corners, m.corner_velocity, float(0.5 * u @ m.mass @ u)

    def with_offsets(self, t, y, phase: Phase) -> Phase:
        raw = self.guards(t, y, phase)
        off = np.where(raw <= self.tol["guard_start"], self.tol["guard_start"] - raw, 0.0)
        return eqx.tree_at(lambda p: p.guard_offset, phase, jnp.asarray(off))

    def solve(self, y, phase, t0, t1, ts):
        # Strongly typed float64 everywhere (a weakly typed leaf would compile the solve a second time).
        t0, t1 = jnp.asarray(t0, dtype=jnp.float64), jnp.asarray(t1, dtype=jnp.float64)
        ts_c = jnp.clip(jnp.asarray(ts, dtype=jnp.float64), t0, t1)
        out = phase_solve_jit(
            self.sc, self.c, phase, self.settings, y, t0, t1, ts_c, self.options, self.inextensible
        )
        sts, sys_, result, acc, rej = out
        self.accepted += int(acc)
        self.rejected += int(rej)
        return as_numpy(sts), sys_, result

    # ---------------------------------------------------------------------------- configurations
    def near_ground(self, t, y):
        corners, cv, _ = self.kin(t, y)
        near = (corners[:, 2] < self.tol["z"] * self.L) & (np.abs(cv[:, 2]) < self.tol["v"] * self.V)
        resting = near & (np.linalg.norm(cv[:, :2], axis=1) < 1.5 * self.v_stop)
        return near, resting, corners, cv

    def _project(self, t, y, full: np.ndarray, normal: np.ndarray):
        """M-orthogonal projection of the velocities onto: corners `full` at rest, corners `normal` with
        zero normal velocity. Returns (y, kinetic energy removed [J])."""
        mats = self.matrices(t, y)
        rows = [mats.jacobians[i] for i in range(4) if full[i]]
        rows += [mats.jacobians[i, 2:3] for i in range(4) if normal[i] and not full[i]]
        if not rows:
            return y, 0.0
        J = np.concatenate(rows, axis=0)
        u = np.concatenate([as_numpy(y.velocity), as_numpy(y.angular_velocity)])
        Minv = np.linalg.inv(mats.mass)
        du = -Minv @ J.T @ np.linalg.pinv(J @ Minv @ J.T, rcond=1e-10) @ (J @ u)
        u1 = u + du
        loss = 0.5 * u @ mats.mass @ u - 0.5 * u1 @ mats.mass @ u1
        return eqx.tree_at(
            lambda s: (s.velocity, s.angular_velocity), y, (jnp.asarray(u1[:3]), jnp.asarray(u1[3:]))
        ), float(loss)

    def _project_taut(self, t, y, full: np.ndarray, normal: np.ndarray, rate_error: float = 0.0):
        """`_project` with the taut inextensible rope: the boom tip's velocity joins the coordinates and
        the rope's rate d|AB|/dt is kept, less `rate_error` [m/s] (a rope impulse P does the hoist work
        P ds/dt, booked as in the rope jerk). Returns (y, loss [J])."""
        mats = self.matrices(t, y, rigid.ROPE_TAUT)
        rows = [mats.jacobians[i] for i in range(4) if full[i]]
        rows += [mats.jacobians[i, 2:3] for i in range(4) if normal[i] and not full[i]]
        if not rows:
            return y, 0.0
        u = np.concatenate([as_numpy(y.velocity), as_numpy(y.angular_velocity), as_numpy(y.tip_velocity)])
        J = np.concatenate(rows + [mats.rope_row[None, :]], axis=0)
        b = np.zeros(J.shape[0])
        b[-1] = mats.rope_row @ u - rate_error  # the rope keeps its rate (less rate_error)
        Minv = np.linalg.inv(mats.mass)
        lam = np.linalg.pinv(J @ Minv @ J.T, rcond=1e-10) @ (J @ u - b)
        u1 = u - Minv @ J.T @ lam
        _, _, s_dot = map(float, rope_state(jnp.asarray(t), y, self.sc, self.c))
        work = float(lam[-1]) * s_dot  # the rope impulse P = λ_rope pulls the tip towards B
        loss = work - (0.5 * u1 @ mats.mass @ u1 - 0.5 * u @ mats.mass @ u)
        y1 = eqx.tree_at(
            lambda s: (s.velocity, s.angular_velocity, s.tip_velocity, s.hoist_work),
            y,
            (jnp.asarray(u1[:3]), jnp.asarray(u1[3:6]), jnp.asarray(u1[6:]), y.hoist_work + work),
        )
        return y1, float(loss)

    def project(self, t, y, phase: Phase):
        """Remove the velocity components that the phase's constraints forbid: the slip of sticking corners
        and of corners that start sliding from rest (their slip died out below the stop velocity; they
        restart along the direction chosen by Coulomb's law), and the normal velocity of contacts. A tiny
        impulse; the kinetic energy it removes [J] is returned."""
        if phase.rest:
            _, _, ke = self.kin(t, y)
            return eqx.tree_at(
                lambda s: (s.velocity, s.angular_velocity), y, (jnp.zeros(3), jnp.zeros(3))
            ), ke
        contact, starting = as_numpy(phase.contact), as_numpy(phase.starting)
        full, normal = (contact == STICK) | ((contact == SLIDE) & starting), contact != FREE
        if self.inextensible and int(phase.rope) == rigid.ROPE_TAUT:
            return self._project_taut(t, y, full, normal)
        return self._project(t, y, full, normal)

    def select(self, t, y, where: str, previous: Phase | None = None) -> Phase:
        """Choose the contact configuration at (t, y) (see the module docstring). With the inextensible
        rope at its length, the taut rope (S >= 0) is tried first, then the slack rope. Sets
        `regularised` to the least violation when the choice is fallback 3 ("" otherwise); raises
        `_Inconsistent` instead where that fallback is switched off (`allow_regularised`)."""
        self.regularised = ""
        if not self.inextensible:
            return self._select(t, y, where, previous, rigid.ROPE_ELASTIC)
        if self.rope_taut:
            try:
                return self._select(t, y, where, previous, rigid.ROPE_TAUT)
            except RopeWouldPush:
                self.rope_taut = False
        return self._select(t, y, where, previous, rigid.ROPE_SLACK)

    def select_or_jam(self, t, y, where: str, previous: Phase | None = None):
        """`select` at (t, y); where no configuration is consistent while corners on the ground slide
        (Painlevé), first a tangential impact at (t, y) (`jam`), then `select` again with fallback 2 off.

        **Returns** `(phase, y, loss [J])`: `y` after the jam (or unchanged), its kinetic energy loss."""
        try:
            return self.select(t, y, where, previous), y, 0.0
        except Jam:
            pass
        y1, loss = self.jam(t, y)
        self.allow_jam = False
        try:
            return self.select(t, y1, where + ", after a tangential impact", previous), y1, loss
        finally:
            self.allow_jam = True

    def jam(self, t, y):
        """The tangential impact of fallback 2: the corners on the ground take a plastic impulse (normal
        velocity 0 after it) with Coulomb friction, as in `impact` (friction dropped if that has no
        solution); the slip it stops is what made the contact problem inconsistent. Returns (y+, loss [J])."""
        near, _, _, _ = self.near_ground(t, y)
        taut = self.inextensible and self.rope_taut
        y1, loss = self.impact(t, y, [i for i in range(4) if near[i]], taut=taut, normal_only=True)
        self.notes.append(f"tangential impact ({loss:.3g} J)")
        return y1, loss

    def _select(self, t, y, where: str, previous: Phase | None, rope: int) -> Phase:
        near, resting, corners, cv = self.near_ground(t, y)
        body_at_rest = bool(np.all(near) and np.all(resting))
        # Evaluate as the chosen phase will start: resting corners still, contacts not moving normally.
        y, _ = self._project(t, y, resting, near)

        # The load resting flat on all four corners: the rest conditions decide.
        rest_phase = rigid.make_phase([STICK] * 4, rest=True, rope=rope)
        if body_at_rest:
            g = self.guards(t, y, rest_phase)
            if g[8] >= -self.tol["rest"] and g[9] >= -self.tol["rest"]:
                if g[10] < -self.tol["force"]:  # the taut rope would push: it is slack
                    raise RopeWouldPush
                return rest_phase

        cand = self._candidates(t, y, near, resting, rope)
        combos, hints, force, accel = cand.combos, cand.hints, cand.force, cand.accel

        def not_again(consistent):
            # A guard of the configuration that just ended fired (a contact's load vanished, a sticking
            # corner's friction reached μN): the same configuration again would end within nanoseconds,
            # over and over (a Zeno loop of the look-ahead). Take it only if nothing else is consistent.
            if self.exclude is None:
                return consistent
            others = [k for k in consistent if not np.array_equal(combos[k], self.exclude)]
            if len(others) < len(consistent):
                excluded.extend(k for k in consistent if k not in others)
            return others

        excluded: list[int] = []  # consistent but not repeated (noted where that changed the choice)

        strict, why, rope_rejected, (violation, reasons) = self.check_value(
            cand, 1.0, near, resting, rope, t, where
        )
        consistent = not_again(strict)
        if not consistent and rope_rejected:
            raise RopeWouldPush  # only the rope's S >= 0 failed: it goes slack
        if not consistent:
            # Fallbacks, in order (each recorded in the phase log; see docs/rigid-contact.md, "Resolution"):
            # 1. a degenerate contact (a load, acceleration or slip direction within rounding of its limit):
            #    the consistency tolerances relaxed by `relax`;
            relaxed = not_again(self.check_value(cand, self.tol["relax"], near, resting, rope, t, where)[0])
            if relaxed:
                consistent = relaxed
                self.notes.append(f"tolerances x{self.tol['relax']:g} (degenerate contact)")
            elif strict:
                consistent = strict  # only the configuration that just ended is consistent: repeat it
                excluded.clear()
                self.notes.append("repeated: nothing else consistent")
            elif self.allow_jam and np.any(near & ~resting):
                # 2. Painlevé-type inconsistency of sliding contacts: a tangential impact (dynamic
                #    jamming; an impulse at the corners on the ground with zero normal velocity after it,
                #    sticking where the cone allows, friction dropped if that has no solution), then choose
                #    again.
                raise Jam(why)
            else:
                # 3. the least inconsistent configuration, as a short regularised phase (its guards end it).
                #    Chosen `ChatterRule.max_regularised` times in a row, a compliant phase takes over
                #    (`_Run.step`), and it is not left while this fallback would be needed (`_Run.compliant`).
                k = int(np.argmin(violation))
                least = f"least violation {violation[k]:.2g} ({reasons[k]})"
                if not self.allow_regularised:
                    raise Inconsistent(least)
                self.regularised = least
                consistent = [k]
                self.notes.append(f"regularised: no consistent configuration, {least}")
        if previous is not None and int(previous.rope) != rope:
            previous = eqx.tree_at(lambda p: p.rope, previous, jnp.asarray(rope, dtype=jnp.int32))
        if previous is not None:
            prev_N = as_numpy(
                forces(jnp.asarray(t), y, self.sc, self.c, previous, self.settings, self.inextensible)
            )[:, 2]
        else:
            prev_N = None
        mats, n_ref = cand.mats, cand.n_ref
        best = self._rank(combos, consistent, force, accel, prev_N, n_ref, near, mats)
        if (
            excluded
            and self._rank(combos, consistent + excluded, force, accel, prev_N, n_ref, near, mats, quiet=True)
            in excluded
        ):
            self.notes.append(f"{fmt(self.exclude)} not repeated after its guard fired")
        combo = combos[best]
        hint = np.where((combo == SLIDE)[:, None], hints[best], 0.0)
        flat3 = bool(np.all(near)) and int(np.sum(combo != FREE)) == 3
        return rigid.make_phase(
            combo,
            rest=False,
            slip_hint=hint,
            starting=(combo == SLIDE) & resting,
            free_on_ground=(combo == FREE) & near & flat3,
            rope=rope,
        )

    def _candidates(self, t, y, near, resting, rope: int) -> _Candidates:
        """Every contact set of the corners `near` the ground with its Coulomb pattern (`coulomb_pattern`),
        evaluated at (t, y): contact forces, corner and body accelerations, rope tension, and the normal
        forces of the reference (every corner on the ground in contact; `_rank`)."""
        mats = self.matrices(t, y, rope)
        near_idx = [i for i in range(4) if near[i]]
        combos, hints_list = [], []
        reference = None  # the configuration with every corner on the ground in contact (see `_rank`)
        for r in range(len(near_idx), -1, -1):
            for subset in itertools.combinations(near_idx, r):
                in_contact = np.zeros(4, dtype=bool)
                in_contact[list(subset)] = True
                modes, hints = coulomb_pattern(
                    mats, in_contact, resting, self.mu, self.G, self.g, debug=self.debug
                )
                if reference is None:
                    reference = (modes, hints)
                n_stick, n_contact = int(np.sum(modes == STICK)), int(np.sum(modes != FREE))
                if np.all(near) and n_stick >= 2 and n_contact >= 3:
                    continue  # held fixed: the rest configuration, which failed above
                combos.append(modes)
                hints_list.append(hints)
        assert reference is not None  # the loop runs at least once (r = 0: the empty subset)
        ref_row = 0 if combos and np.array_equal(combos[0], reference[0]) else len(combos)
        n_max = 16
        contact = np.zeros((n_max, 4), dtype=np.int32)
        hints = np.zeros((n_max, 4, 2))
        contact[: len(combos)] = np.array(combos)
        hints[: len(combos)] = np.array(hints_list)
        if ref_row == len(combos):  # a skipped (rest-like) configuration leaves room for it
            contact[ref_row], hints[ref_row] = reference
        force, acc_c, accel, tension = eval_candidates(
            jnp.asarray(t),
            y,
            self.sc,
            self.c,
            self.settings,
            jnp.asarray(contact),
            jnp.asarray(hints),
            jnp.asarray(rope, dtype=jnp.int32),
            self.inextensible,
        )
        force, acc_c, accel, tension = map(as_numpy, (force, acc_c, accel, tension))
        return _Candidates(
            combos=combos,
            hints=hints,
            force=force,
            acc_c=acc_c,
            accel=accel,
            tension=tension,
            n_ref=force[ref_row, :, 2],
            mats=mats,
        )

    def check_value(self, cand: _Candidates, scale: float, near, resting, rope: int, t, where: str):
        """Consistency of every candidate with the tolerances times `scale`: (consistent indices,
        [(combo, reason)] of the others, whether only the rope's S >= 0 failed somewhere, and per
        candidate its largest violation in units of G or g)."""
        combos, hints, force, acc_c, accel, tension = (
            cand.combos,
            cand.hints,
            cand.force,
            cand.acc_c,
            cand.accel,
            cand.tension,
        )
        tF, tA = scale * self.tol["force"] * self.G, scale * self.tol["accel"] * self.g
        consistent, why, violation, reasons = [], [], np.zeros(len(combos)), [""] * len(combos)
        rope_rejected = False
        for k, combo in enumerate(combos):
            N = force[k, :, 2]
            T = np.linalg.norm(force[k, :, :2], axis=1)
            a = acc_c[k]
            ok, reason, worst = True, "", 0.0
            for i in range(4):
                bad = ""
                if combo[i] != FREE and N[i] < -tF:
                    bad, v = f"N_{rigid.CORNERS[i]} = {N[i]:.4g} N < 0", -N[i] / self.G
                elif combo[i] == STICK and T[i] > self.mu * N[i] + tF:
                    bad = f"|T_{rigid.CORNERS[i]}| = {T[i]:.6g} N > μN = {self.mu * N[i]:.6g} N"
                    v = (T[i] - self.mu * N[i]) / self.G
                elif combo[i] == FREE and near[i] and a[i, 2] < -tA:
                    bad = f"free corner {rigid.CORNERS[i]} accelerates into the ground"
                    v = -a[i, 2] / self.g
                elif combo[i] == SLIDE and resting[i]:
                    h = hints[k, i]
                    ah = a[i, :2]
                    along = float(ah @ h)
                    perp = float(np.linalg.norm(ah - along * h))
                    if along < -tA or perp > tA + self.tol["align"] * np.linalg.norm(ah):
                        bad = (
                            f"{rigid.CORNERS[i]} would not slide along its friction direction "
                            f"(a_h = {ah}, t = {h})"
                        )
                        v = max(-along, perp - self.tol["align"] * np.linalg.norm(ah)) / self.g
                if bad:
                    ok, worst = False, max(worst, v)
                    reason = reason or bad
            if ok and rope == rigid.ROPE_TAUT and tension[k] < -tF:
                ok, reason = False, f"the rope would push (S = {tension[k]:.4g} N)"
                worst = max(worst, -tension[k] / self.G)
                rope_rejected = True
            violation[k], reasons[k] = worst, reason
            (consistent if ok else why).append(k if ok else (combo, reason))
            if self.debug and scale == 1.0:
                print(
                    f"  [{where} t={t:.9g}] {fmt(combo)}: {'ok' if ok else reason}; "
                    f"N={np.round(N, 1)} accel={np.round(accel[k], 6)}"
                )
        return consistent, why, rope_rejected, (violation, reasons)

    def _rank(self, combos, consistent, force, accel, prev_N, n_ref, near, mats, quiet=False) -> int:
        """The resolution rule among consistent configurations (docs/rigid-contact.md, "Resolution"):

        1. the most corners in contact (every corner that can carry load does);
        2. the most continuous normal forces, |N - N_prev| within `jump` G (after an event: the corner whose
           load vanished is the one that unloads, as on a stiff foundation);
        3. the stiff-foundation rule: release the corners whose load is the most negative in the reference
           solution with every corner on the ground in contact (four corners: the linear law (2.3), the flat
           bottom compressing a stiff foundation linearly), Σ_free N_ref,i smallest;
        4. the most sticking corners;
        5. least constraint (Gauss): the body acceleration closest, in the kinetic metric M, to the
           unconstrained one M⁻¹f.

        Steps 3-5 are recorded in the phase log when they decided between configurations whose
        accelerations differ (the contact problem with Coulomb friction was not unique).
        """
        tJ = self.tol["jump"] * self.G
        jump = lambda k: 0.0 if prev_N is None else float(np.linalg.norm(force[k, :, 2] - prev_N))  # noqa: E731
        released = lambda k: float(np.sum(np.where(near & (combos[k] == FREE), n_ref, 0.0)))  # noqa: E731
        M, f = mats.mass[:6, :6], mats.force[:6]
        a_free = np.linalg.solve(M, f)
        gauss = lambda k: float((accel[k] - a_free) @ M @ (accel[k] - a_free))  # noqa: E731
        n_contacts = lambda k: int(np.sum(combos[k] != FREE))  # noqa: E731
        top = max(n_contacts(k) for k in consistent)
        group = [k for k in consistent if n_contacts(k) == top]
        keys = {
            k: (round(jump(k) / tJ), round(released(k) / tJ), -int(np.sum(combos[k] == STICK)), gauss(k))
            for k in group
        }
        group.sort(key=lambda k: keys[k])
        best = group[0]
        tA = self.tol["accel"] * self.g
        a_scale = np.linalg.norm(accel[best]) + tA
        rivals = [
            k
            for k in group[1:]
            if keys[k][0] == keys[best][0]
            and np.linalg.norm(accel[k] - accel[best]) > 1e-5 * a_scale + 10 * tA
        ]
        if rivals and not quiet:
            k = rivals[0]
            rule = (
                "stiff-foundation rule"
                if keys[k][1] != keys[best][1]
                else "most sticking"
                if keys[k][2] != keys[best][2]
                else "least constraint"
            )
            ref = f" (N_ref = {np.round(n_ref, 1).tolist()} N)" if rule.startswith("stiff") else ""
            self.notes.append(f"{rule}: {fmt(combos[best])} over {fmt(combos[k])}{ref}")
        return best

    # ---------------------------------------------------------------------------- impacts
    def impact(self, t, y, striking: list[int], taut: bool = False, normal_only: bool = False):
        """Velocity jump at an impact of the `striking` corners: `numerics.rigid.impacts.impact`."""
        return rigid_impacts.impact(self, t, y, striking, taut=taut, normal_only=normal_only)
