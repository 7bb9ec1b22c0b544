"""How `locate_bifurcation` and `trace_boundary` search, as objects: the refinement method (`Newton`,
`Bisection`, `Multisection`), the tolerance and solve budget, and the bracketing of the continuation
corrector (`SearchOptions`), and the locator's default solver settings."""

from __future__ import annotations

import numbers
from typing import ClassVar

import diffrax
import equinox as eqx
import numpy as np

from ..._errors import ScenarioError
from ..._io.validate import whole_number
from ..._numerics.options import SolverOptions


class AbstractSearchMethod(eqx.Module):
    """How the bracket around a change of character is narrowed."""

    name: ClassVar[str]


class Newton(AbstractSearchMethod):
    """Safeguarded Newton on the indicator g, with dg/dp [1/unit of the parameter] from forward-mode
    sensitivities; bisection whenever a Newton step leaves the bracket or does not shrink it fast enough."""

    name: ClassVar[str] = "newton"


class Bisection(AbstractSearchMethod):
    """Bisection with value-only solves (~log2(width/tol) of them)."""

    name: ClassVar[str] = "bisection"


class Multisection(AbstractSearchMethod):
    """`points_per_round` values per round in one vmapped `scan` (more solves, fewer rounds of wall time).

    - `points_per_round`: values solved per round (>= 2).
    - `lanes`: members per vmapped group of the scan.
    """

    name: ClassVar[str] = "multisection"
    points_per_round: int = eqx.field(static=True, default=16)
    lanes: int = eqx.field(static=True, default=16)

    def __check_init__(self):
        if self.points_per_round < 2:
            raise ScenarioError(
                f"points_per_round must be >= 2 for multisection, got {self.points_per_round}"
            )


_METHODS = {"newton": Newton, "bisection": Bisection, "multisection": Multisection}


def as_method(method) -> AbstractSearchMethod:
    """The method object for the command line's `--method` name ("newton", "bisection", "multisection"),
    or an `AbstractSearchMethod` as it is."""
    if isinstance(method, AbstractSearchMethod):
        return method
    if isinstance(method, str) and method in _METHODS:
        return _METHODS[method]()
    raise ScenarioError(f"method must be 'newton', 'bisection' or 'multisection', got {method!r}")


class SearchOptions(eqx.Module):
    """Settings of the bifurcation search (host-side numbers; nothing here is traced).

    - `method`: `Newton()` (default), `Bisection()` or `Multisection(points_per_round, lanes)`.
    - `tol`: the final bracket width [unit of the located parameter], > 0.
    - `max_solves`: give up (converged=False) after this many solves, a whole number >= 2 (>=
      `points_per_round` for multisection).
    - `initial_half_width`: `trace_boundary` only: the corrector's half-width at the second point [unit of
      the parameter] (default None: 5 % of the initial bracket).
    - `max_expansions`: `trace_boundary` only: how many times the corrector's bracket is doubled before a
      point is given up.
    - `min_jump_fraction`: `trace_boundary` only (with `level=None`): a point whose change across its final
      bracket is below this fraction of the first point's is reported lost.

    **Raises** `ScenarioError` for a non-positive `tol`, an unknown method, fewer than 2 points per round,
    a `max_solves` that is no whole number or below what the method needs first (2 solves for the ends of
    the bracket; `points_per_round` for multisection), a non-positive `initial_half_width`, a
    `max_expansions` below 1 or a negative `min_jump_fraction`.
    """

    method: AbstractSearchMethod
    tol: float = eqx.field(static=True)
    max_solves: int = eqx.field(static=True)
    initial_half_width: float | None = eqx.field(static=True)
    max_expansions: int = eqx.field(static=True)
    min_jump_fraction: float = eqx.field(static=True)

    def __init__(
        self,
        method: AbstractSearchMethod = Newton(),
        tol: float = 1e-6,
        max_solves: int = 200,
        *,
        initial_half_width: float | None = None,
        max_expansions: int = 8,
        min_jump_fraction: float = 0.1,
    ):
        if not isinstance(method, AbstractSearchMethod):
            raise ScenarioError(f"method must be Newton(), Bisection() or Multisection(...), got {method!r}")
        self.method = method
        if not (np.isfinite(tol) and tol > 0):
            raise ScenarioError(f"tol must be > 0, got {tol}")
        self.tol = tol
        # the two ends of the bracket; multisection's first round solves points_per_round values at once
        least = max(2, method.points_per_round) if isinstance(method, Multisection) else 2
        if not whole_number(max_solves) or max_solves < least:
            why = (
                "points_per_round, its first round"
                if isinstance(method, Multisection)
                else "the two ends of the bracket"
            )
            raise ScenarioError(f"max_solves must be a whole number >= {least} ({why}), got {max_solves!r}")
        self.max_solves = int(max_solves)
        if initial_half_width is not None and not (
            _is_real(initial_half_width) and np.isfinite(initial_half_width) and initial_half_width > 0
        ):
            raise ScenarioError(
                f"initial_half_width must be > 0 (or None: 5 % of the bracket), got {initial_half_width!r}"
            )
        self.initial_half_width = initial_half_width
        if not whole_number(max_expansions) or max_expansions < 1:
            raise ScenarioError(f"max_expansions must be a whole number >= 1, got {max_expansions!r}")
        self.max_expansions = int(max_expansions)
        if not (_is_real(min_jump_fraction) and np.isfinite(min_jump_fraction) and min_jump_fraction >= 0):
            raise ScenarioError(f"min_jump_fraction must be a finite number >= 0, got {min_jump_fraction!r}")
        self.min_jump_fraction = min_jump_fraction


def _is_real(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def default_solver_options() -> SolverOptions:
    """The locator's solver settings: `diffrax.Tsit5()` with rtol 1e-6, atol 1e-8 (its default tolerances).
    Not the Rosenbrock-W solver of `simulate` and `scan`: a locator needs the observable to well below its
    `tol` and a slope per Newton step; at its default tolerances W puts μ* further off than Tsit5 and its
    first call compiles for about twice as long (docs/bifurcation-studies.md, "Why Tsit5 for the locator",
    A script since removed)."""
    return SolverOptions(solver=diffrax.Tsit5())


def settings(
    search: SearchOptions | None, options: SolverOptions | None
) -> tuple[SearchOptions, SolverOptions]:
    """(search, options) with the defaults `SearchOptions()` and `default_solver_options()` filled in.

    **Raises** `ScenarioError` for a `search` or `options` of the wrong type."""
    if search is None:
        search = SearchOptions()
    elif not isinstance(search, SearchOptions):
        raise ScenarioError(f"search must be a jaxhoist.SearchOptions, got {type(search).__name__}")
    if options is None:
        options = default_solver_options()
    elif not isinstance(options, SolverOptions):
        raise ScenarioError(f"options must be a jaxhoist.SolverOptions, got {type(options).__name__}")
    return search, options
