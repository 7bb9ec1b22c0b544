"""The rigid model's phase driver (paper §2): `simulate_rigid(scenario, t1)`.

The motion is a sequence of phases, each a fixed contact configuration (`physics.rigid.Phase`). A phase
is integrated by one compiled `diffrax.diffeqsolve` (the phase is an array argument, so every phase reuses
the same compilation) that stops at the first zero of the phase's guards (`diffrax.Event` with bisection
root finding). Between phases, on the host:

1. the guards that fired are identified;
2. a free corner reaching the ground with a downward velocity is an impact: the velocity jump is solved
   with Newton's restitution law at the striking corner (coefficient `restitution`), zero normal velocity
   after the impact at the other corners on the ground, and Coulomb friction impulses (sticking if the
   sticking impulse lies in the friction cone, else sliding against the pre-impact slip);
3. otherwise the old phase is continued a short time past the event (the *look-ahead*, until the fired
   guards are clearly negative) and the next contact configuration is chosen there: every combination of
   modes (free / slide / stick) of the corners on the ground is evaluated, and the ones that are
   consistent (N_i >= 0, friction of sticking corners within μN_i, sliding from rest in the direction of the
   resulting acceleration, free corners on the ground not accelerating into it, or, for a load at rest on
   all four corners, the rest conditions of `statics`) are kept. Among them the resolution rule
   (`_Driver._rank`) picks one: the most contacts, then the most continuous normal forces, then the
   stiff-foundation rule (free the corners whose load is most negative when every corner on the ground is
   in contact: the linear law (2.3) on four corners), then the most sticking corners, then least
   constraint (Gauss). The next phase starts from the event state.

Where no configuration is consistent, documented fallbacks take over, in order: the tolerances relaxed
(degenerate contacts), a tangential impact of the sliding corners on the ground (Painlevé-type
inconsistency; "dynamic jamming"), the least-violating configuration as a short phase. Impacts with no
consistent Coulomb impulse (a grazing touch) take the frictionless one; several consistent impulses, the
most dissipative. A phase that stalls at `max_steps` is chosen again once without its configuration.
Each such step is recorded in the phase log (`PhaseRecord.choice`, or the impact's
`end`); see docs/rigid-model.md, "Resolution of contact choices and impacts". `RigidContactError` is left
for inputs that cannot be continued: too many phases, a failed phase solve, an impact that would gain
energy with the given restitution, an inextensible rope that cannot start.
"""

from __future__ import annotations

import dataclasses
import itertools

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, Int

from .._errors import ScenarioError, SolveStatus, require_x64
from ..physics import rigid
from ..physics.elastic import Constants, State
from ..physics.energy import Energy
from ..physics.params import Scenario
from ..physics.rigid import FREE, SLIDE, STICK, Phase
from .rigid_compliant import ChatterRule, compliant_scenario, elastic_outputs, run_episode


class RigidContactError(RuntimeError):
    """The rigid model cannot continue with these inputs: more than `max_phases` phases (a Zeno sequence),
    a phase solve that failed (`max_steps`, tolerances), an impact that would gain energy with the given
    restitution, or an inextensible rope whose start has no consistent jerk. The message names what to
    change. Ambiguous or inconsistent contact problems are resolved, not raised (module docstring)."""


@dataclasses.dataclass(frozen=True)
class PhaseRecord:
    """One phase of a rigid-model solve.

    - `t_start`, `t_end`: [s]; `contact`: mode per corner D, E, F, H ("free", "slide", "stick");
    - `rest`: the load rested on all four corners (held fixed);
    - `end`: why the phase ended: the guards that fired (e.g. "normal:D", "tangential:E", "rest:slip",
      "rope:slack"), "impact:F" when an impact followed, "rope-jerk" when the inextensible rope snapped
      taut, or "t1".
    - `state_end`: the state at `t_end` (before any impact).
    - `rope`: "elastic" (2.14), or the inextensible rope (2.15) "taut" or "slack".
    - `choice`: how the configuration was chosen where that needed more than consistency (several
      consistent configurations: the rule that picked it; none: the regularised fallback), else "".
    - `merged`: how many sub-microsecond phases were merged into this record (below).

    A phase that lasted less than 1 µs (`min_phase`) has no record of its own: it is merged into the
    previous one, whose `end` then reads "<its end> => <the short configuration> (<duration> s) -> <the
    short phase's end>" (see `_merge`).
    """

    t_start: float
    t_end: float
    contact: tuple[str, str, str, str]
    rest: bool
    end: str
    state_end: State | None = dataclasses.field(default=None, compare=False, repr=False)
    rope: str = "elastic"
    choice: str = ""
    merged: int = 0

    def __str__(self) -> str:
        modes = "rest" if self.rest else " ".join(f"{c}:{m}" for c, m in zip(rigid.CORNERS, self.contact,
                                                                            strict=True))
        if self.rope != "elastic":
            modes += f"  rope:{self.rope}"
        choice = f"  [{self.choice}]" if self.choice else ""
        return f"{self.t_start:10.6f} - {self.t_end:10.6f} s  {modes:40s} -> {self.end}{choice}"


class RigidTrajectory(eqx.Module):
    """Outputs of `simulate_rigid` at the saved times; the field names are those of `Trajectory`.

    - `ts`, `position`, `velocity`, `euler`, `angular_velocity`, `corners`, `normal_forces`,
      `friction_forces`, `ground_reaction`, `rope_tension`, `tip_position`, `energy`, `hoist_work`,
      `damping_loss`, `friction_work`, `states`, `status`, `num_accepted_steps`, `num_rejected_steps`:
      as in `Trajectory` (`energy.ground_spring` is 0 on the rigid ground).
    - `impact_loss`: kinetic energy lost in impacts up to each saved time [J].
    - `phase_index`: index into `phases` of the phase each saved time belongs to.
    - `phases`: the phase log, a tuple of `PhaseRecord` (static).
    """

    ts: Float[Array, " n_t"]
    position: Float[Array, "n_t 3"]
    velocity: Float[Array, "n_t 3"]
    euler: Float[Array, "n_t 3"]
    angular_velocity: Float[Array, "n_t 3"]
    corners: Float[Array, "n_t 4 3"]
    normal_forces: Float[Array, "n_t 4"]
    friction_forces: Float[Array, "n_t 4 3"]
    ground_reaction: Float[Array, " n_t"]
    rope_tension: Float[Array, " n_t"]
    tip_position: Float[Array, "n_t 3"]
    energy: Energy
    hoist_work: Float[Array, " n_t"]
    damping_loss: Float[Array, " n_t"]
    friction_work: Float[Array, " n_t"]
    impact_loss: Float[Array, " n_t"]
    states: State
    status: Int[Array, ""]
    num_accepted_steps: Int[Array, ""]
    num_rejected_steps: Int[Array, ""]
    phase_index: Int[Array, " n_t"]
    phases: tuple = eqx.field(static=True)

    @property
    def ok(self):
        return self.status == SolveStatus.OK

    def energy_residual(self) -> Float[Array, " n_t"]:
        """E(t) - E(0) - [W_hoist - D_damping - W_friction - W_impact](t) [J]: zero up to solver error."""
        e = self.energy
        mech = e.kinetic + e.potential + e.ground_spring + e.rope_spring + e.boom_spring
        supplied = self.hoist_work - self.damping_loss - self.friction_work - self.impact_loss
        return (mech - mech[..., :1]) - (supplied - supplied[..., :1])

    def phase_log(self) -> str:
        return "\n".join(str(p) for p in self.phases)


# --------------------------------------------------------------------------------- compiled pieces


@dataclasses.dataclass(frozen=True)
class _Options:
    rtol: float
    atol: float
    max_steps: int
    event_atol: float


def _phase_solve(scenario, c, phase, settings, y0, t0, t1, ts, options: _Options, inextensible: bool = False):
    event = diffrax.Event(rigid.event_condition,
                          root_finder=optx.Bisection(rtol=1e-14, atol=options.event_atol), direction=False)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rigid.vector_field), diffrax.Tsit5(), t0=t0, t1=t1, dt0=None, y0=y0,
        args=(scenario, c, phase, settings) + ((True,) if inextensible else ()),
        saveat=diffrax.SaveAt(ts=ts, t1=True),
        stepsize_controller=diffrax.PIDController(rtol=options.rtol, atol=options.atol),
        max_steps=options.max_steps, event=event, throw=False)
    return sol.ts, sol.ys, sol.result, sol.stats["num_accepted_steps"], sol.stats["num_rejected_steps"]


_phase_solve_jit = eqx.filter_jit(_phase_solve)
_raw_guards_jit = eqx.filter_jit(rigid.raw_guards)


@eqx.filter_jit
def _eval_candidates(t, y, scenario, c, settings, contact, hints, rope, inextensible=False):
    """Contact forces, corner accelerations, body accelerations and rope tension for a batch of
    configurations (rope mode `rope`, an integer array)."""

    def one(ct, h):
        ph = rigid.make_phase(ct, slip_hint=h, rope=rope)
        d = rigid.contact_dynamics(t, y, scenario, c, ph, settings, inextensible)
        return d.force, d.corner_accel, d.accel, d.loads.rope_tension

    return jax.vmap(one)(contact, hints)


@eqx.filter_jit
def _eval_rope_impulses(t, y, scenario, c, modes, slip_dirs, normal_target, rcond):
    return jax.vmap(lambda m, s: rigid.rope_impulse_response(t, y, scenario, c, m, s, normal_target, rcond))(
        modes, slip_dirs)


@eqx.filter_jit
def _eval_impulses(y, scenario, c, modes, slip_dirs, normal_target, rcond):
    return jax.vmap(lambda m, s: rigid.impulse_response(y, scenario, c, m, s, normal_target, rcond))(
        modes, slip_dirs)


_contact_matrices = eqx.filter_jit(rigid.contact_matrices)


@eqx.filter_jit
def _rope_direction(t, y, scenario, c):
    return rigid.loads(t, y, scenario, c).rope_direction


@eqx.filter_jit
def _rope_state(t, y, scenario, c):
    """|AB| - l(t) [m], d|AB|/dt - dl/dt [m/s] and ds/dt [m/s] of the inextensible rope."""
    ld = rigid.loads(t, y, scenario, c, inextensible=True)
    return ld.stretch, ld.rope_rate_error, ld.hoist_rate


class _Jam(Exception):
    """No consistent contact configuration while corners on the ground slide: resolve by a tangential
    impact (`_Driver.jam`), then choose again."""


class _RopeWouldPush(Exception):
    """No configuration (or impulse) with the taut inextensible rope has S >= 0: try the slack rope."""


@eqx.filter_jit
def _forces(t, y, scenario, c, phase, settings, inextensible=False):
    return rigid.contact_dynamics(t, y, scenario, c, phase, settings, inextensible).force


@eqx.filter_jit
def _outputs(ts, ys, scenario, c, phases, settings, inextensible=False):
    return jax.vmap(lambda t, y, ph: rigid.output(t, y, scenario, c, ph, settings, inextensible))(ts, ys,
                                                                                               phases)


#: Saved samples per output evaluation (`_chunked_outputs`): one compiled shape serves every `n_save`.
OUTPUT_CHUNK = 1024


def _chunked_outputs(ts, states, phase_index, phases, scenario, c, settings, inextensible):
    """`rigid.output` at every saved time, in chunks of `OUTPUT_CHUNK` samples (the last one padded by
    repeating its final sample), concatenated on the host. One compiled evaluation of fixed shape serves
    every number of saved times; a single vmap over all of them (25 001 samples) did not return.

    **Arguments**
    - `ts` (n_t) [s]; `states`: the saved `State`, host arrays with a leading n_t axis; `phase_index` (n_t):
      index into `phases` of each sample's phase; `scenario`, `c`, `settings`, `inextensible`: as for
      `rigid.output`.

    **Returns** a `rigid.Output` with a leading n_t axis.
    """
    n_t = ts.size
    table = jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *phases)
    parts = []
    for start in range(0, n_t, OUTPUT_CHUNK):
        sel = np.minimum(np.arange(start, start + OUTPUT_CHUNK), n_t - 1)
        chunk_states = jax.tree_util.tree_map(lambda x: jnp.asarray(x[sel]), states)
        chunk_phases = jax.tree_util.tree_map(lambda x: jnp.asarray(x[phase_index[sel]]), table)
        out = _outputs(jnp.asarray(ts[sel]), chunk_states, scenario, c, chunk_phases, settings, inextensible)
        m = min(OUTPUT_CHUNK, n_t - start)
        parts.append(jax.tree_util.tree_map(lambda x: np.asarray(x)[:m], out))
    return jax.tree_util.tree_map(lambda *xs: jnp.asarray(np.concatenate(xs)), *parts)


def _tree_index(tree, i):
    return jax.tree_util.tree_map(lambda x: x[i], tree)


def _np(x):
    return np.asarray(x)


# --------------------------------------------------------------------------------- the driver


class _Driver:
    def __init__(self, scenario: Scenario, c: Constants, settings: rigid.Settings, options: _Options,
                 restitution: float, tol: dict):
        self.sc, self.c, self.settings, self.options = scenario, c, settings, options
        self.e = float(restitution)
        sc = rigid.scales(scenario)
        self.G, self.L, self.V, self.g = (float(sc.force), float(sc.length), float(sc.velocity),
                                          float(sc.acceleration))
        self.mu = float(scenario.foundation.friction_coefficient)
        self.v_stop = float(settings.stop_velocity)
        self.tol = tol
        self.accepted = 0
        self.rejected = 0
        self.debug = False
        self.allow_jam = True  # fallback 2 of the configuration choice (off while choosing after a jam)
        self.exclude = None  # contact modes not to choose again at once (`_transition`)
        self.notes: list[str] = []  # how ambiguous or inconsistent contact choices were resolved (phase log)
        self.inextensible = False
        self.rope_taut = False  # the inextensible rope is at its length (taut, or may be): try taut first

    # ---------------------------------------------------------------------------- helpers
    def take_notes(self) -> str:
        """The resolution notes gathered since the last call, as one string (and forget them)."""
        out, self.notes = "; ".join(dict.fromkeys(self.notes)), []
        return out

    def guards(self, t, y, phase) -> np.ndarray:
        return _np(_raw_guards_jit(jnp.asarray(t), y, self.sc, self.c, phase, self.settings,
                                   self.inextensible))

    def matrices(self, t, y, rope: int = rigid.ROPE_ELASTIC):
        m = _contact_matrices(jnp.asarray(t), y, self.sc, self.c, self.settings, rope)
        return jax.tree_util.tree_map(_np, m)

    def kin(self, t, y):
        """Corners [m], corner velocities [m/s] and the load's kinetic energy [J]."""
        m = self.matrices(t, y)
        u = np.concatenate([_np(y.velocity), _np(y.angular_velocity)])
        return m.corners, m.corner_velocity, float(0.5 * u @ m.mass @ u)

    def with_offsets(self, t, y, phase: Phase) -> Phase:
        raw = self.guards(t, y, phase)
        off = np.where(raw <= self.tol["guard_start"], self.tol["guard_start"] - raw, 0.0)
        return eqx.tree_at(lambda p: p.guard_offset, phase, jnp.asarray(off))

    def solve(self, y, phase, t0, t1, ts):
        # Strongly typed float64 everywhere (a weakly typed leaf would compile the solve a second time).
        t0, t1 = jnp.asarray(t0, dtype=jnp.float64), jnp.asarray(t1, dtype=jnp.float64)
        ts_c = jnp.clip(jnp.asarray(ts, dtype=jnp.float64), t0, t1)
        out = _phase_solve_jit(self.sc, self.c, phase, self.settings, y, t0, t1, ts_c, self.options,
                               self.inextensible)
        sts, sys_, result, acc, rej = out
        self.accepted += int(acc)
        self.rejected += int(rej)
        return _np(sts), sys_, result

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
        u = np.concatenate([_np(y.velocity), _np(y.angular_velocity)])
        Minv = np.linalg.inv(mats.mass)
        du = -Minv @ J.T @ np.linalg.pinv(J @ Minv @ J.T, rcond=1e-10) @ (J @ u)
        u1 = u + du
        loss = 0.5 * u @ mats.mass @ u - 0.5 * u1 @ mats.mass @ u1
        return eqx.tree_at(lambda s: (s.velocity, s.angular_velocity), y,
                           (jnp.asarray(u1[:3]), jnp.asarray(u1[3:]))), float(loss)

    def _project_taut(self, t, y, full: np.ndarray, normal: np.ndarray, rate_error: float = 0.0):
        """`_project` with the taut inextensible rope: the boom tip's velocity joins the coordinates and
        the rope's rate d|AB|/dt is kept, less `rate_error` [m/s] (a rope impulse P does the hoist work
        P ds/dt, booked as in the rope jerk). Returns (y, loss [J])."""
        mats = self.matrices(t, y, rigid.ROPE_TAUT)
        rows = [mats.jacobians[i] for i in range(4) if full[i]]
        rows += [mats.jacobians[i, 2:3] for i in range(4) if normal[i] and not full[i]]
        if not rows:
            return y, 0.0
        u = np.concatenate([_np(y.velocity), _np(y.angular_velocity), _np(y.tip_velocity)])
        J = np.concatenate(rows + [mats.rope_row[None, :]], axis=0)
        b = np.zeros(J.shape[0])
        b[-1] = mats.rope_row @ u - rate_error  # the rope keeps its rate (less rate_error)
        Minv = np.linalg.inv(mats.mass)
        lam = np.linalg.pinv(J @ Minv @ J.T, rcond=1e-10) @ (J @ u - b)
        u1 = u - Minv @ J.T @ lam
        _, _, s_dot = map(float, _rope_state(jnp.asarray(t), y, self.sc, self.c))
        work = float(lam[-1]) * s_dot  # the rope impulse P = λ_rope pulls the tip towards B
        loss = work - (0.5 * u1 @ mats.mass @ u1 - 0.5 * u @ mats.mass @ u)
        y1 = eqx.tree_at(lambda s: (s.velocity, s.angular_velocity, s.tip_velocity, s.hoist_work), y,
                         (jnp.asarray(u1[:3]), jnp.asarray(u1[3:6]), jnp.asarray(u1[6:]),
                          y.hoist_work + work))
        return y1, float(loss)

    def project(self, t, y, phase: Phase):
        """Remove the velocity components that the phase's constraints forbid: the slip of sticking corners
        and of corners that start sliding from rest (their slip died out below the stop velocity; they
        restart along the direction chosen by Coulomb's law), and the normal velocity of contacts. A tiny
        impulse; the kinetic energy it removes [J] is returned."""
        if phase.rest:
            _, _, ke = self.kin(t, y)
            return eqx.tree_at(lambda s: (s.velocity, s.angular_velocity), y,
                               (jnp.zeros(3), jnp.zeros(3))), ke
        contact, starting = _np(phase.contact), _np(phase.starting)
        full, normal = (contact == STICK) | ((contact == SLIDE) & starting), contact != FREE
        if self.inextensible and int(phase.rope) == rigid.ROPE_TAUT:
            return self._project_taut(t, y, full, normal)
        return self._project(t, y, full, normal)

    def select(self, t, y, where: str, previous: Phase | None = None) -> Phase:
        """Choose the contact configuration at (t, y) (see the module docstring). With the inextensible
        rope at its length, the taut rope (S >= 0) is tried first, then the slack rope."""
        if not self.inextensible:
            return self._select(t, y, where, previous, rigid.ROPE_ELASTIC)
        if self.rope_taut:
            try:
                return self._select(t, y, where, previous, rigid.ROPE_TAUT)
            except _RopeWouldPush:
                self.rope_taut = False
        return self._select(t, y, where, previous, rigid.ROPE_SLACK)

    def select_or_jam(self, t, y, where: str, previous: Phase | None = None):
        """`select` at (t, y); where no configuration is consistent while corners on the ground slide
        (Painlevé), first a tangential impact at (t, y) (`jam`), then `select` again with fallback 2 off.

        **Returns** `(phase, y, loss [J])`: `y` after the jam (or unchanged), its kinetic energy loss."""
        try:
            return self.select(t, y, where, previous), y, 0.0
        except _Jam:
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
                    raise _RopeWouldPush
                return rest_phase

        mats = self.matrices(t, y, rope)
        near_idx = [i for i in range(4) if near[i]]
        combos, hints_list = [], []
        reference = None  # the configuration with every corner on the ground in contact (see `_rank`)
        for r in range(len(near_idx), -1, -1):
            for subset in itertools.combinations(near_idx, r):
                in_contact = np.zeros(4, dtype=bool)
                in_contact[list(subset)] = True
                modes, hints = coulomb_pattern(mats, in_contact, resting, self.mu, self.G, self.g,
                                               debug=self.debug)
                if reference is None:
                    reference = (modes, hints)
                n_stick, n_contact = int(np.sum(modes == STICK)), int(np.sum(modes != FREE))
                if np.all(near) and n_stick >= 2 and n_contact >= 3:
                    continue  # held fixed: the rest configuration, which failed above
                combos.append(modes)
                hints_list.append(hints)
        ref_row = 0 if combos and np.array_equal(combos[0], reference[0]) else len(combos)
        n_max = 16
        contact = np.zeros((n_max, 4), dtype=np.int32)
        hints = np.zeros((n_max, 4, 2))
        contact[:len(combos)] = np.array(combos)
        hints[:len(combos)] = np.array(hints_list)
        if ref_row == len(combos):  # a skipped (rest-like) configuration leaves room for it
            contact[ref_row], hints[ref_row] = reference
        force, acc_c, accel, tension = _eval_candidates(jnp.asarray(t), y, self.sc, self.c, self.settings,
                                                        jnp.asarray(contact), jnp.asarray(hints),
                                                        jnp.asarray(rope, dtype=jnp.int32), self.inextensible)
        force, acc_c, accel, tension = map(_np, (force, acc_c, accel, tension))
        n_ref = force[ref_row, :, 2]

        def check(scale: float):
            """Consistency of every candidate with the tolerances times `scale`: (consistent indices,
            [(combo, reason)] of the others, whether only the rope's S >= 0 failed somewhere, and per
            candidate its largest violation in units of G or g)."""
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
                            bad = (f"{rigid.CORNERS[i]} would not slide along its friction direction "
                                   f"(a_h = {ah}, t = {h})")
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
                    print(f"  [{where} t={t:.9g}] {_fmt(combo)}: {'ok' if ok else reason}; "
                          f"N={np.round(N, 1)} accel={np.round(accel[k], 6)}")
            return consistent, why, rope_rejected, (violation, reasons)

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

        strict, why, rope_rejected, (violation, reasons) = check(1.0)
        consistent = not_again(strict)
        if not consistent and rope_rejected:
            raise _RopeWouldPush  # only the rope's S >= 0 failed: it goes slack
        if not consistent:
            # Fallbacks, in order (each recorded in the phase log; see docs/rigid-model.md, "Resolution"):
            # 1. a degenerate contact (a load, acceleration or slip direction within rounding of its limit):
            #    the consistency tolerances relaxed by `relax`;
            relaxed = not_again(check(self.tol["relax"])[0])
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
                raise _Jam(why)
            else:
                # 3. the least inconsistent configuration, as a short regularised phase (its guards end it).
                k = int(np.argmin(violation))
                consistent = [k]
                self.notes.append(f"regularised: no consistent configuration, least violation "
                                  f"{violation[k]:.2g} ({reasons[k]})")
        if previous is not None and int(previous.rope) != rope:
            previous = eqx.tree_at(lambda p: p.rope, previous, jnp.asarray(rope, dtype=jnp.int32))
        if previous is not None:
            prev_N = _np(_forces(jnp.asarray(t), y, self.sc, self.c, previous, self.settings,
                                 self.inextensible))[:, 2]
        else:
            prev_N = None
        best = self._rank(combos, consistent, force, accel, prev_N, n_ref, near, mats)
        if excluded and self._rank(combos, consistent + excluded, force, accel, prev_N, n_ref, near, mats,
                                   quiet=True) in excluded:
            self.notes.append(f"{_fmt(self.exclude)} not repeated after its guard fired")
        combo = combos[best]
        hint = np.where((combo == SLIDE)[:, None], hints[best], 0.0)
        flat3 = bool(np.all(near)) and int(np.sum(combo != FREE)) == 3
        return rigid.make_phase(combo, rest=False, slip_hint=hint, starting=(combo == SLIDE) & resting,
                                free_on_ground=(combo == FREE) & near & flat3, rope=rope)

    def _rank(self, combos, consistent, force, accel, prev_N, n_ref, near, mats, quiet=False) -> int:
        """The resolution rule among consistent configurations (docs/rigid-model.md, "Resolution"):

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
        keys = {k: (round(jump(k) / tJ), round(released(k) / tJ), -int(np.sum(combos[k] == STICK)),
                    gauss(k)) for k in group}
        group.sort(key=lambda k: keys[k])
        best = group[0]
        tA = self.tol["accel"] * self.g
        a_scale = np.linalg.norm(accel[best]) + tA
        rivals = [k for k in group[1:] if keys[k][0] == keys[best][0]
                  and np.linalg.norm(accel[k] - accel[best]) > 1e-5 * a_scale + 10 * tA]
        if rivals and not quiet:
            k = rivals[0]
            rule = ("stiff-foundation rule" if keys[k][1] != keys[best][1] else
                    "most sticking" if keys[k][2] != keys[best][2] else "least constraint")
            ref = f" (N_ref = {np.round(n_ref, 1).tolist()} N)" if rule.startswith("stiff") else ""
            self.notes.append(f"{rule}: {_fmt(combos[best])} over {_fmt(combos[k])}{ref}")
        return best

    # ---------------------------------------------------------------------------- impacts
    def impact(self, t, y, striking: list[int], taut: bool = False, normal_only: bool = False):
        """Velocity jump at an impact of the `striking` corners; returns (y+, loss [J]). With the taut
        inextensible rope (`taut`) the rope takes an impulse too (it keeps its rate), unless that would
        need a push: then it goes slack in the impact. `normal_only`: no restitution (every involved
        corner ends with zero normal velocity; the tangential impact of `jam`).

        Resolution (docs/rigid-model.md, "Resolution"), each step after the first recorded in `notes`:
        the consistent Coulomb impulse with the most contacts, then the most sticking corners, then the
        largest kinetic energy loss (maximal dissipation) where several remain; if none is consistent
        (a grazing touch, a Painlevé-type impact), the frictionless impulse ("friction dropped"); if that
        too fails, the M-orthogonal projection onto zero normal velocity of the involved corners."""
        corners, cv, ke0 = self.kin(t, y)
        near = corners[:, 2] < self.tol["z"] * self.L
        involved = [i for i in range(4) if near[i] or i in striking]
        normal_target = np.zeros(4)
        for i in striking:
            if cv[i, 2] < -self.tol["bounce"] * self.V and not normal_only:
                normal_target[i] = -self.e * cv[i, 2]
        if taut:
            try:
                y1, _, loss = _rope_jerk(self, t, y, striking, normal_target)
                return y1, loss
            except _RopeWouldPush:
                self.rope_taut = False
        vh = cv[:, :2]
        speed = np.linalg.norm(vh, axis=1)
        slipping = speed >= self.tol["v"] * self.V
        dirs = np.where(slipping[:, None], vh / np.maximum(speed, 1e-300)[:, None], 0.0)
        mask = np.isin(np.arange(4), involved)
        tP = self.tol["force"] * self.G * 1e-3  # impulses [N s]
        tV = self.tol["v"] * self.V

        def solve(sc, mu, combos):
            # Sliding impulses need a direction: the pre-impact slip, else the opposite of the sticking one.
            sticking = _modes([np.where(cb == SLIDE, STICK, cb) for cb in combos])
            _, _, imp0, _ = map(_np, _eval_impulses(y, sc, self.c, jnp.asarray(sticking),
                                                    jnp.asarray(np.zeros((81, 4, 2))),
                                                    jnp.asarray(normal_target), self.settings.rcond))
            sd = _slide_directions(combos, slipping, dirs, imp0) if mu > 0 else np.zeros((81, 4, 2))
            out = map(_np, _eval_impulses(y, sc, self.c, jnp.asarray(_modes(combos)), jnp.asarray(sd),
                                          jnp.asarray(normal_target), self.settings.rcond))
            v1, w1, imp, cv1 = out
            return v1, w1, _consistent_impulses(combos, imp, cv1, sd, mask, mu, tP, tV)

        combos = _impulse_combinations(mask)
        v1, w1, consistent = solve(self.sc, self.mu, combos)
        names = "".join(rigid.CORNERS[i] for i in involved)
        if not consistent:
            # A grazing touch or a Painlevé-type impact: the frictionless impulse (contacts FREE or SLIDE
            # with μ = 0), which a plastic impact always has.
            sc0 = eqx.tree_at(lambda s: s.foundation.friction_coefficient, self.sc,
                              jnp.zeros((), dtype=jnp.float64))
            combos = [cb for cb in combos if not np.any(cb == STICK)]
            v1, w1, consistent = solve(sc0, 0.0, combos)
            if consistent:
                self.notes.append(f"no Coulomb impulse at {names}: friction dropped")
        if not consistent:
            y1, _ = self._project(t, y, np.zeros(4, dtype=bool), mask)
            self.notes.append(f"no impulse at {names}: normal velocities projected out")
            v1, w1 = _np(y1.velocity)[None], _np(y1.angular_velocity)[None]
            consistent = [0]
        best = consistent[0]
        u_best = np.concatenate([v1[best], w1[best]])
        def counts(k):
            return int(np.sum(combos[k] != FREE)), int(np.sum(combos[k] == STICK))

        def differs(k):
            du = np.linalg.norm(np.concatenate([v1[k], w1[k]]) - u_best)
            return du > 1e-6 * (np.linalg.norm(u_best) + tV)

        def after(k):
            return eqx.tree_at(lambda s: (s.velocity, s.angular_velocity), y,
                               (jnp.asarray(v1[k]), jnp.asarray(w1[k])))

        tied = [k for k in consistent[1:] if counts(k) == counts(best) and differs(k)]
        if tied:
            # Newton's law is not unique for simultaneous multi-corner impacts: maximal dissipation.
            ke = {k: self.kin(t, after(k))[2] for k in [best, *tied]}
            new = min(ke, key=ke.get)
            self.notes.append(f"{len(tied) + 1} consistent impulses: maximal dissipation, "
                              f"{_fmt(combos[new])}")
            best = new
        y1 = eqx.tree_at(lambda s: (s.velocity, s.angular_velocity), y,
                         (jnp.asarray(v1[best]), jnp.asarray(w1[best])))
        _, _, ke1 = self.kin(t, y1)
        loss = ke0 - ke1
        if loss < -1e-9 * max(ke0, 1.0):
            raise RigidContactError(
                f"t = {t:.9g} s: the impact of corner(s) {[rigid.CORNERS[i] for i in striking]} would gain "
                f"kinetic energy ({-loss:.4g} J) with restitution {self.e} and friction μ = {self.mu}: "
                "Newton's restitution law is not energy-consistent here; lower the restitution")
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
            if (cb[i] != FREE and Pz < -tP) or (cb[i] == STICK and Ph > mu * Pz + tP) or (
                    cb[i] == SLIDE and float(cv1[k, i, :2] @ sd[k, i]) < -tV) or (
                    cb[i] == FREE and involved[i] and cv1[k, i, 2] < -tV):
                ok = False
                break
        if ok:
            consistent.append(k)
    consistent.sort(key=lambda k: (-int(np.sum(combos[k] != FREE)), -int(np.sum(combos[k] == STICK))))
    return consistent


def _rope_jerk(drv: _Driver, t: float, y: State, striking=(), normal_target=None, t_rate=None,
               fallback: bool = False):
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
    out0 = map(_np, _eval_rope_impulses(tj, y, drv.sc, drv.c, jnp.asarray(sticking),
                                        jnp.asarray(np.zeros((81, 4, 2))),
                                        jnp.asarray(normal_target), drv.settings.rcond))
    imp0 = list(out0)[3]
    sd = _slide_directions(combos, slipping, dirs, imp0)
    modes = _modes(combos)
    v1, w1, tip1, imp, P, cv1 = map(_np, _eval_rope_impulses(tj, y, drv.sc, drv.c, jnp.asarray(modes),
                                                              jnp.asarray(sd), jnp.asarray(normal_target),
                                                              drv.settings.rcond))
    tP = drv.tol["force"] * drv.G * 1e-3  # impulses [N s]
    tV = drv.tol["v"] * drv.V
    consistent = [k for k in _consistent_impulses(combos, imp, cv1, sd, near, drv.mu, tP, tV) if P[k] >= -tP]
    tip_alone = False
    if not consistent and fallback:
        # As for corner impacts: the frictionless jerk (contacts FREE or SLIDE with μ = 0); if even that has
        # none, the jerk on the boom tip alone (below).
        sc0 = eqx.tree_at(lambda s: s.foundation.friction_coefficient, drv.sc,
                          jnp.zeros((), dtype=jnp.float64))
        combos = [cb for cb in combos if not np.any(cb == STICK)]
        sd = np.zeros((81, 4, 2))
        out = _eval_rope_impulses(tj, y, sc0, drv.c, jnp.asarray(_modes(combos)), jnp.asarray(sd),
                                  jnp.asarray(normal_target), drv.settings.rcond)
        v1, w1, tip1, imp, P, cv1 = map(_np, out)
        consistent = [k for k in _consistent_impulses(combos, imp, cv1, sd, near, 0.0, tP, tV) if P[k] >= -tP]
        if consistent:
            drv.notes.append("no Coulomb jerk: friction dropped")
        else:
            consistent, tip_alone = [0], True
            drv.notes.append("no consistent jerk: on the tip alone")
    if not consistent:
        raise _RopeWouldPush(f"t = {t:.9g} s: the jerk of the inextensible rope has no consistent impulse "
                             "(Painlevé-type impact inconsistency)")
    best = consistent[0]
    _, _, s_dot = map(float, _rope_state(tj, y, drv.sc, drv.c))
    m0 = float(drv.sc.boom.tip_mass)

    def ke(yy):
        return drv.kin(t, yy)[2] + 0.5 * m0 * float(np.sum(_np(yy.tip_velocity) ** 2))

    work = float(P[best]) * s_dot
    y1 = eqx.tree_at(lambda s: (s.velocity, s.angular_velocity, s.tip_velocity, s.hoist_work), y,
                     (jnp.asarray(v1[best]), jnp.asarray(w1[best]), jnp.asarray(tip1[best]),
                      y.hoist_work + work))
    # Settling, as after corner impacts: a load flat on the ground that the jerk would move slower than
    # Settings.rest_velocity stays at rest (the ground takes its share of the impulse) and the jerk acts on
    # the boom tip alone. Without it, a resting load under a rope whose tip lags the hoist chatters: each
    # small jerk lifts it, it falls back and the rope slackens, and the tip springs back into the next jerk.
    if not striking and np.all(near) and float(np.max(np.linalg.norm(cv1[best], axis=1))) < float(
            drv.settings.rest_velocity):
        e = _np(_rope_direction(tj, y, drv.sc, drv.c))
        v_A = _np(y.tip_velocity)
        P_tip = m0 * (float(e @ v_A) + s_dot)  # tip alone: e·v_A+ = dl/dt = -ds/dt, load at rest
        work = P_tip * s_dot
        y1 = eqx.tree_at(lambda s: (s.velocity, s.angular_velocity, s.tip_velocity, s.hoist_work), y,
                         (jnp.zeros(3), jnp.zeros(3), jnp.asarray(v_A - (P_tip / m0) * e),
                          y.hoist_work + work))
    elif tip_alone or (not striking and np.all(near) and float(np.max(np.linalg.norm(cv1[best] - cv, axis=1)))
                       < float(drv.settings.rest_velocity)):
        # The same for a load sliding flat on the ground: a jerk that would change its corner velocities by
        # less than rest_velocity leaves them unchanged (the ground takes the load's share) and jerks the
        # tip alone, to d|AB|/dt = dl/dt (an inextensible rope over a sliding load chattered at ~3 kHz:
        # jerk, the load tips onto one corner for 30 µs, falls back, the rope slackens; paper-2.3, μ = 0.1).
        e = _np(_rope_direction(tj, y, drv.sc, drv.c))
        _, rate_error, _ = map(float, _rope_state(tj, y, drv.sc, drv.c))
        P_tip = m0 * rate_error  # e·(v_A+ - v_B) = -ds/dt
        work = P_tip * s_dot
        y1 = eqx.tree_at(lambda s: (s.tip_velocity, s.hoist_work), y,
                         (jnp.asarray(_np(y.tip_velocity) - (P_tip / m0) * e), y.hoist_work + work))
        if not tip_alone:
            drv.notes.append("jerk on the tip alone")
    loss = work - (ke(y1) - ke(y))
    if loss < -1e-9 * max(abs(work), 1.0):
        raise RigidContactError(f"t = {t:.9g} s: the rope jerk would gain energy ({-loss:.4g} J)")
    return y1, work, loss


def coulomb_pattern(mats, in_contact, resting, mu: float, G: float, g: float, n_outer: int = 12,
                    debug: bool = False):
    """Which resting contacts stick and in which direction the others start to slide, for the contact set
    `in_contact`, from Coulomb's law in its maximum-dissipation form.

    For given normal forces Ñ the accelerations u̇ = (dv_C/dt, dω/dt) minimise the convex function

        ½ u̇ᵀ M u̇ - f̃·u̇ + Σ_{resting contacts i} μ Ñ_i |a_i,h(u̇)|   subject to a_i,z(u̇) = target_i (contacts),

    (f̃: applied forces plus the known friction -μÑ_i t̂_i of contacts that already slide), whose optimality
    conditions are exactly: a resting corner with a_i,h = 0 sticks with |T_i| <= μÑ_i, one with a_i,h != 0
    slides with T_i = -μÑ_i a_i,h / |a_i,h|. The norm is smoothed, sqrt(|a|² + ε²), and ε decreased from
    1e-2 g to 1e-13 g with Newton's method in the null space of the contact constraints; the normal forces
    are the (minimum-norm) multipliers and are iterated to a fixed point (`n_outer` times). Host-side numpy.
    With the taut inextensible rope (`mats.rope_row`), u̇ includes the boom tip's acceleration and the
    rope's d²|AB|/dt² is one more equality constraint (its multiplier is the tension).

    **Returns** `(modes, hints)`: per corner FREE / SLIDE / STICK and the sliding directions (4, 2).
    """
    M, f, jac, bias = mats.mass, mats.force, mats.jacobians, mats.bias
    cv, target = mats.corner_velocity, mats.target
    idx = np.nonzero(in_contact)[0]
    modes = np.full(4, FREE, dtype=np.int32)
    hints = np.zeros((4, 2))
    if idx.size == 0:
        return modes, hints
    speed = np.linalg.norm(cv[:, :2], axis=1)
    res = in_contact & resting
    mov = in_contact & ~resting
    tdir = np.zeros((4, 2))
    tdir[mov] = cv[mov, :2] / speed[mov, None]
    Gz = jac[idx, 2, :]                       # (n_c, 6)
    rz = target[idx, 2] - bias[idx, 2]
    if mats.rope_row is not None:  # the taut inextensible rope: one more equality (coordinates incl. tip)
        Gz = np.concatenate([Gz, mats.rope_row[None, :]], axis=0)
        rz = np.append(rz, mats.rope_rhs)
    u0 = np.linalg.lstsq(Gz, rz, rcond=None)[0]
    _, sv, Vt = np.linalg.svd(Gz)
    rank = int(np.sum(sv > 1e-10 * sv.max()))
    Z = Vt[rank:].T                           # null space of the contact rows (6, 6 - rank)
    A = jac[:, :2, :]                         # horizontal rows (4, 2, 6)
    b = bias[:, :2]

    def multipliers(u, Nt, eps):
        r = M @ u - f
        for i in np.nonzero(mov)[0]:
            r = r - A[i].T @ (-mu * Nt[i] * tdir[i])
        for i in np.nonzero(res)[0]:
            s = A[i] @ u + b[i]
            r = r - A[i].T @ (-mu * Nt[i] * s / np.sqrt(s @ s + eps**2))
        lam = np.linalg.lstsq(Gz.T, r, rcond=None)[0]
        N = np.zeros(4)
        N[idx] = lam[:idx.size]
        return N

    def minimise(Nt, q, eps_list):
        w = mu * np.maximum(Nt, 0.0)
        ft = f.copy()
        for i in np.nonzero(mov)[0]:
            ft = ft + A[i].T @ (-w[i] * tdir[i])
        ri = np.nonzero(res)[0]

        def phi(q, eps):
            u = u0 + Z @ q
            val = 0.5 * u @ M @ u - ft @ u
            for i in ri:
                s = A[i] @ u + b[i]
                val += w[i] * np.sqrt(s @ s + eps**2)
            return val

        for eps in eps_list:
            for _ in range(30):
                u = u0 + Z @ q
                grad = M @ u - ft
                H = M.copy()
                for i in ri:
                    s = A[i] @ u + b[i]
                    r = np.sqrt(s @ s + eps**2)
                    grad = grad + w[i] * A[i].T @ (s / r)
                    H = H + w[i] * A[i].T @ (np.eye(2) / r - np.outer(s, s) / r**3) @ A[i]
                gq, Hq = Z.T @ grad, Z.T @ H @ Z
                if gq.size == 0:
                    break
                d = -np.linalg.solve(Hq, gq)
                f0, step = phi(q, eps), 1.0
                while phi(q + step * d, eps) > f0 + 1e-4 * step * (gq @ d) and step > 1e-12:
                    step *= 0.5
                q = q + step * d
                if np.linalg.norm(step * d) <= 1e-15 * (1.0 + np.linalg.norm(q)):
                    break
        return q

    eps_final = 1e-13 * g
    eps_all = list(g * 10.0 ** -np.arange(2.0, 13.5, 1.0))
    q = np.zeros(Z.shape[1])
    # Frictionless normal forces to start the fixed point.
    Nt = multipliers(u0 + Z @ minimise(np.zeros(4), q, [eps_final]), np.zeros(4), eps_final)
    for it in range(n_outer):
        q = minimise(Nt, q, eps_all if it == 0 else [eps_final])
        u = u0 + Z @ q
        N_new = multipliers(u, Nt, eps_final)
        if np.max(np.abs(N_new - Nt)) <= 1e-10 * G:
            Nt = N_new
            break
        Nt = N_new
    u = u0 + Z @ q
    if debug:
        ah = np.einsum("kij,j->ki", A, u) + b
        print(f"    coulomb_pattern {in_contact.astype(int)}: outer it {it}, N = {np.round(Nt, 3)}, "
              f"|a_h| = {np.linalg.norm(ah, axis=1)}, u = {u}")
    for i in idx:
        if mov[i]:
            modes[i], hints[i] = SLIDE, tdir[i]
        else:
            ah = A[i] @ u + b[i]
            na = np.linalg.norm(ah)
            if na > 1e3 * eps_final:
                modes[i], hints[i] = SLIDE, ah / na
            else:
                modes[i] = STICK
    return modes, hints


def _fmt(combo) -> str:
    return " ".join(f"{c}:{rigid.MODE_NAMES[int(m)]}" for c, m in zip(rigid.CORNERS, combo, strict=True))


#: The persistent-contact rule after impacts (docs/rigid-model.md); False only to compare without it.
PERSISTENT_CONTACT = True

#: The rope models of `simulate_rigid(..., rope=...)`.
ROPE_MODELS = ("elastic", "inextensible")

_DEFAULT_TOL = dict(
    z=1e-7,            # a corner is on the ground if Z < z L
    v=1e-6,            # ... and |v_z| < v V; it rests if also |v_h| < v V
    force=1e-7,        # consistency tolerance on forces [G]
    accel=1e-7,        # consistency tolerance on accelerations [g]
    rest=1e-9,         # tolerance of the rest conditions (dimensionless guards)
    guard_start=1e-9,  # every guard starts at least this positive (offsets)
    min_phase=1e-6,    # [s] a phase shorter than this is merged into the previous record (`_merge`)
    trigger=1e-6,      # guards within this of zero at an event count as fired
    lookahead=1e-5,    # the look-ahead runs until the fired guards are below -lookahead
    align=1e-2,        # a corner sliding from rest must accelerate along its sliding direction (relative)
    jump=1e-3,         # normal-force jumps closer than this [G] count as equally continuous
    bounce=1e-4,       # impacts slower than bounce V are plastic (no restitution): avoids Zeno bouncing
    relax=1e3,         # fallback 1 of the configuration choice: tolerances times this (degenerate contacts)
)


def simulate_rigid(scenario: Scenario, t1: float | None = None, *, ts=None, n_save: int = 501,
                   restitution: float = 0.0, rtol: float = 1e-8, atol: float = 1e-9, max_steps: int = 200_000,
                   max_phases: int = 2000, settings: rigid.Settings | None = None,
                   verbose: bool = False, rope: str = "elastic",
                   chatter: ChatterRule | None = ChatterRule()) -> RigidTrajectory:
    """Simulate a lift with the rigid-body-on-rigid-ground model (paper §2) from rest at t = 0 to `t1`.

    Not differentiable and not vmappable (the phase sequence is decided on the host).

    **Arguments**
    - `scenario`: a `Scenario`; the foundation's stiffness, damping and friction law are not used (the
      ground is rigid, friction is exact Coulomb with μ = `foundation.friction_coefficient`).
    - `t1`: end time [s] (default `scenario.t1`); `ts` saved times (start 0, end t1), default `n_save` even.
    - `restitution`: Newton's coefficient e [-] of corner impacts (0: plastic).
    - `rtol`, `atol`, `max_steps`: Tsit5 settings of each phase; `max_phases`: guard against Zeno
      sequences (counts phase solves, merged sub-microsecond ones included).
    - `settings`: `physics.rigid.Settings` (Baumgarte β, slip blend velocity, pseudo-inverse cut-off).
    - `verbose`: print each phase as it ends.
    - `rope`: "elastic" (the rope law (2.14), default) or "inextensible" (the constraint (2.15) with the
      boom-tip motion (2.13): |AB| = l(t) while taut, tension S >= 0 solved with the contact forces; the
      rope goes slack when S reaches 0 and snaps taut again with a plastic jerk when |AB| reaches l(t);
      `rope.stiffness`, `rope.damping` and `rope.damping_onset` are not used). A hoist whose speed jumps
      at t = 0 (`ConstantSpeedHoist`, `RampedHoist` with ramp_time 0) jerks the taut rope at the start:
      the jerk's loss is booked in `impact_loss` (see docs/rigid-model.md, "Inextensible rope (2.15)");
      `RampedHoist(v, ramp_time > 0)` starts without one.
    - `chatter`: a `ChatterRule`: when a sustained cycle of impacts (or a phase that stalls twice) is passed
      by a compliant phase (`numerics.rigid_compliant`; recorded in the phase log); None: never (such a
      run ends at `max_phases`, or raises at the second stall).

    **Returns** a `RigidTrajectory` (with the phase log in `.phases`).

    **Raises** `ScenarioError` for invalid input, `RigidContactError` for inconsistent or ambiguous
    contact situations and solver failures.
    """
    require_x64()
    if rope not in ROPE_MODELS:
        raise ScenarioError(f"rope must be one of {', '.join(map(repr, ROPE_MODELS))}, got {rope!r}")
    if not isinstance(scenario, Scenario):
        raise TypeError(f"scenario must be a jaxhoist.Scenario, got {type(scenario).__name__}")
    scenario.check()
    if not (0.0 <= restitution <= 1.0):
        raise ScenarioError(f"restitution (e) must be in [0, 1], got {restitution}")
    if t1 is None:
        t1 = scenario.t1 if ts is None else float(np.asarray(ts)[-1])
    t1 = float(t1)
    if not (np.isfinite(t1) and t1 > 0):
        raise ScenarioError(f"t1 must be a positive finite time [s], got {t1}")
    if ts is None:
        ts = np.linspace(0.0, t1, int(n_save))
    ts = np.asarray(ts, dtype=np.float64)
    if ts.ndim != 1 or ts.size < 2 or ts[0] != 0.0 or np.any(np.diff(ts) <= 0) or abs(ts[-1] - t1) > 1e-12:
        raise ScenarioError("ts must be a 1-D, strictly increasing array from 0 to t1 [s]")
    settings = rigid.Settings() if settings is None else settings
    options = _Options(rtol=float(rtol), atol=float(atol), max_steps=int(max_steps), event_atol=1e-10)
    y0, c = rigid.initial_state(scenario)
    drv = _Driver(scenario, c, settings, options, restitution, dict(_DEFAULT_TOL))
    drv.debug = verbose == "debug"
    drv.inextensible = rope == "inextensible"

    n_t = ts.size
    filled = np.zeros(n_t, dtype=bool)
    saved_states = None  # per leaf an (n_t, ...) host array, allocated at the first phase
    saved_phase = np.zeros(n_t, dtype=np.int64)
    saved_impact = np.zeros(n_t)
    records: list[PhaseRecord] = []
    phases: list[Phase] = []   # one per phase solve (the outputs are evaluated with these)
    record_of: list[int] = []  # per phase solve, its record in `records` (several when merged)

    def log(rec: PhaseRecord):
        """Append the record of the phase just solved, or merge it into the previous record when it lasted
        less than `min_phase` (see `_merge`)."""
        if records and rec.t_end - rec.t_start < drv.tol["min_phase"]:
            records[-1] = _merge(records[-1], rec)
        else:
            records.append(rec)
        record_of.append(len(records) - 1)

    impact_total = 0.0
    impact_events: list[tuple[float, float]] = []  # (time [s], loss [J]) of impacts and jerks (`chatter`)
    compliant_mask = np.zeros(n_t, dtype=bool)  # saved samples inside compliant phases

    def compliant(t0: float, y0: State, phase0: Phase, why: str):
        """A compliant phase from (t0, y0) (`numerics.rigid_compliant`): fill its saved samples, log it,
        book its hand-back loss. Returns the state handed back and its time."""
        nonlocal impact_total
        ep = run_episode(drv, t0, y0, t1, ts, filled, chatter)
        drv.accepted += ep.accepted
        drv.rejected += ep.rejected
        idx = len(phases)
        phases.append(phase0)  # a placeholder: these samples' outputs are the compliant model's
        ks = ep.user_index
        if ks.size:
            jax.tree_util.tree_map(lambda dst, src: dst.__setitem__(ks, src), saved_states, ep.user_states)
            saved_phase[ks] = idx
            saved_impact[ks] = impact_total
            filled[ks] = True
            compliant_mask[ks] = True
        impact_total += ep.handback_loss
        loaded = "".join(c for c, on in zip(rigid.CORNERS, ep.loaded, strict=True) if on) or "none"
        end = "t1" if ep.t_end >= t1 else (f"compliant phase ended: loaded {loaded} steady for "
                                            f"{ep.steady * 1e3:.3g} ms; hand-back {ep.handback_loss:.4g} J")
        how = (f"compliant phase: {why}; foundation k = {chatter.stiffness:g} N/m, critically damped, "
               f"ε = {chatter.regularisation_velocity:g} m/s"
               + (f", rope {chatter.rope_stiffness:g} N/m" if drv.inextensible else ""))
        modes = tuple("spring" if on else "free" for on in ep.loaded)
        log(PhaseRecord(t0, ep.t_end, modes, False, end, ep.y_before_handback,
                        "compliant" if drv.inextensible else "elastic", how))
        impact_events.clear()
        return ep.t_end, ep.y_end

    t, y = 0.0, y0
    if drv.inextensible:
        # A taut inextensible rope and a hoist already running at t = 0+: the start is a rope jerk.
        # The hoist speed just after the start (a jump at t = 0 may leave ds/dt(0) = 0 exactly).
        t_plus = 1e-9
        stretch, rate_error, _ = map(float, _rope_state(jnp.asarray(t_plus), y, scenario, c))
        drv.rope_taut = stretch >= -drv.tol["z"] * drv.L  # rope.slack = 0: just taut
        if drv.rope_taut and rate_error > drv.tol["v"] * drv.V:
            try:
                y, _, loss = _rope_jerk(drv, 0.0, y, t_rate=t_plus)
            except _RopeWouldPush as err:
                raise RigidContactError(str(err)) from None
            impact_total += loss
    phase, y, loss = drv.select_or_jam(t, y, "start")
    impact_total += loss
    choice = drv.take_notes()
    retried_at = None  # start time of a stalled phase chosen again (once)
    while True:
        if len(phases) >= max_phases:
            raise RigidContactError(
                f"more than max_phases = {max_phases} phases before t = {t:.9g} s (a Zeno sequence of "
                f"events? raise max_phases, or Settings.rest_velocity to let rocking settle). "
                f"Last phases:\n" + "\n".join(str(r) for r in records[-8:]))
        y, loss = drv.project(t, y, phase)
        impact_total += loss
        phase = drv.with_offsets(t, y, phase)
        g_start = drv.guards(t, y, phase) + _np(phase.guard_offset)
        sts, sys_, result = drv.solve(y, phase, t, t1, ts)
        last = int(np.nonzero(np.isfinite(sts))[0][-1])  # the final state is saved after the last ts kept
        t_end = float(sts[last])
        y_end = _tree_index(sys_, last)
        ok = result == diffrax.RESULTS.successful
        event = result == diffrax.RESULTS.event_occurred
        if not (bool(ok) or bool(event)):
            if retried_at != t and not bool(phase.rest):
                # A stalled phase (typically a corner sliding with a slip speed near zero, where the slip
                # direction turns quickly): choose again at its start without that configuration.
                retried_at = t
                stalled = _fmt(_np(phase.contact))
                drv.exclude = _np(phase.contact).copy()
                try:
                    phase, y, loss = drv.select_or_jam(t, y, "after a stalled phase")
                finally:
                    drv.exclude = None
                impact_total += loss
                how = drv.take_notes()
                choice = f"{stalled} stalled at max_steps, chosen again without it"
                choice += f"; {how}" if how else ""
                continue
            if chatter is None or bool(phase.rest):
                raise RigidContactError(f"the phase starting at t = {t:.9g} s failed: {result} "
                                        f"(raise max_steps = {max_steps} or loosen rtol/atol)")
            # Stalled again: pass the episode with a compliant phase.
            if saved_states is None:
                saved_states = jax.tree_util.tree_map(lambda x: np.zeros((n_t,) + np.shape(x), np.asarray(x).dtype),
                                                      y)
            t, y = compliant(t, y, phase, f"{_fmt(_np(phase.contact))} stalled at max_steps twice")
            if t >= t1:
                break
            phase, y, loss = drv.select_or_jam(t, y, "after a compliant phase")
            impact_total += loss
            choice = drv.take_notes()
            continue
        idx = len(phases)
        phases.append(phase)
        # Saved times of this phase: t <= ts <= t_end not yet filled.
        sys_np = jax.tree_util.tree_map(np.asarray, sys_)  # index on the host, not one dispatch per sample
        if saved_states is None:
            saved_states = jax.tree_util.tree_map(lambda x: np.zeros((n_t,) + x.shape[1:], x.dtype), sys_np)
        ks = np.nonzero((ts >= t) & (ts <= t_end) & ~filled)[0]
        if ks.size:
            jax.tree_util.tree_map(lambda dst, src: dst.__setitem__(ks, src[ks]), saved_states, sys_np)
            saved_phase[ks] = idx
            saved_impact[ks] = impact_total
            filled[ks] = True
        modes = tuple(rigid.MODE_NAMES[int(m)] for m in _np(phase.contact))
        rope_name = rigid.ROPE_NAMES[int(phase.rope)]
        if not bool(event) or t_end >= t1:
            log(PhaseRecord(t, t_end, modes, bool(phase.rest), "t1", y_end, rope_name, choice))
            break
        g = drv.guards(t_end, y_end, phase) + _np(phase.guard_offset)
        # Fired: near zero now, and well below where the guard started (a guard that started at its small
        # offset and stayed there has not fired).
        fired = [k for k in range(rigid.N_GUARDS) if g[k] <= drv.tol["trigger"] and g[k] <= 0.5 * g_start[k]]
        if not fired:
            fired = [int(np.argmin(g))]
        if drv.debug:
            print(f"  guards at start {g_start}\n  guards at end   {g}")
        end = ",".join(rigid.GUARD_NAMES[k] for k in fired)
        contact = _np(phase.contact)
        corners, cv, _ = drv.kin(t_end, y_end)
        striking = [k for k in fired if k < 4 and contact[k] == FREE and not bool(phase.rest)]
        hard = [i for i in striking if cv[i, 2] < -drv.tol["v"] * drv.V]
        if 11 in fired:
            # The slack inextensible rope reaches its length: a jerk if it would stretch, then a new phase.
            _, rate_error, _ = map(float, _rope_state(jnp.asarray(t_end), y_end, scenario, c))
            y_before = y_end
            drv.rope_taut = True
            if rate_error > drv.tol["v"] * drv.V:
                try:
                    y_end, _, loss = _rope_jerk(drv, t_end, y_end, fallback=True)
                except _RopeWouldPush as err:
                    raise RigidContactError(str(err)) from None
                impact_total += loss
                impact_events.append((t_end, loss))
                how = drv.take_notes()
                end += f" rope-jerk ({loss:.4g} J{', ' + how if how else ''})"
            log(PhaseRecord(t, t_end, modes, bool(phase.rest), end, y_before, rope_name, choice))
            new, y_end, loss = drv.select_or_jam(t_end, y_end, "after the rope became taut", phase)
            impact_total += loss
        elif hard:
            y_before = y_end
            y_end, loss = drv.impact(t_end, y_end, hard, taut=int(phase.rope) == rigid.ROPE_TAUT)
            impact_total += loss
            impact_events.append((t_end, loss))
            how = drv.take_notes()
            how = f", {how}" if how else ""
            end += f" impact:{''.join(rigid.CORNERS[i] for i in hard)} ({loss:.4g} J{how})"
            # Settling: if every corner on the ground leaves the impact slower than rest_velocity, the
            # impact is plastic for all of them (their normal velocities are removed; flat on the ground,
            # the load stops). This ends the otherwise endless sequence of ever smaller rocking impacts.
            corners1, cv1, ke1 = drv.kin(t_end, y_end)
            near = corners1[:, 2] < drv.tol["z"] * drv.L
            if np.max(np.linalg.norm(cv1[near], axis=1)) < float(settings.rest_velocity):
                if np.all(near):
                    y_end = eqx.tree_at(lambda s: (s.velocity, s.angular_velocity), y_end,
                                        (jnp.zeros(3), jnp.zeros(3)))
                    impact_total += ke1
                else:
                    y_end, loss = drv._project(t_end, y_end, np.zeros(4, dtype=bool), near)
                    impact_total += loss
                end += " settled"
            elif PERSISTENT_CONTACT and np.max(np.abs(cv1[near, 2])) < float(settings.rest_velocity):
                # Persistent contact: every corner on the ground leaves the impact with a normal velocity
                # below rest_velocity (a corner the impulse lifts, or one still approaching): their normal
                # velocities are removed (plastic for all of them) and the next configuration is chosen
                # with all of them on the ground (docs/rigid-model.md, "Persistent contact").
                lifted = [rigid.CORNERS[i] for i in range(4) if near[i] and cv1[i, 2] > drv.tol["v"] * drv.V]
                if lifted:
                    taut_now = drv.inextensible and drv.rope_taut
                    project = drv._project_taut if taut_now else drv._project
                    y_end, loss = project(t_end, y_end, np.zeros(4, dtype=bool), near)
                    impact_total += loss
                    end += (f" persistent contact ({','.join(lifted)} held, "
                            f"|v_n| <= {np.max(np.abs(cv1[near, 2])):.2g} m/s)")
            log(PhaseRecord(t, t_end, modes, bool(phase.rest), end, y_before, rope_name, choice))
            new, y_end, loss = drv.select_or_jam(t_end, y_end, "after impact")
            impact_total += loss
        else:
            log(PhaseRecord(t, t_end, modes, bool(phase.rest), end, y_end, rope_name, choice))
            new, y_end, loss = _transition(drv, t_end, y_end, phase, fired, ts)
            impact_total += loss
        if verbose:
            print(records[-1], f"[{drv.accepted} steps so far]", flush=True)
        t, y, phase, choice = t_end, y_end, new, drv.take_notes()
        why = chatter.detect(impact_events, t) if chatter is not None else ""
        if why:
            # A sustained cycle of impacts: pass it with a compliant phase, then choose again.
            t, y = compliant(t, y, phase, why)
            if verbose:
                print(records[-1], f"[{drv.accepted} steps so far]", flush=True)
            if t >= t1:
                break
            phase, y, loss = drv.select_or_jam(t, y, "after a compliant phase")
            impact_total += loss
            choice = drv.take_notes()

    for k in np.nonzero(~filled)[0]:  # cannot happen unless ts extends past the last phase
        raise RigidContactError(f"saved time {ts[k]} s was not reached")
    states = jax.tree_util.tree_map(jnp.asarray, saved_states)
    out = _chunked_outputs(ts, saved_states, saved_phase, phases, scenario, c, settings, drv.inextensible)
    if np.any(compliant_mask):
        out = _with_compliant_outputs(out, ts, saved_states, compliant_mask, drv, chatter)
    euler = out.euler.at[:, :2].set(jnp.unwrap(out.euler[:, :2], axis=0))
    return RigidTrajectory(
        ts=jnp.asarray(ts), position=states.position, velocity=states.velocity, euler=euler,
        angular_velocity=states.angular_velocity, corners=out.corners, normal_forces=out.normal,
        friction_forces=out.friction, ground_reaction=jnp.sum(out.normal, axis=-1),
        rope_tension=out.rope_tension, tip_position=states.tip_position, energy=out.energy,
        hoist_work=states.hoist_work, damping_loss=states.damping_loss, friction_work=states.friction_work,
        impact_loss=jnp.asarray(saved_impact), states=states, status=jnp.asarray(SolveStatus.OK, jnp.int32),
        num_accepted_steps=jnp.asarray(drv.accepted), num_rejected_steps=jnp.asarray(drv.rejected),
        phase_index=jnp.asarray(np.asarray(record_of, dtype=np.int64)[saved_phase]), phases=tuple(records))


def _with_compliant_outputs(out, ts, states, mask, drv, rule):
    """`out` (a `rigid.Output` with a leading n_t axis) with the samples `mask` replaced by the outputs of
    the compliant model (`numerics.rigid_compliant`): its corner spring forces, friction, rope and energies
    (ground spring and stiff rope included)."""
    k = np.nonzero(mask)[0]
    sel = jax.tree_util.tree_map(lambda x: jnp.asarray(np.asarray(x)[k]), states)
    el = elastic_outputs(jnp.asarray(ts[k]), sel, compliant_scenario(drv.sc, rule, drv.inextensible), drv.c)

    def put(a, b):
        a = np.array(a)
        a[k] = np.asarray(b)
        return jnp.asarray(a)

    return eqx.tree_at(lambda o: (o.corners, o.normal, o.friction, o.rope_tension, o.energy, o.euler), out,
                       (put(out.corners, el["corners"]), put(out.normal, el["normal"]),
                        put(out.friction, el["friction"]), put(out.rope_tension, el["rope_tension"]),
                        jax.tree_util.tree_map(put, out.energy, el["energy"]), put(out.euler, el["euler"])))


def _merge(previous: PhaseRecord, short: PhaseRecord) -> PhaseRecord:
    """One record for `previous` followed by a phase `short` that lasted less than `min_phase` (1 µs): two
    events closer than the phase solves resolve time (their event root finder works to 1e-10 s, the
    solution to rtol 1e-8) are one event of the log. The merged record keeps the previous phase's contact
    modes and start, ends where `short` ended (its state and reason), and its `end` names both events and
    the short configuration in between: "rest:tip => D:stick E:free F:stick H:free (4.1e-09 s) ->
    normal:D,normal:F". The short phase is still solved and its impacts and losses are booked as usual;
    only the log (and `RigidTrajectory.phase_index`) merge it."""
    between = "rest" if short.rest else " ".join(f"{c}:{m}" for c, m in zip(rigid.CORNERS, short.contact,
                                                                            strict=True))
    n = previous.merged + 1
    first = previous.end if n == 1 else previous.end.split(" => ")[0]
    dt = short.t_end - short.t_start
    what = f"{between} ({dt:.2g} s)" if n == 1 else f"{n} phases < 1 µs, last {between}"
    end = f"{first} => {what} -> {short.end}"
    return dataclasses.replace(previous, t_end=short.t_end, end=end, state_end=short.state_end, merged=n)


def _transition(drv: _Driver, t_e: float, y_e: State, phase: Phase, fired: list[int], ts):
    """The next phase after the guards `fired` of `phase` reached zero at (t_e, y_e) (no impact).

    **Returns** `(phase, y, loss [J])`: `y` is `y_e`, or `y_e` after a tangential impact (`_Driver.jam`)
    where no configuration was consistent."""
    contact, starting = _np(phase.contact), _np(phase.starting)
    _, cv, _ = drv.kin(t_e, y_e)
    speed = np.linalg.norm(cv[:, :2], axis=1)
    tangential = [k - 4 for k in fired if 4 <= k < 8 and contact[k - 4] == SLIDE and not phase.rest]
    # Bookkeeping events of slips that started from rest: the speed has reached 2 v_stop (now an ordinary
    # slide), or the slip has turned by 90° while still moving (new reference direction; the friction
    # already follows the velocity). Nothing changes physically: same configuration.
    grown = [i for i in tangential if starting[i] and speed[i] >= 1.5 * drv.v_stop]
    turned = [i for i in tangential if starting[i] and 0.05 * drv.v_stop <= speed[i] < 1.5 * drv.v_stop]
    if (grown or turned) and len(grown) + len(turned) == len(fired):
        hint, start = _np(phase.slip_hint).copy(), starting.copy()
        for i in grown + turned:
            hint[i] = cv[i, :2] / speed[i]
        for i in grown:
            start[i] = False
        return rigid.make_phase(contact, rest=False, slip_hint=hint, starting=start,
                                free_on_ground=_np(phase.free_on_ground), rope=int(phase.rope)), y_e, 0.0
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
        y_la = _tree_index(sys_, int(np.nonzero(np.isfinite(sts))[0][-1]))
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
    except _Jam:
        # The tangential impact where the event happened, then choose there.
        return drv.select_or_jam(t_e, y_e, where, phase)
    finally:
        drv.exclude = None
