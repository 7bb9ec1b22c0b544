"""The `jaxhoist` command line (also `python -m jaxhoist`). The only module that prints.

    jaxhoist simulate paper-4.2 --out out/paper-4.2
    jaxhoist simulate my-lift.toml --t1 5 --n-save 201 --set foundation.friction_coefficient=0.3
    jaxhoist animate out/paper-4.2

Subcommands live in their own modules: each exposes `configure_parser(subparsers)`, which adds its
subcommand with `subparsers.add_parser(...)` and `set_defaults(func=run)`; `run(args)` returns an exit code
(or None for 0). `build_parser` registers `simulate` from here and the modules of `EXTENSIONS` if they exist.
Invalid input (`ScenarioError`) prints one line naming the field and exits with code 2, before compiling.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

# subcommand name -> module exposing configure_parser(subparsers)
EXTENSIONS = {
    "scan": "jaxhoist.apps.scan_cli",
    "bifurcation": "jaxhoist.apps.bifurcation",
    "identify": "jaxhoist.apps.identify",
}

PROG = "jaxhoist"


def _enable_x64() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


class Progress:
    """Timing lines on stderr: `with progress("compiling"): ...` prints `compiling ... 6.12 s`."""

    def __init__(self, stream=None, quiet: bool = False):
        self.stream = stream
        self.quiet = quiet
        self.start = time.perf_counter()
        self.times: dict[str, float] = {}

    def _out(self):
        return self.stream if self.stream is not None else sys.stderr

    def __call__(self, label: str, *, bar: bool = False):
        """A timed step; with `bar` (a progress bar draws meanwhile) the line is printed whole at the end."""
        return _Step(self, label, bar)

    def note(self, msg: str) -> None:
        if not self.quiet:
            print(msg, file=self._out(), flush=True)


class _Step:
    def __init__(self, progress: Progress, label: str, bar: bool = False):
        self.p, self.label, self.bar = progress, label, bar

    def __enter__(self):
        self.t0 = time.perf_counter()
        if not self.p.quiet and not self.bar:
            print(f"{self.label} ...", end="", file=self.p._out(), flush=True)
        return self

    def __exit__(self, exc_type, exc, tb):
        dt = time.perf_counter() - self.t0
        self.p.times[self.label] = dt
        if not self.p.quiet:
            head = f"{self.label} ..." if self.bar else ""
            print(head + (f" {dt:.2f} s" if exc_type is None else " failed"), file=self.p._out(), flush=True)
        return False


# ------------------------------------------------------------------------------------- progress bars


def _bar(total: float | int, desc: str, unit: str, *, quiet: bool = False, bar_format: str | None = None):
    """A tqdm progress bar on stderr (a disabled one with `quiet`)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=quiet, dynamic_ncols=True,
                leave=True, bar_format=bar_format)


class _LineSink:
    """A text stream that hands every complete line to `on_line` (used to turn what the library prints on
    stdout while it works, diffrax's `TextProgressMeter` percentages or the rigid model's phase log, into a
    progress bar on stderr; stdout keeps only the summary)."""

    def __init__(self, on_line):
        self.on_line, self.buf = on_line, ""

    def write(self, text: str) -> int:
        self.buf += text
        *lines, self.buf = self.buf.split("\n")
        for line in lines:
            if line.strip():
                self.on_line(line.strip())
        return len(text)

    def flush(self) -> None:
        pass


def _percent_to_bar(bar):
    """`on_line` for diffrax's TextProgressMeter: lines "12.34%" move `bar` (total 100) to 12.34."""

    def on_line(line: str) -> None:
        try:
            value = float(line.rstrip("%"))
        except ValueError:
            print(line, file=sys.stderr)
            return
        bar.n = round(min(max(value, 0.0), 100.0), 2)
        bar.refresh()

    return on_line


def _phase_to_bar(bar):
    """`on_line` for the rigid model's verbose phase log ("t0 - t1 s  modes -> end [n steps so far]"): moves
    `bar` (total t1 [s]) to the phase's end time and shows the phase in the postfix."""

    def on_line(line: str) -> None:
        head, sep, rest = line.partition(" s ")
        try:
            t_end = float(head.split("-")[-1])
        except ValueError:
            return
        bar.n = min(round(t_end, 4), bar.total)
        bar.set_postfix_str(rest.split("[")[0].strip(), refresh=False)
        bar.refresh()

    return on_line


class _TqdmReport:
    """What the progress renderers share: a tqdm bar on `stream` (default stderr), none when `quiet`, opened
    on the first report and closed by `close()`."""

    def __init__(self, stream=None, quiet: bool = False):
        self.stream, self.quiet, self.bar = stream, quiet, None

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class ScanProgressBar(_TqdmReport):
    """Renders `jaxhoist.numerics.scan.Progress` reports (one per chunk) as a tqdm bar on stderr: members
    done of the total, members per second, ETA, failures so far (and chunks read back from disk).

    **Arguments**
    - `stream`: where to draw (default stderr); `quiet`: draw nothing.
    """

    def __call__(self, p) -> None:
        from tqdm import tqdm

        if self.bar is None:
            self.bar = tqdm(total=p.total, desc="scan", unit="member", file=self.stream or sys.stderr,
                            disable=self.quiet, dynamic_ncols=True,
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} members "
                            "[{postfix}]")
        rate = f"{p.rate:.3g} members/s" if p.rate else "compiling"
        eta = "?" if p.eta is None else _fmt_seconds(p.eta)
        loaded = ", resumed from disk" if p.loaded else ""
        self.bar.n = p.done
        self.bar.set_postfix_str(
            f"{_fmt_seconds(p.elapsed)} elapsed (compile {p.compile_time:.3g} s), {rate}, ETA {eta}, "
            f"failed {p.failed}{loaded}",
            refresh=False,
        )
        self.bar.refresh()
        if p.done >= p.total:
            self.close()



class LocatorProgressBar(_TqdmReport):
    """Renders `locate_bifurcation` / `trace_boundary` progress reports as a tqdm bar on stderr: the bar is
    the bracket's shrinking on a log scale (0 % at the first bracket, 100 % at `tol`), the postfix the
    iteration, the last value solved and its indicator, the bracket width and the solves so far. A new bar
    starts for every continuation point.

    **Arguments**
    - `stream`: where to draw (default stderr); `quiet`: draw nothing.
    """

    def __init__(self, stream=None, quiet: bool = False):
        super().__init__(stream, quiet)
        self.key, self.w0 = None, None

    def __call__(self, r: dict) -> None:
        from tqdm import tqdm

        key = r.get("point")
        if self.bar is None or key != self.key:
            self.close()
            desc = "locating" if key is None else (
                f"point {key + 1}/{r['n_points']} ({r['along_value']:.6g})")
            self.bar = tqdm(total=100.0, desc=desc, unit="%", file=self.stream or sys.stderr,
                            disable=self.quiet, dynamic_ncols=True,
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}, {postfix}]")
            self.key = key
        if r["iteration"] == 1:  # a new call (a wider retry, the next candidate jump): a new first bracket
            self.w0 = r["width"]
        w, tol = r["width"], r["tol"]
        frac = 1.0 if w <= tol else 0.0
        if tol < w < self.w0:
            frac = math.log(self.w0 / w) / math.log(self.w0 / tol)
        self.bar.n = round(100.0 * min(max(frac, 0.0), 1.0), 1)
        x = r["param"][-1] if isinstance(r["param"], list) else r["param"]
        g = r["indicator"][-1] if isinstance(r["indicator"], list) else r["indicator"]
        self.bar.set_postfix_str(
            f"it {r['iteration']} {r['kind']}, p = {x:.10g}, g = {g:.3g}, width {w:.3g}, "
            f"{r['n_solves']} solves", refresh=False)
        self.bar.refresh()



class FitProgressBar(_TqdmReport):
    """Renders `identify` progress reports as a tqdm counter of Levenberg-Marquardt evaluations on stderr
    (one bar per start, out of `max_iterations`) with the cost, the best cost and the step in the postfix."""

    def __init__(self, total: int | None = None, stream=None, quiet: bool = False):
        super().__init__(stream, quiet)
        self.total, self.start = total, None

    def __call__(self, r: dict) -> None:
        from tqdm import tqdm

        if self.bar is None or r["start"] != self.start:
            self.close()
            desc = "fit" if r["n_starts"] == 1 else f"fit, start {r['start'] + 1}/{r['n_starts']}"
            self.bar = tqdm(total=self.total, desc=desc, unit="eval", file=self.stream or sys.stderr,
                            disable=self.quiet, dynamic_ncols=True)
            self.start = r["start"]
        self.bar.n = r["iteration"]
        mark = "" if r["improved"] else " (rejected)"
        self.bar.set_postfix_str(
            f"cost {r['cost']:.6g}{mark}, best {r['best_cost']:.6g}, step {r['step']:.3g}", refresh=False)
        self.bar.refresh()



def _fmt_seconds(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


class _scan_bars:
    """While a subcommand runs, scans that print their default per-chunk line (`scan(progress=True)`, as the
    `scan` and `bifurcation --scan` commands call it) draw a `ScanProgressBar` instead. The scan module
    picks its default reporter `print_progress` at call time; this swaps it for the bar and back."""

    def __enter__(self):
        import importlib

        try:
            self.mod = importlib.import_module("jaxhoist.numerics.scan")
        except Exception:  # noqa: BLE001 - no scan module: nothing to render
            self.mod = None
        self.saved = getattr(self.mod, "print_progress", None)
        if self.saved is not None:
            self.bars = ScanProgressBar()
            self.mod.print_progress = self.bars  # pyright: ignore[reportAttributeAccessIssue, reportOptionalMemberAccess]  # self.mod is set and holds print_progress when saved is not None
        return self

    def __exit__(self, *exc):
        if self.saved is not None:
            self.bars.close()
            self.mod.print_progress = self.saved  # pyright: ignore[reportAttributeAccessIssue, reportOptionalMemberAccess]  # self.mod is set and holds print_progress when saved is not None
        return False


# ---------------------------------------------------------------------------------------- simulate

_COMPILED: dict = {}


def _cache_key(scenario, ts, options):
    import equinox as eqx
    import jax

    leaves, treedef = jax.tree_util.tree_flatten((scenario, ts))
    return (treedef, tuple((x.shape, str(x.dtype)) if eqx.is_array(x) else x for x in leaves), options)


def _compiled_solve(scenario, ts, options):
    """The solve core `numerics.solve.solve`, compiled ahead of time (so compile and solve are timed apart)
    and cached per structure/shape/options, so repeated `main()` calls in one process compile once."""
    import equinox as eqx

    from ..numerics.solve import solve

    key = _cache_key(scenario, ts, options)
    if key not in _COMPILED:
        _COMPILED[key] = eqx.filter_jit(solve).lower(scenario, ts, options).compile()
    return _COMPILED[key]


def _fmt_vec(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


# Files `simulate` writes into --out besides the plots' PNGs (removed first with --overwrite).
SIMULATE_OUTPUTS = ("trajectory.npz", "trajectory.json", "trajectory.csv", "trajectory.nc")


def summary_status(arrays: dict):
    """The run's `SolveStatus` for the summary and the exit code: the solver's, except that a run marked ok
    whose state or energy residual is not finite everywhere counts as `NONFINITE` (a failed run)."""
    import numpy as np

    from .._errors import SolveStatus

    status = SolveStatus(int(arrays["status"]))
    if status == SolveStatus.OK:
        keys = ("position", "euler", "normal_forces", "rope_tension", "energy_residual")
        if not all(np.all(np.isfinite(arrays[k])) for k in keys if k in arrays):
            return SolveStatus.NONFINITE
    return status


def event_lines(status, ts, normal_forces) -> list[str]:
    """The summary's lift-off and first-detachment lines; a failed run has no event times to report (its
    arrays past the failure are inf or NaN), so it says so instead of reading times from them."""
    from .._errors import SolveStatus
    from ..io.results import corner_detach_times, liftoff_time

    if status != SolveStatus.OK:
        return ["lift-off      not available (the solve failed)", "first N_i = 0 not available"]
    lift = liftoff_time(ts, normal_forces)
    detach = corner_detach_times(ts, normal_forces)
    return [
        "lift-off      "
        + (
            f"{lift:g} s (first saved time with every N_i = 0)"
            if lift is not None
            else "none within the horizon"
        ),
        "first N_i = 0 "
        + ", ".join(f"{c}: {'-' if t is None else f'{t:g} s'}" for c, t in zip("DEFH", detach, strict=True)),
    ]


def run_simulate(args: argparse.Namespace) -> int:
    """`jaxhoist simulate`: load, validate, compile, solve, save npz+json (+ PNGs), print a summary."""
    _enable_x64()
    import jax
    import jax.numpy as jnp
    import numpy as np

    from .._errors import ScenarioError, SolveStatus, require_x64
    from ..io.results import (
        load_metadata,
        save_trajectory,
        save_trajectory_csv,
        save_trajectory_netcdf,
        trajectory_arrays,
    )
    from ..io.scenario import apply_overrides, load_scenario
    from ..io.validate import check_out_dir, clean_outputs
    from ..numerics.options import SolverOptions
    from ..numerics.solve import check_times

    require_x64()
    progress = Progress(quiet=args.quiet)
    wall0 = time.perf_counter()

    # ---- host side: everything is checked before anything is compiled
    with progress(f"loading scenario {args.scenario}"):
        scenario = load_scenario(args.scenario)
        scenario, overrides = apply_overrides(scenario, args.set)
        t1 = scenario.t1 if args.t1 is None else args.t1
        check_times(t1, None)
        if args.n_save < 2:
            raise ScenarioError(f"--n-save must be >= 2, got {args.n_save}")
        if args.rope != "elastic" and args.model != "rigid":
            raise ScenarioError(
                f"--rope {args.rope} needs --model rigid (the elastic-foundation model has the elastic rope)"
            )
        if args.model == "rigid":
            import diffrax

            options = SolverOptions(diffrax.Tsit5(), rtol=args.rtol, atol=args.atol, max_steps=args.max_steps)
        else:
            # diffrax's progress meter (TextProgressMeter) unless --quiet; its lines become a bar on stderr
            options = SolverOptions(rtol=args.rtol, atol=args.atol, max_steps=args.max_steps,
                                    progress=not args.quiet)
        ts = jnp.linspace(0.0, 1.0, args.n_save) * jnp.asarray(t1, dtype=jnp.float64)
    out_dir = Path(args.out) if args.out else Path("out") / scenario.name
    check_out_dir(out_dir, "--out", refuse_existing=True, overwrite=args.overwrite)
    progress.note(
        f"scenario {scenario.name}: t1 = {t1:g} s, {args.n_save} saved times, "
        f"{type(options.solver).__name__}, rtol = {options.rtol:g}, atol = {options.atol:g}"
    )

    if args.model == "rigid":
        from ..numerics.rigid_solve import simulate_rigid

        label = "solving with the rigid-ground model (each phase compiles on first use)"
        with progress(label, bar=True), _bar(float(t1), "rigid model", "s", quiet=args.quiet, bar_format=(
            "{desc}: {percentage:3.0f}%|{bar}| t = {n:.3f}/{total:.3g} s [{elapsed}<{remaining}{postfix}]"
        )) as bar:
            with contextlib.redirect_stdout(_LineSink(_phase_to_bar(bar))):
                traj = simulate_rigid(
                    scenario,
                    t1,
                    ts=np.asarray(ts),
                    rtol=options.rtol,  # pyright: ignore[reportArgumentType]  # SolverOptions fills rtol/atol in
                    atol=options.atol,  # pyright: ignore[reportArgumentType]  # SolverOptions fills rtol/atol in
                    max_steps=args.max_steps,
                    rope=args.rope,
                    verbose=not args.quiet,  # the phase log, one line per phase: drives the bar
                )
            bar.n = bar.total  # the phase ending at t1 is not logged
            bar.refresh()
        wall_solve = progress.times[label]
    else:
        cached = _cache_key(scenario, ts, options) in _COMPILED
        with progress("compiling (cached in this process)" if cached else "compiling"):
            solve_fn = _compiled_solve(scenario, ts, options)
        with progress("solving", bar=True), _bar(100.0, "solving", "%", quiet=args.quiet, bar_format=(
            "{desc}: {percentage:3.0f}%|{bar}| t = {n:.0f}% of t1 [{elapsed}<{remaining}]"
        )) as bar:
            with contextlib.redirect_stdout(_LineSink(_percent_to_bar(bar))):
                traj = jax.block_until_ready(solve_fn(scenario, ts, options))
        wall_solve = progress.times["solving"]

    with progress(f"writing results to {out_dir}"):
        if args.overwrite:
            from .plots import PLOTS

            clean_outputs(out_dir, [*SIMULATE_OUTPUTS, *(f"{n}.png" for n in PLOTS)])
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
        nc_path = save_trajectory_netcdf(out_dir / "trajectory.nc", arrays,
                                         {k: md[k] for k in ("command", "scenario", "solver", "status")})
    pngs = []
    if not args.no_plots:
        from . import plots

        with progress("plotting"):
            pngs = plots.save_all(arrays, out_dir, title_prefix=scenario.name)
    animation = []
    if args.animate:
        animation = _animate(out_dir, quiet=args.quiet)

    # ---- summary (stdout)
    status = summary_status(arrays)
    ts_np = arrays["ts"]
    resid = float(np.max(np.abs(arrays["energy_residual"])))
    lines = [
        f"scenario      {scenario.name} (t = 0 .. {ts_np[-1]:g} s, {len(ts_np)} saved times)",
        f"status        {status.name.lower()}" + ("" if status == SolveStatus.OK else f": {status.message}"),
        f"final C       {_fmt_vec(arrays['position'][-1])} m",
        f"final angles  (φ, ψ, ϑ) = {_fmt_vec(np.degrees(arrays['euler'][-1]))} deg",
        *event_lines(status, ts_np, arrays["normal_forces"]),
        f"max S         {arrays['rope_tension'].max() / 1e3:.4g} kN",
        f"energy check  max |residual| = {resid:.3g} J (hoist work {arrays['hoist_work'][-1]:.4g} J)",
        f"steps         {int(arrays['num_accepted_steps'])} accepted, "
        f"{int(arrays['num_rejected_steps'])} rejected",
        f"wall time     solve {wall_solve:.3g} s, total {time.perf_counter() - wall0:.3g} s",
        f"wrote         {npz}, {meta}, {csv_path.name}, {nc_path.name}"
        + (f", {len(pngs)} PNGs" if pngs else "")
        + "".join(f", {p.name}" for p in animation),
    ]
    print("\n".join(lines), flush=True)
    return 0 if status == SolveStatus.OK else 1


def configure_simulate(subparsers) -> None:
    from ..io.validate import count_arg, number_arg

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
        help="a preset name (paper-2.3, paper-4.1, paper-4.2) or a path to a TOML scenario file",
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
    p.add_argument("--rtol", type=number_arg, default=None, metavar="R",
                   help=_RTOL_HELP + " (default 1e-3 with the default Rosenbrock-W solver; 1e-6 with --model "
                   "rigid)")
    p.add_argument("--atol", type=number_arg, default=None, metavar="A",
                   help=_ATOL_HELP + " (default 1e-5 with the default solver; 1e-8 with --model rigid)")
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
        "or "
        "'load.mass_centre=[1, 2.5, 1]' (repeatable); checked before compiling",
    )
    p.add_argument("--out", default=None, metavar="DIR", help="output folder (default out/<scenario name>)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the results of a previous run in --out (its trajectory files and PNGs are removed "
        "first); without it, an existing non-empty --out is refused",
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


# ---------------------------------------------------------------------------------------- animate


def _animate(result_dir, *, quiet: bool = False, **kw) -> list[Path]:
    from .animate import animate

    bars = []  # the bar opens with the first frame, after every check has passed

    def step(done, total):
        if not bars:
            bars.append(_bar(total, "animating", "frame", quiet=quiet))
        bars[0].update(done - bars[0].n)

    try:
        return animate(result_dir, progress=step, **kw)
    finally:
        for bar in bars:
            bar.close()


def run_animate(args: argparse.Namespace) -> int:
    """`jaxhoist animate RESULT_DIR`: the 3-D animation and the key-frame strip of a saved lift."""
    paths = _animate(
        args.result_dir,
        quiet=args.quiet,
        fps=args.fps,
        duration=args.duration,
        stride=args.stride,
        fmt=args.format,
        keyframes=not args.no_keyframes,
        n_keyframes=args.keyframes,
    )
    print("wrote         " + ", ".join(str(p) for p in paths), flush=True)
    return 0


def configure_animate(subparsers) -> None:
    p = subparsers.add_parser(
        "animate",
        help="draw a saved lift in 3-D: animation (MP4 or GIF) and a key-frame strip (PNG)",
        description="Read RESULT_DIR/trajectory.npz and trajectory.json (written by `jaxhoist simulate`, "
        "either model) and write RESULT_DIR/animation.mp4 (when ffmpeg is on PATH, else animation.gif) and "
        "RESULT_DIR/keyframes.png: the box with its corners D, E, F, H, the rope from B to the boom tip A, "
        "the ground, the corner forces N_i as arrows scaled to the weight, a clock and the contact state "
        "(or the rigid model's phase).",
    )
    p.add_argument("result_dir", metavar="RESULT_DIR", help="a folder written by `jaxhoist simulate --out`")
    p.add_argument("--fps", type=float, default=20.0, metavar="F", help="frames per second of the animation")
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="SECONDS",
        help="length of the animation [s], frames spread evenly over the saved times "
        "(default: min(t1, 10 s), i.e. real time up to 10 s)",
    )
    g.add_argument(
        "--stride", type=int, default=None, metavar="K", help="instead, one frame per K saved times"
    )
    p.add_argument(
        "--format",
        choices=("gif", "mp4"),
        default=None,
        help="file format (default: mp4 if ffmpeg is on PATH, else gif)",
    )
    p.add_argument("--keyframes", type=int, default=5, metavar="N", help="frames in keyframes.png")
    p.add_argument("--no-keyframes", action="store_true", help="do not write keyframes.png")
    p.add_argument("--quiet", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=run_animate)


# -------------------------------------------------------------------------------------------- parser

_RTOL_HELP = (
    "relative tolerance of the adaptive step-size control: each step's local error estimate must stay "
    "below atol + rtol |y| in every state component"
)
_ATOL_HELP = (
    "absolute tolerance of the adaptive step-size control, in the state's SI units (m, m/s, rad, ...); "
    "it matters where a component is near zero"
)
# Help texts the CLI adds where a subcommand module gives none (key: (command, option dest)); each help
# then gets its default appended by `_DefaultsFormatter`.
_EXTRA_HELP = {
    "rtol": _RTOL_HELP + " (default: the solver's, 1e-3 for the default rosenbrock-w, 1e-6 for the others)",
    "atol": _ATOL_HELP + " (default: the solver's, 1e-5 for the default rosenbrock-w, 1e-8 for the others)",
    "t1": "end time [s] (default: the scenario's t1)",
    "n_save": "number of equally spaced saved times from 0 to t1",
    "max_steps": "solver step budget per solve; reaching it is reported as status max_steps",
    ("scan", "out"): "output folder (chunk files, manifest, scan.npz/json/nc); resumable "
    "(default out/scan-<scenario name>)",
    ("bifurcation", "out"): "folder for bifurcation.json and the PNGs (default: none, nothing is written)",
    ("bifurcation", "bracket"): "the parameter interval LO HI in which to locate the change",
}
# Library wording in error messages -> the CLI's flag names
_CLI_WORDS = {
    "use another out_dir, or resume=False to overwrite it": "use another --out, or --no-resume to "
    "recompute and overwrite it",
    "resume=False": "--no-resume",
}


class _DefaultsFormatter(argparse.HelpFormatter):
    """Appends "(default: X)" to every option's help unless the help already names its default or the
    default is None/False (a flag)."""

    def _get_help_string(self, action):
        text = action.help or ""
        d = action.default
        if (
            action.option_strings
            and d is not None
            and d is not False
            and d != []
            and d is not argparse.SUPPRESS
            and "default" not in text
            and "%(default)" not in text
        ):
            text += " (default: %(default)s)"
        return text


def _complete_help(parser: argparse.ArgumentParser, command: str) -> None:
    """Give every option of `command` a help text with its default (see `_EXTRA_HELP`)."""
    parser.formatter_class = _DefaultsFormatter
    for action in parser._actions:
        extra = _EXTRA_HELP.get((command, action.dest))
        if extra is None and not action.help:
            extra = _EXTRA_HELP.get(action.dest)
        if extra is not None:
            action.help = extra
        elif not action.help and action.option_strings and action.default not in (None, False):
            action.help = "default: %(default)s"


def _cli_message(text: str) -> str:
    """An error message of the library in the CLI's words (flag names instead of Python arguments)."""
    for lib, cli in _CLI_WORDS.items():
        text = text.replace(lib, cli)
    return text


def _add_unavailable(subparsers, name: str, module: str, error: BaseException) -> None:
    """Register `name` as a subcommand that explains why its module failed to import."""

    def run(args):
        print(
            f"{PROG} {name}: unavailable, importing {module} failed: {type(error).__name__}: {error}",
            file=sys.stderr,
        )
        return 1

    p = subparsers.add_parser(name, help=f"(unavailable: {error})", add_help=False)
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=run)


def _use_devices(argv: list[str]) -> list[str]:
    """Take `--devices N` (anywhere on the command line) out of `argv` and split the host CPU into N JAX
    devices before JAX starts, so that scans run on every core: default N = the number of CPU cores
    (`os.cpu_count()`). Scans shard their members over `jax.local_devices()`; on a machine with an
    accelerator the accelerator's devices are used and this setting does not matter.

    **Raises** `ValueError` for a value that is not a positive integer.
    """
    import jax

    n, rest, i = None, [], 0
    while i < len(argv):
        a = argv[i]
        if a == "--devices" and i + 1 < len(argv):
            n, i = argv[i + 1], i + 2
            continue
        if a.startswith("--devices="):
            n, i = a.split("=", 1)[1], i + 1
            continue
        rest.append(a)
        i += 1
    if n is not None:
        if not (n.isdigit() and int(n) >= 1):
            raise ValueError(f"--devices must be a positive integer, got {n!r}")
    count = int(n) if n is not None else (os.cpu_count() or 1)
    try:
        jax.config.update("jax_num_cpu_devices", count)
    except (AttributeError, RuntimeError):  # older JAX, or the backend already started (in-process use)
        pass
    return rest


def build_parser() -> argparse.ArgumentParser:
    """The argument parser: `simulate`, plus every subcommand module of `EXTENSIONS` that exists."""
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Differentiable simulation of a crane lifting a 3D load off the ground "
        "(Grabski & Strzałko 2003).",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    parser.add_argument(
        "--devices",
        type=int,
        default=None,
        metavar="N",
        help="split the CPU into N JAX devices for scans (any position on the command line; default: one "
        "per CPU core)",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    configure_simulate(subparsers)
    configure_animate(subparsers)
    for name, module in EXTENSIONS.items():
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as e:
            if e.name is not None and module.startswith(e.name):
                continue  # the module is not written yet
            _add_unavailable(subparsers, name, module, e)
            continue
        except Exception as e:  # a broken extension must not take `simulate` down with it
            _add_unavailable(subparsers, name, module, e)
            continue
        configure = getattr(mod, "configure_parser", None)
        if callable(configure):
            configure(subparsers)
    for name, sub in subparsers.choices.items():
        _complete_help(sub, name)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `jaxhoist` and `python -m jaxhoist`. Returns the exit code: 0 ok, 1 the solve failed
    (status not ok), 2 invalid input (one-line message on stderr, no traceback)."""
    _enable_x64()
    from .._errors import Float64Error, ScenarioError, one_line

    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        argv = _use_devices(argv)
    except ValueError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = argv
    if getattr(args, "func", None) is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        if args.command in ("simulate", "animate"):
            code = args.func(args)
        else:
            with _scan_bars():
                code = args.func(args)
    except (ScenarioError, Float64Error) as e:
        print(f"{PROG}: error: {one_line(_cli_message(str(e)))}", file=sys.stderr)
        return 2
    except OSError as e:  # a write failing after the checks (disk full, folder removed meanwhile)
        print(f"{PROG}: error: {one_line(str(e))}", file=sys.stderr)
        return 1
    except RuntimeError as e:  # the rigid model's RigidContactError: no consistent contact solution
        if type(e).__name__ != "RigidContactError":
            raise
        print(f"{PROG}: error: the rigid-ground model stopped: {str(e).splitlines()[0]}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    return 0 if code is None else int(code)


if __name__ == "__main__":
    raise SystemExit(main())
