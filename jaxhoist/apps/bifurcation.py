"""Where does the motion change character? Candidate jumps on a scan grid, their refinement to a tolerance
with derivative-accelerated root finding, and continuation of a two-parameter boundary.

The paper (§4.3, Figs 10-12) finds that the container's motion changes abruptly near μ ≈ 0.3635. Here a
change of character is the sign change of an *indicator*

    g(p) = observable(p) - level,

where `level` separates the two kinds of motion (by default the midpoint of the observable at the two
ends of the bracket). Two kinds of observables:

- continuous ones whose zero *is* the boundary, e.g. the difference of two event times
  (`observables.detachment_time_difference("E", "D")`: which corner leaves the ground first). Newton steps
  with dg/dp from forward-mode sensitivities (`jax.jvp` through `diffrax.ForwardMode`) converge in a few
  solves;
- discontinuous ones (a final yaw that jumps by tens of degrees). Derivatives say nothing across a jump,
  so the safeguard falls back to bisection, ~log2(width/tol) solves; `method="multisection"` instead solves
  k points per round in one vmapped call (more solves, fewer rounds of wall time).

Either way the result reports how many solves it took against a uniform grid of the same resolution.

    import jaxhoist as jh
    from jaxhoist.apps import bifurcation
    from jaxhoist.numerics import observables as obs
    b = jh.locate_bifurcation(sc, "load.mass_centre[0]", obs.detachment_time_difference("E", "D"),
                              (0.4, 0.6), t1=0.2, n_save=101)
    print(b.summary())
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import ScenarioError, SolveStatus, require_x64
from ..numerics import observables as obs_mod
from ..numerics.options import SolverOptions
from ..numerics.solve import saved_times, solve
from ..physics.params import Scenario
from ..physics.paths import check_path, param_unit, set_param
from .scan import ScanResult, scan


class BifurcationError(RuntimeError):
    """The locator could not proceed: no sign change in the bracket, or a solve failed. `n_solves` says how
    many solves were spent before giving up."""

    def __init__(self, msg: str, n_solves: int = 0):
        super().__init__(msg)
        self.n_solves = n_solves


# -------------------------------------------------------------------------------------- candidates


@dataclasses.dataclass(frozen=True)
class Jump:
    """A candidate change of character between two neighbouring scan points.

    - `param`: the swept parameter path; `lo`, `hi`: the bracketing parameter values [its unit].
    - `y_lo`, `y_hi`: the observable at `lo` and `hi`; `size` = |y_hi - y_lo|.
    - `score`: `size` over the typical neighbouring step (inf where the neighbourhood is flat).
    - `index`: position of `lo` among the valid members sorted by the parameter.
    """

    param: str
    observable: str
    lo: float
    hi: float
    y_lo: float
    y_hi: float
    size: float
    score: float
    index: int


def _series(result: ScanResult, observable: str, param: str | None, who: str):
    """(param, x, y): a scalar observable of a 1-D scan against its parameter, valid members only, sorted."""
    if len(result.params) != 1 and param is None:
        raise ScenarioError(f"{who}: the scan has parameters {list(result.params)}; say which with param=")
    param = result.params[0] if param is None else param
    if result.mode == "grid" and len(result.params) > 1:
        raise ScenarioError(f"{who} works along a 1-D scan; take a slice of the grid first")
    y = np.asarray(result[observable], dtype=np.float64)
    if y.shape != result.shape:
        raise ScenarioError(
            f"{who} needs a scalar observable; {observable!r} has shape {y.shape[1:]} per "
            f"member (use e.g. '{observable}[0]' when scanning)"
        )
    x = np.asarray(result.values(param), dtype=np.float64).ravel()
    y = y.ravel()
    keep = result.ok.ravel() & ~np.isnan(y)
    x, y = x[keep], y[keep]
    order = np.argsort(x, kind="stable")
    return param, x[order], y[order]


def _bracket(param, observable, x, y, i, j, score) -> Jump:
    """The `Jump` between sorted members i < j."""
    with np.errstate(invalid="ignore"):
        size = abs(y[j] - y[i])
    return Jump(
        param=param,
        observable=observable,
        lo=float(x[i]),
        hi=float(x[j]),
        y_lo=float(y[i]),
        y_hi=float(y[j]),
        size=float(size),
        score=float(score),
        index=int(i),
    )


def find_crossings(
    result: ScanResult, observable: str, level: float = 0.0, *, param: str | None = None
) -> list[Jump]:
    """Neighbouring members of a 1-D scan on opposite sides of `level` (observable - level > 0 at one,
    <= 0 at the other): the brackets of the zeros of a continuous indicator, such as an event-time
    difference or a contact margin with level 0, which `find_jumps` does not see. Steps to or from ±inf
    (an event that stops happening) are jumps, not crossings, and left to `find_jumps`. `score` is inf.

    **Returns** the brackets sorted by parameter value, as `Jump`s."""
    param, x, y = _series(result, observable, param, "find_crossings")
    above = y - float(level) > 0.0
    finite = np.isfinite(y)
    idx = np.nonzero((above[:-1] != above[1:]) & finite[:-1] & finite[1:])[0]
    return [_bracket(param, observable, x, y, i, i + 1, np.inf) for i in idx]


def find_jumps(
    result: ScanResult,
    observable: str,
    *,
    param: str | None = None,
    factor: float = 8.0,
    window: int = 6,
    min_size: float | None = None,
) -> list[Jump]:
    """Candidate jumps of a scalar observable along a 1-D scan.

    A step between neighbouring (valid) members is a candidate when it is `factor` times larger than the
    median step of its `window` neighbours on either side, and larger than `min_size` (default 1e-6 of the
    observable's range). Consecutive candidates in the same direction are merged into one (a ramp steeper
    than its surroundings spanning several grid cells); a step back starts a new one (a one-cell excursion
    such as a count going 8 -> 7 -> 8 is two jumps). A step between a finite value and ±inf (an event that
    stops happening) always counts, on its own.

    **Returns** the candidates sorted by parameter value.
    """
    param, x, y = _series(result, observable, param, "find_jumps")
    if x.size < 2:
        return []
    finite = np.isfinite(y)
    with np.errstate(invalid="ignore"):
        d = np.abs(np.diff(y))
    both_inf = ~finite[:-1] & ~finite[1:] & (y[:-1] == y[1:])
    d = np.where(both_inf, 0.0, d)
    d_fin = np.where(np.isfinite(d), d, np.nan)
    yr = np.ptp(y[finite]) if finite.any() else 0.0
    floor = 1e-6 * yr if min_size is None else float(min_size)
    cand = np.zeros(d.size, dtype=bool)
    score = np.zeros(d.size)
    for i in range(d.size):
        if not np.isfinite(d[i]):
            cand[i], score[i] = True, np.inf
            continue
        nb = np.concatenate([d_fin[max(0, i - window) : i], d_fin[i + 1 : i + 1 + window]])
        nb = nb[np.isfinite(nb)]
        bg = float(np.median(nb)) if nb.size else 0.0
        if d[i] > floor and d[i] > factor * bg:
            cand[i] = True
            score[i] = d[i] / bg if bg > 0 else np.inf
    jumps = []
    with np.errstate(invalid="ignore"):
        direction = np.sign(np.diff(y))  # NaN where a step involves ±inf on both sides
    i = 0
    while i < d.size:
        if not cand[i]:
            i += 1
            continue
        j = i
        # merge a run of candidate steps in one direction (a steep ramp); a step back (a one-cell blip
        # 8 -> 7 -> 8 of a count, say) starts a new candidate, or the merged one would have equal ends
        while (
            j + 1 < d.size
            and cand[j + 1]
            and np.isfinite(d[j + 1])
            and np.isfinite(d[i])
            and direction[j + 1] == direction[i]
        ):
            j += 1
        jumps.append(_bracket(param, observable, x, y, i, j + 1, np.max(score[i : j + 1])))
        i = j + 1
    return jumps


# ------------------------------------------------------------------------------------- evaluations


@dataclasses.dataclass(frozen=True)
class _Spec:
    path: str
    observable: obs_mod.Observable
    options: SolverOptions


def _value(scenario, x, ts, spec: _Spec):
    sc = set_param(scenario, spec.path, x)
    traj = solve(sc, ts, spec.options)
    return jnp.asarray(spec.observable(traj, sc), dtype=jnp.float64), (traj.status, traj.num_accepted_steps)


@functools.lru_cache(maxsize=32)
def _value_fn(spec: _Spec):
    return eqx.filter_jit(lambda sc, x, ts: _value(sc, x, ts, spec))


@functools.lru_cache(maxsize=32)
def _jvp_fn(spec: _Spec):
    def f(sc, x, ts):
        y, dy, aux = jax.jvp(lambda p: _value(sc, p, ts, spec), (x,), (jnp.ones_like(x),), has_aux=True)
        return y, dy, aux

    return eqx.filter_jit(f)


_COMPILED: dict = {}  # compiled solves, by kind, spec and the shapes of their inputs


class _Evaluator:
    """Counts solves and turns a failed solve into a `BifurcationError` naming the parameter value."""

    def __init__(self, scenario, path, observable, ts, options: SolverOptions):
        self.scenario, self.path, self.ts = scenario, path, ts
        self.value_spec = _Spec(path, observable, options)
        self.jvp_spec = _Spec(path, observable, dataclasses.replace(options, adjoint="forward"))
        self.n_value = 0
        self.n_jvp = 0
        self.steps = 0
        self.compile_time = 0.0

    def _call(self, kind, x):
        spec = self.value_spec if kind == "value" else self.jvp_spec
        fn = (_value_fn if kind == "value" else _jvp_fn)(spec)
        xs = jnp.asarray(x, dtype=jnp.float64)
        leaves, treedef = jax.tree_util.tree_flatten(self.scenario)
        key = (kind, spec, treedef, tuple(np.shape(v) for v in leaves), self.ts.shape)
        if key not in _COMPILED:
            t0 = time.perf_counter()
            _COMPILED[key] = fn.lower(self.scenario, xs, self.ts).compile()
            self.compile_time += time.perf_counter() - t0
        out = jax.block_until_ready(_COMPILED[key](self.scenario, xs, self.ts))
        aux = out[-1]
        status, steps = int(aux[0]), int(aux[1])
        self.steps += steps
        if status != SolveStatus.OK:
            raise BifurcationError(
                f"the solve at {self.path} = {float(x)!r} failed: {SolveStatus(status).message}",
                n_solves=self.n_value + self.n_jvp,
            )
        return out

    def value(self, x) -> float:
        self.n_value += 1
        y, _ = self._call("value", x)
        return float(y)

    def value_and_slope(self, x) -> tuple[float, float]:
        self.n_jvp += 1
        y, dy, _ = self._call("jvp", x)
        return float(y), float(dy)


# ---------------------------------------------------------------------------------------- locator


@dataclasses.dataclass
class Bifurcation:
    """The located change of character.

    - `param`, `unit`, `observable`: what was varied and watched.
    - `value`: the estimate p* (midpoint of the final bracket) [unit]; `bracket`: the final (lo, hi), with
      the indicator g = observable - `level` of opposite signs at the two ends; `width` = hi - lo.
    - `y_lo`, `y_hi`: the observable at the final bracket ends (the two kinds of motion).
    - `n_solves`: solves used (`n_derivative_solves` of them with forward sensitivities, ~2-3x the cost);
      `n_uniform`: solves a uniform grid over the initial bracket at spacing `tol` would need.
    - `history`: every evaluation as (p, g, dg/dp or None, "newton" | "bisect" | "end" | "multisection").
    - `converged`: width <= tol; `method`; `wall_time`, `compile_time` [s]; `steps`: total solver steps.
    - `notes`: what the safeguards did (e.g. a fall-back to bisection when derivatives were not finite).
    - `jump_fraction`: |y_hi - y_lo| over the change across the initial bracket; `kind` reads it.
    """

    param: str
    unit: str
    observable: str
    value: float
    bracket: tuple[float, float]
    width: float
    level: float
    y_lo: float
    y_hi: float
    tol: float
    n_solves: int
    n_derivative_solves: int
    n_uniform: int
    history: list
    converged: bool
    method: str
    wall_time: float = 0.0
    compile_time: float = 0.0
    steps: int = 0
    notes: list = dataclasses.field(default_factory=list)
    jump_fraction: float = float("nan")

    @property
    def kind(self) -> str:
        """ "jump" if the observable still changes by more than 10 % of its change across the initial bracket
        within the final one (a discontinuity), else "crossing" (a continuous, possibly steep, change)."""
        return "jump" if self.jump_fraction > 0.1 else "crossing"

    def summary(self) -> str:
        unit = "" if self.unit in ("-", "") else f" {self.unit}"
        return (
            f"{self.param} * = {self.value:.10g}{unit} (bracket [{self.bracket[0]:.10g}, "
            f"{self.bracket[1]:.10g}], width {self.width:.2g}): {self.observable} changes from "
            f"{self.y_lo:.6g} to {self.y_hi:.6g} across it, {self.kind} ({100 * self.jump_fraction:.3g} % of "
            f"the change across the initial bracket); {self.n_solves} solves ({self.n_derivative_solves} "
            f"with derivatives, method {self.method}) vs {self.n_uniform} for a uniform grid at spacing "
            f"{self.tol:g}"
        )

    def to_dict(self, history: bool = True) -> dict[str, Any]:
        """Every field as plain Python values (`history` left out with `history=False`), plus `kind`."""
        d = dataclasses.asdict(self)
        if history:
            d["history"] = [list(h) for h in self.history]
        else:
            del d["history"]
        d["kind"] = self.kind
        return d


def _resolve_one(observable) -> obs_mod.Observable:
    try:
        (o,) = obs_mod.resolve(observable)
    except ValueError as e:
        raise ScenarioError(f"locate_bifurcation needs one observable: {e}") from None
    return o


def _indicator(y, level, y_lo_end):
    """g = y - level for finite ends; for an end at ±inf (an event that stops happening), +1 on the side of
    the lower end and -1 on the other, with no slope information."""
    if np.isfinite(level):
        return y - level
    same = (np.isfinite(y) == np.isfinite(y_lo_end)) and (np.isfinite(y) or y == y_lo_end)
    return -1.0 if same else 1.0


def locate_bifurcation(
    scenario: Scenario,
    param: str,
    observable,
    bracket: tuple[float, float],
    *,
    level: float | None = None,
    tol: float = 1e-6,
    method: str = "newton",
    t1: float | None = None,
    ts=None,
    n_save: int = 201,
    solver: diffrax.AbstractSolver | None = None,
    rtol: float | None = None,
    atol: float | None = None,
    dt0: float | None = None,
    max_steps: int = 200_000,
    max_solves: int = 200,
    points_per_round: int = 16,
    lanes: int = 16,
    progress: Callable[[dict], None] | None = None,
) -> Bifurcation:
    """Refine a change of character of `observable` in `param` to a bracket no wider than `tol`.

    **Arguments**
    - `scenario`, `param`: the base scenario and a parameter path (as in `scan`, e.g.
      "foundation.friction_coefficient", "hoist.speed", "rope.stiffness", "load.mass_centre[0]").
    - `observable`: a built-in name (a scalar one, or a component such as "final_euler[1]"), a callable
      `fn(traj[, scenario])` or an `Observable`.
    - `bracket`: (lo, hi) with the two kinds of motion at its ends (e.g. a `Jump` from `find_jumps`).
    - `level`: the indicator is g = observable - level; default the midpoint of the values at the ends
      (0 is natural for an event-time difference).
    - `tol`: the final bracket width [unit of the parameter].
    - `method`: "newton" (safeguarded Newton on g with dg/dp from forward-mode sensitivities; bisection
      whenever a Newton step leaves the bracket or does not shrink it fast enough), "bisection" (value-only
      solves), or "multisection" (`points_per_round` values per round in one vmapped `scan`).
    - `t1`, `ts`, `n_save`, `solver`, `rtol`, `atol`, `dt0`, `max_steps`: as in `simulate`, except that
      the default solver here is `diffrax.Tsit5()` (rtol 1e-6, atol 1e-8): Newton steps need forward-mode
      sensitivities, which through the default Rosenbrock-W solver are not reliable yet at high friction.
    - `max_solves`: give up (converged=False) after this many solves.
    - `progress`: called on the host after every evaluation (every round for "multisection") with a dict:
      `iteration` (1, 2, ...: evaluations, or rounds), `param` (the value just solved; the round's values
      for multisection), `value` (the observable there), `indicator` (g), `kind` ("end", "newton",
      "bisect", "multisection"), `bracket` (lo, hi) after the update, `width`, `tol`, `n_solves`,
      `elapsed` [s]. Default None: silent.

    **Returns** a `Bifurcation`.

    **Raises** `ScenarioError` on invalid input (before compiling); `BifurcationError` if g has the same
    sign at both ends, or a solve fails.
    """
    require_x64()
    wall0 = time.perf_counter()
    if not isinstance(scenario, Scenario):
        raise TypeError(f"scenario must be a jaxhoist.Scenario, got {type(scenario).__name__}")
    scenario.check()
    check_path(scenario, param)
    lo, hi = (float(b) for b in bracket)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ScenarioError(f"bracket must be two finite values lo < hi, got {bracket}")
    for v in (lo, hi):
        set_param(scenario, param, v).check()
    if not (np.isfinite(tol) and tol > 0):
        raise ScenarioError(f"tol must be > 0, got {tol}")
    if method not in ("newton", "bisection", "multisection"):
        raise ScenarioError(f"method must be 'newton', 'bisection' or 'multisection', got {method!r}")
    obs = _resolve_one(observable)
    ts = jnp.asarray(saved_times(scenario, t1, ts, n_save)[1], dtype=jnp.float64)
    if solver is None:
        # Tsit5 (rtol 1e-6): the Newton steps take forward-mode sensitivities, which through the default
        # Rosenbrock-W solver are not reliable yet at high friction (they grow without bound over 25 s of
        # paper-4.2 at mu >= 0.5; docs/performance.md)
        solver = diffrax.Tsit5()
    options = SolverOptions(solver=solver, rtol=rtol, atol=atol, dt0=dt0, max_steps=max_steps)
    n_uniform = int(math.ceil((hi - lo) / tol)) + 1
    unit = param_unit(scenario, param)

    if method == "multisection":
        return _multisection(
            scenario,
            param,
            obs,
            lo,
            hi,
            level,
            tol,
            ts,
            options,
            max_solves,
            points_per_round,
            lanes,
            n_uniform,
            unit,
            wall0,
            progress,
        )

    ev = _Evaluator(scenario, param, obs, ts, options)
    use_d = method == "newton"
    history: list = []
    n_eval = [0]

    def report(x, y, g, tag, br):
        n_eval[0] += 1
        if progress is not None:
            progress(
                dict(
                    iteration=n_eval[0],
                    param=float(x),
                    value=float(y),
                    indicator=float(g),
                    kind=tag,
                    bracket=(float(br[0]), float(br[1])),
                    width=float(br[1] - br[0]),
                    tol=tol,
                    n_solves=n_eval[0],  # one solve per evaluation
                    elapsed=time.perf_counter() - wall0,
                )
            )

    def evaluate(x, tag):
        if use_d:  # reassigned below once the ends are known
            y, dy = ev.value_and_slope(x)
        else:
            y, dy = ev.value(x), None
        return y, dy

    y_a, dy_a = evaluate(lo, "end")
    y_b, dy_b = evaluate(hi, "end")
    y_lo_end = y_a
    lev = 0.5 * (y_a + y_b) if level is None else float(level)
    if level is None and not (np.isfinite(y_a) and np.isfinite(y_b)):
        lev = np.inf  # one end never has the event: classify by finiteness
    g_a, g_b = _indicator(y_a, lev, y_lo_end), _indicator(y_b, lev, y_lo_end)
    slope_ok = use_d and np.isfinite(lev)
    history += [(lo, g_a, dy_a if slope_ok else None, "end"), (hi, g_b, dy_b if slope_ok else None, "end")]
    report(lo, y_a, g_a, "end", (lo, hi))
    report(hi, y_b, g_b, "end", (lo, hi))
    if g_a == 0.0 or g_b == 0.0 or np.sign(g_a) == np.sign(g_b):
        raise BifurcationError(
            f"{obs.name} - level has the same sign at both ends of the bracket ({param} = {lo:g}: {y_a:g}, "
            f"{hi:g}: {y_b:g}, level {lev:g}); give a bracket across the change (see find_jumps)",
            n_solves=2,
        )
    notes: list[str] = []
    if slope_ok and not (np.isfinite(dy_a) or np.isfinite(dy_b)):
        slope_ok = False
        notes.append(
            "forward-mode derivatives are not finite at the bracket ends: bisection with value-only solves"
        )
    a, b, ga, gb = lo, hi, g_a, g_b
    ya, yb = y_a, y_b
    use_d = slope_ok  # no slope information across an event that stops happening: value-only solves
    n_bad_slopes = 0
    # Safeguarded Newton (the rtsafe rule): from the last point, take the Newton step if it stays inside
    # the bracket and is at most half the step before last; otherwise bisect.
    x, gx, dgx = (a, ga, dy_a) if abs(ga) <= abs(gb) else (b, gb, dy_b)
    dx_old = dx = b - a
    while b - a > tol and ev.n_value + ev.n_jvp < max_solves:
        tag = "bisect"
        x_new = 0.5 * (a + b)
        if use_d and dgx is not None and np.isfinite(dgx) and dgx != 0.0:
            step = -gx / dgx
            if abs(step) < 0.5 * tol:
                # converged to within tol/2: step a little past the root to close the bracket behind it
                step = math.copysign(0.45 * tol, step if step != 0.0 else (b - a))
            if a < x + step < b and abs(step) <= 0.5 * abs(dx_old):
                x_new, tag = x + step, "newton"
        dx_old, dx = dx, abs(x_new - x)
        x_new = min(max(x_new, a + 0.05 * tol), b - 0.05 * tol)
        y_new, dy_new = evaluate(x_new, tag)
        g_new = _indicator(y_new, lev, y_lo_end)
        history.append((x_new, g_new, dy_new if use_d else None, tag))
        if g_new == 0.0:
            a, b, ya, yb = x_new, x_new, y_new, y_new
            report(x_new, y_new, g_new, tag, (a, b))
            break
        if np.sign(g_new) == np.sign(ga):
            a, ga, ya = x_new, g_new, y_new
        else:
            b, gb, yb = x_new, g_new, y_new
        report(x_new, y_new, g_new, tag, (a, b))
        x, gx, dgx = x_new, g_new, dy_new
        n_bad_slopes = 0 if (dy_new is None or np.isfinite(dy_new)) else n_bad_slopes + 1
        if use_d and n_bad_slopes >= 2:
            use_d = False
            notes.append(
                f"forward-mode derivatives not finite twice in a row near {param} = {x_new:.10g}: "
                f"bisection with value-only solves from there"
            )
    return Bifurcation(
        param=param,
        unit=unit,
        observable=obs.name,
        value=0.5 * (a + b),
        bracket=(a, b),
        width=b - a,
        level=float(lev),
        y_lo=float(ya),
        y_hi=float(yb),
        tol=tol,
        n_solves=ev.n_value + ev.n_jvp,
        n_derivative_solves=ev.n_jvp,
        n_uniform=n_uniform,
        history=history,
        converged=(b - a) <= tol,
        method=method,
        wall_time=time.perf_counter() - wall0,
        compile_time=ev.compile_time,
        steps=ev.steps,
        notes=notes,
        jump_fraction=_fraction(ya, yb, y_a, y_b),
    )


def _multisection(
    scenario,
    param,
    obs,
    lo,
    hi,
    level,
    tol,
    ts,
    options,
    max_solves,
    k,
    lanes,
    n_uniform,
    unit,
    wall0,
    progress=None,
):
    """Each round solves `k` points in one vmapped scan and keeps the first sign change."""
    kw = dict(
        observables={obs.name: obs},
        ts=ts,
        solver=options.solver,
        rtol=options.rtol,
        atol=options.atol,
        dt0=options.dt0,
        max_steps=options.max_steps,
        lanes=lanes,
        sort=False,
    )
    if k < 2:
        raise ScenarioError(f"points_per_round must be >= 2 for multisection, got {k}")
    # Every round solves exactly k points (one compiled shape): the first round spans the bracket, ends
    # included; later rounds put k points strictly inside the current bracket.
    xs = np.linspace(lo, hi, k)
    first = scan(scenario, {param: xs}, **kw)
    _raise_failed(first, param)
    ys = np.asarray(first[obs.name], dtype=np.float64)
    y_a, y_b = float(ys[0]), float(ys[-1])
    y_lo_end = y_a
    lev = 0.5 * (y_a + y_b) if level is None else float(level)
    if level is None and not (np.isfinite(y_a) and np.isfinite(y_b)):
        lev = np.inf
    gs = [_indicator(float(y), lev, y_lo_end) for y in ys]
    if np.sign(gs[0]) == np.sign(gs[-1]) or gs[0] == 0 or gs[-1] == 0:
        raise BifurcationError(
            f"{obs.name} - level has the same sign at both ends of the bracket "
            f"({lo:g}: {y_a:g}, {hi:g}: {y_b:g}, level {lev:g})",
            n_solves=k,
        )
    history = [(float(x), g, None, "multisection") for x, g in zip(xs, gs, strict=True)]
    n_solves, compile_time = k, first.attrs["timings_s"]["compile"]
    steps = int(np.sum(first.num_accepted_steps))
    pts = list(zip(xs.tolist(), gs, ys.tolist(), strict=True))
    a = b = ga = gb = ya = yb = None
    for (x0, g0, y0), (x1, g1, y1) in zip(pts[:-1], pts[1:], strict=True):
        if g1 == 0.0 or np.sign(g1) != np.sign(g0):
            a, ga, ya, b, gb, yb = x0, g0, y0, x1, g1, y1
            break
    rounds = 0

    def report(xs, ys, gs):
        nonlocal rounds
        rounds += 1
        if progress is not None:
            progress(
                dict(
                    iteration=rounds,
                    param=[float(x) for x in xs],
                    value=[float(y) for y in ys],
                    indicator=[float(g) for g in gs],
                    kind="multisection",
                    bracket=(float(a), float(b)),
                    width=float(b - a),
                    tol=tol,
                    n_solves=n_solves,
                    elapsed=time.perf_counter() - wall0,
                )
            )

    report(xs, ys, gs)
    while b - a > tol and n_solves + k <= max_solves:
        xs = a + (b - a) * np.arange(1, k + 1) / (k + 1)
        r = scan(scenario, {param: xs}, **kw)
        _raise_failed(r, param)
        n_solves += k
        compile_time += r.attrs["timings_s"]["compile"]
        steps += int(np.sum(r.num_accepted_steps))
        ys = np.asarray(r[obs.name], dtype=np.float64)
        gs = [_indicator(float(y), lev, y_lo_end) for y in ys]
        history += [(float(x), g, None, "multisection") for x, g in zip(xs, gs, strict=True)]
        pts = [(a, ga, ya)] + list(zip(xs.tolist(), gs, ys.tolist(), strict=True)) + [(b, gb, yb)]
        for (x0, g0, y0), (x1, g1, y1) in zip(pts[:-1], pts[1:], strict=True):
            if g1 == 0.0 or np.sign(g1) != np.sign(g0):
                a, ga, ya, b, gb, yb = x0, g0, y0, x1, g1, y1
                break
        report(xs, ys, gs)
    return Bifurcation(
        param=param,
        unit=unit,
        observable=obs.name,
        value=0.5 * (a + b),
        bracket=(a, b),
        width=b - a,
        level=float(lev),
        y_lo=float(ya),
        y_hi=float(yb),
        tol=tol,
        n_solves=n_solves,
        n_derivative_solves=0,
        n_uniform=n_uniform,
        history=history,
        converged=(b - a) <= tol,
        method="multisection",
        wall_time=time.perf_counter() - wall0,
        compile_time=compile_time,
        steps=steps,
        jump_fraction=_fraction(ya, yb, y_a, y_b),
    )


def _fraction(ya, yb, y_a, y_b) -> float:
    """|yb - ya| / |y_b - y_a|, with an event that happens on one side only counting as a full jump."""
    if not (np.isfinite(y_a) and np.isfinite(y_b)):
        return 1.0 if np.isfinite(ya) != np.isfinite(yb) else 0.0
    full = abs(y_b - y_a)
    return float(abs(yb - ya) / full) if full > 0 else 0.0


def _raise_failed(r: ScanResult, param):
    if not np.all(r.ok):
        f = r.failures()[0]
        raise BifurcationError(f"the solve at {param} = {f['params'][param]!r} failed: {f['reason']}")


def locate_jumps(
    scenario: Scenario, result: ScanResult, observable: str, *, max_jumps: int | None = None, **kw
) -> list[Bifurcation]:
    """`find_jumps` on a 1-D scan (and, with `level=` given, `find_crossings` of that level), then
    `locate_bifurcation` in every candidate bracket (largest first). Keyword arguments go to both
    (`factor`, `window`, `min_size` to `find_jumps`, the rest to the locator); a candidate whose refinement
    fails is skipped."""
    fj = {k: kw.pop(k) for k in ("factor", "window", "min_size") if k in kw}
    cands = find_jumps(result, observable, **fj)
    if kw.get("level") is not None:
        seen = {(j.lo, j.hi) for j in cands}
        cands += [c for c in find_crossings(result, observable, kw["level"]) if (c.lo, c.hi) not in seen]
    jumps = sorted(cands, key=lambda j: -j.size if np.isfinite(j.size) else -np.inf)
    if max_jumps is not None:
        jumps = jumps[:max_jumps]
    out = []
    for j in jumps:
        try:
            out.append(locate_bifurcation(scenario, j.param, observable, (j.lo, j.hi), **kw))
        except BifurcationError:
            continue
    return sorted(out, key=lambda b: b.value)


# ----------------------------------------------------------------------------------- continuation


@dataclasses.dataclass
class Boundary:
    """A boundary p*(q) traced by continuation.

    - `param`, `along`: the located parameter p and the continuation parameter q (paths).
    - `along_values`, `values`: q_k and p*(q_k) (NaN where the corrector failed or lost the jump);
      `widths`: final brackets.
    - `n_solves`: solves used in all; `n_dense`: solves a dense grid at spacing `tol` in p, over the initial
      bracket and every located p*, at the same q values would need.
    - `points`: the `Bifurcation` of each q (None where it failed; kept, with a note, where it was lost).
    """

    param: str
    along: str
    along_values: np.ndarray
    values: np.ndarray
    widths: np.ndarray
    n_solves: int
    n_dense: int
    points: list
    tol: float

    def rows(self) -> list[dict[str, Any]]:
        """One dict per continuation point, for tables and JSON: its `Bifurcation` fields (no history;
        none where the corrector failed), then `along_value` = q and `value` = p* (None where failed or
        lost)."""
        out = []
        for q, v, pt in zip(self.along_values, self.values, self.points, strict=True):
            d = pt.to_dict(history=False) if pt is not None else {}
            d.update(along_value=float(q), value=float(v) if np.isfinite(v) else None)
            out.append(d)
        return out


def trace_boundary(
    scenario: Scenario,
    param: str,
    bracket: tuple[float, float],
    along: str,
    along_values: Sequence[float] | np.ndarray,
    observable,
    *,
    level: float | None = None,
    tol: float = 1e-6,
    method: str = "newton",
    initial_half_width: float | None = None,
    max_expansions: int = 8,
    min_jump_fraction: float = 0.1,
    progress: Callable[[dict], None] | None = None,
    **solve_kw,
) -> Boundary:
    """Follow the boundary p*(q) in the (p, q) plane by continuation, not a dense grid.

    At `along_values[0]`, p* is located in `bracket`. At each next q the predictor extrapolates the last two
    points linearly (a secant along the boundary), and the corrector brackets the prediction by
    ±w (w = half the last change of p*, at least 20 tol; doubled until the indicator changes sign) and
    refines it with `locate_bifurcation`. With `level=None` the level is re-estimated in each bracket, so
    the corrector always finds *some* crossing; a point whose change across its final bracket is below
    `min_jump_fraction` of the first point's is therefore reported as lost (NaN, with a note on the point):
    the jump has vanished or moved out of reach there, and a level crossing of a nearly flat observable is
    not the boundary.

    `progress` (default None: silent) receives every report of the inner `locate_bifurcation` calls, with
    `point` (index k of q), `n_points` and `along_value` (q) added.

    **Returns** a `Boundary`.
    """
    qs = np.asarray(along_values, dtype=np.float64)
    if qs.ndim != 1 or qs.size < 1:
        raise ScenarioError("along_values must be a non-empty 1-D sequence")
    check_path(scenario, along)
    check_path(scenario, param)
    obs = _resolve_one(observable)
    lo, hi = (float(v) for v in bracket)
    ps: list[float] = []
    points: list = []
    n_solves = 0
    ref_size = None
    for k, q in enumerate(qs):
        sc = set_param(scenario, along, q)
        good = [(qq, pp) for qq, pp in zip(qs[:k], ps, strict=True) if np.isfinite(pp)]
        if not good:
            candidates = [(lo, hi)]
        else:
            if len(good) >= 2:  # secant predictor along the boundary
                (q0, p0), (q1, p1) = good[-2], good[-1]
                pred = p1 + (p1 - p0) * (q - q1) / (q1 - q0)
                w = max(20 * tol, 0.5 * abs(p1 - p0))
            else:
                pred = good[-1][1]
                w = max(20 * tol, initial_half_width if initial_half_width else 0.05 * (hi - lo))
            candidates = [(pred - w * 2**i, pred + w * 2**i) for i in range(max_expansions)]
        pt = None
        inner = None
        if progress is not None:

            def inner(d, k=k, q=q):
                progress(d | {"point": k, "n_points": int(qs.size), "along_value": float(q)})

        for br in candidates:
            try:
                pt = locate_bifurcation(
                    sc, param, obs, br, level=level, tol=tol, method=method, progress=inner, **solve_kw
                )
                break
            except BifurcationError as e:  # no sign change in this bracket: widen it
                n_solves += e.n_solves
            except ScenarioError:  # the widened bracket left the valid range of the parameter
                break
        lost = False
        if pt is not None:
            n_solves += pt.n_solves
            size = abs(pt.y_hi - pt.y_lo)
            if level is None and ref_size is None:
                ref_size = size
            elif level is None and not size >= min_jump_fraction * ref_size:
                lost = True
                pt.notes.append(
                    f"lost: the change across the final bracket, {size:.3g}, is below "
                    f"{min_jump_fraction:g} x the first point's {ref_size:.3g}; not the traced jump"
                )
        ps.append(pt.value if pt is not None and not lost else np.nan)
        points.append(pt)
    vals = np.asarray(ps)
    fin = vals[np.isfinite(vals)]
    span = max([hi, *fin.tolist()]) - min([lo, *fin.tolist()])
    n_dense = int(qs.size * (math.ceil(span / tol) + 1))
    widths = np.array([p.width if p is not None else np.nan for p in points])
    return Boundary(
        param=param,
        along=along,
        along_values=qs,
        values=vals,
        widths=widths,
        n_solves=n_solves,
        n_dense=n_dense,
        points=points,
        tol=tol,
    )


# ---------------------------------------------------------------------------------------------- CLI


def configure_parser(subparsers) -> None:
    """Add `jaxhoist bifurcation SCENARIO --param PATH --bracket LO HI --observable NAME [...]` (and
    `--along PATH --along-values SPEC` to trace the boundary in a second parameter)."""
    from ..io.validate import count_arg, number_arg

    p = subparsers.add_parser(
        "bifurcation",
        help="locate where an observable changes character as a parameter varies",
        description="Refine a change of character of an observable (a jump, or the sign change of an event-"
        "time difference) to a tolerance, with derivative-accelerated root finding. With --scan N, "
        "first scan N points across the bracket and refine every candidate jump.",
    )
    p.add_argument("scenario", metavar="SCENARIO", help="preset name (e.g. paper-4.2) or TOML file")
    p.add_argument("--param", required=True, metavar="PATH", help="e.g. foundation.friction_coefficient")
    p.add_argument("--bracket", nargs=2, type=number_arg, required=True, metavar=("LO", "HI"))
    p.add_argument(
        "--observable",
        default="final_psi",
        help="scalar observable (built-in name, a component like final_euler[1], or "
        "detach:E-D for a detachment-time difference); default final_psi",
    )
    p.add_argument(
        "--level", type=number_arg, default=None, help="indicator level (default: midpoint of the ends)"
    )
    p.add_argument("--tol", type=number_arg, default=1e-6, help="final bracket width (default 1e-6)")
    p.add_argument("--method", choices=("newton", "bisection", "multisection"), default="newton")
    p.add_argument(
        "--scan",
        type=count_arg,
        default=0,
        metavar="N",
        help="first scan N >= 2 points over the bracket and refine every candidate jump (default 0: no scan)",
    )
    p.add_argument(
        "--along",
        default=None,
        metavar="PATH",
        help="trace the boundary in a second parameter by continuation, e.g. hoist.speed",
    )
    p.add_argument(
        "--along-values",
        default=None,
        metavar="SPEC",
        help="values of --along, start:stop:num or v1,v2,...; the first is where --bracket applies",
    )
    p.add_argument("--t1", type=number_arg, default=None)
    p.add_argument("--n-save", type=count_arg, default=201)
    p.add_argument("--rtol", type=number_arg, default=None)
    p.add_argument("--atol", type=number_arg, default=None)
    p.add_argument("--max-steps", type=count_arg, default=200_000)
    p.add_argument("--set", action="append", default=[], metavar="PATH=VALUE", help="fixed leaf overrides")
    p.add_argument(
        "--out",
        default=None,
        help="folder for bifurcation.json, locator_<k>.png per located value (and, with --scan, the scan "
        "and scan_<observable>.png with the located values marked)",
    )
    p.add_argument("--no-plots", action="store_true", help="write no PNGs")
    p.add_argument(
        "--classify",
        action="store_true",
        help="name every located change (final-state jump, steep ramp, event-count change, event-definition "
        "change, continuous crossing) by solving a window around it (jaxhoist.classify_change; ~43 solves "
        "each)",
    )
    p.add_argument(
        "--quiet", action="store_true", help="no progress bars on stderr (scan members, locator brackets)"
    )
    p.set_defaults(func=run_cli)


def _cli_observable(name: str):
    if name.startswith("detach:"):
        a, _, b = name[len("detach:") :].partition("-")
        corners = obs_mod.CORNERS
        if a.upper() not in corners or b.upper() not in corners or a.upper() == b.upper():
            raise ScenarioError(
                f"--observable {name!r}: detach:X-Y needs two different corners among {list(corners)}, "
                f"e.g. detach:E-D"
            )
        return obs_mod.detachment_time_difference(a, b)
    return name


def _check_cli_args(args, scenario) -> np.ndarray | None:
    """Every argument of `jaxhoist bifurcation` checked before any solve; returns the --along values."""
    from ..io.validate import check_count, check_out_dir, check_param_path, check_scalar_observable
    from ..io.validate import parse_values as strict_values

    check_count(args.scan, "--scan", 2, allow_zero=True)
    check_scalar_observable(_resolve_one(_cli_observable(args.observable)), "--observable")
    check_param_path(scenario, args.param, "--param")
    along = None
    if args.along is not None:
        check_param_path(scenario, args.along, "--along")
    if args.along_values is not None:
        along = strict_values(args.along_values, "--along-values")
    if args.out:
        check_out_dir(args.out, "--out")
    return along


def run_cli(args) -> int:
    jax.config.update("jax_enable_x64", True)
    from ..io.scenario import apply_overrides, load_scenario

    scenario, overrides = apply_overrides(load_scenario(args.scenario), args.set)
    along_values = _check_cli_args(args, scenario)
    observable = _cli_observable(args.observable)
    kw = dict(t1=args.t1, n_save=args.n_save, rtol=args.rtol, atol=args.atol, max_steps=args.max_steps)
    out = Path(args.out) if args.out else None
    lo, hi = args.bracket
    bar = None
    quiet = getattr(args, "quiet", False)
    if not quiet:
        from .progress_bars import LocatorProgressBar

        bar = LocatorProgressBar()
    try:
        found, boundary, res = _run_locator(args, scenario, observable, along_values, lo, hi, out, kw, bar)
    finally:
        if bar is not None:
            bar.close()
    for b in found:
        print(b.summary())
    classes = _classify_cli(args, scenario, found, boundary, kw) if getattr(args, "classify", False) else None
    return _write_cli(args, scenario, overrides, found, boundary, res, out, classes)


def _classify_cli(args, scenario, found, boundary, kw) -> list:
    """`classify_change` for every located value (at its own --along value when tracing); printed."""
    from .classify import classify_change

    scenarios = [scenario] * len(found)
    if boundary is not None:
        scenarios = [
            set_param(scenario, boundary.along, q)
            for q, b in zip(boundary.along_values, boundary.points, strict=True)
            if b is not None
        ]
    classes = []
    for sc, b in zip(scenarios, found, strict=True):
        c = classify_change(sc, b, **kw)
        print("  " + c.summary())
        classes.append(c)
    return classes


def _run_locator(args, scenario, observable, along_values, lo, hi, out, kw, bar):
    boundary = res = None
    quiet = getattr(args, "quiet", False)
    if (args.along is None) != (args.along_values is None):
        raise ScenarioError("--along and --along-values go together")
    if args.along is not None and args.scan:
        raise ScenarioError("--along traces one boundary from --bracket; it does not combine with --scan")
    if args.along is not None:
        boundary = trace_boundary(
            scenario,
            args.param,
            (lo, hi),
            args.along,
            along_values,
            observable,
            level=args.level,
            tol=args.tol,
            method=args.method,
            progress=bar,
            **kw,
        )
        if bar is not None:
            bar.close()
        found = [b for b in boundary.points if b is not None]
        for r in boundary.rows():
            v = "lost or not found" if r["value"] is None else f"{r['value']:.10g}"
            print(f"{args.along} = {r['along_value']:.6g}: {args.param}* = {v}")
        print(f"{boundary.n_solves} solves in all; a dense grid at {args.tol:g}: {boundary.n_dense}")
    elif args.scan:
        name = _resolve_one(observable).name
        res = scan(
            scenario,
            {args.param: np.linspace(lo, hi, args.scan)},
            observables={name: observable},
            out_dir=None if out is None else out / "scan",
            progress=not quiet,
            **kw,
        )
        found = locate_jumps(
            scenario, res, name, level=args.level, tol=args.tol, method=args.method, progress=bar, **kw
        )
        if bar is not None:
            bar.close()
        print(
            f"{len(find_jumps(res, name))} candidate jumps"
            + ("" if args.level is None else f" and {len(find_crossings(res, name, args.level))} crossings")
            + f" of {name} in {args.scan} points; located {len(found)}:"
        )
    else:
        found = [
            locate_bifurcation(
                scenario,
                args.param,
                observable,
                (lo, hi),
                level=args.level,
                tol=args.tol,
                method=args.method,
                progress=bar,
                **kw,
            )
        ]
    return found, boundary, res


def _write_cli(args, scenario, overrides, found, boundary, res, out, classes=None) -> int:
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        rec = {
            "scenario": scenario.name,
            "overrides": overrides,
            "command": getattr(args, "argv", sys.argv),
            "bifurcations": [b.to_dict() for b in found],
        }
        if classes is not None:
            for d, c in zip(rec["bifurcations"], classes, strict=True):
                d["classification"] = c.to_dict()
        if boundary is not None:
            rec["boundary"] = {
                "param": boundary.param,
                "along": boundary.along,
                "rows": boundary.rows(),
                "n_solves": boundary.n_solves,
                "n_dense": boundary.n_dense,
            }
        (out / "bifurcation.json").write_text(json.dumps(rec, indent=1, default=float) + "\n")
        print(f"wrote {out / 'bifurcation.json'}")
        if not args.no_plots:
            from .plots import save_figure
            from .scan_plots import plot_boundary, plot_locator, save_scan_plots

            pngs = [save_figure(plot_locator(b), out / f"locator_{k}.png") for k, b in enumerate(found)]
            if boundary is not None:
                pngs.append(save_figure(plot_boundary(boundary), out / "boundary.png"))
            if args.scan:
                pngs += save_scan_plots(res, out, located=found)
            print(f"wrote {len(pngs)} PNGs in {out}")
    complete = boundary is None or bool(np.all(np.isfinite(boundary.values)))
    return 0 if complete and all(b.converged for b in found) else 1
