"""Scans that report their own accuracy: `AccuracyCheck` re-solves a subset of a scan's healthy members at a
much tighter tolerance, as a small `Points` scan through the same machinery, and reports how far each
observable and each kept history of the scan is from that reference (`ScanResult.accuracy`, `scan.json`).

The subset is targeted and random: half of it is the members whose solves took the most steps (accepted
and rejected), the other half is drawn at random, seeded, from the other healthy members. The step count is
the cheapest indicator of a member's error that the scan already holds: on the random plausible scenarios
of `experiments/figures/robustness.py` (three seeds of 48 over 8 s) a member's distance to a tight reference
has a Spearman rank correlation of 0.6 to 0.85 with its step count, of 0.25 to 0.5 with the energy
balance's residual and at most 0.55 with any single parameter (the hoist speed). The random half keeps the
reported median an unbiased sample of the healthy members. Where the largest difference is near the target
(within a factor `margin`, 4) but not over it, the check re-solves more members, the next by step count:
the differences among a scan's members spread over decades, so a worst sampled member at a quarter of the
target says that an unsampled one may be over it.

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

    - `members`: how many healthy members to re-solve (all of them if the scan has fewer) [-].
    - `most_steps`: the share of `members` taken as the healthy members whose solves took the most steps
      (accepted plus rejected: the members most likely to be the least accurate); the rest are drawn at
      random from the other healthy members [-], in [0, 1].
    - `max_members`: where the largest difference found is within a factor `margin` of its target but not
      over it, the check re-solves `members` more, the next by step count, until a member is over the
      target, the largest difference is below target / `margin`, or `max_members` have been re-solved
      (at least `members`; default None: 4 `members`) [-].
    - `margin`: that factor (>= 1; 1: never re-solve more than `members`) [-].
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

    **Raises** `ScenarioError` for `members` below 1, `most_steps` outside [0, 1], `margin` below 1 or a
    target that is not a positive number.
    """

    members: int = eqx.field(default=16, static=True)
    most_steps: float = eqx.field(default=0.5, static=True)
    max_members: int | None = eqx.field(default=None, static=True)
    margin: float = eqx.field(default=4.0, static=True)
    options: SolverOptions | None = None
    length_target: float = eqx.field(default=0.01, static=True)
    relative_target: float = eqx.field(default=0.01, static=True)
    seed: int = eqx.field(default=0, static=True)

    def __check_init__(self):
        if int(self.members) < 1:
            raise ScenarioError(f"AccuracyCheck.members must be >= 1, got {self.members}")
        share = float(self.most_steps)
        if not 0.0 <= share <= 1.0:
            raise ScenarioError(f"AccuracyCheck.most_steps must be a share in [0, 1], got {self.most_steps}")
        if self.max_members is not None and int(self.max_members) < 1:
            raise ScenarioError(f"AccuracyCheck.max_members must be >= 1 or None, got {self.max_members}")
        if not float(self.margin) >= 1.0:
            raise ScenarioError(f"AccuracyCheck.margin must be >= 1, got {self.margin}")
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


def by_steps(result: ScanResult) -> np.ndarray:
    """The flat indices of the healthy members, the most solver steps (accepted plus rejected) first, ties
    to the lower index."""
    ok = np.flatnonzero(result.ok.ravel())
    steps = (result.num_accepted_steps.ravel() + result.num_rejected_steps.ravel())[ok]
    return ok[np.argsort(-steps, kind="stable")]


def choose(result: ScanResult, check: AccuracyCheck) -> tuple[np.ndarray, np.ndarray]:
    """The flat indices of the members to re-solve, each in increasing order: `(most, drawn)`, the
    `round(check.most_steps * k)` healthy members with the most solver steps (accepted plus rejected; ties
    to the lower index) and the rest of the `k = min(check.members, healthy members)` drawn without
    repetition from the other healthy members with `numpy.random.default_rng(check.seed)`."""
    ok = by_steps(result)
    k = min(int(check.members), ok.size)
    n_most = int(round(float(check.most_steps) * k))
    most = np.sort(ok[:n_most])
    rest = np.setdiff1d(ok, most)
    rng = np.random.default_rng(check.seed)
    drawn = np.sort(rng.choice(rest, size=k - n_most, replace=False)) if k > n_most else ok[:0]
    return most, drawn


def _suggestion(options: SolverOptions) -> dict[str, float]:
    """The option that gives more accuracy: rtol and atol 10x smaller, or steps 4x shorter."""
    if options.fixed_step and options.dt0 is not None:
        return {"dt0": float(options.dt0) / 4}
    if options.rtol is not None and options.atol is not None:
        return {"rtol": float(options.rtol) / 10, "atol": float(options.atol) / 10}
    return {}


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _differences(a: np.ndarray, b: np.ndarray, length: bool) -> np.ndarray:
    """Per member, the difference between `a` and `b`, both shaped (members, saved times, components)
    (one saved time for an observable): the largest distance over the saved times [m] (`length`: the
    Euclidean norm over the components), or the largest component-wise difference relative to the largest
    magnitude of that component in `b` (over its members and saved times) [-]; inf where a value is defined
    in one and not the other."""
    same = (a == b) | (np.isnan(a) & np.isnan(b))  # equal, both inf (no event) or both undefined
    with np.errstate(invalid="ignore"):
        diff = np.where(same, 0.0, np.abs(a - b))  # NaN or inf where only one of them is defined
    if diff.size == 0:
        return np.zeros(a.shape[0])
    if length:
        d = np.max(np.sqrt(np.sum(diff**2, axis=2)), axis=1)
    else:
        scale = np.max(np.where(np.isfinite(b), np.abs(b), 0.0), axis=(0, 1))
        scale = np.where(scale > 0, scale, 1.0)
        d = np.max(diff / scale, axis=(1, 2))
    return np.where(np.isfinite(d), d, np.inf)


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
    entry point, called with a `Points` sweep, `observables`, the scan's `histories` and no accuracy check
    of its own) and compare; while the largest difference is within `check.margin` of its target but not
    over it, re-solve `check.members` more, the next by step count, up to `check.max_members` (each round
    as many members as the first, so the reference is compiled once).

    **Returns** the JSON-ready report stored as `result.attrs["accuracy"]`: the members re-solved
    (`members`, `indices`, flat; `chosen`: `most_steps`, the members with the most solver steps, `random`,
    the ones drawn, and `more`, those re-solved in further rounds; `rounds`), the reference (`reference`:
    its options described), the targets, per observable (`observables`) and per kept history (`histories`:
    the largest difference over the saved times) `kind` ("length": distance [m]; "relative": relative
    difference [-]), `median` (over the drawn members, an unbiased sample of the healthy ones; over all
    re-solved where none is drawn), `max` (over all re-solved; None where a value is NaN in one solve and
    not the other), `over_target` (members), `target`; in all `over_target` (members over the target in
    some observable or history), `reference_failed` (members whose reference solve failed, left out) and
    `suggest` (the option that gives more accuracy, where members are over the target)."""
    most, drawn = choose(result, check)
    first = np.sort(np.concatenate([most, drawn]))
    ref_opts = reference_options(check, options)
    report: dict[str, Any] = {
        "members": 0,
        "indices": [],
        "chosen": {"most_steps": [int(i) for i in most], "random": [int(i) for i in drawn], "more": []},
        "rounds": 0,
        "seed": int(check.seed),
        "reference": ref_opts.describe(),
        "length_target_m": float(check.length_target),
        "relative_target": float(check.relative_target),
        "observables": {},
        "histories": {},
        "over_target": 0,
        "reference_failed": 0,
        "suggest": None,
    }
    if first.size == 0:
        return report
    size = first.size
    cap = 4 * int(check.members) if check.max_members is None else int(check.max_members)
    hist = tuple(result.histories)
    entries: dict[tuple[str, str], dict[str, Any]] = {}
    done: list[np.ndarray] = []
    failed = 0
    todo = first
    while todo.size:
        rows = np.concatenate([todo, np.repeat(todo[:1], size - todo.size)])  # the first round's size
        values = {p: np.asarray(result.values(p)).ravel()[rows] for p in result.params}
        ref = run_scan(
            scenario,
            Points(values),
            Times(ts=np.asarray(ts)),
            observables=observables,
            options=ref_opts,
            histories=hist,
        )
        ref_ok = ref.ok.ravel()[: todo.size]
        failed += int(np.sum(~ref_ok))
        compared = [("observables", k, v, ref.data[k]) for k, v in result.data.items()]
        compared += [("histories", k, v, ref.histories[k]) for k, v in result.histories.items()]
        for group, name, data, ref_data in compared:
            if group == "observables" and name.startswith("d_") and name[2:] in result.data:
                continue  # sensitivities: the reference solves no derivatives
            n_t = 1 if group == "observables" else len(ts)  # a history's axis after the members: time
            a = np.asarray(data).reshape(result.size, n_t, -1)[todo][ref_ok]
            b = np.asarray(ref_data).reshape(size, n_t, -1)[: todo.size][ref_ok]
            length = result.units.get(name) == "m"
            e = entries.setdefault(
                (group, name),
                {
                    "kind": "length" if length else "relative",
                    "target": float(check.length_target if length else check.relative_target),
                    "index": [],
                    "d": [],
                },
            )
            e["index"].append(todo[ref_ok])
            e["d"].append(_differences(a, b, length))
        done.append(todo)
        worst = max(
            (float(np.max(np.concatenate(e["d"]), initial=0.0)) / e["target"] for e in entries.values()),
            default=0.0,
        )
        n_done = sum(x.size for x in done)
        if worst > 1.0 or worst <= 1.0 / float(check.margin) or n_done >= cap:
            break
        seen = np.concatenate(done)
        rest = by_steps(result)
        rest = rest[~np.isin(rest, seen)][: min(size, cap - n_done)]
        todo = np.sort(rest)
        report["chosen"]["more"] += [int(i) for i in todo]
    idx = np.sort(np.concatenate(done))
    report.update(
        members=int(idx.size), indices=[int(i) for i in idx], rounds=len(done), reference_failed=failed
    )
    over_members: set[int] = set()
    for (group, name), e in entries.items():
        index, d = np.concatenate(e["index"]), np.concatenate(e["d"])
        over = d > e["target"]
        over_members.update(int(i) for i in index[over])
        sample = d[np.isin(index, drawn)]
        sample = sample if sample.size else d
        report[group][name] = {
            "kind": e["kind"],
            "unit": "m" if e["kind"] == "length" else "1",
            "median": _finite(float(np.median(sample))) if sample.size else None,
            "max": _finite(float(np.max(d))) if d.size else None,
            "over_target": int(np.sum(over)),
            "target": e["target"],
        }
    report["over_target"] = len(over_members)
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
    """One line of a report: the members (how many of them were taken for their step counts, how many
    more were re-solved because the differences came near the target), the reference's rtol, the worst
    observable or kept history (the length farthest over its target, else the one farthest over its
    target) with its max and median, the members over the target and, where some are, the option that
    gives more accuracy (`flag(name, value)` writes it, e.g. `--rtol 5e-05`; default `rtol=5e-05`)."""
    if report is None:
        return "not checked"
    n = report["members"]
    obs = dict(report["observables"])
    obs.update({f"{k} (history)": v for k, v in report.get("histories", {}).items()})
    rtol = report["reference"].get("rtol")
    chosen = report.get("chosen", {})
    n_most, n_more = len(chosen.get("most_steps", ())), len(chosen.get("more", ()))
    how = [f"{n_most} with the most steps"] if n_most else []
    how += [f"{n_more} more by steps, the differences being near the target"] if n_more else []
    head = f"{n} members re-solved" + (f" ({', '.join(how)})" if how else "")
    head += f" at rtol {rtol:.0e}" if rtol else ""
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
