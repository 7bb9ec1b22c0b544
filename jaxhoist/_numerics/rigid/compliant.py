"""The compliant phase of the rigid model: a regularised step for sustained contact cycles.

Some lifts drive the rigid model into a limit cycle of impacts that does not decay: the load pivoting on
one corner while a second one strikes and lifts the first again (0.1-0.2 J per impact every ~2 ms), or,
with the inextensible rope, an impact that slackens the rope and a jerk microseconds later, at kHz rates.
The stiff elastic foundation does not chatter there: its corners share the load softly. Such an episode is
passed with a *compliant phase*: the elastic-foundation model (`physics.elastic.vector_field`: corner
spring-dampers, critically damped, with regularised Coulomb friction; the inextensible rope replaced by a
stiff, critically damped elastic rope) is integrated from the rigid state until the set of loaded corners
has been steady for `ChatterRule.steady` seconds, and the state is handed back to the rigid model: the
body moved (the smallest displacement in the kinetic metric) so that its loaded corners lie on the ground,
the inextensible rope brought back to its length by moving the boom tip along it, the velocities
projected onto the contact constraints (and the taut rope's rate onto dl/dt). The energy
that this hand-back removes (the springs' energy, the lift, the projection) is booked with the impact
losses, so the energy balance stays closed; the phase log records the episode.

Detection (`ChatterRule.detect`): at least `min_impacts` impacts (corner impacts and rope jerks) within
the last `window` seconds, whose losses do not decay (the mean of the later half at least `decay` times
the mean of the earlier half). A decaying train (a rocking load settling) is left to the rigid model,
whose settling rule (`Settings.rest_velocity`) ends it. A phase that stalls twice (its mean step below
`StallRule.min_step`, or `max_steps` reached) is passed the same way, and so is a state where no contact
configuration is consistent `ChatterRule.max_regularised` times in a row (the least-violating one chosen as
a regularised phase again and again: two sticking corners on an edge whose minimum-norm friction split
breaks one cone, a Painlevé-type situation with no rigid phase to continue with). The compliant phase is
not left while the rigid model would have no consistent configuration at its end: it goes on from its own
state, episode after episode (`run._Run.compliant`); the stiff foundation it integrates is the limit
the rigid model stands for, and it has a motion where the rigid contact problem has none.
"""

from __future__ import annotations

import dataclasses
import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._errors import ScenarioError
from ..._physics import elastic, forces, kinematics, rigid
from ..._physics import energy as energy_mod
from ..._physics.params import RegularisedCoulomb, Scenario
from ..callback_free import callback_free
from ..compile_cache import stored_jit
from .compiled import rope_state
from .records import RigidContactError


@dataclasses.dataclass(frozen=True)
class ChatterRule:
    """When a sequence of impacts counts as a sustained cycle, and how the compliant phase passes it.

    - `window` [s], `min_impacts`: at least this many impacts (or rope jerks) within the last `window`.
    - `decay` [-]: ... whose losses do not decay: mean loss of the later half >= `decay` x the earlier half
      (or at least 4 `min_impacts` impacts within `window`, decaying or not).
    - `stiffness` [N/m per corner]: the foundation of the compliant phase, critically damped
      (h = sqrt(k m)), damper onset 1e-4 m x 1.5e7 / k; `regularisation_velocity` [m/s]: ε of its friction.
      k = 1.5e11 N/m: 100 x the stiffest row of the convergence table (docs/rigid-limit.md), so that the
      hand-back moves the corners by ~1 µm (their static penetration ~ G/k) and books well under 1 J; with
      critical damping and ε = 1e-4 m/s the friction, not k, sets the step size.
    - `rope_stiffness` [N/m]: the inextensible rope's stand-in (critically damped for the boom tip's mass;
      1e11 N/m: a stretch of ~2 µm at the paper's loads).
    - `chunk` [s]: the compliant phase is integrated in chunks of this length; `steady` [s]: it ends once the
      loaded corners (N > `load_fraction` G) have not changed for this long; `max_duration` [s]: at the
      latest after this long.
    - `samples`: contact samples per chunk (the steadiness test).
    - `min_switches`: ... or at least this many contact changes without impact within `window` (a load
      see-sawing between two configurations every few µs, e.g. about the diagonal EF).
    - `max_regularised`: ... or no consistent contact configuration, the least-violating one chosen as a
      regularised phase (fallback 3 of `_Driver._select`) this many times in a row. In the sweep such a
      fallback either stood alone (the next choice was consistent again) or repeated at microsecond
      intervals until the switching detection took over, 47 or 48 times (the load on an edge, E-F or F-H,
      with both corners sticking; docs/rigid-contact.md, "Resolution"): 4 separates the two with a margin on
      both sides.
      Whatever triggered it, a compliant phase is not left while the rigid model would need fallback 3 at
      its end: it is extended (from the compliant state, no hand-back in between) until a configuration is
      consistent again, or to `t1`.
    """

    window: float = 0.05
    min_impacts: int = 12
    decay: float = 0.5
    stiffness: float = 1.5e11
    regularisation_velocity: float = 1e-4
    rope_stiffness: float = 1e11
    chunk: float = 0.01
    steady: float = 0.03
    max_duration: float = 1.0
    load_fraction: float = 1e-3
    samples: int = 65
    min_switches: int = 48
    max_regularised: int = 4

    def check(self) -> None:
        """Raise `ScenarioError` naming the first field that is not a positive finite number (`decay` may
        be 0, `min_impacts`, `min_switches`, `max_regularised` and `samples` are integers >= 1, >= 1, >= 1 and
        >= 2)."""
        for name in (
            "window",
            "stiffness",
            "regularisation_velocity",
            "rope_stiffness",
            "chunk",
            "steady",
            "max_duration",
            "load_fraction",
        ):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ScenarioError(f"ChatterRule.{name} must be a positive finite number, got {v!r}")
        if not (isinstance(self.decay, (int, float)) and 0.0 <= self.decay < math.inf):
            raise ScenarioError(f"ChatterRule.decay must be >= 0, got {self.decay!r}")
        if not (isinstance(self.min_impacts, int) and self.min_impacts >= 1):
            raise ScenarioError(f"ChatterRule.min_impacts must be an integer >= 1, got {self.min_impacts!r}")
        if not (isinstance(self.min_switches, int) and self.min_switches >= 1):
            raise ScenarioError(
                f"ChatterRule.min_switches must be an integer >= 1, got {self.min_switches!r}"
            )
        if not (isinstance(self.max_regularised, int) and self.max_regularised >= 1):
            raise ScenarioError(
                f"ChatterRule.max_regularised must be an integer >= 1, got {self.max_regularised!r}"
            )
        if not (isinstance(self.samples, int) and self.samples >= 2):
            raise ScenarioError(f"ChatterRule.samples must be an integer >= 2, got {self.samples!r}")

    def detect_switching(self, times: list[float], t: float) -> str:
        """`times`: when contact changes without an impact happened. Returns a description if at least
        `min_switches` of them fall within the last `window` seconds before `t`, else ""."""
        n = sum(1 for te in times if te >= t - self.window)
        if n < self.min_switches:
            return ""
        return f"{n} contact changes without impact in {self.window * 1e3:g} ms"

    def detect(self, events: list[tuple[float, float]], t: float) -> str:
        """`events`: (time [s], loss [J]) of the impacts so far. Returns a description of the sustained
        cycle ending at `t`, or "" if there is none."""
        recent = [loss for (te, loss) in events if te >= t - self.window]
        if len(recent) < self.min_impacts:
            return ""
        half = max(len(recent) // 2, 1)
        early, late = float(np.mean(recent[:half])), float(np.mean(recent[-half:]))
        if late < self.decay * early and len(recent) < 4 * self.min_impacts:
            return ""  # a decaying train (a rocking load settling), unless it is very dense
        return (
            f"{len(recent)} impacts in {self.window * 1e3:g} ms, losses not decaying "
            f"({early:.3g} -> {late:.3g} J)"
        )


def compliant_scenario(scenario: Scenario, rule: ChatterRule, inextensible: bool) -> Scenario:
    """The scenario of the compliant phase: the foundation `rule.stiffness`, critically damped, with
    regularised Coulomb friction (ε = `rule.regularisation_velocity`); for the inextensible rope a stiff
    elastic rope, critically damped for the boom tip's mass, damper acting at once."""
    k = float(rule.stiffness)
    m = float(scenario.load.mass)
    sc = scenario.replace(
        **{
            "foundation.stiffness": k,
            "foundation.damping": math.sqrt(k * m),
            "foundation.damping_onset": 1e-4 * 1.5e7 / k,
        }
    )
    sc = eqx.tree_at(lambda s: s.foundation.friction, sc, RegularisedCoulomb(rule.regularisation_velocity))
    if inextensible:
        kr = float(rule.rope_stiffness)
        m0 = float(scenario.boom.tip_mass)
        sc = sc.replace(
            **{"rope.stiffness": kr, "rope.damping": 2.0 * math.sqrt(kr * m0), "rope.damping_onset": 0.0}
        )
    return sc


def _chunk_solve(scenario, c, y0, t0, t1, ts_user, ts_dense, rtol, atol, max_steps):
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(elastic.vector_field),  # pyright: ignore[reportArgumentType]  # jaxtyping Scalar vs diffrax RealScalarLike
        diffrax.Tsit5(),
        t0=t0,
        t1=t1,
        dt0=None,
        y0=y0,
        args=(scenario, c),
        saveat=diffrax.SaveAt(subs=[diffrax.SubSaveAt(ts=ts_user), diffrax.SubSaveAt(ts=ts_dense)]),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=max_steps,
        throw=False,
    )
    ys = sol.ys
    assert ys is not None  # SaveAt(subs=...) saves
    return ys[0], ys[1], sol.result, sol.stats["num_accepted_steps"], sol.stats["num_rejected_steps"]


# stored whole in the cache folder, like the phase driver's pieces (`compiled.py`); no host callback
_chunk_solve_jit = stored_jit("rigid-compliant-chunk-solve")(callback_free(_chunk_solve))


@stored_jit("rigid-compliant-normals")
def _normals(ts, ys, scenario, c):
    """Normal forces N_i [N] and corner velocities [m/s] at the states `ys` (leading axis)."""
    snaps = jax.vmap(lambda t, y: elastic.snapshot(t, y, scenario, c))(ts, ys)
    return snaps.normal, snaps.corner_velocity


@stored_jit("rigid-compliant-mechanical")
def _mechanical(t, y, scenario, c):
    snap = elastic.snapshot(t, y, scenario, c)
    return energy_mod.energy(y, snap, scenario, c).mechanical


@stored_jit("rigid-compliant-elastic-outputs")
def elastic_outputs(ts, ys, scenario, c):
    """Per saved sample of a compliant phase: corners, normal and friction forces, rope tension, energy
    and Euler angles, as `physics.rigid.Output` fields (a dict)."""

    def one(t, y):
        snap = elastic.snapshot(t, y, scenario, c)
        return dict(
            corners=snap.corners,
            normal=snap.normal,
            friction=snap.friction,
            rope_tension=snap.rope_tension,
            energy=energy_mod.energy(y, snap, scenario, c),
            euler=kinematics.matrix_to_euler(snap.rotation),
        )

    return jax.vmap(one)(ts, ys)


@dataclasses.dataclass
class Episode:
    """The result of one compliant phase (host side).

    - `t_end` [s], `y_end`: the state handed back to the rigid model (after the hand-back);
    - `y_before_handback`: the elastic state at `t_end`;
    - `user_states`, `user_index`: the states at the saved times inside the phase and their indices;
    - `loaded`: per corner, loaded when the phase ended; `steady` [s]: how long the loaded set had not
      changed; `handback_loss` [J]: mechanical energy removed by the hand-back (booked with the impact
      losses); `accepted`, `rejected`: solver steps.
    """

    t_end: float
    y_end: elastic.State
    y_before_handback: elastic.State
    user_states: object
    user_index: np.ndarray
    loaded: np.ndarray
    steady: float
    handback_loss: float
    accepted: int
    rejected: int


def run_episode(
    drv, t0: float, y0: elastic.State, t1: float, ts: np.ndarray, filled: np.ndarray, rule: ChatterRule
) -> Episode:
    """Integrate the compliant model from (t0, y0) until the loaded corners are steady (or `max_duration`,
    or `t1`), then hand the state back (module docstring). `drv` is the rigid driver (`_Driver`): its
    scenario, constants, tolerances, settings and velocity projections are used; `ts`/`filled`: the saved
    times and which are filled already."""
    sc_c = compliant_scenario(drv.sc, rule, drv.inextensible)
    c = drv.c
    G = drv.G
    t_stop = min(t1, t0 + rule.max_duration)
    t, y = t0, y0
    user_idx: list[np.ndarray] = []
    user_states = []
    accepted = rejected = 0
    history: list[tuple[float, np.ndarray]] = []  # (time, loaded set) of every dense sample
    opt = drv.options
    while True:
        t_next = min(t + rule.chunk, t_stop)
        if t_stop - t_next < 0.25 * rule.chunk:
            t_next = t_stop
        ts_c = jnp.clip(jnp.asarray(ts, dtype=jnp.float64), t, t_next)
        dense = jnp.linspace(t, t_next, rule.samples)
        yu, yd, result, acc, rej = _chunk_solve_jit(
            sc_c,
            c,
            y,
            jnp.asarray(t, dtype=jnp.float64),
            jnp.asarray(t_next, dtype=jnp.float64),
            ts_c,
            dense,
            opt.rtol,
            opt.atol,
            opt.max_steps,
        )
        accepted += int(acc)
        rejected += int(rej)
        if result != diffrax.RESULTS.successful:
            raise RigidContactError(
                f"the compliant phase from t = {t:.9g} s failed at {t_next:.9g} s: "
                f"{result} (raise max_steps = {opt.max_steps} or loosen rtol/atol)"
            )
        ks = np.nonzero((ts >= t) & (ts <= t_next) & ~filled)[0]
        if ks.size:
            user_idx.append(ks)
            user_states.append(jax.tree_util.tree_map(lambda x: np.asarray(x)[ks], yu))
            filled = filled.copy()
            filled[ks] = True
        N, _ = map(np.asarray, _normals(dense, yd, sc_c, c))
        dense_np = np.asarray(dense)
        for k in range(1, rule.samples):  # the first sample repeats the previous chunk's last
            history.append((float(dense_np[k]), N[k] > rule.load_fraction * G))
        y = jax.tree_util.tree_map(lambda x: x[-1], yd)
        t = t_next
        last = history[-1][1]
        since = t
        for th, ld in reversed(history):
            if not np.array_equal(ld, last):
                break
            since = th
        steady = t - since
        if t >= t_stop or (steady >= rule.steady and t - t0 >= rule.steady):
            break
    y_el = y
    y_hb, loss = handback(drv, sc_c, t, y_el, last)
    index = np.concatenate(user_idx) if user_idx else np.zeros(0, dtype=np.int64)
    states = jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *user_states) if user_states else None
    return Episode(
        t_end=t,
        y_end=y_hb,
        y_before_handback=y_el,
        user_states=states,
        user_index=index,
        loaded=last,
        steady=steady,
        handback_loss=loss,
        accepted=accepted,
        rejected=rejected,
    )


def _onto_ground(drv, t, y, loaded, iterations: int = 3):
    """The smallest displacement of the body (in the kinetic metric M: translation of C, rotation in body
    axes) that puts the `loaded` corners at Z = 0 (a few linearised steps)."""
    for _ in range(iterations):
        mats = drv.matrices(t, y)
        z = mats.corners[loaded, 2]
        J = mats.jacobians[loaded, 2, :]  # dZ_i = J (dr_C, dθ_body)
        Minv = np.linalg.inv(mats.mass)
        d = -Minv @ J.T @ np.linalg.pinv(J @ Minv @ J.T, rcond=1e-12) @ z
        q = np.asarray(y.quaternion)
        w, v = q[0], q[1:]
        dq = np.concatenate([[1.0], 0.5 * d[3:]])  # q ⊗ (1, dθ/2): a rotation dθ in body axes
        q1 = np.array([w * dq[0] - v @ dq[1:], *(w * dq[1:] + dq[0] * v + np.cross(v, dq[1:]))])
        y = eqx.tree_at(
            lambda s: (s.position, s.quaternion),
            y,
            (y.position + jnp.asarray(d[:3]), jnp.asarray(q1 / np.linalg.norm(q1))),
        )
    return y


def handback(drv, sc_c: Scenario, t: float, y: elastic.State, loaded: np.ndarray):
    """The compliant state `y` at `t` as a rigid-model state: the body lifted by the mean penetration of the
    `loaded` corners, the inextensible rope's tip moved along the rope to |AB| = l(t), the velocities
    projected onto zero normal velocity of the loaded corners (the taut rope keeping its rate). Returns
    `(y_rigid, mechanical energy removed [J])`."""
    e_before = float(_mechanical(jnp.asarray(t), y, sc_c, drv.c))
    y_el_work = y.hoist_work
    if np.any(loaded):
        y = _onto_ground(drv, t, y, loaded)
    if drv.inextensible:
        B = kinematics.points_world(
            y.position, kinematics.quat_to_matrix(y.quaternion), drv.c.attachment_rel[None]
        )[0]
        AB = y.tip_position - B
        L = float(forces.safe_norm(AB))
        length = float(drv.c.rope_length - drv.sc.hoist.shortening(jnp.asarray(t)))
        taut = L >= length - drv.tol["z"] * drv.L
        if taut:
            y = eqx.tree_at(lambda s: s.tip_position, y, y.tip_position - (L - length) * AB / L)
        drv.rope_taut = bool(taut)
    if drv.inextensible and drv.rope_taut:
        # The taut rope at its rate as well: d|AB|/dt = dl/dt.
        _, rate_error, _ = map(float, rope_state(jnp.asarray(t), y, drv.sc, drv.c))
        y, _ = drv._project_taut(t, y, np.zeros(4, dtype=bool), loaded, rate_error=rate_error)
    elif np.any(loaded):
        y, _ = drv._project(t, y, np.zeros(4, dtype=bool), loaded)
    # The rigid model's energy of the handed-back state (no ground spring; the inextensible rope stores
    # none); a rope impulse of the projection is hoist work (`_project_taut`): loss = ΔW_hoist - ΔE.
    e_after = float(_rigid_mechanical(jnp.asarray(t), y, drv.sc, drv.c, drv.inextensible))
    work = float(y.hoist_work) - float(y_el_work)
    return y, e_before - e_after + work


@stored_jit("rigid-compliant-rigid-mechanical")
def _rigid_mechanical(t, y, scenario, c, inextensible):
    ld = rigid.loads(t, y, scenario, c, inextensible)
    return rigid.energy(y, ld, scenario, c).mechanical


def with_compliant_outputs(out, ts, states, mask, drv, rule):
    """`out` (a `rigid.Output` with a leading n_t axis) with the samples `mask` replaced by the outputs of
    the compliant model (this module): its corner spring forces, friction, rope and energies
    (ground spring and stiff rope included)."""
    k = np.nonzero(mask)[0]
    sel = jax.tree_util.tree_map(lambda x: jnp.asarray(np.asarray(x)[k]), states)
    el = elastic_outputs(jnp.asarray(ts[k]), sel, compliant_scenario(drv.sc, rule, drv.inextensible), drv.c)

    def put(a, b):
        a = np.array(a)
        a[k] = np.asarray(b)
        return jnp.asarray(a)

    return eqx.tree_at(
        lambda o: (o.corners, o.normal, o.friction, o.rope_tension, o.energy, o.euler),
        out,
        (
            put(out.corners, el["corners"]),
            put(out.normal, el["normal"]),
            put(out.friction, el["friction"]),
            put(out.rope_tension, el["rope_tension"]),
            jax.tree_util.tree_map(put, out.energy, el["energy"]),
            put(out.euler, el["euler"]),
        ),
    )
