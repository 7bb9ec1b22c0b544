"""Cost of a large μ-scan of paper-4.2 (issue 3's targets): wall time per trajectory after compilation,
accuracy against a tight adaptive solve, scipy LSODA and RK45 on the same vector field in the same process,
and forward-mode sensitivities against the plain scan.

    python experiments/benchmark_scan.py --out out/bench-scan --devices 2           # 4096 μ, 25 s
    python experiments/benchmark_scan.py --out out/bench-scan --devices 2 --quick   # 64 μ, 3 s: a smoke run

What it runs (all in one process, so every ratio is against a baseline measured under the same load):

1. **the scan**: `scan(paper-4.2 with the regularised Coulomb law at ε = --eps, {μ: linspace(0.1, 0.6, n)},
   t1, solver=Bosh3, fixed_step=True, dt0=--dt, lanes=--lanes, n_save=2)`: compile time, wall time per
   trajectory (compute / n), µs per step per trajectory, peak RSS;
2. **accuracy**: the final mass-centre position against adaptive Tsit5 at rtol --ref-rtol (atol 1e-2 rtol)
   on --ref-n members evenly spaced through the scan: the fraction within 1 cm, median, 95th percentile and
   max of the error, and for every member off by more than 1 cm how much its scan neighbours (Δμ = 0.5/(n-1))
   differ from it: a large spread means the outcome changes abruptly there (a bifurcation), so solver-error
   differences legitimately change it;
3. **scipy** `solve_ivp` (LSODA and RK45, --scipy-methods) on the same vector field, jitted and called on
   the flattened state, for --scipy-n of the reference members, at each tolerance of --scipy-rtol
   (atol = rtol/100): wall time, function evaluations and error against the same reference; ratio of its
   time per trajectory to the scan's;
4. **forward sensitivities**: `scan(..., derivatives=True)` (d final position / dμ and d final Euler angles /
   dμ by forward mode through the same fixed steps) over the whole scan (or --deriv-n evenly spaced
   members, against a plain scan of the same members).

With `--half-step-check` it also solves every member again at dt/2 and reports how many land within 1 cm
of that finer solution (a check of all members, where the adaptive reference covers --ref-n of them).

With `--adaptive-n N` it also runs the previous default, adaptive Tsit5 at rtol 1e-6 / atol 1e-8 in groups
of 16 lanes, on N evenly spaced members over the same horizon, for the ratio of the two.

With `--sweep-lanes 64,128,...` it first times the same scan over a short horizon (--sweep-t1) for each
lane width (µs per step per trajectory), on the devices given by --devices; `--only-sweep` stops there.

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

if "--devices" in sys.argv:  # must happen before JAX starts its backend
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "")
        + " --xla_force_host_platform_device_count="
        + sys.argv[sys.argv.index("--devices") + 1]
    ).strip()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402
from jax.flatten_util import ravel_pytree  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist.numerics.scan import scan  # noqa: E402
from jaxhoist.physics.elastic import vector_field  # noqa: E402
from jaxhoist.physics.equilibrium import initial_state  # noqa: E402

MU = "foundation.friction_coefficient"
EPS = "foundation.friction.regularisation_velocity"
OBS = ["final_position", "final_euler"]
SOLVERS = {"bosh3": diffrax.Bosh3, "tsit5": diffrax.Tsit5, "dopri5": diffrax.Dopri5, "heun": diffrax.Heun}


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


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="64 μ over 3 s, small reference: a smoke run")
    p.add_argument("--n", type=int, default=None, help="number of μ in [0.1, 0.6] (default 4096; quick 64)")
    p.add_argument(
        "--t1", type=float, default=None, help="horizon [s] (default 25, paper-4.2's span; quick 3)"
    )
    p.add_argument("--eps", type=float, default=1e-2, help="regularisation velocity ε [m/s] (default 1e-2)")
    p.add_argument("--solver", choices=sorted(SOLVERS), default="bosh3")
    p.add_argument("--dt", type=float, default=1.5e-3, help="fixed step [s] (default 1.5e-3)")
    p.add_argument("--lanes", type=int, default=256, help="members per vmapped group (default 256)")
    p.add_argument("--devices", type=int, default=None, help="host CPU devices to shard over (XLA flag)")
    p.add_argument(
        "--ref-n", type=int, default=None, help="members checked against the reference (512; quick 8)"
    )
    p.add_argument("--ref-rtol", type=float, default=1e-10, help="rtol of the adaptive Tsit5 reference")
    p.add_argument("--scipy-n", type=int, default=None, help="members for scipy (default 3; quick 1)")
    p.add_argument(
        "--scipy-methods",
        default="LSODA,RK45",
        help="solve_ivp methods (default LSODA,RK45)",
    )
    p.add_argument(
        "--scipy-rtol", default="1e-6,1e-4", help="scipy tolerances (comma-separated; atol = rtol/100)"
    )
    p.add_argument("--deriv-n", type=int, default=None, help="members for the sensitivities (default: all)")
    p.add_argument("--sweep-lanes", default=None, help="lane widths to time first, e.g. 64,128,256,512,1024")
    p.add_argument("--sweep-t1", type=float, default=0.5, help="horizon of the lane sweep [s] (default 0.5)")
    p.add_argument("--only-sweep", action="store_true", help="stop after the lane sweep")
    p.add_argument(
        "--adaptive-n", type=int, default=0, help="members for the adaptive Tsit5 comparison (0: none)"
    )
    p.add_argument("--half-step-check", action="store_true", help="also solve every member at dt/2")
    args = p.parse_args(argv)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    n = args.n or (64 if args.quick else 4096)
    t1 = args.t1 or (3.0 if args.quick else 25.0)
    ref_n = min(n, args.ref_n if args.ref_n is not None else (8 if args.quick else 512))
    scipy_n = args.scipy_n if args.scipy_n is not None else (1 if args.quick else 3)
    deriv_n = min(n, args.deriv_n if args.deriv_n is not None else n)  # default: the whole scan
    if ref_n < 1:
        p.error("--ref-n must be >= 1 (the accuracy check and the LSODA errors use the reference)")
    sc = jh.load_scenario("paper-4.2").replace(**{EPS: args.eps})
    mus = np.linspace(0.1, 0.6, n)
    solver = SOLVERS[args.solver]()
    kw = dict(
        observables=OBS,
        n_save=2,
        solver=solver,
        dt0=args.dt,
        fixed_step=True,
        lanes=args.lanes,
        max_steps=10**7,
    )
    rec = {
        "scenario": sc.name,
        "friction_law": f"RegularisedCoulomb, eps = {args.eps} m/s",
        "n": n,
        "t1": t1,
        "solver": f"{args.solver}, fixed step {args.dt} s",
        "lanes": args.lanes,
        "devices": [str(d) for d in jax.devices()],
        "load_average_at_start": os.getloadavg(),
        "command": [sys.executable, *sys.argv],
    }
    print(
        f"benchmark: {n} μ in [0.1, 0.6] of {sc.name} (ε = {args.eps} m/s), t1 = {t1:g} s, {args.solver} at "
        f"fixed dt = {args.dt * 1e3:g} ms, {args.lanes} lanes, {len(jax.devices())} device(s), load average "
        f"{os.getloadavg()[0]:.1f}",
        flush=True,
    )

    # 0. Lane widths, over a short horizon (every member takes the same steps, so the horizon only scales).
    if args.sweep_lanes:
        sweep = []
        for rep_ in range(2):  # a second pass: the first may still warm up caches; keep the best of both
            for lanes in (int(x) for x in args.sweep_lanes.split(",")):
                rs = scan(sc, {MU: mus}, args.sweep_t1, **{**kw, "lanes": lanes})
                ts_ = rs.attrs["timings_s"]
                us = 1e6 * ts_["compute"] / n / int(np.median(rs.num_accepted_steps))
                sweep.append(
                    {
                        "lanes": lanes,
                        "pass": rep_,
                        "us_per_step_per_trajectory": us,
                        "compile_s": ts_["compile"],
                    }
                )
        best = {}
        for x in sweep:
            best[x["lanes"]] = min(best.get(x["lanes"], np.inf), x["us_per_step_per_trajectory"])
        for lanes, us in best.items():
            print(f"  lanes {lanes:5d}: {us:.3f} us per step per trajectory (best of 2)", flush=True)
        rec["lane_sweep"] = {"t1": args.sweep_t1, "runs": sweep, "best_us_per_step_per_trajectory": best}
        if args.only_sweep:
            path = out / "benchmark_scan.json"
            path.write_text(json.dumps(rec, indent=1) + "\n")
            print(f"wrote {path}")
            return

    # 1. The scan.
    r = scan(sc, {MU: mus}, t1, progress=True, **kw)
    t = r.attrs["timings_s"]
    steps = int(np.median(r.num_accepted_steps))
    run = {
        "compile_s": t["compile"],
        "compute_s": t["compute"],
        "ms_per_trajectory": 1e3 * t["compute"] / n,
        "steps_per_trajectory": steps,
        "us_per_step_per_trajectory": 1e6 * t["compute"] / n / steps,
        "total_s": t["total"],
        "failed": int(np.sum(~r.ok)),
        "peak_rss_mb": peak_rss_mb(),
    }
    rec["scan"] = run
    print(
        f"  scan: compile {run['compile_s']:.1f} s, total {run['total_s']:.1f} s, "
        f"{run['ms_per_trajectory']:.2f} ms per trajectory "
        f"({steps} steps, {run['us_per_step_per_trajectory']:.3f} us per step per trajectory), failed "
        f"{run['failed']}, peak RSS {run['peak_rss_mb']:.0f} MB",
        flush=True,
    )
    pos = r["final_position"]

    # 1b. The previous default (adaptive Tsit5, lock-step groups of 16) on some of the members.
    if args.adaptive_n:
        sub = mus[np.linspace(0, n - 1, args.adaptive_n).round().astype(int)]
        ra = scan(
            sc, {MU: sub}, t1, observables=OBS, n_save=2, rtol=1e-6, atol=1e-8, lanes=16, max_steps=10**6
        )
        ta = ra.attrs["timings_s"]
        rec["adaptive_tsit5"] = {
            "members": int(sub.size),
            "ms_per_trajectory": 1e3 * ta["compute"] / sub.size,
            "steps_median": int(np.median(ra.num_accepted_steps)),
            "compile_s": ta["compile"],
            "ratio_to_fixed_step_scan": (ta["compute"] / sub.size) / (t["compute"] / n),
        }
        x = rec["adaptive_tsit5"]
        print(
            f"  adaptive Tsit5 rtol 1e-6, 16 lanes, {x['members']} members: {x['ms_per_trajectory']:.1f} ms "
            f"per trajectory ({x['steps_median']} steps median), "
            f"{x['ratio_to_fixed_step_scan']:.1f}x the fixed-step scan",
            flush=True,
        )

    # 2. Accuracy against the adaptive reference on evenly spaced members.
    idx = np.unique(np.linspace(0, n - 1, ref_n).round().astype(int))
    t0 = time.perf_counter()
    ref = scan(
        sc,
        {MU: mus[idx]},
        t1,
        observables=OBS,
        n_save=2,
        rtol=args.ref_rtol,
        atol=1e-2 * args.ref_rtol,
        lanes=8,
        max_steps=5_000_000,
    )
    ref_wall = time.perf_counter() - t0
    err = np.linalg.norm(pos[idx] - ref["final_position"], axis=-1)
    within = err < 0.01
    spread = []
    for i in idx:  # how far the scan's neighbours land from member i [m]
        nb = [j for j in (i - 1, i + 1) if 0 <= j < n]
        spread.append(max(float(np.linalg.norm(pos[j] - pos[i])) for j in nb))
    spread = np.asarray(spread)
    outliers = [
        {"mu": float(mus[i]), "error_cm": float(100 * e), "neighbour_spread_cm": float(100 * s)}
        for i, e, s in zip(idx, err, spread, strict=True)
        if e >= 0.01
    ]
    rec["accuracy"] = {
        "reference": f"Tsit5 adaptive, rtol {args.ref_rtol:g}, atol {1e-2 * args.ref_rtol:g}",
        "members": int(idx.size),
        "reference_wall_s": ref_wall,
        "reference_steps_median": int(np.median(ref.num_accepted_steps)),
        "reference_failed": int(np.sum(~ref.ok)),
        "fraction_within_1cm": float(np.mean(within)),
        "median_cm": float(100 * np.median(err)),
        "p95_cm": float(100 * np.quantile(err, 0.95)),
        "max_cm": float(100 * np.max(err)),
        "median_neighbour_spread_cm": float(100 * np.median(spread)),
        "outliers": outliers,
    }
    a = rec["accuracy"]
    print(
        f"  accuracy vs {a['reference']} on {a['members']} members: "
        f"{100 * a['fraction_within_1cm']:.1f} % within "
        f"1 cm, error median {a['median_cm']:.3g} cm, 95 % {a['p95_cm']:.3g} cm, max {a['max_cm']:.3g} cm "
        f"(reference {ref_wall:.0f} s, {a['reference_steps_median']} steps median)",
        flush=True,
    )
    for o in outliers:
        print(
            f"    μ = {o['mu']:.6f}: error {o['error_cm']:.2f} cm; scan neighbours "
            f"{o['neighbour_spread_cm']:.2f} cm "
            f"away (median over members {a['median_neighbour_spread_cm']:.3f} cm)",
            flush=True,
        )

    # 2b. Every member against the same scan at half the step.
    if args.half_step_check:
        rh = scan(sc, {MU: mus}, t1, **{**kw, "dt0": args.dt / 2})
        eh = np.linalg.norm(pos - rh["final_position"], axis=-1)
        bad = np.flatnonzero(eh >= 0.01)
        rec["half_step_check"] = {
            "dt_s": args.dt / 2,
            "fraction_within_1cm": float(np.mean(eh < 0.01)),
            "median_cm": float(100 * np.median(eh)),
            "max_cm": float(100 * np.max(eh)),
            "outliers": [{"mu": float(mus[i]), "difference_cm": float(100 * eh[i])} for i in bad],
        }
        h = rec["half_step_check"]
        print(
            f"  all {n} members vs the same scan at dt/2: "
            f"{100 * h['fraction_within_1cm']:.2f} % within 1 cm, "
            f"median {h['median_cm']:.3g} cm, max {h['max_cm']:.3g} cm"
            + (f"; off by > 1 cm at μ = {', '.join(f'{mus[i]:.5f}' for i in bad[:12])}" if bad.size else ""),
            flush=True,
        )

    # 3. scipy (LSODA, RK45) on the same vector field, for a few of the reference members.
    if scipy_n:
        per = t["compute"] / n
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
                            "scan_error_cm": float(100 * err[k]),
                            "ratio_to_scan": wall / per,
                        }
                    )
                    print(
                        f"  {method} rtol {tol:g}, μ = {mu:.4f}: {wall:.2f} s, {nfev} f-evals, "
                        f"error {100 * e:.3g} cm "
                        f"(scan {100 * err[k]:.3g} cm); {wall / per:.0f}x the scan's time per trajectory",
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

    # 4. Forward sensitivities vs the plain scan of the same members.
    if deriv_n:
        sub = mus[np.linspace(0, n - 1, deriv_n).round().astype(int)]
        plain = r if deriv_n == n else scan(sc, {MU: sub}, t1, **kw)  # the whole scan: its own timing
        der = scan(sc, {MU: sub}, t1, derivatives=True, progress=True, **kw)
        tp, td = plain.attrs["timings_s"], der.attrs["timings_s"]
        same = float(np.max(np.abs(der["final_position"] - plain["final_position"])))
        rec["derivatives"] = {
            "members": deriv_n,
            "plain_ms_per_trajectory": 1e3 * tp["compute"] / deriv_n,
            "forward_ms_per_trajectory": 1e3 * td["compute"] / deriv_n,
            "ratio": td["compute"] / tp["compute"],
            "compile_plain_s": tp["compile"],
            "compile_forward_s": td["compile"],
            "failed": int(np.sum(~der.ok)),
            "max_difference_of_values_m": same,
        }
        d = rec["derivatives"]
        print(
            f"  forward sensitivities: {d['forward_ms_per_trajectory']:.2f} vs plain "
            f"{d['plain_ms_per_trajectory']:.2f}"
            f" ms per trajectory ({d['ratio']:.2f}x), compile {d['compile_forward_s']:.1f} s",
            flush=True,
        )

    rec["load_average_at_end"] = os.getloadavg()
    rec["peak_rss_mb"] = peak_rss_mb()
    path = out / "benchmark_scan.json"
    path.write_text(json.dumps(rec, indent=1) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
