"""A lock-step group of adaptive solves: one while loop over the whole group, each lane's step batched inside
its body, with diffrax's own step, step-size control and dense output.

Each lane runs the loop of `diffrax.diffeqsolve` with `SaveAt(ts=...)`: the solver's `step`, the
controller's `adapt_step_size`, the last step clipped to t1 as diffrax clips it, the first failure kept as
the lane's result, and the saved times that an accepted step passes filled from the solver's dense output
(`solver.interpolation_cls`). A lane that has reached t1, failed, or used its `max_steps` steps stays as it
is while the others go on. The step and its control are diffrax's own functions, only the loop around
them is written here, so a lane takes the steps its solve alone takes, up to rounding: XLA compiles the
two programs differently, and in stick-slip a rounding that flips a step's acceptance moves the rest of
the solution by up to the solver's tolerance.

Why this design: a group written as `jax.vmap` of `diffeqsolve` batches the solve's while loop, and JAX
batches a while loop's body once per pass of its search for which parts of the loop's state are batched,
then once more: four times for the default scan group's loop body (4 536 equations, about 1.2 s each on
the 2-core AMD machine). Here the loop is written over the group, so its body (`jax.vmap` of one lane's
step) is batched once, and the saves are a scatter into the group's arrays. On that machine, 16 lanes of
paper-4.2 over 25 s, two runs each against the vmapped group in the same minutes: the group traces in
2.6-2.7 s instead of 9.5 s (less than one member alone, 3.1-3.3 s), XLA compiles it in 13.3-13.5 s
instead of 13.0-13.1 s, and it runs in 0.33 s instead of 0.35-0.36 s
(`python experiments/benchmarks/bench_compile_phases.py --program scan --run`).
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._physics.elastic import vector_field


def supports(solver, controller, progress_meter) -> bool:
    """Whether a group with this solver and step-size controller (as `solve.step_size_controller` makes it)
    can be solved in lock step: an adaptive solver with diffrax's PID controller (no jumps, no clipping to
    given times), without an in-loop progress meter."""
    return (
        isinstance(solver, diffrax.AbstractAdaptiveSolver)
        and type(controller) is diffrax.PIDController
        and isinstance(progress_meter, diffrax.NoProgressMeter)
    )


class GroupSolution(eqx.Module):
    """The lanes' solutions, each with a leading lane axis: `ys` the states at the saved times (inf where a
    failed lane never got), `result` diffrax's `RESULTS` of each lane, and the accepted and rejected steps."""

    ys: object
    result: diffrax.RESULTS
    num_accepted_steps: Int[Array, " lanes"]
    num_rejected_steps: Int[Array, " lanes"]


class _Lane(eqx.Module):
    """One lane's loop state, as `diffeqsolve`'s loop keeps it: the step [tprev, tnext] to take next [s], the
    state at tprev, the solver's and the controller's state, the first failure, and the step counts."""

    tprev: Float[Array, ""]
    tnext: Float[Array, ""]
    y: object
    solver_state: object
    controller_state: object
    result: diffrax.RESULTS
    steps: Int[Array, ""]
    accepted: Int[Array, ""]
    rejected: Int[Array, ""]


def solve_group(
    solver, controller, ts: Float[Array, " n_t"], y0s, args, dt0: float | None, max_steps: int
) -> GroupSolution:
    """Solve dy/dt = `physics.elastic.vector_field`(t, y, args) for every lane from t = 0 to `ts[-1]`,
    saving at `ts`.

    - `solver`, `controller`: a diffrax adaptive solver and PID controller (`supports`).
    - `ts`: the saved times [s], the same for every lane; the first is t0 = 0 as in `solve`.
    - `y0s`, `args`: each lane's initial state and arguments, every array leaf with a leading lane axis.
    - `dt0`: the first step [s], or None (0.01 s, where `diffeqsolve` with diffrax's PID controller starts);
      `max_steps`: each lane's step budget (accepted and rejected steps, as `diffeqsolve` counts them).
    """
    terms = diffrax.ODETerm(vector_field)  # pyright: ignore[reportArgumentType]  # jaxtyping Scalar vs diffrax RealScalarLike
    # `diffeqsolve` hands the controller its term wrapped (for the direction of time), and diffrax's PID
    # controller starts a wrapped term at 0.01 s when no first step is given (it estimates one for a bare
    # `ODETerm` only): the lanes start as a solve does (tests/test_scan.py checks the steps against `solve`)
    if dt0 is None:
        dt0 = 0.01
    n_t = ts.shape[0]
    t0, t1 = ts[0] * 0.0, ts[-1]
    error_order = solver.error_order(terms)
    t1_clip_floor = t1  # t1 less 100 ULPs: a step ending past it ends at t1 (diffrax's `_clip_to_end`)
    for _ in range(100):
        t1_clip_floor = eqxi.prevbefore(t1_clip_floor)

    def start(y0, args) -> _Lane:
        tnext, controller_state = controller.init(terms, t0, t1, y0, dt0, args, solver.func, error_order)
        tnext = jnp.minimum(tnext, t1)
        zero = jnp.zeros((), jnp.int32)
        return _Lane(
            tprev=t0,
            tnext=tnext,
            y=y0,
            solver_state=solver.init(terms, t0, tnext, y0, args),
            controller_state=controller_state,
            result=diffrax.RESULTS.successful,
            steps=zero,
            accepted=zero,
            rejected=zero,
        )

    def running(s: _Lane):
        return (s.tprev < t1) & (s.result == diffrax.RESULTS.successful) & (s.steps < max_steps)

    def step(s: _Lane, args):
        """One lane's step (diffrax's loop body without the saves); returns the new state, the step's dense
        output and whether it saves (accepted, and the lane was running)."""
        y, y_error, dense_info, solver_state, solver_result = solver.step(
            terms, s.tprev, s.tnext, s.y, args, s.solver_state, False
        )
        y_error = jax.tree_util.tree_map(lambda x: jnp.where(jnp.isnan(x), jnp.inf, x), y_error)
        keep, tprev, tnext, _, controller_state, controller_result = controller.adapt_step_size(
            s.tprev, s.tnext, s.y, y, args, y_error, error_order, s.controller_state
        )
        tprev = jnp.minimum(tprev, t1)
        tnext = jnp.where(tnext > t1_clip_floor, jnp.where(keep, t1, tprev + 0.5 * (t1 - tprev)), tnext)
        kept = lambda a, b: jnp.where(keep, a, b)  # noqa: E731
        solver_result = diffrax.RESULTS.where(keep, solver_result, diffrax.RESULTS.successful)
        result = diffrax.RESULTS.where(s.result == diffrax.RESULTS.successful, solver_result, s.result)
        result = diffrax.RESULTS.where(result == diffrax.RESULTS.successful, controller_result, result)
        new = _Lane(
            tprev=tprev,
            tnext=tnext,
            y=jax.tree_util.tree_map(kept, y, s.y),
            solver_state=jax.tree_util.tree_map(kept, solver_state, s.solver_state),
            controller_state=controller_state,
            result=result,
            steps=s.steps + 1,
            accepted=s.accepted + jnp.where(keep, 1, 0),
            rejected=s.rejected + jnp.where(keep, 0, 1),
        )
        on = running(s)
        new = jax.tree_util.tree_map(lambda a, b: jnp.where(on, a, b), new, s)
        return new, dense_info, keep & on

    def evaluate(dense_info, ta, tb, t):
        return solver.interpolation_cls(t0=ta, t1=tb, **dense_info).evaluate(t)

    # args' array leaves batched over the lanes, the rest (static) closed over; every part of a lane's
    # state, Python constants included, batched
    dynamic, static = eqx.partition(args, eqx.is_array)
    lane_step = jax.vmap(lambda s, d: step(s, eqx.combine(d, static)))
    lane_evaluate = jax.vmap(evaluate)

    def body(carry):
        s, index, ys = carry
        new, dense_info, saves = lane_step(s, dynamic)
        lanes = jnp.arange(index.shape[0])

        def due(i):  # the next saved time lies in the step just taken [tprev, tnext]
            return saves & (i < n_t) & (ts[jnp.minimum(i, n_t - 1)] <= s.tnext)

        def save(c):
            i, ys = c
            d = due(i)
            i_ = jnp.minimum(i, n_t - 1)
            y_at = lane_evaluate(dense_info, s.tprev, s.tnext, ts[i_])

            def put(a, v):
                mask = d.reshape(d.shape + (1,) * (v.ndim - 1))
                return a.at[lanes, i_].set(jnp.where(mask, v, a[lanes, i_]))

            return i + jnp.where(d, 1, 0), jax.tree_util.tree_map(put, ys, y_at)

        index, ys = jax.lax.while_loop(lambda c: jnp.any(due(c[0])), save, (index, ys))
        return new, index, ys

    s = jax.vmap(lambda y0, d: start(y0, eqx.combine(d, static)))(y0s, dynamic)
    n_lanes = s.steps.shape[0]
    ys = jax.tree_util.tree_map(lambda y: jnp.full((n_lanes, n_t, *y.shape[1:]), jnp.inf, y.dtype), y0s)
    index = jnp.zeros((n_lanes,), jnp.int32)
    s, _, ys = jax.lax.while_loop(lambda c: jnp.any(jax.vmap(running)(c[0])), body, (s, index, ys))
    out_of_steps = (s.steps >= max_steps) & (s.tprev < t1) & (s.result == diffrax.RESULTS.successful)
    result = jax.vmap(lambda out, r: diffrax.RESULTS.where(out, diffrax.RESULTS.max_steps_reached, r))(
        out_of_steps, s.result
    )
    return GroupSolution(ys=ys, result=result, num_accepted_steps=s.accepted, num_rejected_steps=s.rejected)
