"""Forward-mode sensitivities through the Rosenbrock-W solver, solved as their own error-controlled ODE.

Differentiating the W steps themselves (what `jax.jvp` of `diffeqsolve` does) gives the *discrete* tangent:
the same steps applied to the variational equations ṡ = f_y s + f_θ, with W held fixed. The primal solution
is kept accurate by error control; the tangent is not, and in stick-slip the two part company. The stage
Jacobian f_y at a corner crossing the friction band |v| < ε has the slope μN/ε, while W, taken at the
step's start, may hold the sliding slope μN/|v|; one such step multiplies the tangent by ~hμN/(εm) while
the friction force itself saturates at μN and keeps the primal bounded. On paper-4.2 over 25 s the discrete
tangent reached |∂x/∂μ| ~ 1e125 m at μ = 0.55 (and, for Tsit5 at rtol 1e-8, 1e59 m at μ = 0.3), against
central differences of 1-10 m.

So here the tangent is integrated *with* the state, as one augmented system (y, s), s = ∂y/∂θ along one
direction θ̇ (Hairer, Nørsett & Wanner I, §I.14; the "staggered-direct" forward sensitivities of CVODES):

    ẏ = f(t, y, θ),    ṡ = f_y(t, y, θ) s + f_θ(t, y, θ) θ̇,    s(0) = ∂y0/∂θ θ̇,

by the same W-method with the same W for both blocks (one factorisation serves both: W approximates the
Jacobian of the variational block as well as of f), and with the step-size controller seeing the error of
s too: a step is accepted when max(‖e_y‖, w ‖e_s‖) ≤ 1 in the controller's scaled norm (its own rtol,
atol). The weight w = `RosenbrockW.tangent_weight` (default 0.1) lets a sensitivity carry 1/w times the
relative local error of the state; w = 1 controls both alike. Measured on paper-4.2, 25 s, default
tolerances, against central differences (h = 1e-4) of Tsit5 solves at rtol 1e-10 (`python
experiments/benchmarks/w_sensitivity.py`): see docs/performance.md.

`solve_forward` wraps the solve in `jax.custom_jvp`, so `jax.jvp`, `jax.jacfwd` and everything built on
them (`locate_bifurcation`) get these sensitivities. The values under differentiation are those of the
plain solve, bit for bit (the primal is solved as usual, the augmented system only for the tangent: a
tangent must not change the primal, and `jax.jacfwd` needs the primal to be the same for every direction).
Reverse mode (`jax.grad`) is not available on this path: use `adjoint=diffrax.RecursiveCheckpointAdjoint()`
(the default) for it.

With `joint=True` (`solve.solve_joint`, what `scan(derivatives=True)` differentiates) the primal under
`jax.jvp` is the augmented solve's own state instead: one solve gives the values and their sensitivities,
and the program holds no plain solve beside the augmented one. The values then agree with the plain solve's
to the solver's tolerance, not bit for bit (the step-size control also watches the sensitivities), and
depend on the direction, so such a solve is differentiated along one direction at a time (`jax.jvp`, or
`jax.vmap` of it over directions), never by `jax.jacfwd`.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero

from .._errors import SolveStatus
from .._physics.elastic import vector_field
from .._physics.equilibrium import initial_state
from .._physics.linearise import linearise as elastic_linearise
from .._physics.linearise import linearise_exact_slope
from .._physics.params import Scenario
from .callback_free import checks_as_nan
from .options import SolverOptions
from .rosenbrock import RosenbrockW, time_derivative_of


class _TangentLinearisation(eqx.Module):
    """The W of the augmented system (y, s): the state's W on both blocks, factorised once. With `many`,
    s holds several tangents along a leading axis (`identify`'s p parameter directions), all solved with the
    same factors."""

    lin: eqx.Module
    many: bool = eqx.field(static=True, default=False)

    def factor(self, hg):
        return self.lin.factor(hg)  # pyright: ignore[reportAttributeAccessIssue]  # a Linearisation

    def solve(self, factors, r, hg):
        solve = self.lin.solve  # pyright: ignore[reportAttributeAccessIssue]  # a Linearisation
        if self.many:
            return (solve(factors, r[0], hg), jax.vmap(lambda ri: solve(factors, ri, hg))(r[1]))
        return (solve(factors, r[0], hg), solve(factors, r[1], hg))


@dataclasses.dataclass(frozen=True)
class _Augmented:
    """Static helpers of the augmented system for a solver's `linearise` and `quadrature` (hashable, so
    that they can be static fields of `RosenbrockW`)."""

    linearise: Callable
    quadrature: Callable | None
    many: bool = False  # s holds several tangents along a leading axis (`_TangentLinearisation`)

    def lin(self, t, y, args):
        scenario_args = args[0]
        return _TangentLinearisation(self.linearise(t, y[0], scenario_args), self.many)

    def quad(self, y):
        assert self.quadrature is not None
        return (*self.quadrature(y[0]), *self.quadrature(y[1]))

    @staticmethod
    def time_column(f, t, y, args):
        """∂f/∂t of the state's block and zero for the tangents' (their time column would be the time
        derivative of the variational equations, a second derivative of the vector field; W-methods keep
        their order with any column, `rosenbrock.w_step`)."""
        f_t = time_derivative_of(lambda tt, yy, aa: f(tt, yy, aa)[0], t, y, args)
        return (f_t, jax.tree_util.tree_map(jnp.zeros_like, y[1]))


def uses_tangent_solve(options: SolverOptions) -> bool:
    """Whether forward-mode derivatives of a solve with `options` take the augmented route (the
    Rosenbrock-W solver in forward mode)."""
    return isinstance(options.solver, RosenbrockW) and options.forward_mode


def tangent_weighted_controller(controller, weight: float, many: bool = False):
    """`controller` with the error norm of (e_y, e_s) max(‖e_y‖, weight ‖e_s‖) if it is a PIDController;
    others (constant steps) unchanged. With `many` (tangents along a leading axis of s), ‖e_s‖ is the largest
    of the tangents' norms: a step passes when each tangent would pass on its own."""
    if not isinstance(controller, diffrax.PIDController):
        return controller
    norm = controller.norm
    if many:
        return dataclasses.replace(
            controller, norm=lambda e: jnp.maximum(norm(e[0]), weight * jnp.max(jax.vmap(norm)(e[1])))
        )
    return dataclasses.replace(controller, norm=lambda e: jnp.maximum(norm(e[0]), weight * norm(e[1])))


def augmented_solver(solver: RosenbrockW, many: bool = False) -> RosenbrockW:
    """The W-method of the augmented system (y, s) (or, with `many`, (y, S) with several tangents along a
    leading axis of S): `solver`'s tableau and tangent weight, its W on every block. Its `args` are
    `(scenario_args, anything)`: the linearisation reads `args[0]` = (scenario, derived constants).

    With the elastic model's default linearisation, W here has the friction law's exact slope
    (`linearise_exact_slope`): the band-entry slope of the state's solve made the sensitivities' error
    estimate misjudge over-damped steps (up to 15 % off central differences instead of 1.9 %). Any other
    `solver.linearise` is used as given."""
    lin = linearise_exact_slope if solver.linearise is elastic_linearise else solver.linearise
    aug = _Augmented(lin, solver.quadrature, many)
    return RosenbrockW(
        linearise=aug.lin,
        quadrature=None if solver.quadrature is None else aug.quad,
        tableau=solver.tableau,
        tangent_weight=solver.tangent_weight,
        time_derivative=solver.time_derivative,
        time_column=aug.time_column if solver.time_column is None else solver.time_column,
        stage_loop=True,
    )


def solve_forward(
    solve_plain: Callable, controller: Callable, outputs: Callable, status_of: Callable, joint: bool = False
):
    """`solve(scenario, ts, options)` whose forward-mode derivative is the augmented solve (module
    docstring). The arguments are the plain core and its helpers from `solve.py` (passed in, so that this
    module does not import it back): `solve_plain(scenario, ts, options) -> Trajectory`,
    `controller(options, ts)`, `outputs(ts, ys, scenario, c, status, stats)`, `status_of(result, y1)`.
    `joint`: under `jax.jvp` the primal is the augmented solve's, not the plain solve's (module
    docstring)."""

    def solve(scenario: Scenario, ts, options: SolverOptions):
        dyn, static = eqx.partition(scenario, eqx.is_inexact_array)
        # the options' arrays (the tolerances, where `SolverOptions.traced_tolerances` made them values of
        # the program) are inputs of the rule like the scenario's, never differentiated: a rule that closed
        # over them would close over the compiled program's tracers, which JAX refuses
        o_dyn, o_static = eqx.partition(options, eqx.is_array)

        @jax.custom_jvp
        def run(dyn, ts, o_dyn):
            return solve_plain(eqx.combine(dyn, static), ts, eqx.combine(o_dyn, o_static))

        # symbolic zeros: the leaves that are not differentiated (every scenario leaf but the swept ones,
        # and the saved times) stay constants of the tangent solve instead of carrying zero tangents
        # `checks_as_nan`: JAX traces this rule when it differentiates the traced core, which for
        # `jax.jvp` of the compiled core happens after the core's own `callback_free` block has ended
        @functools.partial(run.defjvp, symbolic_zeros=True)
        def run_jvp(primals, tangents):
            dyn, ts, o_dyn = primals
            ddyn, dts, _ = tangents  # the options' tangent: zero (tolerances are settings, not parameters)
            opts = eqx.combine(o_dyn, o_static)

            def augmented():
                return _tangent_solve(static, opts, dyn, ts, ddyn, dts, controller, outputs, status_of)

            with checks_as_nan():
                if joint:
                    return augmented()
                primal = solve_plain(eqx.combine(dyn, static), ts, opts)
                return primal, augmented()[1]

        return run(dyn, ts, o_dyn)

    return solve


def _is_zero(x) -> bool:
    return isinstance(x, SymbolicZero)


def _tangent_solve(static, options, dyn, ts, ddyn, dts, controller, outputs, status_of):
    """The augmented solve along (`ddyn`, `dts`), whose leaves may be `SymbolicZero`: those are held fixed
    (no tangent is traced for them), the others differentiated. **Returns** `(primal, tangent)`: the
    `Trajectory` of the augmented solve's own state and its tangent."""
    solver = options.solver
    assert isinstance(solver, RosenbrockW)
    moving = jax.tree_util.tree_map(lambda x: not _is_zero(x), ddyn, is_leaf=_is_zero)
    ddyn = eqx.filter(ddyn, moving, is_leaf=_is_zero)

    def split(d):  # (the differentiated leaves, the fixed ones)
        return eqx.partition(d, moving)

    def init(d_mov):
        return initial_state(eqx.combine(d_mov, split(dyn)[1], static))

    (y0, c), (dy0, dc) = jax.jvp(init, (split(dyn)[0],), (ddyn,))

    def field(t, y, args):
        (d, cc), (dd, dcc) = args
        ys, s = y
        d_mov, d_fix = split(d)

        def f(yy, d_, c_):
            return vector_field(t, yy, (eqx.combine(d_, d_fix, static), c_))

        return jax.jvp(f, (ys, d_mov, cc), (s, dd, dcc))

    aug_solver = augmented_solver(solver)
    sc = eqx.combine(dyn, static)
    weighted = tangent_weighted_controller(options.stepsize_controller, solver.tangent_weight)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        aug_solver,
        t0=ts[0] * 0.0,
        t1=ts[-1],
        dt0=options.dt0,
        y0=(y0, dy0),
        args=((dyn, c), (ddyn, dc)),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=controller(options.replace(stepsize_controller=weighted), ts),
        max_steps=options.max_steps,
        progress_meter=options.progress_meter,
        throw=False,
    )
    ys, ss = sol.ys  # pyright: ignore[reportGeneralTypeIssues]  # the saved (y, s) pair
    if not _is_zero(dts):  # a moved saved time t_k moves the saved state by f(t_k, y_k) dt_k
        rates = jax.vmap(lambda t, y: vector_field(t, y, (sc, c)))(ts, ys)
        ss = jax.tree_util.tree_map(lambda s, r: s + r * dts.reshape((-1,) + (1,) * (r.ndim - 1)), ss, rates)
    y1 = jax.tree_util.tree_map(lambda x: x[-1], ys)
    status, stats = status_of(sol.result, y1), sol.stats

    # a sensitivity solve that failed gives NaN sensitivities (a scan marks them), never silently wrong ones
    ok = status == SolveStatus.OK
    ss = jax.tree_util.tree_map(lambda s: jnp.where(ok, s, jnp.nan), ss)

    d_mov, d_fix = split(dyn)

    def out(ys_, d_, c_, ts_=ts):
        return outputs(ts_, ys_, eqx.combine(d_, d_fix, static), c_, status, stats)

    primals, tangents = (ys, d_mov, c), (ss, ddyn, dc)
    if not _is_zero(dts):
        primals, tangents = (*primals, ts), (*tangents, dts)
    return jax.jvp(out, primals, tangents)
