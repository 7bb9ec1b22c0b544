"""Where the cold time of a first call goes: Python tracing, lowering to StableHLO and XLA's compile, timed
apart (`jax.jit(f).trace(...)`, `.lower()`, `.compile()`) for each core program, with the size of what is
compiled. Compiled with the compiler options jaxhoist compiles its programs with
(`jaxhoist._numerics.xla_options`); `--options xla-defaults` compiles with XLA's defaults instead, `--options
both` each program both ways in turn (the comparison behind that module's choice).

    python experiments/benchmarks/bench_compile_phases.py [--program NAME ...] [--t1 25] [--n-save 501]
        [--lanes 16] [--run] [--options jaxhoist|xla-defaults|both] [--out DIR] [--quick]

Programs: `simulate` (the elastic core of `jaxhoist simulate` / `jh.simulate`, default solver),
`scan` (one lock-step group of `jh.scan` of the friction coefficient, `numerics.batch.group_fn`: one while
loop over its lanes, `numerics.lockstep`; timed as one program with the small one that sets the members'
values, which a scan compiles apart) and `scan-derivatives` (the same group with `derivatives=True`:
forward-mode sensitivities, a `jax.vmap` of members); on request `scan-member` and
`scan-derivatives-member`, one member of those groups alone, unbatched (`numerics.batch.member`): a group's
trace less its member's is what batching the group adds (JAX batches a vmapped while loop's body several
times: once per pass of its search for the batched carry, then once more; the lock-step group batches its
step once). Each program is
traced, lowered and compiled in a fresh Python process (JAX caches the traces of inner jitted functions, so
a second program in one process would trace faster than a first call does), without the persistent
compilation cache. Prints one line per program: each phase's wall time and, in brackets, its CPU time
(the process's, all threads: less sensitive than the wall time to other work on a shared machine) [s], the
lowered program's lines, the optimized HLO's fusions (each one an LLVM kernel that XLA's CPU backend
compiles) and, with `--run`, a second call of the compiled program (the run alone). With `--out`, the
table also goes to `DIR/compile_phases.txt`. The numbers are only comparable within one machine and load:
compare programs or commits in the same minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repository root

CHILD = """\
import json, re, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import equinox as eqx
import jax.numpy as jnp
import numpy as np
import jaxhoist as jh
from jaxhoist._apps.scan.layout import scan_solver_options
from jaxhoist._numerics import batch, observables, solve, xla_options
from jaxhoist._numerics.options import SolverOptions

program, t1, n_save, lanes, do_run = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), \\
    sys.argv[5] == "1"
# the compiler options jaxhoist compiles its programs with, or XLA's defaults (the comparison)
options = xla_options.compiler_options() if sys.argv[6] == "jaxhoist" else {}
ts = jnp.linspace(0.0, t1, n_save)
if program == "simulate":
    sc = solve.as_float64_leaves(jh.load_scenario("paper-4.2")).unlabelled()
    dyn, static = eqx.partition(sc, eqx.is_array)
    opts = SolverOptions()
    f = jax.jit(lambda dyn, ts: solve.solve(eqx.combine(dyn, static), ts, opts))
    args = (dyn, ts)
else:
    derivatives = program.startswith("scan-derivatives")
    spec = batch.BatchSpec(
        paths=("foundation.friction_coefficient",),
        observables=observables.resolve(None),
        histories=(),
        options=scan_solver_options(None, derivatives),
        lanes=lanes,
        devices=tuple(jax.local_devices()[:1]),
        derivatives=derivatives,
    )
    dyn, static = eqx.partition(jh.load_scenario("paper-4.2").unlabelled(), eqx.is_array)
    values = jnp.linspace(0.1, 0.6, lanes).reshape(lanes, 1)
    # the options as the scan passes them: the tolerances are inputs of the program (batch.group_options)
    o_dyn, o_static = eqx.partition(batch.group_options(spec), eqx.is_array)
    if program.endswith("-member"):
        f = jax.jit(lambda dyn, ts, row, o: batch.member(
            eqx.combine(dyn, static), ts, row, eqx.combine(o, o_static), spec))
        args = (dyn, ts, values[0], o_dyn)
    else:
        f = jax.jit(lambda dyn, ts, v, o: batch.group_fn(
            eqx.combine(dyn, static), ts, v, eqx.combine(o, o_static), spec))
        args = (dyn, ts, values, o_dyn)
res = {}
def timed(name, fn):
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn()
    res[name], res[name + "_cpu"] = time.perf_counter() - t0, time.process_time() - c0
    return out
traced = timed("trace", lambda: f.trace(*args))
lowered = timed("lower", traced.lower)
compiled = timed("compile", lambda: lowered.compile(compiler_options=options))
hlo = compiled.as_text() or ""
res["lines"] = lowered.as_text().count("\\n")
res["fusions"] = len(re.findall(r"= \\S+ fusion\\(", hlo))
if do_run:
    jax.block_until_ready(compiled(*args))
    timed("run", lambda: jax.block_until_ready(compiled(*args)))
print("RESULT " + json.dumps(res))
"""

PROGRAMS = ("simulate", "scan", "scan-derivatives")  # the default set
MEMBERS = ("scan-member", "scan-derivatives-member")  # on request (--program)


def run_program(name: str, t1: float, n_save: int, lanes: int, run: bool, options: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "JAXHOIST_CACHE_DIR": ""}
    argv = [sys.executable, "-c", CHILD, name, str(t1), str(n_save), str(lanes), "1" if run else "0", options]
    # run in the repository root: `python -c` puts the working folder first on sys.path
    proc = subprocess.run(argv, env=env, capture_output=True, text=True, cwd=ROOT)
    if proc.returncode != 0:
        raise SystemExit(f"{name} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    line = [s for s in proc.stdout.splitlines() if s.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT ") :])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--program", action="append", choices=PROGRAMS + MEMBERS, help="only these programs")
    p.add_argument("--t1", type=float, default=25.0, help="last saved time [s] (default 25)")
    p.add_argument("--n-save", type=int, default=501, help="saved times (default 501)")
    p.add_argument("--lanes", type=int, default=16, help="members of a scan group (default 16)")
    p.add_argument("--run", action="store_true", help="also time a second call (the run alone)")
    p.add_argument(
        "--options",
        choices=("jaxhoist", "xla-defaults", "both"),
        default="jaxhoist",
        help="compile with jaxhoist's compiler options (default), XLA's defaults, or both, alternating",
    )
    p.add_argument("--out", default=None, help="folder for compile_phases.txt (optional)")
    p.add_argument("--quick", action="store_true", help="the scan group only, 1 s, 11 saved times, 2 lanes")
    a = p.parse_args()
    if a.quick:  # a smoke check that the script runs: its numbers are not the programs'
        a.program, a.t1, a.n_save, a.lanes = ["scan"], 1.0, 11, 2
    head = (
        f"{'program':<31} {'trace':>13} {'lower':>13} {'compile':>15} {'lines':>7} {'fusions':>8} {'run':>15}"
    )
    lines = [head]
    print(head, flush=True)
    variants = ("jaxhoist", "xla-defaults") if a.options == "both" else (a.options,)
    for name, variant in [(n, v) for n in a.program or PROGRAMS for v in variants]:
        r = run_program(name, a.t1, a.n_save, a.lanes, a.run, variant)

        def both(k, w):  # wall (CPU) seconds
            return f"{r[k]:{w}.2f} ({r[k + '_cpu']:{w}.2f})" if k in r else f"{'-':>{2 * w + 3}}"

        label = name + ("" if variant == "jaxhoist" else " (XLA defaults)")
        line = (
            f"{label:<31} {both('trace', 5)} {both('lower', 5)} {both('compile', 6)} {r['lines']:7d} "
            f"{r['fusions']:8d} {both('run', 6)}"
        )
        lines.append(line)
        print(line, flush=True)
    load = " ".join(open("/proc/loadavg").read().split()[:3]) if os.path.exists("/proc/loadavg") else "-"
    lines.append(f"t1 = {a.t1} s, {a.n_save} saved times, {a.lanes} lanes; load average {load}")
    lines.append(f"command: python {' '.join(sys.argv)}")
    print("\n".join(lines[-2:]))
    if a.out:
        Path(a.out).mkdir(parents=True, exist_ok=True)
        Path(a.out, "compile_phases.txt").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
