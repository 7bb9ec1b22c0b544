"""The compiled core of `identify`: the model with its forward sensitivities, the residual function with a
one-pass Jacobian (`jax.custom_jvp`), the Levenberg-Marquardt run, and the host side of its progress
reports."""

from __future__ import annotations

import dataclasses
import math
import time
import typing

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..._errors import SolveStatus
from ..._numerics.compile_cache import compiled, structure_key
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
    """Host side of the fit's progress reports. The compiled core always calls `_report` (through
    `jax.debug.callback`, once or more per LM evaluation); `_report` forwards to the reporter installed by
    `identify` for the duration of one LM run, so the compiled program does not depend on the callback and
    nothing is reported (or printed) when none is installed."""

    def __init__(self, progress, start: int, n_starts: int, t0: float):
        self.progress, self.start, self.n_starts, self.t0 = progress, start, n_starts, t0
        self.n, self.best_cost, self.best_z, self.last_z = 0, math.inf, None, None

    def __call__(self, z, cost, info) -> None:
        z = np.array(z, dtype=np.float64)
        if self.last_z is not None and np.array_equal(z, self.last_z):
            return  # the same evaluation seen again (its Jacobian pass)
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


REPORTER: list = [None]  # the active `_FitReporter`, or None


def _report(z, cost, info) -> None:
    rep = REPORTER[0]
    if rep is not None:
        rep(z, cost, info)


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
        r, status, steps = model(cfg, z, args)
        r, _ = guard(r, status)
        return r, jnp.stack([status, steps]).astype(jnp.float64)

    @res.defjvp
    def res_jvp(primals, tangents):
        # The data and scenario in `args` are constants of the fit: their tangents are ignored.
        (z, args), (dz, _) = primals, tangents

        r, J, status, steps = _model_and_jacobian(cfg, z, args)
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


# no_type_check: the tests' jaxtyping hook would check the inherited __init__ (rtol: float), which
# `_fit_core` calls with traced tolerances (as it called optimistix's class, which the hook leaves alone)
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


@eqx.filter_jit
def _fit_core(cfg: Config, z0, args, lm_tol, scale):
    """Levenberg-Marquardt on the residuals multiplied by `scale`. The LM tolerances and the scale are traced
    (not static), so changing them does not recompile; with infinite tolerances the run stops after the
    first evaluation, which `identify` uses to probe the Jacobian at the start (same compiled program).

    optimistix's LM starts with the damping λ = 1 (and changes it by the trust-region ratio test); `identify`
    chooses `scale` so that λ = 1 equals the largest diagonal entry of JᵀJ at the start (Marquardt's τ = 1)
    instead of a nearly undamped Gauss-Newton step, which on paper-4.2 jumps k and h by factors of 10³ into
    stiff, expensive regions."""
    inner = _residual_fn(cfg)

    def fn(z, a):
        r, info = inner(z, a)
        jax.debug.callback(_report, z, 0.5 * jnp.sum(r**2), info)
        return r * scale, info

    # LevenbergMarquardt.__init__ (inherited) gives norm, descent and search their defaults
    solver = _LevenbergMarquardt(rtol=lm_tol[0], atol=lm_tol[1], verbose=_VERBOSE)  # pyright: ignore[reportCallIssue]
    sol = optx.least_squares(
        fn, solver, z0, args, has_aux=True, max_steps=cfg.max_iterations, throw=False, options={"jac": "fwd"}
    )
    f_info = sol.state.f_info
    J = f_info.jac.as_matrix() / scale  # J @ e_i through the custom JVP: no new solve
    codes = jnp.stack(
        [sol.result == optx.RESULTS.successful, sol.result == optx.RESULTS.nonlinear_max_steps_reached]
    )
    return (
        sol.value,
        f_info.residual / scale,
        J,
        sol.aux,
        sol.stats["num_steps"],
        sol.state.num_accepted_steps,
        codes,
    )


def compiled_core(cfg: Config, z0, args, lm_tol, scale):
    """`_fit_core` compiled ahead of time (so compile and fit are timed apart), cached per structure."""
    key = (cfg, *structure_key(z0, args, lm_tol, scale))
    fn, _ = compiled("identify", key, lambda: _fit_core.lower(cfg, z0, args, lm_tol, scale))
    return fn
