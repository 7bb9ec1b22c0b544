"""Time to first result of the Python API: the first call of `scan` (256 values of μ, then in the same
process 256 values of the foundation's stiffness), `scan` with derivatives (16 values), `identify` (the
docs' five-parameter fit), docs/getting-started.md's first derivative d x_C(1 s)/dμ by `jax.jvp` (forward
mode) and by `jax.grad` (reverse mode), and `locate_bifurcation` (paper-4.3's μ*), each in a fresh Python
process with the README's set-up lines (float64, every core, the persistent compilation cache), cold (an
empty cache folder) and warm (the same folder again, a new process).

    python experiments/benchmarks/bench_first_call.py [--out DIR] [--quick] [--case NAME ...]

Prints one line per case and temperature: the import time, the first call's wall time (compile included),
a second call's wall time in the same process (other parameter values: the run alone; for
`scan-256-another-param` a scan of another parameter) and, for the scans, the second call's time per
trajectory. `--quick` runs each case but the `jax.grad` one once, over 2 s with fewer members (a smoke
check), in `$JAXHOIST_CACHE_DIR` where it is set (CI's folder, shared by every smoke run: "cold" is then
only as cold as that folder), else in a fresh folder. With `--out`, the table also goes to
`DIR/first_call.txt`. The user's cache is never touched.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repository root

SETUP = """\
import json, os, sys, time
t0 = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_num_cpu_devices", os.cpu_count())  # scans shard over every core, as in the README
import numpy as np
import jaxhoist as jh
jh.enable_compilation_cache(sys.argv[1])
T1 = float(sys.argv[2])
t_import = time.perf_counter() - t0
MU = "foundation.friction_coefficient"
"""

# Each case defines `first()` and `again()` (the same call with other values) and `n` (trajectories).
CASES = {
    "scan-256": """\
sc = jh.load_scenario("paper-4.2")
n = 256 if T1 >= 25.0 else 16
def first():
    jh.scan(sc, {MU: np.linspace(0.1, 0.6, n)}, jh.Times(T1))
def again():
    jh.scan(sc, {MU: np.linspace(0.15, 0.65, n)}, jh.Times(T1))
""",
    "scan-256-another-param": """\
sc = jh.load_scenario("paper-4.2")
n = 256 if T1 >= 25.0 else 16
def first():
    jh.scan(sc, {MU: np.linspace(0.1, 0.6, n)}, jh.Times(T1))
def again():  # another swept parameter: the same group program (batch.group_spec)
    jh.scan(sc, {"foundation.stiffness": np.linspace(1.0e7, 3.0e7, n)}, jh.Times(T1))
""",
    "scan-derivatives-16": """\
sc = jh.load_scenario("paper-4.2")
n = 16 if T1 >= 25.0 else 2
def first():
    jh.scan(sc, {MU: np.linspace(0.1, 0.6, n)}, jh.Times(T1), derivatives=True)
def again():
    jh.scan(sc, {MU: np.linspace(0.15, 0.65, n)}, jh.Times(T1), derivatives=True)
""",
    "identify-five": """\
import tempfile, os
n = 0
folder = tempfile.mkdtemp()
def fit(seed):
    m = jh.synthetic_measurement(jh.load_scenario("paper-4.2"), np.arange(0.02, min(T1, 5.0), 0.02),
                                 ["position", "rope_tension"],
                                 noise={"position": 0.005, "rope_tension": "1%"}, seed=seed)
    path = os.path.join(folder, f"lift{seed}.csv")
    jh.write_measurement(path, m)
    jh.identify("paper-4.2", path, ["mu", "k", "h", "c_l", "b_l"], start={"mu": 0.3},
                noise={"position": 0.005, "rope_tension": "1%"})
def first():
    fit(0)
def again():
    fit(1)
""",
    "jvp-getting-started": """\
import diffrax
sc = jh.load_scenario("paper-4.2")
n = 0
forward = jh.SolverOptions(adjoint=diffrax.ForwardMode())
def x_end(mu):  # docs/getting-started.md's first derivative: d x_C(1 s)/d mu, forward mode
    s = sc.replace(**{MU: mu})
    return jh.simulate(s, jh.Times(1.0, n=2), options=forward).position[-1, 0]
def first():
    jax.jvp(x_end, (0.3,), (1.0,))
def again():
    jax.jvp(x_end, (0.35,), (1.0,))
""",
    "grad-getting-started": """\
sc = jh.load_scenario("paper-4.2")
n = 0
def x_end(mu):  # the same derivative by reverse mode (the default adjoint)
    s = sc.replace(**{MU: mu})
    return jh.simulate(s, jh.Times(1.0, n=2)).position[-1, 0]
def first():
    jax.grad(x_end)(0.3)
def again():
    jax.grad(x_end)(0.35)
""",
    "locate-paper-4.3": """\
sc = jh.load_scenario("paper-4.3")
n = 0
# theta(t1) = 15 deg marks the change over 25 s; over the quick mode's 2 s, a level between the ends' values
LEVEL = float(np.radians(15.0)) if T1 >= 25.0 else 0.0041658
def locate(lo, hi):
    jh.locate_bifurcation(sc, MU, "final_theta", (lo, hi), level=LEVEL,
                          times=jh.Times(T1, n=2501))
def first():
    locate(0.362, 0.365)
def again():
    locate(0.3625, 0.3645)
""",
}

TAIL = """\
t0 = time.perf_counter(); first(); t_first = time.perf_counter() - t0
t0 = time.perf_counter(); again(); t_again = time.perf_counter() - t0
print("RESULT " + json.dumps({"import": t_import, "first": t_first, "again": t_again, "n": n}))
"""


def run_case(name: str, cache: str, t1: float) -> dict:
    code = SETUP + CASES[name] + TAIL
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    proc = subprocess.run(
        [sys.executable, "-c", code, cache, str(t1)], env=env, capture_output=True, text=True
    )
    if proc.returncode != 0:
        raise SystemExit(f"{name} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    line = [s for s in proc.stdout.splitlines() if s.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT ") :])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="each case once, cold, 2 s: a smoke check")
    p.add_argument("--out", default=None, help="folder for first_call.txt (optional)")
    p.add_argument("--case", action="append", choices=sorted(CASES), help="run only these cases")
    a = p.parse_args()
    t1 = 2.0 if a.quick else 25.0
    lines = [f"{'case':<22} {'cache':<5} {'import':>7} {'first call':>11} {'again':>8} {'ms/traj.':>9}"]
    print(lines[0], flush=True)
    # quick: every case in one cache folder, CI's shared one where .ci/experiments set $JAXHOIST_CACHE_DIR
    # (another smoke run may have compiled the same program: "cold" is then not cold); the full run: each
    # case in a fresh folder, cold then warm
    shared = os.environ.get("JAXHOIST_CACHE_DIR") if a.quick else None
    # quick: not the reverse-mode derivative (its trace alone is about 10 s; experiments/figures/
    # derivative_modes.py --quick, also a smoke run, takes the same jax.grad through simulate)
    for name in a.case or [c for c in CASES if not (a.quick and c == "grad-getting-started")]:
        with tempfile.TemporaryDirectory() as tmp:
            cache = shared or tmp
            for temp in ("cold",) if a.quick else ("cold", "warm"):
                r = run_case(name, cache, t1)
                per = f"{1e3 * r['again'] / r['n']:9.2f}" if r["n"] else f"{'-':>9}"
                times = f"{r['import']:6.2f}s {r['first']:10.2f}s {r['again']:7.2f}s"
                line = f"{name:<22} {temp:<5} {times} {per}"
                lines.append(line)
                print(line, flush=True)
    load = " ".join(open("/proc/loadavg").read().split()[:3]) if os.path.exists("/proc/loadavg") else "-"
    lines.append(f"t1 = {t1} s; load average {load}; command: python {' '.join(sys.argv)}")
    print(lines[-1])
    if a.out:
        Path(a.out).mkdir(parents=True, exist_ok=True)
        Path(a.out, "first_call.txt").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
