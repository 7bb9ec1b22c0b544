"""Wall time of the rigid-ground model (paper §2) on a preset: the first call (with compilation) and the
second (solve only), in one process, with JAX's own compile-time counters.

    python experiments/benchmarks/bench_rigid.py  # paper-4.1 over its 70 s, elastic rope
    python experiments/benchmarks/bench_rigid.py --rope inextensible       # the inextensible rope (2.15)
    python experiments/benchmarks/bench_rigid.py --preset paper-2.3 --t1 20
    # a new process's first call, cold then warm: run twice with one cache folder (the second loads the
    # phase driver's compiled pieces, stored whole, without tracing them)
    python experiments/benchmarks/bench_rigid.py --cache out/bench-rigid-cache
    # smoke check: paper-2.3 over 1 s
    python experiments/benchmarks/bench_rigid.py --quick --out out/bench-rigid

The budget for the paper-4.1 lift is 30 s on this 2-core CPU; the machine is shared, so report the
load average (printed) with the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jaxhoist  # noqa: E402
from jaxhoist import simulate_rigid  # noqa: E402


def _model(rope: str) -> jaxhoist.RigidGround:
    """The rigid model with the rope named "elastic" (2.14) or "inextensible" (2.15)."""
    ropes = {"elastic": jaxhoist.ElasticRope(), "inextensible": jaxhoist.InextensibleRope()}
    return jaxhoist.RigidGround(rope=ropes[rope])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--preset", default="paper-4.1")
    p.add_argument("--t1", type=float, default=None, help="end time [s] (default: the preset's)")
    p.add_argument("--n-save", type=int, default=701)
    p.add_argument("--rope", default="elastic", choices=("elastic", "inextensible"))
    p.add_argument("--out", default=None, help="folder for bench_rigid.json (optional)")
    p.add_argument("--quick", action="store_true", help="smoke check: paper-2.3 over 1 s, 101 saved times")
    p.add_argument("--cache", default=None, help="the compilation-cache folder to use (default: none)")
    args = p.parse_args(argv)
    if args.cache is not None:
        jaxhoist.enable_compilation_cache(args.cache)
    elif args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jaxhoist.enable_compilation_cache()
    if args.quick:
        args.preset, args.t1, args.n_save = "paper-2.3", 1.0, 101
    durations: dict[str, float] = {}

    def listener(event, duration, **kw):
        durations[event] = durations.get(event, 0.0) + duration

    jax.monitoring.register_event_duration_secs_listener(listener)
    sc = jaxhoist.load_scenario(args.preset)
    t1 = sc.t1 if args.t1 is None else args.t1
    print(f"{args.preset}, t1 = {t1:g} s, rope {args.rope}, load average {os.getloadavg()[0]:.2f}")
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        tr = simulate_rigid(sc, jaxhoist.Times(t1, n=args.n_save), model=_model(args.rope))
        times.append(time.perf_counter() - t0)
        if len(times) == 1:
            compile_s = {k.rsplit("/", 1)[-1]: v for k, v in durations.items() if "/compile/" in k}
    print(
        f"first call {times[0]:.1f} s, second call {times[1]:.2f} s; {len(tr.phases)} phases, "
        f"{int(tr.num_accepted_steps)} accepted steps"
    )
    print("compilation in the first call: " + ", ".join(f"{k} {v:.1f} s" for k, v in compile_s.items()))
    if args.out is not None:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        rec = dict(vars(args), t1=t1, first_s=times[0], second_s=times[1], compile_s=compile_s)
        (out / "bench_rigid.json").write_text(json.dumps(rec, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
