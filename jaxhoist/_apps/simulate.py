"""`simulate`, the one entry point of both models: it dispatches on the model type to the elastic core
(`_numerics/solve.py`) or the rigid phase driver (`simulate_rigid`), so that neither imports the other."""

from __future__ import annotations

import diffrax

from .._errors import ScenarioError, require_x64
from .._numerics.options import SolverOptions
from .._numerics.rigid.options import RigidOptions
from .._numerics.rigid.solve import simulate_rigid
from .._numerics.solve import simulate_elastic
from .._numerics.times import TimesLike, as_times
from .._numerics.trajectory import Trajectory
from .._physics.elastic import AbstractModel, ElasticFoundation
from .._physics.params import Scenario
from .._physics.rigid.model import RigidGround


def simulate(
    scenario: Scenario,
    times: TimesLike = None,
    model: AbstractModel = ElasticFoundation(),
    options: SolverOptions | None = None,
    *,
    throw: bool = True,
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
      `RigidTrajectory` with the same output names plus `impact_loss` and the phase log).
    - `options`: `SolverOptions` (solver, step-size controller, adjoint, dt0, max_steps, progress meter).
      The rigid model reads only its tolerances and step budget.
    - `throw`: raise if the status of the elastic model's solve is not ok: the solver reached max steps or
      failed, the state became non-finite, or the solver reported success but the energy balance does not
      close (`SolveStatus.ENERGY_BALANCE`); with False, read `Trajectory.status`. The rigid model does not
      read it.

    **Returns** a `Trajectory`: for the rigid model its subclass `RigidTrajectory`, which adds `impact_loss`
    and the phase log.

    **Raises** `ScenarioError` for invalid input (before compiling), `Float64Error` without x64,
    and (with `throw=True`) an `EquinoxRuntimeError` naming the failure; the rigid model raises
    `RigidContactError` when it cannot continue, whatever `throw`.
    """
    require_x64()
    times = as_times(times)
    if not isinstance(model, AbstractModel):
        raise ScenarioError(f"model must be ElasticFoundation() or RigidGround(...), got {model!r}")
    if options is not None and not isinstance(options, SolverOptions):
        raise ScenarioError(f"options must be a jaxhoist.SolverOptions, got {type(options).__name__}")
    if isinstance(model, RigidGround):
        if options is None:
            options = SolverOptions(diffrax.Tsit5())  # for its default tolerances 1e-6, 1e-8
        if options.rtol is None or options.atol is None:
            raise ScenarioError(
                "model=RigidGround() reads only the tolerances (rtol, atol of a PIDController) and max_steps "
                f"of options; got the step-size controller {type(options.stepsize_controller).__name__}"
            )
        rigid_options = RigidOptions(
            rtol=options.rtol,  # pyright: ignore[reportArgumentType]  # SolverOptions fills rtol/atol in
            atol=options.atol,  # pyright: ignore[reportArgumentType]  # SolverOptions fills rtol/atol in
            max_steps=options.max_steps,
        )
        return simulate_rigid(scenario, times, model, rigid_options)
    return simulate_elastic(scenario, times, options, throw=throw)
