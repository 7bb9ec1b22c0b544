"""What the command line shows while it works: timed steps on stderr (`StepTimer`: "compiling ...
6.12 s") and tqdm progress bars fed by the callbacks of `scan`, `locate_bifurcation`/`trace_boundary`
and `identify`, or by the lines that diffrax's progress meter and the rigid phase log print."""

from __future__ import annotations

import contextlib
import math
import sys
import time


class StepTimer:
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
    def __init__(self, progress: StepTimer, label: str, bar: bool = False):
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


def tqdm_bar(total: float | int, desc: str, unit: str, *, quiet: bool = False, bar_format: str | None = None):
    """A tqdm progress bar on stderr (a disabled one with `quiet`)."""
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        disable=quiet,
        dynamic_ncols=True,
        leave=True,
        bar_format=bar_format,
    )


class LineSink:
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


class _Eta:
    """The remaining time of a bar from the progress made since its first report, so that the compile
    before that report (and the solve's own start) does not enter the rate: empty text until a second
    report has moved the bar, then "ETA m:ss". (tqdm's own `{remaining}` divides by the whole elapsed
    time, and showed hours while the first phase compiled.)"""

    def __init__(self):
        self.t0, self.n0 = None, 0.0

    def __call__(self, n: float, total: float) -> str:
        now = time.perf_counter()
        if self.t0 is None:
            self.t0, self.n0 = now, n
            return ""
        if n <= self.n0 or now <= self.t0:
            return ""
        return f"ETA {_fmt_seconds((total - n) * (now - self.t0) / (n - self.n0))}"


def percent_to_bar(bar):
    """`on_line` for diffrax's TextProgressMeter: lines "12.34%" move `bar` (total 100) to 12.34, with the
    ETA of `_Eta` in the postfix."""
    eta = _Eta()

    def on_line(line: str) -> None:
        try:
            value = float(line.rstrip("%"))
        except ValueError:
            print(line, file=sys.stderr)
            return
        bar.n = round(min(max(value, 0.0), 100.0), 2)
        bar.set_postfix_str(eta(bar.n, 100.0), refresh=False)
        bar.refresh()

    return on_line


def phase_to_bar(bar):
    """`on_line` for the rigid model's verbose phase log ("t0 - t1 s  modes -> end [n steps so far]"): moves
    `bar` (total t1 [s]) to the phase's end time and shows the ETA of `_Eta` (none before the second
    phase: each new phase compiles on first use) and the phase in the postfix."""
    eta = _Eta()

    def on_line(line: str) -> None:
        head, sep, rest = line.partition(" s ")
        try:
            t_end = float(head.split("-")[-1])
        except ValueError:
            return
        bar.n = min(round(t_end, 4), bar.total)
        remaining = eta(bar.n, bar.total)
        phase = rest.split("[")[0].strip()
        bar.set_postfix_str(f"{remaining}, {phase}" if remaining else phase, refresh=False)
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

    def new_bar(self, total: float | int | None, desc: str, unit: str, bar_format: str):
        """A tqdm bar of `total` steps in `unit` on `stream` (drawing nothing when `quiet`)."""
        from tqdm import tqdm

        return tqdm(
            total=total,
            desc=desc,
            unit=unit,
            file=self.stream or sys.stderr,
            disable=self.quiet,
            dynamic_ncols=True,
            bar_format=bar_format,
        )


class ScanProgressBar(_TqdmReport):
    """Renders `jaxhoist._apps.scan.progress.Progress` reports (one per chunk) as a tqdm bar on stderr:
    members done of the total, members per second, ETA, failures so far (and chunks read back from disk).

    **Arguments**
    - `stream`: where to draw (default stderr); `quiet`: draw nothing.
    """

    def __call__(self, p) -> None:
        if self.bar is None:
            self.bar = self.new_bar(
                p.total,
                "scan",
                "member",
                "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} members [{postfix}]",
            )
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
        key = r.get("point")
        if self.bar is None or key != self.key:
            self.close()
            desc = (
                "locating" if key is None else (f"point {key + 1}/{r['n_points']} ({r['along_value']:.6g})")
            )
            self.bar = self.new_bar(
                100.0, desc, "%", "{desc}: {percentage:3.0f}%|{bar}| [{elapsed}, {postfix}]"
            )
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
            f"{r['n_solves']} solves",
            refresh=False,
        )
        self.bar.refresh()


class FitProgressBar(_TqdmReport):
    """Renders `identify` progress reports as a tqdm counter of Levenberg-Marquardt evaluations on stderr
    (one bar per start, out of `max_iterations`) with the cost, the best cost and the step in the postfix."""

    def __init__(self, total: int | None = None, stream=None, quiet: bool = False):
        super().__init__(stream, quiet)
        self.total, self.start = total, None

    def __call__(self, r: dict) -> None:
        if self.bar is None or r["start"] != self.start:
            self.close()
            desc = "fit" if r["n_starts"] == 1 else f"fit, start {r['start'] + 1}/{r['n_starts']}"
            # no rate or ETA: the first evaluation carries the compile, and the total is a budget
            self.bar = self.new_bar(
                self.total,
                desc,
                "eval",
                "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} evals [{elapsed}{postfix}]",
            )
            self.start = r["start"]
        self.bar.n = r["iteration"]
        mark = "" if r["improved"] else " (rejected)"
        self.bar.set_postfix_str(
            f"cost {r['cost']:.6g}{mark}, best {r['best_cost']:.6g}, step {r['step']:.3g}", refresh=False
        )
        self.bar.refresh()


def _fmt_seconds(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


@contextlib.contextmanager
def scan_bars():
    """While a subcommand runs, scans that report with their default (`scan(progress=True)`, as the `scan`
    and `bifurcation --scan` commands call it) draw a `ScanProgressBar` instead of printing lines."""
    from ..scan.progress import reporting

    bar = ScanProgressBar()
    try:
        with reporting(bar):
            yield bar
    finally:
        bar.close()
