"""The bifurcation indicator and its evaluation: the checked inputs of one search (`Problem`), the indicator
g = observable - level, and `Evaluator`: the observable of one solve at a parameter value, with or without
its derivative dy/dp (forward mode), compiled once per setting through `numerics.compile_cache.program`
(stored whole where the persistent compilation cache is on), counted, and a failed solve turned into a
`BifurcationError`."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from ..._errors import ScenarioError, SolveStatus
from ..._io.validate import brief, check_scalar_observable
from ..._numerics import observables as obs_mod
from ..._numerics.compile_cache import program
from ..._numerics.options import SolverOptions
from ..._numerics.solve import solve
from ..._physics.params import Scenario
from ..._physics.paths import set_param
from .options import SearchOptions
from .result import Bifurcation, BifurcationError, jump_fraction


def resolve_one(observable, where: str = "observable") -> obs_mod.Observable:
    """The one scalar `Observable` named or given by `observable`, checked before any solve (the Python API
    and `jaxhoist bifurcation --observable` alike).

    **Arguments**
    - `observable`: a built-in name (a scalar one, or a component such as "final_position[z]"), a callable
      or an `Observable`.
    - `where`: the argument or flag it came from, for the message.

    **Raises** `ScenarioError` naming `where` for an unknown name, none or several observables, or a vector
    observable (with the component to pick).
    """
    try:
        found = obs_mod.resolve(observable)
    except TypeError:
        raise ScenarioError(
            f"{where}: expected a built-in name, a callable or an Observable, got {brief(observable)}"
        ) from None
    except ValueError as e:
        raise ScenarioError(f"{where}: {e}") from None
    if len(found) != 1:
        raise ScenarioError(f"{where}: one observable is needed, got {len(found)}: {[o.name for o in found]}")
    check_scalar_observable(found[0], where)
    return found[0]


def indicator(y, level, y_lo_end):
    """g = y - level for finite ends; for an end at ±inf (an event that stops happening), +1 on the side of
    the lower end and -1 on the other, with no slope information."""
    if np.isfinite(level):
        return y - level
    same = (np.isfinite(y) == np.isfinite(y_lo_end)) and (np.isfinite(y) or y == y_lo_end)
    return -1.0 if same else 1.0


def level_from_ends(level, y_a: float, y_b: float) -> float:
    """The level: as given, else the midpoint of the ends' values, or inf where an end never has the event
    (then the ends are told apart by finiteness)."""
    lev = 0.5 * (y_a + y_b) if level is None else float(level)
    if level is None and not (np.isfinite(y_a) and np.isfinite(y_b)):
        lev = np.inf
    return lev


@dataclasses.dataclass
class Problem:
    """One located change: the checked inputs of `locate_bifurcation` (`lo`, `hi`, `tol` in the parameter's
    unit; `ts` [s]; `wall0` the start time [s] of `time.perf_counter`)."""

    scenario: Scenario
    param: str
    obs: obs_mod.Observable
    lo: float
    hi: float
    level: float | None
    search: SearchOptions
    ts: jnp.ndarray
    options: SolverOptions
    unit: str
    n_uniform: int
    wall0: float
    progress: Callable[[dict], None] | None

    @property
    def tol(self) -> float:
        return self.search.tol

    def result(self, a: float, b: float, ya, yb, lev, y_a, y_b, **stats) -> Bifurcation:
        """The `Bifurcation` for the final bracket (a, b) [unit of the parameter] with the observable `ya`,
        `yb` at its ends, the level `lev`, and the observable `y_a`, `y_b` at the initial ends; `stats`: the
        remaining fields (`n_solves`, `n_derivative_solves`, `history`, `method`, `compile_time`, `steps`,
        `notes`)."""
        return Bifurcation(
            param=self.param,
            unit=self.unit,
            observable=self.obs.name,
            value=0.5 * (a + b),
            bracket=(a, b),
            width=b - a,
            level=float(lev),
            y_lo=float(ya),
            y_hi=float(yb),
            tol=self.tol,
            n_uniform=self.n_uniform,
            converged=(b - a) <= self.tol,
            wall_time=time.perf_counter() - self.wall0,
            jump_fraction=jump_fraction(ya, yb, y_a, y_b),
            **stats,
        )


@dataclasses.dataclass(frozen=True)
class _Spec:
    path: str
    observable: obs_mod.Observable
    options: SolverOptions


def _value(scenario, x, ts, spec: _Spec):
    sc = set_param(scenario, spec.path, x)
    traj = solve(sc, ts, spec.options)
    return jnp.asarray(spec.observable(traj, sc), dtype=jnp.float64), (traj.status, traj.num_accepted_steps)


def _jvp(scenario, x, ts, spec: _Spec):
    y, dy, aux = jax.jvp(lambda p: _value(scenario, p, ts, spec), (x,), (jnp.ones_like(x),), has_aux=True)
    return y, dy, aux


class Evaluator:
    """Counts solves (`n_value`, `n_jvp`), solver `steps` and `compile_time` [s], and turns a failed solve
    into a `BifurcationError` naming the parameter value."""

    def __init__(self, scenario, path, observable, ts, options: SolverOptions):
        self.scenario, self.path, self.ts = scenario, path, ts
        self.value_spec = _Spec(path, observable, options)
        self.jvp_spec = _Spec(path, observable, options.replace(adjoint=diffrax.ForwardMode()))
        self.n_value = 0
        self.n_jvp = 0
        self.steps = 0
        self.compile_time = 0.0

    @property
    def n_solves(self) -> int:
        return self.n_value + self.n_jvp

    def _call(self, kind, x):
        spec = self.value_spec if kind == "value" else self.jvp_spec
        fn = _value if kind == "value" else _jvp
        args = (self.scenario, jnp.asarray(x, dtype=jnp.float64), self.ts, spec)
        exe, seconds, _ = program(f"bifurcation-{kind}", f"bifurcation-{kind}", fn, args)
        self.compile_time += seconds
        out = jax.block_until_ready(exe(*args))
        aux = out[-1]
        status, steps = int(aux[0]), int(aux[1])
        self.steps += steps
        if status != SolveStatus.OK:
            raise BifurcationError(
                f"the solve at {self.path} = {float(x)!r} failed: {SolveStatus(status).message}",
                n_solves=self.n_solves,
            )
        return out

    def value(self, x) -> float:
        """The observable at `x` [unit of the parameter] (one solve)."""
        self.n_value += 1
        y, _ = self._call("value", x)
        return float(y)

    def value_and_slope(self, x) -> tuple[float, float]:
        """The observable and its derivative in the parameter at `x` (one forward-mode solve)."""
        self.n_jvp += 1
        y, dy, _ = self._call("jvp", x)
        return float(y), float(dy)
