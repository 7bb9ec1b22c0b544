"""Host-side validation shared by every entry point (the CLI commands and the Python API).

Every function here raises `ScenarioError` with one line of bounded length that names the field, the flag
or the file, before anything is compiled or solved; none imports JAX transformations or runs a solve.

- Numbers typed by a user (`--set`, `--values`, CSV cells) are read by `parse_number`, which accepts the
  plain decimal forms TOML and JSON accept (`0.3`, `-2`, `1.5e7`, `inf`, `nan`) and refuses what Python's
  `float()` would also accept but nobody means: `0_3` (that is 3.0), hex, Unicode digits.
- Files are read by `read_text`: a folder, an unreadable file, UTF-16 or non-UTF-8 bytes each get a clear
  message; a UTF-8 byte-order mark is dropped.
- Output folders are checked by `check_out_dir` before any work (a file in the way, a read-only parent,
  an existing result folder without `--overwrite`), and `clean_outputs` removes a previous run's files.
- Parameter paths (`check_param_path`), counts (`check_count`), observables (`check_scalar_observable`) and
  (the agreement of `t1` with `ts` is checked with the time grid, `numerics.solve.check_times`).
- A scenario's own values, including each parameter's plausible range (refused outside unless the scenario
  opts in with `allow_implausible`), are checked by `Scenario.check()` (`jaxhoist._physics.params`),
  which every solving entry point calls through `jaxhoist._numerics.solve.checked_scenario`.
"""

from __future__ import annotations

import argparse
import numbers
import os
import re
import reprlib
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._errors import MAX_MESSAGE_CHARS, ScenarioError, one_line

if TYPE_CHECKING:
    from .._physics import params as P

__all__ = [
    "MAX_MESSAGE_CHARS",
    "brief",
    "check_count",
    "check_out_dir",
    "check_param_path",
    "check_scalar_observable",
    "clean_outputs",
    "count_arg",
    "number_arg",
    "one_line",
    "parse_list",
    "parse_number",
    "parse_values",
    "read_text",
]

_REPR = reprlib.Repr()
_REPR.maxlevel = 3
_REPR.maxlist = 6
_REPR.maxtuple = 6
_REPR.maxdict = 4
_REPR.maxstring = 40
_REPR.maxother = 40
_REPR.maxlong = 24


def brief(value, limit: int = 80) -> str:
    """A short `repr` of `value` for an error message: long lists, deep nesting and huge integers are
    elided (`[0.3, 0.3, 0.3, 0.3, 0.3, 0.3, ...]`), and the result is at most `limit` characters.

    **Arguments**
    - `value`: anything (a TOML value, a numpy array, a string typed by a user).
    - `limit`: the longest result [characters].

    **Returns** the short representation.
    """
    if isinstance(value, np.ndarray):
        value = value.tolist() if value.size <= 6 else f"<array of shape {value.shape}>"
    try:
        text = _REPR.repr(value)
    except (RecursionError, ValueError):  # ValueError: int too large to convert to a decimal string
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def finite_number(x) -> float | None:
    """`x` as a float if it is a finite number given as a number (not a bool or text), else None: for the
    checks of numeric arguments of the Python API (`find_jumps`'s factor, `locate_bifurcation`'s level)."""
    if isinstance(x, bool | str | bytes):
        return None
    try:
        v = float(x)
    except (TypeError, ValueError, OverflowError):
        return None
    return v if np.isfinite(v) else None


def whole_number(x) -> bool:
    """Whether `x` is a whole number given as one (a Python or numpy integer, not a bool): for the checks
    of counts among the Python API's arguments (`find_jumps`'s window, `SearchOptions`' max_solves,
    `write_measurement`'s digits)."""
    return isinstance(x, numbers.Integral) and not isinstance(x, bool)


# ------------------------------------------------------------------------------------------- numbers

_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*(?:[eE][+-]?[0-9]+)?|\.[0-9]+(?:[eE][+-]?[0-9]+)?)")
_SPECIAL = re.compile(r"[+-]?(?:inf|infinity|nan)", re.IGNORECASE)


def parse_number(text: str, where: str) -> float:
    """A number typed by a user, read strictly.

    Accepts decimal forms (`0.3`, `-2`, `.5`, `1.5e7`, `1E-3`) and `inf`/`nan` (refused later by the field's
    own check, with its name); refuses underscores (`float("0_3")` is 3.0), hex, Unicode digits, empty text.

    **Arguments**
    - `text`: the text; surrounding white space is ignored.
    - `where`: what the text is, for the message (e.g. `"--set foundation.friction_coefficient"`).

    **Returns** the value as a float (numbers beyond the float range become ±inf).

    **Raises** `ScenarioError` naming `where`.
    """
    s = str(text).strip()
    if _NUMBER.fullmatch(s) or _SPECIAL.fullmatch(s):
        return float(s)
    hint = " (underscores are not allowed in numbers: write 0.3, not 0_3)" if "_" in s else ""
    raise ScenarioError(f"{where}: expected a number like 0.3 or 1.5e7, got {brief(s)}{hint}")


def _float(v, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ScenarioError(f"{where}: expected a number, got {brief(v)}")
    try:
        return float(v)
    except OverflowError:
        raise ScenarioError(f"{where}: the integer {brief(v)} is too large for a float") from None


def parse_list(text: str, where: str) -> list:
    """A list typed by a user, `[1, 2.5, 1]` (JSON syntax; nested lists for matrices).

    **Arguments**
    - `text`: the text, starting with `[`.
    - `where`: what the text is, for the message.

    **Returns** the list with every number as a float.

    **Raises** `ScenarioError` naming `where` for bad syntax, a non-number, an integer too large for a
    float, or nesting deeper than 2.
    """
    import json

    try:
        value = json.loads(text)
    except RecursionError:
        raise ScenarioError(f"{where}: the list is nested too deeply") from None
    except ValueError:
        raise ScenarioError(
            f"{where}: expected a number or a list of numbers like [1, 2.5, 1], got {brief(text)}"
        ) from None

    def conv(v, depth):
        if isinstance(v, list):
            if depth >= 2:
                raise ScenarioError(f"{where}: a list of numbers nested at most 2 deep, got {brief(text)}")
            return [conv(x, depth + 1) for x in v]
        return _float(v, where)

    if not isinstance(value, list):
        raise ScenarioError(f"{where}: expected a list like [1, 2.5, 1], got {brief(text)}")
    return conv(value, 0)  # pyright: ignore[reportReturnType]  # conv of a list is a list


def parse_values(spec, flag: str = "--values") -> np.ndarray:
    """Values of a swept parameter, read strictly: `"start:stop:num"` (inclusive, num >= 1, like
    `numpy.linspace`) or `"v1,v2,..."`; an array-like is checked to be 1-D and non-empty.

    **Arguments**
    - `spec`: the text (or array-like).
    - `flag`: the flag or argument it came from, for the message.

    **Returns** a 1-D float64 array.

    **Raises** `ScenarioError` naming `flag`.
    """
    if not isinstance(spec, str):
        try:
            a = np.asarray(spec, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise ScenarioError(f"{flag}: expected numbers, got {brief(spec)}") from None
        a = a[None] if a.ndim == 0 else a
        if a.ndim != 1 or a.size == 0:
            raise ScenarioError(f"{flag}: expected a non-empty 1-D list of values, got shape {a.shape}")
        return a
    s = spec.strip()
    if ":" in s:
        parts = s.split(":")
        if len(parts) != 3:
            raise ScenarioError(f"{flag}: expected 'start:stop:num' or 'v1,v2,...', got {brief(spec)}")
        a, b = (parse_number(x, flag) for x in parts[:2])
        n = parts[2].strip()
        if not re.fullmatch(r"[0-9]+", n) or int(n) < 1 or len(n) > 9:
            raise ScenarioError(
                f"{flag}: num in 'start:stop:num' must be a whole number >= 1, got {brief(n)}"
            )
        return np.linspace(a, b, int(n))
    items = [x for x in s.split(",") if x.strip()]
    if not items:
        raise ScenarioError(f"{flag}: no values in {brief(spec)}; expected 'start:stop:num' or 'v1,v2,...'")
    try:
        return np.array([parse_number(x, flag) for x in items])
    except ScenarioError:
        raise ScenarioError(
            f"{flag}: expected a range 'start:stop:num' (inclusive, e.g. 0.2:0.4:11) or a list 'v1,v2,...' "
            f"(e.g. 0.2,0.3,0.4), got {brief(spec)}"
        ) from None


def number_arg(text: str) -> float:
    """`argparse` type for a number flag: `parse_number`, reported by argparse as `argument --t1: ...`."""
    try:
        return parse_number(text, "expected a number")
    except ScenarioError:
        raise argparse.ArgumentTypeError(f"expected a number like 0.3 or 1.5e7, got {brief(text)}") from None


def count_arg(text: str) -> int:
    """`argparse` type for a whole-number flag: decimal digits only (no `1_000`, no `1e3`)."""
    s = str(text).strip()
    if not re.fullmatch(r"[+-]?[0-9]{1,18}", s):
        raise argparse.ArgumentTypeError(f"expected a whole number like 201, got {brief(text)}")
    return int(s)


# --------------------------------------------------------------------------------------------- files


def read_text(path: str | Path, what: str = "scenario file") -> str:
    """The text of a UTF-8 file, with a clear error for anything else.

    **Arguments**
    - `path`: the file.
    - `what`: what the file is, for the message.

    **Returns** the text (a leading UTF-8 byte-order mark removed).

    **Raises** `ScenarioError` naming the file if it is missing, a folder or unreadable, is UTF-16 (or
    holds NUL bytes), or is not valid UTF-8 (the message gives the line and column of the first bad byte).
    """
    p = Path(path)
    if p.is_dir():
        raise ScenarioError(f"{p}: is a folder, not a {what}")
    if not p.exists():
        raise ScenarioError(f"{p}: no such {what}")
    try:
        data = p.read_bytes()
    except OSError as e:
        raise ScenarioError(f"{p}: cannot read the {what}: {e.strerror or e}") from None
    if data.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in data[:4096]:
        raise ScenarioError(f"{p}: the {what} is UTF-16 encoded (or holds NUL bytes); save it as UTF-8 text")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        col = e.start - (data.rfind(b"\n", 0, e.start) + 1) + 1
        raise ScenarioError(
            f"{p}: the {what} is not UTF-8 text: byte 0x{data[e.start]:02x} at line {line}, column {col} "
            f"(Latin-1 or Windows-1252?); save it as UTF-8"
        ) from None


def check_out_dir(
    path: str | Path, flag: str = "--out", *, refuse_existing: bool = False, overwrite: bool = False
) -> Path:
    """Check, before any work, that results can be written into the folder `path`.

    **Arguments**
    - `path`: the output folder (it need not exist yet).
    - `flag`: the flag or argument it came from, for the message.
    - `refuse_existing`: refuse a folder that exists and is not empty (a previous run's results), unless
      `overwrite`.
    - `overwrite`: allow such a folder (the caller then removes its own old files with `clean_outputs`).

    **Returns** `path` as a `Path`.

    **Raises** `ScenarioError` naming `flag` and the path if `path` or one of its parents is a file, the
    nearest existing parent is not writable, or (with `refuse_existing`) the folder holds files.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ScenarioError(f"{flag} {p}: is a file, not a folder")
    anc = p.absolute()
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if not anc.is_dir():
        raise ScenarioError(f"{flag} {p}: {anc} is a file, so the folder cannot be made there")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise ScenarioError(f"{flag} {p}: {anc} is not writable")
    if refuse_existing and p.is_dir() and not overwrite:
        names = sorted(x.name for x in p.iterdir())
        if names:
            more = f" and {len(names) - 3} more" if len(names) > 3 else ""
            raise ScenarioError(
                f"{flag} {p} already holds files ({', '.join(names[:3])}{more}); pass --overwrite to "
                f"replace a previous run's results, or choose another {flag}"
            )
    return p


# The file that marks a results folder as written by a jaxhoist command (its first line names the command):
# the command may replace its own results there when it runs again (see `jaxhoist._apps.cli_common`).
MARKER = ".jaxhoist"


def marker_command(folder: str | Path) -> str | None:
    """The command named by `folder`'s marker file `MARKER`, or None if it has none (or an unreadable one)."""
    try:
        text = (Path(folder) / MARKER).read_text()
    except (OSError, UnicodeDecodeError):
        return None
    return text.splitlines()[0].strip() if text.strip() else None


def mark_folder(folder: str | Path, command: str) -> None:
    """Write the marker file `MARKER` into the existing folder `folder`: its results are `jaxhoist
    command`'s, which replaces them when it runs again."""
    (Path(folder) / MARKER).write_text(
        f"{command}\nThis folder holds the results of `jaxhoist {command}`; running the command again "
        f"replaces them.\n"
    )


def clean_outputs(folder: str | Path, names: Iterable[str]) -> list[Path]:
    """Remove a previous run's output files from `folder`: only the files called `names`, nothing else
    (no sub-folders, no other files).

    **Arguments**
    - `folder`: the output folder.
    - `names`: file names a run writes there (e.g. `trajectory.npz` and every plot's PNG name).

    **Returns** the paths removed.
    """
    removed = []
    folder = Path(folder)
    for name in dict.fromkeys(names):
        f = folder / name
        if f.is_symlink() or f.is_file():
            f.unlink()
            removed.append(f)
    return removed


# ------------------------------------------------------------------------------------- times, scans


def _concrete(x):
    import jax

    return None if isinstance(x, jax.core.Tracer) else x  # pyright: ignore[reportAttributeAccessIssue]  # jax.core is a lazily loaded submodule


def check_param_path(scenario: P.Scenario, path: str, flag: str = "--param") -> tuple[str, int | None]:
    """Check that `path` names a float scalar leaf of `scenario`, or one component of a float vector leaf
    (`load.mass_centre[0]`): what a scan or a bifurcation may vary.

    **Arguments**
    - `scenario`: the scenario whose fields are meant.
    - `path`: the dotted path, with an optional component index.
    - `flag`: the flag or argument it came from, for the message.

    **Returns** `(dotted path, index or None)`.

    **Raises** `ScenarioError` naming `flag` and the path (static settings such as `t1` and `name` are no
    parameters; a misspelt field gets a "did you mean").
    """
    from .._physics.paths import get_leaf, parse_path

    try:
        dotted, index = parse_path(str(path))
    except ScenarioError:
        raise ScenarioError(
            f"{flag} {brief(path)}: not a parameter path; use dotted field names with an optional component "
            f"index, e.g. foundation.friction_coefficient or load.mass_centre[0]"
        ) from None
    try:
        leaf = np.asarray(get_leaf(scenario, dotted))
    except ScenarioError as e:
        raise ScenarioError(f"{flag}: {e}") from None
    if not np.issubdtype(leaf.dtype, np.floating):
        raise ScenarioError(f"{flag} {path!r}: not a float leaf (dtype {leaf.dtype})")
    if index is None and leaf.ndim != 0:
        raise ScenarioError(
            f"{flag} {path!r}: a vector of shape {leaf.shape}; vary one component, e.g. '{dotted}[0]'"
        )
    if index is not None and (leaf.ndim != 1 or index >= leaf.shape[0]):
        raise ScenarioError(f"{flag} {path!r}: index {index} out of range for a leaf of shape {leaf.shape}")
    return dotted, index


def check_count(n: int, flag: str, minimum: int = 2, *, allow_zero: bool = False) -> None:
    """Refuse a count below `minimum` (e.g. `bifurcation --scan N` needs N >= 2 points; 0 means off).

    **Raises** `ScenarioError` naming `flag`.
    """
    if allow_zero and n == 0:
        return
    if n < minimum:
        off = " (0: no scan)" if allow_zero else ""
        raise ScenarioError(f"{flag} must be >= {minimum}{off}, got {n}")


def check_scalar_observable(observable, flag: str = "--observable") -> None:
    """Refuse a vector observable where a scalar one is needed (a bifurcation's indicator).

    **Arguments**
    - `observable`: a resolved `jaxhoist._numerics.observables.Observable` (its `name` and `components`).
    - `flag`: the flag or argument it came from, for the message.

    **Raises** `ScenarioError` naming the observable and suggesting a component.
    """
    comps: Sequence[str] | None = getattr(observable, "components", None)
    if comps:
        name = observable.name
        raise ScenarioError(
            f"{flag} {name!r} is a vector observable with components {list(comps)}; a scalar is needed: "
            f"pick one, e.g. '{name}[{comps[-1]}]'"
        )
