"""Continuation of a two-parameter boundary: `trace_boundary` follows p*(q) with a secant predictor and
`locate_bifurcation` as the corrector, instead of a dense grid in (p, q)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from ..._errors import ScenarioError
from ..._io.validate import brief, check_param_path, parse_values
from ..._numerics.options import SolverOptions
from ..._numerics.solve import checked_scenario
from ..._numerics.times import TimesLike, as_times
from ..._physics.params import Scenario
from ..._physics.paths import parse_path, set_param
from ..scan.sweep import validate_members
from .eval import resolve_one
from .jumps import Jump
from .locate import check_bracket, check_level, locate_bifurcation
from .options import SearchOptions, settings
from .result import BifurcationError, Boundary


def trace_boundary(
    scenario: Scenario,
    param: str,
    bracket: tuple[float, float] | Jump,
    along: str,
    along_values: Sequence[float] | np.ndarray | str,
    observable,
    *,
    level: float | None = None,
    search: SearchOptions | None = None,
    options: SolverOptions | None = None,
    times: TimesLike = None,
    progress: Callable[[dict], None] | None = None,
) -> Boundary:
    """Follow the boundary p*(q) in the (p, q) plane by continuation, not a dense grid.

    At `along_values[0]`, p* is located in `bracket`. At each next q the predictor extrapolates the last two
    points linearly (a secant along the boundary), and the corrector brackets the prediction by
    ±w (w = half the last change of p*, at least 20 tol; at the second point `search.initial_half_width`,
    default 5 % of `bracket`; doubled up to `search.max_expansions` times until the indicator changes sign)
    and refines it with `locate_bifurcation`. With `level=None` the level is re-estimated in each bracket,
    so the corrector always finds *some* crossing; a point whose change across its final bracket is below
    `search.min_jump_fraction` of the first point's is therefore reported as lost (NaN, with a note on the
    point): the jump has vanished or moved out of reach there, and a level crossing of a nearly flat
    observable is not the boundary.

    **Arguments**
    - `scenario`, `param`, `bracket`, `observable`, `level`: as in `locate_bifurcation`, at q =
      `along_values[0]`.
    - `along`, `along_values`: the continuation parameter's path and its values q [its unit] (at least one;
      finite and distinct; a sequence, an array or text "start:stop:num" / "v1,v2,..."; see
      `check_along`).
    - `search`: `SearchOptions` (method, tol, max_solves of each point; the corrector's bracketing).
    - `options`: `SolverOptions` (default `SolverOptions(diffrax.Tsit5())`, as in `locate_bifurcation`).
    - `times`: the saved times, a `Times(t1, n, ts)` (a number is t1 [s], a 1-D array ts [s]), as in
      `locate_bifurcation` (default 201 equally spaced times from 0 to the scenario's t1).
    - `progress` (default None: silent) receives every report of the inner `locate_bifurcation` calls, with
      `point` (index k of q), `n_points` and `along_value` (q) added.

    **Returns** a `Boundary`.

    **Raises** `ScenarioError` on invalid input, before any solve: as `locate_bifurcation` (the bracket,
    `level`, a vector observable), and `check_along` (the continuation parameter and its values).
    """
    times = as_times(times)
    search, options = settings(search, options)
    scenario = checked_scenario(scenario)
    check_param_path(scenario, param, "param")
    qs = check_along(scenario, param, along, along_values)
    lo, hi = check_bracket(bracket)
    level = check_level(level)
    # the bracket's ends at the first q are checked by the first point's locate_bifurcation, before it
    # solves (its ScenarioError is raised, not taken for a lost point)
    obs = resolve_one(observable)
    tol = search.tol
    ps: list[float] = []
    points: list = []
    n_solves = 0
    ref_size = None
    for k, q in enumerate(qs):
        sc = set_param(scenario, along, q)
        inner: Callable[[dict], None] | None = None
        if progress is not None:

            def with_point(d, k=k, q=q):
                progress(d | {"point": k, "n_points": int(qs.size), "along_value": float(q)})

            inner = with_point

        pt = None
        for br in _candidate_brackets(qs, ps, k, q, lo, hi, search):
            try:
                pt = locate_bifurcation(
                    sc,
                    param,
                    obs,
                    br,
                    level=level,
                    search=search,
                    options=options,
                    times=times,
                    progress=inner,
                )
                break
            except BifurcationError as e:  # no sign change in this bracket: widen it
                n_solves += e.n_solves
            except ScenarioError:  # the widened bracket left the valid range of the parameter
                if k == 0:  # the given bracket and level: an invalid input, not a lost point
                    raise
                break
        lost = False
        if pt is not None:
            n_solves += pt.n_solves
            size = abs(pt.y_hi - pt.y_lo)
            if level is None and ref_size is None:
                ref_size = size
            elif level is None and ref_size is not None and not size >= search.min_jump_fraction * ref_size:
                lost = True
                pt.notes.append(
                    f"lost: the change across the final bracket, {size:.3g}, is below "
                    f"{search.min_jump_fraction:g} x the first point's {ref_size:.3g}; not the traced jump"
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


def check_along(
    scenario: Scenario,
    param: str,
    along: str,
    along_values,
    where: tuple[str, str] = ("along", "along_values"),
) -> np.ndarray:
    """The continuation values q [unit of `along`], checked before any solve.

    **Arguments**
    - `scenario`, `param`: the base scenario and the located parameter's path.
    - `along`: the continuation parameter's path: a float leaf (or a component of one) other than `param`.
    - `along_values`: its values, a 1-D sequence or array, or text as `scan`'s `--values` ("start:stop:num",
      inclusive, or "v1,v2,..."): finite and distinct, in any order (the secant predictor divides by the
      step between two of them), each valid for the scenario (its range checks, as a scan member's).
    - `where`: the names of the two arguments (or flags) for the messages.

    **Returns** the values as a 1-D float64 array.

    **Raises** `ScenarioError` naming the argument.
    """
    f_along, f_values = where
    check_param_path(scenario, along, f_along)
    if parse_path(str(along)) == parse_path(str(param)):
        raise ScenarioError(
            f"{f_along} {along!r} is the located parameter itself; continue along another parameter"
        )
    qs = parse_values(along_values, f_values)
    if not np.all(np.isfinite(qs)):
        raise ScenarioError(f"{f_values} must be finite numbers, got {brief(qs)}")
    if np.unique(qs).size != qs.size:
        raise ScenarioError(f"{f_values} must be distinct values (a value repeats), got {brief(qs)}")
    bad = validate_members(scenario, [along], qs[:, None])
    if bad:
        i, msg = min(bad.items())
        raise ScenarioError(f"{f_values}: {along} = {qs[i]:g} is invalid: {msg}")
    return qs


def _candidate_brackets(qs, ps, k, q, lo, hi, search: SearchOptions) -> list[tuple[float, float]]:
    """The corrector's brackets at q = qs[k], narrowest first: the initial bracket until a point is found;
    then ±w around the secant prediction from the last two points (or the last point), doubled
    `search.max_expansions` - 1 times."""
    tol = search.tol
    good = [(qq, pp) for qq, pp in zip(qs[:k], ps, strict=True) if np.isfinite(pp)]
    if not good:
        return [(lo, hi)]
    if len(good) >= 2:  # secant predictor along the boundary
        (q0, p0), (q1, p1) = good[-2], good[-1]
        pred = p1 + (p1 - p0) * (q - q1) / (q1 - q0)
        w = max(20 * tol, 0.5 * abs(p1 - p0))
    else:
        pred = good[-1][1]
        hw = search.initial_half_width
        w = max(20 * tol, hw if hw else 0.05 * (hi - lo))
    return [(pred - w * 2**i, pred + w * 2**i) for i in range(search.max_expansions)]
