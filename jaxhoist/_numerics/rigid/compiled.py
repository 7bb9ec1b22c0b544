"""The compiled (jitted) pieces of the rigid model's phase driver: the phase solve, guards, candidate
configurations, impulses, rope state and outputs (`numerics.rigid.solve`), and small host helpers."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..._errors import ScenarioError
from ..._physics import rigid
from ..callback_free import callback_free
from ..compile_cache import stored_jit


@dataclasses.dataclass(frozen=True)
class Options:
    rtol: float
    atol: float
    max_steps: int
    event_atol: float
    stall_window: int = 0  # step attempts per progress check (0: no check); see `StallRule`
    stall_step: float = 0.0  # [s] smallest mean step over a window before the phase counts as stalled


@dataclasses.dataclass(frozen=True)
class StallRule:
    """When a phase solve of the rigid model counts as stalled, long before `max_steps`.

    A phase stalls when its step size collapses and stays collapsed: typically a corner sliding with a slip
    speed near zero, where the slip direction turns quickly and the steps resolve the slip regularisation
    (`Settings.slip_velocity` ε_v = 1e-6 m/s over accelerations ~g: ε_v/g ≈ 1e-7 s) instead of the motion.
    The solve checks its progress every `window` step attempts (accepted and rejected): if the time reached
    advanced by less than `window x min_step` since the previous check, the phase has stalled (the solve
    ends with `diffrax.RESULTS.dt_min_reached`); the driver then treats it as it treats a phase that reached
    `max_steps` (chosen again once without its configuration, then a compliant phase).

    - `window` [-]: step attempts per progress check.
    - `min_step` [s]: the smallest mean step over a window.

    Defaults (docs/rigid-contact.md, "Resolution"), from the mean step over windows of 1000 attempts: stalled
    phases 0.6-1.6e-7 s (paper-2.3, elastic rope, μ = 0.30 at 16.1-16.9 s; paper-4.2 at 0.3 ms), i.e. about
    ε_v/g; phases that complete: at least 3.3e-6 s in the presets paper-2.3 and paper-4.1 (both ropes, full
    length), 1.4e-6 s at the start of sliding (paper-2.3, μ = 0.30, 0.32 s), and the slowest, corner F of
    paper-4.2 sliding at near-zero slip at 10.1-11.5 s, 3.8-5.7e-7 s (8 000-18 000 attempts each).
    `min_step` = 2e-7 s (about 2 ε_v/g) lies between; 5000 attempts average over a start-up transient of a
    few hundred small steps, and cost 1/40 of `max_steps` = 200 000.
    """

    window: int = 5000
    min_step: float = 2e-7

    def check(self) -> None:
        """Raise `ScenarioError` if `window` is not an integer >= 1 or `min_step` not a positive finite
        time [s]."""
        if not (isinstance(self.window, int) and self.window >= 1):
            raise ScenarioError(f"StallRule.window must be an integer >= 1, got {self.window!r}")
        v = self.min_step
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ScenarioError(f"StallRule.min_step must be a positive finite time [s], got {v!r}")


class _StallGuard(diffrax.AbstractAdaptiveStepSizeController):
    """A `diffrax.PIDController` that also ends the solve when it stops making progress: after every
    `window` step attempts (accepted or rejected) the time reached must have advanced by at least
    `window x min_step` [s] since the previous check, else the solve ends with
    `diffrax.RESULTS.dt_min_reached` (the mean step fell below `min_step`; "stalled").

    The step sizes, acceptance and controller state are the PID controller's, unchanged: a solve that never
    falls below the floor takes exactly the steps it took without the guard. See `_Driver.solve` and
    docs/rigid-contact.md, "Resolution", for the values and why."""

    rtol: float
    atol: float
    window: int = eqx.field(static=True)
    min_step: float = eqx.field(static=True)
    norm: Callable = optx.rms_norm

    @property
    def controller(self) -> diffrax.PIDController:
        """The PID controller whose steps are taken."""
        return diffrax.PIDController(rtol=self.rtol, atol=self.atol, norm=self.norm)

    def wrap(self, direction):
        del direction  # PIDController.wrap keeps itself
        return self

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        tnext, state = self.controller.init(terms, t0, t1, y0, dt0, args, func, error_order)
        return tnext, (state, jnp.asarray(t0, dtype=jnp.result_type(tnext)), jnp.asarray(0, dtype=jnp.int32))

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state):
        state, t_mark, n = controller_state
        keep, next_t0, next_t1, jump, state, result = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, state
        )
        n = n + 1
        check = n >= self.window
        stalled = check & (next_t0 - t_mark < self.window * self.min_step)
        result = diffrax.RESULTS.where(stalled, diffrax.RESULTS.dt_min_reached, result)
        t_mark = jnp.where(check, next_t0, t_mark)
        n = jnp.where(check, 0, n)
        return keep, next_t0, next_t1, jump, (state, t_mark, n), result


def _phase_solve(scenario, c, phase, settings, y0, t0, t1, ts, options: Options, inextensible: bool = False):
    event = diffrax.Event(
        rigid.event_condition,
        root_finder=optx.Bisection(rtol=1e-14, atol=options.event_atol),
        direction=False,
    )
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rigid.vector_field),  # pyright: ignore[reportArgumentType]  # jaxtyping Scalar vs diffrax RealScalarLike
        diffrax.Tsit5(),
        t0=t0,
        t1=t1,
        dt0=None,
        y0=y0,
        args=(scenario, c, phase, settings) + ((True,) if inextensible else ()),
        saveat=diffrax.SaveAt(ts=ts, t1=True),
        stepsize_controller=_controller(options),
        max_steps=options.max_steps,
        event=event,
        throw=False,
    )
    return sol.ts, sol.ys, sol.result, sol.stats["num_accepted_steps"], sol.stats["num_rejected_steps"]


def _controller(options: Options):
    """The phase solves' step size controller: PID at (rtol, atol), with the progress check of
    `_StallGuard` when `options.stall_window` > 0."""
    if options.stall_window <= 0:
        return diffrax.PIDController(rtol=options.rtol, atol=options.atol)
    return _StallGuard(
        rtol=options.rtol, atol=options.atol, window=options.stall_window, min_step=options.stall_step
    )


# The driver's compiled pieces are stored whole in the cache folder (`compile_cache.stored_jit`): a later
# process loads them untraced (tracing them took most of a warm run's first call). No host callback.
phase_solve_jit = stored_jit("rigid-phase-solve")(callback_free(_phase_solve))
raw_guards_jit = stored_jit("rigid-raw-guards")(rigid.raw_guards)


@stored_jit("rigid-eval-candidates")
def eval_candidates(t, y, scenario, c, settings, contact, hints, rope, inextensible=False):
    """Contact forces, corner accelerations, body accelerations and rope tension for a batch of
    configurations (rope mode `rope`, an integer array)."""

    def one(ct, h):
        ph = rigid.make_phase(ct, slip_hint=h, rope=rope)
        d = rigid.contact_dynamics(t, y, scenario, c, ph, settings, inextensible)
        return d.force, d.corner_accel, d.accel, d.loads.rope_tension

    return jax.vmap(one)(contact, hints)


@stored_jit("rigid-eval-rope-impulses")
def eval_rope_impulses(t, y, scenario, c, modes, slip_dirs, normal_target, rcond):
    return jax.vmap(lambda m, s: rigid.rope_impulse_response(t, y, scenario, c, m, s, normal_target, rcond))(
        modes, slip_dirs
    )


@stored_jit("rigid-eval-impulses")
def eval_impulses(y, scenario, c, modes, slip_dirs, normal_target, rcond):
    return jax.vmap(lambda m, s: rigid.impulse_response(y, scenario, c, m, s, normal_target, rcond))(
        modes, slip_dirs
    )


contact_matrices_jit = stored_jit("rigid-contact-matrices")(rigid.contact_matrices)


@stored_jit("rigid-rope-direction")
def rope_direction_jit(t, y, scenario, c):
    return rigid.loads(t, y, scenario, c).rope_direction


@stored_jit("rigid-rope-state")
def rope_state(t, y, scenario, c):
    """|AB| - l(t) [m], d|AB|/dt - dl/dt [m/s] and ds/dt [m/s] of the inextensible rope."""
    ld = rigid.loads(t, y, scenario, c, inextensible=True)
    return ld.stretch, ld.rope_rate_error, ld.hoist_rate


class Jam(Exception):
    """No consistent contact configuration while corners on the ground slide: resolve by a tangential
    impact (`_Driver.jam`), then choose again."""


class RopeWouldPush(Exception):
    """No configuration (or impulse) with the taut inextensible rope has S >= 0: try the slack rope."""


@stored_jit("rigid-forces")
def forces(t, y, scenario, c, phase, settings, inextensible=False):
    return rigid.contact_dynamics(t, y, scenario, c, phase, settings, inextensible).force


@stored_jit("rigid-outputs")
def _outputs(ts, ys, scenario, c, phases, settings, inextensible=False):
    return jax.vmap(lambda t, y, ph: rigid.output(t, y, scenario, c, ph, settings, inextensible))(
        ts, ys, phases
    )


#: Saved samples per output evaluation (`_chunked_outputs`): one compiled shape serves every `n_save`.
OUTPUT_CHUNK = 1024


def chunked_outputs(ts, states, phase_index, phases, scenario, c, settings, inextensible):
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


def tree_index(tree, i):
    return jax.tree_util.tree_map(lambda x: x[i], tree)


def as_numpy(x):
    return np.asarray(x)
