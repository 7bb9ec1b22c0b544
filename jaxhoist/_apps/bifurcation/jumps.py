"""Candidate changes of character on a 1-D scan, before any refinement: `find_jumps` (steps much larger than
their neighbours') and `find_crossings` (neighbours on opposite sides of a level), both returning `Jump`
brackets for `locate_bifurcation`."""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from ..._errors import ScenarioError
from ..._io.validate import brief, finite_number, whole_number
from ..scan.result import ScanResult


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


def _series(result: object, observable: str, param: str | None, who: str):
    """(param, x, y): a scalar observable of a 1-D scan against its parameter, valid members only, sorted.

    **Raises** `TypeError` for a `result` that is no `ScanResult` (a saved scan's path among them);
    `ScenarioError` for a `param` or `observable` the scan does not have, a grid, a vector observable."""
    if not isinstance(result, ScanResult):
        load = " (a saved scan: load it with jaxhoist.ScanResult.load(path) first)"
        raise TypeError(
            f"{who}: result must be a jaxhoist.ScanResult, got {type(result).__name__}"
            + (load if isinstance(result, str | os.PathLike) else "")
        )
    if len(result.params) != 1 and param is None:
        raise ScenarioError(f"{who}: the scan has parameters {list(result.params)}; say which with param=")
    if param is not None and param not in result.params:
        raise ScenarioError(f"{who}: param {param!r} is not a parameter of the scan: {list(result.params)}")
    param = result.params[0] if param is None else param
    if result.mode == "grid" and len(result.params) > 1:
        raise ScenarioError(f"{who} works along a 1-D scan; take a slice of the grid first")
    if observable not in result.data:
        raise ScenarioError(
            f"{who}: observable {observable!r} is not an observable of the scan: {list(result.data)}"
        )
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


def _check_jump_settings(factor, window, min_size) -> None:
    """Refuse `find_jumps` settings that would silently find nothing (a NaN `factor`) or anything."""
    f = finite_number(factor)
    if f is None or f <= 0:
        raise ScenarioError(f"find_jumps: factor must be a finite number > 0, got {brief(factor)}")
    if not (whole_number(window) and int(window) >= 1):
        raise ScenarioError(f"find_jumps: window must be a whole number >= 1, got {brief(window)}")
    m = finite_number(min_size)
    if min_size is not None and (m is None or m < 0):
        raise ScenarioError(
            f"find_jumps: min_size must be a finite number >= 0 (or None: 1e-6 of the observable's range), "
            f"got {brief(min_size)}"
        )


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
    if finite_number(level) is None:
        raise ScenarioError(f"find_crossings: level must be a finite number, got {brief(level)}")
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

    **Arguments**
    - `result`: a 1-D `ScanResult` (`scan`'s result, or `ScanResult.load` of a saved one).
    - `observable`: the name of a scalar observable of the scan; `param`: the swept parameter (needed when
      the scan has several).
    - `factor`: how many times the median neighbouring step a candidate step is, a finite number > 0.
    - `window`: neighbours on either side of a step that set its median, a whole number >= 1.
    - `min_size`: the smallest candidate step [unit of the observable], finite and >= 0 (default None:
      1e-6 of the observable's range).

    **Returns** the candidates sorted by parameter value.

    **Raises** `ScenarioError` naming the argument for an invalid `factor`, `window`, `min_size`, `param` or
    `observable`; `TypeError` for a `result` that is no `ScanResult`.
    """
    _check_jump_settings(factor, window, min_size)
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
