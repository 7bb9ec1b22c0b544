"""`simulate`: validate on the host, then one `eqx.filter_jit` core that solves the elastic model with
diffrax and evaluates every output at the saved times."""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._deprecated import warn_moved
from .._errors import ScenarioError, SolveStatus, forward_mode_hint, require_x64
from .._physics import energy as energy_mod
from .._physics import kinematics
from .._physics.elastic import Constants, State, snapshot, vector_field
from .._physics.equilibrium import initial_state
from .._physics.params import Scenario
from .callback_free import callback_free, raise_on_status
from .options import AbstractModel, ElasticFoundation, RigidGround, SolverOptions, as_model
from .rigid_options import RigidOptions
from .rigid_solve import simulate_rigid
from .sensitivity import solve_forward, uses_tangent_solve
from .times import TimesLike
from .times import convert_legacy as convert_legacy_times
from .trajectory import Trajectory as Trajectory


def _status(result, y1: State) -> Int[Array, ""]:
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
    return outputs(ts, sol.ys, scenario, c, _status(sol.result, y1), sol.stats)  # pyright: ignore[reportArgumentType]  # sol.ys is the saved State with SaveAt(ts=...)


_solve_forward = solve_forward(_solve_plain, step_size_controller, outputs, _status)
_solve_jit = eqx.filter_jit(solve)


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


#: The number of saved times of `simulate` and `simulate_rigid` when `Times.n` is None.
DEFAULT_N = 501

_LEGACY_SOLVER_KW = ("solver", "rtol", "atol", "dt0", "max_steps", "adjoint", "progress", "fixed_step")

#: The new spelling of each earlier keyword of `simulate` (for the deprecation warning).
_NEW_SPELLING = {
    "solver": "options=SolverOptions(solver)",
    "rtol": "options=SolverOptions(rtol=...)",
    "atol": "options=SolverOptions(atol=...)",
    "dt0": "options=SolverOptions(dt0=...)",
    "max_steps": "options=SolverOptions(max_steps=...)",
    "adjoint": "options=SolverOptions(adjoint=diffrax.ForwardMode() | diffrax.RecursiveCheckpointAdjoint())",
    "progress": "options=SolverOptions(progress_meter=diffrax.TextProgressMeter())",
    "fixed_step": "options=SolverOptions(stepsize_controller=diffrax.ConstantStepSize(), dt0=...)",
    "rope": "model=RigidGround(rope=ElasticRope() | InextensibleRope())",
}


def convert_legacy(
    model: AbstractModel | str, options: SolverOptions | None, old: dict
) -> tuple[AbstractModel, SolverOptions | None, dict[str, str]]:
    """`(model, options, moved)` from `simulate`'s earlier keywords in `old` (the solver block `solver, rtol,
    atol, dt0, max_steps, adjoint, progress, fixed_step` and `rope`) and the earlier model strings
    "elastic"/"rigid", built exactly as the earlier `simulate` built them; `moved` (old name -> new
    spelling) is for the one `DeprecationWarning`, which the caller gives once nothing can fail any more.
    `options` stays None where neither it nor a solver keyword is given.

    **Raises** `TypeError` for an unknown keyword, `ScenarioError` for an old keyword given with the object
    that replaces it, an unknown model or rope name, or a solver keyword the rigid model does not read.
    """
    old = dict(old)
    rope = old.pop("rope", None)
    unknown = sorted(set(old) - set(_LEGACY_SOLVER_KW))
    if unknown:
        raise TypeError(f"simulate() got unexpected keyword argument(s): {', '.join(unknown)}")
    moved = {k: _NEW_SPELLING[k] for k in old}
    if rope is not None:
        moved["rope"] = _NEW_SPELLING["rope"]
    if isinstance(model, str):
        moved["model"] = f"model={'RigidGround()' if model == 'rigid' else 'ElasticFoundation()'}"
    model = as_model(model, rope)
    if options is not None and old:
        raise ScenarioError(f"give either options or the keywords {', '.join(sorted(old))}, not both")
    if options is None and old:
        if isinstance(model, RigidGround):
            extra = set(old) - {"rtol", "atol", "max_steps"}
            if extra and any(old[k] not in (None, False, "reverse") for k in extra):
                raise ScenarioError("model='rigid' takes only t1, ts, n_save, rtol, atol, max_steps and rope")
            kw = {k: v for k, v in old.items() if k in ("rtol", "atol", "max_steps")}
            options = SolverOptions(diffrax.Tsit5(), **kw)  # for its default tolerances 1e-6, 1e-8
        else:
            options = SolverOptions(**old)
    return model, options, moved


def simulate(
    scenario: Scenario,
    times: TimesLike = None,
    model: AbstractModel | str = ElasticFoundation(),
    options: SolverOptions | None = None,
    *,
    throw: bool = True,
    **deprecated,
) -> Trajectory:
    """Simulate a lift from rest at t = 0 to the end time t1 [s] of `times`.

    Works under `jax.jit`, `jax.vmap` over any scenario leaf, `jax.grad` (the default adjoint) and
    `jax.jacfwd` (`SolverOptions(adjoint=diffrax.ForwardMode())`), for the elastic model. For derivatives
    over long spans pass `options=SolverOptions(diffrax.Tsit5())`: through the default Rosenbrock-W solver
    they are not reliable yet at high friction (see `RosenbrockW`).

    **Arguments**
    - `scenario`: a `Scenario` (see `load_scenario`).
    - `times`: the saved times, a `Times(t1, n, ts)`: end time t1 [s] (default `ts[-1]` if `ts` is given,
      else `scenario.t1`), `n` equally spaced times from 0 to t1 (default 501) or the saved times `ts` [s]
      (starting at 0, ending at t1). A number is t1 [s], a 1-D array is ts [s]. Default `Times()`.
    - `model`: `ElasticFoundation()` (paper §3, the default: one compiled, differentiable solve) or
      `RigidGround(rope=ElasticRope() | InextensibleRope())` (paper §2, the event-driven reference
      `simulate_rigid`: host-side phase loop, not differentiable or vmappable; it returns a
      `RigidTrajectory` with the same output names plus `impact_loss` and the phase log). The earlier
      strings "elastic" and "rigid" still work, with a `DeprecationWarning`.
    - `options`: `SolverOptions` (solver, step-size controller, adjoint, dt0, max_steps, progress meter).
      The rigid model reads only its tolerances and step budget.
    - `throw`: raise if the solve fails (max steps, non-finite state, or an energy balance that does not
      close: `SolveStatus.ENERGY_BALANCE`, the solver's success contradicted by the result); with False,
      read `Trajectory.status`.
    - `**deprecated`: the earlier keywords `t1`, `ts`, `n_save` (converted to `Times`: the same saved
      times), `solver`, `rtol`, `atol`, `dt0`, `max_steps`, `adjoint`, `progress`, `fixed_step` (converted
      to `SolverOptions` exactly as before; not together with `options`) and `rope` ("elastic" or
      "inextensible", rigid model only; converted to `RigidGround`) still work, with one
      `DeprecationWarning` naming the new spelling.

    **Returns** a `Trajectory`: for the rigid model its subclass `RigidTrajectory`, which adds `impact_loss`
    and the phase log.

    **Raises** `ScenarioError` for invalid input (before compiling), `Float64Error` without x64,
    and (with `throw=True`) an `EquinoxRuntimeError` naming the failure.
    """
    require_x64()
    times, moved_times = convert_legacy_times("simulate", times, deprecated)
    model, options, moved = convert_legacy(model, options, deprecated)
    moved = moved_times | moved
    if isinstance(model, RigidGround):
        if options is None:
            options = SolverOptions(diffrax.Tsit5())  # for its default tolerances 1e-6, 1e-8
        warn_moved("simulate", moved)
        rigid_options = RigidOptions(
            rtol=options.rtol,  # pyright: ignore[reportArgumentType]  # SolverOptions fills rtol/atol in
            atol=options.atol,  # pyright: ignore[reportArgumentType]  # SolverOptions fills rtol/atol in
            max_steps=options.max_steps,
        )
        return simulate_rigid(scenario, times, model, rigid_options)
    if not isinstance(scenario, Scenario):
        raise TypeError(f"scenario must be a jaxhoist.Scenario, got {type(scenario).__name__}")
    scenario.check()
    scenario = as_float64_leaves(scenario)
    if options is None:
        options = SolverOptions()
    _, ts = times.resolve(scenario, DEFAULT_N, jnp)
    warn_moved("simulate", moved)
    ts = jnp.asarray(ts, dtype=jnp.float64)
    with forward_mode_hint():  # jacfwd through the reverse adjoint: say to pass adjoint="forward"
        traj = _solve_jit(scenario.unlabelled(), ts, options)  # one program for any labels
    return _raise_on_failure(traj) if throw else traj
