"""Single-trajectory cost of a preset: compile time, run time after compilation, steps; optionally
scipy's solve_ivp on the same (jitted) vector field in the same process, as a baseline ratio.

    python experiments/benchmarks/bench_single.py --scenario paper-4.2            # jaxhoist only
    # + scipy LSODA and RK45 baseline
    python experiments/benchmarks/bench_single.py --scenario paper-4.2 --scipy
    python experiments/benchmarks/bench_single.py --quick                          # 5 s horizon
"""

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from jax.flatten_util import ravel_pytree  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import initial_state, vector_field  # noqa: E402


def scipy_baseline(sc, t1, method):
    from scipy.integrate import solve_ivp

    y0, c = initial_state(sc)
    flat0, unravel = ravel_pytree(y0)
    rhs = jax.jit(lambda t, y: ravel_pytree(vector_field(t, unravel(y), (sc, c)))[0])
    rhs(0.0, flat0).block_until_ready()
    t0 = time.perf_counter()
    sol = solve_ivp(
        lambda t, y: np.asarray(rhs(t, y)), (0.0, t1), np.asarray(flat0), method=method, rtol=1e-6, atol=1e-8
    )
    wall = time.perf_counter() - t0
    return wall, sol.nfev, unravel(sol.y[:, -1]).position


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default="paper-4.2")
    p.add_argument("--out", default=None, help="directory for a JSON record")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--scipy", action="store_true")
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    sc = jh.load_scenario(args.scenario)
    t1 = 5.0 if args.quick else sc.t1
    t0 = time.perf_counter()
    tr = jax.block_until_ready(jh.simulate(sc, jh.Times(t1, n=251)))
    compile_s = time.perf_counter() - t0
    walls = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        tr = jax.block_until_ready(jh.simulate(sc, jh.Times(t1, n=251)))
        walls.append(time.perf_counter() - t0)
    law = sc.foundation.friction
    rec = {
        "scenario": args.scenario,
        "t1": t1,
        "friction_law": type(law).__name__,
        "friction_params": {k: float(getattr(law, k)) for k in law.__dataclass_fields__ if k != "state_size"},
        "first_call_s": compile_s,
        "run_s_median": float(np.median(walls)),
        "run_s_all": walls,
        "accepted_steps": int(tr.num_accepted_steps),
        "rejected_steps": int(tr.num_rejected_steps),
        "status": int(tr.status),
        "final_position_m": np.asarray(tr.position[-1]).tolist(),
    }
    print(
        f"{args.scenario} t1={t1} s, {rec['friction_law']} {rec['friction_params']}: first call "
        f"(compile+run) {compile_s:.2f} s, run after compilation {rec['run_s_median'] * 1e3:.0f} ms "
        f"(median of {args.repeats}), "
        f"accepted {rec['accepted_steps']} rejected {rec['rejected_steps']} steps, "
        f"{rec['run_s_median'] / max(rec['accepted_steps'] + rec['rejected_steps'], 1) * 1e6:.1f} us/step"
    )
    if args.scipy:
        for method in ("LSODA", "RK45"):
            wall, nfev, pos = scipy_baseline(sc, t1, method)
            rec[f"scipy_{method}_s"] = wall
            print(
                f"  scipy {method}: {wall:.2f} s, {nfev} RHS evaluations, final C "
                f"{np.round(np.asarray(pos), 4)} (jaxhoist {np.round(np.asarray(tr.position[-1]), 4)}); "
                f"ratio {wall / rec['run_s_median']:.0f}x"
            )
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / f"bench_single_{args.scenario}.json").write_text(json.dumps(rec, indent=2))


if __name__ == "__main__":
    main()
