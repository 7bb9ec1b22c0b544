"""`jaxhoist bifurcation`: locate where an observable changes character as a parameter varies (one bracket,
every candidate jump of a scan, or a boundary traced in a second parameter), print the results and write
bifurcation.json and the plots."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import diffrax
import jax
import numpy as np

from ..._errors import ScenarioError, one_line
from ..._numerics import observables as obs_mod
from ..._numerics.options import SolverOptions
from ..._numerics.times import Times
from ..._physics.paths import set_param
from ..bifurcation.eval import resolve_one
from ..bifurcation.jumps import find_crossings, find_jumps
from ..bifurcation.locate import check_bracket, check_level, locate_bifurcation, locate_jumps
from ..bifurcation.options import SearchOptions, as_method
from ..bifurcation.result import BifurcationError, fmt_located
from ..bifurcation.trace import check_along, trace_boundary
from ..scan.run import scan
from .common import (
    PROG,
    add_allow_implausible,
    add_out_options,
    claim_out_dir,
    prepare_out_dir,
    rerun_scan,
)


def configure_parser(subparsers) -> None:
    """Add `jaxhoist bifurcation SCENARIO --param PATH --bracket LO HI --observable NAME [...]` (and
    `--along PATH --along-values SPEC` to trace the boundary in a second parameter)."""
    from ..._io.validate import count_arg, number_arg

    p = subparsers.add_parser(
        "bifurcation",
        help="locate where an observable changes character as a parameter varies",
        description="Refine a change of character of an observable (a jump, or the sign change of an event-"
        "time difference) to a tolerance, with derivative-accelerated root finding. With --scan N, "
        "first scan N points across the bracket and refine every candidate jump.",
    )
    p.add_argument("scenario", metavar="SCENARIO", help="preset name (e.g. paper-4.2) or TOML file")
    p.add_argument("--param", required=True, metavar="PATH", help="e.g. foundation.friction_coefficient")
    p.add_argument("--bracket", nargs=2, type=number_arg, required=True, metavar=("LO", "HI"))
    p.add_argument(
        "--observable",
        default="final_psi",
        help="scalar observable (built-in name, a component like final_euler[1], or "
        "detach:E-D for a detachment-time difference); default final_psi",
    )
    p.add_argument(
        "--level", type=number_arg, default=None, help="indicator level (default: midpoint of the ends)"
    )
    p.add_argument("--tol", type=number_arg, default=1e-6, help="final bracket width (default 1e-6)")
    p.add_argument("--method", choices=("newton", "bisection", "multisection"), default="newton")
    p.add_argument(
        "--scan",
        type=count_arg,
        default=0,
        metavar="N",
        help="first scan N >= 2 points over the bracket and refine every candidate jump (default 0: no scan)",
    )
    p.add_argument(
        "--along",
        default=None,
        metavar="PATH",
        help="trace the boundary in a second parameter by continuation, e.g. hoist.speed",
    )
    p.add_argument(
        "--along-values",
        default=None,
        metavar="SPEC",
        help="values of --along, start:stop:num or v1,v2,...; the first is where --bracket applies",
    )
    p.add_argument("--t1", type=number_arg, default=None)
    p.add_argument("--n-save", type=count_arg, default=201)
    p.add_argument("--rtol", type=number_arg, default=None)
    p.add_argument("--atol", type=number_arg, default=None)
    p.add_argument("--max-steps", type=count_arg, default=200_000)
    p.add_argument("--set", action="append", default=[], metavar="PATH=VALUE", help="fixed leaf overrides")
    add_allow_implausible(p)
    add_out_options(
        p,
        "bifurcation",
        "the files it writes are replaced",
        out_help="folder for bifurcation.json, locator_<k>.png per located value (and, with --scan, the scan "
        "and scan_<observable>.png with the located values marked)",
    )
    p.add_argument("--no-plots", action="store_true", help="write no PNGs")
    p.add_argument(
        "--classify",
        action="store_true",
        help="name every located change (final-state jump, steep ramp, event-count change, event-definition "
        "change, continuous crossing) by solving a window around it (jaxhoist.classify_change; ~43 solves "
        "each)",
    )
    p.add_argument(
        "--quiet", action="store_true", help="no progress bars on stderr (scan members, locator brackets)"
    )
    p.set_defaults(func=run_cli)


def _cli_observable(name: str):
    if name.startswith("detach:"):
        a, _, b = name[len("detach:") :].partition("-")
        corners = obs_mod.CORNERS
        if a.upper() not in corners or b.upper() not in corners or a.upper() == b.upper():
            raise ScenarioError(
                f"--observable {name!r}: detach:X-Y needs two different corners among {list(corners)}, "
                f"e.g. detach:E-D"
            )
        return obs_mod.detachment_time_difference(a, b)
    return name


def _check_cli_args(args, scenario) -> np.ndarray | None:
    """Every argument of `jaxhoist bifurcation` checked before any solve; returns the --along values."""
    from ..._io.validate import check_count, check_param_path

    check_count(args.scan, "--scan", 2, allow_zero=True)
    resolve_one(_cli_observable(args.observable), "--observable")
    check_param_path(scenario, args.param, "--param")
    check_bracket(args.bracket, "--bracket")
    check_level(args.level, "--level")
    if (args.along is None) != (args.along_values is None):
        raise ScenarioError("--along and --along-values go together")
    if args.along is not None and args.scan:
        raise ScenarioError("--along traces one boundary from --bracket; it does not combine with --scan")
    along = None
    if args.along is not None:
        along = check_along(
            scenario, args.param, args.along, args.along_values, ("--along", "--along-values")
        )
    if args.out:
        prepare_out_dir(args.out, "bifurcation", overwrite=getattr(args, "overwrite", False))
    return along


def run_cli(args) -> int:
    jax.config.update("jax_enable_x64", True)
    from ..._io.scenario import apply_overrides, load_scenario

    scenario, overrides = apply_overrides(
        load_scenario(args.scenario, allow_implausible=args.allow_implausible), args.set
    )
    along_values = _check_cli_args(args, scenario)
    try:
        return _locate_and_write(args, scenario, overrides, along_values)
    except BifurcationError as e:  # the search ran and could not go on: no sign change, a failed solve
        print(f"{PROG}: error: {one_line(str(e))}", file=sys.stderr)
        return 1


def _locate_and_write(args, scenario, overrides, along_values) -> int:
    """The located values (or the traced boundary) printed and written; the exit code."""
    observable = _cli_observable(args.observable)
    # the settings of the --scan and --classify solves (scan's default solver at --rtol/--atol/--max-steps)
    kw = dict(
        times=Times(args.t1, n=args.n_save),
        options=SolverOptions(rtol=args.rtol, atol=args.atol, max_steps=args.max_steps),
    )
    out = Path(args.out) if args.out else None
    lo, hi = args.bracket
    bar = None
    quiet = getattr(args, "quiet", False)
    if not quiet:
        from .progress import LocatorProgressBar

        bar = LocatorProgressBar()
    try:
        found, boundary, res = _run_locator(args, scenario, observable, along_values, lo, hi, out, kw, bar)
    finally:
        if bar is not None:
            bar.close()
    for b in found:
        print(b.summary())
    classes = _classify_cli(args, scenario, found, boundary, kw) if getattr(args, "classify", False) else None
    return _write_cli(args, scenario, overrides, found, boundary, res, out, classes)


def _classify_cli(args, scenario, found, boundary, kw) -> list:
    """`classify_change` for every located value (at its own --along value when tracing); printed."""
    from ..bifurcation.classify import classify_change

    scenarios = [scenario] * len(found)
    if boundary is not None:
        scenarios = [
            set_param(scenario, boundary.along, q)
            for q, b in zip(boundary.along_values, boundary.points, strict=True)
            if b is not None
        ]
    classes = []
    for sc, b in zip(scenarios, found, strict=True):
        c = classify_change(sc, b, **kw)
        print("  " + c.summary())
        classes.append(c)
    return classes


def _locator_settings(args) -> dict:
    """The keywords of `locate_bifurcation` from the flags: `SearchOptions(--method, --tol)`, Tsit5 with
    --rtol/--atol/--max-steps, --t1 and --n-save."""
    return dict(
        search=SearchOptions(as_method(args.method), args.tol),
        options=SolverOptions(diffrax.Tsit5(), rtol=args.rtol, atol=args.atol, max_steps=args.max_steps),
        times=Times(args.t1, n=args.n_save),
    )


def _run_locator(args, scenario, observable, along_values, lo, hi, out, kw, bar):
    boundary = res = None
    quiet = getattr(args, "quiet", False)
    loc = _locator_settings(args)
    if args.along is not None:
        boundary = trace_boundary(
            scenario,
            args.param,
            (lo, hi),
            args.along,
            along_values,
            observable,
            level=args.level,
            progress=bar,
            **loc,
        )
        if bar is not None:
            bar.close()
        found = [b for b in boundary.points if b is not None]
        for r in boundary.rows():
            v = "lost or not found" if r["value"] is None else fmt_located(r["value"], args.tol)
            print(f"{args.along} = {r['along_value']:.6g}: {args.param}* = {v}")
        print(f"{boundary.n_solves} solves in all; a dense grid at {args.tol:g}: {boundary.n_dense}")
    elif args.scan:
        name = resolve_one(observable).name
        if out is not None:
            claim_out_dir(out, "bifurcation", _BIFURCATION_OUTPUTS)
        res = rerun_scan(
            lambda resume: scan(
                scenario,
                {args.param: np.linspace(lo, hi, args.scan)},
                observables={name: observable},
                out_dir=None if out is None else out / "scan",
                resume=resume,
                progress=not quiet,
                **kw,
            ),
            None if out is None else out / "scan",
            True,
            lambda msg: None if quiet else print(msg, file=sys.stderr, flush=True),
        )
        found = locate_jumps(scenario, res, name, level=args.level, progress=bar, **loc)
        if bar is not None:
            bar.close()
        print(
            f"{len(find_jumps(res, name))} candidate jumps"
            + ("" if args.level is None else f" and {len(find_crossings(res, name, args.level))} crossings")
            + f" of {name} in {args.scan} points; located {len(found)}:"
        )
    else:
        found = [
            locate_bifurcation(
                scenario, args.param, observable, (lo, hi), level=args.level, progress=bar, **loc
            )
        ]
    return found, boundary, res


# What `jaxhoist bifurcation` writes into --out (its scan/ sub-folder resumes or is recomputed by the scan)
_BIFURCATION_OUTPUTS = ("bifurcation.json", "locator_*.png", "boundary.png", "scan_*.png")


def _write_cli(args, scenario, overrides, found, boundary, res, out, classes=None) -> int:
    if out is not None:
        claim_out_dir(out, "bifurcation", _BIFURCATION_OUTPUTS)
        rec = {
            "scenario": scenario.name,
            "overrides": overrides,
            "command": getattr(args, "argv", sys.argv),
            "bifurcations": [b.to_dict() for b in found],
        }
        if classes is not None:
            for d, c in zip(rec["bifurcations"], classes, strict=True):
                d["classification"] = c.to_dict()
        if boundary is not None:
            rec["boundary"] = {
                "param": boundary.param,
                "along": boundary.along,
                "rows": boundary.rows(),
                "n_solves": boundary.n_solves,
                "n_dense": boundary.n_dense,
            }
        (out / "bifurcation.json").write_text(json.dumps(rec, indent=1, default=float) + "\n")
        print(f"wrote {out / 'bifurcation.json'}")
        if not args.no_plots:
            from ..plots.scan import plot_boundary, plot_locator, save_scan_plots
            from ..plots.trajectory import save_figure

            pngs = [save_figure(plot_locator(b), out / f"locator_{k}.png") for k, b in enumerate(found)]
            if boundary is not None:
                pngs.append(save_figure(plot_boundary(boundary), out / "boundary.png"))
            if args.scan:
                pngs += save_scan_plots(res, out, located=found)
            print(f"wrote {len(pngs)} PNGs in {out}")
    complete = boundary is None or bool(np.all(np.isfinite(boundary.values)))
    return 0 if complete and all(b.converged for b in found) else 1
