"""`simulate_elastic`, the elastic-foundation model of `simulate`: validate on the host, then one
`eqx.filter_jit` core that solves the elastic model with diffrax and evaluates every output at the saved
times. It knows nothing of the rigid model (`_apps/simulate.py` dispatches on the model type)."""

from __future__ import annotations

import functools
from collections.abc import Callable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, Float, Int

from .._errors import SolveStatus, forward_mode_hint
from .._physics import energy as energy_mod
from .._physics import kinematics
from .._physics.elastic import Constants, State, snapshot, vector_field
from .._physics.equilibrium import initial_state
from .._physics.params import Scenario
from . import compile_cache, xla_options
from .callback_free import callback_free, raise_on_status
from .options import SolverOptions
from .sensitivity import solve_forward, uses_tangent_solve
from .times import Times, is_tracer
from .trajectory import Trajectory as Trajectory


def solve_status(result, y1: State) -> Int[Array, ""]:
    """The `SolveStatus` of a solve from diffrax's `result` and the last saved state `y1` (not finite:
    `NONFINITE`)."""
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(y1)]))
    return jnp.where(
        result == diffrax.RESULTS.successful,
        jnp.where(finite, SolveStatus.OK, SolveStatus.NONFINITE),
        jnp.where(
            result == diffrax.RESULTS.max_steps_reached, SolveStatus.MAX_STEPS, SolveStatus.SOLVER_FAILED
        ),
    ).astype(jnp.int32)


def checked_status(status, energies: energy_mod.Energy, ys: State) -> Int[Array, ""]:
    """`status`, or `SolveStatus.ENERGY_BALANCE` where the solver reported success but the energy balance
    over the saved times does not close (`energy.relative_balance_residual` above `energy.BALANCE_BOUND`,
    or not finite). Computed inside the compiled solve from what it already has, so a vmapped scan checks
    every member; it only reads the result."""
    rel = energy_mod.relative_balance_residual(
        energies.mechanical, ys.hoist_work, ys.damping_loss, ys.friction_work
    )
    broken = (status == SolveStatus.OK) & ~(jnp.asarray(rel) <= energy_mod.BALANCE_BOUND)
    return jnp.where(broken, SolveStatus.ENERGY_BALANCE, status).astype(jnp.int32)


def outputs(ts, ys: State, scenario: Scenario, c: Constants, status, stats) -> Trajectory:
    """Evaluate every output at the saved states; a solve marked ok whose energy balance does not close is
    marked `ENERGY_BALANCE` (`checked_status`)."""

    def one(t, y):
        snap = snapshot(t, y, scenario, c)
        return snap, energy_mod.energy(y, snap, scenario, c)

    snaps, energies = jax.vmap(one)(ts, ys)
    status = checked_status(status, energies, ys)
    euler = jax.vmap(kinematics.matrix_to_euler)(snaps.rotation)
    euler = euler.at[:, :2].set(jnp.unwrap(euler[:, :2], axis=0))
    return Trajectory(
        ts=ts,
        position=ys.position,
        velocity=ys.velocity,
        euler=euler,
        angular_velocity=ys.angular_velocity,
        corners=snaps.corners,
        normal_forces=snaps.normal,
        friction_forces=snaps.friction,
        ground_reaction=jnp.sum(snaps.normal, axis=-1),
        rope_tension=snaps.rope_tension,
        tip_position=ys.tip_position,
        energy=energies,
        hoist_work=ys.hoist_work,
        damping_loss=ys.damping_loss,
        friction_work=ys.friction_work,
        states=ys,
        status=status,
        num_accepted_steps=stats["num_accepted_steps"],
        num_rejected_steps=stats["num_rejected_steps"],
    )


def step_size_controller(options: SolverOptions, ts):
    """The step-size controller of `options`; for a solver whose dense output is only linear, error control
    also lands a step on every saved time, so that saved values are the method's own rather than linearly
    interpolated (the Rosenbrock-W solver's dense output is cubic Hermite, diffrax's Runge-Kutta methods'
    their own: neither needs it)."""
    ctrl = options.stepsize_controller
    linear = options.solver.interpolation_cls is diffrax.LocalLinearInterpolation
    if linear and isinstance(ctrl, diffrax.PIDController):
        ctrl = diffrax.ClipStepSizeController(ctrl, step_ts=ts)
    return ctrl


@callback_free
def solve(scenario: Scenario, ts: Float[Array, " n_t"], options: SolverOptions) -> Trajectory:
    """The traceable core: initial state, one diffeqsolve with `throw=False`, outputs. Never raises, and
    carries no host callback unless `options.progress_meter` asks for one (`callback_free`).
    With the Rosenbrock-W solver in forward mode, derivatives are the error-controlled sensitivities of
    `sensitivity.solve_forward`."""
    if uses_tangent_solve(options):
        return _solve_forward(scenario, ts, options)
    return _solve_plain(scenario, ts, options)


def _solve_plain(scenario: Scenario, ts: Float[Array, " n_t"], options: SolverOptions) -> Trajectory:
    y0, c = initial_state(scenario)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field),  # pyright: ignore[reportArgumentType]  # jaxtyping Scalar vs diffrax RealScalarLike
        options.solver,
        t0=ts[0] * 0.0,
        t1=ts[-1],
        dt0=options.dt0,
        y0=y0,
        args=(scenario, c),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=step_size_controller(options, ts),
        max_steps=options.max_steps,
        adjoint=options.adjoint,
        progress_meter=options.progress_meter,
        throw=False,
    )
    y1 = jax.tree_util.tree_map(lambda x: x[-1], sol.ys)
    return outputs(ts, sol.ys, scenario, c, solve_status(sol.result, y1), sol.stats)  # pyright: ignore[reportArgumentType]  # sol.ys is the saved State with SaveAt(ts=...)


_solve_forward = solve_forward(_solve_plain, step_size_controller, outputs, solve_status)
_solve_forward_joint = solve_forward(_solve_plain, step_size_controller, outputs, solve_status, joint=True)


@callback_free
def solve_joint(scenario: Scenario, ts: Float[Array, " n_t"], options: SolverOptions) -> Trajectory:
    """`solve`, for differentiation along one direction (`jax.jvp`) as a scan with derivatives does: with
    the Rosenbrock-W solver in forward mode, the trajectory and its tangent both come from the augmented
    solve (`sensitivity.solve_forward` with `joint=True`), one solve instead of the plain one and the
    augmented one, so the values agree with `solve`'s to the solver's tolerance, not bit for bit. Not for
    `jax.jacfwd` (the primal depends on the direction). Undifferentiated, and with any other solver, the
    same as `solve`."""
    if uses_tangent_solve(options):
        return _solve_forward_joint(scenario, ts, options)
    return _solve_plain(scenario, ts, options)


_solve_jit = eqx.filter_jit(solve)


def _has_tangent(x) -> bool:
    """Whether an output leaf `x` has a tangent a compiled program returns: a float one (an integer or bool
    leaf's tangent is `float0`, which none returns)."""
    return bool(jnp.issubdtype(jnp.result_type(x), jnp.inexact))


def _jvp_of_solve(scenario: Scenario, ts, options: SolverOptions, moved: tuple[bool, ...], d_moved: list):
    """`jax.jvp` of `_solve_jit` along the leaves of `(scenario, ts)` marked in `moved` (their tangents
    `d_moved`; every other leaf held, a symbolic zero): the program JAX builds for a caller's `jax.jvp` of a
    function that calls `simulate` (explicit zero tangents on the held leaves give another program, which
    rounds differently)."""
    leaves, tree = jax.tree_util.tree_flatten((scenario, ts))

    def moving(xs):
        it = iter(xs)
        s, t = jax.tree_util.tree_unflatten(tree, [next(it) if m else x for x, m in zip(leaves, moved)])
        return _solve_jit(s, t, options)

    return jax.jvp(moving, ([x for x, m in zip(leaves, moved) if m],), (list(d_moved),))


def solve_jvp(scenario: Scenario, ts, options: SolverOptions, moved: tuple[bool, ...], d_moved: list):
    """`_jvp_of_solve` as one program, as `compile_cache.program` stores it. **Returns** `(trajectory,
    tangent leaves)`: the tangent's leaves in `Trajectory` order, those of `_has_tangent` leaves only."""
    out, d_out = _jvp_of_solve(scenario, ts, options, moved, d_moved)
    leaves = jax.tree_util.tree_leaves(out)
    return out, [d for x, d in zip(leaves, jax.tree_util.tree_leaves(d_out)) if _has_tangent(x)]


def _stored_forward(options: SolverOptions):
    """`_solve_jit` with forward-mode `options` bound, for a call under a caller's transformation, as a
    `jax.custom_jvp` whose rule runs `solve_jvp` as the stored program of `compile_cache.program` where the
    primals and tangents are concrete: a `jax.jvp` of a function that calls `simulate`, outside `jax.jit`.
    A later process then loads the derivative's program instead of tracing the solve and its tangent solve
    again. Anywhere else (under `jax.jit` or `jax.vmap`, as in `jax.jacfwd`) the rule is `_jvp_of_solve`
    traced in place. Both are the program JAX builds without the rule; the stored one is compiled with
    jaxhoist's compiler options (`xla_options`), the one traced in place with the caller's, so the two
    agree to rounding (and to the solver's local error where rounding flips a step's acceptance)."""

    @jax.custom_jvp
    def core(scenario, ts):
        return _solve_jit(scenario, ts, options)

    def core_jvp(primals, tangents):
        scenario, ts = primals
        d_leaves = jax.tree_util.tree_leaves(tangents, is_leaf=lambda x: isinstance(x, SymbolicZero))
        moved = tuple(not isinstance(d, SymbolicZero) for d in d_leaves)
        d_moved = [d for d, m in zip(d_leaves, moved) if m]
        if any(map(is_tracer, jax.tree_util.tree_leaves((primals, d_moved)))):
            return _jvp_of_solve(scenario, ts, options, moved, d_moved)
        args = (scenario, ts, options, moved, d_moved)
        out, d_floats = compile_cache.program("simulate-jvp", "solve_jvp", solve_jvp, args)[0](*args)
        d_floats = iter(d_floats)
        leaves, tree = jax.tree_util.tree_flatten(out)
        d_out = [
            next(d_floats) if _has_tangent(x) else np.zeros(np.shape(x), jax.dtypes.float0) for x in leaves
        ]
        return out, jax.tree_util.tree_unflatten(tree, d_out)

    core.defjvp(core_jvp, symbolic_zeros=True)
    return lambda scenario, ts, options: core(scenario, ts)


def _core(scenario: Scenario, ts, options: SolverOptions):
    """The compiled solve core for these inputs: with concrete inputs, the one program of
    `compile_cache.program`, compiled with jaxhoist's compiler options (`xla_options`) and, with the
    persistent compilation cache on, stored whole in the cache folder, so that a later process loads it
    without tracing or lowering it (the command line's `simulate` shares it); under a caller's
    transformation with forward-mode `options`, `_stored_forward` (`_solve_jit` in a `jax.custom_jvp` whose
    rule runs the derivative's program of `compile_cache.program` where a `jax.jvp` brings concrete
    values); under a caller's transformation with other `options` (`jax.jit`, `jax.vmap`, `jax.grad`),
    `_solve_jit`, traced into the caller's program; with an in-loop progress meter (a host callback, which
    no stored program carries), `_solve_jit` compiled with jaxhoist's compiler options."""
    args = (scenario, ts, options)
    if not isinstance(options.progress_meter, diffrax.NoProgressMeter):
        return _solve_jit_with(tuple(xla_options.compiler_options().items()))
    if any(map(is_tracer, jax.tree_util.tree_leaves(args))):
        if uses_tangent_solve(options) and not any(map(is_tracer, jax.tree_util.tree_leaves(options))):
            return _stored_forward(options)
        return _solve_jit
    return compile_cache.program("simulate", "solve", solve, args)[0]


@functools.cache
def _solve_jit_with(compiler_options: tuple) -> Callable:
    """`solve` as `eqx.filter_jit` compiles it at the top level with the XLA options `compiler_options`
    ((name, value) pairs)."""
    # filter_jit passes jax.jit's keyword arguments on (its typed overloads leave them out)
    return eqx.filter_jit(solve, compiler_options=dict(compiler_options))  # pyright: ignore[reportCallIssue]


def _raise_on_failure(traj: Trajectory) -> Trajectory:
    return raise_on_status(traj, traj.status, SolveStatus.OK, [s.message for s in SolveStatus])


def as_float64_leaves(scenario: Scenario) -> Scenario:
    """Every float leaf as a strongly typed float64 array, so that a leaf set with `eqx.tree_at` to a Python
    float or a weakly typed array hits the same compiled core instead of compiling again."""

    def fix(x):
        if isinstance(x, bool) or not isinstance(x, float | int | np.ndarray | np.generic | jax.Array):
            return x
        return jax.lax.convert_element_type(jnp.asarray(x), jnp.float64)

    return jax.tree_util.tree_map(fix, scenario)


def checked_scenario(scenario: object) -> Scenario:
    """What every entry point that solves (`simulate`, `simulate_rigid`, `scan`, `locate_bifurcation`,
    `identify`) does first with its scenario, on the host, before anything compiles: refuse what is no
    `Scenario`, run `Scenario.check()`, and pass every float leaf through `as_float64_leaves`.

    **Returns** the checked scenario, its float leaves strongly typed float64 arrays (a leaf set to a Python
    float reuses the programs compiled for the others).

    **Raises** `TypeError` for what is no `Scenario`; `ScenarioError` naming the first invalid field.
    """
    if not isinstance(scenario, Scenario):
        raise TypeError(f"scenario must be a jaxhoist.Scenario, got {type(scenario).__name__}")
    scenario.check()
    return as_float64_leaves(scenario)


#: The number of saved times of `simulate` and `simulate_rigid` when `Times.n` is None.
DEFAULT_N = 501


def simulate_elastic(
    scenario: Scenario, times: Times, options: SolverOptions | None = None, *, throw: bool = True
) -> Trajectory:
    """The elastic-foundation model (paper §3) of `jaxhoist.simulate`: check `scenario` on the host, then
    one `eqx.filter_jit` core that solves with diffrax and evaluates every output at the saved `times`.

    **Arguments**
    - `scenario`: a `Scenario`.
    - `times`: the saved times, a `Times` (its defaults resolved here: t1 the scenario's, 501 times).
    - `options`: `SolverOptions` (default `SolverOptions()`, the Rosenbrock-W solver).
    - `throw`: raise if the solve fails (max steps, non-finite state, or an energy balance that does not
      close: `SolveStatus.ENERGY_BALANCE`, the solver's success contradicted by the result); with False,
      read `Trajectory.status`.

    **Returns** a `Trajectory`.

    **Raises** `ScenarioError` for invalid input (before compiling), and (with `throw=True`) an
    `EquinoxRuntimeError` naming the failure.
    """
    scenario = checked_scenario(scenario)
    if options is None:
        options = SolverOptions()
    _, ts = times.resolve(scenario, DEFAULT_N, jnp)
    ts = jnp.asarray(ts, dtype=jnp.float64)
    with forward_mode_hint():  # jacfwd through the reverse adjoint: say to pass adjoint=diffrax.ForwardMode()
        scenario = scenario.unlabelled()  # one program for any labels
        options = options.traced_tolerances()  # one program for any rtol and atol
        traj = _core(scenario, ts, options)(scenario, ts, options)
    return _raise_on_failure(traj) if throw else traj
