"""`jaxhoist simulate`: one solve of a scenario from the command line, its summary, result files and
plots."""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

from ..._io.scenario import preset_names
from .animate import animate_folder
from .common import (
    ATOL_HELP,
    PROG,
    RTOL_HELP,
    add_allow_implausible,
    claim_out_dir,
    default_out,
    enable_x64,
    import_matplotlib_meanwhile,
    prepare_out_dir,
)
from .progress import LineSink, StepTimer, percent_to_bar, phase_to_bar, tqdm_bar

# ---------------------------------------------------------------------------------------- simulate


def _compiled_solve(scenario, ts, options, progress):
    """The solve core `numerics.solve.solve`, compiled ahead of time (so compile and solve are timed apart)
    through `compile_cache.program`: cached per structure/shape/options, so repeated `main()` calls in one
    process compile once, and with the persistent compilation cache on, stored whole in the cache folder,
    so that a later run loads it without tracing or lowering it."""
    from ..._numerics import compile_cache
    from ..._numerics.solve import solve

    return compile_cache.program("simulate", "solve", solve, (scenario, ts, options), step=progress)[0]


def _fmt_vec(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


# Files `simulate` writes into --out besides the plots' PNGs (removed first when it writes there again),
# with those of `--animate`.
SIMULATE_OUTPUTS = ("trajectory.npz", "trajectory.json", "trajectory.csv", "trajectory.nc")
ANIMATE_OUTPUTS = ("animation.gif", "animation.mp4", "keyframes.png")


def summary_status(arrays: dict):
    """The run's `SolveStatus` for the summary and the exit code: the solver's, except that a run marked ok
    whose state or energy residual is not finite everywhere counts as `NONFINITE` (a failed run)."""
    import numpy as np

    from ..._errors import SolveStatus

    status = SolveStatus(int(arrays["status"]))
    if status == SolveStatus.OK:
        keys = ("position", "euler", "normal_forces", "rope_tension", "energy_residual")
        if not all(np.all(np.isfinite(arrays[k])) for k in keys if k in arrays):
            return SolveStatus.NONFINITE
    return status


def transient_detachments(phases, ts) -> list[tuple[float, float, list[str]]]:
    """The rigid model's detachments shorter than the save interval: `(start [s], end [s], corners)` for
    every run of consecutive phases in which a corner is free, lasts less than `ts[1] - ts[0]` and ends
    with the corner back on the ground (e.g. the first 0.2 ms of paper-4.1 with the inextensible rope,
    where only F touches until the rope's start jerk settles D, E and H). A saved time inside one shows
    N_i = 0 although the corner is on the ground before and after it."""
    import numpy as np

    ts = np.asarray(ts)
    dt = float(ts[1] - ts[0]) if ts.size > 1 else 0.0
    found: dict[tuple[float, float], list[str]] = {}
    for i, corner in enumerate("DEFH"):
        start = None
        for k, ph in enumerate(phases):
            free = ph["contact"][i] == "free"
            if free and start is None:
                start = ph["t_start"]
            last = k == len(phases) - 1
            if start is not None and (not free or last):
                end = ph["t_start"] if not free else ph["t_end"]
                if not free and end - start < dt:
                    found.setdefault((float(start), float(end)), []).append(corner)
                start = None
    return [(a, b, cs) for (a, b), cs in sorted(found.items())]


def event_lines(status, ts, normal_forces, phases=None) -> list[str]:
    """The summary's lift-off and first-detachment lines; a failed run has no event times to report (its
    arrays past the failure are inf or NaN), so it says so instead of reading times from them. With the
    rigid model's `phases` (`jaxhoist._io.results.phase_records`), detachments shorter than the save
    interval (`transient_detachments`) are left out of the first N_i = 0 times and named on a line of
    their own."""
    import numpy as np

    from ..._errors import SolveStatus
    from ..._io.results import corner_detach_times, liftoff_time

    if status != SolveStatus.OK:
        return ["lift-off      not available (the solve failed)", "first N_i = 0 not available"]
    lift = liftoff_time(ts, normal_forces)
    transients = transient_detachments(phases, ts) if phases else []
    normal = np.array(normal_forces, dtype=float)
    for a, b, corners in transients:  # a sample inside a transient does not count as a detachment
        inside = (np.asarray(ts) >= a) & (np.asarray(ts) <= b)
        for c in corners:
            normal[inside, "DEFH".index(c)] = np.inf
    detach = corner_detach_times(ts, normal)
    lines = [
        "lift-off      "
        + (
            f"{lift:g} s (first saved time with every N_i = 0)"
            if lift is not None
            else "none within the horizon"
        ),
        "first N_i = 0 "
        + ", ".join(f"{c}: {'-' if t is None else f'{t:g} s'}" for c, t in zip("DEFH", detach, strict=True))
        + (" (after the transients below)" if transients else ""),
    ]
    for a, b, corners in transients:
        lines.append(
            f"transient     {', '.join(corners)} off the ground from {a:g} s for {_fmt_duration(b - a)}, "
            "shorter than the save interval (then back in contact)"
        )
    return lines


def _fmt_duration(seconds: float) -> str:
    return f"{seconds * 1e3:.2g} ms" if seconds < 1.0 else f"{seconds:.3g} s"


def run_simulate(args: argparse.Namespace) -> int:
    """`jaxhoist simulate`: load, validate, compile, solve, save npz+json (+ PNGs), print a summary."""
    enable_x64()
    from ..._errors import SolveStatus, require_x64
    from ..._io.results import phase_records

    require_x64()
    progress = StepTimer(quiet=args.quiet)
    wall0 = time.perf_counter()

    # ---- host side: everything is checked before anything is compiled
    with progress(f"loading scenario {args.scenario}"):
        scenario, overrides, t1, options, ts = _load_checked(args)
    out_dir = Path(args.out) if args.out else default_out(args.scenario)
    prepare_out_dir(out_dir, "simulate", overwrite=args.overwrite)
    plotting = None if args.no_plots else import_matplotlib_meanwhile()  # while the solve loads or compiles
    progress.note(
        f"scenario {scenario.name}: t1 = {t1:g} s, {args.n_save} saved times, "
        f"{type(options.solver).__name__}, rtol = {options.rtol:g}, atol = {options.atol:g}"
    )

    if args.model == "rigid":
        traj, wall_solve = _solve_rigid(args, scenario, t1, ts, options, progress)
    else:
        traj, wall_solve = _solve_elastic(args, scenario, ts, options, progress)

    arrays, written = _write_results(args, out_dir, traj, scenario, options, t1, overrides, progress)
    pngs = []
    if plotting is not None:  # not --no-plots
        from ..plots import trajectory as plots

        with progress("plotting"):
            plotting.join()
            pngs = plots.save_all(arrays, out_dir, title_prefix=scenario.name)
    animation = []
    if args.animate:
        animation = animate_folder(out_dir, quiet=args.quiet)

    # ---- summary (stdout)
    status = summary_status(arrays)
    wall_total = time.perf_counter() - wall0
    phases = phase_records(traj) if hasattr(traj, "phases") else None
    lines = _summary_lines(scenario, arrays, status, wall_solve, wall_total, written, pngs, animation, phases)
    print("\n".join(lines), flush=True)
    return 0 if status == SolveStatus.OK else 1


def _load_checked(args: argparse.Namespace):
    """(scenario, overrides, t1 [s], SolverOptions, saved times ts [s]) from the flags, all checked."""
    import jax.numpy as jnp

    from ..._errors import ScenarioError
    from ..._io.scenario import apply_overrides, load_scenario
    from ..._numerics.options import SolverOptions
    from ..._numerics.times import Times

    scenario = load_scenario(args.scenario, allow_implausible=args.allow_implausible)
    scenario, overrides = apply_overrides(scenario, args.set)
    if args.n_save < 2:
        raise ScenarioError(f"--n-save must be >= 2, got {args.n_save}")
    t1, ts = Times(args.t1, n=args.n_save).resolve(scenario, args.n_save, jnp)
    if args.rope != "elastic" and args.model != "rigid":
        raise ScenarioError(
            f"--rope {args.rope} needs --model rigid (the elastic-foundation model has the elastic rope)"
        )
    import diffrax

    if args.model == "rigid":
        options = SolverOptions(diffrax.Tsit5(), rtol=args.rtol, atol=args.atol, max_steps=args.max_steps)
    else:
        # no in-loop progress meter: a compiled program with a host callback cannot be stored in the
        # persistent compilation cache (the solve's bar shows it done once the program returns)
        options = SolverOptions(rtol=args.rtol, atol=args.atol, max_steps=args.max_steps)
    return scenario, overrides, t1, options, ts


def _solve_rigid(args, scenario, t1, ts, options, progress):
    """The rigid-ground model's phase loop, its phase log drawn as a bar; (trajectory, solve time [s])."""
    import numpy as np

    from ..._numerics.rigid.options import RigidOptions
    from ..._numerics.rigid.solve import simulate_rigid
    from ..._numerics.times import Times
    from ..._physics.rigid.model import ElasticRope, InextensibleRope, RigidGround

    label = "solving with the rigid-ground model (its compiled pieces made or loaded on first use)"
    with (
        progress(label, bar=True),
        tqdm_bar(
            float(t1),
            "rigid model",
            "s",
            quiet=args.quiet,
            bar_format=("{desc}: {percentage:3.0f}%|{bar}| t = {n:.3f}/{total:.3g} s [{elapsed}{postfix}]"),
        ) as bar,
    ):
        with contextlib.redirect_stdout(LineSink(phase_to_bar(bar))):
            traj = simulate_rigid(
                scenario,
                Times(t1, ts=np.asarray(ts)),
                model=RigidGround(rope=InextensibleRope() if args.rope == "inextensible" else ElasticRope()),
                options=RigidOptions(
                    rtol=options.rtol,  # pyright: ignore[reportArgumentType]  # SolverOptions fills rtol/atol in
                    atol=options.atol,  # pyright: ignore[reportArgumentType]  # SolverOptions fills rtol/atol in
                    max_steps=args.max_steps,
                ),
                verbose=not args.quiet,  # the phase log, one line per phase: drives the bar
            )
        bar.n = bar.total  # the phase ending at t1 is not logged
        bar.refresh()
    return traj, progress.times[label]


def _solve_elastic(args, scenario, ts, options, progress):
    """The elastic model: compile (cached in the process, and on disk where the persistent compilation
    cache is on) and solve, drawn as a bar; (trajectory, solve time [s])."""
    import jax

    scenario = scenario.unlabelled()  # one compiled program for any scenario's labels
    options = options.traced_tolerances()  # and for any --rtol and --atol, as `simulate`'s
    solve_fn = _compiled_solve(scenario, ts, options, progress)
    with (
        progress("solving", bar=True),
        tqdm_bar(
            100.0,
            "solving",
            "%",
            quiet=args.quiet,
            bar_format=("{desc}: {percentage:3.0f}%|{bar}| t = {n:.0f}% of t1 [{elapsed}{postfix}]"),
        ) as bar,
    ):
        with contextlib.redirect_stdout(LineSink(percent_to_bar(bar))):
            traj = jax.block_until_ready(solve_fn(scenario, ts, options))
        bar.n = bar.total
        bar.refresh()
    return traj, progress.times["solving"]


def _summary_lines(
    scenario, arrays, status, wall_solve, wall_total, written, pngs, animation, phases=None
) -> list[str]:
    """The run's summary for stdout: final state, events, rope tension, energy check, steps, timings."""
    import numpy as np

    from ..._errors import SolveStatus

    ts_np = arrays["ts"]
    resid = float(np.max(np.abs(arrays["energy_residual"])))
    return [
        f"scenario      {scenario.name} (t = 0 .. {ts_np[-1]:g} s, {len(ts_np)} saved times)",
        f"status        {status.name.lower()}" + ("" if status == SolveStatus.OK else f": {status.message}"),
        f"final C       {_fmt_vec(arrays['position'][-1])} m",
        f"final angles  (φ, ψ, ϑ) = {_fmt_vec(np.degrees(arrays['euler'][-1]))} deg",
        *event_lines(status, ts_np, arrays["normal_forces"], phases),
        f"max S         {arrays['rope_tension'].max() / 1e3:.4g} kN",
        f"energy check  max |residual| = {resid:.3g} J (hoist work {arrays['hoist_work'][-1]:.4g} J)",
        f"steps         {int(arrays['num_accepted_steps'])} accepted, "
        f"{int(arrays['num_rejected_steps'])} rejected",
        f"wall time     solve {wall_solve:.3g} s, total {wall_total:.3g} s",
        f"wrote         {', '.join(p.name for p in written)}"
        + (f", {len(pngs)} PNGs" if pngs else "")
        + "".join(f", {p.name}" for p in animation)
        + f" in {written[0].parent}",
    ]


def configure_simulate(subparsers) -> None:
    from ..._io.validate import count_arg, number_arg

    p = subparsers.add_parser(
        "simulate",
        help="simulate one lift and write npz/json/csv/nc results and PNG plots",
        description="Simulate one lift with the elastic-foundation model (paper §3, or --model rigid) and "
        "write trajectory.npz + trajectory.json (arrays and what they are), trajectory.csv (every signal, "
        "SI units in the header; `jaxhoist identify` reads it), trajectory.nc (netCDF) and PNG plots to "
        "--out.",
    )
    p.add_argument(
        "scenario",
        metavar="SCENARIO",
        help=f"a preset name ({', '.join(preset_names())}) or a path to a TOML scenario file",
    )
    p.add_argument(
        "--t1", type=number_arg, default=None, metavar="T", help="end time [s] (default: the scenario's t1)"
    )
    p.add_argument(
        "--n-save",
        type=count_arg,
        default=501,
        metavar="N",
        help="number of equally spaced saved times from 0 to t1 (default 501)",
    )
    p.add_argument(
        "--rtol",
        type=number_arg,
        default=None,
        metavar="R",
        help=RTOL_HELP + " (default 5e-4 with the default Rosenbrock-W solver; 1e-6 with --model rigid)",
    )
    p.add_argument(
        "--atol",
        type=number_arg,
        default=None,
        metavar="A",
        help=ATOL_HELP + " (default 1e-5 with the default solver; 1e-8 with --model rigid)",
    )
    p.add_argument(
        "--max-steps",
        type=count_arg,
        default=200_000,
        metavar="M",
        help="solver step budget (default 200000)",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="PATH=VALUE",
        help="replace a scenario value by dotted path, e.g. foundation.friction_coefficient=0.3 "
        "or, for a vector, load.mass_centre=1,2.5,1 (x,y,z) (repeatable); checked before compiling",
    )
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="output folder (default out/<preset name or scenario file name>); a folder an earlier "
        "`jaxhoist simulate` wrote is reused, its results replaced",
    )
    add_allow_implausible(p)
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="write into a non-empty --out that `jaxhoist simulate` did not write (only the files simulate "
        "writes are replaced); without it, such a folder is refused",
    )
    p.add_argument(
        "--model",
        choices=("elastic", "rigid"),
        default="elastic",
        help="elastic foundation (paper §3, default) or the rigid-ground reference (paper §2)",
    )
    p.add_argument(
        "--rope",
        choices=("elastic", "inextensible"),
        default="elastic",
        help="elastic rope (2.14, default) or inextensible rope (2.15, with --model rigid only)",
    )
    p.add_argument("--no-plots", action="store_true", help="write no PNG plots")
    p.add_argument(
        "--animate",
        action="store_true",
        help="also write the 3-D animation and keyframes.png (as `jaxhoist animate DIR` with its defaults)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars or lines on stderr")
    p.set_defaults(func=run_simulate)


def _write_results(args, out_dir: Path, traj, scenario, options, t1, overrides, progress):
    """The result files of `jaxhoist simulate`. **Returns** `(arrays, [npz, json, csv, nc])`, paths."""
    from ..._io.results import (
        load_metadata,
        save_trajectory,
        save_trajectory_csv,
        save_trajectory_netcdf,
        trajectory_arrays,
    )
    from ..plots.trajectory import PLOTS

    with progress(f"writing results to {out_dir}"):
        claim_out_dir(
            out_dir, "simulate", [*SIMULATE_OUTPUTS, *(f"{n}.png" for n in PLOTS), *ANIMATE_OUTPUTS]
        )
        arrays = trajectory_arrays(traj)
        npz, meta = save_trajectory(
            out_dir / "trajectory",
            traj,
            scenario,
            command=[PROG, *args.argv] if args.argv is not None else sys.argv,
            options={
                "model": args.model,
                "rope": args.rope,
                "solver": type(options.solver).__name__,
                "rtol": options.rtol,
                "atol": options.atol,
                "max_steps": args.max_steps,
                "t1": t1,
                "n_save": args.n_save,
            },
            extra={
                "source": str(args.scenario),
                "overrides": overrides,
                "timings_s": {k: round(v, 4) for k, v in progress.times.items()},
            },
        )
        csv_path = save_trajectory_csv(out_dir / "trajectory.csv", arrays)
        md = load_metadata(npz)
        nc_path = save_trajectory_netcdf(
            out_dir / "trajectory.nc", arrays, {k: md[k] for k in ("command", "scenario", "solver", "status")}
        )
    return arrays, [npz, meta, csv_path, nc_path]
