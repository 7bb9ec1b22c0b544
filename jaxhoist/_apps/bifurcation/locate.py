"""Where does the motion change character? `locate_bifurcation` refines a bracket around a change of an
observable to a tolerance, with derivative-accelerated root finding; `locate_jumps` does it for every
candidate jump of a scan.

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
  so the safeguard falls back to bisection, ~log2(width/tol) solves; `Multisection()` instead solves
  k points per round in one vmapped call (more solves, fewer rounds of wall time).

Either way the result reports how many solves it took against a uniform grid of the same resolution.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from ..._errors import ScenarioError, require_x64
from ..._io.validate import brief, finite_number
from ..._numerics.options import SolverOptions
from ..._numerics.solve import checked_scenario
from ..._numerics.times import TimesLike, as_times
from ..._physics.params import Scenario
from ..._physics.paths import check_path, param_unit, set_param
from ..scan.result import ScanResult
from .eval import Evaluator, Problem, indicator, level_from_ends, resolve_one
from .jumps import Jump, find_crossings, find_jumps
from .multisection import multisection
from .options import Multisection, Newton, SearchOptions, settings
from .result import Bifurcation, BifurcationError

#: The number of saved times of `locate_bifurcation` and `trace_boundary` when `Times.n` is None.
DEFAULT_N = 201


def locate_bifurcation(
    scenario: Scenario,
    param: str,
    observable,
    bracket: tuple[float, float] | Jump,
    *,
    level: float | None = None,
    search: SearchOptions | None = None,
    options: SolverOptions | None = None,
    times: TimesLike = None,
    progress: Callable[[dict], None] | None = None,
) -> Bifurcation:
    """Refine a change of character of `observable` in `param` to a bracket no wider than `search.tol`.

    **Arguments**
    - `scenario`, `param`: the base scenario and a parameter path (as in `scan`, e.g.
      "foundation.friction_coefficient", "hoist.speed", "rope.stiffness", "load.mass_centre[0]").
    - `observable`: a built-in name (a scalar one, or a component such as "final_euler[1]"), a callable
      `fn(traj[, scenario])` or an `Observable`.
    - `bracket`: (lo, hi) [unit of the parameter] with the two kinds of motion at its ends (e.g. a `Jump`
      from `find_jumps`).
    - `level`: the indicator is g = observable - level [unit of the observable]; default the midpoint of the
      values at the ends (0 is natural for an event-time difference).
    - `search`: `SearchOptions(method, tol, max_solves)`: `Newton()` (default; safeguarded Newton on g with
      dg/dp from forward-mode sensitivities, bisection whenever a Newton step leaves the bracket or does not
      shrink it fast enough), `Bisection()` (value-only solves) or `Multisection(points_per_round, lanes)`
      (that many values per round in one vmapped `scan`); `tol` the final bracket width [unit of the
      parameter] (default 1e-6); give up (converged=False) after `max_solves` solves (default 200).
    - `options`: `SolverOptions`; default `SolverOptions(diffrax.Tsit5())` (rtol 1e-6, atol 1e-8), not the
      Rosenbrock-W default of `simulate`: on the paper's §4.3 change it located μ* 40x closer to the
      reference in half the time (`options.default_solver_options`, docs/bifurcation.md).
    - `times`: the saved times, a `Times(t1, n, ts)` as in `simulate` (a number is t1 [s], a 1-D array ts
      [s]); default `Times()`: 201 equally spaced times from 0 to the scenario's t1.
    - `progress`: called on the host after every evaluation (every round for multisection) with a dict:
      `iteration` (1, 2, ...: evaluations, or rounds), `param` (the value just solved; the round's values
      for multisection), `value` (the observable there), `indicator` (g), `kind` ("end", "newton",
      "bisect", "multisection"), `bracket` (lo, hi) after the update, `width`, `tol`, `n_solves`,
      `elapsed` [s]. Default None: silent.

    **Returns** a `Bifurcation`.

    **Raises** `ScenarioError` on invalid input (before compiling: the bracket, a level that is not a finite
    number, a vector observable, a bracket end outside the parameter's valid range); `BifurcationError` if
    g has the same sign at both ends, or a solve fails.
    """
    times = as_times(times)
    search, options = settings(search, options)
    require_x64()
    wall0 = time.perf_counter()
    scenario = checked_scenario(scenario)
    check_path(scenario, param)
    lo, hi = check_bracket(bracket)
    level = check_level(level)
    for v in (lo, hi):
        set_param(scenario, param, v).check()
    obs = resolve_one(observable)
    ts = jnp.asarray(times.resolve(scenario, DEFAULT_N)[1], dtype=jnp.float64)
    n_uniform = int(math.ceil((hi - lo) / search.tol)) + 1
    unit = param_unit(scenario, param)
    p = Problem(scenario, param, obs, lo, hi, level, search, ts, options, unit, n_uniform, wall0, progress)
    if isinstance(search.method, Multisection):
        return multisection(p)
    return _refine(p)


def check_bracket(bracket, where: str = "bracket") -> tuple[float, float]:
    """(lo, hi) of a bracket [unit of the parameter], checked before any solve: two finite numbers lo < hi
    (or a `Jump` from `find_jumps`, its `lo` and `hi`).

    **Arguments**
    - `bracket`: the bracket as given; `where`: the argument or flag it came from, for the message.

    **Raises** `ScenarioError` naming `where` for one number, three, text, NaN or inf, or lo >= hi.
    """
    if isinstance(bracket, Jump):
        bracket = (bracket.lo, bracket.hi)
    try:
        if isinstance(bracket, str | bytes):  # "12" would unpack as (1, 2)
            raise TypeError
        lo, hi = (float(b) for b in bracket)
    except (TypeError, ValueError, OverflowError):
        raise ScenarioError(f"{where} must be two numbers lo < hi, got {brief(bracket)}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ScenarioError(f"{where} must be two finite values lo < hi, got {brief(bracket)}")
    return lo, hi


def check_level(level, where: str = "level") -> float | None:
    """The indicator's level [unit of the observable], checked before any solve: None (the midpoint of the
    values at the bracket ends) or a finite number.

    **Raises** `ScenarioError` naming `where` for NaN, ±inf or what is no number.
    """
    if level is None:
        return None
    value = finite_number(level)
    if value is None:
        raise ScenarioError(
            f"{where} must be a finite number (or none: the midpoint of the values at the bracket ends), "
            f"got {brief(level)}"
        )
    return value


class _Reporter:
    """The progress reports of the one-point-at-a-time methods (one solve per evaluation)."""

    def __init__(self, p: Problem):
        self.p, self.n_eval = p, 0

    def __call__(self, x, y, g, tag, br):
        self.n_eval += 1
        if self.p.progress is not None:
            self.p.progress(
                dict(
                    iteration=self.n_eval,
                    param=float(x),
                    value=float(y),
                    indicator=float(g),
                    kind=tag,
                    bracket=(float(br[0]), float(br[1])),
                    width=float(br[1] - br[0]),
                    tol=self.p.tol,
                    n_solves=self.n_eval,  # one solve per evaluation
                    elapsed=time.perf_counter() - self.p.wall0,
                )
            )


def _evaluate(ev: Evaluator, x, use_d: bool):
    """(y, dy/dp or None) at `x`: a forward-mode solve with `use_d`, else a value-only one."""
    if use_d:
        return ev.value_and_slope(x)
    return ev.value(x), None


def _refine(p: Problem) -> Bifurcation:
    """Safeguarded Newton (the rtsafe rule) or bisection: from the last point, take the Newton step if it
    stays inside the bracket and is at most half the step before last; otherwise bisect."""
    ev = Evaluator(p.scenario, p.param, p.obs, p.ts, p.options)
    report = _Reporter(p)
    lo, hi, tol = p.lo, p.hi, p.tol
    use_d = isinstance(p.search.method, Newton)
    y_a, dy_a = _evaluate(ev, lo, use_d)
    y_b, dy_b = _evaluate(ev, hi, use_d)
    y_lo_end = y_a
    lev = level_from_ends(p.level, y_a, y_b)
    g_a, g_b = indicator(y_a, lev, y_lo_end), indicator(y_b, lev, y_lo_end)
    slope_ok = use_d and bool(np.isfinite(lev))
    history: list = [
        (lo, g_a, dy_a if slope_ok else None, "end"),
        (hi, g_b, dy_b if slope_ok else None, "end"),
    ]
    report(lo, y_a, g_a, "end", (lo, hi))
    report(hi, y_b, g_b, "end", (lo, hi))
    if g_a == 0.0 or g_b == 0.0 or np.sign(g_a) == np.sign(g_b):
        raise BifurcationError(
            f"{p.obs.name} - level has the same sign at both ends of the bracket ({p.param} = {lo:g}: "
            f"{y_a:g}, {hi:g}: {y_b:g}, level {lev:g}); give a bracket across the change (see find_jumps)",
            n_solves=2,
        )
    notes: list[str] = []
    # (slope_ok implies derivative solves, so dy_a and dy_b are numbers)
    if slope_ok and dy_a is not None and dy_b is not None and not (np.isfinite(dy_a) or np.isfinite(dy_b)):
        slope_ok = False
        notes.append(
            "forward-mode derivatives are not finite at the bracket ends: bisection with value-only solves"
        )
    a, b, ga, gb = lo, hi, g_a, g_b
    ya, yb = y_a, y_b
    use_d = slope_ok  # no slope information across an event that stops happening: value-only solves
    n_bad_slopes = 0
    x, gx, dgx = (a, ga, dy_a) if abs(ga) <= abs(gb) else (b, gb, dy_b)
    dx_old = dx = b - a
    while b - a > tol and ev.n_value + ev.n_jvp < p.search.max_solves:
        x_new, tag = _next_point(a, b, x, gx, dgx, dx_old, tol, use_d)
        dx_old, dx = dx, abs(x_new - x)  # the step before last, and this one
        x_new = min(max(x_new, a + 0.05 * tol), b - 0.05 * tol)
        y_new, dy_new = _evaluate(ev, x_new, use_d)
        g_new = indicator(y_new, lev, y_lo_end)
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
                f"forward-mode derivatives not finite twice in a row near {p.param} = {x_new:.10g}: "
                f"bisection with value-only solves from there"
            )
    stats = dict(
        n_solves=ev.n_value + ev.n_jvp,
        n_derivative_solves=ev.n_jvp,
        history=history,
        method=p.search.method.name,
        compile_time=ev.compile_time,
        steps=ev.steps,
        notes=notes,
    )
    return p.result(a, b, ya, yb, lev, y_a, y_b, **stats)


def _next_point(a, b, x, gx, dgx, dx_old, tol, use_d) -> tuple[float, str]:
    """The next evaluation point in (a, b): the Newton step from x if it stays inside the bracket and is at
    most half the step before last (`dx_old`), else the midpoint; with its tag "newton" or "bisect"."""
    tag = "bisect"
    x_new = 0.5 * (a + b)
    if use_d and dgx is not None and np.isfinite(dgx) and dgx != 0.0:
        step = -gx / dgx
        if abs(step) < 0.5 * tol:
            # converged to within tol/2: step a little past the root to close the bracket behind it
            step = math.copysign(0.45 * tol, step if step != 0.0 else (b - a))
        if a < x + step < b and abs(step) <= 0.5 * abs(dx_old):
            x_new, tag = x + step, "newton"
    return x_new, tag


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
