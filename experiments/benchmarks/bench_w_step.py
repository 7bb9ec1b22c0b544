"""Cost of one integrator step in a vmapped loop: the vector field alone, an explicit Bosh3 step, the
linearisation with its factorisation and one solve, and a full Rosenbrock-W (ROS34PW2) step, each as a
`fori_loop` of `--steps` steps of 1 ms over `--lanes` members of paper-4.2 (μ spread over [0.1, 0.6]).

    python experiments/benchmarks/bench_w_step.py --lanes 256
    python experiments/benchmarks/bench_w_step.py --lanes 64 --kinds f,w
    python experiments/benchmarks/bench_w_step.py --lanes 16,256 --kinds lin,w --baseline REV --rounds 7
    # smoke check: 8 lanes, 20 steps
    python experiments/benchmarks/bench_w_step.py --quick --out out/bench-w-step

`--baseline REV` also times `lin` and `w` with `jaxhoist/_physics/linearise.py` and
`jaxhoist/_numerics/rosenbrock.py` as they were at git revision REV (read with `git show`, everything else as
checked out), in the same process: every kind is compiled first,
then timed once per round in `--rounds` rounds (the order reversed every other round, so that a load change
on the shared machine hits both alike), and the best round counts. The ratio printed is baseline / current.

Prints compile time and µs per step per trajectory, one device; with `--out DIR`, also
`DIR/bench_w_step.json`.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import initial_state, vector_field  # noqa: E402
from jaxhoist._numerics import fixed_step  # noqa: E402  (internal: times one RK step)
from jaxhoist._numerics.rosenbrock import ROS34PW2, w_step  # noqa: E402  (internal: times one W step)
from jaxhoist._physics.linearise import linearise  # noqa: E402  (internal: times the linearisation)

H = 1e-3


def _module_at(rev: str, path: str, package: str):
    """The module `path` as it was at git revision `rev`, imported as a sibling module in `package` (so its
    relative imports resolve to the current package)."""
    root = Path(__file__).resolve().parents[2]  # the repository root
    src = subprocess.run(
        ["git", "show", f"{rev}:{path}"], cwd=root, check=True, capture_output=True, text=True
    ).stdout
    name = f"{package}._{Path(path).stem}_at_{rev}"
    spec = importlib.util.spec_from_loader(name, loader=None)
    assert spec is not None
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = package
    sys.modules[name] = mod
    exec(compile(src, f"{rev}:{path}", "exec"), mod.__dict__)
    return mod


def baseline(rev: str):
    """(`linearise`, `w_step`) as they were at git revision `rev` (jaxhoist/_physics/linearise.py and
    jaxhoist/_numerics/rosenbrock.py; the vector field and everything else as checked out)."""
    lin = _module_at(rev, "jaxhoist/_physics/linearise.py", "jaxhoist._physics")
    ros = _module_at(rev, "jaxhoist/_numerics/rosenbrock.py", "jaxhoist._numerics")
    return lin.linearise, ros.w_step


def loop(kind: str, n_steps: int, lin_fn=linearise, step_fn=w_step):
    def one(y0, args):
        if kind == "f":  # one evaluation per step, folded into the state so that XLA keeps it

            def body(i, y):
                return jax.tree_util.tree_map(lambda a, b: a + 1e-9 * b, y, vector_field(i * H, y, args))

        elif kind == "bosh3":
            tab = diffrax.Bosh3.tableau

            def body(i, c):
                return fixed_step.rk_step(vector_field, tab, i * H, c[0], c[1], H, args)

            return jax.lax.fori_loop(0, n_steps, body, (y0, vector_field(0.0, y0, args)))[0]
        elif kind == "lin":

            def body(i, y):
                lin = lin_fn(i * H, y, args)
                hg = H * ROS34PW2.gamma
                u = lin.solve(lin.factor(hg), y, hg)
                return jax.tree_util.tree_map(lambda a, b: a + 1e-12 * b, y, u)

        elif kind == "w":

            def body(i, y):
                return step_fn(vector_field, lin_fn, ROS34PW2, i * H, y, H, args)[0]

        else:
            raise SystemExit(f"unknown kind {kind!r}")
        return jax.lax.fori_loop(0, n_steps, body, y0)

    return jax.jit(jax.vmap(one))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--lanes", default="256", help="members in the vmap, comma-separated (default 256)")
    p.add_argument("--steps", type=int, default=500, help="steps per call (default 500)")
    p.add_argument("--kinds", default="f,bosh3,lin,w", help="what to time (default f,bosh3,lin,w)")
    p.add_argument("--baseline", default=None, help="git revision of linearise.py to time lin and w against")
    p.add_argument("--rounds", type=int, default=3, help="timed rounds (default 3)")
    p.add_argument("--out", default=None, help="folder for bench_w_step.json (optional)")
    p.add_argument("--quick", action="store_true", help="smoke check: 8 lanes, 20 steps, 1 round")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
        args.lanes, args.steps, args.rounds = "8", 20, 1
    records = []
    sc = jh.load_scenario("paper-4.2")
    base = baseline(args.baseline) if args.baseline else None

    def member(mu):
        s = eqx.tree_at(lambda s: s.foundation.friction_coefficient, sc, mu)
        y0, c = initial_state(s)
        return y0, (s, c)

    for lanes in [int(x) for x in args.lanes.split(",")]:
        y0s, argss = jax.vmap(member)(jnp.linspace(0.1, 0.6, lanes))
        runs = {}
        for kind in args.kinds.split(","):
            runs[kind] = loop(kind, args.steps)
            if base is not None and kind in ("lin", "w"):
                runs[f"{kind}@{args.baseline}"] = loop(kind, args.steps, *base)
        compile_s, best = {}, {k: float("inf") for k in runs}
        for k, f in runs.items():
            t0 = time.perf_counter()
            jax.block_until_ready(f(y0s, argss))
            compile_s[k] = time.perf_counter() - t0
        for r in range(args.rounds):
            for k in list(runs) if r % 2 == 0 else list(runs)[::-1]:
                t0 = time.perf_counter()
                jax.block_until_ready(runs[k](y0s, argss))
                best[k] = min(best[k], time.perf_counter() - t0)
        for k in runs:
            us = 1e6 * best[k] / args.steps / lanes
            line = f"{k:16s} lanes {lanes}: compile {compile_s[k]:.1f} s, {us:.3f} us per step per trajectory"
            if "@" in k:
                line += f"  (baseline / current: {best[k] / best[k.split('@')[0]]:.2f}x)"
            print(line, flush=True)
            records.append(dict(kind=k, lanes=lanes, compile_s=compile_s[k], us_per_step_per_trajectory=us))
    if args.out is not None:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        rec = dict(vars(args), rows=records)
        (Path(args.out) / "bench_w_step.json").write_text(json.dumps(rec, indent=1))


if __name__ == "__main__":
    main()
