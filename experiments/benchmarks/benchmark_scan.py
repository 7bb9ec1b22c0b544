"""Cost of a large μ-scan of paper-4.2 with the DEFAULT call: wall time per trajectory
after compilation, accuracy against a tight adaptive solve, baselines in the same process (scipy LSODA,
Radau and RK45 on the same jitted vector field; a plain `jax.vmap` of `diffrax.diffeqsolve(Tsit5,
PIDController(1e-6, 1e-8))`), the cost at ε = 1e-4, forward-mode sensitivities against the plain scan, peak
memory.

    python experiments/benchmarks/benchmark_scan.py --out out/bench-scan  # 4096 μ, 25 s, every CPU core
    python experiments/benchmarks/benchmark_scan.py --out out/bench-scan --quick  # 16 μ, 1 s, a smoke run

What it runs (all in one process, so every ratio is against a baseline measured under the same load):

1. **the scan, as a user calls it**: `scan(load_scenario("paper-4.2"), {μ: linspace(0.1, 0.6, n)},
   Times(t1, n=2), observables=[final_position, final_euler])`: the preset's physics (regularised Coulomb,
   ε = 1e-3 m/s) and the default solver (Rosenbrock-W, rtol 1e-3, atol 1e-5, lock-step groups); compile
   time, wall time per trajectory (compute / n), steps, peak RSS;
2. **accuracy**: the final mass-centre position against adaptive Tsit5 at rtol --ref-rtol (atol 1e-2 rtol)
   on --ref-n members evenly spaced through the scan: the fraction within 1 cm, median, 95th percentile and
   max of the error, and for every member off by more than 1 cm how much its scan neighbours differ from it
   (a large spread marks an outcome that changes abruptly with μ);
3. **scipy** `solve_ivp` (--scipy-methods, default LSODA, Radau, RK45) on the same vector field, jitted and
   called on the flattened state, for --scipy-n of the reference members at each --scipy-rtol: wall time,
   evaluations, error; ratio of its time per trajectory to the scan's;
4. **plain vmap**: `jax.jit(jax.vmap(diffeqsolve(Tsit5, PIDController(1e-6, 1e-8))))` over --vmap-n members
   (all lanes in one lock step, no sorting, no sharding): its time per trajectory over the scan's;
5. **ε = 1e-4**: the default scan of --eps-n members at ε = 1e-4 m/s against the same members at the preset's
   1e-3 (the target: at most 2x); with --eps-lanes W, the same pair again in groups of W lanes;
6. **forward sensitivities**: `scan(..., derivatives=True)` over the whole scan (or --deriv-n members);
7. **the earlier expert row** (`--expert-row`, on by default): ε = 1e-2 m/s (changes the physics), Bosh3 at
   a fixed 1.5 ms step, 256 lanes: the previous README figure, for comparison only.

Everything goes to DIR/benchmark_scan.json; docs/performance.md records a run.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import jax  # noqa: E402

# every CPU core by default (--devices N to change), set before JAX starts its backend
jax.config.update(
    "jax_num_cpu_devices",
    int(sys.argv[sys.argv.index("--devices") + 1]) if "--devices" in sys.argv else (os.cpu_count() or 1),
)
jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402
from jax.flatten_util import ravel_pytree  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import initial_state, scan, vector_field  # noqa: E402

MU = "foundation.friction_coefficient"
EPS = "foundation.friction.regularisation_velocity"
OBS = ["final_position", "final_euler"]


def tsit5_final(sc, mu, t1: float, controller, max_steps: int = 1_000_000):
    """(final mass-centre position [m], accepted steps, success) of one Tsit5 solve at μ (the same plain
    solve as `benchmark_accelerator.py`'s)."""
    s = jh.set_param(sc, MU, mu)
    y0, c = initial_state(s)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field),
        diffrax.Tsit5(),
        0.0,
        t1,
        None,
        y0,
        (s, c),
        stepsize_controller=controller,
        max_steps=max_steps,
        saveat=diffrax.SaveAt(t1=True),
        throw=False,
    )
    assert sol.stats is not None and sol.ys is not None
    ok = (sol.result == diffrax.RESULTS.successful) & jax.numpy.all(jax.numpy.isfinite(sol.ys.position[-1]))
    return sol.ys.position[-1], sol.stats["num_accepted_steps"], ok


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def scipy_baseline(sc, t1, method, rtol, atol):
    """`solve_ivp(method=...)` on the flattened state with a jitted right-hand side; (wall s, f-evals, final
    position, ok)."""
    from scipy.integrate import solve_ivp

    y0, c = initial_state(sc)
    flat0, unravel = ravel_pytree(y0)
    rhs = jax.jit(lambda t, y: ravel_pytree(vector_field(t, unravel(y), (sc, c)))[0])
    rhs(0.0, flat0).block_until_ready()  # compile outside the timing
    t0 = time.perf_counter()
    sol = solve_ivp(
        lambda t, y: np.asarray(rhs(t, y)), (0.0, t1), np.asarray(flat0), method=method, rtol=rtol, atol=atol
    )
    wall = time.perf_counter() - t0
    return wall, int(sol.nfev), np.asarray(unravel(sol.y[:, -1]).position), bool(sol.success)


def _timed_scan(sc, mus, times, **kw):
    r = scan(sc, {MU: mus}, times, **kw)
    t = r.attrs["timings_s"]
    return r, {
        "members": int(len(mus)),
        "compile_s": t["compile"],
        "compute_s": t["compute"],
        "ms_per_trajectory": 1e3 * t["compute"] / len(mus),
        "steps_median": int(np.median(r.num_accepted_steps)),
        "steps_max": int(np.max(r.num_accepted_steps)),
        "rejected_median": int(np.median(r.num_rejected_steps)),
        "total_s": t["total"],
        "failed": int(np.sum(~r.ok)),
        "solver": r.attrs["solver"],
        "lanes": r.attrs["lanes"],
    }


def plain_vmap_tsit5(sc, mus, t1):
    """`jax.jit(jax.vmap(...))` of a plain `diffrax.diffeqsolve(Tsit5, PIDController(1e-6, 1e-8))` over every
    member at once: (wall s after compilation, compile s, final positions)."""

    def one(mu):
        return tsit5_final(sc, mu, t1, diffrax.PIDController(rtol=1e-6, atol=1e-8))[0]

    f = jax.jit(jax.vmap(one))
    x = jax.numpy.asarray(mus)
    t0 = time.perf_counter()
    f.lower(x).compile()
    tc = time.perf_counter() - t0
    jax.block_until_ready(f(x))  # the compiled call is cached by jit; this call is timed
    t0 = time.perf_counter()
    out = jax.block_until_ready(f(x))
    return time.perf_counter() - t0, tc, np.asarray(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="smoke run: 16 μ over 1 s, 2 checked, no baselines")
    p.add_argument("--n", type=int, default=None, help="number of μ in [0.1, 0.6] (default 4096; quick 16)")
    p.add_argument("--t1", type=float, default=None, help="horizon [s] (default 25, paper-4.2's; quick 1)")
    p.add_argument("--devices", type=int, default=None, help="host CPU devices (default: one per core)")
    p.add_argument(
        "--ref-n", type=int, default=None, help="members checked against the reference (512; quick 2)"
    )
    p.add_argument("--ref-rtol", type=float, default=1e-10, help="rtol of the adaptive Tsit5 reference")
    p.add_argument("--scipy-n", type=int, default=None, help="members for scipy (default 3; quick 0)")
    p.add_argument("--scipy-methods", default="LSODA,Radau,RK45", help="solve_ivp methods")
    p.add_argument("--scipy-rtol", default="1e-6", help="scipy tolerances (comma-separated; atol = rtol/100)")
    p.add_argument(
        "--vmap-n", type=int, default=None, help="members of the plain vmap baseline (64; quick 0)"
    )
    p.add_argument(
        "--eps-n", type=int, default=None, help="members of the ε = 1e-4 row (256; quick 0; 0: none)"
    )
    p.add_argument(
        "--eps-lanes", type=int, default=None, help="also run the ε = 1e-4 row in groups of this width"
    )
    p.add_argument("--deriv-n", type=int, default=None, help="sensitivity members (all; quick 0)")
    p.add_argument("--no-expert-row", action="store_true", help="skip the ε = 1e-2 fixed-step Bosh3 row")
    args = p.parse_args(argv)
    if args.eps_lanes is not None and (args.eps_lanes < 1 or args.eps_n == 0 or args.quick):
        p.error("--eps-lanes takes a width >= 1 and the ε = 1e-4 row (--eps-n > 0, not --quick)")
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    q = args.quick  # a smoke run: the scan and its check only (the baselines compile programs of their own)
    n = args.n or (16 if q else 4096)
    t1 = args.t1 or (1.0 if q else 25.0)
    ref_n = min(n, args.ref_n if args.ref_n is not None else (2 if q else 512))
    scipy_n = args.scipy_n if args.scipy_n is not None else (0 if q else 3)
    vmap_n = min(n, args.vmap_n if args.vmap_n is not None else (0 if q else 64))
    eps_n = min(n, args.eps_n if args.eps_n is not None else (0 if q else 256))
    deriv_n = min(n, args.deriv_n if args.deriv_n is not None else (0 if q else n))
    if q:
        args.no_expert_row = True
    sc = jh.load_scenario("paper-4.2")  # as shipped: ε = 1e-3 m/s
    mus = np.linspace(0.1, 0.6, n)
    obs = dict(observables=OBS)
    times = jh.Times(t1, n=2)  # the saved times 0 and t1
    rec = {
        "scenario": sc.name,
        "friction_law": "RegularisedCoulomb, eps = "
        f"{float(sc.foundation.friction.regularisation_velocity)} m/s",
        "n": n,
        "t1": t1,
        "devices": [str(d) for d in jax.devices()],
        "load_average_at_start": os.getloadavg(),
        "command": [sys.executable, *sys.argv],
    }
    print(
        f"benchmark: {n} μ in [0.1, 0.6] of {sc.name} as shipped, t1 = {t1:g} s, default solver, "
        f"{len(jax.devices())} device(s), load average {os.getloadavg()[0]:.1f}",
        flush=True,
    )

    # 1. The scan, as a user calls it.
    r, run = _timed_scan(sc, mus, times, progress=True, **obs)
    run["peak_rss_mb"] = peak_rss_mb()
    rec["scan"] = run
    per = run["compute_s"] / n
    print(
        f"  default scan: compile {run['compile_s']:.1f} s, total {run['total_s']:.1f} s, "
        f"{run['ms_per_trajectory']:.2f} ms per trajectory (steps median {run['steps_median']}, max "
        f"{run['steps_max']}, rejected median {run['rejected_median']}), failed {run['failed']}, peak RSS "
        f"{run['peak_rss_mb']:.0f} MB",
        flush=True,
    )
    pos = r["final_position"]

    # 2. Accuracy against the adaptive reference on evenly spaced members.
    idx = np.unique(np.linspace(0, n - 1, ref_n).round().astype(int))
    t0 = time.perf_counter()
    ref = scan(
        sc,
        {MU: mus[idx]},
        times,
        options=jh.SolverOptions(
            diffrax.Tsit5(), rtol=args.ref_rtol, atol=1e-2 * args.ref_rtol, max_steps=5_000_000
        ),
        batch=jh.BatchOptions(lanes=8),
        **obs,
    )
    ref_wall = time.perf_counter() - t0
    err = np.linalg.norm(pos[idx] - ref["final_position"], axis=-1)
    spread = []
    for i in idx:  # how far the scan's neighbours land from member i [m]
        nb = [j for j in (i - 1, i + 1) if 0 <= j < n]
        spread.append(max(float(np.linalg.norm(pos[j] - pos[i])) for j in nb))
    spread = np.asarray(spread)
    rec["accuracy"] = {
        "reference": f"Tsit5 adaptive, rtol {args.ref_rtol:g}, atol {1e-2 * args.ref_rtol:g}",
        "members": int(idx.size),
        "reference_wall_s": ref_wall,
        "reference_steps_median": int(np.median(ref.num_accepted_steps)),
        "reference_failed": int(np.sum(~ref.ok)),
        "fraction_within_1cm": float(np.mean(err < 0.01)),
        "median_cm": float(100 * np.median(err)),
        "p95_cm": float(100 * np.quantile(err, 0.95)),
        "max_cm": float(100 * np.max(err)),
        "median_neighbour_spread_cm": float(100 * np.median(spread)),
        "outliers": [
            {"mu": float(mus[i]), "error_cm": float(100 * e), "neighbour_spread_cm": float(100 * s_)}
            for i, e, s_ in zip(idx, err, spread, strict=True)
            if e >= 0.01
        ],
    }
    a = rec["accuracy"]
    print(
        f"  accuracy vs {a['reference']} on {a['members']} members: {100 * a['fraction_within_1cm']:.1f} % "
        f"within 1 cm, error median {a['median_cm']:.3g} cm, 95 % {a['p95_cm']:.3g} cm, max "
        f"{a['max_cm']:.3g} cm (reference {ref_wall:.0f} s)",
        flush=True,
    )
    for o in a["outliers"]:
        print(
            f"    μ = {o['mu']:.6f}: error {o['error_cm']:.2f} cm; scan neighbours "
            f"{o['neighbour_spread_cm']:.2f} cm away",
            flush=True,
        )

    # 3. scipy on the same vector field.
    if scipy_n:
        k_idx = np.unique(np.linspace(0, idx.size - 1, scipy_n + 2)[1:-1].round().astype(int))
        rows = []
        for method in args.scipy_methods.split(","):
            for tol in (float(x) for x in args.scipy_rtol.split(",")):
                for k in k_idx:
                    mu = float(mus[idx[k]])
                    wall, nfev, p_end, ok = scipy_baseline(
                        sc.replace(**{MU: mu}), t1, method, tol, 1e-2 * tol
                    )
                    e = float(np.linalg.norm(p_end - ref["final_position"][k]))
                    rows.append(
                        {
                            "method": method,
                            "rtol": tol,
                            "mu": mu,
                            "wall_s": wall,
                            "nfev": nfev,
                            "success": ok,
                            "error_cm": 100 * e,
                            "ratio_to_scan": wall / per,
                        }
                    )
                    print(
                        f"  scipy {method} rtol {tol:g}, μ = {mu:.4f}: {wall:.2f} s, {nfev} f-evals, error "
                        f"{100 * e:.3g} cm; {wall / per:.0f}x the scan's time per trajectory",
                        flush=True,
                    )
        rec["scipy"] = {
            "runs": rows,
            "mean_ratio": {
                f"{m} rtol {tol:g}": float(
                    np.mean([x["ratio_to_scan"] for x in rows if x["rtol"] == tol and x["method"] == m])
                )
                for m in sorted({x["method"] for x in rows})
                for tol in sorted({x["rtol"] for x in rows})
            },
        }

    # 4. A plain vmap of diffeqsolve(Tsit5, PID(1e-6, 1e-8)).
    if vmap_n:
        sub_i = np.linspace(0, n - 1, vmap_n).round().astype(int)
        wall, tc, p_end = plain_vmap_tsit5(sc, mus[sub_i], t1)
        rec["plain_vmap_tsit5"] = {
            "members": vmap_n,
            "compile_s": tc,
            "ms_per_trajectory": 1e3 * wall / vmap_n,
            "ratio_to_scan": (wall / vmap_n) / per,
            "max_difference_cm": float(100 * np.max(np.linalg.norm(p_end - pos[sub_i], axis=-1))),
        }
        v = rec["plain_vmap_tsit5"]
        print(
            f"  plain vmap of diffeqsolve(Tsit5, PID 1e-6/1e-8), {vmap_n} members: "
            f"{v['ms_per_trajectory']:.1f} ms "
            f"per trajectory, {v['ratio_to_scan']:.1f}x the scan",
            flush=True,
        )

    # 5. ε = 1e-4 against the preset's ε on the same members (default width, then --eps-lanes's).
    if eps_n:
        sub = mus[np.linspace(0, n - 1, eps_n).round().astype(int)]

        def eps_pair(**kw):
            _, base = _timed_scan(sc, sub, times, **kw, **obs)
            _, stiff = _timed_scan(sc.replace(**{EPS: 1e-4}), sub, times, **kw, **obs)
            return {"preset_eps": base, "eps_1e-4": stiff, "ratio": stiff["compute_s"] / base["compute_s"]}

        e = rec["eps_1e-4"] = eps_pair()
        base, stiff = e["preset_eps"], e["eps_1e-4"]
        print(
            f"  ε = 1e-4 on {eps_n} members: {stiff['ms_per_trajectory']:.2f} vs "
            f"{base['ms_per_trajectory']:.2f} ms "
            f"per trajectory at 1e-3 ({e['ratio']:.2f}x; {base['lanes']} lanes, steps median "
            f"{stiff['steps_median']}, max {stiff['steps_max']} against {base['steps_median']}, "
            f"{base['steps_max']}), failed {stiff['failed']}",
            flush=True,
        )
        if args.eps_lanes:
            e = rec["eps_1e-4_lanes"] = {
                "lanes": args.eps_lanes,
                **eps_pair(batch=jh.BatchOptions(lanes=args.eps_lanes)),
            }
            base, stiff = e["preset_eps"], e["eps_1e-4"]
            print(
                f"  the same in groups of {args.eps_lanes} lanes: {stiff['ms_per_trajectory']:.2f} vs "
                f"{base['ms_per_trajectory']:.2f} ms per trajectory ({e['ratio']:.2f}x), "
                f"failed {stiff['failed']}",
                flush=True,
            )

    # 6. Forward sensitivities.
    if deriv_n:
        sub = mus[np.linspace(0, n - 1, deriv_n).round().astype(int)]
        plain = run if deriv_n == n else _timed_scan(sc, sub, times, **obs)[1]
        der, d = _timed_scan(sc, sub, times, derivatives=True, progress=True, **obs)
        rec["derivatives"] = {"plain": plain, "forward": d, "ratio": d["compute_s"] / plain["compute_s"]}
        print(
            f"  forward sensitivities on {deriv_n} members: {d['ms_per_trajectory']:.2f} vs plain "
            f"{plain['ms_per_trajectory']:.2f} ms per trajectory ({rec['derivatives']['ratio']:.2f}x), "
            "compile "
            f"{d['compile_s']:.1f} s, failed {d['failed']}",
            flush=True,
        )

    # 7. The earlier expert row: softer friction (other physics), explicit fixed steps.
    if not args.no_expert_row:
        sc2 = sc.replace(**{EPS: 1e-2})
        _, x = _timed_scan(
            sc2,
            mus,
            times,
            options=jh.SolverOptions(
                diffrax.Bosh3(), diffrax.ConstantStepSize(), dt0=1.5e-3, max_steps=10**7
            ),
            batch=jh.BatchOptions(lanes=256),
            **obs,
        )
        rec["expert_eps_1e-2_bosh3_fixed"] = x
        print(
            f"  expert row (ε = 1e-2, Bosh3 fixed 1.5 ms, 256 lanes): {x['ms_per_trajectory']:.2f} ms per "
            f"trajectory, compile {x['compile_s']:.1f} s",
            flush=True,
        )

    rec["load_average_at_end"] = os.getloadavg()
    rec["peak_rss_mb"] = peak_rss_mb()
    path = out / "benchmark_scan.json"
    path.write_text(json.dumps(rec, indent=1) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
