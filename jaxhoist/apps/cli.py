"""The `jaxhoist` command line (also `python -m jaxhoist`). The only module that prints.

    jaxhoist simulate paper-4.2 --out out/paper-4.2
    jaxhoist simulate my-lift.toml --t1 5 --n-save 201 --set foundation.friction_coefficient=0.3

Subcommands live in their own modules: each exposes `configure_parser(subparsers)`, which adds its
subcommand with `subparsers.add_parser(...)` and `set_defaults(func=run)`; `run(args)` returns an exit code
(or None for 0). `build_parser` registers `simulate` from here and the modules of `EXTENSIONS` if they exist.
Invalid input (`ScenarioError`) prints one line naming the field and exits with code 2, before compiling.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from collections.abc import Sequence
from pathlib import Path

# subcommand name -> module exposing configure_parser(subparsers)
EXTENSIONS = {
    "scan": "jaxhoist.numerics.scan",
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

    def __call__(self, label: str):
        return _Step(self, label)

    def note(self, msg: str) -> None:
        if not self.quiet:
            print(msg, file=self._out(), flush=True)


class _Step:
    def __init__(self, progress: Progress, label: str):
        self.p, self.label = progress, label

    def __enter__(self):
        self.t0 = time.perf_counter()
        if not self.p.quiet:
            print(f"{self.label} ...", end="", file=self.p._out(), flush=True)
        return self

    def __exit__(self, exc_type, exc, tb):
        dt = time.perf_counter() - self.t0
        self.p.times[self.label] = dt
        if not self.p.quiet:
            print(f" {dt:.2f} s" if exc_type is None else " failed", file=self.p._out(), flush=True)
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
    from ..io.results import save_trajectory, trajectory_arrays
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
            options = SolverOptions(rtol=args.rtol, atol=args.atol, max_steps=args.max_steps)
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
        with progress(label):
            traj = simulate_rigid(
                scenario,
                t1,
                ts=np.asarray(ts),
                rtol=options.rtol,
                atol=options.atol,
                max_steps=args.max_steps,
                rope=args.rope,
            )
        wall_solve = progress.times[label]
    else:
        cached = _cache_key(scenario, ts, options) in _COMPILED
        with progress("compiling (cached in this process)" if cached else "compiling"):
            solve_fn = _compiled_solve(scenario, ts, options)
        with progress("solving"):
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
    pngs = []
    if not args.no_plots:
        from . import plots

        with progress("plotting"):
            pngs = plots.save_all(arrays, out_dir, title_prefix=scenario.name)

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
        f"wrote         {npz}, {meta}" + (f", {len(pngs)} PNGs" if pngs else ""),
    ]
    print("\n".join(lines), flush=True)
    return 0 if status == SolveStatus.OK else 1


def configure_simulate(subparsers) -> None:
    from ..io.validate import count_arg, number_arg

    p = subparsers.add_parser(
        "simulate",
        help="simulate one lift and write npz/json results and PNG plots",
        description="Simulate one lift with the elastic-foundation model (paper §3) and write "
        "trajectory.npz, trajectory.json and PNG plots to --out.",
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
        help="number of equally spaced saved times (default 501)",
    )
    p.add_argument("--rtol", type=number_arg, default=None, metavar="R",
                   help="relative tolerance of the step-size control (default 1e-3 with the default "
                        "Rosenbrock-W solver; 1e-6 with --model rigid)")
    p.add_argument("--atol", type=number_arg, default=None, metavar="A",
                   help="absolute tolerance (default 1e-5 with the default solver; 1e-8 with --model rigid)")
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
    p.add_argument("--no-plots", action="store_true", help="write only the npz/json files")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run_simulate)


# -------------------------------------------------------------------------------------------- parser


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


def build_parser() -> argparse.ArgumentParser:
    """The argument parser: `simulate`, plus every subcommand module of `EXTENSIONS` that exists."""
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Differentiable simulation of a crane lifting a 3D load off the ground "
        "(Grabski & Strzałko 2003).",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    configure_simulate(subparsers)
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
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `jaxhoist` and `python -m jaxhoist`. Returns the exit code: 0 ok, 1 the solve failed
    (status not ok), 2 invalid input (one-line message on stderr, no traceback)."""
    _enable_x64()
    from .._errors import Float64Error, ScenarioError, one_line

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = argv
    if getattr(args, "func", None) is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        code = args.func(args)
    except (ScenarioError, Float64Error) as e:
        print(f"{PROG}: error: {one_line(str(e))}", file=sys.stderr)
        return 2
    except OSError as e:  # a write failing after the checks (disk full, folder removed meanwhile)
        print(f"{PROG}: error: {one_line(str(e))}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    return 0 if code is None else int(code)


if __name__ == "__main__":
    raise SystemExit(main())
