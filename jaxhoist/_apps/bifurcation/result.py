"""What the bifurcation locator returns: `Bifurcation` (one located change), `Boundary` (a boundary p*(q)
traced by continuation) and `BifurcationError` (the locator could not proceed)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np


class BifurcationError(RuntimeError):
    """The locator could not proceed: no sign change in the bracket, or a solve failed. `n_solves` says how
    many solves were spent before giving up."""

    def __init__(self, msg: str, n_solves: int = 0):
        super().__init__(msg)
        self.n_solves = n_solves


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
    - `converged`: width <= tol; `method` (its name); `wall_time`, `compile_time` [s]; `steps`: total
      solver steps.
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
        """One line: the located value to the digits its bracket supports (`fmt_located`), the bracket
        rounded outward, the change of the observable and the solves it took."""
        unit = "" if self.unit in ("-", "") else f" {self.unit}"
        lo, hi = self.bracket
        return (
            f"{self.param} * = {fmt_located(self.value, self.width)}{unit} (bracket "
            f"[{fmt_located(lo, self.width, -1)}, {fmt_located(hi, self.width, +1)}], width "
            f"{self.width:.2g}): {self.observable} changes from "
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


def fmt_located(x: float, width: float, direction: int = 0) -> str:
    """`x` written to the digits that a bracket of `width` supports: down to the decimal place of `width`'s
    leading digit (width 4.5e-7 -> 1e-7: 0.2795234), no more. `direction` -1 or +1 rounds down or up (a
    bracket's ends, so the printed bracket holds the computed one), 0 to nearest.

    **Arguments**
    - `x`: the value; `width`: the bracket width, in `x`'s unit (0 or not finite: 10 significant digits).
    - `direction`: the rounding, -1 down, 0 nearest, +1 up.

    **Returns** the text.
    """
    if not (np.isfinite(x) and np.isfinite(width) and width > 0):
        return f"{x:.10g}"
    e = int(np.floor(np.log10(width)))  # the decimal place of width's leading digit
    q = 10.0**e
    r = {-1: np.floor, 0: np.round, 1: np.ceil}[direction](x / q) * q
    if e < 0:
        return f"{r:.{-e}f}"
    return f"{r:.0f}"


def jump_fraction(ya, yb, y_a, y_b) -> float:
    """|yb - ya| / |y_b - y_a| (final bracket over initial bracket, in the observable's unit), with an event
    that happens on one side only counting as a full jump."""
    if not (np.isfinite(y_a) and np.isfinite(y_b)):
        return 1.0 if np.isfinite(ya) != np.isfinite(yb) else 0.0
    full = abs(y_b - y_a)
    return float(abs(yb - ya) / full) if full > 0 else 0.0


@dataclasses.dataclass
class Boundary:
    """A boundary p*(q) traced by continuation.

    - `param`, `along`: the located parameter p and the continuation parameter q (paths).
    - `along_values`, `values`: q_k and p*(q_k) [their units] (NaN where the corrector failed or lost the
      jump); `widths`: final brackets [unit of p].
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
