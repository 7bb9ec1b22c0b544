"""`jaxhoist identify`: the command line of `apps.identify.fit.identify` (argument parsing, what it prints
and writes)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ..._errors import ScenarioError
from ..._io.measurement import (
    read_measurement,
)
from ..._io.scenario import apply_overrides, load_scenario
from ..._numerics.options import SolverOptions
from ..identify.fit import check_inputs, identify
from ..identify.options import FitOptions
from ..identify.parameters import ALIASES
from ..identify.result import plot_fit
from .common import (
    ATOL_HELP,
    CLI_SOLVERS,
    RTOL_HELP,
    add_allow_implausible,
    add_out_options,
    claim_out_dir,
    default_out,
    prepare_out_dir,
)

# ------------------------------------------------------------------------------------- CLI

CLI_DEFAULT_SOLVER = "rosenbrock-w"  # `--solver` default, identify's own (`fit_solver_options`)


def _parse_kv(text: str | None, what: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        k, sep, v = item.partition("=")
        if not sep or not k.strip() or not v.strip():
            raise ScenarioError(f"{what} expects NAME=VALUE[,NAME=VALUE...], got {item!r}")
        out[k.strip()] = v.strip()
    return out


def configure_parser(subparsers) -> None:
    """Register `jaxhoist identify SCENARIO MEASUREMENT.csv --fit mu,k,... [--out DIR]`."""
    p = subparsers.add_parser(
        "identify",
        help="fit scenario parameters to a measured CSV (Levenberg-Marquardt, forward sensitivities)",
        description="Fit scenario leaves to measured time series by weighted least squares "
        "(optimistix Levenberg-Marquardt with forward-mode sensitivities) and write the estimates "
        "(JSON) and a plot of measured against fitted signals. Short names: "
        + ", ".join(f"{k} -> {v}" for k, v in ALIASES.items())
        + "; any dotted leaf path works.",
    )
    p.add_argument(
        "scenario", metavar="SCENARIO", help="a preset name (e.g. paper-4.2) or a TOML scenario file"
    )
    p.add_argument(
        "measurement",
        metavar="MEASUREMENT.csv",
        help="CSV with a time column 't [s]' and signal columns such as 'position_x [m]'",
    )
    p.add_argument(
        "--fit",
        required=True,
        metavar="P1,P2,...",
        help="parameters to fit: mu, k, h, c_l, b_l or dotted paths (load.mass_centre[0], boom.stiffness)",
    )
    p.add_argument(
        "--signals",
        default=None,
        metavar="S1,S2,...",
        help="fit only these signals or groups (default: every column)",
    )
    p.add_argument(
        "--noise",
        default=None,
        metavar="S=SIGMA,...",
        help="noise standard deviation per signal or group in SI units, or x%% of its RMS, e.g. "
        "position=0.005,rope_tension=1%% (overrides the side JSON)",
    )
    p.add_argument(
        "--start", default=None, metavar="P=VALUE,...", help="start values (default: the scenario's)"
    )
    p.add_argument(
        "--starts", type=int, default=1, help="number of starts (extra ones random around --start)"
    )
    p.add_argument(
        "--t1", type=float, default=None, help="end of the simulated span [s] (default the scenario's)"
    )
    p.add_argument(
        "--solver",
        choices=sorted(CLI_SOLVERS),
        default=CLI_DEFAULT_SOLVER,
        help=f"integrator of the fit's simulations and their sensitivity equations (default "
        f"{CLI_DEFAULT_SOLVER}: linearly implicit, one W for the state and its sensitivities) or a diffrax "
        "Runge-Kutta method; on paper-4.2 rosenbrock-w fits a 25 s record 1.8x faster than tsit5 in all, "
        "tsit5 compiles faster and wins on records of a few seconds (docs/identification.md)",
    )
    p.add_argument(
        "--rtol",
        type=float,
        default=None,
        help=RTOL_HELP + " (default: the solver's, 5e-4 for rosenbrock-w, 1e-6 for the others)",
    )
    p.add_argument(
        "--atol",
        type=float,
        default=None,
        help=ATOL_HELP + " (default: the solver's, 1e-5 for rosenbrock-w, 1e-8 for the others)",
    )
    p.add_argument("--max-iterations", type=int, default=100, help="LM step budget (default 100)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="PATH=VALUE",
        help="replace a scenario value by dotted path before fitting, e.g. hoist.speed=0.25 (repeatable; "
        "as in `jaxhoist simulate --set`); checked before compiling",
    )
    add_allow_implausible(p)
    add_out_options(p, "identify", "estimates.json and fit.png are replaced", prefix="identify-")
    p.add_argument("--no-plots", action="store_true", help="write only the JSON file")
    p.add_argument("--quiet", action="store_true", help="no progress line or bar on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """`jaxhoist identify`: read and check everything, fit, write `estimates.json` and `fit.png`, print a
    summary. Returns 0 if the fit converged and the parameters are identifiable, else 1."""
    jax.config.update("jax_enable_x64", True)
    quiet = getattr(args, "quiet", False)

    def note(msg):
        if not quiet:
            print(msg, file=sys.stderr, flush=True)

    scenario, overrides = apply_overrides(
        load_scenario(args.scenario, allow_implausible=args.allow_implausible),
        getattr(args, "set", None) or [],
    )
    measurement = read_measurement(args.measurement)
    params = [s.strip() for s in args.fit.split(",") if s.strip()]
    noise = _parse_kv(args.noise, "--noise")
    start = {}
    for k, v in _parse_kv(args.start, "--start").items():
        try:
            start[k] = float(v)
        except ValueError:
            raise ScenarioError(f"--start {k}: value must be a number, got {v!r}") from None
    signals = [s.strip() for s in args.signals.split(",")] if args.signals else None
    out_dir = Path(args.out) if args.out else default_out(args.scenario, "identify-")
    prepare_out_dir(out_dir, "identify", overwrite=getattr(args, "overwrite", False))
    options = SolverOptions(CLI_SOLVERS[args.solver](), rtol=args.rtol, atol=args.atol)
    fit = FitOptions(n_starts=args.starts, max_iterations=args.max_iterations)
    inputs: dict[str, Any] = dict(signals=signals, noise=noise or None, start=start, t1=args.t1)
    # every input checked (the fit's own host-side checks) before the line that says the fit starts
    check_inputs(scenario, measurement, params, options=options, fit=fit, **inputs)
    note(
        f"fitting {', '.join(params)} of {scenario.name} to {len(measurement.names)} signals x "
        f"{measurement.t.size} samples of {args.measurement} (its programs compiled or loaded from the "
        "cache, then the iterations) ..."
    )
    bar = None
    if not quiet:
        from .progress import FitProgressBar

        bar = FitProgressBar(total=args.max_iterations)
    try:
        res = identify(scenario, measurement, params, options=options, fit=fit, progress=bar, **inputs)
    finally:
        if bar is not None:
            bar.close()
    claim_out_dir(out_dir, "identify", ["estimates.json", "fit.png"])
    doc = res.to_dict() | {
        "command": ["jaxhoist", *args.argv] if getattr(args, "argv", None) is not None else sys.argv,
        "scenario": scenario.name,
        "overrides": overrides,
        "measurement": str(args.measurement),
        "solver": {"name": args.solver, "rtol": options.rtol, "atol": options.atol},
        "fitted_signals": list(res.measured),
    }
    (out_dir / "estimates.json").write_text(json.dumps(doc, indent=2, default=_json_default) + "\n")
    written = [out_dir / "estimates.json"]
    if not args.no_plots:
        fig = plot_fit(res)
        fig.savefig(out_dir / "fit.png", dpi=110)
        written.append(out_dir / "fit.png")
    print(res.summary())
    print("wrote " + ", ".join(str(w) for w in written))
    return 0 if res.converged and res.identifiable else 1


def _json_default(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return str(x)
