"""The phase loop of the rigid model (paper §2) behind `simulate_rigid` (`solve`): `_Run` solves
phase after phase, resolves impacts and contact changes, passes sustained cycles by compliant phases and
assembles the `RigidTrajectory`; `_transition` is its helper."""

from __future__ import annotations

from typing import cast

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._errors import SolveStatus
from ..._physics import rigid
from ..._physics.elastic import Constants, State
from ..._physics.rigid import FREE, SLIDE, STICK, Phase
from .compiled import (
    Jam,
    RopeWouldPush,
    as_numpy,
    chunked_outputs,
    rope_state,
    tree_index,
)
from .compliant import ChatterRule, run_episode, with_compliant_outputs
from .driver import Driver, Inconsistent
from .impacts import rope_jerk
from .records import PhaseRecord, RigidContactError, RigidTrajectory, fmt, merge

#: The persistent-contact rule after impacts (docs/rigid-contact.md); False only to compare without it.
PERSISTENT_CONTACT = True


class Run:
    """The phase loop of one `simulate_rigid` call: the saved samples, the phase log and the booked impact
    losses, filled phase by phase (`step`), and the trajectory assembled from them (`result`)."""

    def __init__(
        self,
        drv: Driver,
        ts: np.ndarray,
        t1: float,
        max_phases: int,
        max_steps: int,
        chatter: ChatterRule | None,
        verbose,
    ):
        self.drv, self.ts, self.t1 = drv, ts, t1
        self.max_phases, self.max_steps, self.chatter, self.verbose = max_phases, max_steps, chatter, verbose
        n_t = ts.size
        self.filled = np.zeros(n_t, dtype=bool)
        self.saved_states = None  # per leaf an (n_t, ...) host array, allocated at the first phase
        self.saved_phase = np.zeros(n_t, dtype=np.int64)
        self.saved_impact = np.zeros(n_t)
        self.records: list[PhaseRecord] = []
        self.phases: list[Phase] = []  # one per phase solve (the outputs are evaluated with these)
        self.record_of: list[int] = []  # per phase solve, its record in `records` (several when merged)
        self.impact_total = 0.0
        self.impact_events: list[tuple[float, float]] = []  # (time [s], loss [J]) of impacts and jerks
        self.switch_events: list[float] = []  # times [s] of contact changes without an impact
        self.compliant_mask = np.zeros(n_t, dtype=bool)  # saved samples inside compliant phases
        self.retried_at = None  # start time of a stalled phase chosen again (once)
        self.n_regularised = 0  # the current phase is the n-th in a row chosen by fallback 3 (`regularised`)

    def log(self, rec: PhaseRecord):
        """Append the record of the phase just solved, or merge it into the previous record when it lasted
        less than `min_phase` (see `_merge`)."""
        records = self.records
        if records and rec.t_end - rec.t_start < self.drv.tol["min_phase"]:
            records[-1] = merge(records[-1], rec)
        else:
            records.append(rec)
        self.record_of.append(len(records) - 1)

    def start(self, y0: State):
        """The state and first phase at t = 0 (with the inextensible rope, the start jerk first)."""
        drv = self.drv
        t, y = 0.0, y0
        if drv.inextensible:
            # A taut inextensible rope and a hoist already running at t = 0+: the start is a rope jerk.
            # The hoist speed just after the start (a jump at t = 0 may leave ds/dt(0) = 0 exactly).
            t_plus = 1e-9
            stretch, rate_error, _ = map(
                float, rope_state(jnp.asarray(t_plus, jnp.float64), y, drv.sc, drv.c)
            )
            drv.rope_taut = stretch >= -drv.tol["z"] * drv.L  # rope.slack = 0: just taut
            if drv.rope_taut and rate_error > drv.tol["v"] * drv.V:
                try:
                    y, _, loss = rope_jerk(drv, 0.0, y, t_rate=t_plus)
                except RopeWouldPush as err:
                    raise RigidContactError(str(err)) from None
                self.impact_total += loss
        phase, y, loss = drv.select_or_jam(t, y, "start")
        self.impact_total += loss
        self.t, self.y, self.phase, self.choice = t, y, phase, drv.take_notes()
        self.count_regularised()

    def resume(self, t: float, y: State):
        """The first phase at (t [s], y), a state of an earlier run (tests and experiments that start near
        a known event; `tests/data/make_rigid_edge_state.py`): chosen as after any event, with no start
        jerk (the inextensible rope's `_Driver.rope_taut` is the caller's to set)."""
        phase, y, loss = self.drv.select_or_jam(t, y, "resumed")
        self.impact_total += loss
        self.t, self.y, self.phase, self.choice = t, y, phase, self.drv.take_notes()
        self.count_regularised()

    def count_regularised(self):
        """After a choice of the next phase: how many in a row were fallback 3 (`_Driver.regularised`)."""
        self.n_regularised = self.n_regularised + 1 if self.drv.regularised else 0

    def step(self) -> bool:
        """Solve the current phase and choose the next one. Returns False when t1 is reached."""
        drv, t, y, phase = self.drv, self.t, self.y, self.phase
        if len(self.phases) >= self.max_phases:
            raise RigidContactError(
                f"more than max_phases = {self.max_phases} phases before t = {t:.9g} s (a Zeno sequence of "
                f"events? raise max_phases, or Settings.rest_velocity to let rocking settle). "
                f"Last phases:\n" + "\n".join(str(r) for r in self.records[-8:])
            )
        y, loss = drv.project(t, y, phase)
        self.impact_total += loss
        phase = drv.with_offsets(t, y, phase)
        g_start = drv.guards(t, y, phase) + as_numpy(phase.guard_offset)
        sts, sys_, result = drv.solve(y, phase, t, self.t1, self.ts)
        last = int(np.nonzero(np.isfinite(sts))[0][-1])  # the final state is saved after the last ts kept
        t_end = float(sts[last])
        y_end = tree_index(sys_, last)
        ok = result == diffrax.RESULTS.successful
        event = result == diffrax.RESULTS.event_occurred
        if not (bool(ok) or bool(event)):
            return self.stalled(t, y, phase, result)
        self.save(t, t_end, phase, sys_)
        modes = cast(
            tuple[str, str, str, str], tuple(rigid.MODE_NAMES[int(m)] for m in as_numpy(phase.contact))
        )
        rope_name = rigid.ROPE_NAMES[int(phase.rope)]
        if not bool(event) or t_end >= self.t1:
            self.log(PhaseRecord(t, t_end, modes, bool(phase.rest), "t1", y_end, rope_name, self.choice))
            return False
        new, y_end = self.after_event(t, t_end, y_end, phase, g_start, modes, rope_name)
        if self.verbose:
            print(self.records[-1], f"[{drv.accepted} steps so far]", flush=True)
        self.t, self.y, self.phase, self.choice = t_end, y_end, new, drv.take_notes()
        self.count_regularised()
        rule = self.chatter
        why = rule and (
            self.detect_regularised(rule)
            or rule.detect(self.impact_events, t_end)
            or rule.detect_switching(self.switch_events, t_end)
        )
        if why:
            # A sustained cycle of impacts or contact changes, or no consistent configuration again and
            # again: pass it with a compliant phase, then choose again.
            return self.compliant(t_end, y_end, new, why)
        return True

    def detect_regularised(self, rule: ChatterRule) -> str:
        """A description if the phase just chosen is the `rule.max_regularised`-th in a row without a
        consistent configuration (fallback 3), else "" (`ChatterRule.max_regularised`)."""
        if self.n_regularised < rule.max_regularised:
            return ""
        return (
            f"no consistent configuration {self.n_regularised} times in a row (least-violation fallback; "
            f"last: {self.drv.regularised})"
        )

    def save(self, t: float, t_end: float, phase: Phase, sys_):
        """Keep the phase and its states at the saved times t <= ts <= t_end not yet filled."""
        idx = len(self.phases)
        self.phases.append(phase)
        ts, filled = self.ts, self.filled
        sys_np = jax.tree_util.tree_map(np.asarray, sys_)  # index on the host, not one dispatch per sample
        if self.saved_states is None:
            self.saved_states = jax.tree_util.tree_map(
                lambda x: np.zeros((ts.size,) + x.shape[1:], x.dtype), sys_np
            )
        ks = np.nonzero((ts >= t) & (ts <= t_end) & ~filled)[0]
        if ks.size:
            jax.tree_util.tree_map(lambda dst, src: dst.__setitem__(ks, src[ks]), self.saved_states, sys_np)
            self.saved_phase[ks] = idx
            self.saved_impact[ks] = self.impact_total
            filled[ks] = True

    def stalled(self, t: float, y: State, phase: Phase, result) -> bool:
        """A phase that failed (typically a corner sliding with a slip speed near zero, where the slip
        direction turns quickly): its mean step fell below `StallRule.min_step` or it reached `max_steps`.
        Chosen again once at its start without that configuration; a second stall at the same time is
        passed by a compliant phase (or raises without `chatter`)."""
        drv = self.drv
        opt = drv.options
        if result == diffrax.RESULTS.dt_min_reached and opt.stall_window > 0:
            how_stalled = f"stalled (mean step < {opt.stall_step:g} s over {opt.stall_window} steps)"
        else:
            how_stalled = "stalled at max_steps"
        if self.retried_at != t and not bool(phase.rest):
            self.retried_at = t
            stalled = fmt(as_numpy(phase.contact))
            drv.exclude = as_numpy(phase.contact).copy()
            try:
                phase, y, loss = drv.select_or_jam(t, y, "after a stalled phase")
            finally:
                drv.exclude = None
            self.impact_total += loss
            how = drv.take_notes()
            choice = f"{stalled} {how_stalled}, chosen again without it"
            choice += f"; {how}" if how else ""
            self.y, self.phase, self.choice = y, phase, choice
            self.count_regularised()
            return True
        if self.chatter is None or bool(phase.rest):
            hint = ", or pass chatter=ChatterRule() to pass it by a compliant phase"
            hint = hint if self.chatter is None else ""
            raise RigidContactError(
                f"the phase starting at t = {t:.9g} s failed: {how_stalled}, {result} "
                f"(raise max_steps = {self.max_steps} or loosen rtol/atol{hint})"
            )
        if self.saved_states is None:
            self.saved_states = jax.tree_util.tree_map(
                lambda x: np.zeros((self.ts.size,) + np.shape(x), np.asarray(x).dtype), y
            )
        return self.compliant(t, y, phase, f"{fmt(as_numpy(phase.contact))} {how_stalled}, twice")

    def after_event(self, t, t_end, y_end, phase, g_start, modes, rope_name):
        """The guards of `phase` fired at (t_end, y_end): log the phase, resolve an impact or rope jerk, and
        choose the next phase. Returns `(next phase, state)`."""
        drv = self.drv
        drv.regularised = ""  # set again only if the choice below is fallback 3
        g = drv.guards(t_end, y_end, phase) + as_numpy(phase.guard_offset)
        # Fired: near zero now, and well below where the guard started (a guard that started at its small
        # offset and stayed there has not fired).
        fired = [k for k in range(rigid.N_GUARDS) if g[k] <= drv.tol["trigger"] and g[k] <= 0.5 * g_start[k]]
        if not fired:
            fired = [int(np.argmin(g))]
        if drv.debug:
            print(f"  guards at start {g_start}\n  guards at end   {g}")
        end = ",".join(rigid.GUARD_NAMES[k] for k in fired)
        contact = as_numpy(phase.contact)
        corners, cv, _ = drv.kin(t_end, y_end)
        striking = [k for k in fired if k < 4 and contact[k] == FREE and not bool(phase.rest)]
        hard = [i for i in striking if cv[i, 2] < -drv.tol["v"] * drv.V]
        choice = self.choice

        def record(end: str, state_end: State) -> PhaseRecord:
            return PhaseRecord(t, t_end, modes, bool(phase.rest), end, state_end, rope_name, choice)

        if 11 in fired:
            # The slack inextensible rope reaches its length: a jerk if it would stretch, then a new phase.
            _, rate_error, _ = map(float, rope_state(jnp.asarray(t_end, jnp.float64), y_end, drv.sc, drv.c))
            y_before = y_end
            drv.rope_taut = True
            if rate_error > drv.tol["v"] * drv.V:
                try:
                    y_end, _, loss = rope_jerk(drv, t_end, y_end, fallback=True)
                except RopeWouldPush as err:
                    raise RigidContactError(str(err)) from None
                self.impact_total += loss
                self.impact_events.append((t_end, loss))
                how = drv.take_notes()
                end += f" rope-jerk ({loss:.4g} J{', ' + how if how else ''})"
            self.log(record(end, y_before))
            new, y_end, loss = drv.select_or_jam(t_end, y_end, "after the rope became taut", phase)
            self.impact_total += loss
        elif hard:
            y_before = y_end
            y_end, end = self.after_impact(t_end, y_end, phase, hard, end)
            self.log(record(end, y_before))
            new, y_end, loss = drv.select_or_jam(t_end, y_end, "after impact")
            self.impact_total += loss
        else:
            self.log(record(end, y_end))
            self.switch_events.append(t_end)
            new, y_end, loss = _transition(drv, t_end, y_end, phase, fired, self.ts)
            self.impact_total += loss
        return new, y_end

    def after_impact(self, t_end, y_end, phase, hard, end):
        """The impact of the corners `hard` at (t_end, y_end), then the settling and persistent-contact
        rules. Returns `(state after it, the phase's end description)`."""
        drv = self.drv
        rest_velocity = float(drv.settings.rest_velocity)
        y_end, loss = drv.impact(t_end, y_end, hard, taut=int(phase.rope) == rigid.ROPE_TAUT)
        self.impact_total += loss
        self.impact_events.append((t_end, loss))
        how = drv.take_notes()
        how = f", {how}" if how else ""
        end += f" impact:{''.join(rigid.CORNERS[i] for i in hard)} ({loss:.4g} J{how})"
        # Settling: if every corner on the ground leaves the impact slower than rest_velocity, the
        # impact is plastic for all of them (their normal velocities are removed; flat on the ground,
        # the load stops). This ends the otherwise endless sequence of ever smaller rocking impacts.
        corners1, cv1, ke1 = drv.kin(t_end, y_end)
        near = corners1[:, 2] < drv.tol["z"] * drv.L
        if np.max(np.linalg.norm(cv1[near], axis=1)) < rest_velocity:
            if np.all(near):
                y_end = eqx.tree_at(
                    lambda s: (s.velocity, s.angular_velocity), y_end, (jnp.zeros(3), jnp.zeros(3))
                )
                self.impact_total += ke1
            else:
                y_end, loss = drv._project(t_end, y_end, np.zeros(4, dtype=bool), near)
                self.impact_total += loss
            end += " settled"
        elif PERSISTENT_CONTACT and np.max(np.abs(cv1[near, 2])) < rest_velocity:
            # Persistent contact: every corner on the ground leaves the impact with a normal velocity
            # below rest_velocity (a corner the impulse lifts, or one still approaching): their normal
            # velocities are removed (plastic for all of them) and the next configuration is chosen
            # with all of them on the ground (docs/rigid-contact.md, "Persistent contact").
            lifted = [rigid.CORNERS[i] for i in range(4) if near[i] and cv1[i, 2] > drv.tol["v"] * drv.V]
            if lifted:
                taut_now = drv.inextensible and drv.rope_taut
                project = drv._project_taut if taut_now else drv._project
                y_end, loss = project(t_end, y_end, np.zeros(4, dtype=bool), near)
                self.impact_total += loss
                end += (
                    f" persistent contact ({','.join(lifted)} held, "
                    f"|v_n| <= {np.max(np.abs(cv1[near, 2])):.2g} m/s)"
                )
        return y_end, end

    def compliant(self, t0: float, y0: State, phase0: Phase, why: str) -> bool:
        """A compliant phase from (t0, y0) (`numerics.rigid.compliant`): fill its saved samples, log it,
        book its hand-back loss, and choose the next phase. Returns False when t1 is reached.

        The phase is not left while no contact configuration is consistent at its end (the choice would
        need fallback 3, the least-violating configuration): it is extended from the compliant state, with
        no hand-back in between, until one is, or to t1 (`ChatterRule.max_regularised`). Without a rigid
        solution (a Painlevé-type or jammed contact) the stiff-foundation limit, which the compliant phase
        integrates, is the motion; the extensions are counted in the phase log."""
        drv, chatter = self.drv, self.chatter
        assert chatter is not None  # called only with a ChatterRule (`advance`, `stalled`)
        idx = len(self.phases)
        self.phases.append(phase0)  # a placeholder: these samples' outputs are the compliant model's
        t, y_el = t0, y0
        extended: list[str] = []  # when and why each extension was needed (the least violation)
        while True:
            ep = run_episode(drv, t, y_el, self.t1, self.ts, self.filled, chatter)
            drv.accepted += ep.accepted
            drv.rejected += ep.rejected
            ks = ep.user_index
            if ks.size:
                jax.tree_util.tree_map(
                    lambda dst, src: dst.__setitem__(ks, src), self.saved_states, ep.user_states
                )
                self.saved_phase[ks] = idx
                self.saved_impact[ks] = self.impact_total
                self.filled[ks] = True
                self.compliant_mask[ks] = True
            if ep.t_end >= self.t1:
                break
            # Consistency at the end, before leaving (fallback 3 switched off): the state handed back.
            drv.allow_regularised = False
            try:
                phase, y, loss = drv.select_or_jam(ep.t_end, ep.y_end, "after a compliant phase")
                break
            except Inconsistent as err:
                drv.take_notes()  # the notes of a choice not taken
                extended.append(f"{ep.t_end:.6f} s: {err}")
                t, y_el = ep.t_end, ep.y_before_handback  # go on from the compliant state
            finally:
                drv.allow_regularised = True
        self.impact_total += ep.handback_loss  # only the last hand-back is applied
        loaded = "".join(c for c, on in zip(rigid.CORNERS, ep.loaded, strict=True) if on) or "none"
        end = (
            "t1"
            if ep.t_end >= self.t1
            else (
                f"compliant phase ended: loaded {loaded} steady for {ep.steady * 1e3:.3g} ms; "
                f"hand-back {ep.handback_loss:.4g} J"
            )
        )
        how = (
            f"compliant phase: {why}; foundation k = {chatter.stiffness:g} N/m, critically damped, "
            f"ε = {chatter.regularisation_velocity:g} m/s"
            + (f", rope {chatter.rope_stiffness:g} N/m" if drv.inextensible else "")
        )
        if extended:
            how += (
                f"; extended {len(extended)} time{'s' if len(extended) > 1 else ''}: no consistent "
                f"configuration at its end (first at {extended[0]}; last at {extended[-1]})"
            )
        modes = cast(tuple[str, str, str, str], tuple("spring" if on else "free" for on in ep.loaded))
        self.log(
            PhaseRecord(
                t0,
                ep.t_end,
                modes,
                False,
                end,
                ep.y_before_handback,
                "compliant" if drv.inextensible else "elastic",
                how,
            )
        )
        self.impact_events.clear()
        self.switch_events.clear()
        if self.verbose:
            print(self.records[-1], f"[{drv.accepted} steps so far]", flush=True)
        if ep.t_end >= self.t1:
            return False
        self.impact_total += loss
        self.t, self.y, self.phase, self.choice = ep.t_end, y, phase, drv.take_notes()
        self.count_regularised()
        return True

    def result(self, c: Constants, settings: rigid.Settings) -> RigidTrajectory:
        """The trajectory at the saved times, with the outputs of every phase (`_chunked_outputs`; the
        compliant phases' from the compliant model) and the phase log."""
        drv, ts, saved_states = self.drv, self.ts, self.saved_states
        for k in np.nonzero(~self.filled)[0]:  # cannot happen unless ts extends past the last phase
            raise RigidContactError(f"saved time {ts[k]} s was not reached")
        states = jax.tree_util.tree_map(jnp.asarray, saved_states)
        out = chunked_outputs(
            ts, saved_states, self.saved_phase, self.phases, drv.sc, c, settings, drv.inextensible
        )
        if np.any(self.compliant_mask):
            out = with_compliant_outputs(out, ts, saved_states, self.compliant_mask, drv, self.chatter)
        euler = out.euler.at[:, :2].set(jnp.unwrap(out.euler[:, :2], axis=0))
        return RigidTrajectory(
            ts=jnp.asarray(ts),
            position=states.position,
            velocity=states.velocity,
            euler=euler,
            angular_velocity=states.angular_velocity,
            corners=out.corners,
            normal_forces=out.normal,
            friction_forces=out.friction,
            ground_reaction=jnp.sum(out.normal, axis=-1),
            rope_tension=out.rope_tension,
            tip_position=states.tip_position,
            energy=out.energy,
            hoist_work=states.hoist_work,
            damping_loss=states.damping_loss,
            friction_work=states.friction_work,
            impact_loss=jnp.asarray(self.saved_impact),
            states=states,
            status=jnp.asarray(SolveStatus.OK, jnp.int32),
            num_accepted_steps=jnp.asarray(drv.accepted),
            num_rejected_steps=jnp.asarray(drv.rejected),
            phase_index=jnp.asarray(np.asarray(self.record_of, dtype=np.int64)[self.saved_phase]),
            phases=tuple(self.records),
        )


def _transition(drv: Driver, t_e: float, y_e: State, phase: Phase, fired: list[int], ts):
    """The next phase after the guards `fired` of `phase` reached zero at (t_e, y_e) (no impact).

    **Returns** `(phase, y, loss [J])`: `y` is `y_e`, or `y_e` after a tangential impact (`_Driver.jam`)
    where no configuration was consistent."""
    contact, starting = as_numpy(phase.contact), as_numpy(phase.starting)
    _, cv, _ = drv.kin(t_e, y_e)
    speed = np.linalg.norm(cv[:, :2], axis=1)
    tangential = [k - 4 for k in fired if 4 <= k < 8 and contact[k - 4] == SLIDE and not phase.rest]
    # Bookkeeping events of slips that started from rest: the speed has reached 2 v_stop (now an ordinary
    # slide), or the slip has turned by 90° while still moving (new reference direction; the friction
    # already follows the velocity). Nothing changes physically: same configuration.
    grown = [i for i in tangential if starting[i] and speed[i] >= 1.5 * drv.v_stop]
    turned = [i for i in tangential if starting[i] and 0.05 * drv.v_stop <= speed[i] < 1.5 * drv.v_stop]
    if (grown or turned) and len(grown) + len(turned) == len(fired):
        hint, start = as_numpy(phase.slip_hint).copy(), starting.copy()
        for i in grown + turned:
            hint[i] = cv[i, :2] / speed[i]
        for i in grown:
            start[i] = False
        return (
            rigid.make_phase(
                contact,
                rest=False,
                slip_hint=hint,
                starting=start,
                free_on_ground=as_numpy(phase.free_on_ground),
                rope=int(phase.rope),
            ),
            y_e,
            0.0,
        )
    where = f"after {','.join(rigid.GUARD_NAMES[k] for k in fired)}"
    # A slip that died out: choose at the event itself (the corner is now resting).
    if any(speed[i] < 1.5 * drv.v_stop for i in tangential):
        return drv.select_or_jam(t_e, y_e, where, phase)
    # Otherwise look ahead: continue the old phase (guards disabled) until the fired guards are clearly
    # negative, and choose there.
    blind = eqx.tree_at(lambda p: p.guard_offset, phase, jnp.full(rigid.N_GUARDS, 1e6, dtype=jnp.float64))
    dt = 1e-6
    y_la, t_la = y_e, t_e
    for _ in range(11):
        t_la = t_e + dt
        sts, sys_, result = drv.solve(y_e, blind, t_e, t_la, ts)
        y_la = tree_index(sys_, int(np.nonzero(np.isfinite(sts))[0][-1]))
        g = drv.guards(t_la, y_la, phase)
        if all(g[k] < -drv.tol["lookahead"] for k in fired):
            break
        dt *= 2.0
    # A contact whose load vanished, a free corner that reached the ground (or, lying on it, would take
    # load) or a sticking corner whose friction reached μN: not the same configuration again (`_select`).
    hard = [k for k in fired if k < 4 or (4 <= k < 8 and contact[k - 4] == STICK)]
    drv.exclude = contact.copy() if hard and not bool(phase.rest) else None
    try:
        return drv.select(t_la, y_la, where, phase), y_e, 0.0
    except Jam:
        # The tangential impact where the event happened, then choose there.
        return drv.select_or_jam(t_e, y_e, where, phase)
    finally:
        drv.exclude = None
