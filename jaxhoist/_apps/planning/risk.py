"""`lift_risk`: the probability of each hazard of a lift whose inputs are uncertain, at every point of a
design grid, with confidence intervals, computed by randomised quasi-Monte Carlo on the scan machinery;
`LiftRisk`: its result (probabilities, intervals, quantiles of the observables, failure counts, files)."""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..._errors import ScenarioError, require_x64
from ..._numerics import observables as obs_mod
from ..._numerics.batch import ScanStatus
from ..._numerics.solve import checked_scenario
from ..._numerics.times import TimesLike, as_times
from ..._physics.params import Scenario
from ..._physics.paths import check_path, param_unit
from ..scan import BatchOptions, Grid, Points, ScanResult, Sweep, scan
from ..scan.sweep import validate_members
from .hazards import Hazard
from .uncertain import AbstractDistribution, check_uncertain, sample

#: The file format tag of `LiftRisk.save` and `to_netcdf`.
FORMAT = "jaxhoist-lift-risk-1"


def check_inputs(scenario: Scenario, uncertain) -> dict[str, AbstractDistribution]:
    """What `lift_risk` and `optimise_lift` check first: float64 is on, `scenario` is a valid `Scenario`
    and `uncertain` maps paths of it to distributions (see `check_uncertain`).

    **Returns** the distributions by path.

    **Raises** `TypeError` for a `scenario` that is no `Scenario`; `ScenarioError` naming the field.
    """
    require_x64()
    checked_scenario(scenario)
    dists = check_uncertain(uncertain)
    for p in dists:
        check_path(scenario, p)
    return dists


def lift_risk(
    scenario: Scenario,
    uncertain: Mapping[str, Any],  # checked by check_uncertain, with messages naming the path
    hazards: Hazard | Sequence[Hazard],
    design: Sweep | Grid | Points | Mapping[str, Any] | None = None,
    *,
    samples: int = 512,
    replicates: int = 8,
    times: TimesLike = None,
    seed: int = 0,
    observables: Sequence[Any] = (),
    quantiles: Sequence[float] = (0.05, 0.5, 0.95),
    confidence: float = 0.95,
    max_failed: float = 0.05,
    options=None,
    batch: BatchOptions | None = None,
    progress: bool | Callable | None = None,
) -> LiftRisk:
    """The probability of each hazard of a lift with uncertain inputs, at each design point.

    For every design point (a value of the design parameters: the boom-tip position, the hoist speed, ...)
    the uncertain inputs are sampled `samples` times, every (design point, sample) pair is solved as one
    member of a `jaxhoist.scan` (vmapped, chunked and sharded as scan is), and each hazard's probability
    is the share of the successfully solved samples in which it happens. Every design point sees the same
    samples (common random numbers), so differences between design points are not blurred by sampling
    noise.

    Sampling: randomised quasi-Monte Carlo. `replicates` (R) independent scrambles (Owen-scrambled Sobol
    points, `scipy.stats.qmc.Sobol`, seeded from `seed`) of m = samples / R points each, mapped through each
    distribution's inverse CDF (`Fixed` inputs take no dimension). A power of 2 for m keeps the Sobol
    points balanced.

    Interval: each replicate r gives an unbiased estimate p_r (its share of hazardous members); the
    estimate is their mean p̄ and the interval the Student-t interval over the replicates,
    p̄ ± t_{(1+c)/2, R-1} s / √R (s the sample standard deviation of the p_r, c = `confidence`), clipped to
    [0, 1]. It is honest for randomised QMC because the replicates are independent and identically
    distributed. Where every replicate gives the same share (no member shows the hazard, every member does,
    or the strata of the Sobol points split alike in every scramble) the replicates cannot measure their
    spread and the t-interval would have zero width; the interval is then the exact binomial
    (Clopper-Pearson) one of the pooled count k of N successful members, as if they were independent
    draws (for k = 0: [0, 1 - ((1-c)/2)^(1/N)]), which is wider than the RQMC error.

    Failures: a member whose solve fails (a `ScanStatus` other than OK, e.g. a step budget exhausted, or a
    sample outside a leaf's valid range) is left out and counted: `LiftRisk.n_failed` per design point.
    Probabilities, intervals and quantiles are over the successful members; where more than a share
    `max_failed` of a design point's members failed they are NaN.

    **Arguments**
    - `scenario`: the base `Scenario`.
    - `uncertain`: parameter path -> distribution (`Uniform`, `Normal`, `TruncatedNormal`, `LogNormal`,
      `Fixed`; a plain number is `Fixed`), paths spelled as for `scan` (`"load.mass_centre[0]"`), values in
      the field's SI unit.
    - `hazards`: a `Hazard` or a sequence of them (`slide`, `tilt`, `strike`, `overload`, `swing`,
      `no_liftoff`, or `Hazard(name, observable, threshold, above)`), distinct names.
    - `design`: the design points: `Sweep(path, values)`, `Grid({path: values})`, `Points({path: values})`,
      a mapping path -> values (`Sweep` for one path, `Grid` for several), or None (one design point: the
      scenario as it is). Design paths must differ from the uncertain ones.
    - `samples`: members per design point, a multiple of `replicates` (default 512).
    - `replicates`: independent scrambles, at least 2 (default 8).
    - `times`: the saved times, as for `scan` (a number is t1 [s]; default the scenario's t1 and 201
      times); the observables are read on this grid.
    - `seed`: the seed of the scrambles: the same seed gives the same samples.
    - `observables`: more observables (names, `Observable`s) whose quantiles to report besides those
      of the hazards.
    - `quantiles`: the quantile levels reported for every observable, in [0, 1].
    - `confidence`: the confidence level c of the intervals, in (0, 1).
    - `max_failed`: the largest share of failed members of a design point that still gives numbers.
    - `options`, `batch`, `progress`: as for `scan` (`SolverOptions`, `BatchOptions`, progress lines).

    **Returns** a `LiftRisk`.

    **Raises** `ScenarioError` (a `ValueError`) naming the field for bad distributions, paths, hazards,
    designs or settings, before anything is compiled.
    """
    dists = check_inputs(scenario, uncertain)
    hz = check_hazards(hazards)
    des = _check_design(scenario, design, dists)
    samples, replicates, seed = _check_counts(samples, replicates, seed)
    qs = _check_levels(quantiles, confidence, max_failed)
    t1 = float(np.asarray(as_times(times).resolve(scenario, 201)[1])[-1])
    for h in hz:
        if h.observable_name == "liftoff_time" and h.above and h.threshold > t1:
            raise ScenarioError(
                f"Hazard {h.name!r}: no lift-off by {h.threshold} s cannot be seen in a solve that ends at "
                f"t1 = {t1} s"
            )
    obs = hazard_observables(hz, observables)

    draws = sample(dists, samples, replicates, seed)  # path -> (R, m)
    if des is None:
        d_paths, d_shape, d_mode, d_coords, d_rows = (), (), "none", {}, np.zeros((1, 0))
    else:
        d_paths, d_shape, d_mode = des.params, des.shape, des.mode
        d_coords, d_rows = dict(des.values), des.members()
    n_design = d_rows.shape[0]
    cols = {p: np.repeat(d_rows[:, k], samples) for k, p in enumerate(d_paths)}
    cols.update({p: np.tile(v.ravel(), n_design) for p, v in draws.items()})
    res = scan(
        scenario, Points(cols), times, observables=obs, options=options, batch=batch, progress=progress
    )
    return _summarise(
        res,
        hz,
        dists,
        draws,
        design=(d_mode, d_paths, d_shape, d_coords),
        samples=samples,
        replicates=replicates,
        seed=seed,
        levels=qs,
        confidence=float(confidence),
        max_failed=float(max_failed),
        units={p: param_unit(scenario, p) for p in (*d_paths, *dists)},
    )


# ------------------------------------------------------------------------------------------ checks


def check_hazards(hazards) -> tuple[Hazard, ...]:
    if isinstance(hazards, Hazard):
        hazards = (hazards,)
    if isinstance(hazards, str) or not isinstance(hazards, Sequence):
        raise ScenarioError(f"hazards must be a Hazard or a sequence of them, got {type(hazards).__name__}")
    if not hazards:
        raise ScenarioError("hazards: give at least one Hazard (e.g. jh.slide(0.5), jh.tilt(degrees=10))")
    for h in hazards:
        if not isinstance(h, Hazard):
            raise ScenarioError(f"hazards: every entry must be a Hazard, got {type(h).__name__}")
    names = [h.name for h in hazards]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ScenarioError(f"hazards: names must be distinct, got {dup} more than once (pass name=...)")
    return tuple(hazards)


def _check_design(scenario, design, dists) -> Sweep | Grid | Points | None:
    if design is None:
        return None
    if isinstance(design, Mapping):
        design = Sweep(*next(iter(design.items()))) if len(design) == 1 else Grid(dict(design))
    if not isinstance(design, Sweep | Grid | Points):
        raise ScenarioError(
            f"design must be Sweep, Grid, Points, a mapping path -> values or None, got "
            f"{type(design).__name__}"
        )
    for p in design.params:
        check_path(scenario, p)
        if p in dists:
            raise ScenarioError(f"design: {p!r} is also an uncertain input; a path is one or the other")
    rows = design.members()
    bad = validate_members(scenario, design.params, rows)
    if bad:  # a design point the scenario refuses (a negative knot speed, a tip below the ground, ...)
        i = min(bad)
        at = ", ".join(f"{p} = {v:g}" for p, v in zip(design.params, rows[i], strict=True))
        raise ScenarioError(f"design point {at}: {bad[i]}")
    return design


def _check_counts(samples, replicates, seed) -> tuple[int, int, int]:
    for name, v in (("samples", samples), ("replicates", replicates), ("seed", seed)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer):
            raise ScenarioError(f"{name} must be an integer, got {v!r:.60}")
    if replicates < 2:
        raise ScenarioError(f"replicates must be >= 2 (the interval needs their spread), got {replicates}")
    if samples < 2 * replicates or samples % replicates:
        raise ScenarioError(
            f"samples must be a multiple of replicates = {replicates} and at least {2 * replicates}, "
            f"got {samples}"
        )
    if seed < 0:
        raise ScenarioError(f"seed must be >= 0, got {seed}")
    return int(samples), int(replicates), int(seed)


def _check_levels(quantiles, confidence, max_failed) -> np.ndarray:
    try:
        qs = np.atleast_1d(np.asarray(quantiles, dtype=np.float64))
    except (TypeError, ValueError):
        raise ScenarioError(f"quantiles must be numbers in [0, 1], got {quantiles!r:.60}") from None
    if qs.ndim != 1 or not np.all((qs >= 0) & (qs <= 1)):
        raise ScenarioError(f"quantiles must be numbers in [0, 1], got {quantiles!r:.60}")
    for name, v, lo_open in (("confidence", confidence, True), ("max_failed", max_failed, False)):
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise ScenarioError(f"{name} must be a number, got {v!r:.60}") from None
        ok = (0 < x < 1) if lo_open else (0 <= x <= 1)
        if not ok:
            raise ScenarioError(f"{name} must be in {'(0, 1)' if lo_open else '[0, 1]'}, got {x}")
    return qs


def hazard_observables(hazards, extra) -> dict[str, Any]:
    """Observable name -> observable (a name or an `Observable`) for the scan: the hazards' and `extra`."""
    out: dict[str, Any] = {}
    items = [(h.observable_name, h.observable, f"Hazard {h.name!r}") for h in hazards]
    if isinstance(extra, str):
        extra = (extra,)
    for o in extra:
        name = o if isinstance(o, str) else getattr(o, "name", None)
        if name is None:
            raise ScenarioError(f"observables: give names or Observables, got {type(o).__name__}")
        items.append((name, o, "observables"))
    for name, o, where in items:
        if name in out and not same_observable(out[name], o):
            raise ScenarioError(f"{where}: two different observables are called {name!r}; rename one")
        out[name] = o
    return out


def same_observable(a, b) -> bool:
    """Whether two observables given as names or `Observable`s are one: the same name, the same object, or a
    built-in's name and its own `Observable` (`jh.get_observable(name)`)."""
    if a is b or (isinstance(a, str) and isinstance(b, str)):
        return a == b
    try:
        a, b = (obs_mod.get(o) if isinstance(o, str) else o for o in (a, b))
    except ValueError:  # a name that is no built-in's: not the caller's Observable of that name
        return False
    return a == b


# ------------------------------------------------------------------------------------------ statistics


def _interval(k_rep: np.ndarray, n_ok_rep: np.ndarray, confidence: float):
    """Estimate and interval from the hazardous-member counts `k_rep` (..., R) of the replicates, of
    `n_ok_rep` successful members each: the mean of the replicate shares with the Student-t interval over
    them, or, where every replicate gives the same share, the Clopper-Pearson interval of the pooled count.
    NaN where fewer than two replicates have a successful member."""
    from scipy import stats

    has = n_ok_rep > 0
    r_eff = has.sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        p_rep = np.where(has, k_rep / np.where(has, n_ok_rep, 1), 0.0)
        p = p_rep.sum(axis=-1) / r_eff
        dev = np.where(has, p_rep - p[..., None], 0.0)
        s = np.sqrt((dev**2).sum(axis=-1) / (r_eff - 1))
        t = stats.t.ppf(0.5 * (1 + confidence), np.maximum(r_eff - 1, 1))
        half = t * s / np.sqrt(r_eff)
    lo, hi = np.clip(p - half, 0.0, 1.0), np.clip(p + half, 0.0, 1.0)
    # Replicates that all agree cannot measure their spread (an indicator's share is discrete: with every
    # replicate at 0, or at the same k/m, the t-interval has zero width): the exact binomial interval of
    # the pooled k of N members instead, as if they were independent draws (wider than RQMC needs).
    k, n = np.sum(np.where(has, k_rep, 0), axis=-1), np.sum(n_ok_rep, axis=-1)
    alpha = 1 - confidence
    with np.errstate(invalid="ignore", divide="ignore"):
        cp_lo = np.where(k > 0, stats.beta.ppf(0.5 * alpha, k, n - k + 1), 0.0)
        cp_hi = np.where(k < n, stats.beta.ppf(1 - 0.5 * alpha, k + 1, n - k), 1.0)
    agree = (s == 0) & (r_eff >= 2)
    lo, hi = np.where(agree, cp_lo, lo), np.where(agree, cp_hi, hi)
    bad = r_eff < 2
    return np.where(bad, np.nan, p), np.where(bad, np.nan, lo), np.where(bad, np.nan, hi)


def _summarise(
    res: ScanResult,
    hazards,
    dists,
    draws,
    *,
    design,
    samples,
    replicates,
    seed,
    levels,
    confidence,
    max_failed,
    units,
) -> LiftRisk:
    d_mode, d_paths, d_shape, d_coords = design
    n_design = int(np.prod(d_shape, dtype=np.int64))
    m = samples // replicates
    ok = (res.status == ScanStatus.OK).reshape(n_design, replicates, m)
    n_ok_rep = ok.sum(axis=-1)
    n_ok = n_ok_rep.sum(axis=-1)
    too_many = (samples - n_ok) > max_failed * samples
    prob, lo, hi, rep = {}, {}, {}, {}
    for h in hazards:
        v = res.data[h.observable_name].reshape(n_design, replicates, m, -1)
        with np.errstate(invalid="ignore"):
            ev = np.any(v > h.threshold if h.above else v < h.threshold, axis=-1) & ok
        k_rep = ev.sum(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            p_rep = k_rep / n_ok_rep
        p, a, b = _interval(k_rep, n_ok_rep, confidence)
        prob[h.name], lo[h.name], hi[h.name] = (
            np.where(too_many, np.nan, x).reshape(d_shape) for x in (p, a, b)
        )
        rep[h.name] = np.where(n_ok_rep > 0, p_rep, np.nan).reshape(*d_shape, replicates)
    qdata = {}
    for name, v in res.data.items():
        v = v.reshape(n_design, samples, *v.shape[1:])
        with warnings.catch_warnings():  # a design point with every member failed: all-NaN slices
            warnings.simplefilter("ignore", RuntimeWarning)
            q = np.nanquantile(v, levels, axis=1)  # (Q, D, ...)
        q = np.moveaxis(q, 0, 1)
        q[too_many] = np.nan
        qdata[name] = q.reshape(*d_shape, *q.shape[1:])
    all_units = {**units, **{k: res.units.get(k, "?") for k in res.data}}
    return LiftRisk(
        design_mode=d_mode,
        design_params=d_paths,
        design_coords=d_coords,
        shape=d_shape,
        hazards=tuple(hazards),
        uncertain={p: d.describe() for p, d in dists.items()},
        samples=samples,
        replicates=replicates,
        seed=seed,
        confidence=confidence,
        max_failed=max_failed,
        probabilities=prob,
        lower=lo,
        upper=hi,
        replicate_probabilities=rep,
        n_ok=n_ok.reshape(d_shape),
        quantile_levels=levels,
        quantiles=qdata,
        components={k: res.components.get(k) for k in res.data},
        units=all_units,
        descriptions={k: res.descriptions.get(k, "") for k in res.data},
        draws={p: v for p, v in draws.items()},
        scan=res,
    )


# ------------------------------------------------------------------------------------------ result


class LiftRisk:
    """The risk map of `lift_risk`: per design point, each hazard's probability and interval, quantiles
    of each observable and the failed-member count.

    - `design_mode`: "none" (one design point), "sweep", "grid" or "points"; `design_params`: the design
      paths; `design_coords`: path -> values (grid: the axis values; otherwise one value per design point);
      `shape`: the shape of the design axes (`()` without a design).
    - `hazards`: the `Hazard`s; `uncertain`: path -> the distribution, as text.
    - `samples` (per design point), `replicates`, `seed`, `confidence`, `max_failed`: the settings.
    - `n_ok`, `n_failed`: successful and failed members per design point (shape `shape`).
    - `quantile_levels`, `quantiles`: observable name -> values of shape `shape + (levels,) + components`
      over the successful members [the observable's unit].
    - `draws`: path -> the sampled input values, shape (replicates, samples / replicates), the same at
      every design point.
    - `scan`: the underlying `ScanResult`, one member per (design point, replicate, sample) in that order.
    - `units`, `descriptions`: SI units and meanings of the paths and observables.
    """

    def __init__(
        self,
        *,
        design_mode,
        design_params,
        design_coords,
        shape,
        hazards,
        uncertain,
        samples,
        replicates,
        seed,
        confidence,
        max_failed,
        probabilities,
        lower,
        upper,
        replicate_probabilities,
        n_ok,
        quantile_levels,
        quantiles,
        components,
        units,
        descriptions,
        draws,
        scan: ScanResult | None = None,
    ):
        self.design_mode = str(design_mode)
        self.design_params = tuple(design_params)
        self.design_coords = {k: np.asarray(v) for k, v in design_coords.items()}
        self.shape = tuple(int(s) for s in shape)
        self.hazards = tuple(hazards)
        self.uncertain = dict(uncertain)
        self.samples, self.replicates, self.seed = int(samples), int(replicates), int(seed)
        self.confidence, self.max_failed = float(confidence), float(max_failed)
        self._p = {k: np.asarray(v, dtype=np.float64) for k, v in probabilities.items()}
        self._lo = {k: np.asarray(v, dtype=np.float64) for k, v in lower.items()}
        self._hi = {k: np.asarray(v, dtype=np.float64) for k, v in upper.items()}
        self._rep = {k: np.asarray(v, dtype=np.float64) for k, v in replicate_probabilities.items()}
        self.n_ok = np.asarray(n_ok, dtype=np.int64)
        self.quantile_levels = np.asarray(quantile_levels, dtype=np.float64)
        self.quantiles = {k: np.asarray(v, dtype=np.float64) for k, v in quantiles.items()}
        self.components = dict(components)
        self.units = dict(units)
        self.descriptions = dict(descriptions)
        self.draws = {k: np.asarray(v) for k, v in draws.items()}
        self.scan = scan

    # ---- access
    @property
    def n_failed(self) -> np.ndarray:
        """Failed members per design point (shape `shape`): left out of every probability and quantile."""
        return np.asarray(self.samples - self.n_ok)

    def _name(self, hazard: Hazard | str) -> str:
        name = hazard.name if isinstance(hazard, Hazard) else str(hazard)
        if name not in self._p:
            raise KeyError(f"{name!r} is not a hazard of this result; hazards are {list(self._p)}")
        return name

    def probability(self, hazard: Hazard | str) -> np.ndarray:
        """P(hazard) per design point, shape `shape` (NaN where more than `max_failed` failed)."""
        return self._p[self._name(hazard)]

    def interval(self, hazard: Hazard | str) -> tuple[np.ndarray, np.ndarray]:
        """The `confidence` interval (lower, upper) of P(hazard) per design point (see `lift_risk`)."""
        name = self._name(hazard)
        return self._lo[name], self._hi[name]

    def replicate_probabilities(self, hazard: Hazard | str) -> np.ndarray:
        """The share of hazardous members in each replicate, shape `shape + (replicates,)`."""
        return self._rep[self._name(hazard)]

    def quantile(self, observable: str, level: float) -> np.ndarray:
        """The `level` quantile of `observable` per design point (one of `quantile_levels`)."""
        if observable not in self.quantiles:
            raise KeyError(f"{observable!r}: observables are {list(self.quantiles)}")
        hit = np.flatnonzero(np.isclose(self.quantile_levels, level))
        if hit.size == 0:
            raise KeyError(f"level {level} was not computed; levels are {self.quantile_levels.tolist()}")
        return np.take(self.quantiles[observable], hit[0], axis=len(self.shape))

    def summary(self) -> str:
        """A text table: one row per design point, P and interval of every hazard, failures; where members
        failed, a line with their statuses counted and the first one's reason."""
        lines = []
        rows = list(np.ndindex(*self.shape)) if self.shape else [()]
        for idx in rows:
            where = ", ".join(f"{p} = {self._design_value(p, idx):g}" for p in self.design_params)
            head = f"[{where}] " if where else ""
            cells = [
                f"{h.name} {self._p[h.name][idx]:.3f} "
                f"[{self._lo[h.name][idx]:.3f}, {self._hi[h.name][idx]:.3f}]"
                for h in self.hazards
            ]
            lines.append(head + "; ".join(cells) + f"; failed {int(self.n_failed[idx])}/{self.samples}")
        lines += self._failure_lines()
        return "\n".join(lines)

    def _failure_lines(self) -> list[str]:
        """Why members failed (their statuses counted, the first one's reason) and, where a design point's
        numbers are NaN, that more than `max_failed` of its members failed; nothing if none failed."""
        if not int(np.sum(self.n_failed)):
            return []
        lines = []
        if self.scan is not None:
            counts = ", ".join(f"{k} {v}" for k, v in self.scan.status_counts().items() if k != "ok")
            first = self.scan.failures()[0]
            values = ", ".join(f"{p} = {v:g}" for p, v in first["params"].items())
            lines.append(f"failed members: {counts}; the first ({values}): {first['reason']}")
        if np.any(self.n_failed > self.max_failed * self.samples):
            lines.append(
                f"NaN where more than max_failed = {self.max_failed:g} of a design point's {self.samples} "
                f"members failed"
            )
        return lines

    def _design_value(self, p: str, idx: tuple) -> float:
        if self.design_mode == "grid":
            return float(self.design_coords[p][idx[self.design_params.index(p)]])
        return float(self.design_coords[p][idx[0]])

    def __repr__(self) -> str:
        return (
            f"LiftRisk(design={list(self.design_params)}, shape={self.shape}, hazards="
            f"{[h.name for h in self.hazards]}, samples={self.samples}, replicates={self.replicates}, "
            f"failed={int(np.sum(self.n_failed))})"
        )

    # ---- files
    def _layout(self):
        """(dimension sizes, coordinates, variables), each as (name, dims, values, attributes)."""
        dims: dict[str, int] = {}
        ddims = list(self.design_params) if self.design_mode == "grid" else (["design"] if self.shape else [])
        for d, n in zip(ddims, self.shape, strict=True):
            dims[d] = n
        coords = []
        for p in self.design_params:
            cd = (p,) if self.design_mode == "grid" else ("design",)
            coords.append((p, cd, self.design_coords[p], {"units": self.units.get(p, "?"), "role": "design"}))
        dims["replicate"] = self.replicates
        dims["quantile"] = self.quantile_levels.size
        coords.append(("quantile", ("quantile",), self.quantile_levels, {"units": "1"}))
        variables = []
        conf = f"{100 * self.confidence:g} %"
        for h in self.hazards:
            a = {"units": "1", "hazard": h.describe(), "description": f"P({h.describe()})"}
            variables.append((f"p_{h.name}", tuple(ddims), self._p[h.name], a))
            variables.append(
                (f"p_{h.name}_lower", tuple(ddims), self._lo[h.name], {"units": "1", "confidence": conf})
            )
            variables.append(
                (f"p_{h.name}_upper", tuple(ddims), self._hi[h.name], {"units": "1", "confidence": conf})
            )
            variables.append(
                (f"p_{h.name}_replicates", (*ddims, "replicate"), self._rep[h.name], {"units": "1"})
            )
        for k, v in self.quantiles.items():
            extra = []
            for i, n in enumerate(v.shape[len(self.shape) + 1 :]):
                d = f"{k}_component" if i == 0 else f"{k}_dim{i}"
                dims[d], extra = n, [*extra, d]
                labels = self.components.get(k) if i == 0 else None
                if labels and len(labels) == n:
                    coords.append((d, (d,), list(labels), {}))
            a = {"units": self.units.get(k, "?"), "description": self.descriptions.get(k, "")}
            variables.append((f"q_{k}", (*ddims, "quantile", *extra), v, a))
        variables.append(("n_ok", tuple(ddims), self.n_ok, {"units": "1", "description": "members solved"}))
        variables.append(
            ("n_failed", tuple(ddims), self.n_failed, {"units": "1", "description": "members failed"})
        )
        attrs = {
            "format": FORMAT,
            "samples": self.samples,
            "replicates": self.replicates,
            "seed": self.seed,
            "confidence": self.confidence,
            "max_failed": self.max_failed,
            "uncertain_json": json.dumps(self.uncertain),
            "hazards_json": json.dumps({h.name: h.describe() for h in self.hazards}),
            "design_mode": self.design_mode,
        }
        return dims, coords, variables, attrs

    def to_xarray(self):
        """An `xarray.Dataset` (only if xarray is installed; it is not a dependency of jaxhoist):
        `p_<hazard>`, `p_<hazard>_lower`/`_upper`, `p_<hazard>_replicates`, `q_<observable>`, `n_ok`,
        `n_failed`."""
        try:
            import xarray as xr  # pyright: ignore[reportMissingImports]  # xarray is optional
        except ImportError:
            raise ImportError(
                "to_xarray() needs xarray, which jaxhoist does not depend on: `pip install xarray`, or use "
                "to_netcdf() and open the file with any netCDF reader"
            ) from None
        _, coords, variables, attrs = self._layout()
        return xr.Dataset(
            {k: (d, v, a) for k, d, v, a in variables},
            coords={k: (d, v, a) for k, d, v, a in coords},
            attrs=attrs,
        )

    def to_netcdf(self, path: str | Path) -> Path:
        """Write the risk map as a classic netCDF file (the variables of `to_xarray`; names netCDF does not
        allow, such as brackets, become '_', the original kept in the `path` attribute)."""
        from ..._io.netcdf import nc_name, nc_variable, write_netcdf

        dims, coords, variables, attrs = self._layout()
        nc_dims = {nc_name(d): n for d, n in dims.items()}
        out = [nc_variable(k, d, v, a, nc_dims) for k, d, v, a in [*coords, *variables]]
        return write_netcdf(path, nc_dims, out, {"title": "jaxhoist lift risk", **attrs})
