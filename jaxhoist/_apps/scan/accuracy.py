"""Scans that report their own accuracy: `AccuracyCheck` re-solves a random, seeded subset of a scan's healthy
members at a much tighter tolerance, as a small `Points` scan through the same machinery, and reports how far
each observable of the scan is from that reference (`ScanResult.accuracy`, `scan.json`).

The reference is the scan's own solver family at a 1000x tighter tolerance: by default the Rosenbrock-W
solver at rtol = min(5e-7, rtol/1000), atol = min(1e-8, atol/1000) (fixed-step scans: rtol 5e-7, atol 1e-8).
On paper-4.2 over 4 s it takes about 6x the default's time per member and agrees with Tsit5 at rtol 1e-9 to
well under 1 mm, where Tsit5 at rtol 1e-9 takes about 45x (docs/how-to-scan.md). Its own error is then about
a thousandth of the scan's, so the differences it reports are the scan's error.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import numpy as np

from ..._errors import ScenarioError
from ..._numerics.options import SolverOptions
from ..._numerics.times import Times
from .result import ScanResult
from .sweep import Points

#: A scan of this many members or more checks its accuracy unless told not to (`scan(accuracy=False)`).
AUTO_MIN_MEMBERS = 1024

#: The reference's tolerances are the scan's divided by this (and at most the defaults below).
TIGHTENING = 1000.0
REFERENCE_RTOL = 5e-7
REFERENCE_ATOL = 1e-8


class AccuracyCheck(eqx.Module):
    """How a scan checks its own accuracy (the `accuracy` argument of `scan`).

    - `members`: how many healthy members to re-solve (chosen at random, without repetition; all of them
      if the scan has fewer) [-].
    - `options`: the reference's `SolverOptions`; default (None): the default Rosenbrock-W solver at
      rtol = min(5e-7, rtol/1000), atol = min(1e-8, atol/1000) of the scan's options, a step budget of
      2 000 000.
    - `length_target`: the accuracy asked of observables in metres (e.g. `final_position`): a member is
      over the target where the distance between its value and the reference's (the Euclidean norm over the
      components) exceeds it [m].
    - `relative_target`: the accuracy asked of every other observable (angles, times, forces): a member is
      over the target where some component differs from the reference by more than `relative_target` times
      the largest magnitude of that component among the re-solved members' reference values [-].
    - `seed`: the seed of the random choice of members (the same seed, the same members).

    **Raises** `ScenarioError` for `members` below 1 or a target that is not a positive number.
    """

    members: int = eqx.field(default=16, static=True)
    options: SolverOptions | None = None
    length_target: float = eqx.field(default=0.01, static=True)
    relative_target: float = eqx.field(default=0.01, static=True)
    seed: int = eqx.field(default=0, static=True)

    def __check_init__(self):
        if int(self.members) < 1:
            raise ScenarioError(f"AccuracyCheck.members must be >= 1, got {self.members}")
        for name in ("length_target", "relative_target"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ScenarioError(f"AccuracyCheck.{name} must be a positive number, got {v}")
        if self.options is not None and not isinstance(self.options, SolverOptions):
            raise ScenarioError(
                f"AccuracyCheck.options must be a jaxhoist.SolverOptions, got {type(self.options).__name__}"
            )


def resolve(accuracy: object, n_members: int) -> AccuracyCheck | None:
    """The check a scan of `n_members` runs: `None` (the default) -> `AccuracyCheck()` for scans of
    `AUTO_MIN_MEMBERS` members or more, none below; True -> `AccuracyCheck()`; False -> none; an
    `AccuracyCheck` -> itself. **Raises** `ScenarioError` for anything else."""
    if accuracy is None:
        return AccuracyCheck() if n_members >= AUTO_MIN_MEMBERS else None
    if isinstance(accuracy, bool):
        return AccuracyCheck() if accuracy else None
    if isinstance(accuracy, AccuracyCheck):
        return accuracy
    raise ScenarioError(
        f"accuracy must be None (automatic), True, False or a jaxhoist.AccuracyCheck, got "
        f"{type(accuracy).__name__}"
    )


def reference_options(check: AccuracyCheck, options: SolverOptions) -> SolverOptions:
    """The reference's `SolverOptions`: `check.options`, or the default solver 1000x tighter than
    `options`."""
    if check.options is not None:
        return check.options
    rtol, atol = REFERENCE_RTOL, REFERENCE_ATOL
    if not options.fixed_step and options.rtol is not None and options.atol is not None:
        rtol, atol = min(rtol, options.rtol / TIGHTENING), min(atol, options.atol / TIGHTENING)
    return SolverOptions(rtol=rtol, atol=atol, max_steps=2_000_000)


def choose(result: ScanResult, check: AccuracyCheck) -> np.ndarray:
    """The flat indices of the members to re-solve: up to `check.members` healthy members, drawn with
    `numpy.random.default_rng(check.seed)`, in increasing order."""
    ok = np.flatnonzero(result.ok.ravel())
    k = min(int(check.members), ok.size)
    rng = np.random.default_rng(check.seed)
    return np.sort(rng.choice(ok, size=k, replace=False)) if k else ok[:0]


def _suggestion(options: SolverOptions) -> dict[str, float]:
    """The option that gives more accuracy: rtol and atol 10x smaller, or steps 4x shorter."""
    if options.fixed_step and options.dt0 is not None:
        return {"dt0": float(options.dt0) / 4}
    if options.rtol is not None and options.atol is not None:
        return {"rtol": float(options.rtol) / 10, "atol": float(options.atol) / 10}
    return {}


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def check_accuracy(
    result: ScanResult,
    check: AccuracyCheck,
    *,
    scenario,
    ts,
    observables,
    options: SolverOptions,
    run_scan: Callable[..., ScanResult],
) -> dict[str, Any]:
    """Re-solve the members `choose(result, check)` with `reference_options` through `run_scan` (the scan
    entry point, called with a `Points` sweep, `observables` and no accuracy check of its own) and compare.

    **Returns** the JSON-ready report stored as `result.attrs["accuracy"]`: the members re-solved
    (`indices`, flat), the reference (`reference`: its options described), the targets, per observable
    `kind` ("length": distance [m]; "relative": relative difference [-]), `median`, `max` (None where a value
    is NaN in one solve and not the other), `over_target` (members), `target`; in all `over_target` (members
    over the target in some observable), `reference_failed` (members whose reference solve failed, left out)
    and `suggest` (the option that gives more accuracy, where members are over the target)."""
    idx = choose(result, check)
    ref_opts = reference_options(check, options)
    report: dict[str, Any] = {
        "members": int(idx.size),
        "indices": [int(i) for i in idx],
        "seed": int(check.seed),
        "reference": ref_opts.describe(),
        "length_target_m": float(check.length_target),
        "relative_target": float(check.relative_target),
        "observables": {},
        "over_target": 0,
        "reference_failed": 0,
        "suggest": None,
    }
    if idx.size == 0:
        return report
    values = {p: np.asarray(result.values(p)).ravel()[idx] for p in result.params}
    ref = run_scan(
        scenario, Points(values), Times(ts=np.asarray(ts)), observables=observables, options=ref_opts
    )
    ref_ok = ref.ok.ravel()
    report["reference_failed"] = int(np.sum(~ref_ok))
    over_any = np.zeros(idx.size, dtype=bool)
    for name, data in result.data.items():
        if name.startswith("d_") and name[2:] in result.data:
            continue  # sensitivities: the reference solves no derivatives
        a = np.asarray(data).reshape(result.size, -1)[idx][ref_ok]
        b = np.asarray(ref.data[name]).reshape(idx.size, -1)[ref_ok]
        same = (a == b) | (np.isnan(a) & np.isnan(b))  # equal, both inf (no event) or both undefined
        with np.errstate(invalid="ignore"):
            diff = np.where(same, 0.0, np.abs(a - b))  # NaN or inf where only one of them is defined
        if result.units.get(name) == "m":
            kind, target = "length", float(check.length_target)
            d = np.sqrt(np.sum(diff**2, axis=1))
        else:
            kind, target = "relative", float(check.relative_target)
            scale = np.max(np.where(np.isfinite(b), np.abs(b), 0.0), axis=0, initial=0.0)
            scale = np.where(scale > 0, scale, 1.0)
            d = np.max(diff / scale, axis=1) if diff.size else np.zeros(0)
        d = np.where(np.isfinite(d), d, np.inf)  # defined in one solve, undefined in the other
        over = d > target
        over_any[np.flatnonzero(ref_ok)] |= over
        report["observables"][name] = {
            "kind": kind,
            "unit": "m" if kind == "length" else "1",
            "median": _finite(float(np.median(d))) if d.size else None,
            "max": _finite(float(np.max(d))) if d.size else None,
            "over_target": int(np.sum(over)),
            "target": target,
        }
    report["over_target"] = int(np.sum(over_any))
    if report["over_target"]:
        report["suggest"] = _suggestion(options)
    return report


def _length(x: float | None) -> str:
    if x is None:
        return "undefined"
    if x >= 0.1:
        return f"{x:.3g} m"
    if x >= 0.01:
        return f"{1e2 * x:.2g} cm"
    return f"{1e3 * x:.2g} mm"


def _relative(x: float | None) -> str:
    return "undefined" if x is None else f"{x:.1e}"


def summary(report: dict[str, Any] | None, flag: Callable[[str, float], str] | None = None) -> str:
    """One line of a report: the members, the reference's rtol, the worst observable (the first length
    observable, else the one farthest over its target) with its max and median, the members over the target
    and, where some are, the option that gives more accuracy (`flag(name, value)` writes it, e.g.
    `--rtol 5e-05`; default `rtol=5e-05`)."""
    if report is None:
        return "not checked"
    n, obs = report["members"], report["observables"]
    rtol = report["reference"].get("rtol")
    head = f"{n} members re-solved" + (f" at rtol {rtol:.0e}" if rtol else "")
    if not obs or n == 0:
        return head + ": no healthy member to check"

    def badness(item):
        v = item[1]
        return (v["max"] is None, (v["max"] or 0.0) / v["target"])

    lengths = [(k, v) for k, v in obs.items() if v["kind"] == "length"]
    name, v = max(lengths or list(obs.items()), key=badness)
    fmt = _length if v["kind"] == "length" else _relative
    what = "" if v["kind"] == "length" else " (relative)"
    target = _length(v["target"]) if v["kind"] == "length" else f"{v['target']:g} relative"
    line = f"{head}: {name}{what} max {fmt(v['max'])}, median {fmt(v['median'])}"
    others = sum(1 for k, w in obs.items() if k != name and w["over_target"])
    line += f"; {report['over_target']} over {target}" + (" or another target" if others else "")
    if report["reference_failed"]:
        line += f"; reference failed for {report['reference_failed']}"
    if report["suggest"]:
        flag = flag or (lambda k, x: f"{k}={x:.0e}")
        line += "; for more accuracy: " + " ".join(flag(k, x) for k, x in report["suggest"].items())
    return line
