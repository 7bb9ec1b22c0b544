"""Gradient-based parameter identification: fit scenario leaves to measured time series.

    import jaxhoist as jh
    from jaxhoist.apps.identify import identify
    res = identify("paper-4.2", "lift.csv", ["mu", "k", "rope.stiffness"])
    print(res.summary())          # estimates, standard errors, correlations, identifiability
    res.estimates["foundation.friction_coefficient"]

The fit is weighted nonlinear least squares, solved by optimistix's Levenberg-Marquardt
(`optimistix.least_squares` with `optimistix.LevenbergMarquardt`) through the differentiable solver. The
Jacobian comes from forward-mode sensitivities, no finite differences: the state and its p sensitivities are
integrated together as one ODE whose step-size control also watches the sensitivities (see
`_sensitivity_solve` for why `jax.jacfwd` through `diffrax.ForwardMode` is not used by default). It enters
optimistix through a `jax.custom_jvp` whose rule returns the whole Jacobian once, so each LM step costs one
augmented solve and the damped linear solves reuse the matrix.

Positivity and bounds are kept by reparameterisation: a positive leaf θ = θ_ref exp(z) (log), a bounded
leaf θ = lo + (hi - lo) sigmoid(z) (scaled logit), any other θ = θ_ref + scale z. The covariance is the
Gauss-Newton one, σ² (JᵀJ)⁻¹ at the optimum, carried to θ by the chain rule (delta method); σ² = 1 with
residuals whitened by given noise levels, else the residual variance estimate RSS / (n - p).

Everything the user gives is checked on the host before anything is compiled; the compiled core is cached
per problem structure (parameters, signals, sizes, solver options), so repeated fits and several starts
compile once.
"""

from __future__ import annotations

import argparse
import dataclasses
import difflib
import json
import math
import re
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._errors import ScenarioError, SolveStatus, require_x64
from ..io.measurement import (
    SIGNALS,
    Measurement,
    MeasurementError,
    check_signal_names,
    read_measurement,
    signal_groups,
)
from ..io.scenario import apply_overrides, load_scenario
from ..numerics.options import SolverOptions
from ..numerics.solve import outputs, simulate, solve
from ..physics.elastic import vector_field
from ..physics.equilibrium import initial_state
from ..physics.params import Scenario, get_leaf, leaf_getter

ALIASES: dict[str, str] = {
    "mu": "foundation.friction_coefficient",
    "k": "foundation.stiffness",
    "h": "foundation.damping",
    "c_l": "rope.stiffness",
    "b_l": "rope.damping",
}
"""Short names accepted for `params` (and by the CLI's `--fit`)."""

SYMBOLS: dict[str, str] = {v: k for k, v in ALIASES.items()}

# Leaves (by last path component) that are positive by nature: fitted as θ = θ_ref exp(z).
_POSITIVE = {
    "stiffness",
    "damping",
    "friction_coefficient",
    "mass",
    "tip_mass",
    "size",
    "speed",
    "gravity",
    "regularisation_velocity",
    "deflection",
    "relaxation_time",
    "ramp_time",
}
_PENALTY = 1e6  # whitened residual entry used when a trial solve fails: LM rejects such a step
_VERBOSE = False


class _FitReporter:
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


_REPORTER: list = [None]  # the active `_FitReporter`, or None


def _report(z, cost, info) -> None:
    rep = _REPORTER[0]
    if rep is not None:
        rep(z, cost, info)


# ------------------------------------------------------------------------------------- parameters


@dataclasses.dataclass(frozen=True)
class _Param:
    """One fitted leaf (or one element of a vector leaf, `path[i]`)."""

    name: str  # as reported: "foundation.stiffness", "load.mass_centre[1]"
    path: str  # dotted leaf path
    index: int | None  # element of a vector leaf, or None for the whole leaf
    shape: tuple[int, ...]  # shape of the fitted value
    kind: str  # "log" | "logit" | "affine"
    ref: np.ndarray  # θ_ref (log, affine) [unit of the leaf]
    lo: np.ndarray  # lower bound (logit)
    hi: np.ndarray  # upper bound (logit)
    scale: np.ndarray  # affine scale

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=int))

    def element_names(self) -> list[str]:
        if self.shape == ():
            return [self.name]
        return [f"{self.name}[{i}]" for i in range(self.size)]

    def to_z(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=np.float64)
        if self.kind == "log":
            return np.asarray(np.log(theta / self.ref))
        if self.kind == "logit":
            u = (theta - self.lo) / (self.hi - self.lo)
            return np.asarray(np.log(u) - np.log1p(-u))
        return np.asarray((theta - self.ref) / self.scale)


def _to_theta(kind: str, z, ref, lo, hi, scale):
    if kind == "log":
        return ref * jnp.exp(z)
    if kind == "logit":
        return lo + (hi - lo) * jax.nn.sigmoid(z)
    return ref + scale * z


def _dtheta_dz(kind: str, z, ref, lo, hi, scale):
    if kind == "log":
        return ref * np.exp(z)
    if kind == "logit":
        s = 1.0 / (1.0 + np.exp(-z))
        return (hi - lo) * s * (1 - s)
    return scale * np.ones_like(z)


_INDEXED = re.compile(r"^(.*)\[(\d+)\]$")


def resolve_param(name: str) -> tuple[str, int | None]:
    """`"mu"` -> (`"foundation.friction_coefficient"`, None); `"load.mass_centre[1]"` -> (path, 1)."""
    name = name.strip()
    m = _INDEXED.match(name)
    base, index = (m.group(1), int(m.group(2))) if m else (name, None)
    return ALIASES.get(base, base), index


def _leaf(scenario: Scenario, path: str, given: str) -> np.ndarray:
    if "." not in path and path not in ("gravity",):
        hint = difflib.get_close_matches(path, list(ALIASES), n=1, cutoff=0.5)
        raise ScenarioError(
            f"parameter {given!r} is neither a short name ({', '.join(ALIASES)}) nor a dotted leaf path such "
            f"as 'foundation.stiffness'" + (f" (did you mean {hint[0]!r}?)" if hint else "")
        )
    leaf = get_leaf(scenario, path)
    if not isinstance(leaf, jax.Array | np.ndarray):
        raise ScenarioError(
            f"parameter {given!r}: {path} is not an array leaf of the scenario and cannot be fitted"
        )
    return np.asarray(leaf, dtype=np.float64)


def _default_bounds(scenario: Scenario, path: str) -> tuple[np.ndarray, np.ndarray] | None:
    if path == "load.mass_centre":
        size = np.asarray(scenario.load.size)
        return np.zeros(3), size
    if path == "foundation.friction.breakaway_ratio":
        return np.zeros(()), np.ones(())
    return None


def _build_params(
    scenario: Scenario,
    params: Sequence[str],
    start: Mapping[str, Any],
    bounds: Mapping[str, tuple[float, float]],
) -> tuple[list[_Param], np.ndarray]:
    """Check the parameter list on the host; return the parameter specs and the flat start θ0."""
    if isinstance(params, str):
        params = [p for p in params.split(",") if p.strip()]
    if not params:
        raise ScenarioError("identify: give at least one parameter to fit (params=[...])")
    resolved = [resolve_param(p) for p in params]
    seen: dict[tuple[str, int | None], str] = {}
    for given, key in zip(params, resolved, strict=True):
        if key in seen or (key[0], None) in seen or (key[1] is None and any(k[0] == key[0] for k in seen)):
            raise ScenarioError(f"parameter {given!r} is listed twice (as {seen.get(key, key[0])!r})")
        seen[key] = given
    start_r = {resolve_param(k): v for k, v in (start or {}).items()}
    for k, given in zip(start_r, (start or {}), strict=True):
        if k not in resolved:
            raise ScenarioError(
                f"start value given for {given!r}, which is not a fitted parameter ({', '.join(params)})"
            )
    bounds_r = {resolve_param(k): v for k, v in (bounds or {}).items()}
    for k, given in zip(bounds_r, (bounds or {}), strict=True):
        if k not in resolved:
            raise ScenarioError(
                f"bounds given for {given!r}, which is not a fitted parameter ({', '.join(params)})"
            )
    out, theta0 = [], []
    for given, (path, index) in zip(params, resolved, strict=True):
        leaf = _leaf(scenario, path, given)
        if index is not None:
            if leaf.ndim != 1 or not 0 <= index < leaf.shape[0]:
                raise ScenarioError(
                    f"parameter {given!r}: {path} has shape {leaf.shape}, index {index} is out of range"
                )
            value = np.asarray(leaf[index])
        else:
            value = leaf
        name = path if index is None else f"{path}[{index}]"
        if (path, index) in start_r:
            try:
                v = np.asarray(start_r[(path, index)], dtype=np.float64)
                value = np.broadcast_to(v, value.shape).copy()
            except (ValueError, TypeError):
                raise ScenarioError(
                    f"start value of {name} must be a number or array of shape {value.shape}, "
                    f"got {start_r[(path, index)]!r}"
                ) from None
        if not np.all(np.isfinite(value)):
            raise ScenarioError(f"start value of {name} must be finite, got {value.tolist()}")
        b = bounds_r.get((path, index))
        if b is None:
            b = _default_bounds(scenario, path)
            if b is not None and index is not None:
                b = (b[0][index], b[1][index])
        if b is not None:
            try:
                lo, hi = (np.broadcast_to(np.asarray(x, dtype=np.float64), value.shape).copy() for x in b)
            except (ValueError, TypeError):
                raise ScenarioError(f"bounds of {name} must be (low, high), got {b!r}") from None
            if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
                raise ScenarioError(f"bounds of {name} must be finite with low < high, got {b!r}")
            if np.any(value <= lo) or np.any(value >= hi):
                raise ScenarioError(
                    f"start value of {name} = {value.tolist()} must lie strictly inside its "
                    f"bounds ({lo.tolist()}, {hi.tolist()})"
                )
            kind, ref, scale = "logit", np.zeros_like(value), np.ones_like(value)
        elif path.rsplit(".", 1)[-1] in _POSITIVE:
            if np.any(value <= 0):
                raise ScenarioError(
                    f"{name} is fitted on a log scale (it is positive by nature) and needs a "
                    f"start value > 0, got {value.tolist()}; give start={{{name!r}: ...}}"
                )
            kind, ref, scale, lo, hi = (
                "log",
                value.copy(),
                np.ones_like(value),
                np.zeros_like(value),
                np.zeros_like(value),
            )
        else:
            scale = np.asarray(np.where(np.abs(value) > 0, np.abs(value), 1.0))
            kind, ref, lo, hi = "affine", value.copy(), np.zeros_like(value), np.zeros_like(value)
        out.append(_Param(name, path, index, value.shape, kind, ref, lo, hi, scale))
        theta0.append(value.ravel())
    return out, np.concatenate(theta0)


def _unflatten(params: list[_Param], flat: np.ndarray) -> dict[str, np.ndarray | float]:
    out, i = {}, 0
    for p in params:
        v = flat[i : i + p.size].reshape(p.shape)
        out[p.name] = float(v) if p.shape == () else v.copy()
        i += p.size
    return out


def _flat_z(params: list[_Param], theta: np.ndarray) -> np.ndarray:
    out, i = [], 0
    for p in params:
        out.append(p.to_z(theta[i : i + p.size].reshape(p.shape)).ravel())
        i += p.size
    return np.concatenate(out)


def _flat_dtheta_dz(params: list[_Param], z: np.ndarray) -> np.ndarray:
    out, i = [], 0
    for p in params:
        seg = z[i : i + p.size].reshape(p.shape)
        out.append(np.asarray(_dtheta_dz(p.kind, seg, p.ref, p.lo, p.hi, p.scale)).ravel())
        i += p.size
    return np.concatenate(out)


def apply_params(scenario: Scenario, values: Mapping[str, Any]) -> Scenario:
    """A copy of `scenario` with fitted values set (names as in `IdentificationResult.estimates`, aliases
    and `path[i]` allowed)."""
    out = scenario
    for name, v in values.items():
        path, index = resolve_param(name)
        if index is None:
            out = out.replace(**{path: v})
        else:
            leaf = jnp.asarray(get_leaf(out, path))
            out = out.replace(**{path: leaf.at[index].set(v)})
    return out


# ------------------------------------------------------------------------------------- the core


@dataclasses.dataclass(frozen=True)
class _Config:
    """The static structure of one identification problem (a change recompiles the core)."""

    params: tuple[tuple[str, int | None, tuple[int, ...], str], ...]  # (path, index, shape, kind)
    signals: tuple[tuple[str, tuple[int, ...]], ...]  # (Trajectory field, index)
    drop_first: bool  # the solver's ts has t = 0 prepended to the measured times
    options: SolverOptions
    max_iterations: int
    sensitivity: str = "equations"  # "equations" | "solver", see `_model_and_jacobian`


def _scenario_at(cfg: _Config, scenario: Scenario, tr, z):
    i = 0
    for (path, index, shape, kind), (ref, lo, hi, scale) in zip(cfg.params, tr, strict=True):
        n = int(np.prod(shape, dtype=int))
        theta = _to_theta(kind, z[i : i + n].reshape(shape), ref, lo, hi, scale)
        i += n
        get = leaf_getter(path)
        new = theta if index is None else get(scenario).at[index].set(theta)
        scenario = eqx.tree_at(get, scenario, new)
    return scenario


def _signals(cfg: _Config, traj):
    m = jnp.stack([getattr(traj, f)[(slice(None), *idx)] for f, idx in cfg.signals])
    return m[:, 1:] if cfg.drop_first else m


def _model(cfg: _Config, z, args):
    """Whitened residuals (model - data) / σ, flattened signal-major, and the solve's status and steps."""
    scenario, tr, data, sigma, ts = args
    traj = solve(_scenario_at(cfg, scenario, tr, z), ts, cfg.options)
    return ((_signals(cfg, traj) - data) / sigma).ravel(), traj.status, traj.num_accepted_steps


def _sensitivity_solve(cfg: _Config, z, args):
    """Model signals and their derivatives d(signal)/dz from the forward sensitivity equations.

    The state y and its p sensitivities S_i = dy/dz_i are integrated together as one ODE,
    dy/dt = f(t, y, θ(z)), dS_i/dt = ∂f/∂y S_i + ∂f/∂z_i, with the step-size controller watching the error
    of both (the norm runs over the whole augmented state). Differentiating the solver's own steps instead
    (`jax.jacfwd` through `diffrax.ForwardMode`) leaves the tangents without error control; on paper-4.2 the
    explicit solver then runs at its stability limit for the stiff friction/contact modes and the tangents
    can blow up by many orders of magnitude while the state stays accurate.

    **Returns** `(m, dm, status, steps)`: signals (n_sig, n_t), derivatives (p, n_sig, n_t), a `SolveStatus`
    code and the accepted steps.
    """
    import diffrax

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

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rhs),
        opt.solver,
        t0=ts[0] * 0.0,
        t1=ts[-1],
        dt0=opt.dt0,
        y0=(y0, Y0),
        args=(z, c, dC),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=opt.stepsize_controller,
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


def _model_and_jacobian(cfg: _Config, z, args):
    """Whitened residuals r (n,), their Jacobian dr/dz (n, p), status and solver steps.

    `cfg.sensitivity = "equations"` (default): the forward sensitivity equations with error control
    (`_sensitivity_solve`). `"solver"`: `jax.jacfwd` through the solve with `diffrax.ForwardMode`
    (`simulate(..., adjoint="forward")`), cheaper but without error control on the tangents."""
    _, _, data, sigma, _ = args
    if cfg.sensitivity == "solver":

        def f(zz):
            r, status, steps = _model(cfg, zz, args)
            return r, (r, status, steps)

        J, (r, status, steps) = jax.jacfwd(f, has_aux=True)(z)
        return r, J, status, steps
    m, dm, status, steps = _sensitivity_solve(cfg, z, args)
    r = ((m - data) / sigma).ravel()
    J = (dm / sigma[None]).reshape(dm.shape[0], -1).T
    return r, J, status, steps


def _residual_fn(cfg: _Config):
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
        r, status, steps = _model(cfg, z, args)
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


@eqx.filter_jit
def _fit_core(cfg: _Config, z0, args, lm_tol, scale):
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

    solver = optx.LevenbergMarquardt(rtol=lm_tol[0], atol=lm_tol[1], verbose=_VERBOSE)
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


_COMPILED: dict = {}


def _compiled_core(cfg: _Config, z0, args, lm_tol, scale):
    """`_fit_core` compiled ahead of time (so compile and fit are timed apart), cached per structure."""
    leaves, treedef = jax.tree_util.tree_flatten((z0, args, lm_tol, scale))
    key = (cfg, treedef, tuple((x.shape, str(x.dtype)) if eqx.is_array(x) else x for x in leaves))
    if key not in _COMPILED:
        _COMPILED[key] = _fit_core.lower(cfg, z0, args, lm_tol, scale).compile()
    return _COMPILED[key]


# ------------------------------------------------------------------------------------- results


@dataclasses.dataclass(frozen=True)
class StartResult:
    """One Levenberg-Marquardt run: its start, end, cost 0.5 Σ r², iterations and outcome."""

    start: dict[str, Any]
    estimate: dict[str, Any]
    cost: float
    iterations: int
    accepted_steps: int
    converged: bool
    message: str
    wall_time: float


@dataclasses.dataclass(frozen=True)
class IdentificationResult:
    """The outcome of `identify`.

    - `names`: fitted scalar names (vector leaves expand to `path[i]`); `values`, `std_errors`: θ̂ and its
      standard errors, flat, in the leaves' SI units; `estimates`/`standard_errors`: the same by parameter.
    - `covariance`, `correlation`: Gauss-Newton covariance σ²(JᵀJ)⁻¹ at θ̂ (delta method from the fit
      variables z) and the correlation matrix, (p, p).
    - `sigma2`: the variance factor used (1 with known noise, else RSS/(n - p)); `noise_known`.
    - `chi2_reduced`: RSS/(n - p) of the whitened residuals (≈ 1 if the noise levels and the model are right).
    - `t`, `measured`, `fitted`, `residuals` (fitted - measured), `sigma`: per signal, SI units.
    - `cost`: 0.5 Σ r² of the whitened residuals; `n_residuals`.
    - `iterations`, `accepted_steps`: LM steps of the best start; `converged`, `message`.
    - `solve_status`: `SolveStatus` of the simulation at θ̂; `solver_steps`: its accepted steps.
    - `condition_number`: of the information matrix JᵀJ in relative units (Δθ/θ); `weak_direction`: the
      unit vector in relative units along which the fit changes least; `identifiable`: False if the matrix is
      near-singular or a parameter's relative standard error exceeds the limit; `warnings`: plain sentences.
    - `starts`: every LM run (several starts); `scenario`: the scenario with θ̂ set.
    - `wall_time`: the whole call [s]; `compile_time`: compiling the core (≈ 0 when cached) [s];
      `fit_time`: the LM runs [s].
    - `jacobian`: d(whitened residual)/dθ at θ̂ from the forward sensitivities, (n_residuals, p).
    """

    names: list[str]
    params: list[str]
    values: np.ndarray
    std_errors: np.ndarray
    start_values: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    sigma2: float
    noise_known: bool
    chi2_reduced: float
    t: np.ndarray
    measured: dict[str, np.ndarray]
    fitted: dict[str, np.ndarray]
    residuals: dict[str, np.ndarray]
    sigma: dict[str, float]
    cost: float
    n_residuals: int
    iterations: int
    accepted_steps: int
    converged: bool
    message: str
    solve_status: SolveStatus
    solver_steps: int
    condition_number: float
    weak_direction: dict[str, float]
    identifiable: bool
    warnings: list[str]
    starts: list[StartResult]
    scenario: Scenario
    wall_time: float
    compile_time: float
    fit_time: float
    jacobian: np.ndarray
    units: dict[str, str]

    @property
    def estimates(self) -> dict[str, Any]:
        return dict(zip(self.names, self.values.tolist(), strict=True))

    @property
    def standard_errors(self) -> dict[str, float]:
        return dict(zip(self.names, self.std_errors.tolist(), strict=True))

    def summary(self) -> str:
        w = max(len(n) for n in self.names) + 2
        lines = [f"{'parameter':<{w}} {'start':>12} {'estimate':>14} {'std error':>11} {'rel.':>8}  unit"]
        for i, n in enumerate(self.names):
            rel = self.std_errors[i] / abs(self.values[i]) if self.values[i] != 0 else math.inf
            lines.append(
                f"{n:<{w}} {self.start_values[i]:>12.5g} {self.values[i]:>14.8g} "
                f"{self.std_errors[i]:>11.3g} {100 * rel:>7.2g}%  {self.units.get(n, '')}"
            )
        if len(self.names) > 1:
            lines.append("correlations:")
            for i, n in enumerate(self.names):
                lines.append(f"  {n:<{w}} " + " ".join(f"{c:+.3f}" for c in self.correlation[i]))
        noise = "given noise levels (σ² = 1)" if self.noise_known else f"σ² = RSS/(n-p) = {self.sigma2:.4g}"
        lines += [
            f"fit: {self.iterations} LM iterations ({self.accepted_steps} accepted), "
            f"{'converged' if self.converged else 'NOT converged: ' + self.message}; "
            f"cost 0.5Σr² = {self.cost:.6g} over {self.n_residuals} residuals; "
            f"χ²/dof = {self.chi2_reduced:.4g}",
            f"covariance: Gauss-Newton at the optimum, {noise}; condition number of JᵀJ (relative units) "
            f"{self.condition_number:.3g}",
            f"simulation at the estimate: {self.solve_status.name.lower()}, {self.solver_steps} steps; "
            f"wall time {self.wall_time:.3g} s (compile {self.compile_time:.3g} s, fit {self.fit_time:.3g} s"
            + (f" over {len(self.starts)} starts)" if len(self.starts) > 1 else ")"),
        ]
        if self.identifiable:
            lines.append("identifiable: yes")
        else:
            lines.append("identifiable: NO")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no arrays of the time series)."""
        return {
            "estimates": {
                n: {
                    "value": float(v),
                    "std_error": float(s),
                    "start": float(s0),
                    "unit": self.units.get(n, ""),
                }
                for n, v, s, s0 in zip(
                    self.names, self.values, self.std_errors, self.start_values, strict=True
                )
            },
            "correlation": self.correlation.tolist(),
            "covariance": self.covariance.tolist(),
            "sigma2": self.sigma2,
            "noise_known": self.noise_known,
            "chi2_reduced": self.chi2_reduced,
            "sigma": self.sigma,
            "cost": self.cost,
            "n_residuals": self.n_residuals,
            "iterations": self.iterations,
            "accepted_steps": self.accepted_steps,
            "converged": self.converged,
            "message": self.message,
            "solve_status": self.solve_status.name.lower(),
            "solver_steps": self.solver_steps,
            "condition_number": self.condition_number,
            "weak_direction": self.weak_direction,
            "identifiable": self.identifiable,
            "warnings": self.warnings,
            "rms_residuals": {k: float(np.sqrt(np.mean(v**2))) for k, v in self.residuals.items()},
            "starts": [dataclasses.asdict(s) for s in self.starts],
            "wall_time_s": self.wall_time,
            "compile_time_s": self.compile_time,
            "fit_time_s": self.fit_time,
        }


def _units_of(scenario_leaf_path: str) -> str:
    last = scenario_leaf_path.split("[")[0]
    return {
        "foundation.stiffness": "N/m",
        "foundation.damping": "N s/m",
        "foundation.friction_coefficient": "-",
        "rope.stiffness": "N/m",
        "rope.damping": "N s/m",
        "rope.attachment": "m",
        "rope.slack": "m",
        "boom.stiffness": "N/m",
        "boom.damping": "N s/m",
        "boom.tip_mass": "kg",
        "boom.tip_position": "m",
        "load.mass": "kg",
        "load.mass_centre": "m",
        "load.size": "m",
        "load.inertia": "kg m^2",
        "hoist.speed": "m/s",
        "gravity": "m/s^2",
        "foundation.friction.regularisation_velocity": "m/s",
        "foundation.friction.deflection": "m",
        "foundation.friction.relaxation_time": "s",
        "foundation.friction.breakaway_ratio": "-",
    }.get(last, "")


# ------------------------------------------------------------------------------------- noise/weights


def _spec_value(raw, name: str, y: np.ndarray, what: str) -> float:
    if isinstance(raw, str) and raw.strip().endswith("%"):
        try:
            pct = float(raw.strip()[:-1])
        except ValueError:
            raise ScenarioError(f"{what} of {name!r} must be a number or 'x%', got {raw!r}") from None
        rms = float(np.sqrt(np.mean(y**2)))
        value = pct / 100.0 * rms
    else:
        try:
            value = float(raw)
        except (TypeError, ValueError):
            raise ScenarioError(
                f"{what} of {name!r} must be a positive number (or 'x%' for noise), got {raw!r}"
            ) from None
    if not (np.isfinite(value) and value > 0):
        raise ScenarioError(f"{what} of {name!r} must be positive, got {raw!r}")
    return value


def _expand(spec: Mapping[str, Any] | None, names: list[str], what: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, raw in (spec or {}).items():
        check_signal_names([key], what, groups=True)
        hits = [s for s in signal_groups(key) if s in names]
        if not hits:
            raise MeasurementError(f"{what}: {key!r} names no fitted signal (fitted: {names})")
        for s in hits:
            out[s] = raw
    return out


def _sigmas(m: Measurement, noise, weights) -> tuple[dict[str, float], bool, list[str]]:
    names = m.names
    noise_e = _expand(noise, names, "noise")
    weight_e = _expand(weights, names, "weights")
    both = sorted(set(noise_e) & set(weight_e))
    if both:
        raise ScenarioError(f"give a noise level or a weight for a signal, not both: {both}")
    sig, warn = {}, []
    for s in names:
        y = m.signals[s]
        if s in noise_e:
            sig[s] = _spec_value(noise_e[s], s, y, "noise")
        elif s in weight_e:
            sig[s] = 1.0 / _spec_value(weight_e[s], s, y, "weight")
        elif s in m.noise:
            sig[s] = m.noise[s]
        else:
            spread = float(np.std(y))
            sig[s] = spread if spread > 0 else (float(np.sqrt(np.mean(y**2))) or 1.0)
    unknown = [s for s in names if s not in noise_e and s not in m.noise]
    if unknown:
        warn.append(
            f"no noise level for {', '.join(unknown)}: "
            + (
                "residuals weighted by the given weights"
                if weight_e
                else "each such signal is scaled by its spread (standard deviation over time)"
            )
            + "; the covariance uses the residual variance estimate RSS/(n - p)"
        )
    return sig, not unknown, warn


# ------------------------------------------------------------------------------------- identify


@dataclasses.dataclass(frozen=True)
class _Problem:
    scenario: Scenario
    measurement: Measurement
    params: list[_Param]
    theta0: np.ndarray
    names: list[str]
    sigma: dict[str, float]
    noise_known: bool
    warnings: list[str]
    n_residuals: int
    cfg: _Config
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
    rtol=None,
    atol=None,
    max_steps=200_000,
    max_iterations=100,
) -> _Problem:
    """Check every input on the host and build the static structure and the arrays of the problem."""
    if isinstance(scenario, str | Path):
        scenario = load_scenario(scenario)
    if not isinstance(scenario, Scenario):
        raise TypeError(
            f"scenario must be a jaxhoist.Scenario, a preset name or a path, got {type(scenario).__name__}"
        )
    scenario.check()
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
    plist, theta0 = _build_params(scenario, params, start or {}, bounds or {})
    sig, noise_known, warnings = _sigmas(measurement, noise, weights)
    if int(max_iterations) < 1:
        raise ScenarioError(f"max_iterations must be >= 1, got {max_iterations}")
    # Tsit5: the fit integrates the state with its parameter tangents as one augmented system (below), which
    # the Rosenbrock-W solver's structured linearisation does not cover.
    options = SolverOptions(diffrax.Tsit5(), rtol=rtol, atol=atol, max_steps=max_steps, adjoint="forward")
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
    cfg = _Config(
        params=tuple((p.path, p.index, p.shape, p.kind) for p in plist),
        signals=tuple((SIGNALS[s].field, SIGNALS[s].index) for s in names),
        drop_first=drop_first,
        options=options,
        max_iterations=int(max_iterations),
    )
    tr = tuple(tuple(jnp.asarray(a, dtype=jnp.float64) for a in (p.ref, p.lo, p.hi, p.scale)) for p in plist)
    args = (scenario, tr, jnp.asarray(data), jnp.asarray(sigma), jnp.asarray(ts))
    return _Problem(scenario, measurement, plist, theta0, names, sig, noise_known, warnings, n_res, cfg, args)


@eqx.filter_jit
def _model_jit(cfg: _Config, z, args):
    return _model(cfg, z, args)


def residual_function(scenario, measurement, params, **kwargs):
    """The whitened residual vector of `identify`'s problem as a plain numpy function of θ (flat, in the
    order of `IdentificationResult.names`), for comparisons with other optimisers (e.g. scipy with finite
    differences). Takes the same keyword arguments as `identify` (signals, noise, weights, start, bounds, t1,
    rtol, atol, max_steps). A failed solve gives non-finite residuals.

    **Returns** `(fn, theta0)`: `fn(theta) -> r` (n_residuals,) and the start θ0.
    """
    require_x64()
    prob = _setup(scenario, measurement, params, **kwargs)
    reverse = prob.cfg.options.replace(adjoint=diffrax.RecursiveCheckpointAdjoint())
    cfg = dataclasses.replace(prob.cfg, options=reverse)

    def fn(theta):
        z = jnp.asarray(_flat_z(prob.params, np.asarray(theta, dtype=np.float64)))
        r, status, _ = _model_jit(cfg, z, prob.args)
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
    weights: Mapping[str, float] | None = None,
    start: Mapping[str, Any] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    n_starts: int = 1,
    start_spread: float = 0.3,
    seed: int = 0,
    t1: float | None = None,
    rtol: float | None = None,
    atol: float | None = None,
    max_steps: int = 200_000,
    lm_rtol: float = 1e-4,
    lm_atol: float = 1e-6,
    max_iterations: int = 100,
    max_relative_se: float = 0.5,
    condition_limit: float = 1e12,
    progress: Callable[[dict], None] | None = None,
) -> IdentificationResult:
    """Fit scenario leaves to measured time series by weighted nonlinear least squares.

    **Arguments**
    - `scenario`: a `Scenario`, a preset name or a TOML path; its values are the defaults and starts.
    - `measurement`: a `Measurement` or a CSV path (see `jaxhoist.io.measurement`).
    - `params`: what to fit: dotted leaf paths (`"foundation.stiffness"`, `"load.mass_centre"`,
      `"load.mass_centre[1]"`, `"boom.stiffness"`) or short names `mu, k, h, c_l, b_l`.
    - `signals`: the measured signals to fit (names or groups like `"position"`); default all.
    - `noise`: signal or group -> noise standard deviation [SI unit of the signal] or "x%" (of the signal's
      RMS value). Overrides noise levels from the measurement's side file.
    - `weights`: signal or group -> residual weight [1/unit] for signals without a known noise level.
      Signals with neither are scaled by their spread. Unless every fitted signal has a noise level, the
      covariance uses the residual variance estimate RSS/(n - p).
    - `start`: parameter -> start value (default: the scenario's value). `bounds`: parameter -> (low, high);
      bounded parameters are fitted through a scaled logit; positive leaves (stiffness, damping, μ, mass,
      ...) through a log; `load.mass_centre` is bounded by the box by default.
    - `n_starts`, `start_spread`, `seed`: extra starts drawn around `start` (relative spread: θ·(1+s)^U(-1,1)
      for positive leaves); the lowest cost wins, all are reported in `result.starts`.
    - `t1`: end of the simulated span [s] (default `scenario.t1`); every sample time must lie in [0, t1].
      The solver runs only to the last sample time.
    - `rtol`, `atol`, `max_steps`: ODE solver settings (see `SolverOptions`).
    - `lm_rtol`, `lm_atol`, `max_iterations`: Levenberg-Marquardt termination (Cauchy test on the fit
      variables z and the whitened residuals) and step budget.
    - `max_relative_se`, `condition_limit`: identifiability thresholds (relative standard error; condition
      number of JᵀJ in relative units).
    - `progress`: called on the host (through `jax.debug.callback` from the compiled fit) after every
      Levenberg-Marquardt evaluation, accepted or rejected, with a dict: `start` (0-based) and `n_starts`,
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
    # ---- host side: every input is checked before anything is compiled
    prob = _setup(
        scenario,
        measurement,
        params,
        signals=signals,
        noise=noise,
        weights=weights,
        start=start,
        bounds=bounds,
        t1=t1,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        max_iterations=max_iterations,
    )
    if int(n_starts) < 1:
        raise ScenarioError(f"n_starts must be >= 1, got {n_starts}")
    if not (np.isfinite(start_spread) and start_spread >= 0):
        raise ScenarioError(f"start_spread must be >= 0, got {start_spread}")
    for nm, v in (("lm_rtol", lm_rtol), ("lm_atol", lm_atol)):
        if not (np.isfinite(v) and v > 0):
            raise ScenarioError(f"{nm} must be a positive number, got {v}")
    scenario, measurement, plist, theta0 = prob.scenario, prob.measurement, prob.params, prob.theta0
    cfg, args, names, sig, noise_known = prob.cfg, prob.args, prob.names, prob.sigma, prob.noise_known
    warnings, n_res, t = list(prob.warnings), prob.n_residuals, measurement.t
    # Each start is checked as a scenario before compiling (e.g. a mass centre outside the box).
    starts = [theta0] + _random_starts(plist, theta0, int(n_starts) - 1, float(start_spread), int(seed))
    for th in starts:
        apply_params(scenario, _unflatten(plist, th)).check()
    lm_tol = jnp.asarray([lm_rtol, lm_atol], dtype=jnp.float64)

    # ---- the compiled core, once per start
    c0 = time.perf_counter()
    one = jnp.asarray(1.0)
    core = _compiled_core(cfg, jnp.asarray(_flat_z(plist, starts[0])), args, lm_tol, one)
    compile_time = time.perf_counter() - c0
    probe_tol = jnp.asarray([1e300, 1e300])  # stops after the first evaluation (inf * 0 would give NaN)
    runs, outs = [], []
    for th in starts:
        w0 = time.perf_counter()
        z0 = jnp.asarray(_flat_z(plist, th))
        # Probe J at the start (one evaluation), then set the damping scale (see `_fit_core`).
        J0 = np.asarray(core(cfg, z0, args, probe_tol, one)[2])
        d = float(np.max(np.sum(J0**2, axis=0))) if np.all(np.isfinite(J0)) else 0.0
        scale = jnp.asarray(1.0 / math.sqrt(d) if d > 0 else 1.0)
        if progress is not None:
            _REPORTER[0] = _FitReporter(progress, len(runs), len(starts), wall0)
        try:
            z, r, J, info, n_steps, n_acc, codes = jax.block_until_ready(core(cfg, z0, args, lm_tol, scale))
            jax.effects_barrier()  # every report delivered before the reporter goes
        finally:
            _REPORTER[0] = None
        z, r, J, info, codes = (np.asarray(x) for x in (z, r, J, info, codes))
        theta = _theta_of(plist, z)
        converged = bool(codes[0])
        msg = "converged" if converged else ("reached max_iterations" if codes[1] else "LM failed")
        cost = 0.5 * float(np.sum(r**2))
        runs.append(
            StartResult(
                _unflatten(plist, th),
                _unflatten(plist, theta),
                cost,
                int(n_steps),
                int(n_acc),
                converged,
                msg,
                time.perf_counter() - w0,
            )
        )
        outs.append((z, r, J, info, theta))
    best = int(np.argmin([s.cost if np.isfinite(s.cost) else np.inf for s in runs]))
    z, r, J, info, theta = outs[best]
    run = runs[best]

    # ---- covariance and identifiability at the optimum
    D = _flat_dtheta_dz(plist, z)
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
    warnings = rep["warnings"] + warnings
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
    fitted_scenario = apply_params(scenario, _unflatten(plist, theta))
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
        t=t.copy(),
        measured=dict(measurement.signals),
        fitted=fitted,
        residuals={s: fitted[s] - measurement.signals[s] for s in names},
        sigma=sig,
        cost=run.cost,
        n_residuals=n_res,
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
        units={n: _units_of(n) for n in flat_names} | {s: SIGNALS[s].unit for s in names},
    )


def covariance_report(
    J: np.ndarray,
    r: np.ndarray,
    theta: np.ndarray,
    names: Sequence[str],
    *,
    noise_known: bool,
    scales: np.ndarray | None = None,
    max_relative_se: float = 0.5,
    condition_limit: float = 1e12,
) -> dict[str, Any]:
    """Gauss-Newton covariance and identifiability at a least-squares optimum (host side, numpy).

    **Arguments**
    - `J`: d(whitened residual)/dθ, (n, p); `r`: the whitened residuals (n,); `theta`: θ̂ (p,); `names`.
    - `noise_known`: residuals whitened by true noise levels (σ² = 1); else σ² = RSS/(n - p).
    - `scales`: the size of a parameter that is zero at θ̂, for relative units (default 1).

    **Returns** a dict: `covariance` σ²(JᵀJ)⁻¹ (p, p), `std_errors`, `correlation`, `sigma2`,
    `chi2_reduced` = RSS/(n - p), `condition_number` of JᵀJ in relative units (columns scaled by |θ̂|),
    `weak_direction` (its least-determined unit vector, by name, largest component positive),
    `identifiable` (no relative standard error above `max_relative_se` and condition number at most
    `condition_limit`), `warnings` (a sentence naming what cannot be identified, and why). Parameters on an
    exactly singular direction get infinite standard errors.
    """
    J, r, theta = (np.asarray(x, dtype=np.float64) for x in (J, r, theta))
    n, p = J.shape
    scales = np.ones(p) if scales is None else np.asarray(scales, dtype=np.float64)
    chi2 = float(np.sum(r**2)) / max(n - p, 1)
    sigma2 = 1.0 if noise_known else chi2
    rel_scale = np.where(theta != 0, np.abs(theta), scales)
    Jn = J * rel_scale[None, :]  # sensitivity to relative changes Δθ/θ
    _, Sn, Vtn = np.linalg.svd(Jn, full_matrices=False)
    cond = float((Sn[0] / Sn[-1]) ** 2) if Sn[-1] > 0 else math.inf
    tiny = Sn <= Sn[0] * 1e-12
    inv_s2 = np.where(tiny, 0.0, 1.0 / np.where(tiny, 1.0, Sn) ** 2)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        cov = sigma2 * ((Vtn.T * inv_s2) @ Vtn) * rel_scale[:, None] * rel_scale[None, :]
        if np.any(tiny):  # singular: parameters on a null direction have no finite error
            null = np.any(np.abs(Vtn[tiny]) > 1e-6, axis=0)
            cov[null, :] = np.inf
            cov[:, null] = np.inf
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
        corr = cov / np.outer(se, se)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    weak = Vtn[-1] * np.sign(Vtn[-1][np.argmax(np.abs(Vtn[-1]))])
    weak_direction = {str(k): float(c) for k, c in zip(names, weak, strict=True)}
    rel_se = se / np.where(theta != 0, np.abs(theta), 1.0)
    poorly = [k for k, e in zip(names, rel_se, strict=True) if not (e <= max_relative_se)]
    identifiable = not poorly and cond <= condition_limit
    warnings = []
    if not identifiable:
        what = (
            f"{', '.join(poorly)} (relative standard error "
            f"{', '.join(f'{100 * rel_se[list(names).index(k)]:.3g} %' for k in poorly)})"
            if poorly
            else "the parameters jointly"
        )
        if p == 1:
            info = float(Sn[0] ** 2 / sigma2) if sigma2 > 0 else math.inf
            why = (
                f"the fitted signals barely depend on it (information JᵀJ/σ² = {info:.3g} per unit relative "
                f"change Δθ/θ)"
            )
        else:
            direction = " ".join(
                f"{c:+.2f} Δ{_short(k)}/{_short(k)}" for k, c in weak_direction.items() if abs(c) >= 0.05
            )
            kind = "singular" if math.isinf(cond) else "near-singular" if cond > condition_limit else "weak"
            why = (
                f"the information matrix JᵀJ is {kind} (condition number {cond:.3g} in relative units); the "
                f"poorly determined direction is {direction} (moving along it barely changes the fit)"
            )
        warnings.append(f"the data cannot identify {what}: {why}")
    elif cond > 1e8:
        warnings.append(
            f"the information matrix is ill-conditioned (condition number {cond:.3g}); "
            f"poorly determined direction {weak_direction}"
        )
    return {
        "covariance": cov,
        "std_errors": se,
        "correlation": corr,
        "sigma2": sigma2,
        "chi2_reduced": chi2,
        "condition_number": cond,
        "weak_direction": weak_direction,
        "identifiable": identifiable,
        "warnings": warnings,
    }


def _short(name: str) -> str:
    return SYMBOLS.get(name, name)


def _theta_of(plist: list[_Param], z: np.ndarray) -> np.ndarray:
    out, i = [], 0
    for p in plist:
        seg = z[i : i + p.size].reshape(p.shape)
        out.append(np.asarray(_to_theta(p.kind, seg, p.ref, p.lo, p.hi, p.scale)).ravel())
        i += p.size
    return np.concatenate(out).astype(np.float64)


def _random_starts(
    plist: list[_Param], theta0: np.ndarray, n: int, spread: float, seed: int
) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        parts, i = [], 0
        for p in plist:
            v = theta0[i : i + p.size]
            u = rng.uniform(-1.0, 1.0, size=v.shape)
            if p.kind == "log":
                w = v * (1.0 + spread) ** u
            elif p.kind == "logit":
                lo, hi = p.lo.ravel(), p.hi.ravel()
                w = np.clip(v * (1.0 + spread) ** u, lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo))
            else:
                w = v + spread * p.scale.ravel() * u
            parts.append(w)
            i += p.size
        out.append(np.concatenate(parts))
    return out


# ------------------------------------------------------------------------------------- synthetic data


def synthetic_measurement(
    scenario: Scenario,
    t,
    signals: Sequence[str],
    *,
    noise: Mapping[str, Any] | None = None,
    seed: int = 0,
    rtol: float | None = None,
    atol: float | None = None,
    max_steps: int = 200_000,
    source: str = "synthetic",
) -> Measurement:
    """Simulate `scenario`, sample `signals` (names or groups) at times `t` [s] and add Gaussian noise.

    - `noise`: signal or group -> standard deviation [SI unit] or "x%" of the true signal's RMS value;
      signals not named are noise-free. The noise levels are stored in the returned `Measurement`.
    """
    require_x64()
    t = np.asarray(t, dtype=np.float64)
    names: list[str] = []
    check_signal_names(signals, "synthetic_measurement: signals", groups=True)
    for s in signals:
        names += [n for n in signal_groups(s) if n not in names]
    Measurement(t, {n: np.zeros_like(t) for n in names})  # validates the times
    drop = bool(t[0] > 0)
    ts = np.concatenate([[0.0], t]) if drop else t
    # the solver identify's model uses (Tsit5, its default tolerances), so a fit to noise-free data recovers
    # the parameters to the solver's accuracy
    traj = simulate(
        scenario, ts=jnp.asarray(ts), solver=diffrax.Tsit5(), rtol=rtol, atol=atol, max_steps=max_steps
    )
    clean = {}
    for n in names:
        spec = SIGNALS[n]
        v = np.asarray(getattr(traj, spec.field))[(slice(None), *spec.index)]
        clean[n] = v[1:] if drop else v
    noise_e = _expand(noise, names, "synthetic_measurement: noise")
    rng = np.random.default_rng(seed)
    sig = {n: _spec_value(raw, n, clean[n], "noise") for n, raw in noise_e.items()}
    noisy = {n: clean[n] + (rng.normal(0.0, sig[n], size=t.shape) if n in sig else 0.0) for n in names}
    return Measurement(t, noisy, sig, source)


# ------------------------------------------------------------------------------------- plotting


_DEGREES = {"rad": "deg", "rad/s": "deg/s"}  # SI angle units and how `plot_fit` shows them


def plot_fit(result: IdentificationResult, *, max_signals: int = 12, title: str | None = None):
    """Measured (dots) against fitted (line) signals, one panel per signal, in SI units except angles
    (Euler angles in deg, angular velocities in deg/s); returns a matplotlib Figure."""
    from matplotlib.figure import Figure

    names = list(result.measured)[:max_signals]
    ncols = 1 if len(names) < 4 else 2
    nrows = math.ceil(len(names) / ncols)
    fig = Figure(figsize=(7.0 * ncols, 2.2 * nrows + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, squeeze=False)).ravel()
    for ax, n in zip(axes, names, strict=False):
        unit = SIGNALS[n].unit
        k = 1.0
        if unit in _DEGREES:  # angles in degrees, as in every other plot
            unit, k = _DEGREES[unit], 180.0 / math.pi
        ax.plot(result.t, k * result.measured[n], ".", ms=2.5, color="0.45", label="measured")
        ax.plot(result.t, k * result.fitted[n], "-", lw=1.2, color="tab:red", label="fitted")
        ax.set_ylabel(f"{n} [{unit}]")
        ax.grid(alpha=0.3)
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    for ax in axes[max(0, len(names) - ncols) : len(names)]:
        ax.set_xlabel("t [s]")
    axes[0].legend(loc="best", fontsize=8)
    est = ", ".join(
        f"{_short(n)} = {v:.5g} ± {s:.2g}"
        for n, v, s in zip(result.names, result.values, result.std_errors, strict=True)
    )
    fig.suptitle(title or f"measured vs fitted: {est}", fontsize=9)
    return fig


# ------------------------------------------------------------------------------------- CLI


def _parse_kv(text: str | None, what: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        k, sep, v = item.partition("=")
        if not sep or not k.strip() or not v.strip():
            raise ScenarioError(f"{what} expects NAME=VALUE[,NAME=VALUE...], got {item!r}")
        out[k.strip()] = v.strip()
    return out


def configure_parser(subparsers) -> None:
    """Register `jaxhoist identify SCENARIO MEASUREMENT.csv --fit mu,k,... [--out DIR]`."""
    p = subparsers.add_parser(
        "identify",
        help="fit scenario parameters to a measured CSV (Levenberg-Marquardt, forward sensitivities)",
        description="Fit scenario leaves to measured time series by weighted least squares "
        "(optimistix Levenberg-Marquardt with forward-mode sensitivities) and write the estimates "
        "(JSON) and a plot of measured against fitted signals. Short names: "
        + ", ".join(f"{k} -> {v}" for k, v in ALIASES.items())
        + "; any dotted leaf path works.",
    )
    p.add_argument(
        "scenario", metavar="SCENARIO", help="a preset name (e.g. paper-4.2) or a TOML scenario file"
    )
    p.add_argument(
        "measurement",
        metavar="MEASUREMENT.csv",
        help="CSV with a time column 't [s]' and signal columns such as 'position_x [m]'",
    )
    p.add_argument(
        "--fit",
        required=True,
        metavar="P1,P2,...",
        help="parameters to fit: mu, k, h, c_l, b_l or dotted paths (load.mass_centre[0], boom.stiffness)",
    )
    p.add_argument(
        "--signals",
        default=None,
        metavar="S1,S2,...",
        help="fit only these signals or groups (default: every column)",
    )
    p.add_argument(
        "--noise",
        default=None,
        metavar="S=SIGMA,...",
        help="noise standard deviation per signal or group in SI units, or x%% of its RMS, e.g. "
        "position=0.005,rope_tension=1%% (overrides the side JSON)",
    )
    p.add_argument(
        "--start", default=None, metavar="P=VALUE,...", help="start values (default: the scenario's)"
    )
    p.add_argument(
        "--starts", type=int, default=1, help="number of starts (extra ones random around --start)"
    )
    p.add_argument(
        "--t1", type=float, default=None, help="end of the simulated span [s] (default the scenario's)"
    )
    p.add_argument("--rtol", type=float, default=None, help="ODE relative tolerance (default 1e-6)")
    p.add_argument("--atol", type=float, default=None, help="ODE absolute tolerance (default 1e-8)")
    p.add_argument("--max-iterations", type=int, default=100, help="LM step budget (default 100)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="PATH=VALUE",
        help="replace a scenario value by dotted path before fitting, e.g. hoist.speed=0.25 (repeatable; "
        "as in `jaxhoist simulate --set`); checked before compiling",
    )
    p.add_argument("--out", default=None, help="output folder (default out/identify-<scenario name>)")
    p.add_argument("--no-plots", action="store_true", help="write only the JSON file")
    p.add_argument("--quiet", action="store_true", help="no progress line or bar on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """`jaxhoist identify`: read and check everything, fit, write `estimates.json` and `fit.png`, print a
    summary. Returns 0 if the fit converged and the parameters are identifiable, else 1."""
    jax.config.update("jax_enable_x64", True)
    quiet = getattr(args, "quiet", False)

    def note(msg):
        if not quiet:
            print(msg, file=sys.stderr, flush=True)

    scenario, overrides = apply_overrides(load_scenario(args.scenario), getattr(args, "set", None) or [])
    measurement = read_measurement(args.measurement)
    params = [s.strip() for s in args.fit.split(",") if s.strip()]
    noise = _parse_kv(args.noise, "--noise")
    start = {}
    for k, v in _parse_kv(args.start, "--start").items():
        try:
            start[k] = float(v)
        except ValueError:
            raise ScenarioError(f"--start {k}: value must be a number, got {v!r}") from None
    signals = [s.strip() for s in args.signals.split(",")] if args.signals else None
    out_dir = Path(args.out) if args.out else Path("out") / f"identify-{scenario.name}"
    note(
        f"fitting {', '.join(params)} of {scenario.name} to {len(measurement.names)} signals x "
        f"{measurement.t.size} samples of {args.measurement} (compiles once, then iterates) ..."
    )
    bar = None
    if not quiet:
        from .cli import FitProgressBar

        bar = FitProgressBar(total=args.max_iterations)
    try:
        res = identify(
            scenario,
            measurement,
            params,
            signals=signals,
            noise=noise or None,
            start=start,
            n_starts=args.starts,
            t1=args.t1,
            rtol=args.rtol,
            atol=args.atol,
            max_iterations=args.max_iterations,
            progress=bar,
        )
    finally:
        if bar is not None:
            bar.close()
    out_dir.mkdir(parents=True, exist_ok=True)
    doc = res.to_dict() | {
        "command": ["jaxhoist", *args.argv] if getattr(args, "argv", None) is not None else sys.argv,
        "scenario": scenario.name,
        "overrides": overrides,
        "measurement": str(args.measurement),
        "fitted_signals": list(res.measured),
    }
    (out_dir / "estimates.json").write_text(json.dumps(doc, indent=2, default=_json_default) + "\n")
    written = [out_dir / "estimates.json"]
    if not args.no_plots:
        fig = plot_fit(res)
        fig.savefig(out_dir / "fit.png", dpi=110)
        written.append(out_dir / "fit.png")
    print(res.summary())
    print("wrote " + ", ".join(str(w) for w in written))
    return 0 if res.converged and res.identifiable else 1


def _json_default(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return str(x)
