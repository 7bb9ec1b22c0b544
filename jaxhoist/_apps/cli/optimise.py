"""`jaxhoist optimise-lift`: the command line of `optimise_lift` (argument parsing, the report it prints, the
JSON it writes).

    jaxhoist optimise-lift my-lift.toml --uncertain "foundation.friction_coefficient=uniform(0.2,0.4)" \\
        --bound "boom.tip_position[0]=1:2.5" --bound "hoist.speed=0.2:0.5" \\
        --objective max_rope_tension=1e-4 --objective hoist_time=0.1 --hoist-distance 1 \\
        --limit slide=0.25:0.05 --samples 16 --t1 3 --out out/optimise
"""

from __future__ import annotations

import json
import math

from ..._errors import ScenarioError
from ..planning import OptimisedLift, optimise_lift
from .common import (
    add_out_options,
    add_sampled_scan_command,
    add_sampled_scan_options,
    claim_out_dir,
    sampled_scan_inputs,
)
from .risk import parse_hazard, parse_uncertain, split_item


def _float(text: str, flag: str, item: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ScenarioError(f"{flag} {item!r}: {text!r} is not a number") from None


def parse_bound(item: str) -> tuple[str, tuple[float, float]]:
    """`PATH=LOW:HIGH` -> (path, (low, high)), or a `ScenarioError` naming the flag."""
    path, spec = split_item(item, "--bound")
    low, colon, high = spec.partition(":")
    if not colon:
        raise ScenarioError(f"--bound {item!r}: expected PATH=LOW:HIGH, e.g. hoist.speed=0.2:0.5")
    return path, (_float(low, "--bound", item), _float(high, "--bound", item))


def parse_objective(item: str) -> tuple[str, float]:
    """`NAME` (weight 1) or `NAME=WEIGHT` -> (name, weight)."""
    name, eq, weight = item.partition("=")
    if not name.strip():
        raise ScenarioError(f"--objective {item!r}: expected NAME or NAME=WEIGHT, e.g. max_rope_tension=1e-4")
    return name.strip(), (_float(weight, "--objective", item) if eq else 1.0)


def parse_limit(item: str):
    """`HAZARD:P` (the hazard as for `jaxhoist risk --hazard`, P its largest probability) -> (Hazard, P)."""
    spec, colon, p = item.rpartition(":")
    if not colon or not spec.strip():
        raise ScenarioError(f"--limit {item!r}: expected HAZARD:P, e.g. slide=0.25:0.05 or strike:0.1")
    return parse_hazard(spec, "--limit"), _float(p, "--limit", item)


def configure_parser(subparsers) -> None:
    """Add `jaxhoist optimise-lift SCENARIO --uncertain PATH=DIST ... --bound PATH=LOW:HIGH ...
    --objective NAME[=WEIGHT] ... [--limit HAZARD:P ...]`."""
    p = add_sampled_scan_command(
        subparsers,
        "optimise-lift",
        "the design within bounds that minimises an expected outcome of a lift with uncertain inputs",
        "Minimise a weighted sum of expected smooth outcomes over a fixed sample of the uncertain inputs by "
        "L-BFGS-B on the forward sensitivities, then check the hazard limits on a fresh sample "
        "(docs/lift-optimisation.md).",
    )
    p.add_argument(
        "--bound",
        action="append",
        required=True,
        metavar="PATH=LOW:HIGH",
        help="a design variable and its bounds (repeatable), e.g. hoist.speed=0.2:0.5",
    )
    p.add_argument(
        "--objective",
        action="append",
        required=True,
        metavar="NAME[=WEIGHT]",
        help="a term of the objective (repeatable): a scalar observable (max_rope_tension, ground_slide, "
        "swing_amplitude, max_tilt, ...) or hoist_time (needs --hoist-distance), with its weight",
    )
    p.add_argument(
        "--limit",
        action="append",
        default=[],
        metavar="HAZARD:P",
        help="a hazard and its largest probability (repeatable), checked on a fresh sample, e.g. "
        "slide=0.25:0.05, tilt=10deg:0.1, strike:0.1",
    )
    p.add_argument("--hoist-distance", type=float, default=None, help="rope to reel in [m] for hoist_time")
    p.add_argument("--samples", type=int, default=64, help="members of the fixed sample")
    p.add_argument("--seed", type=int, default=0, help="seed of the fixed sample")
    p.add_argument("--starts", type=int, default=1, help="starting points screened (1: the scenario's)")
    p.add_argument("--max-iterations", type=int, default=30, help="L-BFGS-B iterations at most")
    p.add_argument("--penalty", type=float, default=0.0, help="weight of the softplus penalty of the limits")
    p.add_argument("--check-samples", type=int, default=256, help="members of the fresh sample of the check")
    p.add_argument("--check-replicates", type=int, default=8, help="scrambles of the check's sample")
    add_sampled_scan_options(p)
    add_out_options(
        p, "optimise-lift", "optimise.json is replaced", writes="optimise.json", prefix="optimise-"
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run_cli)


#: The options of `jaxhoist optimise-lift` that are keywords of the same name of `optimise_lift`.
_PASSED = (
    "samples",
    "seed",
    "hoist_distance",
    "penalty",
    "starts",
    "max_iterations",
    "check_samples",
    "check_replicates",
)


def run_cli(args) -> int:
    scenario, out, keywords = sampled_scan_inputs(args, "optimise-lift", "optimise-", _PASSED)
    uncertain = parse_uncertain(args.uncertain)
    bounds = dict(parse_bound(b) for b in args.bound)
    objective = dict(parse_objective(o) for o in args.objective)
    limits = dict(parse_limit(x) for x in args.limit)
    res = optimise_lift(scenario, uncertain, objective, bounds, hazard_limits=limits or None, **keywords)
    print(res.summary())
    claim_out_dir(out, "optimise-lift", ["optimise.json"])
    path = out / "optimise.json"
    path.write_text(json.dumps(summary_json(res), indent=1))
    print(f"wrote         {path}")
    return 0 if res.limits_hold in (None, True) else 1


def summary_json(res: OptimisedLift) -> dict:
    """The result as plain JSON (NaN and inf as null)."""

    def num(x):
        x = float(x)
        return x if math.isfinite(x) else None

    return {
        "design": res.design,
        "start": res.start,
        "bounds": {p: list(b) for p, b in res.bounds.items()},
        "units": res.units,
        "value": num(res.value),
        "start_value": num(res.start_value),
        "terms": {k: num(v) for k, v in res.terms.items()},
        "start_terms": {k: num(v) for k, v in res.start_terms.items()},
        "gradient": {k: num(v) for k, v in res.gradient.items()},
        "uncertain": res.uncertain,
        "samples": res.samples,
        "seed": res.seed,
        "iterations": res.iterations,
        "evaluations": res.evaluations,
        "screened": len(res.screened),
        "solves": res.solves,
        "converged": res.converged,
        "message": res.message,
        "n_failed": res.n_failed,
        "limits": res.limit_table(),
        "limits_hold": res.limits_hold,
        "history": [{**h, "value": num(h["value"])} for h in res.history],
    }
