"""Progress of long computations, reported through a callback: `Progress` (what a scan reports after each
chunk), the plain one-line printer `print_progress`, and the default reporter that `scan(progress=True)`
uses (`default_reporter`), which the command line swaps for its progress bars (`reporting`)."""

from __future__ import annotations

import contextlib
import dataclasses
import sys
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np


@dataclasses.dataclass(frozen=True)
class Progress:
    """What a progress callback receives after each chunk.

    - `chunk`, `n_chunks`: the chunk just finished (0-based) and the total.
    - `done`, `total`: members finished (incl. those loaded from disk) and in all.
    - `elapsed`: wall time of this call so far [s]; `eta`: estimated time left [s] (None before the first
      computed chunk); `rate`: members per second over the computed chunks.
    - `loaded`: True if the chunk was read from `out_dir` rather than computed.
    - `compile_time`: time spent compiling [s] (0 until the first computed chunk).
    - `failed`: members failed so far.
    """

    chunk: int
    n_chunks: int
    done: int
    total: int
    elapsed: float
    eta: float | None
    rate: float | None
    loaded: bool
    compile_time: float
    failed: int


def fmt_time(s: float | None) -> str:
    """Seconds as `m:ss` or `h:mm:ss` ("?" if unknown)."""
    if s is None or not np.isfinite(s):
        return "?"
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def print_progress(p: Progress, stream=None) -> None:
    """The plain progress report: one line per chunk on stderr."""
    stream = sys.stderr if stream is None else stream
    rate = f"{p.rate:.3g} members/s" if p.rate else "-"
    src = " (loaded)" if p.loaded else ""
    print(
        f"scan: chunk {p.chunk + 1}/{p.n_chunks}{src}  {p.done}/{p.total} members  "
        f"{100.0 * p.done / p.total:5.1f}%  elapsed {fmt_time(p.elapsed)}  left ~{fmt_time(p.eta)}  "
        f"{rate}  failed {p.failed}",
        file=stream,
        flush=True,
    )


_DEFAULT: list[Callable[[Progress], None]] = [print_progress]


def default_reporter() -> Callable[[Progress], None]:
    """The reporter of `scan(progress=True)`: `print_progress`, or what `reporting` put in its place."""
    return _DEFAULT[-1]


@contextlib.contextmanager
def reporting(report: Callable[[Progress], None]) -> Iterator[Callable[[Progress], None]]:
    """Within the block, `scan(progress=True)` reports to `report` (the command line's progress bar)."""
    _DEFAULT.append(report)
    try:
        yield report
    finally:
        _DEFAULT.remove(report)


def resolve(progress) -> Callable[[Progress], Any] | None:
    """A `progress` argument (True, False/None or a callable) -> the callable to report to, or None."""
    if progress is True:
        return default_reporter()
    return progress if callable(progress) else None
