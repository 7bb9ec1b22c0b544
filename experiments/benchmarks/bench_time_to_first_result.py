"""Time to first result of `jaxhoist simulate`: wall time of whole command-line runs, as the user sees them,
with a cold persistent compilation cache (an empty folder), warm (the same command again) and warm with
another parameter value (`--set foundation.friction_coefficient=0.3`), with and without `--no-plots`, and
with `--no-cache` for comparison.

    python experiments/benchmarks/bench_time_to_first_result.py [--out DIR] [--quick] \\
        [--scenario paper-4.2] [--repeat N]

Each run is a fresh `python -m jaxhoist simulate SCENARIO --out DIR` subprocess with `JAXHOIST_CACHE_DIR`
set to a temporary folder (the user's cache is never touched). `--quick` runs each case once and skips the
`--no-cache` and `--set` rows and the plots (a smoke check: cold and warm, `--no-plots`, `--t1 2`).
Prints one line per case: the wall time [s], the CPU time [s], the time of the `compiling` step as the
command reports it (or, marked `load`, of the step that loads the stored compiled program instead) and the
command, then the machine's load average; with `--out`, the same table goes to
`DIR/time_to_first_result.txt`.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repository root


def run(args: list[str], cache: str, out: Path) -> tuple[float, float, str, str]:
    """(wall time [s], CPU time [s], the compile or load step's reported time, the command) of one CLI run.
    The CPU time (user + system, of the process and its threads) varies less than the wall time on a
    machine shared with other jobs."""
    if out.exists():
        shutil.rmtree(out)
    cmd = [sys.executable, "-m", "jaxhoist", "simulate", *args, "--out", str(out)]
    env = {**os.environ, "JAXHOIST_CACHE_DIR": cache, "PYTHONPATH": str(ROOT)}
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if proc.returncode != 0:
        raise SystemExit(f"failed ({proc.returncode}): {' '.join(cmd)}\n{proc.stderr[-2000:]}")
    m = re.search(r"(compiling|loading the compiled program)[^\n]*?\.\.\. ([0-9.]+) s", proc.stderr)
    step = "-" if m is None else f"{'load ' if m.group(1).startswith('loading') else ''}{m.group(2)} s"
    shown = " ".join(["JAXHOIST_CACHE_DIR=DIR", "python -m jaxhoist simulate", *args, "--out OUT"])
    return wall, cpu, step, shown


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="smoke check: cold and warm, --no-plots, --t1 2")
    p.add_argument("--out", default=None, help="folder for time_to_first_result.txt (optional)")
    p.add_argument("--scenario", default="paper-4.2")
    p.add_argument("--repeat", type=int, default=2, help="warm runs per case (the best is shown)")
    a = p.parse_args()
    repeat = 1 if a.quick else a.repeat
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        for plots in [["--no-plots"]] if a.quick else ([], ["--no-plots"]):
            cache = str(Path(tmp) / f"cache{len(plots)}")
            label = "no plots" if plots else "plots"
            base = [a.scenario, *plots, *(["--t1", "2"] if a.quick else [])]
            rows.append(("cold", label, *run(base, cache, out)))
            best = min((run(base, cache, out) for _ in range(repeat)), key=lambda r: r[0])
            rows.append(("warm", label, *best))
            if a.quick:
                continue
            other = [*base, "--set", "foundation.friction_coefficient=0.3"]
            best = min((run(other, cache, out) for _ in range(repeat)), key=lambda r: r[0])
            rows.append(("warm, mu = 0.3", label, *best))
            if not a.quick:
                rows.append(("--no-cache", label, *run([*base, "--no-cache"], cache, out)))
    lines = [f"{'case':<16} {'output':<9} {'wall [s]':>8} {'CPU [s]':>8} {'compiling':>10}  command"]
    for case, label, wall, cpu, comp, cmd in rows:
        lines.append(f"{case:<16} {label:<9} {wall:8.2f} {cpu:8.2f} {comp:>10}  {cmd}")
    lines.append(f"load average {' '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    print("\n".join(lines))
    if a.out is not None:
        Path(a.out).mkdir(parents=True, exist_ok=True)
        (Path(a.out) / "time_to_first_result.txt").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
