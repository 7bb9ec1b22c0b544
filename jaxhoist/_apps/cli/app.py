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
import importlib
import os
import re
import sys
import warnings
from collections.abc import Sequence
from typing import NoReturn

from .animate import configure_animate
from .common import ATOL_HELP, PROG, RTOL_HELP, enable_x64
from .progress import FitProgressBar as FitProgressBar
from .progress import LineSink as LineSink
from .progress import LocatorProgressBar as LocatorProgressBar
from .progress import ScanProgressBar as ScanProgressBar
from .progress import percent_to_bar as percent_to_bar
from .progress import phase_to_bar as phase_to_bar
from .progress import scan_bars as scan_bars
from .simulate import configure_simulate
from .simulate import event_lines as event_lines
from .simulate import summary_status as summary_status

# subcommand name -> module exposing configure_parser(subparsers)
EXTENSIONS = {
    "scan": "jaxhoist._apps.cli.scan",
    "bifurcation": "jaxhoist._apps.cli.bifurcation",
    "identify": "jaxhoist._apps.cli.identify",
    "risk": "jaxhoist._apps.cli.risk",
    "optimise-lift": "jaxhoist._apps.cli.optimise",
}


# -------------------------------------------------------------------------------------------- parser

# Help texts the CLI adds where a subcommand module gives none (key: (command, option dest)); each help
# then gets its default appended by `_DefaultsFormatter`.
_EXTRA_HELP = {
    "rtol": RTOL_HELP + " (default: the solver's, 5e-4 for the default rosenbrock-w, 1e-6 for the others)",
    "atol": ATOL_HELP + " (default: the solver's, 1e-5 for the default rosenbrock-w, 1e-8 for the others)",
    "t1": "end time [s] (default: the scenario's t1)",
    "n_save": "number of equally spaced saved times from 0 to t1",
    "max_steps": "solver step budget per solve; reaching it is reported as status max_steps",
    ("scan", "out"): "output folder (chunk files, manifest, scan.npz/json/nc); a re-run of the same scan "
    "resumes, a different one is recomputed (default out/scan-<preset name or scenario file name>)",
    ("bifurcation", "out"): "folder for bifurcation.json and the PNGs (default: none, nothing is written)",
    ("bifurcation", "bracket"): "the parameter interval LO HI in which to locate the change",
}
# Library wording in error messages -> the CLI's flag names
_CLI_WORDS = {
    "use another out_dir, or resume=False to overwrite it": "use another --out, or --no-resume to "
    "recompute and overwrite it",
    "resume=False": "--no-resume",
    # `jaxhoist._physics.checks.OPT_IN`, the opt-in named by a plausible range's message
    "pass allow_implausible=True (load_scenario, scenario_from_dict, Scenario, Scenario.replace) or "
    "--allow-implausible on the command line": "pass --allow-implausible",
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


#: The options whose value is a list or range of numbers (`-0.2:0.4:4`, `-1,0,1`).
_SPEC_OPTIONS = ("--values", "--along-values")


def _join_negative_specs(argv: list[str]) -> list[str]:
    """`--values -0.2:0.4:4` as `--values=-0.2:0.4:4`: argparse reads a word that starts with a minus sign as
    an option unless it is one plain negative number, so a list or range of values that starts with a
    negative number would be refused as a missing value."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in _SPEC_OPTIONS and i + 1 < len(argv) and re.match(r"-[0-9.]", argv[i + 1]):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


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


def _take_no_cache(argv: list[str]) -> tuple[list[str], bool]:
    """`(argv without --no-cache, whether it was there)`: the flag may stand anywhere on the command line."""
    rest = [a for a in argv if a != "--no-cache"]
    return rest, len(rest) < len(argv)


def _use_cache() -> None:
    """Switch on the persistent compilation cache (`enable_compilation_cache`: `$JAXHOIST_CACHE_DIR`, else
    the per-user cache folder; `JAXHOIST_CACHE_DIR=""` leaves it off), so that a repeated command loads
    its compiled programs instead of compiling them."""
    from ..._numerics.persistent_cache import enable_compilation_cache

    enable_compilation_cache()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser: `simulate`, plus every subcommand module of `EXTENSIONS` that exists."""
    from ..._version import __version__

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
    parser.add_argument(
        "--no-cache",
        action="store_true",
        help="do not read or write the persistent compilation cache (any position on the command line; "
        "default: on, in $JAXHOIST_CACHE_DIR or the per-user cache folder, ~/.cache/jaxhoist on Linux)",
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
    """The command line on `argv` (default: the process's arguments), in this process: what the `jaxhoist`
    command runs (through `entry_point`, which then exits), and what in-process callers (the tests) call.
    Returns the exit code: 0 ok, 1 the solve failed (status not ok), 2 invalid input (one-line message on
    stderr, no traceback)."""
    enable_x64()
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        argv = _use_devices(argv)
    except ValueError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    argv, no_cache = _take_no_cache(argv)
    argv = _join_negative_specs(argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = argv
    if getattr(args, "func", None) is None:
        parser.print_help(sys.stderr)
        return 2
    shown, warnings.showwarning = warnings.showwarning, _warning_line
    try:
        return _run(args, no_cache)
    finally:  # Python's own display again once the command returns (in-process callers: the tests)
        warnings.showwarning = shown


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as the command line's one line, `jaxhoist: warning: <message>` on stderr, without the source
    file, line number and code line of Python's own display (which reads as a crash)."""
    from ..._errors import one_line

    text = str(message).removeprefix(f"{PROG}: ")
    print(f"{PROG}: warning: {one_line(text)}", file=sys.stderr if file is None else file, flush=True)


def _run(args: argparse.Namespace, no_cache: bool) -> int:
    """The parsed command run, its errors turned into their one-line messages and exit codes (see `main`)."""
    from ..._errors import Float64Error, ScenarioError, one_line

    if not no_cache:
        _use_cache()
    try:
        if args.command in ("simulate", "animate"):
            code = args.func(args)
        else:
            with scan_bars():
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


def entry_point() -> NoReturn:
    """The `jaxhoist` command and `python -m jaxhoist`: `main()` on the process's arguments, then the exit
    with its code.

    Once `main()` has returned (every file it wrote is closed), the exit handlers run (logging's flush among
    them), stdout and stderr are flushed and the process ends at once (`os._exit`), without the
    interpreter tearing down jax's, jaxlib's and matplotlib's modules and objects one by one, about 0.3 s
    of a warm `simulate` with plots on a 2-core machine, a tenth of it. As at a normal exit, a failed flush
    of stdout (a full disk, a closed pipe) turns exit code 0 into 120. An exception that escapes `main()` (a
    traceback, argparse's `--help` and usage errors) exits the usual way."""
    import atexit

    code = main()
    atexit._run_exitfuncs()  # what a normal exit runs before the teardown
    for stream in (sys.stdout, sys.stderr):
        if stream is None:  # started with that descriptor closed: Python made it None, prints went nowhere
            continue
        try:
            stream.flush()
        except (OSError, ValueError):  # what is left cannot be written (broken pipe, full disk)
            if stream is sys.stdout and code == 0:
                code = 120  # CPython's exit code when flushing stdout at exit fails
    os._exit(code)


if __name__ == "__main__":
    entry_point()
