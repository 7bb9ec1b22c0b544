"""Name a located change of character for what it is.

`find_jumps` / `locate_bifurcation` report *where* an observable changes abruptly; this module says *what*
changes there, in one of five words:

- **final-state jump**: the state at t1 (x, y, φ, ϑ, ψ of the mass centre and the Euler angles) is
  discontinuous at p*: most of its change across a window around p* happens inside the final bracket
  (width ~1e-6) — two distinct motions meet there;
- **steep ramp**: the final state changes fast but continuously; `width` is the parameter interval over
  which it moves from 10 % to 90 % of its change across the window (resolved by a grid finer than that);
- **event-count change**: a corner hops or lands once more or once less (the impact count differs at the
  two ends of the bracket) while the final state stays continuous — a grazing contact;
- **event-definition change**: the first instant with all four corners off the ground (`liftoff_time`)
  jumps while the last contact (`last_contact_time`) and the final state do not: a momentary all-off
  instant appears or disappears before the real lift-off, and only which instant is *called* lift-off moves;
- **continuous crossing**: none of the above (a level crossing of a smooth observable).

A change can show several of these at once (a final-state jump usually changes the impact count too); the
`kind` is the first that applies in the order above, except that for an event-time observable the
event-definition test comes before the count, and `facets` lists every one that applies.

    import jaxhoist as jh
    b = jh.locate_bifurcation(sc, "foundation.friction_coefficient", "liftoff_time", (0.4721, 0.4723),
                              times=jh.Times(25.0, n=2501))
    c = jh.classify_change(sc, b, times=jh.Times(25.0, n=2501))
    print(c.summary())

`classify_samples` is the pure part (arrays in, `ChangeClass` out), for samples you already have.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..._errors import ScenarioError
from ..._numerics.options import SolverOptions
from ..._numerics.times import Times, TimesLike, as_times
from ..scan.layout import BatchOptions

FINAL_STATE = ("final_x", "final_y", "final_phi", "final_theta", "final_psi")
EVENT_TIMES = ("liftoff_time", "last_contact_time")
COUNT = "impacts"
OBSERVABLES = (*FINAL_STATE, *EVENT_TIMES, COUNT)
# what counts as a material change of each final-state coordinate (m or rad): 1 cm, 1 degree
_MATERIAL = {
    "final_x": 0.01,
    "final_y": 0.01,
    "final_phi": np.radians(1.0),
    "final_theta": np.radians(1.0),
    "final_psi": np.radians(1.0),
}

#: The number of saved times of `classify_change` when `Times.n` is None (every ~10 ms over 25 s).
DEFAULT_N = 2501

KINDS = (
    "final-state jump",
    "steep ramp",
    "event-count change",
    "event-definition change",
    "continuous crossing",
)


@dataclasses.dataclass
class ChangeClass:
    """What changes at a located p*.

    - `kind`: one of `KINDS`; `facets`: every kind that applies (the first is `kind`).
    - `param`, `value` (p*), `bracket`: where; `observable`: what was located.
    - `width`: for a steep ramp, the parameter interval over which the final-state coordinate with the
      largest change goes from 10 % to 90 % of its change across the window (`ramp_observable`); else None.
    - `jump_fractions`: per final-state coordinate, |change inside the bracket| / |change across the window|.
    - `count_change`: impacts at the bracket's (lo, hi) ends; `event_jumps`: per event time, its change
      across the bracket [s].
    - `window`: the parameter interval of the samples; `n_samples`; `notes`.
    """

    kind: str
    facets: list
    param: str
    value: float
    bracket: tuple
    observable: str
    width: float | None = None
    ramp_observable: str | None = None
    jump_fractions: dict = dataclasses.field(default_factory=dict)
    count_change: tuple | None = None
    event_jumps: dict = dataclasses.field(default_factory=dict)
    window: tuple | None = None
    n_samples: int = 0
    notes: list = dataclasses.field(default_factory=list)

    def summary(self) -> str:
        s = f"{self.param} = {self.value:.7g} ({self.observable}): {self.kind}"
        if self.width is not None:
            s += f" of width {self.width:.2g} (10-90 % of {self.ramp_observable})"
        if self.count_change is not None and self.count_change[0] != self.count_change[1]:
            s += f"; impacts {self.count_change[0]:g} -> {self.count_change[1]:g}"
        ev = ", ".join(f"{k} {v:+.3g} s" for k, v in self.event_jumps.items() if np.isfinite(v) and v != 0.0)
        if ev:
            s += f"; across the bracket {ev}"
        others = [f for f in self.facets[1:]]
        if others:
            s += f" (also: {', '.join(others)})"
        return s

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        return json_safe(d)  # pyright: ignore[reportReturnType]  # json_safe keeps a dict a dict


def json_safe(x):
    """Plain JSON values: tuples to lists, numpy scalars to floats, ±inf/NaN to strings."""
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return str(x)
    return x


def ramp_width(x, y, lo: float = 0.1, hi: float = 0.9) -> float:
    """The parameter interval over which y(x) goes from `lo` to `hi` of its change y[-1] - y[0]
    (linear interpolation; x sorted). For a non-monotone y the first entry above `lo` and the last entry
    below `hi` bound it. NaN if y does not change."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    d = y[-1] - y[0]
    if not np.isfinite(d) or d == 0.0:
        return float("nan")
    u = (y - y[0]) / d
    i = int(np.argmax(u >= lo))  # first sample at or above lo
    above_hi = np.nonzero(u < hi)[0]
    j = int(above_hi[-1]) + 1 if above_hi.size else 0  # first sample after the last one below hi
    j = min(j, x.size - 1)

    def cross(k, level):
        if k == 0:
            return x[0]
        u0, u1 = u[k - 1], u[k]
        return x[k - 1] + (level - u0) / (u1 - u0) * (x[k] - x[k - 1]) if u1 != u0 else x[k]

    return float(max(cross(j, hi) - cross(i, lo), 0.0))


def _relocate(x, y, i_lo, i_hi):
    """Indices of the window cell to classify instead of the given bracket, or None: when the located
    observable `y` has one step between neighbouring samples that holds more than half its range over the
    window (a jump) and changes by less than a tenth of that across the given bracket."""
    if y is None:
        return None
    y = np.where(np.isfinite(y), y, np.nan)
    if np.all(np.isnan(y)):
        return None
    steps = np.abs(np.diff(y))
    if not np.any(np.isfinite(steps)):
        return None
    k = int(np.nanargmax(steps))
    span = float(np.nanmax(y) - np.nanmin(y))
    inner = abs(y[i_hi] - y[i_lo])
    if not (span > 0 and steps[k] > 0.5 * span and not inner >= 0.1 * steps[k]):
        return None
    return k, k + 1


def _bracket_indices(x, ys, bracket, observable, notes) -> tuple[int, int, float, float]:
    """(i_lo, i_hi, lo, hi): the bracket's ends among the sorted samples `x`, moved to where `observable`
    does jump in these solves if it does not across the given bracket (with a note)."""
    lo, hi = float(bracket[0]), float(bracket[1])
    try:
        i_lo = int(np.nonzero(x == lo)[0][0])
        i_hi = int(np.nonzero(x == hi)[0][0])
    except IndexError:
        raise ScenarioError("classify_samples: the samples must include both ends of the bracket") from None
    moved = _relocate(x, ys.get(observable), i_lo, i_hi)
    if moved is not None:
        i_lo, i_hi = moved
        notes.append(
            f"{observable} does not jump across the given bracket [{lo:.10g}, {hi:.10g}] in these solves, "
            f"but in [{x[i_lo]:.10g}, {x[i_hi]:.10g}]: classified there (rounding in another vmapped group "
            f"can move a jump of a long history by more than a narrow bracket)"
        )
        lo, hi = float(x[i_lo]), float(x[i_hi])
    return i_lo, i_hi, lo, hi


def _final_state_changes(ys, i_lo, i_hi) -> tuple[dict[str, float], dict[str, float]]:
    """(fractions, window_change): per final-state coordinate, the fraction of its change across the
    window that happens inside the bracket, and that change [its unit]."""
    fractions: dict[str, float] = {}
    window_change: dict[str, float] = {}
    for name in FINAL_STATE:
        if name not in ys:
            continue
        y = ys[name]
        full = abs(y[-1] - y[0])
        inner = abs(y[i_hi] - y[i_lo])
        window_change[name] = full
        fractions[name] = float(inner / full) if full > 0 else 0.0
    return fractions, window_change


def _ramp(x, ys, window_change, notes) -> tuple[float | None, str | None]:
    """(width, observable) of a ramp: the coordinate that changes most (in units of its material size)
    changes materially across the window; its 10-90 % width [unit of the parameter]. (None, None) where
    there is none, or the change is spread over more than half the window (with a note)."""
    width = ramp_obs = None
    if window_change:
        ramp_obs = max(window_change, key=lambda n: window_change[n] / _MATERIAL[n])
        if window_change[ramp_obs] > 10 * _MATERIAL[ramp_obs]:
            width = ramp_width(x, ys[ramp_obs])
            if not width < 0.5 * (x[-1] - x[0]):  # spread over the window: a gradual change, not a ramp
                notes.append(
                    f"{ramp_obs} changes across the window but gradually (10-90 % over {width:.2g}, "
                    f"more than half the window): no steep ramp"
                )
                width = None
        if width is None:
            ramp_obs = None
    return width, ramp_obs


def _event_jumps(ys, i_lo, i_hi) -> dict[str, float]:
    """Per event time, its change across the bracket [s] (inf where it appears or disappears)."""
    events = {}
    for name in EVENT_TIMES:
        if name in ys:
            a, b = ys[name][i_lo], ys[name][i_hi]
            events[name] = (
                float(b - a) if (np.isfinite(a) and np.isfinite(b)) else (0.0 if a == b else float("inf"))
            )
    return events


def _facets(observable, jumped, counts, events, width, event_tol) -> list[str]:
    """The names that apply to the change, the one that names it first."""
    facets: list[str] = []

    def ev_jumps(name):
        return name in events and abs(events[name]) > event_tol

    definition = (
        ev_jumps("liftoff_time")
        and "last_contact_time" in events
        and not ev_jumps("last_contact_time")
        and not jumped
    )
    count = counts is not None and counts[0] != counts[1]
    if jumped:
        facets.append("final-state jump")
    is_event_obs = observable in EVENT_TIMES or observable.startswith(("detachment", "impact_times"))
    if definition and is_event_obs:
        facets.append("event-definition change")
    if count:
        facets.append("event-count change")
    if definition and not is_event_obs:
        facets.append("event-definition change")
    if width is not None and not jumped and np.isfinite(width):
        # a ramp is the name for a located final-state change; beside an event change it is a facet
        if observable in FINAL_STATE or not facets:
            facets.insert(0, "steep ramp")
        else:
            facets.append("steep ramp")
    if not facets:
        facets.append("continuous crossing")
    return facets


def classify_samples(
    x,
    samples: Mapping[str, Any],
    bracket: tuple[float, float],
    *,
    observable: str = "final_psi",
    param: str = "p",
    jump_fraction: float = 0.5,
    event_tol: float = 0.01,
) -> ChangeClass:
    """Classify a change located in `bracket` from samples of the observables around it.

    **Arguments**
    - `x`: parameter values (sorted or not), including the two ends of `bracket`, spread over a window
      around it (the window's ends define "the change" the fractions and the ramp width refer to).
    - `samples`: observable name -> values at `x` (any of `OBSERVABLES`; missing ones are skipped).
    - `bracket`: (lo, hi), the located change's final bracket.
    - `observable`: the located observable's name (decides whether the event-definition test comes first).
    - `jump_fraction`: a final-state coordinate jumps if more than this fraction of its change across the
      window, and more than 1 cm / 1°, happens inside the bracket.
    - `event_tol`: an event time "jumps" across the bracket if it moves by more than this [s].
    """
    x = np.asarray(x, dtype=np.float64)
    order = np.argsort(x, kind="stable")
    x = x[order]
    ys = {k: np.asarray(v, dtype=np.float64)[order] for k, v in samples.items()}
    notes: list[str] = []
    i_lo, i_hi, lo, hi = _bracket_indices(x, ys, bracket, observable, notes)
    fractions, window_change = _final_state_changes(ys, i_lo, i_hi)
    jumped = [
        n for n in fractions if fractions[n] > jump_fraction and abs(ys[n][i_hi] - ys[n][i_lo]) > _MATERIAL[n]
    ]
    width, ramp_obs = _ramp(x, ys, window_change, notes)
    counts = None
    if COUNT in ys:
        counts = (float(ys[COUNT][i_lo]), float(ys[COUNT][i_hi]))
    events = _event_jumps(ys, i_lo, i_hi)
    facets = _facets(observable, jumped, counts, events, width, event_tol)
    if jumped:
        notes.append(f"jumping: {', '.join(jumped)}")
        width = None
        ramp_obs = None
    elif width is not None and facets[0] != "steep ramp":
        notes.append(
            f"the final state varies across the window ({ramp_obs} 10-90 % over {width:.2g}), continuously"
        )
    return ChangeClass(
        kind=facets[0],
        facets=facets,
        param=param,
        value=0.5 * (lo + hi),
        bracket=(lo, hi),
        observable=observable,
        width=width if facets[0] == "steep ramp" else None,
        ramp_observable=ramp_obs if facets[0] == "steep ramp" else None,
        jump_fractions=fractions,
        count_change=counts,
        event_jumps=events,
        window=(float(x[0]), float(x[-1])),
        n_samples=int(x.size),
        notes=notes,
    )


def classify_change(
    scenario,
    change=None,
    *,
    param: str | None = None,
    bracket: tuple[float, float] | None = None,
    observable: str | None = None,
    half_window: float | None = None,
    n_window: int = 41,
    times: TimesLike = None,
    options: SolverOptions | None = None,
    batch: BatchOptions | None = None,
) -> ChangeClass:
    """Classify a located change by solving around it.

    **Arguments**
    - `scenario`: the scenario the change was located in.
    - `change`: a `Bifurcation` (from `locate_bifurcation`) or a `Jump` (from `find_jumps`); or give
      `param`, `bracket` (and `observable`, default "final_psi") instead.
    - `half_window`: the window p* ± `half_window` sampled with `n_window` uniform points besides the two
      bracket ends (points inside the bracket are dropped; default: 100 bracket widths, at least 1 % of
      |p*|).
    - `times` (`Times(t1, n, ts)`, a number t1 [s] or an array ts [s]; default 2501 equally spaced times
      from 0 to the scenario's t1), `options` (`SolverOptions`) and `batch` (`BatchOptions`; the members are
      always solved in the order given) go to `scan`; save every ~10 ms (the default 2501 over 25 s) so
      event times and counts are read reliably.

    **Returns** a `ChangeClass` (`classify_samples` on the solves).
    """
    from ..scan.run import Sweep, scan

    if change is not None:
        param = change.param if param is None else param
        observable = change.observable if observable is None else observable
        if bracket is None:
            bracket = tuple(change.bracket) if hasattr(change, "bracket") else (change.lo, change.hi)
    if param is None or bracket is None:
        raise ScenarioError("classify_change needs a located change, or param= and bracket=")
    observable = observable or "final_psi"
    lo, hi = float(bracket[0]), float(bracket[1])
    mid = 0.5 * (lo + hi)
    if half_window is None:
        half_window = max(100 * (hi - lo), 0.01 * abs(mid), 1e-6)
    xs = np.linspace(mid - half_window, mid + half_window, n_window)
    xs = np.unique(np.concatenate([xs[(xs < lo) | (xs > hi)], [lo, hi]]))  # the bracket's ends are neighbours
    times = as_times(times)
    if times.n is None and times.ts is None:
        times = Times(times.t1, n=DEFAULT_N)
    batch = dataclasses.replace(BatchOptions() if batch is None else batch, sort=False)
    res = scan(
        scenario,
        Sweep(param, xs),
        times,
        observables=list(OBSERVABLES),
        options=options,
        batch=batch,
    )
    if not np.all(res.ok):
        raise ScenarioError(f"classify_change: solves failed: {res.failures()[:2]}")
    samples = {k: np.asarray(res[k]) for k in OBSERVABLES}
    return classify_samples(xs, samples, (lo, hi), observable=observable, param=param)
