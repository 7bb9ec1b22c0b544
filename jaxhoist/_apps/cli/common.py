"""What the command-line modules share: the program name, float64 set-up, the tolerance help texts, the
`--solver` choices and the rule for output folders."""

from __future__ import annotations

import threading
from pathlib import Path

import diffrax

from ..._io.validate import MARKER as MARKER
from ..._io.validate import mark_folder, marker_command
from ..._numerics.rosenbrock import RosenbrockW

PROG = "jaxhoist"

CLI_SOLVERS = {  # `--solver` name -> solver class (`jaxhoist scan`, `jaxhoist identify`)
    "rosenbrock-w": RosenbrockW,
    "tsit5": diffrax.Tsit5,
    "bosh3": diffrax.Bosh3,
    "dopri5": diffrax.Dopri5,
    "dopri8": diffrax.Dopri8,
    "heun": diffrax.Heun,
}


def enable_x64() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


def import_matplotlib_meanwhile() -> threading.Thread:
    """Start importing matplotlib's figure and Agg modules on a background thread and return it; `join` it
    before the first plot. The import (about 0.35 s of a command's start-up, 0.1 s more for the font cache)
    then runs while the main thread loads or compiles the solve, which waits in XLA with the interpreter
    released. Joined before plotting, so matplotlib is only ever used by one thread at a time; any error is
    left to the main thread's own import, which raises it there."""

    def run() -> None:
        try:
            import matplotlib.backends.backend_agg  # noqa: F401
            import matplotlib.figure  # noqa: F401
            from matplotlib import font_manager

            font_manager.findfont("DejaVu Sans")  # reads (or builds) the font list once
        except Exception:
            pass

    thread = threading.Thread(target=run, name="import-matplotlib", daemon=True)
    thread.start()
    return thread


RTOL_HELP = (
    "relative tolerance of the adaptive step-size control: each step's local error estimate must stay "
    "below atol + rtol |y| in every state component"
)
ATOL_HELP = (
    "absolute tolerance of the adaptive step-size control, in the state's SI units (m, m/s, rad, ...); "
    "it matters where a component is near zero"
)


# ------------------------------------------------------------------------------------- output folders
#
# One rule for every command that writes a folder (simulate, scan, bifurcation, identify, risk,
# optimise-lift): the folder gets a marker file MARKER naming the command; a folder holding the marker of
# the same command is the command's own and a re-run replaces its results there (scan resumes the same
# scan, recomputes another); a non-empty folder without it (or with another command's) is refused unless
# --overwrite. Only the files the command writes are ever removed, and only once every input is checked
# (`claim_out_dir` after the checks); anything else in the folder stays.


def default_out(scenario_arg: str, prefix: str = "") -> Path:
    """The default output folder `out/<prefix><name>`: `name` is the preset name for a preset, else the
    scenario FILE's name without its suffix (`my-lift.toml` -> `my-lift`), not the `name` field inside
    it (a copy of a preset keeps the preset's name)."""
    from ..._io.scenario import preset_names

    s = str(scenario_arg)
    name = s if s in preset_names() else Path(s).stem
    return Path("out") / f"{prefix}{name}"


def prepare_out_dir(path, command: str, *, flag: str = "--out", overwrite: bool = False) -> Path:
    """Check, before any work, that `command` may write its results into the folder `path` (see MARKER).

    **Arguments**
    - `path`: the output folder (it need not exist).
    - `command`: the subcommand (`"simulate"`, `"scan"`, ...), as its marker names it.
    - `flag`: the option it came from, for the message.
    - `overwrite`: allow a non-empty folder without the command's marker.

    **Returns** `path` as a `Path`.

    **Raises** `ScenarioError` naming `flag` and the folder: not writable, a file, or (without `overwrite`)
    non-empty and not marked as written by `command`.
    """
    from ..._errors import ScenarioError
    from ..._io.validate import check_out_dir

    p = check_out_dir(path, flag)
    if overwrite or not p.is_dir():
        return p
    names = sorted(x.name for x in p.iterdir() if x.name != MARKER)
    owner = marker_command(p)
    if not names or owner == command:
        return p
    more = f" and {len(names) - 3} more" if len(names) > 3 else ""
    held = (
        f"holds the results of `{PROG} {owner}`"
        if owner
        else f"holds files that {PROG} did not write there ({', '.join(names[:3])}{more})"
    )
    raise ScenarioError(
        f"{flag} {p} {held}; choose another {flag}, or pass --overwrite to write the {command} results "
        f"into it (only the files `{PROG} {command}` writes are replaced)"
    )


def claim_out_dir(path, command: str, outputs=()) -> Path:
    """Make the folder `path`, remove the files of an earlier run of `command` there (`outputs`: file names
    or glob patterns such as `scan_*.png`; nothing else is touched) and mark it as `command`'s.
    **Returns** `path` as a `Path`."""
    p = Path(path)
    p.mkdir(parents=True, exist_ok=True)
    for pattern in dict.fromkeys(outputs):
        for f in p.glob(pattern):
            if f.is_symlink() or f.is_file():
                f.unlink()
    mark_folder(p, command)
    return p


def rerun_scan(call, out: Path | None, resume: bool, note):
    """`call(resume)` (a scan into `out`); when `out` holds the chunks of another scan (a folder this
    command owns, checked by `prepare_out_dir`), says so through `note` and recomputes with resume off."""
    from ..._io.scan_store import DifferentScanError

    try:
        return call(resume)
    except DifferentScanError:
        if not resume:
            raise
        note(f"{out} holds another scan's chunks: recomputing there")
        return call(False)


def add_allow_implausible(parser) -> None:
    """The `--allow-implausible` flag of the commands that read a scenario."""
    parser.add_argument(
        "--allow-implausible",
        action="store_true",
        help="accept scenario values outside their plausible ranges (a typo like rope.stiffness=1e16 is "
        "refused without it); the solve's own checks, e.g. the energy balance, still apply",
    )


def add_out_options(
    parser,
    command: str,
    replaced: str,
    *,
    writes: str = "",
    prefix: str = "",
    out_help: str = "",
    metavar=None,
) -> None:
    """`--out` and `--overwrite` of a command that writes a folder (the rule of `prepare_out_dir`).

    **Arguments**
    - `command`: the subcommand, as in `{PROG} {command}`.
    - `replaced`: what `--overwrite` replaces, e.g. `"fit.png is replaced"`.
    - `writes`: what the folder gets, e.g. `"risk.json"` (in the default help of `--out`).
    - `prefix`: the prefix of the default folder `out/<prefix><name>` (see `default_out`).
    - `out_help`: the help of `--out` when not the default one.
    - `metavar`: the metavar of `--out`.
    """
    out_help = out_help or (
        f"output folder{' for ' + writes if writes else ''} (default out/{prefix}<preset name or scenario "
        f"file name>); a folder an earlier `{PROG} {command}` wrote is reused, its results replaced"
    )
    parser.add_argument("--out", default=None, metavar=metavar, help=out_help)
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help=f"write into a non-empty --out that `{PROG} {command}` did not write (only {replaced}); without "
        "it, such a folder is refused",
    )


def add_sampled_scan_command(subparsers, name: str, help: str, description: str):
    """Add the subcommand `name` of a scan over sampled uncertain inputs (`risk`, `optimise-lift`) with its
    `SCENARIO` argument and `--uncertain PATH=DIST` option. **Returns** its parser."""
    parser = subparsers.add_parser(name, help=help, description=description)
    parser.add_argument("scenario", metavar="SCENARIO", help="preset name (e.g. paper-4.2) or TOML file")
    parser.add_argument(
        "--uncertain",
        action="append",
        required=True,
        metavar="PATH=DIST",
        help="an uncertain input (repeatable): uniform(low,high), normal(mean,std), "
        "truncnormal(mean,std,low,high), lognormal(median,sigma), fixed(value) or a number, e.g. "
        "foundation.friction_coefficient=uniform(0.2,0.4)",
    )
    return parser


def sampled_scan_inputs(args, command: str, prefix: str, passed=()) -> tuple:
    """Switch on float64 and read what `add_sampled_scan_command`, `add_sampled_scan_options` and
    `add_out_options` parsed, apart from `--uncertain`; check the output folder (`prepare_out_dir`).

    **Arguments**
    - `args`: the parsed command line.
    - `command`: the subcommand, as its folder's marker names it.
    - `prefix`: the prefix of the default output folder (see `default_out`).
    - `passed`: the names of further options that are keywords of the same name of the library call.

    **Returns** `(scenario, out, keywords)`: the scenario with `--set` applied, the output folder, and the
    keywords of the library call (`lift_risk`, `optimise_lift`): `times` (the saved `Times`), `options`
    (the `SolverOptions`), `batch` (the scan's `BatchOptions`), `progress` (off with `--quiet`) and those
    named in `passed`.

    **Raises** `ScenarioError` naming the field of a bad scenario, override, option or output folder.
    """
    from ..._io.scenario import apply_overrides, load_scenario
    from ..._numerics.options import SolverOptions
    from ..._numerics.times import Times
    from ..scan import BatchOptions

    enable_x64()
    scenario, _ = apply_overrides(
        load_scenario(args.scenario, allow_implausible=args.allow_implausible), args.set
    )
    out = Path(args.out) if args.out else default_out(args.scenario, prefix)
    prepare_out_dir(out, command, overwrite=args.overwrite)
    options = SolverOptions(
        CLI_SOLVERS[args.solver](), rtol=args.rtol, atol=args.atol, max_steps=args.max_steps
    )
    batch = BatchOptions(lanes=args.lanes, chunk_size=args.chunk_size)
    keywords = dict(
        times=Times(args.t1, n=args.n_save), options=options, batch=batch, progress=not args.quiet
    )
    return scenario, out, {**keywords, **{name: getattr(args, name) for name in passed}}


def add_sampled_scan_options(parser) -> None:
    """The options that `risk` and `optimise-lift` share: the horizon and saved times, the solver and its
    tolerances, the scan layout, `--set` and `--allow-implausible`."""
    p = parser
    p.add_argument("--t1", type=float, default=None, help="end time [s] (default: the scenario's t1)")
    p.add_argument("--n-save", type=int, default=201, help="saved times (the observables are read on them)")
    p.add_argument("--rtol", type=float, default=None)
    p.add_argument("--atol", type=float, default=None)
    p.add_argument("--max-steps", type=int, default=200_000)
    p.add_argument("--solver", choices=sorted(CLI_SOLVERS), default="rosenbrock-w", help="integrator")
    p.add_argument("--lanes", type=int, default=None, help="members per vmapped lock-step solve")
    p.add_argument(
        "--chunk-size", type=int, default=None, help="members per compiled call (default: automatic)"
    )
    p.add_argument("--set", action="append", default=[], metavar="PATH=VALUE", help="fixed leaf overrides")
    add_allow_implausible(p)
