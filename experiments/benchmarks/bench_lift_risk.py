"""Wall time of a lift-risk map of the paper's §4.2 container (`jaxhoist.lift_risk` with defaults): a grid of
boom-tip positions (x, y) times a sample of the uncertain inputs μ ~ U(0.2, 0.5), ξ_C ~ N(1.0 m, 0.1 m), one
solve per (tip, sample) pair; optionally the map's estimates against brute-force Monte Carlo of 10x the
samples at a few tips.

    python experiments/benchmarks/bench_lift_risk.py                    # 16 x 16 tips x 512 samples, 25 s
    python experiments/benchmarks/bench_lift_risk.py --nx 4 --ny 4 --samples 32        # a small size
    python experiments/benchmarks/bench_lift_risk.py --brute-force 4    # + plain MC of 10x at 4 tips
    python experiments/benchmarks/bench_lift_risk.py --quick --out out/bench-lift-risk # smoke check

The full size is 16 x 16 x 512 = 131 072 solves over 25 s. The time includes compilation (the first call in
the process; `--repeat` times a second call too) and is printed with the solves per second and the time per
solve, so that a run at a small size extrapolates to the full one (per-solve time grows little with the
size once the chunks are full). The machine may be shared: the load average is printed with the numbers.

Hazards (as in experiments/figures/lift_planning.py, with the built-in tilt): slide > 0.5 m, tilt > 70°,
a corner strike, and a peak rope tension above 1.2 m g.

`--brute-force K`: at K tips of the grid (spread along its diagonal), `jaxhoist.scan` solves 10 x `--samples`
independent random draws of (μ, ξ_C) (plain Monte Carlo), and each hazard's share there is compared with the
map's estimate: whether it lies in the map's confidence interval, and whether the two differ by less than
their combined 95 % half-widths (the map's interval half-width and the binomial one of the plain sample).

Writes `bench_lift_risk.json` into --out (the settings, times, solve counts and the comparison).
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
jax.config.update("jax_num_cpu_devices", os.cpu_count())  # every core a device, as in the README's set-up

import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

TIP_X, TIP_Y = "boom.tip_position[0]", "boom.tip_position[1]"
MU, XI = "foundation.friction_coefficient", "load.mass_centre[0]"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--nx", type=int, default=16, help="tips along x, 0 to 4 m (default 16)")
    p.add_argument("--ny", type=int, default=16, help="tips along y, 0 to 6 m (default 16)")
    p.add_argument("--samples", type=int, default=512, help="samples per tip (default 512)")
    p.add_argument("--replicates", type=int, default=8, help="RQMC scrambles (default 8)")
    p.add_argument("--t1", type=float, default=25.0, help="end time [s] (default 25)")
    p.add_argument("--brute-force", type=int, default=0, metavar="K", help="plain MC of 10x at K tips")
    p.add_argument("--repeat", action="store_true", help="time a second call too (compiled)")
    p.add_argument("--quick", action="store_true", help="2 x 2 tips x 16 samples over 2 s, brute force at 1")
    p.add_argument("--out", default=None, help="folder for bench_lift_risk.json")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
        args.nx, args.ny, args.samples, args.replicates, args.t1 = 2, 2, 16, 4, 2.0
        args.brute_force = max(args.brute_force, 1)

    sc = jh.load_scenario("paper-4.2")
    weight = float(sc.load.mass) * float(sc.gravity)
    uncertain = {MU: jh.Uniform(0.2, 0.5), XI: jh.Normal(1.0, 0.1)}
    hazards = [jh.slide(0.5), jh.tilt(degrees=70.0), jh.strike(), jh.overload(1.2 * weight)]
    xs, ys = np.linspace(0.0, 4.0, args.nx), np.linspace(0.0, 6.0, args.ny)
    times = jh.Times(args.t1)
    # quick: the map and the plain Monte Carlo in groups of 16 lanes, so that they share one compiled program
    batch = jh.BatchOptions(lanes=16) if args.quick else None
    n_solves = args.nx * args.ny * args.samples
    print(
        f"lift_risk: paper-4.2, {args.nx} x {args.ny} tips x {args.samples} samples = {n_solves} solves over "
        f"{args.t1:g} s; {os.cpu_count()} CPUs, devices {jax.devices()}",
        file=sys.stderr,
    )

    def run():
        t0 = time.perf_counter()
        r = jh.lift_risk(
            sc,
            uncertain,
            hazards,
            jh.Grid({TIP_X: xs, TIP_Y: ys}),
            samples=args.samples,
            replicates=args.replicates,
            times=times,
            seed=0,
            progress=True,
            batch=batch,
        )
        return r, time.perf_counter() - t0

    risk, wall = run()
    report: dict = {
        "settings": vars(args) | {"solves": n_solves},
        "first_call_s": round(wall, 2),
        "solves_per_s": round(n_solves / wall, 2),
        "ms_per_solve": round(1e3 * wall / n_solves, 3),
        "failed": int(np.sum(risk.n_failed)),
        "max_accepted_steps": int(np.max(risk.scan.num_accepted_steps)),
        "load_average": os.getloadavg(),
        "devices": [str(d) for d in jax.devices()],
    }
    print(
        f"first call (with compilation): {wall:.1f} s, {n_solves / wall:.1f} solves/s, "
        f"{1e3 * wall / n_solves:.2f} ms per solve; {report['failed']} failed; load average "
        f"{report['load_average'][0]:.1f}"
    )
    if args.repeat:
        _, wall2 = run()
        report |= {"second_call_s": round(wall2, 2), "second_ms_per_solve": round(1e3 * wall2 / n_solves, 3)}
        per = 1e3 * wall2 / n_solves
        print(f"second call: {wall2:.1f} s, {n_solves / wall2:.1f} solves/s, {per:.2f} ms per solve")
    print(risk.summary())

    if args.brute_force:
        report["brute_force"] = brute_force(sc, risk, hazards, uncertain, xs, ys, times, args, batch)

    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "bench_lift_risk.json").write_text(json.dumps(report, indent=2, default=float) + "\n")
        print(f"wrote {out}/bench_lift_risk.json", file=sys.stderr)
    return 0


def brute_force(sc, risk, hazards, uncertain, xs, ys, times, args, batch=None) -> dict:
    """Plain Monte Carlo of 10 x samples independent draws at K tips along the grid's diagonal, against the
    map's estimates and intervals there."""
    k = min(args.brute_force, min(len(xs), len(ys)))
    idx = [
        (int(round(i * (len(xs) - 1) / max(k - 1, 1))), int(round(i * (len(ys) - 1) / max(k - 1, 1))))
        for i in range(k)
    ]
    n = 10 * args.samples
    rng = np.random.default_rng(12345)
    draws = {p: d.ppf(rng.uniform(size=n)) for p, d in uncertain.items()}
    cols = {
        TIP_X: np.repeat([xs[i] for i, _ in idx], n),
        TIP_Y: np.repeat([ys[j] for _, j in idx], n),
        **{p: np.tile(v, k) for p, v in draws.items()},
    }
    obs = {h.observable_name: h.observable for h in hazards}
    t0 = time.perf_counter()
    mc = jh.scan(sc, jh.Points(cols), times, observables=obs, progress=True, batch=batch)
    wall = time.perf_counter() - t0
    ok = np.asarray(mc.ok).reshape(k, n)
    rows, inside, within = [], 0, 0
    for h in hazards:
        v = np.asarray(mc[h.observable_name]).reshape(k, n)
        hit = (v > h.threshold) if h.above else (v < h.threshold)
        p_map, (lo, hi) = risk.probability(h), risk.interval(h)
        for m, (i, j) in enumerate(idx):
            n_ok = int(ok[m].sum())
            p_mc = float(hit[m][ok[m]].mean())
            half_mc = 1.96 * np.sqrt(max(p_mc * (1 - p_mc), 1.0 / n_ok) / n_ok)
            pm, a, b = float(p_map[i, j]), float(lo[i, j]), float(hi[i, j])
            half_map = max(b - pm, pm - a, 0.0)
            in_interval = a <= p_mc <= b
            agree = abs(pm - p_mc) <= np.hypot(half_map, half_mc) + 1e-12
            inside += in_interval
            within += agree
            rows.append(
                dict(hazard=h.name, tip=[float(xs[i]), float(ys[j])], p_map=pm, interval=[a, b], p_mc=p_mc,
                     mc_half_width=half_mc, mc_solved=n_ok, in_interval=bool(in_interval), agree=bool(agree))
            )  # fmt: skip
            print(
                f"  {h.name:9s} tip ({xs[i]:.2f}, {ys[j]:.2f}) m: map {pm:.4f} [{a:.4f}, {b:.4f}]  plain MC "
                f"{p_mc:.4f} ± {half_mc:.4f}  {'in' if in_interval else 'OUT of'} the interval, "
                f"{'agree' if agree else 'DISAGREE'}"
            )
    print(
        f"brute force: {k} tips x {n} draws = {k * n} solves in {wall:.1f} s; {inside}/{len(rows)} inside "
        f"the map's interval, {within}/{len(rows)} within the combined 95 % half-widths"
    )
    return dict(solves=k * n, wall_s=round(wall, 2), inside=inside, agree=within, total=len(rows), rows=rows)


if __name__ == "__main__":
    sys.exit(main())
