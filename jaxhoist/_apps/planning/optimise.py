"""`optimise_lift`: the design of a lift (the boom tip's position, the hoist speed, the ramp time, ...)
that minimises a smooth expected outcome over a fixed sample of the uncertain inputs, by a bounded
quasi-Newton method on the model's forward sensitivities; the hazard limits are checked at the end by
`lift_risk` on a fresh sample. `OptimisedLift`: its result."""

from __future__ import annotations

import math
import numbers
import sys
import time
import warnings
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from ..._errors import ScenarioError
from ..._numerics import observables as obs_mod
from ..._numerics.batch import ScanStatus
from ..._numerics.times import TimesLike, as_times
from ..._physics.params import Scenario
from ..._physics.paths import check_path, get_param, param_unit, set_param
from ..scan import BatchOptions, Points, scan
from .hazards import EVENTS, Hazard
from .risk import LiftRisk, check_hazards, check_inputs, hazard_observables, lift_risk, same_observable
from .uncertain import sample

#: The objective's pseudo-observable: the time [s] the hoist takes to reel in `hoist_distance` metres.
HOIST_TIME = "hoist_time"

#: The optimiser's variables span [0, BOX] per design path (its tolerances are in these units).
BOX = 1.0

#: The value (above the start's J / |J(x0)|) of a trial design at which a member's solve failed.
FAILED = 1e3

#: Observables an objective refuses: counts and event times (possibly inf) whose derivative is zero or
#: undefined almost everywhere; they belong in `hazard_limits`.
NOT_SMOOTH = EVENTS | {"first_corner"}


def optimise_lift(
    scenario: Scenario,
    uncertain: Mapping[str, Any],
    objective: str | Mapping[str, Any],  # checked by _check_objective, with messages naming the term
    design_bounds: Mapping[str, Any],  # path -> (low, high), checked by _check_bounds
    *,
    hazard_limits: Mapping[Any, Any] | None = None,  # Hazard -> probability, checked by _check_limits
    samples: int = 64,
    seed: int = 0,
    times: TimesLike = None,
    x0: Mapping[str, Any] | None = None,
    hoist_distance: float | None = None,
    penalty: float = 0.0,
    penalty_width: float = 0.1,
    starts: int = 1,
    max_iterations: int = 30,
    tolerance: float = 1e-4,
    check_samples: int = 256,
    check_replicates: int = 8,
    check_seed: int | None = None,
    confidence: float = 0.95,
    options=None,
    batch: BatchOptions | None = None,
    progress: bool | Callable[[dict], None] | None = None,
) -> OptimisedLift:
    """The design values within bounds that minimise a smooth expected outcome of a lift with uncertain
    inputs, and whether the hazard probabilities there stay below their limits.

    The objective is a weighted sum of sample averages,

        J(x) = Σ_o w_o (1/n) Σ_s o(x, θ_s)  +  w_T T_hoist(x)  +  penalty Σ_h (1/n) Σ_s softplus_h(x, θ_s),

    over a FIXED sample θ_1..θ_n of the uncertain inputs (common random numbers: one randomised
    quasi-Monte Carlo scramble of `samples` points drawn once from `seed`, as `lift_risk` draws them), so
    that J is a smooth deterministic function of the design x. Its gradient is the average of the members'
    forward sensitivities (`scan(..., derivatives=True)`: through the default Rosenbrock-W solver they are
    solved as their own error-controlled ODE beside the state). Each evaluation of J and its gradient is
    one scan of `samples` members.

    The optimiser is L-BFGS-B (`scipy.optimize.minimize`), a quasi-Newton method with simple bounds, on
    the design scaled to the unit box, u = (x - low) / (high - low) in [0, 1]: the bounds are kept exactly
    (the steps are projected onto the box), and a design at a bound is reached and reported there. J is
    divided by |J(x0)| so that `tolerance` is relative. A trial design at which a member's solve fails gets
    a value far above the start's, so that the line search steps back. Iterations are driven from the
    host; the compiled scan carries no host callback. The design with the lowest J seen (every member
    solved) is returned.

    At the end, if `hazard_limits` are given, `lift_risk` estimates each hazard's probability at the start
    and at the optimum on a FRESH sample (`check_samples` members in `check_replicates` scrambles from
    `check_seed`), with its interval; a limit holds when the upper end of the interval is at most the
    limit. The probabilities themselves (indicators, not smooth) never enter J; `penalty` > 0 adds a smooth
    stand-in for them: for each limited hazard on a smooth built-in scalar observable v with threshold c,
    the sample average of softplus((v - c) / w) = log(1 + exp((v - c) / w)), w = `penalty_width` |c| (the
    sign flipped for `above=False`), times `penalty`.

    **Arguments**
    - `scenario`: the base `Scenario` (its values of the non-design, non-uncertain leaves are used).
    - `uncertain`: parameter path -> distribution, as for `lift_risk`.
    - `objective`: an observable's name (weight 1), or a mapping name -> weight w_o [1 per unit of the
      observable]: built-in scalar observables such as `"max_rope_tension"` [N], `"ground_slide"` [m],
      `"swing_amplitude"` [m], `"max_tilt"` [rad], one component `"contact_margin[D]"`, and
      `"hoist_time"` [s], the time the hoist takes to reel in `hoist_distance` metres at the design's
      speed (d / v_l for a constant-speed hoist, d / v_l + T_ramp / 2 for a `RampedHoist`, the root of
      s(T) = d for a `KnotHoist`, with its gradient dT/dv_k = -(∂s/∂v_k)(T) / v(T)), which weighs speed
      against the outcomes that grow with it. Counts and event times (`impacts`, `liftoff_time`,
      ...) are refused: they are not smooth in the design (use them in `hazard_limits`).
    - `design_bounds`: design path -> (low, high) in the field's SI unit, e.g.
      `{"boom.tip_position[0]": (1.0, 3.0), "hoist.speed": (0.1, 0.4)}`; any float leaf that is not
      uncertain (`"hoist.ramp_time"` of a `RampedHoist`, a knot speed `"hoist.speeds[1]"` of a
      `KnotHoist`, the rope's attachment, ...).
    - `hazard_limits`: `Hazard` -> the largest acceptable probability in [0, 1], checked at the end.
    - `samples`: members of the fixed sample (a power of 2 keeps the Sobol points balanced; default 64).
    - `seed`: the seed of that sample.
    - `times`: the saved times, as for `scan` (a number is t1 [s]; default the scenario's t1, 201 times).
    - `x0`: the start, path -> value (default: the scenario's value, moved into the bounds).
    - `hoist_distance`: d [m] of the `"hoist_time"` term (needed with it).
    - `penalty`, `penalty_width`: the weight of the smooth hazard penalty (0: none) and its width as a
      share of each threshold.
    - `starts`: 1 (default): L-BFGS-B starts at `x0`. More: J (without derivatives, one scan of
      `starts` x `samples` members) is screened at `x0` and `starts` - 1 scrambled Sobol points of the
      box (seeded by `seed`), and L-BFGS-B starts at the best of them; J is often not convex in the
      design (a tip that pulls the load sideways may be better than one straight above it only at low
      speed), and a local method finds the minimum of the basin it starts in.
    - `max_iterations`: L-BFGS-B iterations at most (each takes one or more evaluations).
    - `tolerance`: stop when J / |J(x0)| decreases by less than this in an iteration, or the projected
      gradient in the unit box is below it (default 1e-4: J carries the adaptive solver's error, and a
      design moved by 1e-12 can move J by some 1e-5 of itself as the steps change; a tighter tolerance
      spends evaluations on that noise).
    - `check_samples`, `check_replicates`, `check_seed` (default `seed` + 1, never `seed`), `confidence`:
      the fresh sample and the interval level of the final check.
    - `options`, `batch`, `progress`: `SolverOptions` and `BatchOptions` as for `scan` (one setting for
      every solve); `progress` True prints a line per iteration on stderr, a callable receives a dict
      (iteration, value, design, gradient, evaluations) after each iteration.

    **Returns** an `OptimisedLift`.

    **Raises** `ScenarioError` (a `ValueError`) naming the field for bad bounds, design paths, objective
    names or weights, hazards, limits or settings, before anything is compiled.
    """
    prep = _prepare(
        scenario,
        uncertain,
        objective,
        design_bounds,
        hazard_limits=hazard_limits,
        samples=samples,
        seed=seed,
        times=times,
        x0=x0,
        hoist_distance=hoist_distance,
        penalty=penalty,
        penalty_width=penalty_width,
        starts=starts,
        max_iterations=max_iterations,
        tolerance=tolerance,
        check_samples=check_samples,
        check_replicates=check_replicates,
        check_seed=check_seed,
        confidence=confidence,
        options=options,
        batch=batch,
    )
    problem, paths, start, limits = prep["problem"], prep["paths"], prep["start"], prep["limits"]
    hz, dists, weights = tuple(limits), prep["dists"], prep["weights"]
    fresh: int = prep["check_seed"]
    lo, hi, samples, seed, t1 = problem.lo, problem.hi, prep["samples"], prep["seed"], prep["t1"]
    max_iterations, tol, starts = prep["max_iterations"], prep["tolerance"], prep["starts"]
    wall0 = time.perf_counter()
    run = _minimise(problem, start, max_iterations, tol, _reporter(progress, paths), starts, seed)
    best = run["best"]
    check = None
    if hz:
        rows = {p: [start[k], best["x"][k]] for k, p in enumerate(paths)}
        check = lift_risk(
            scenario,
            dists,
            hz,
            Points(rows),
            samples=check_samples,
            replicates=check_replicates,
            times=times,
            seed=fresh,
            observables=tuple(weights),
            confidence=confidence,
            options=options,
            batch=batch,
        )
    optimum = scenario
    for k, p in enumerate(paths):
        optimum = set_param(optimum, p, best["x"][k])
    return OptimisedLift(
        paths=paths,
        bounds={p: (float(lo[k]), float(hi[k])) for k, p in enumerate(paths)},
        design=best["x"],
        start=start,
        value=best["value"],
        start_value=run["start"]["value"],
        terms=best["terms"],
        start_terms=run["start"]["terms"],
        gradient=best["grad"],
        n_failed=best["n_failed"],
        screened=run["screened"],
        iterations=run["iterations"],
        evaluations=run["evaluations"],
        samples=samples,
        seed=seed,
        converged=run["converged"],
        message=run["message"],
        history=run["history"],
        limits=limits,
        check=check,
        scenario=optimum,
        units={p: param_unit(scenario, p) for p in paths},
        uncertain={p: d.describe() for p, d in dists.items()},
        t1=t1,
        wall_s=time.perf_counter() - wall0,
    )


# ------------------------------------------------------------------------------------------ checks


def _prepare(
    scenario,
    uncertain,
    objective,
    design_bounds,
    *,
    hazard_limits,
    samples,
    seed,
    times,
    x0,
    hoist_distance,
    penalty,
    penalty_width,
    starts,
    max_iterations,
    tolerance,
    check_samples,
    check_replicates,
    check_seed,
    confidence,
    options,
    batch,
) -> dict[str, Any]:
    """Every argument of `optimise_lift` checked (a `ScenarioError` naming the field, before anything is
    compiled), the fixed sample drawn and the `_Problem` built."""
    dists = check_inputs(scenario, uncertain)
    paths, lo, hi = _check_bounds(scenario, design_bounds, dists)
    weights, t_weight = _check_objective(objective)
    distance = _check_hoist_time(scenario, t_weight, hoist_distance)
    limits = _check_limits(hazard_limits)
    hz = tuple(limits)
    start = _check_start(scenario, paths, lo, hi, x0)
    samples, seed, check_seed = _check_counts(samples, seed, check_samples, check_replicates, check_seed)
    pen, width = _number("penalty", penalty, low=0.0), _number("penalty_width", penalty_width, low=0.0)
    if pen > 0 and not width > 0:
        raise ScenarioError(f"penalty_width must be > 0 with a penalty, got {width}")
    if not 0 < float(confidence) < 1:
        raise ScenarioError(f"confidence must be in (0, 1), got {confidence}")
    max_iterations = _integer("max_iterations", max_iterations, low=1)
    starts = _integer("starts", starts, low=1)
    tol = _number("tolerance", tolerance, low=0.0)
    t1 = float(np.asarray(as_times(times).resolve(scenario, 201)[1])[-1])
    penalised = tuple(h for h in hz if pen > 0 and _smooth_builtin_scalar(h))
    obs = hazard_observables(hz, tuple(weights))
    problem = _Problem(
        scenario=scenario,
        paths=paths,
        lo=lo,
        hi=hi,
        draws={p: v.ravel() for p, v in sample(dists, samples, 1, seed).items()},
        times=times,
        observables=obs,
        weights=weights,
        hoist_time=(t_weight, distance),
        penalised=penalised,
        penalty=pen,
        width=width,
        options=options,
        batch=batch,
    )
    return dict(
        problem=problem,
        paths=paths,
        start=start,
        limits=limits,
        dists=dists,
        weights=weights,
        check_seed=check_seed,
        samples=samples,
        seed=seed,
        t1=t1,
        max_iterations=max_iterations,
        tolerance=tol,
        starts=starts,
    )


def _number(name: str, value, low: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ScenarioError(f"{name} must be a number, got {value!r:.60}")
    x = float(value)
    if not math.isfinite(x):
        raise ScenarioError(f"{name} must be finite, got {x}")
    if low is not None and x < low:
        raise ScenarioError(f"{name} must be >= {low:g}, got {x:g}")
    return x


def _integer(name: str, value, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ScenarioError(f"{name} must be an integer, got {value!r:.60}")
    if value < low:
        raise ScenarioError(f"{name} must be >= {low}, got {value}")
    return int(value)


def _check_bounds(scenario, design_bounds, dists) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """The design paths and their bounds, or a `ScenarioError` naming the path: a float leaf of the
    scenario, not uncertain, low < high (finite), and the scenario valid at both ends."""
    if not isinstance(design_bounds, Mapping) or not design_bounds:
        raise ScenarioError(
            "design_bounds must be a non-empty mapping of parameter path -> (low, high), e.g. "
            "{'boom.tip_position[0]': (1.0, 3.0)}"
        )
    paths, lo, hi = [], [], []
    for path, b in design_bounds.items():
        if not isinstance(path, str) or not path.strip():
            raise ScenarioError(f"design_bounds: a parameter path must be a dotted name, got {path!r}")
        try:
            check_path(scenario, path)
        except ScenarioError as e:
            raise ScenarioError(f"design_bounds[{path!r}]: {e}") from None
        if path in dists:
            raise ScenarioError(
                f"design_bounds[{path!r}]: the path is also uncertain; a path is one or the other"
            )
        try:
            a, c = b
        except (TypeError, ValueError):
            raise ScenarioError(
                f"design_bounds[{path!r}] must be a pair (low, high), got {b!r:.60}"
            ) from None
        a = _number(f"design_bounds[{path!r}] low", a)
        c = _number(f"design_bounds[{path!r}] high", c)
        if not a < c:
            raise ScenarioError(f"design_bounds[{path!r}]: low must be < high, got low = {a:g}, high = {c:g}")
        for v in (a, c):
            try:
                set_param(scenario, path, v).check()
            except ScenarioError as e:
                raise ScenarioError(f"design_bounds[{path!r}] = ({a:g}, {c:g}): at {v:g}: {e}") from None
        paths.append(path)
        lo.append(a)
        hi.append(c)
    return tuple(paths), np.array(lo), np.array(hi)


def _smooth_scalar(name: str) -> bool:
    """Whether the built-in observable `name` is scalar and not a count or an event time."""
    if name.partition("[")[0] in NOT_SMOOTH:
        return False
    try:
        return obs_mod.get(name).components is None
    except ValueError:
        return False


def _smooth_builtin_scalar(hazard) -> bool:
    """Whether `hazard` reads a smooth built-in scalar observable, given by its name (or as the built-in's
    own `Observable`, `jh.get_observable(name)`, for a name without an index); never an `Observable` of the
    caller's, whatever its name."""
    name = hazard.observable_name
    return _smooth_scalar(name) and same_observable(hazard.observable, name)


def _check_objective(objective) -> tuple[dict[str, float], float]:
    """observable name -> weight, and the weight of `hoist_time` (0 if absent)."""
    if isinstance(objective, str):
        objective = {objective: 1.0}
    if not isinstance(objective, Mapping) or not objective:
        raise ScenarioError(
            "objective must be an observable's name or a mapping name -> weight, e.g. "
            "{'max_rope_tension': 1e-4, 'ground_slide': 1.0}"
        )
    weights, t_weight = {}, 0.0
    for name, w in objective.items():
        if not isinstance(name, str):
            raise ScenarioError(f"objective: keys must be observable names, got {name!r:.60}")
        w = _number(f"objective[{name!r}]", w)
        if w == 0:
            raise ScenarioError(f"objective[{name!r}]: the weight must not be 0 (leave the term out)")
        if name == HOIST_TIME:
            t_weight = w
            continue
        if name.partition("[")[0] in NOT_SMOOTH:
            raise ScenarioError(
                f"objective: {name!r} is a count or an event time, not smooth in the design; give it as a "
                f"hazard limit (e.g. jh.strike(), jh.no_liftoff(t)) instead"
            )
        try:
            o = obs_mod.get(name)
        except ValueError as e:
            raise ScenarioError(f"objective: {e} (or {HOIST_TIME!r})") from None
        if o.components is not None:
            raise ScenarioError(
                f"objective: {name!r} is a vector observable; name one component, e.g. "
                f"'{name}[{o.components[0]}]'"
            )
        weights[name] = w
    return weights, t_weight


def _check_hoist_time(scenario, t_weight, distance) -> float:
    if t_weight == 0:
        if distance is not None:
            raise ScenarioError(f"hoist_distance is given but the objective has no {HOIST_TIME!r} term")
        return 0.0
    if distance is None:
        raise ScenarioError(f"objective {HOIST_TIME!r} needs hoist_distance [m], the rope to reel in")
    d = _number("hoist_distance", distance)
    if not d > 0:
        raise ScenarioError(f"hoist_distance must be > 0 [m], got {d:g}")
    law = type(scenario.hoist).__name__
    if law not in ("ConstantSpeedHoist", "RampedHoist", "KnotHoist"):
        raise ScenarioError(
            f"objective {HOIST_TIME!r} needs a ConstantSpeedHoist, a RampedHoist or a KnotHoist, the "
            f"scenario has {law}"
        )
    if law == "KnotHoist" and not math.isfinite(reel_time(scenario.hoist, d)):
        raise ScenarioError(
            f"objective {HOIST_TIME!r}: the scenario's hoist profile never reels in hoist_distance = {d:g} m "
            f"(its last knot speed is 0 or its travel is shorter)"
        )
    return d


def _shortening(hoist, t):
    import equinox as eqx

    global _shortening_jit
    if _shortening_jit is None:
        _shortening_jit = eqx.filter_jit(lambda h, t: h.shortening(t))
    return _shortening_jit(hoist, t)


_shortening_jit = None


def reel_time(hoist, distance: float) -> float:
    """The time T [s] at which a hoist law has reeled in `distance` [m], s(T) = d (s is non-decreasing):
    bisection to round-off, on the host; inf if the hoist never gets there."""

    def s(t):
        return float(_shortening(hoist, np.float64(t)))

    hi = 1.0
    while s(hi) < distance:
        hi *= 2.0
        if hi > 1e7:
            return math.inf
    lo = 0.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        lo, hi = (mid, hi) if s(mid) < distance else (lo, mid)
    return hi


def _check_limits(hazard_limits) -> dict[Hazard, float]:
    if hazard_limits is None:
        return {}
    if not isinstance(hazard_limits, Mapping):
        raise ScenarioError(
            f"hazard_limits must be a mapping Hazard -> largest probability, got "
            f"{type(hazard_limits).__name__}"
        )
    if not hazard_limits:
        return {}
    hz = check_hazards(tuple(hazard_limits))
    out = {}
    for h in hz:
        p = _number(f"hazard_limits[{h.name!r}]", hazard_limits[h])
        if not 0 <= p <= 1:
            raise ScenarioError(f"hazard_limits[{h.name!r}] must be a probability in [0, 1], got {p:g}")
        out[h] = p
    return out


def _check_start(scenario, paths, lo, hi, x0) -> np.ndarray:
    if x0 is not None and not isinstance(x0, Mapping):
        raise ScenarioError(f"x0 must be a mapping path -> value, got {type(x0).__name__}")
    x0 = {} if x0 is None else dict(x0)
    extra = sorted(set(x0) - set(paths))
    if extra:
        raise ScenarioError(f"x0: {extra} are not design paths; design paths are {list(paths)}")
    out = []
    for k, p in enumerate(paths):
        if p in x0:
            v = _number(f"x0[{p!r}]", x0[p])
            if not lo[k] <= v <= hi[k]:
                raise ScenarioError(f"x0[{p!r}] = {v:g} lies outside its bounds [{lo[k]:g}, {hi[k]:g}]")
        else:
            v = float(np.clip(float(np.asarray(get_param(scenario, p))), lo[k], hi[k]))
        out.append(v)
    return np.array(out)


def _check_counts(samples, seed, check_samples, check_replicates, check_seed) -> tuple[int, int, int]:
    samples = _integer("samples", samples, low=2)
    seed = _integer("seed", seed, low=0)
    check_replicates = _integer("check_replicates", check_replicates, low=2)
    check_samples = _integer("check_samples", check_samples, low=2 * check_replicates)
    if check_samples % check_replicates:
        raise ScenarioError(
            f"check_samples must be a multiple of check_replicates = {check_replicates}, got {check_samples}"
        )
    check_seed = seed + 1 if check_seed is None else _integer("check_seed", check_seed, low=0)
    if check_seed == seed:
        raise ScenarioError(
            f"check_seed must differ from seed = {seed}: the check needs a fresh sample, not the one "
            f"optimised on"
        )
    return samples, seed, check_seed


# ------------------------------------------------------------------------------------------ the problem


class _Problem:
    """J(x) and its gradient over the fixed sample: one scan of the sample's members per design point."""

    def __init__(
        self,
        *,
        scenario,
        paths,
        lo,
        hi,
        draws,
        times,
        observables,
        weights,
        hoist_time,
        penalised,
        penalty,
        width,
        options,
        batch,
    ):
        self.scenario, self.paths, self.lo, self.hi = scenario, paths, lo, hi
        self.draws, self.times, self.observables = draws, times, observables
        self.weights, self.hoist_time = weights, hoist_time
        self.penalised, self.penalty, self.width = penalised, penalty, width
        self.options, self.batch = options, batch
        self.n = next(iter(draws.values())).size
        self.solves = 0

    def _scan(self, X: np.ndarray, derivatives: bool):
        """One scan of every (design point, sample) pair: members (k, n) -> ScanResult."""
        X = np.atleast_2d(X)
        k = X.shape[0]
        cols = {p: np.repeat(X[:, j], self.n) for j, p in enumerate(self.paths)}
        cols.update({p: np.tile(v, k) for p, v in self.draws.items()})
        self.solves += k * self.n
        return scan(
            self.scenario,
            Points(cols),
            self.times,
            observables=self.observables,
            options=self.options,
            derivatives=derivatives,
            batch=self.batch,
        )

    def _hoist_value(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """T_hoist [s] and its gradient over the design."""
        w, d = self.hoist_time
        g = np.zeros(len(self.paths))
        if w == 0:
            return 0.0, g
        sc = self.scenario
        if type(sc.hoist).__name__ == "KnotHoist":
            return self._knot_time(x, d)
        v = float(np.asarray(sc.hoist.speed))
        if "hoist.speed" in self.paths:
            v = float(x[self.paths.index("hoist.speed")])
            g[self.paths.index("hoist.speed")] = -d / v**2
        ramp = 0.0
        if type(sc.hoist).__name__ == "RampedHoist":
            ramp = float(np.asarray(sc.hoist.ramp_time))
            if "hoist.ramp_time" in self.paths:
                ramp = float(x[self.paths.index("hoist.ramp_time")])
                g[self.paths.index("hoist.ramp_time")] = 0.5
        return d / v + 0.5 * ramp, g

    def _knot_time(self, x: np.ndarray, d: float) -> tuple[float, np.ndarray]:
        """T_hoist [s] of a `KnotHoist` at design x, s(T) = d, and its gradient by the implicit function
        theorem, dT/dθ = -(∂s/∂θ)(T) / v(T), for the design paths in `hoist.` (0 for the others)."""
        import jax
        import jax.numpy as jnp

        sc = self.scenario
        for p, v in zip(self.paths, x, strict=True):
            sc = set_param(sc, p, v)
        T = reel_time(sc.hoist, d)
        g = np.zeros(len(self.paths))
        if not math.isfinite(T):
            return math.inf, g
        tT = jnp.asarray(T, dtype=jnp.float64)
        rate = float(sc.hoist.rate(tT))
        for j, p in enumerate(self.paths):
            if p.startswith("hoist."):
                ds = jax.grad(lambda v, p=p: set_param(sc, p, v).hoist.shortening(tT))(np.float64(x[j]))
                g[j] = -float(ds) / rate if rate > 0 else math.nan
        return T, g

    def evaluate(self, X: np.ndarray, derivatives: bool = False) -> list[dict]:
        """For each design point (a row of X): J, its terms (sample averages before their weights), the
        number of failed members and, with `derivatives`, the gradient dJ/dx and each term's gradient."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        k, nd = X.shape
        res = self._scan(X, derivatives)
        ok = (np.asarray(res.status) == ScanStatus.OK).reshape(k, self.n)
        n_ok = ok.sum(axis=1)
        out = []
        for i in range(k):
            if n_ok[i] == 0:  # no average to take: the optimiser rejects such a trial design
                code = int(np.asarray(res.status).reshape(k, self.n)[i, 0])
                out.append(
                    dict(
                        x=X[i].copy(),
                        value=math.nan,
                        terms={},
                        grad=np.zeros(nd) if derivatives else None,
                        term_grads={},
                        n_failed=self.n,
                        reason=ScanStatus(code).message,
                    )
                )
                continue
            terms, grads, grad = {}, {}, np.zeros(nd)
            sel = ok[i]

            def avg(key, i=i, sel=sel):
                v = np.asarray(res.data[key]).reshape(k, self.n, *np.shape(res.data[key])[1:])[i][sel]
                return v.mean(axis=0)

            for name, w in self.weights.items():
                terms[name] = float(avg(name))
                if derivatives:
                    grads[name] = avg(f"d_{name}")[:nd]
                    grad += w * grads[name]
            for h in self.penalised:
                name = h.observable_name
                v = np.asarray(res.data[name]).reshape(k, self.n)[i][sel]
                wd = self.width * max(abs(h.threshold), 1e-12)
                sign = 1.0 if h.above else -1.0
                z = sign * (v - h.threshold) / wd
                terms[f"penalty:{h.name}"] = float(np.mean(np.logaddexp(0.0, z)))
                if derivatives:
                    dv = np.asarray(res.data[f"d_{name}"]).reshape(k, self.n, -1)[i][sel][:, :nd]
                    sig = 0.5 * (1.0 + np.tanh(0.5 * z))  # d softplus / dz, without overflow
                    grads[f"penalty:{h.name}"] = np.mean((sig * sign / wd)[:, None] * dv, axis=0)
                    grad += self.penalty * grads[f"penalty:{h.name}"]
            th, tg = self._hoist_value(X[i])
            if self.hoist_time[0] != 0:
                terms[HOIST_TIME], grads[HOIST_TIME] = th, tg
                grad += self.hoist_time[0] * tg
            value = sum(w * terms[nm] for nm, w in self.weights.items())
            value += sum(self.penalty * terms[f"penalty:{h.name}"] for h in self.penalised)
            value += self.hoist_time[0] * terms.get(HOIST_TIME, 0.0)
            out.append(
                dict(
                    x=X[i].copy(),
                    value=float(value),
                    terms=terms,
                    grad=grad if derivatives else None,
                    term_grads=grads,
                    n_failed=int(self.n - n_ok[i]),
                )
            )
        return out


def _minimise(
    problem: _Problem, x0: np.ndarray, max_iterations: int, tol: float, report, starts: int = 1, seed: int = 0
) -> dict:
    """L-BFGS-B on u = BOX (x - lo) / (hi - lo) in [0, BOX]^d with J / |J(x0)|, from x0 or (with `starts` > 1)
    from the best of x0 and `starts` - 1 scrambled Sobol points of the box (J without derivatives, one
    scan): the best evaluation, the start's, the history and the optimiser's verdict."""
    from scipy.optimize import minimize
    from scipy.stats import qmc

    lo, span = problem.lo, (problem.hi - problem.lo) / BOX
    history: list[dict] = []
    cache: dict[bytes, dict] = {}

    def at(u):
        u = np.clip(np.asarray(u, dtype=np.float64), 0.0, BOX)
        key = u.tobytes()
        if key not in cache:
            ev = problem.evaluate(lo + u * span, derivatives=True)[0]
            cache[key] = ev
            history.append({"design": ev["x"].tolist(), "value": ev["value"], "n_failed": ev["n_failed"]})
        return cache[key]

    u0 = (x0 - lo) / span
    screened: list[dict] = []
    if starts > 1:
        with warnings.catch_warnings():  # "balance properties ... power of 2": any number of starts is fine
            warnings.simplefilter("ignore", UserWarning)
            rng = np.random.default_rng(seed)
            try:  # scipy >= 1.15 names the generator `rng`
                sobol = qmc.Sobol(len(u0), scramble=True, rng=rng)
            except TypeError:  # scipy 1.13, 1.14: `seed`
                sobol = qmc.Sobol(len(u0), scramble=True, seed=rng)  # pyright: ignore[reportCallIssue]
            U = np.vstack([u0, BOX * sobol.random(starts - 1)])
        screened = problem.evaluate(lo + U * span)
        ok = [e["value"] if e["n_failed"] == 0 else math.inf for e in screened]
        first = screened[0]
        u_start = U[int(np.argmin(ok))] if np.isfinite(min(ok)) else u0
        at(u_start)
    else:
        first = at(u0)
        u_start = u0
    if first["n_failed"] == problem.n:
        raise RuntimeError(
            f"every one of the {problem.n} members failed at the start "
            f"{dict(zip(problem.paths, first['x'].tolist(), strict=True))}: {first['reason']}"
        )
    scale = abs(first["value"]) if first["value"] != 0 else 1.0

    def fun(u):
        ev = at(u)
        if (ev["n_failed"] or not math.isfinite(ev["value"])) and not np.array_equal(ev["x"], first["x"]):
            # a member failed at this trial design: a value far above the start's, so that the line search
            # steps back (an average over the other members would be over another sample)
            return abs(first["value"] / scale) + FAILED, np.zeros_like(u)
        return ev["value"] / scale, ev["grad"] * span / scale

    iterations = 0

    def callback(intermediate_result=None, *args):
        nonlocal iterations
        iterations += 1
        if report is not None:
            u = np.asarray(getattr(intermediate_result, "x", intermediate_result))
            ev = at(u)
            report(iterations, ev, len(history))

    res = minimize(
        fun,
        u_start,
        jac=True,
        method="L-BFGS-B",
        bounds=[(0.0, BOX)] * len(u0),
        callback=callback,
        options={"maxiter": max_iterations, "ftol": tol, "gtol": tol, "maxfun": 4 * max_iterations + 10},
    )
    best = min(cache.values(), key=lambda e: e["value"] if e["n_failed"] == 0 else math.inf)
    if best["n_failed"]:  # failures wherever the optimiser went: the start
        best = cache[np.clip(u_start, 0.0, BOX).tobytes()]
    msg = res.message if isinstance(res.message, str) else res.message.decode()
    return dict(
        best=best,
        start=first,
        screened=[
            {"design": e["x"].tolist(), "value": e["value"], "n_failed": e["n_failed"]} for e in screened
        ],
        history=history,
        iterations=int(res.nit),
        evaluations=len(history),
        converged=bool(res.success),
        message=msg,
    )


def _reporter(progress, paths):
    if progress is None or progress is False:
        return None
    if callable(progress) and progress is not True:

        def call(it, ev, n_eval):
            progress(
                dict(
                    iteration=it,
                    value=ev["value"],
                    design=dict(zip(paths, ev["x"].tolist(), strict=True)),
                    gradient=dict(zip(paths, ev["grad"].tolist(), strict=True)),
                    evaluations=n_eval,
                )
            )

        return call

    def line(it, ev, n_eval):
        where = ", ".join(f"{p} = {v:.6g}" for p, v in zip(paths, ev["x"], strict=True))
        print(
            f"optimise_lift: iteration {it}: J = {ev['value']:.6g} at {where} ({n_eval} evaluations)",
            file=sys.stderr,
        )

    return line


# ------------------------------------------------------------------------------------------ result


class OptimisedLift:
    """The result of `optimise_lift`.

    - `paths`, `bounds`: the design paths and their (low, high) [SI unit of each, `units`].
    - `design`, `start`: path -> the optimum's and the start's values.
    - `value`, `start_value`: J there; `terms`, `start_terms`: each term's sample average (observable
      name, `"hoist_time"`, `"penalty:<hazard>"`) before its weight.
    - `gradient`: path -> dJ/dx at the optimum [1 per unit of the path] (near 0 inside the bounds).
    - `n_failed`: members of the fixed sample whose solve failed at the optimum (left out of its averages).
    - `iterations`, `evaluations`: L-BFGS-B iterations and evaluations of J with its gradient (one scan
      of `samples` members each); `solves`: members solved in all, the check included.
    - `converged`, `message`: the optimiser's verdict.
    - `history`: one dict per evaluation (design, value, n_failed), in order; `screened`: the same for the
      starting points screened (without derivatives) when `starts` > 1.
    - `limits`: `Hazard` -> the largest acceptable probability; `check`: the `LiftRisk` of the final check
      (design points: 0 the start, 1 the optimum) or None without limits; `limit_table()` reads it.
    - `scenario`: the base scenario with the optimum's design values.
    """

    def __init__(
        self,
        *,
        paths,
        bounds,
        design,
        start,
        value,
        start_value,
        terms,
        start_terms,
        gradient,
        n_failed,
        screened,
        iterations,
        evaluations,
        samples,
        seed,
        converged,
        message,
        history,
        limits,
        check: LiftRisk | None,
        scenario,
        units,
        uncertain,
        t1,
        wall_s,
    ):
        self.paths = tuple(paths)
        self.bounds = dict(bounds)
        self.design = {p: float(v) for p, v in zip(self.paths, design, strict=True)}
        self.start = {p: float(v) for p, v in zip(self.paths, start, strict=True)}
        self.value, self.start_value = float(value), float(start_value)
        self.terms, self.start_terms = dict(terms), dict(start_terms)
        self.gradient = {p: float(v) for p, v in zip(self.paths, gradient, strict=True)}
        self.n_failed = int(n_failed)
        self.screened = list(screened)
        self.iterations, self.evaluations = int(iterations), int(evaluations)
        self.samples, self.seed = int(samples), int(seed)
        self.converged, self.message = bool(converged), str(message)
        self.history = list(history)
        self.limits = dict(limits)
        self.check = check
        self.scenario = scenario
        self.units = dict(units)
        self.uncertain = dict(uncertain)
        self.t1 = float(t1)
        self.wall_s = float(wall_s)

    @property
    def solves(self) -> int:
        """Members solved in all: (`evaluations` + screened starts) x `samples`, plus the check's."""
        extra = 0 if self.check is None else int(np.prod(self.check.shape)) * self.check.samples
        return (self.evaluations + len(self.screened)) * self.samples + extra

    def limit_table(self) -> dict[str, dict[str, float | bool]]:
        """Hazard name -> p, lower, upper (the interval at the check's confidence) at the optimum and
        p_start at the start, the limit, and `holds` (upper <= limit)."""
        out = {}
        if self.check is None:
            return out
        for h, limit in self.limits.items():
            p = self.check.probability(h)
            lo, hi = self.check.interval(h)
            out[h.name] = dict(
                p=float(p[1]),
                lower=float(lo[1]),
                upper=float(hi[1]),
                p_start=float(p[0]),
                limit=float(limit),
                holds=bool(hi[1] <= limit),
            )
        return out

    @property
    def limits_hold(self) -> bool | None:
        """Whether every hazard limit holds at the optimum (None without limits)."""
        table = self.limit_table()
        return None if not table else all(bool(r["holds"]) for r in table.values())

    def summary(self) -> str:
        """A text report: the design, J and its terms at the start and the optimum, the limits."""
        screen = f"{len(self.screened)} starts screened, " if self.screened else ""
        lines = [
            f"optimise_lift: {screen}{self.iterations} iterations, {self.evaluations} evaluations of "
            f"{self.samples} members, {self.solves} solves in all ({self.wall_s:.1f} s); {self.message}"
        ]
        for p in self.paths:
            lo, hi = self.bounds[p]
            u = self.units.get(p, "?")
            lines.append(
                f"  {p} [{u}]: {self.start[p]:.6g} -> {self.design[p]:.6g} (bounds [{lo:g}, {hi:g}], "
                f"dJ/dx {self.gradient[p]:.3g})"
            )
        lines.append(f"  J: {self.start_value:.6g} -> {self.value:.6g}")
        for k in self.terms:
            lines.append(f"    {k}: {self.start_terms[k]:.6g} -> {self.terms[k]:.6g}")
        if self.n_failed:
            lines.append(f"  {self.n_failed} of {self.samples} members failed at the optimum (left out)")
        table = self.limit_table()
        if table:
            assert self.check is not None
            conf = f"{100 * self.check.confidence:g} %"
            lines.append(f"  hazard limits (fresh sample of {self.check.samples}, {conf} intervals):")
            for name, r in table.items():
                verdict = "holds" if r["holds"] else "NOT shown to hold"
                lines.append(
                    f"    {name}: P = {r['p']:.3f} [{r['lower']:.3f}, {r['upper']:.3f}] (start "
                    f"{r['p_start']:.3f}), limit {r['limit']:g}: {verdict}"
                )
        return "\n".join(lines)

    def __repr__(self) -> str:
        d = ", ".join(f"{p}={v:.6g}" for p, v in self.design.items())
        return f"OptimisedLift({d}, value={self.value:.6g}, evaluations={self.evaluations})"
