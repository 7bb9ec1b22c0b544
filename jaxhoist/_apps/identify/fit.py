"""Gradient-based parameter identification: fit scenario leaves to measured time series.

    import jaxhoist as jh
    res = jh.identify("paper-4.2", "lift.csv", ["mu", "k", "rope.stiffness"], fit=jh.FitOptions(n_starts=3))
    print(res.summary())          # estimates, standard errors, correlations, identifiability
    res.estimates["foundation.friction_coefficient"]

The fit is weighted nonlinear least squares, solved by optimistix's Levenberg-Marquardt
(`optimistix.LevenbergMarquardt`, iterated as `optimistix.least_squares` does, one compiled step at a time
from the host, see `core.Core`) through the differentiable solver. The
Jacobian comes from forward-mode sensitivities, no finite differences: the state and its p sensitivities are
integrated together as one ODE whose step-size control also watches the sensitivities (see
`_sensitivity_solve` for why `jax.jacfwd` through `diffrax.ForwardMode` is not used by default), by the
Rosenbrock-W solver with one W for every block (default) or by any diffrax Runge-Kutta method
(`SolverOptions(diffrax.Tsit5())`). It enters optimistix through a `jax.custom_jvp` whose rule returns the
whole Jacobian once, so each LM step costs one augmented solve and the damped linear solves reuse the matrix.

Positivity and bounds are kept by reparameterisation: a positive leaf θ = θ_ref exp(z) (log), a bounded
leaf θ = lo + (hi - lo) sigmoid(z) (scaled logit), any other θ = θ_ref + scale z. The covariance is the
Gauss-Newton one, σ² (JᵀJ)⁻¹ at the optimum, carried to θ by the chain rule (delta method); σ² = 1 with
residuals whitened by given noise levels, else the residual variance estimate RSS / (n - p).

Everything the user gives is checked on the host before anything is compiled; the compiled programs are
cached per problem structure (parameters, signals, sizes, solver options), so repeated fits and several
starts compile once, and they hold no host callback, so the persistent compilation cache
(`enable_compilation_cache`) stores them whole and the next process loads them without tracing the model.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import diffrax
import jax.numpy as jnp
import numpy as np

from ..._errors import ScenarioError, SolveStatus, require_x64
from ..._io.measurement import (
    SIGNALS,
    Measurement,
    MeasurementError,
    check_signal_names,
    read_measurement,
    signal_groups,
)
from ..._io.scenario import load_scenario
from ..._numerics.options import SolverOptions
from ..._numerics.solve import checked_scenario
from ..._numerics.times import Times
from ..._physics.params import Scenario
from ..._physics.paths import param_unit
from ..simulate import simulate
from .core import Config, FitReporter, compiled_core, model_nested
from .options import FitOptions, fit_solver_options
from .parameters import ALIASES as ALIASES
from .parameters import SYMBOLS as SYMBOLS
from .parameters import Param, expand, random_starts, sigmas, spec_value, unflatten
from .parameters import apply_params as apply_params
from .parameters import build_params as build_params
from .parameters import flat_dtheta_dz as flat_dtheta_dz
from .parameters import flat_z as flat_z
from .parameters import resolve_param as resolve_param
from .parameters import theta_of as theta_of
from .result import IdentificationResult as IdentificationResult
from .result import StartResult as StartResult
from .result import covariance_report as covariance_report
from .result import plot_fit as plot_fit

# ------------------------------------------------------------------------------------- identify


@dataclasses.dataclass(frozen=True)
class _Problem:
    scenario: Scenario
    measurement: Measurement
    params: list[Param]
    theta0: np.ndarray
    names: list[str]
    sigma: dict[str, float]
    noise_known: bool
    warnings: list[str]
    n_residuals: int
    cfg: Config
    args: tuple


def _setup(
    scenario,
    measurement,
    params,
    *,
    signals=None,
    noise=None,
    weights=None,
    start=None,
    bounds=None,
    t1=None,
    options: SolverOptions,
    max_iterations: int = 100,
) -> _Problem:
    """Check every input on the host and build the static structure and the arrays of the problem."""
    if isinstance(scenario, str | Path):
        scenario = load_scenario(scenario)
    if not isinstance(scenario, Scenario):
        raise TypeError(
            f"scenario must be a jaxhoist.Scenario, a preset name or a path, got {type(scenario).__name__}"
        )
    scenario = checked_scenario(scenario)
    if isinstance(measurement, str | Path):
        measurement = read_measurement(measurement)
    if not isinstance(measurement, Measurement):
        raise TypeError(f"measurement must be a Measurement or a CSV path, got {type(measurement).__name__}")
    if signals is not None:
        measurement = measurement.select([signals] if isinstance(signals, str) else signals)
    t1 = scenario.t1 if t1 is None else float(t1)
    if not (np.isfinite(t1) and t1 > 0):
        raise ScenarioError(f"t1 must be a positive finite time [s], got {t1}")
    measurement.check_span(t1)
    plist, theta0 = build_params(scenario, params, start or {}, bounds or {})
    sig, noise_known, warnings = sigmas(measurement, noise, weights)
    names = measurement.names
    n_res = len(names) * measurement.t.size
    if n_res <= theta0.size:
        raise MeasurementError(
            f"{measurement.source}: {n_res} residuals cannot determine {theta0.size} parameters"
        )
    t = measurement.t
    drop_first = bool(t[0] > 0.0)
    ts = np.concatenate([[0.0], t]) if drop_first else t
    data = np.stack([measurement.signals[s] for s in names])
    sigma = np.stack([np.full(t.shape, sig[s]) for s in names])
    cfg = Config(
        params=tuple((p.path, p.index, p.shape, p.kind) for p in plist),
        signals=tuple((SIGNALS[s].field, SIGNALS[s].index) for s in names),
        drop_first=drop_first,
        options=options,
        max_iterations=int(max_iterations),
    )
    tr = tuple(tuple(jnp.asarray(a, dtype=jnp.float64) for a in (p.ref, p.lo, p.hi, p.scale)) for p in plist)
    # unlabelled: one program for any name, t1 or description (the solves read `ts`, not the labels)
    args = (scenario.unlabelled(), tr, jnp.asarray(data), jnp.asarray(sigma), jnp.asarray(ts))
    return _Problem(scenario, measurement, plist, theta0, names, sig, noise_known, warnings, n_res, cfg, args)


def check_inputs(
    scenario,
    measurement,
    params,
    *,
    signals=None,
    noise=None,
    start=None,
    bounds=None,
    t1=None,
    options: SolverOptions | None = None,
    fit: FitOptions | None = None,
) -> None:
    """Every check that `identify` makes of these arguments before it compiles anything, and nothing else
    (the command line runs it before it says that the fit starts). **Raises** as `identify` does for invalid
    input."""
    fit = FitOptions() if fit is None else fit
    _checked_problem(scenario, measurement, params, signals, noise, start, bounds, t1, options, fit)


def _checked_problem(scenario, measurement, params, signals, noise, start, bounds, t1, options, fit):
    """`_setup` with `identify`'s arguments (the fit options checked, the solver options completed), and the
    fit's starts, each checked as a scenario (e.g. a mass centre outside the box). **Returns** `(problem,
    starts)`."""
    if not isinstance(fit, FitOptions):
        raise ScenarioError(f"fit must be a jaxhoist.FitOptions, got {type(fit).__name__}")
    prob = _setup(
        scenario,
        measurement,
        params,
        signals=signals,
        noise=noise,
        weights=fit.weights,
        start=start,
        bounds=bounds,
        t1=t1,
        options=fit_solver_options(options),
        max_iterations=fit.max_iterations,
    )
    starts = [prob.theta0] + random_starts(
        prob.params, prob.theta0, int(fit.n_starts) - 1, float(fit.start_spread), int(fit.seed)
    )
    for th in starts:
        apply_params(prob.scenario, unflatten(prob.params, th)).check()
    return prob, starts


def residual_function(
    scenario,
    measurement,
    params,
    *,
    options: SolverOptions | None = None,
    fit: FitOptions | None = None,
    signals: Sequence[str] | None = None,
    noise: Mapping[str, float | str] | None = None,
    start: Mapping[str, Any] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    t1: float | None = None,
):
    """The whitened residual vector of `identify`'s problem as a plain numpy function of θ (flat, in the
    order of `IdentificationResult.names`), for comparisons with other optimisers (e.g. scipy with finite
    differences). Takes `identify`'s `signals`, `noise`, `start`, `bounds`, `t1`, `options` and `fit` (only
    its `weights` are read). A failed solve gives non-finite residuals. `options` defaults to `identify`'s
    (the Rosenbrock-W solver at rtol 5e-4): its residuals carry that tolerance, too noisy for finite
    differences with small steps; for those pass a tight solve, e.g. `SolverOptions(diffrax.Tsit5(),
    rtol=1e-8, atol=1e-10)` (`experiments/figures/identify_paper42.py` does).

    **Returns** `(fn, theta0)`: `fn(theta) -> r` (n_residuals,) and the start θ0.
    """
    require_x64()
    if fit is not None and not isinstance(fit, FitOptions):
        raise ScenarioError(f"fit must be a jaxhoist.FitOptions, got {type(fit).__name__}")
    weights = None if fit is None else fit.weights
    data: dict[str, Any] = dict(signals=signals, noise=noise, start=start, bounds=bounds, t1=t1)
    prob = _setup(scenario, measurement, params, weights=weights, options=fit_solver_options(options), **data)
    reverse = prob.cfg.options.replace(adjoint=diffrax.RecursiveCheckpointAdjoint())
    cfg = dataclasses.replace(prob.cfg, options=reverse)

    def fn(theta):
        z = jnp.asarray(flat_z(prob.params, np.asarray(theta, dtype=np.float64)))
        r, status, _ = model_nested(cfg, z, prob.args)
        r = np.asarray(r)
        return r if int(status) == SolveStatus.OK else np.full_like(r, np.nan)

    return fn, prob.theta0


def identify(
    scenario: Scenario | str | Path,
    measurement: Measurement | str | Path,
    params: Sequence[str] | str,
    *,
    signals: Sequence[str] | None = None,
    noise: Mapping[str, float | str] | None = None,
    start: Mapping[str, Any] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    t1: float | None = None,
    options: SolverOptions | None = None,
    fit: FitOptions | None = None,
    progress: Callable[[dict], None] | None = None,
) -> IdentificationResult:
    """Fit scenario leaves to measured time series by weighted nonlinear least squares.

    **Arguments**
    - `scenario`: a `Scenario`, a preset name or a TOML path; its values are the defaults and starts.
    - `measurement`: a `Measurement` or a CSV path (see `jaxhoist._io.measurement`).
    - `params`: what to fit: dotted leaf paths (`"foundation.stiffness"`, `"load.mass_centre"`,
      `"load.mass_centre[1]"`, `"boom.stiffness"`) or short names `mu, k, h, c_l, b_l`.
    - `signals`: the measured signals to fit (names or groups like `"position"`); default all.
    - `noise`: signal or group -> noise standard deviation [SI unit of the signal] or "x%" (of the signal's
      RMS value). Overrides noise levels from the measurement's side file.
    - `start`: parameter -> start value [SI unit of the leaf] (default: the scenario's value). `bounds`:
      parameter -> (low, high) [SI]; bounded parameters are fitted through a scaled logit; positive leaves
      (stiffness, damping, μ, mass, ...) through a log; `load.mass_centre` is bounded by the box by default.
    - `t1`: end of the simulated span [s] (default `scenario.t1`); every sample time must lie in [0, t1].
      The solver runs only to the last sample time.
    - `options`: `SolverOptions` of the simulations (solver, tolerances, step budget); default
      `SolverOptions()`, the Rosenbrock-W solver at rtol 5e-4, atol 1e-5 (one W for the state and every
      sensitivity). Forward mode is always used: the state is integrated with its sensitivities as one
      error-controlled system. `SolverOptions(diffrax.Tsit5())` (rtol 1e-6, atol 1e-8) compiles in about
      half the time and suits short records, where the compile dominates; W suits long ones
      (`options.fit_solver_options`, docs/identification.md).
    - `fit`: `FitOptions` (extra random starts, Levenberg-Marquardt termination and step budget,
      identifiability thresholds, and `weights`: signal or group -> residual weight [1/unit] for signals
      without a known noise level); default `FitOptions()`. Signals with neither a noise level nor a weight
      are scaled by their spread; unless every fitted signal has a noise level, the covariance uses the
      residual variance estimate RSS/(n - p).
    - `progress`: called on the host between the compiled Levenberg-Marquardt steps, after every
      evaluation, accepted or rejected, with a dict: `start` (0-based) and `n_starts`,
      `iteration` (1, 2, ... within the start), `cost` (0.5 Σ r² of the whitened residuals there),
      `best_cost` (the lowest so far, non-increasing), `improved` (this evaluation lowered it: LM accepts
      such steps), `step` (|Δz| from the best point so far, in the fit variables z: log θ for positive
      leaves), `solve_ok`, `solver_steps` (of that simulation) and `elapsed` [s] since the call. Default
      None: silent.

    **Returns** an `IdentificationResult` (`summary()` prints a table).

    **Raises** `ScenarioError` / `MeasurementError` for invalid input, before anything is compiled;
    `Float64Error` without x64.
    """
    require_x64()
    wall0 = time.perf_counter()
    fit = FitOptions() if fit is None else fit
    # ---- host side: every input is checked before anything is compiled
    prob, starts = _checked_problem(
        scenario, measurement, params, signals, noise, start, bounds, t1, options, fit
    )
    scenario, plist, cfg, args = prob.scenario, prob.params, prob.cfg, prob.args
    lm_tol = jnp.asarray([fit.lm_rtol, fit.lm_atol], dtype=jnp.float64)

    # ---- the compiled core, once per start
    c0 = time.perf_counter()
    core = compiled_core(cfg, jnp.asarray(flat_z(plist, starts[0])), args, lm_tol, jnp.asarray(1.0))
    compile_time = time.perf_counter() - c0
    runs, outs = [], []
    for th in starts:
        run, out = _run_start(core, args, plist, th, lm_tol, (len(runs), len(starts)), progress, wall0)
        runs.append(run)
        outs.append(out)
    best = int(np.argmin([s.cost if np.isfinite(s.cost) else np.inf for s in runs]))
    return _result(
        prob,
        starts,
        runs,
        outs[best],
        best,
        max_relative_se=fit.max_relative_se,
        condition_limit=fit.condition_limit,
        timings=(wall0, compile_time),
    )


def _run_start(core, args, plist, th, lm_tol, which: tuple[int, int], progress, wall0: float):
    """One Levenberg-Marquardt run from start `th` (`which`: its index and the number of starts).
    **Returns** `(StartResult, (z, r, J, info, theta))`."""
    w0 = time.perf_counter()
    one = jnp.asarray(1.0)
    probe_tol = jnp.asarray([1e300, 1e300])  # stops after the first evaluation (inf * 0 would give NaN)
    z0 = jnp.asarray(flat_z(plist, th))
    # Probe J at the start (one evaluation), then set the damping scale (see `core.Core.__call__`).
    J0 = core(z0, args, probe_tol, one)[2]
    d = float(np.max(np.sum(J0**2, axis=0))) if np.all(np.isfinite(J0)) else 0.0
    scale = jnp.asarray(1.0 / math.sqrt(d) if d > 0 else 1.0)
    report = None if progress is None else FitReporter(progress, which[0], which[1], wall0)
    z, r, J, info, n_steps, n_acc, codes = core(z0, args, lm_tol, scale, report)
    theta = theta_of(plist, z)
    converged = bool(codes[0])
    msg = "converged" if converged else ("reached max_iterations" if codes[1] else "LM failed")
    cost = 0.5 * float(np.sum(r**2))
    run = StartResult(
        unflatten(plist, th),
        unflatten(plist, theta),
        cost,
        int(n_steps),
        int(n_acc),
        converged,
        msg,
        time.perf_counter() - w0,
    )
    return run, (z, r, J, info, theta)


def _result(prob, starts, runs, out, best: int, *, max_relative_se, condition_limit, timings):
    """The `IdentificationResult` of the best start: covariance and identifiability at its optimum."""
    wall0, compile_time = timings
    scenario, measurement, plist = prob.scenario, prob.measurement, prob.params
    names, sig, noise_known = prob.names, prob.sigma, prob.noise_known
    z, r, J, info, theta = out
    run = runs[best]
    # ---- covariance and identifiability at the optimum
    D = flat_dtheta_dz(plist, z)
    J_theta = J / D[None, :]
    flat_names = [n for p_ in plist for n in p_.element_names()]
    rep = covariance_report(
        J_theta,
        r,
        theta,
        flat_names,
        noise_known=noise_known,
        scales=np.concatenate([p_.scale.ravel() for p_ in plist]),
        max_relative_se=max_relative_se,
        condition_limit=condition_limit,
    )
    sigma2, chi2, cov, se, corr = (
        rep["sigma2"],
        rep["chi2_reduced"],
        rep["covariance"],
        rep["std_errors"],
        rep["correlation"],
    )
    cond, weak_direction, identifiable = rep["condition_number"], rep["weak_direction"], rep["identifiable"]
    warnings = rep["warnings"] + list(prob.warnings)
    if not run.converged:
        warnings.append(
            f"Levenberg-Marquardt did not converge ({run.message}) after {run.iterations} "
            f"iterations; raise max_iterations or try n_starts > 1"
        )
    status = SolveStatus(int(info[0]))
    if status != SolveStatus.OK:
        warnings.append(f"the simulation at the estimate failed: {status.message}")
    if noise_known and not (0.5 < chi2 < 2.0):
        warnings.append(
            f"χ²/dof = {chi2:.3g} is far from 1: the given noise levels or the model do not fit "
            f"the data's scatter, so the standard errors may be off"
        )

    sig_rows = r.reshape(len(names), -1)
    fitted = {s: measurement.signals[s] + sig[s] * sig_rows[i] for i, s in enumerate(names)}
    fitted_scenario = apply_params(scenario, unflatten(plist, theta))
    return IdentificationResult(
        names=flat_names,
        params=[p_.name for p_ in plist],
        values=theta,
        std_errors=se,
        start_values=starts[best],
        covariance=cov,
        correlation=corr,
        sigma2=sigma2,
        noise_known=noise_known,
        chi2_reduced=chi2,
        t=measurement.t.copy(),
        measured=dict(measurement.signals),
        fitted=fitted,
        residuals={s: fitted[s] - measurement.signals[s] for s in names},
        sigma=sig,
        cost=run.cost,
        n_residuals=prob.n_residuals,
        iterations=run.iterations,
        accepted_steps=run.accepted_steps,
        converged=run.converged,
        message=run.message,
        solve_status=status,
        solver_steps=int(info[1]),
        condition_number=cond,
        weak_direction=weak_direction,
        identifiable=identifiable,
        warnings=warnings,
        starts=runs,
        scenario=fitted_scenario,
        wall_time=time.perf_counter() - wall0,
        compile_time=compile_time,
        fit_time=sum(s_.wall_time for s_ in runs),
        jacobian=J_theta,
        units={n: _unit(scenario, n) for n in flat_names} | {s: SIGNALS[s].unit for s in names},
    )


def _unit(scenario: Scenario, name: str) -> str:
    """The SI unit of a fitted element ("foundation.stiffness", "load.mass_centre[1]"), "" if unknown."""
    try:
        unit = param_unit(scenario, name)
    except ScenarioError:
        return ""
    return "" if unit == "?" else unit


# ------------------------------------------------------------------------------------- synthetic data


def synthetic_measurement(
    scenario: Scenario,
    t,
    signals: Sequence[str],
    *,
    noise: Mapping[str, Any] | None = None,
    seed: int = 0,
    options: SolverOptions | None = None,
    source: str = "synthetic",
) -> Measurement:
    """Simulate `scenario`, sample `signals` (names or groups) at times `t` [s] and add Gaussian noise.

    - `noise`: signal or group -> standard deviation [SI unit] or "x%" of the true signal's RMS value;
      signals not named are noise-free. The noise levels are stored in the returned `Measurement`.
    - `seed`: of `numpy.random.default_rng`; `source`: a label stored in the `Measurement`.
    - `options`: `SolverOptions` of the simulation; default `SolverOptions()` (the Rosenbrock-W solver,
      rtol 5e-4), the default solver of `identify`'s model, so that a fit to noise-free data with the
      defaults recovers the parameters to the solver's accuracy. For data that stand in for a real lift,
      whose model error should be far below the fit's, pass tighter tolerances (`SolverOptions(rtol=1e-8,
      atol=1e-10)`).
    """
    require_x64()
    options = SolverOptions() if options is None else options
    t = np.asarray(t, dtype=np.float64)
    names: list[str] = []
    signals = [signals] if isinstance(signals, str) else list(signals)  # one name, or several
    check_signal_names(signals, "synthetic_measurement: signals", groups=True)
    for s in signals:
        names += [n for n in signal_groups(s) if n not in names]
    Measurement(t, {n: np.zeros_like(t) for n in names})  # validates the times
    drop = bool(t[0] > 0)
    ts = np.concatenate([[0.0], t]) if drop else t
    traj = simulate(scenario, Times(ts=jnp.asarray(ts)), options=options)
    clean = {}
    for n in names:
        spec = SIGNALS[n]
        v = np.asarray(getattr(traj, spec.field))[(slice(None), *spec.index)]
        clean[n] = v[1:] if drop else v
    noise_e = expand(noise, names, "synthetic_measurement: noise")
    rng = np.random.default_rng(seed)
    sig = {n: spec_value(raw, n, clean[n], "noise") for n, raw in noise_e.items()}
    noisy = {n: clean[n] + (rng.normal(0.0, sig[n], size=t.shape) if n in sig else 0.0) for n in names}
    return Measurement(t, noisy, sig, source)
