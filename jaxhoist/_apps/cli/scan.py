"""`jaxhoist scan`: the command line of `apps.scan.scan` (argument parsing, the summary it prints, the
plots it writes)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import diffrax
import jax
import numpy as np

from ..._errors import ScenarioError
from ..._io.validate import parse_values
from ..._numerics.options import SolverOptions
from ..._numerics.times import Times
from ..scan.accuracy import AccuracyCheck, summary
from ..scan.layout import BatchOptions
from ..scan.run import check_inputs, scan
from ..scan.sweep import as_sweep
from .common import (
    CLI_SOLVERS,
    add_allow_implausible,
    claim_out_dir,
    default_out,
    prepare_out_dir,
    rerun_scan,
)


def configure_parser(subparsers) -> None:
    """Add `jaxhoist scan SCENARIO --param PATH --values a:b:n [...] --t1 T --out DIR`."""
    p = subparsers.add_parser(
        "scan",
        help="sweep scenario parameters; observables per member as npz/json/nc and plots",
        description="Solve a scenario for many values of one or more float leaves (vmapped, chunked, "
        "sharded over all devices, resumable) and save the observables of every member.",
    )
    p.add_argument("scenario", metavar="SCENARIO", help="preset name (e.g. paper-4.2) or TOML file")
    p.add_argument(
        "--param",
        action="append",
        required=True,
        metavar="PATH",
        help="dotted parameter path, e.g. foundation.friction_coefficient or load.mass_centre[0] "
        "(repeat for several parameters, each followed by its --values)",
    )
    p.add_argument(
        "--values",
        action="append",
        required=True,
        metavar="SPEC",
        help="values of the matching --param: start:stop:num (inclusive) or v1,v2,...",
    )
    p.add_argument(
        "--mode",
        choices=("sweep", "grid", "points"),
        default=None,
        help="several parameters: grid (every combination, the default) or points (zipped)",
    )
    p.add_argument(
        "--observable",
        action="append",
        default=None,
        metavar="NAME",
        help="built-in observable to record (repeatable); default final_position, final_euler, "
        "max_tilt, liftoff_time",
    )
    p.add_argument(
        "--history",
        action="append",
        default=[],
        metavar="FIELD",
        help="Trajectory field to keep at every saved time (e.g. position, euler)",
    )
    p.add_argument("--t1", type=float, default=None, help="end time [s] (default: the scenario's t1)")
    p.add_argument(
        "--n-save", type=int, default=201, help="saved times (event times are interpolated on them)"
    )
    p.add_argument("--rtol", type=float, default=None)
    p.add_argument("--atol", type=float, default=None)
    p.add_argument("--max-steps", type=int, default=200_000)
    p.add_argument(
        "--solver",
        choices=sorted(CLI_SOLVERS),
        default="rosenbrock-w",
        help="integrator: rosenbrock-w (default: linearly implicit, stiff contact and rope forces implicit) "
        "or a diffrax Runge-Kutta method (bosh3 is the accurate explicit choice at fixed steps)",
    )
    p.add_argument(
        "--fixed-step",
        type=float,
        default=None,
        metavar="DT",
        help="constant steps of DT seconds, every member the same steps (lean fixed-step loop; no error "
        "control: check the accuracy, see docs/performance.md), e.g. --solver bosh3 --fixed-step 1.5e-3",
    )
    p.add_argument(
        "--lanes",
        type=int,
        default=None,
        help="members per vmapped lock-step solve (default: 16-256 from the member count and the devices, "
        "or 256 with --fixed-step)",
    )
    p.add_argument(
        "--chunk-size", type=int, default=None, help="members per compiled call (default: automatic)"
    )
    p.add_argument("--set", action="append", default=[], metavar="PATH=VALUE", help="fixed leaf overrides")
    add_allow_implausible(p)
    p.add_argument(
        "--out", default=None, help="output folder (chunk files, manifest, scan.npz/json/nc); resumable"
    )
    p.add_argument("--no-resume", action="store_true", help="recompute even if --out holds finished chunks")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="write into a non-empty --out that `jaxhoist scan` did not write (only the files scan writes "
        "are replaced); without it, such a folder is refused",
    )
    acc = p.add_mutually_exclusive_group()
    acc.add_argument(
        "--no-accuracy-check",
        action="store_true",
        help="do not re-solve a subset of members at a 1000x tighter tolerance (by default done for scans of "
        "1024 members or more)",
    )
    acc.add_argument(
        "--accuracy-members",
        type=int,
        default=None,
        metavar="N",
        help="re-solve N healthy members (half with the most solver steps, half at random; N more while "
        "the largest difference is within 4x of its target, up to 4N) at a 1000x tighter tolerance and "
        "report the differences (forces the check on below 1024 members; default 16, from 1024 members)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument(
        "--no-plots",
        action="store_true",
        help="do not write scan_<observable>.png (written for a sweep of one parameter or a 2-D grid)",
    )
    p.set_defaults(func=run_cli)


def run_cli(args) -> int:
    jax.config.update("jax_enable_x64", True)
    from ..._io.scenario import apply_overrides, load_scenario

    if len(args.param) != len(args.values):
        raise ScenarioError(
            f"give one --values per --param (got {len(args.param)} --param and {len(args.values)} --values)"
        )
    scenario, _ = apply_overrides(
        load_scenario(args.scenario, allow_implausible=args.allow_implausible), args.set
    )
    repeated = sorted({p for p in args.param if args.param.count(p) > 1})
    if repeated:
        raise ScenarioError(f"--param {repeated[0]} is given more than once: give each parameter once")
    params = {p: parse_values(v, "--values") for p, v in zip(args.param, args.values, strict=True)}
    if args.n_save < 2:
        raise ScenarioError(f"--n-save must be >= 2, got {args.n_save}")
    # every option is made, and so checked, before the folder is touched
    for flag, value in (("--lanes", args.lanes), ("--chunk-size", args.chunk_size)):
        if value is not None and value < 1:
            raise ScenarioError(f"{flag} must be >= 1, got {value}")
    accuracy = _accuracy(args)
    times = Times(args.t1, n=args.n_save)
    batch = BatchOptions(lanes=args.lanes, chunk_size=args.chunk_size)
    out = Path(args.out) if args.out else default_out(args.scenario, "scan-")
    prepare_out_dir(out, "scan", overwrite=args.overwrite)
    if args.fixed_step is None:
        options = SolverOptions(
            CLI_SOLVERS[args.solver](), rtol=args.rtol, atol=args.atol, max_steps=args.max_steps
        )
    else:  # constant steps of --fixed-step [s]: --rtol/--atol are not read
        options = SolverOptions(
            CLI_SOLVERS[args.solver](),
            diffrax.ConstantStepSize(),
            dt0=args.fixed_step,
            max_steps=args.max_steps,
        )
    sweep = as_sweep(params, args.mode)
    _check_before_writing(scenario, args)
    what: dict[str, Any] = dict(
        observables=args.observable, options=options, histories=args.history, batch=batch
    )
    # the scan's own checks (the members' values among them): a refused scan leaves the folder as it was
    check_inputs(scenario, sweep, times, accuracy=accuracy, **what)
    claim_out_dir(out, "scan", ["scan.npz", "scan.json", "scan.nc", "scan_*.png"])
    res = rerun_scan(
        lambda resume: scan(
            scenario,
            sweep,
            times,
            out_dir=out,
            resume=resume,
            progress=not args.quiet,
            accuracy=accuracy,
            **what,
        ),
        out,
        not args.no_resume,
        lambda msg: None if args.quiet else print(msg, file=sys.stderr, flush=True),
    )
    n_fail = int(np.sum(~res.ok))
    t = res.attrs["timings_s"]
    print(f"scan          {scenario.name}: {res.size} members over {', '.join(res.params)} ({res.mode})")
    counts = ", ".join(f"{k}: {v}" for k, v in res.status_counts().items() if k != "ok")
    print(f"failed        {n_fail}" + (f" ({counts}; first: {res.failures()[0]})" if n_fail else ""))
    print(
        f"steps         median {int(np.median(res.num_accepted_steps))}, "
        f"max {int(res.num_accepted_steps.max())}"
    )
    # "load" where the group program came from the cache folder (the seconds are then mostly the load)
    making = "load" if res.attrs.get("group_program") == "loaded" else "compile"
    print(
        f"wall time     {making} {t['compile']:.3g} s, solve {t['compute']:.3g} s "
        f"({1e3 * t['compute'] / max(1, t['members_computed']):.3g} ms per member), total {t['total']:.3g} s"
    )
    if res.accuracy is not None:
        print(f"accuracy      {summary(res.accuracy, _flag)}")
    pngs = []
    if not args.no_plots:
        from ..plots.scan import plot_skips, save_scan_plots

        pngs = save_scan_plots(res, out)
        for name, why in plot_skips(res).items():
            print(f"no plot       scan_{name}.png: {why}")
    print(
        f"wrote         {out / 'scan.npz'}, {out / 'scan.json'}, {out / 'scan.nc'}"
        + (f", {len(pngs)} PNGs (scan_<observable>.png)" if pngs else "")
    )
    return 0 if n_fail == 0 else 1


def _accuracy(args) -> AccuracyCheck | bool | None:
    """The `accuracy` argument of `scan`: off, N members, or automatic."""
    if args.no_accuracy_check:
        return False
    if args.accuracy_members is not None:
        return AccuracyCheck(members=args.accuracy_members)
    return None


def _flag(name: str, value: float) -> str:
    """The command-line option of a suggestion: rtol -> --rtol 5e-05, dt0 -> --fixed-step 0.00025."""
    return f"--fixed-step {value:.3g}" if name == "dt0" else f"--{name} {value:.0e}"


def _check_before_writing(scenario, args) -> None:
    """The --param paths and --observable names, checked first for messages that name their flags
    (`check_inputs` then checks them again, with everything else, before the folder is claimed)."""
    from ..._io.validate import check_param_path
    from ..._numerics import observables as obs_mod

    for path in args.param:
        check_param_path(scenario, path, "--param")
    try:
        obs_mod.resolve(args.observable)
    except ValueError as e:
        raise ScenarioError(f"--observable: {e}") from None
