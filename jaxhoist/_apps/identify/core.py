"""The compiled core of `identify`: the model with its forward sensitivities, the residual function with a
one-pass Jacobian (`jax.custom_jvp`), the Levenberg-Marquardt run as compiled pieces (its start, one step)
in a loop on the host, and the host side of its progress reports. No piece holds a host callback; the pieces
are stored whole in the compilation cache folder (`compile_cache.program`), and a later process loads them
without tracing the model."""

from __future__ import annotations

import dataclasses
import math
import time
import typing
from collections.abc import Callable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from equinox.internal import ω
from optimistix._misc import (
    OutAsArray,
    cauchy_termination,
    filter_cond,
    inexact_asarray,
    tree_allfinite,
    tree_where,
)
from optimistix._solver.gauss_newton import _GaussNewtonState, _make_f_info

from ..._errors import SolveStatus
from ..._numerics.callback_free import callback_free
from ..._numerics.compile_cache import program
from ..._numerics.options import SolverOptions
from ..._numerics.rosenbrock import RosenbrockW
from ..._numerics.sensitivity import augmented_solver, tangent_weighted_controller
from ..._numerics.solve import outputs, solve, step_size_controller
from ..._physics.elastic import vector_field
from ..._physics.equilibrium import initial_state
from ..._physics.params import Scenario
from ..._physics.paths import set_leaf
from .parameters import to_theta

_PENALTY = 1e6  # whitened residual entry used when a trial solve fails: LM rejects such a step
_VERBOSE = False


class FitReporter:
    """Host side of the fit's progress reports: `Core` calls it after every Levenberg-Marquardt evaluation
    (one per step, accepted or rejected) with the point z, the cost there and the solve's (status, steps),
    and it hands `progress` one dict per evaluation (see `identify`'s `progress`)."""

    def __init__(self, progress, start: int, n_starts: int, t0: float):
        self.progress, self.start, self.n_starts, self.t0 = progress, start, n_starts, t0
        self.n, self.best_cost, self.best_z, self.last_z = 0, math.inf, None, None

    def __call__(self, z, cost, info) -> None:
        z = np.array(z, dtype=np.float64)
        if self.last_z is not None and np.array_equal(z, self.last_z):
            return  # the same point evaluated again: one report
        self.last_z = z
        self.n += 1
        cost = float(cost)
        step = 0.0 if self.best_z is None else float(np.linalg.norm(z - self.best_z))
        improved = bool(np.isfinite(cost) and cost < self.best_cost)
        if improved:
            self.best_cost, self.best_z = cost, z
        elif self.best_z is None:
            self.best_z = z
        self.progress(
            dict(
                start=self.start,
                n_starts=self.n_starts,
                iteration=self.n,
                cost=cost,
                best_cost=self.best_cost,
                improved=improved,
                step=step,
                solve_ok=int(info[0]) == SolveStatus.OK,
                solver_steps=int(info[1]),
                elapsed=time.perf_counter() - self.t0,
            )
        )


# ------------------------------------------------------------------------------------- the core


@dataclasses.dataclass(frozen=True)
class Config:
    """The static structure of one identification problem (a change recompiles the core)."""

    params: tuple[tuple[str, int | None, tuple[int, ...], str], ...]  # (path, index, shape, kind)
    signals: tuple[tuple[str, tuple[int, ...]], ...]  # (Trajectory field, index)
    drop_first: bool  # the solver's ts has t = 0 prepended to the measured times
    options: SolverOptions
    max_iterations: int
    sensitivity: str = "equations"  # "equations" | "solver", see `_model_and_jacobian`


def _scenario_at(cfg: Config, scenario: Scenario, tr, z):
    i = 0
    for (path, index, shape, kind), (ref, lo, hi, scale) in zip(cfg.params, tr, strict=True):
        n = int(np.prod(shape, dtype=int))
        theta = to_theta(kind, z[i : i + n].reshape(shape), ref, lo, hi, scale)
        i += n
        scenario = set_leaf(scenario, path, index, theta)
    return scenario


def _signals(cfg: Config, traj):
    m = jnp.stack([getattr(traj, f)[(slice(None), *idx)] for f, idx in cfg.signals])
    return m[:, 1:] if cfg.drop_first else m


def model(cfg: Config, z, args):
    """Whitened residuals (model - data) / σ, flattened signal-major, and the solve's status and steps."""
    scenario, tr, data, sigma, ts = args
    traj = solve(_scenario_at(cfg, scenario, tr, z), ts, cfg.options)
    return ((_signals(cfg, traj) - data) / sigma).ravel(), traj.status, traj.num_accepted_steps


@callback_free  # diffrax's checks of `ts` (already checked on the host) return NaN instead of calling back
def _sensitivity_solve(cfg: Config, z, args):
    """Model signals and their derivatives d(signal)/dz from the forward sensitivity equations.

    The state y and its p sensitivities S_i = dy/dz_i are integrated together as one ODE,
    dy/dt = f(t, y, θ(z)), dS_i/dt = ∂f/∂y S_i + ∂f/∂z_i, with the step-size controller watching the error
    of both (the norm runs over the whole augmented state). With the Rosenbrock-W solver one W serves the
    state and every S_i (factorised once per step) and the norm is max(‖e_y‖, w max_i ‖e_Si‖), w =
    `RosenbrockW.tangent_weight`, as in `numerics.sensitivity` for one direction.

    Differentiating the solver's own steps instead (`jax.jacfwd` through `diffrax.ForwardMode`) leaves the
    tangents without error control; on paper-4.2 the explicit solver then runs at its stability limit for the
    stiff friction/contact modes and the tangents can blow up by many orders of magnitude while the state
    stays accurate.

    **Returns** `(m, dm, status, steps)`: signals (n_sig, n_t), derivatives (p, n_sig, n_t), a `SolveStatus`
    code and the accepted steps.
    """

    scenario0, tr, _, _, ts = args
    p = z.shape[0]
    eye = jnp.eye(p, dtype=z.dtype)
    opt = cfg.options

    def scen(zz):
        return _scenario_at(cfg, scenario0, tr, zz)

    (y0, c), init_lin = jax.linearize(lambda zz: initial_state(scen(zz)), z)
    Y0, dC = jax.vmap(init_lin)(eye)  # tangents of the initial state and of the derived constants

    def rhs(t, state, a):
        zz, cc, dcc = a
        y, Y = state
        ydot, lin = jax.linearize(lambda y_, z_, c_: vector_field(t, y_, (scen(z_), c_)), y, zz, cc)
        return ydot, jax.vmap(lin)(Y, eye, dcc)

    if isinstance(opt.solver, RosenbrockW):
        # W on every block, factorised once per step for the state and its p sensitivities; the step-size
        # control as in `numerics.sensitivity` (each sensitivity's error weighted by `tangent_weight`), and a
        # step landing on every saved time as in `numerics.solve`
        solver = augmented_solver(opt.solver, many=True)
        args = ((scen(z), c), (z, c, dC))
        term = diffrax.ODETerm(lambda t, state, a: rhs(t, state, a[1]))
        weighted = tangent_weighted_controller(opt.stepsize_controller, opt.solver.tangent_weight, many=True)
        controller = step_size_controller(opt.replace(stepsize_controller=weighted), ts)
    else:
        solver, args, term, controller = opt.solver, (z, c, dC), diffrax.ODETerm(rhs), opt.stepsize_controller
    sol = diffrax.diffeqsolve(
        term,
        solver,
        t0=ts[0] * 0.0,
        t1=ts[-1],
        dt0=opt.dt0,
        y0=(y0, Y0),
        args=args,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=controller,
        max_steps=opt.max_steps,
        adjoint=diffrax.ForwardMode(),
        throw=False,
    )
    ys, Ys = sol.ys  # pyright: ignore[reportGeneralTypeIssues]  # sol.ys is the saved (state, tangent) pair with SaveAt(ts=...)
    y1 = jax.tree_util.tree_map(lambda x: x[-1], ys)
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves((y1, Ys))]))
    status = jnp.where(
        sol.result == diffrax.RESULTS.successful,
        jnp.where(finite, SolveStatus.OK, SolveStatus.NONFINITE),
        jnp.where(
            sol.result == diffrax.RESULTS.max_steps_reached, SolveStatus.MAX_STEPS, SolveStatus.SOLVER_FAILED
        ),
    ).astype(jnp.int32)
    steps = sol.stats["num_accepted_steps"]
    stats = {"num_accepted_steps": steps, "num_rejected_steps": sol.stats["num_rejected_steps"]}

    def signals_of(ys_, z_, c_):
        return _signals(cfg, outputs(ts, ys_, scen(z_), c_, status, stats))

    m, out_lin = jax.linearize(signals_of, ys, z, c)
    Ys_p = jax.tree_util.tree_map(lambda a: jnp.moveaxis(a, 1, 0), Ys)  # (p, n_t, ...)
    dm = jax.vmap(out_lin)(Ys_p, eye, dC)
    return m, dm, status, steps


def _model_and_jacobian(cfg: Config, z, args):
    """Whitened residuals r (n,), their Jacobian dr/dz (n, p), status and solver steps.

    `cfg.sensitivity = "equations"` (default, any solver): the forward sensitivity equations with error
    control (`_sensitivity_solve`). `"solver"` (kept for comparison): `jax.jacfwd` through the solve in
    forward mode. With an explicit solver that differentiates the solver's own steps, without error control
    on the tangents (see `_sensitivity_solve`). With the Rosenbrock-W solver it is error-controlled (the
    solve's `jax.custom_jvp`, `numerics.sensitivity`, integrates each direction's tangent beside the state),
    but it solves the state p + 1 times and factorises W for each direction: on paper-4.2 (3 s, five
    parameters) its fit took 2.1x the time of `"equations"` and its compile 2.8x."""
    _, _, data, sigma, _ = args
    if cfg.sensitivity == "solver":

        def f(zz):
            r, status, steps = model(cfg, zz, args)
            return r, (r, status, steps)

        J, (r, status, steps) = jax.jacfwd(f, has_aux=True)(z)
        return r, J, status, steps
    m, dm, status, steps = _sensitivity_solve(cfg, z, args)
    r = ((m - data) / sigma).ravel()
    J = (dm / sigma[None]).reshape(dm.shape[0], -1).T
    return r, J, status, steps


# The model and the model with its Jacobian as nested programs of the fit's pieces: JAX keeps each one's
# trace (per problem and process), so the step, which traces the residual function and its Jacobian more
# than once (`lm_step`, `_problem`), traces the model once. XLA inlines nested programs: the compiled code,
# and the fit's bits, are those of the plain calls.
model_nested = eqx.filter_jit(model)
_model_and_jacobian_nested = eqx.filter_jit(_model_and_jacobian)


def _residual_fn(cfg: Config):
    """`fn(z, args) -> (r, info)` for optimistix, info = (status, solver steps). Its JVP computes the full
    forward-mode Jacobian once (p tangents carried by one solve) and applies it as a matrix."""

    def guard(r, status, J=None):
        ok = (status == SolveStatus.OK) & jnp.all(jnp.isfinite(r))
        if J is not None:
            ok = ok & jnp.all(jnp.isfinite(J))
            J = jnp.where(ok, J, 0.0)
        return jnp.where(ok, r, _PENALTY), J

    @jax.custom_jvp
    def res(z, args):
        r, status, steps = model_nested(cfg, z, args)
        r, _ = guard(r, status)
        return r, jnp.stack([status, steps]).astype(jnp.float64)

    @res.defjvp
    def res_jvp(primals, tangents):
        # The data and scenario in `args` are constants of the fit: their tangents are ignored.
        (z, args), (dz, _) = primals, tangents

        r, J, status, steps = _model_and_jacobian_nested(cfg, z, args)
        if _VERBOSE:
            jax.debug.print(
                "  z = {z}: status {s}, {n} solver steps, cost {c}",
                z=z,
                s=status,
                n=steps,
                c=0.5 * jnp.sum(r**2),
            )
        r, J = guard(r, status, J)
        info = jnp.stack([status, steps]).astype(jnp.float64)
        return (r, info), (J @ dz, jnp.zeros_like(info))

    def fn(z, args):
        return res(z, args)

    return fn


# no_type_check: the tests' jaxtyping hook would check the inherited __init__ (rtol: float), which the
# compiled pieces call with traced tolerances (as they called optimistix's class, which the hook leaves alone)
@typing.no_type_check
class _LevenbergMarquardt(optx.LevenbergMarquardt):
    """optimistix's Levenberg-Marquardt that also stops when, after a rejected step, the next trial step is
    below the termination's resolution in z: ‖Δz / (atol + rtol |z|)‖ < 1, the Cauchy test's y part.

    optimistix tests termination on accepted steps only. Near the minimum the residuals' own noise (the
    solver's tolerance: the Rosenbrock-W default's rtol 5e-4) makes every further step fail the ratio test,
    and the trust region then shrinks through ever smaller rejected trial points until the step is zero:
    25 of 35 evaluations in docs/cli.md's identify example. A point within the requested resolution of the
    last accepted one cannot be told from it, so the fit stops there, with the last accepted z."""

    def terminate(self, fn, y, args, options, state, tags):
        done, result = super().terminate(fn, y, args, options, state, tags)
        step = jax.tree_util.tree_map(lambda a, b: a - b, state.y_eval, y)
        scale = jax.tree_util.tree_map(lambda a: self.atol + self.rtol * jnp.abs(a), y)
        below = self.norm(jax.tree_util.tree_map(lambda d, s_: jnp.abs(d) / s_, step, scale)) < 1
        return done | ((state.num_steps_since_acceptance > 0) & below), result

    def step_and_evaluation(self, fn, y, args, options, state, tags):
        """`step` that also returns the evaluation it made, `(z, aux)`: the point where `fn` was evaluated
        (`state.y_eval`) and its auxiliary output, which `step` keeps only for an accepted step.

        Adapted from optimistix's `AbstractGaussNewton.step` (optimistix 0.1.0, Apache License 2.0, by
        Patrick Kidger and contributors): its body without the `verbose` log, returning the evaluation too.
        It uses optimistix's private names, so an optimistix upgrade can break it: the pin in pyproject.toml
        and `tests/test_identify.py` (the host-driven loop takes optimistix's own iterates) guard that."""
        jac = options.get("jac", "fwd")
        f_eval_info, aux_eval = _make_f_info(fn, state.y_eval, args, tags, jac)
        # the Jacobian operator's static part (a jaxpr, compared by identity) is the state's, as in optimistix
        dynamic = eqx.filter(f_eval_info.jac, eqx.is_array)
        static = eqx.filter(state.f_info.jac, eqx.is_array, inverse=True)
        f_eval_info = eqx.tree_at(lambda f: f.jac, f_eval_info, eqx.combine(dynamic, static))

        step_size, accept, search_result, search_state = self.search.step(
            state.first_step, y, state.y_eval, state.f_info, f_eval_info, state.search_state
        )
        num_steps = state.num_steps + 1
        num_accepted_steps = state.num_accepted_steps + jnp.where(accept, 1, 0)
        num_steps_since_acceptance = jnp.where(accept, 0, state.num_steps_since_acceptance + 1)

        def accepted(descent_state):
            descent_state = self.descent.query(state.y_eval, f_eval_info, descent_state)
            y_diff = (state.y_eval**ω - y**ω).ω
            f_diff = (f_eval_info.residual**ω - state.f_info.residual**ω).ω
            terminate = cauchy_termination(
                self.rtol, self.atol, self.norm, state.y_eval, y_diff, f_eval_info.residual, f_diff
            )
            return state.y_eval, f_eval_info, aux_eval, descent_state, terminate

        def rejected(descent_state):
            return y, state.f_info, state.aux, descent_state, jnp.array(False)

        y_new, f_info, aux, descent_state, terminate = filter_cond(
            accept, accepted, rejected, state.descent_state
        )
        y_descent, descent_result = self.descent.step(step_size, descent_state)
        y_eval = (y_new**ω + y_descent**ω).ω
        result = optx.RESULTS.where(search_result == optx.RESULTS.successful, descent_result, search_result)
        prev_aux = tree_where(state.first_step, aux, state.aux)
        new_state = _GaussNewtonState(
            first_step=jnp.array(False),
            y_eval=y_eval,
            search_state=search_state,
            f_info=f_info,
            aux=aux,
            descent_state=descent_state,
            terminate=terminate,
            result=result,
            num_steps=num_steps,
            num_accepted_steps=num_accepted_steps,
            num_steps_since_acceptance=num_steps_since_acceptance,
        )
        return y_new, new_state, prev_aux, (state.y_eval, aux_eval)


# ------------------------------------------------------------------- the Levenberg-Marquardt pieces
#
# `optimistix.least_squares(fn, solver, z0, args, has_aux=True, max_steps=cfg.max_iterations, throw=False,
# options={"jac": "fwd"})` runs `solver.init`, then `solver.step` and `terminate` in a while loop, then
# `postprocess` (optimistix's `_iterate`), in one program. Here the loop runs on the host over two compiled
# pieces, `lm_init` and `lm_step` (one step and its termination test), which hand on the loop's carry
# (z, steps taken, the array leaves of the solver state, aux, terminate, result): arrays only, so that both
# pieces are keyed by their inputs' structure and the residual function (`Residuals`, a dataclass of the
# problem's `Config`) and stored whole (`compile_cache.program`), and a later process loads them without
# tracing the model. Each piece builds the residual function and the solver state's static part itself
# (`_problem`). Neither holds a host callback; the host reports progress between steps.

_OPTIONS = {"jac": "fwd"}
_TAGS: frozenset = frozenset()


@dataclasses.dataclass(frozen=True)
class Residuals:
    """The fit's residual function of one problem, `fn(z, args) -> (r, info)` (`_residual_fn(cfg)`), as a
    value: equal problems give equal values, so the compiled pieces are keyed by it."""

    cfg: Config

    def __call__(self, z, args):
        return _residual_fn(self.cfg)(z, args)


def _solver(lm_tol):
    return _LevenbergMarquardt(rtol=lm_tol[0], atol=lm_tol[1])  # pyright: ignore[reportCallIssue]


def _problem(residual_fn, y, args, lm_tol, scale):
    """What `least_squares` builds before iterating: the residual function `residual_fn(z, args) -> (r,
    info)` times `scale`, with its aux info and the cost 0.5 Σ r² of the unscaled r, closure-converted at
    `y`; the solver and its first state. **Returns** `(fn, solver, state, aux_struct)`."""

    def residuals(z, a):
        r, info = residual_fn(z, a)
        return r * scale, jnp.concatenate([info, (0.5 * jnp.sum(r**2))[None]])

    fn = eqx.filter_closure_convert(OutAsArray(residuals), y, args)
    f_struct, aux_struct = fn.out_struct  # pyright: ignore[reportFunctionMemberAccess]
    solver = _solver(lm_tol)
    state = solver.init(fn, y, args, _OPTIONS, f_struct, aux_struct, _TAGS)
    return fn, solver, state, aux_struct


def _terminate_and_result(solver, fn, y, args, state):
    done, result = solver.terminate(fn, y, args, _OPTIONS, state, _TAGS)
    return done, optx.RESULTS.where(tree_allfinite(y), result, optx.RESULTS.nonfinite)


def _outcome(solver, fn, args, state, carry, scale):
    """Whether the loop goes on (the step budget aside: the host counts it), and what `least_squares` would
    return if it stopped here: `(value, r, J, info, steps, accepted steps, codes)`, r and J of the unscaled
    residuals at the value, info the solve's (status, steps) there, codes (converged, reached
    max_iterations; the latter read only when the host stops at the budget). `state` is the carry's."""
    y, num_steps, _, aux, terminate, result = carry
    successful = result == optx.RESULTS.successful
    go_on = jnp.invert(terminate) & successful
    result = optx.RESULTS.where(
        successful & jnp.invert(terminate), optx.RESULTS.nonlinear_max_steps_reached, result
    )
    value, aux, _ = solver.postprocess(fn, y, aux, args, _OPTIONS, state, _TAGS, result)
    f_info = state.f_info
    J = f_info.jac.as_matrix() / scale  # J @ e_i through the custom JVP: no new solve
    codes = jnp.stack([result == optx.RESULTS.successful, result == optx.RESULTS.nonlinear_max_steps_reached])
    return go_on, (value, f_info.residual / scale, J, aux[:2], num_steps, state.num_accepted_steps, codes)


def lm_init(residual_fn, z0, args, lm_tol, scale):
    """The loop's first carry and its `_outcome`, for the residual function `residual_fn(z, args) -> (r,
    info)` (`Residuals`) from `z0`. **Returns** `(carry, outcome)`."""
    y0 = inexact_asarray(z0)
    fn, solver, state, aux_struct = _problem(residual_fn, y0, args, lm_tol, scale)
    terminate, result = _terminate_and_result(solver, fn, y0, args, state)
    aux = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), aux_struct)
    leaves = jax.tree_util.tree_leaves(eqx.filter(state, eqx.is_array))
    carry = (y0, jnp.array(0), leaves, aux, terminate, result)
    return carry, _outcome(solver, fn, args, state, carry, scale)


def lm_step(residual_fn, carry, args, lm_tol, scale):
    """One Levenberg-Marquardt step (one evaluation of the residuals and their Jacobian) and its
    termination test. **Returns** the next carry, its `_outcome` and the evaluation `(z, [status, solver
    steps, cost])`."""
    y, num_steps, leaves, _, _, _ = carry
    fn, solver, first, _ = _problem(residual_fn, y, args, lm_tol, scale)
    dynamic, static = eqx.partition(first, eqx.is_array)
    like = jax.tree_util.tree_leaves(dynamic)
    if [(x.shape, x.dtype) for x in leaves] != [(x.shape, x.dtype) for x in like]:
        raise TypeError("identify: the carried solver state does not match the state the step builds")
    state = eqx.combine(jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(dynamic), leaves), static)
    y_new, state, aux, evaluation = solver.step_and_evaluation(fn, y, args, _OPTIONS, state, _TAGS)
    terminate, result = _terminate_and_result(solver, fn, y, args, state)  # optimistix tests the old y
    dynamic, new_static = eqx.partition(state, eqx.is_array)
    assert eqx.tree_equal(static, new_static) is True
    carry = (y_new, num_steps + 1, jax.tree_util.tree_leaves(dynamic), aux, terminate, result)
    return carry, _outcome(solver, fn, args, state, carry, scale), evaluation


class Core:
    """The fit's compiled pieces for one problem structure, and the host loop over them."""

    def __init__(self, residual_fn, max_iterations: int, init, step):
        self.residual_fn, self.max_iterations = residual_fn, max_iterations
        self._init, self._step = init, step

    def __call__(self, z0, args, lm_tol, scale, report: Callable | None = None):
        """Levenberg-Marquardt on the residuals multiplied by `scale` from `z0`, with the termination
        tolerances `lm_tol` = [rtol, atol], at most `max_iterations` steps; `report(z, cost, info)` (if
        given) after every evaluation, on the host. The tolerances and the scale are arguments of the
        compiled pieces (not static), so changing them does not recompile; with tolerances of 1e300 the run
        stops after the first evaluation, which `identify` uses to probe the Jacobian at the start.

        optimistix's LM starts with the damping λ = 1 (and changes it by the trust-region ratio test);
        `identify` chooses `scale` so that λ = 1 equals the largest diagonal entry of JᵀJ at the start
        (Marquardt's τ = 1) instead of a nearly undamped Gauss-Newton step, which on paper-4.2 jumps k and h
        by factors of 10³ into stiff, expensive regions.

        **Returns** `(z, r, J, info, iterations, accepted steps, codes)` as numpy arrays: the estimate, the
        unscaled residuals (n,) and Jacobian dr/dz (n, p) there, info = (solve status, solver steps) there,
        codes = (converged, reached max_iterations)."""
        carry, (go_on, out) = self._init(self.residual_fn, z0, args, lm_tol, scale)
        steps = 0
        while bool(go_on) and steps < self.max_iterations:
            carry, (go_on, out), (z, info) = self._step(self.residual_fn, carry, args, lm_tol, scale)
            steps += 1
            if report is not None:
                info = np.asarray(info)
                report(np.asarray(z), info[2], info[:2])
        return tuple(np.asarray(x) for x in out)


def compiled_core(cfg: Config, z0, args, lm_tol, scale) -> Core:
    """The fit's pieces compiled ahead of time (so compile and fit are timed apart), cached per structure
    in this process and, where the compilation cache is on, stored whole (`compile_cache.program`): other
    tolerances, scales, starts, data values and step budgets reuse them."""
    fn = Residuals(dataclasses.replace(cfg, max_iterations=0))  # the host counts the steps
    init = program("identify-init", "identify-init", lm_init, (fn, z0, args, lm_tol, scale))[0]
    carry, _ = init(fn, z0, args, lm_tol, scale)  # the step's example inputs (no solve: a cheap program)
    step = program("identify-step", "identify-step", lm_step, (fn, carry, args, lm_tol, scale))[0]
    return Core(fn, cfg.max_iterations, init, step)
