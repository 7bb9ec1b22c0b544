"""Cost of the elastic model's vector field and of one fixed step, per trajectory, in a vmapped batch.

    python experiments/benchmarks/bench_vector_field.py --out out/bench-vf            # B = 256 lanes
    # fewer repeats, shorter loops
    python experiments/benchmarks/bench_vector_field.py --out out/bench-vf --quick
    python experiments/benchmarks/bench_vector_field.py --out out/bench-vf --lanes 1024 --baseline-rev REV
    # + the costliest XLA kernels
    python experiments/benchmarks/bench_vector_field.py --out out/bench-vf --profile

Measured in one process, on one CPU device, after compilation (best of several repeats, since other work
may share the CPU):

1. one vmapped evaluation of `physics.elastic.vector_field` per trajectory [ns], the scenario passed as an
   argument (as in a scan), K evaluations in a `fori_loop`: (a) every derivative, (b) the motion only (what a
   scan integrates when no observable reads the energy integrals: XLA drops the rest), (c) its forward-mode
   JVP with respect to the state and μ (b + tangents); the number of XLA fusions in the loop body;
2. one Bosh3 step per trajectory [µs]: diffrax `diffeqsolve` with `ConstantStepSize` vs the lean loop of
   `numerics.fixed_step` (same tableau, same numbers), both vmapped over μ;
3. with `--profile`: the kernels that take most of a lean step (XLA's CPU thunk trace);
4. with `--baseline-rev REV`: the loops of (1) and the lean step of (2) with the vector field of that git
   revision, imported in the same process under another package name, and the largest difference of its
   derivatives and final positions from the current one's (e.g. a revision with the written-out variant: 3x3
   products and short sums spelled out, no `dot`/`reduce` per lane, optimisation barriers).

Writes DIR/bench_vector_field.json.
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import sys
import tempfile
import time
from pathlib import Path

if "--profile" in sys.argv:  # per-kernel trace events; must be set before JAX starts its backend
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "") + " --xla_cpu_enable_xprof_traceme=true"
    ).strip()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import SolverOptions, initial_state, vector_field  # noqa: E402
from jaxhoist._numerics.fixed_step import integrate, solve_fixed  # noqa: E402  (internal: times the integrator)
from jaxhoist._numerics.solve import solve  # noqa: E402  (internal: times the solve core)

MU = "foundation.friction_coefficient"
MOTION = ("position", "velocity", "quaternion", "angular_velocity", "tip_position", "tip_velocity")


def best_time(fn, *args, repeats: int) -> float:
    """Best wall time of `fn(*args)` [s] over `repeats` rounds of 3 calls (after one warm-up call)."""
    jax.block_until_ready(fn(*args))
    best = np.inf
    for _ in range(repeats):
        for _ in range(3):
            t0 = time.perf_counter()
            jax.block_until_ready(fn(*args))
            best = min(best, time.perf_counter() - t0)
    return best


def batch_of_states(sc, B):
    """B states near the initial rest state, made different per lane (the cost does not depend on values,
    but equal lanes could let XLA take shortcuts)."""
    y0, c = initial_state(sc)
    yb = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (B, *x.shape)), y0)
    k = jnp.arange(B, dtype=jnp.float64)
    yb = eqx.tree_at(
        lambda y: y.velocity, yb, yb.velocity + 0.01 * jnp.sin(k)[:, None] * jnp.array([1, 0.5, 0.2])
    )
    yb = eqx.tree_at(
        lambda y: y.angular_velocity,
        yb,
        yb.angular_velocity + 0.01 * jnp.cos(k)[:, None] * jnp.array([0.3, 1.0, 0.2]),
    )
    yb = eqx.tree_at(lambda y: y.position, yb, yb.position + 0.002 * jnp.cos(3 * k)[:, None])
    return yb, c


def load_baseline(rev: str):
    """`physics.elastic` of git revision `rev`, extracted to a temporary package `jaxhoist_base`."""
    import importlib
    import subprocess

    root = Path(__file__).resolve().parents[2]  # the repository root
    tmp = Path(tempfile.mkdtemp(prefix="jaxhoist-base-"))
    tar = subprocess.run(
        ["git", "-C", str(root), "archive", rev, "jaxhoist"], check=True, capture_output=True
    )
    subprocess.run(["tar", "-x", "-C", str(tmp)], input=tar.stdout, check=True)
    (tmp / "jaxhoist").rename(tmp / "jaxhoist_base")
    sys.path.insert(0, str(tmp))
    return importlib.import_module("jaxhoist_base.physics.elastic")


def convert(obj, cls):
    """The same fields in another class (State/Constants of the baseline package and back)."""
    return cls(*[getattr(obj, f) for f in obj.__dataclass_fields__])


def rhs_loops(K, module=None):
    """Jittable loops of K vmapped evaluations: all derivatives, the motion only, and the JVP (of
    `module.vector_field`; default today's)."""

    def f1(sc, c, y, mu):
        args = (sc.replace(**{MU: mu}), c)
        if module is None:
            return vector_field(jnp.asarray(1.0), y, args)
        args = (args[0], convert(c, module.Constants))
        return convert(module.vector_field(jnp.asarray(1.0), convert(y, module.State), args), type(y))

    def step(y, d):  # y + 1e-9 d on the leaves kept, so nothing is dead code and values hardly move
        return jax.tree_util.tree_map(lambda a, b: a + 1e-9 * b, y, d)

    def all_terms(sc, c, yb, mus):
        f = jax.vmap(lambda y, mu: f1(sc, c, y, mu))
        return jax.lax.fori_loop(0, K, lambda i, y: step(y, f(y, mus)), yb)

    def motion(sc, c, yb, mus):
        f = jax.vmap(lambda y, mu: f1(sc, c, y, mu))

        def body(i, y):
            d = f(y, mus)
            return eqx.tree_at(
                lambda s: [getattr(s, m) for m in MOTION],
                y,
                [getattr(y, m) + 1e-9 * getattr(d, m) for m in MOTION],
            )

        return jax.lax.fori_loop(0, K, body, yb)

    def jvp(sc, c, yb, tb, mus):
        f = jax.vmap(
            lambda y, t, mu: jax.jvp(lambda y_, m_: f1(sc, c, y_, m_), (y, mu), (t, jnp.ones_like(mu)))
        )

        def body(i, st):
            y, t = st
            d, dt = f(y, t, mus)
            keep = lambda s: [getattr(s, m) for m in MOTION]  # noqa: E731
            y = eqx.tree_at(keep, y, [a + 1e-9 * b for a, b in zip(keep(y), keep(d), strict=True)])
            t = eqx.tree_at(keep, t, [a + 1e-9 * b for a, b in zip(keep(t), keep(dt), strict=True)])
            return y, t

        return jax.lax.fori_loop(0, K, body, (yb, tb))

    return all_terms, motion, jvp


def count_fusions(compiled) -> int:
    text = compiled.compiled.as_text() if hasattr(compiled, "compiled") else compiled.as_text()
    return text.count(" fusion(")


def profile_step(fn, args, n_steps, B, top=12):
    """The XLA CPU kernels that take most of the time of one call [µs per step]."""
    with tempfile.TemporaryDirectory() as d:
        with jax.profiler.trace(d):
            jax.block_until_ready(fn(*args))
        f = glob.glob(f"{d}/**/*.trace.json.gz", recursive=True)
        events = json.load(gzip.open(f[0]))["traceEvents"]
    agg: collections.Counter = collections.Counter()
    for e in events:
        if e.get("ph") == "X" and ("fusion" in e["name"] or e["name"].startswith("copy")):
            agg[e["name"]] += e["dur"]
    total = sum(agg.values())
    return {
        "kernels_us_per_step": {k: round(v / n_steps, 2) for k, v in agg.most_common(top)},
        "all_kernels_ns_per_step_per_trajectory": round(1e3 * total / n_steps / B, 1),
    }


def baseline(rev, K, B, repeats, sc, c, yb, mus):
    """Cost of the vector field of git revision `rev` and the largest relative difference of its
    derivatives from today's."""
    base = load_baseline(rev)
    b_all, b_motion, _ = rhs_loops(K, base)
    f_now = jax.vmap(lambda y, mu: vector_field(jnp.asarray(1.0), y, (sc.replace(**{MU: mu}), c)))
    f_base = jax.vmap(
        lambda y, mu: base.vector_field(
            jnp.asarray(1.0), convert(y, base.State), (sc.replace(**{MU: mu}), convert(c, base.Constants))
        )
    )
    d_now, d_base = jax.jit(f_now)(yb, mus), jax.jit(f_base)(yb, mus)
    rel = {}
    for m in MOTION:
        a, b = getattr(d_now, m), getattr(d_base, m)
        scale = float(jnp.max(jnp.abs(a)))
        if scale > 0:
            rel[m] = float(jnp.max(jnp.abs(a - b))) / scale
    rec = {"rev": rev, "max_relative_difference_of_derivatives": rel}
    for name, loop in (("all_derivatives", b_all), ("motion_only", b_motion)):
        fn = eqx.filter_jit(loop).lower(sc, c, yb, mus).compile()
        rec[name] = {
            "ns_per_eval_per_trajectory": 1e9 * best_time(fn, sc, c, yb, mus, repeats=repeats) / K / B,
            "fusions": count_fusions(fn),
        }
        print(
            f"baseline {rev}, {name:16s}: {rec[name]['ns_per_eval_per_trajectory']:6.1f} ns per evaluation "
            f"per trajectory, {rec[name]['fusions']} fusions",
            flush=True,
        )
    print(f"  derivatives today vs {rev}: largest relative difference {max(rel.values()):.1e}", flush=True)
    return rec


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="fewer repeats, shorter loops")
    p.add_argument("--lanes", type=int, default=256, help="batch width B (default 256)")
    p.add_argument(
        "--eps", type=float, default=1e-2, help="regularisation velocity ε of the Coulomb law [m/s]"
    )
    p.add_argument(
        "--profile", action="store_true", help="also list the costliest XLA kernels of a lean step"
    )
    p.add_argument("--baseline-rev", default=None, help="git revision whose vector field to compare")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    B = args.lanes
    K = 50 if args.quick else 100
    repeats = 2 if args.quick else 4
    sc = jh.load_scenario("paper-4.2").replace(**{"foundation.friction.regularisation_velocity": args.eps})
    mus = jnp.linspace(0.1, 0.6, B)
    yb, c = batch_of_states(sc, B)
    tb = jax.tree_util.tree_map(lambda x: 0.01 * jnp.ones_like(x), yb)
    rec = {
        "scenario": sc.name,
        "eps": args.eps,
        "lanes": B,
        "devices": [str(d) for d in jax.devices()[:1]],
        "command": [sys.executable, *sys.argv],
    }

    all_terms, motion, jvp = rhs_loops(K)
    comp = {
        "all_derivatives": eqx.filter_jit(all_terms).lower(sc, c, yb, mus).compile(),
        "motion_only": eqx.filter_jit(motion).lower(sc, c, yb, mus).compile(),
        "jvp_motion": eqx.filter_jit(jvp).lower(sc, c, yb, tb, mus).compile(),
    }
    calls = {
        "all_derivatives": (comp["all_derivatives"], (sc, c, yb, mus)),
        "motion_only": (comp["motion_only"], (sc, c, yb, mus)),
        "jvp_motion": (comp["jvp_motion"], (sc, c, yb, tb, mus)),
    }
    rhs = {}
    for name, (fn, a) in calls.items():
        rhs[name] = {
            "ns_per_eval_per_trajectory": 1e9 * best_time(fn, *a, repeats=repeats) / K / B,
            "fusions": count_fusions(comp[name]),
        }
        print(
            f"vector field, {name:16s}: {rhs[name]['ns_per_eval_per_trajectory']:6.1f} ns per evaluation per "
            f"trajectory (B = {B}), {rhs[name]['fusions']} fusions",
            flush=True,
        )
    rhs["jvp_over_motion"] = (
        rhs["jvp_motion"]["ns_per_eval_per_trajectory"] / rhs["motion_only"]["ns_per_eval_per_trajectory"]
    )
    rec["vector_field"] = rhs
    if args.baseline_rev:
        rec["baseline"] = baseline(args.baseline_rev, K, B, repeats, sc, c, yb, mus)

    # One Bosh3 step: diffrax ConstantStepSize vs the lean loop, both vmapped over μ (final position only).
    dt, t1 = 1.5e-3, (0.15 if args.quick else 0.3)
    n_steps = round(t1 / dt)
    ts = jnp.array([0.0, t1])
    opt = SolverOptions(
        solver=diffrax.Bosh3(), stepsize_controller=diffrax.ConstantStepSize(), dt0=dt, max_steps=100_000
    )
    steps = {}
    fns = {}
    for name, core in (("diffrax_constant_step", solve), ("lean_fixed_step", solve_fixed)):
        f = eqx.filter_jit(
            lambda s, m, core=core: jax.vmap(lambda mu: core(s.replace(**{MU: mu}), ts, opt).position[-1])(m)
        )
        t0 = time.perf_counter()
        fns[name] = f.lower(sc, mus).compile()
        compile_s = time.perf_counter() - t0
        wall = best_time(fns[name], sc, mus, repeats=repeats)
        steps[name] = {"us_per_step_per_trajectory": 1e6 * wall / n_steps / B, "compile_s": compile_s}
        print(
            f"Bosh3 step, {name:22s}: {steps[name]['us_per_step_per_trajectory']:.3f} us per step per "
            f"trajectory (B = {B}, {n_steps} steps of {1e3 * dt:g} ms), compile {compile_s:.1f} s",
            flush=True,
        )
    a, b = (np.asarray(fns[k](sc, mus)) for k in ("diffrax_constant_step", "lean_fixed_step"))
    steps["max_abs_difference_m"] = float(np.max(np.abs(a - b)))
    steps["speed_up"] = (
        steps["diffrax_constant_step"]["us_per_step_per_trajectory"]
        / steps["lean_fixed_step"]["us_per_step_per_trajectory"]
    )
    print(
        f"lean vs diffrax: {steps['speed_up']:.1f}x faster, final positions differ by "
        f"{steps['max_abs_difference_m']:.1e} m",
        flush=True,
    )
    if args.baseline_rev:
        # The same lean loop with the baseline revision's vector field (motion only, as in a scan).
        base = load_baseline(args.baseline_rev)

        def vf_base(t, y, a):
            s_, c_ = a
            d = base.vector_field(t, convert(y, base.State), (s_, convert(c_, base.Constants)))
            return convert(d, type(y))

        def lean_base(s, m):
            def one(mu):
                s1 = s.replace(**{MU: mu})
                y0, c0 = initial_state(s1)
                ys, _ = integrate(vf_base, diffrax.Bosh3(), ts, y0, (s1, c0), dt)
                return ys.position[-1]

            return jax.vmap(one)(m)

        fb = eqx.filter_jit(lean_base).lower(sc, mus).compile()
        wall = best_time(fb, sc, mus, repeats=repeats)
        steps["lean_fixed_step_baseline_vector_field"] = {
            "us_per_step_per_trajectory": 1e6 * wall / n_steps / B
        }
        steps["baseline_max_abs_difference_m"] = float(np.max(np.abs(np.asarray(fb(sc, mus)) - b)))
        us = steps["lean_fixed_step_baseline_vector_field"]["us_per_step_per_trajectory"]
        diff = steps["baseline_max_abs_difference_m"]
        print(
            f"Bosh3 step, lean, vector field of {args.baseline_rev}: {us:.3f} us per step per trajectory; "
            f"final positions differ from today's by {diff:.1e} m",
            flush=True,
        )
    rec["bosh3_step"] = steps
    if args.profile:
        rec["lean_step_profile"] = profile_step(fns["lean_fixed_step"], (sc, mus), n_steps, B)
        for k, v in rec["lean_step_profile"]["kernels_us_per_step"].items():
            print(f"  {v:8.2f} us per step  {k}")

    path = out / "bench_vector_field.json"
    path.write_text(json.dumps(rec, indent=1) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
