"""Choices of numerics as objects: `SolverOptions` (which integrator, which step-size control, which adjoint,
how many steps).

Every choice is a real object (a diffrax solver, a diffrax step-size controller, a diffrax adjoint), the way
`diffrax.diffeqsolve` takes them.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ScenarioError

#: Default tolerances of the adaptive step-size control (relative, absolute in SI units of each state), for
#: the default Rosenbrock-W solver (order 3) and for any other solver (the higher-order explicit ones).
DEFAULT_TOLERANCES = {"RosenbrockW": (5e-4, 1e-5)}
DEFAULT_RTOL = 1e-6
DEFAULT_ATOL = 1e-8
#: Default (pcoeff, icoeff) of diffrax's PID controller where they differ from diffrax's own (0, 1: the
#: integral controller): a PI controller for the Rosenbrock-W solver.
DEFAULT_CONTROLLER_COEFFICIENTS = {"RosenbrockW": (0.3, 0.3)}


def default_tolerances(solver) -> tuple[float, float]:
    """(rtol, atol) used when a solver is given without tolerances: 5e-4, 1e-5 for the Rosenbrock-W
    solver (with its PI controller within 0.1 % of the rope tension and 0.1 mm of the mass centre of Tsit5
    at rtol 1e-8 over the tests' 2 s of paper-4.2, and within 0.1 cm of an rtol 1e-10 reference on the
    default scan over 25 s, docs/performance.md), 1e-6, 1e-8 otherwise."""
    return DEFAULT_TOLERANCES.get(type(solver).__name__, (DEFAULT_RTOL, DEFAULT_ATOL))


def default_controller_coefficients(solver) -> tuple[float, float]:
    """(pcoeff, icoeff) of the `diffrax.PIDController` used when a solver is given without a controller:
    for the Rosenbrock-W solver diffrax's PI coefficients pcoeff = icoeff = 0.3 (the integral controller
    oscillated between long and rejected steps where a corner sticks: half the steps rejected at
    ε = 1e-4 m/s, docs/performance.md "The time derivative"); diffrax's integral controller (0, 1)
    otherwise."""
    return DEFAULT_CONTROLLER_COEFFICIENTS.get(type(solver).__name__, (0.0, 1.0))


#: Default step budget of one solve.
DEFAULT_MAX_STEPS = 200_000


def _positive(name: str, v) -> float:
    v = float(v)
    if not (np.isfinite(v) and v > 0):
        raise ScenarioError(f"solver option {name} must be a positive number, got {v}")
    return v


class SolverOptions(eqx.Module):
    """Numerical settings of a solve. A change of the solver, the step-size controller (but for the tolerances
    below), the adjoint, `dt0` or `max_steps` compiles anew; `simulate` and `scan` pass the tolerances
    `rtol` and `atol` of a `PIDController` to their compiled programs as values (`traced_tolerances`), so
    that one program serves any tolerances, forward-mode derivatives included.

    - `solver`: a diffrax solver. Default (None): `jaxhoist.RosenbrockW()`, the linearly implicit solver that
      treats the model's stiff contact, rope and boom forces implicitly (`numerics.rosenbrock`); any diffrax
      solver works (e.g. `diffrax.Tsit5()`, explicit, for short non-stiff spans).
    - `stepsize_controller`: a diffrax step-size controller: `diffrax.PIDController(rtol, atol)` for error
      control (the default; with the default solver rtol 5e-4, atol 1e-5 and the PI coefficients
      pcoeff = icoeff = 0.3, with any other solver rtol 1e-6, atol 1e-8 and diffrax's integral controller) or
      `diffrax.ConstantStepSize()` for constant steps of `dt0` (no error control; every member of a vmapped
      batch takes the same steps).
    - `adjoint`: how derivatives are taken: `diffrax.RecursiveCheckpointAdjoint()` (default; `jax.grad`) or
      `diffrax.ForwardMode()` (`jax.jacfwd`/`jax.jvp`, cheaper for a few parameters). With the default
      solver, forward mode solves the derivatives under error control; `jax.grad` differentiates the steps
      and can be far off at the default tolerances (`RosenbrockW`): use it at tight tolerances. Reverse mode
      does not go through `ForwardMode`: `jax.grad` of a solve with it stops with an error of JAX's
      (an `AssertionError` from its transpose of the step-size control, which watches the derivatives).
    - `dt0`: first step [s] (None: chosen by the controller); the constant step with `ConstantStepSize`.
    - `max_steps`: the step budget; reaching it is reported as `SolveStatus.MAX_STEPS`.
    - `progress_meter`: a diffrax progress meter (default `diffrax.NoProgressMeter()`).

    - `rtol`, `atol`: the tolerances of the default `PIDController` (relative; absolute in SI units of each
      state); None: the solver's defaults above. Not together with `stepsize_controller`.

    **Raises** `ScenarioError` for a non-positive tolerance or step, a constant step without `dt0`, a step
    budget below 1 or an adjoint that is not a diffrax adjoint.
    """

    solver: diffrax.AbstractSolver
    stepsize_controller: diffrax.AbstractStepSizeController
    adjoint: diffrax.AbstractAdjoint
    progress_meter: diffrax.AbstractProgressMeter
    dt0: float | None = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)

    def __init__(
        self,
        solver: diffrax.AbstractSolver | None = None,
        stepsize_controller: diffrax.AbstractStepSizeController | None = None,
        adjoint: diffrax.AbstractAdjoint | None = None,
        *,
        dt0: float | None = None,
        max_steps: int = DEFAULT_MAX_STEPS,
        progress_meter: diffrax.AbstractProgressMeter | None = None,
        rtol: float | None = None,
        atol: float | None = None,
    ):
        if solver is None:
            from .rosenbrock import RosenbrockW

            solver = RosenbrockW()
        self.solver = solver
        if not isinstance(self.solver, diffrax.AbstractSolver):
            raise ScenarioError(f"solver must be a diffrax solver, got {solver!r}")
        if stepsize_controller is not None and (rtol is not None or atol is not None):
            raise ScenarioError("give either stepsize_controller or rtol/atol, not both")
        if stepsize_controller is None:
            d_rtol, d_atol = default_tolerances(self.solver)
            pcoeff, icoeff = default_controller_coefficients(self.solver)
            stepsize_controller = diffrax.PIDController(
                rtol=_positive("rtol", d_rtol if rtol is None else rtol),
                atol=_positive("atol", d_atol if atol is None else atol),
                pcoeff=pcoeff,
                icoeff=icoeff,
            )
        elif isinstance(stepsize_controller, diffrax.PIDController):
            _positive("rtol", stepsize_controller.rtol)
            _positive("atol", stepsize_controller.atol)
        self.stepsize_controller = stepsize_controller
        if adjoint is None:
            adjoint = diffrax.RecursiveCheckpointAdjoint()
        elif not isinstance(adjoint, diffrax.AbstractAdjoint):
            raise ScenarioError(
                "solver option adjoint must be a diffrax adjoint (diffrax.RecursiveCheckpointAdjoint() or "
                f"diffrax.ForwardMode()), got {adjoint!r}"
            )
        self.adjoint = adjoint
        self.progress_meter = diffrax.NoProgressMeter() if progress_meter is None else progress_meter
        if dt0 is not None:
            dt0 = _positive("dt0", dt0)
        self.dt0 = dt0
        if self.fixed_step and dt0 is None:
            raise ScenarioError("a constant step (diffrax.ConstantStepSize()) needs the step size dt0 [s]")
        if int(max_steps) < 1:
            raise ScenarioError(f"solver option max_steps must be >= 1, got {max_steps}")
        self.max_steps = int(max_steps)

    # Read-outs used by the scan records and the command line.
    @property
    def fixed_step(self) -> bool:
        """True for constant steps (`ConstantStepSize`)."""
        return isinstance(self.stepsize_controller, diffrax.ConstantStepSize)

    @property
    def rtol(self) -> float | None:
        """The controller's relative tolerance (None for constant steps)."""
        return getattr(self.stepsize_controller, "rtol", None)

    @property
    def atol(self) -> float | None:
        """The controller's absolute tolerance (None for constant steps)."""
        return getattr(self.stepsize_controller, "atol", None)

    @property
    def forward_mode(self) -> bool:
        """True if derivatives are taken in forward mode (`diffrax.ForwardMode`)."""
        return isinstance(self.adjoint, diffrax.ForwardMode)

    def traced_tolerances(self) -> SolverOptions:
        """These options with a `diffrax.PIDController`'s `rtol` and `atol` as float64 arrays (other
        controllers unchanged). `eqx.filter_jit` compiles Python floats into the program and traces arrays,
        so with these one compiled solve serves every tolerance; the steps and the results are bit for bit
        those of the floats (tests/test_reference_results.py)."""
        ctrl = self.stepsize_controller
        if not isinstance(ctrl, diffrax.PIDController):
            return self
        tols = tuple(jnp.asarray(x, dtype=jnp.float64) for x in (ctrl.rtol, ctrl.atol))
        ctrl = eqx.tree_at(lambda c: (c.rtol, c.atol), ctrl, tols)
        return eqx.tree_at(lambda o: o.stepsize_controller, self, ctrl)

    def replace(self, **changes) -> SolverOptions:
        """A copy with some fields changed (`eqx.tree_at` on the named fields)."""
        out = self
        for name, value in changes.items():
            out = eqx.tree_at(lambda o, n=name: getattr(o, n), out, value, is_leaf=lambda x: x is None)
        return out

    def describe(self) -> dict:
        """A JSON-ready summary (solver class, controller, tolerances, dt0, step budget, adjoint, and the
        solver's and controller's settings that differ from their defaults, e.g. the PI coefficients)."""
        return {
            "solver": type(self.solver).__name__,
            "stepsize_controller": type(self.stepsize_controller).__name__,
            "solver_settings": eqx.tree_pformat(self.solver),
            "controller_settings": eqx.tree_pformat(self.stepsize_controller),
            "rtol": self.rtol,
            "atol": self.atol,
            "dt0": self.dt0,
            "max_steps": self.max_steps,
            "fixed_step": self.fixed_step,
            "adjoint": type(self.adjoint).__name__,
        }
