"""Bifurcation map of paper-4.2 in the friction coefficient μ (the paper's §4.3, Figs 10-12).

1. scan μ over [0.1, 0.6] (4000 points, 2501 saved times; resumable: the chunks go to DIR/scan-s2501) and
   record final position and Euler angles, maximum tilt, lift-off time, the corner that leaves first and
   the impact count;
2. find candidate jumps of every observable on the grid (`find_jumps`);
3. refine every candidate jump of the lift-off time, final position and Euler angles, maximum tilt and the
   impact count (one per grid cell) to |Δμ| <= 1e-6, value-only bisection by default (a candidate
   that is not a discontinuity comes out as a "crossing"); and the level crossing in the cell where ψ(t1)
   changes most steeply (a steep ramp need not be a jump);
4. plot every observable against μ with its located μ* marked, a zoom and the time histories x, y, φ, ϑ, ψ
   across the steepest change of ψ (μ* ± 0.25e-3, ± 2.5e-3: the Figs 10-12 analogue) and across the
   located jumps with the highest scores (`--detail`);
5. continue the highest-scoring jump along the hoist speed v_l (μ*(v_l), by continuation).

    python experiments/figures/bifurcation_mu.py --out out/bifurcation-mu            # full: 4000 μ over 25 s
    python experiments/figures/bifurcation_mu.py --out out/bifurcation-mu --quick    # 48 μ over 4 s, tol 1e-4

Writes DIR/bifurcation_mu.json (jumps, located μ*, solves used vs a uniform grid, timings; rewritten after
every stage, so an interrupted run leaves what it had) and PNGs. The scan resumes from its chunks if the
command is rerun.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import diffrax  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import BifurcationError, find_jumps, locate_bifurcation, scan, trace_boundary  # noqa: E402

MU = "foundation.friction_coefficient"
#: The search method of each `--method` name.
METHODS = {"newton": jh.Newton, "bisection": jh.Bisection, "multisection": jh.Multisection}
OBSERVABLES = [
    "final_x",
    "final_y",
    "final_phi",
    "final_theta",
    "final_psi",
    "max_tilt",
    "liftoff_time",
    "first_corner",
    "impacts",
]
LABELS = {
    "final_x": ("x(t1)", "m", 1.0),
    "final_y": ("y(t1)", "m", 1.0),
    "final_phi": ("φ(t1)", "deg", 180 / np.pi),
    "final_theta": ("ϑ(t1)", "deg", 180 / np.pi),
    "final_psi": ("ψ(t1)", "deg", 180 / np.pi),
    "max_tilt": ("max tilt", "deg", 180 / np.pi),
    "liftoff_time": ("lift-off time", "s", 1.0),
    "first_corner": ("first corner off (0=D,1=E,2=F,3=H)", "-", 1.0),
    "impacts": ("corner impacts", "-", 1.0),
}


def _scan_kw(kw: dict, t1: float, lanes: int | None, sort: bool = True) -> dict:
    """`scan`'s objects for the solver keywords `kw` (n_save, rtol, atol) that the locator takes, to `t1`
    [s]."""
    options = jh.SolverOptions(rtol=kw["rtol"], atol=kw["atol"])
    times = jh.Times(t1, n=kw["n_save"])
    return dict(times=times, options=options, batch=jh.BatchOptions(lanes=lanes, sort=sort))


def _plot_observables(sc, mus, res, jumps, located, ramp, out, t1):
    """Every observable against μ; in each panel the μ* located in a grid cell where that observable had a
    candidate jump (one cell may hold the jumps of several observables, located once: the lift-off-time jump
    is also a change of the impact count), red for a jump, grey for a continuous crossing."""
    n = mus.size
    fig, axes = plt.subplots(3, 3, figsize=(13, 9), sharex=True)
    for ax, name in zip(axes.ravel(), OBSERVABLES, strict=True):
        label, unit, scale = LABELS[name]
        ax.plot(mus, res[name] * scale, ".", ms=2 if n > 500 else 4)
        bad = ~res.ok
        if bad.any():
            ax.plot(mus[bad], np.zeros(bad.sum()), "rx", ms=4, label="failed")
        for b in located:
            if b.observable == name or any(j.lo <= b.value <= j.hi for j in jumps.get(name, [])):
                ax.axvline(b.value, color="C3" if b.kind == "jump" else "0.6", lw=0.6, alpha=0.7)
        ax.axvline(ramp.value, color="C2", lw=0.8, ls="--")
        ax.set_ylabel(f"{label} [{unit}]")
    for ax in axes[-1]:
        ax.set_xlabel("friction coefficient μ [-]")
    fig.suptitle(
        f"{sc.name}: outcome of the lift against μ ({n} values, t1 = {t1:g} s)\nin each panel the value "
        f"located where it jumps: red = jump, grey = continuous crossing; green dashed: steepest change of ψ"
    )
    fig.tight_layout()
    fig.savefig(out / "observables_vs_mu.png", dpi=110)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True)
    p.add_argument("--quick", action="store_true", help="48 μ over 4 s, tolerance 1e-4: a smoke run")
    p.add_argument("--n", type=int, default=None, help="μ values in the scan (default 4000; quick 48)")
    p.add_argument("--t1", type=float, default=None, help="horizon [s] (default 25; quick 4)")
    p.add_argument(
        "--n-save",
        type=int,
        default=None,
        help="saved times (default 2501, every 10 ms: event times such as lift-off are read on this grid, "
        "and "
        "a 0.1 s grid misses corner hops shorter than 0.1 s; quick 101)",
    )
    p.add_argument(
        "--tol", type=float, default=None, help="|Δμ| of the located μ* (default 1e-6; quick 1e-4)"
    )
    p.add_argument(
        "--jumps",
        type=int,
        default=None,
        help="how many candidate jumps to refine, highest score first (default: every one; quick 1)",
    )
    p.add_argument(
        "--detail",
        type=int,
        default=3,
        help="zooms and histories for the steepest change of ψ and the N - 1 highest-scoring jumps "
        "(3; 0: none)",
    )
    p.add_argument(
        "--method",
        choices=("bisection", "multisection", "newton"),
        default="bisection",
        help="locator (default bisection: ~log2(Δμ/tol)+2 value-only solves per jump)",
    )
    p.add_argument(
        "--refine",
        default="liftoff_time,final_psi,final_x,final_y,final_phi,final_theta,max_tilt,impacts",
        help="observables whose candidate jumps are refined (comma-separated)",
    )
    p.add_argument(
        "--refine-n-save",
        type=int,
        default=None,
        help="saved times in the refining solves (default: as the scan)",
    )
    p.add_argument("--lanes", type=int, default=16)
    p.add_argument(
        "--trace",
        default=None,
        help="hoist speeds v_l [m/s] along which to continue the first located μ*, as start:stop:num "
        "(default 0.26:0.34:9; quick 0.3:0.31:2; 'none' to skip)",
    )
    p.add_argument(
        "--replot",
        action="store_true",
        help="no refinement: redraw observables_vs_mu.png from DIR/bifurcation_mu.json and the scan's chunks",
    )
    p.add_argument("--rtol", type=float, default=1e-6)
    p.add_argument("--atol", type=float, default=1e-8)
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    q = args.quick
    n = args.n or (48 if q else 4000)
    t1 = args.t1 or (4.0 if q else 25.0)
    n_save = args.n_save or (101 if q else 2501)
    tol = args.tol or (1e-4 if q else 1e-6)
    n_jumps = args.jumps if args.jumps is not None else (1 if q else None)
    wall_start = time.perf_counter()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = jh.load_scenario("paper-4.2")
    solve_kw = dict(n_save=n_save, rtol=args.rtol, atol=args.atol)
    locator_options = jh.SolverOptions(
        diffrax.Tsit5(), rtol=args.rtol, atol=args.atol
    )  # the locator's solver
    rec: dict = {
        "scenario": sc.name,
        "n": n,
        "t1": t1,
        "n_save": n_save,
        "tol": tol,
        "quick": q,
        "command": [sys.executable, *sys.argv],
        "devices": [str(d) for d in jax.devices()],
    }
    path = out / "bifurcation_mu.json"
    previous = json.loads(path.read_text()) if args.replot else None  # before this run rewrites it

    def write(stage):
        rec["stage"] = stage
        rec["wall_total_s"] = time.perf_counter() - wall_start
        path.write_text(json.dumps(rec, indent=1, default=float) + "\n")

    # 1. the scan
    mus = np.linspace(0.1, 0.6, n)
    t0 = time.perf_counter()
    res = scan(
        sc,
        {MU: mus},
        observables=OBSERVABLES,
        out_dir=out / f"scan-s{n_save}",
        progress=True,
        **_scan_kw(solve_kw, t1, args.lanes),
    )
    rec["scan"] = {
        "wall_s": time.perf_counter() - t0,
        **res.attrs["timings_s"],
        "failed": res.failures()[:20],
        "n_failed": int(np.sum(~res.ok)),
        "steps_median": int(np.median(res.num_accepted_steps)),
        "steps_max": int(res.num_accepted_steps.max()),
    }
    print(
        f"scan: {n} μ in {rec['scan']['wall_s']:.1f} s ({res.attrs['timings_s']['compile']:.1f} s compile), "
        f"{rec['scan']['n_failed']} failed",
        flush=True,
    )

    write("scan")

    # 2. candidate jumps
    jumps = {name: find_jumps(res, name) for name in OBSERVABLES}
    rec["candidate_jumps"] = {k: [vars(j) for j in v] for k, v in jumps.items()}
    for k, v in jumps.items():
        print(f"  {k}: {len(v)} candidate jumps", flush=True)
    if args.replot:
        import types

        located = [types.SimpleNamespace(**b) for b in previous["located"]]
        ramp = types.SimpleNamespace(**previous["steepest_psi"])
        _plot_observables(sc, mus, res, jumps, located, ramp, out, t1)
        path.write_text(json.dumps(previous, indent=1, default=float) + "\n")  # as it was
        print(f"redrew {out / 'observables_vs_mu.png'} with {len(located)} located values")
        return

    # 3. refine every candidate jump of the continuous observables (event counts and the first corner are
    #    read on the saved grid and are not refined), one per grid cell: where several observables jump in
    #    the same cells, the one with the highest score is refined. The refinement saves `--refine-n-save`
    #    times, finer than the scan: a jump that only the coarse grid produced comes out as a "crossing".
    refine_obs = [o for o in args.refine.split(",") if o]
    cands = sorted(
        (j for o in refine_obs for j in jumps[o]),
        key=lambda j: -j.score if np.isfinite(j.score) else -np.inf,
    )
    chosen: list = []
    for j in cands:
        if all(j.hi <= c.lo or j.lo >= c.hi for c in chosen):  # cells may share an end
            chosen.append(j)
    chosen = chosen[:n_jumps]
    refine_n_save = args.refine_n_save or n_save
    refine_kw = dict(solve_kw, n_save=refine_n_save)
    located = []
    score_of: dict = {}
    not_refined = []
    t0 = time.perf_counter()
    for k, j in enumerate(chosen):
        try:
            b = locate_bifurcation(
                sc,
                MU,
                j.observable,
                (j.lo, j.hi),
                # multisection: 16 points per round, 16 lanes
                search=jh.SearchOptions(METHODS[args.method](), tol),
                options=locator_options,
                times=jh.Times(t1, n=refine_n_save),
            )
        except BifurcationError as e:
            print(f"  {j.observable} jump at μ in [{j.lo:.6f}, {j.hi:.6f}]: not refined ({e})", flush=True)
            not_refined.append(
                {"observable": j.observable, "lo": j.lo, "hi": j.hi, "size": j.size, "reason": str(e)}
            )
            continue
        located.append(b)
        score_of[id(b)] = j.score
        print(f"  [{k + 1}/{len(chosen)}] " + b.summary(), flush=True)
        if (k + 1) % 5 == 0:
            rec["located"] = [b.to_dict() for b in located]
            write(f"locate {k + 1}/{len(chosen)}")
    rec["located"] = [b.to_dict() for b in located]
    rec["not_refined"] = not_refined

    # 3b. the steepest change of ψ on the grid (a steep ramp need not be a jump): its level crossing
    psi = np.asarray(res["final_psi"])
    steep = int(np.nanargmax(np.abs(np.diff(psi))))
    ramp = locate_bifurcation(
        sc,
        MU,
        "final_psi",
        (mus[steep], mus[steep + 1]),
        search=jh.SearchOptions(METHODS[args.method](), tol),
        options=locator_options,
        times=jh.Times(t1, n=refine_n_save),
    )
    slope = np.abs(np.diff(psi)) / np.diff(mus)
    big = slope > 0.5 * slope[steep]
    rec["steepest_psi"] = {
        **ramp.to_dict(),
        "max_slope_rad_per_unit_mu": float(slope[steep]),
        "median_slope_rad_per_unit_mu": float(np.median(slope)),
        "cells_above_half_max_slope": int(big.sum()),
        "psi_deg_at": {
            f"{m:.4f}": float(np.degrees(np.interp(m, mus, psi))) for m in (0.450, 0.452, 0.457, 0.460)
        },
    }
    print("  steepest ψ: " + ramp.summary(), flush=True)
    rec["locate_summary"] = {
        "observables": refine_obs,
        "n_candidates": {o: len(jumps[o]) for o in refine_obs},
        "n_refined": len(chosen),
        "n_located": len(located),
        "n_jump": sum(b.kind == "jump" for b in located),
        "n_crossing": sum(b.kind == "crossing" for b in located),
        "solves": int(sum(b.n_solves for b in located)),
        "uniform_grid_solves": int(sum(b.n_uniform for b in located)),
        "refine_n_save": refine_n_save,
        "wall_s": time.perf_counter() - t0,
    }
    print(f"  locate: {rec['locate_summary']}", flush=True)
    write("located")

    # 4a. observables against μ, with the located μ* marked
    _plot_observables(sc, mus, res, jumps, located, ramp, out, t1)

    # 4b. zoom around each μ* and 4c. histories across it (Figs 10-12 analogue): the steepest change of ψ
    #     and the located jumps with the highest scores
    ranked = sorted((b for b in located if b.kind == "jump"), key=lambda b: -score_of[id(b)])
    detail = ([ramp] + ranked[: args.detail - 1]) if args.detail > 0 else []
    rec["detail"] = [{"mu_star": b.value, "observable": b.observable, "kind": b.kind} for b in detail]
    for i, b in enumerate(detail):
        lo, hi = b.bracket
        name = b.observable
        label, unit, scale = LABELS.get(name, (name, "", 1.0))
        is_ramp = b is ramp
        half = 4e-3 if is_ramp else max(50 * tol, 20 * (hi - lo))
        zoom = scan(
            sc,
            {MU: np.linspace(b.value - half, b.value + half, 32)},
            # quick: every observable, as the scan of step 1 (the same saved times and lanes), whose compiled
            # program the zooms then share; the full run: the one observable
            observables=OBSERVABLES if q else [name],
            **_scan_kw(refine_kw, t1, 16),
        )
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(zoom.coords[MU], zoom[name] * scale, "o-", ms=3)
        ax.axvline(b.value, color="C3", lw=0.8)
        ax.set_xlabel("μ [-]")
        ax.set_ylabel(f"{label} [{unit}]")
        ax.set_title(f"zoom around μ = {b.value:.7f} ({b.kind}; bracket width {b.width:.1e})")
        fig.tight_layout()
        fig.savefig(out / f"zoom_{i}.png", dpi=110)
        plt.close(fig)

        d = 2.5e-4 if is_ramp else max(2 * tol, b.width)
        across = np.array([b.value - 10 * d, b.value - d, b.value + d, b.value + 10 * d])
        hist = scan(
            sc,
            {MU: across},
            observables=["final_psi"],
            histories=("position", "euler"),
            **_scan_kw(solve_kw, t1, 4, sort=False),
        )
        ts = hist.ts
        fig, axes = plt.subplots(5, 1, figsize=(8, 11), sharex=True)
        series = [
            ("x", hist["position"][..., 0], "m", 1.0),
            ("y", hist["position"][..., 1], "m", 1.0),
            ("φ", hist["euler"][..., 0], "deg", 180 / np.pi),
            ("ϑ", hist["euler"][..., 2], "deg", 180 / np.pi),
            ("ψ", hist["euler"][..., 1], "deg", 180 / np.pi),
        ]
        for ax, (sym, val, unit, scale) in zip(axes, series, strict=True):
            for k, mu in enumerate(across):
                side = "below" if mu < b.value else "above"
                ax.plot(
                    ts,
                    val[k] * scale,
                    lw=1.0,
                    ls="-" if side == "below" else "--",
                    label=f"μ = {mu:.7f} ({side} it)",
                )
            ax.set_ylabel(f"{sym} [{unit}]")
        axes[0].legend(fontsize=7)
        axes[-1].set_xlabel("t [s]")
        fig.suptitle(
            f"{sc.name}: histories across μ = {b.value:.7f} ({name}, {b.kind}; cf. the paper's Figs 10-12)"
        )
        fig.tight_layout()
        fig.savefig(out / f"histories_across_mu_star_{i}.png", dpi=110)
        plt.close(fig)

    # 5. the boundary μ*(v_l) by continuation from the first located μ* (predictor + 1-D corrector)
    trace_spec = args.trace or ("0.3:0.31:2" if q else "0.26:0.34:9")
    if located and trace_spec != "none":
        a_, b_, k_ = trace_spec.split(":")
        speeds = np.linspace(float(a_), float(b_), int(k_))
        v0 = float(sc.hoist.speed)
        speeds = np.concatenate([[v0], speeds[~np.isclose(speeds, v0, rtol=0, atol=1e-12)]])  # start at μ*
        b0 = (ranked or located)[0]
        t0 = time.perf_counter()
        tr = trace_boundary(
            sc,
            MU,
            b0.bracket,
            "hoist.speed",
            speeds,
            b0.observable,
            search=jh.SearchOptions(jh.Bisection(), tol, initial_half_width=max(10 * tol, 0.002)),
            options=locator_options,
            times=jh.Times(t1, n=n_save),
        )
        rec["trace"] = {
            "observable": b0.observable,
            "hoist_speed": tr.along_values.tolist(),
            "mu_star": tr.values.tolist(),
            "widths": tr.widths.tolist(),
            "n_solves": tr.n_solves,
            "n_dense": tr.n_dense,
            "wall_s": time.perf_counter() - t0,
        }
        print(
            f"  boundary μ*(v_l): {np.round(tr.values, 7).tolist()} at v_l = {speeds.tolist()} m/s; "
            f"{tr.n_solves} solves vs {tr.n_dense} for a dense grid",
            flush=True,
        )
        order = np.argsort(tr.along_values)
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.plot(tr.along_values[order], tr.values[order], "o-")
        ax.set_xlabel("hoist speed v_l [m/s]")
        ax.set_ylabel("μ* [-]")
        ax.set_title("boundary traced by continuation (NaN: the corrector lost it)")
        fig.tight_layout()
        fig.savefig(out / "boundary_mu_vl.png", dpi=110)
        plt.close(fig)

    write("done")
    print(f"wrote {path} and PNGs in {out} ({rec['wall_total_s']:.0f} s in all)")


if __name__ == "__main__":
    main()
