"""Two-parameter regime map of paper-4.2 in (μ, v_l) with its boundary traced by continuation.

**The boundary.** paper-4.2 is pulled at the top corner above D: D and then H leave the ground. Whether
corner E then also hops off briefly (a fraction of a millimetre, ending in an impact) or stays down until
the load tips, seconds later, depends on μ and on the hoist speed v_l
(`experiments/figures/bifurcation_eps.py` locates it along μ at v_l = 0.3 m/s and follows it in ε). The
indicator is the built-in observable

    g(μ, v_l) = contact_margin[E] = min over t in [0, t1] of f_E(t) / k    [m]

(E's contact function over the foundation stiffness): g > 0 if E stays on the ground throughout, g <= 0 if
it leaves; continuous in both parameters, so its zero set is the regime boundary and Newton steps on
forward-mode slopes converge on it. t1 = 0.6 s (saved every 0.1 ms) holds the hop at every speed of the
map (it happens at ~0.2 s at v_l = 0.42 m/s and ~0.4 s at 0.2 m/s) and ends long before the load tips.

**What the script does.**
1. a grid scan of g over (μ, v_l), the map (one compiled, vmapped call; resumable from DIR/scan);
2. μ*(v_l) by continuation (`trace_boundary`, secant predictor + safeguarded Newton corrector, to
   |Δμ| <= 1e-6), from the grid's sign change in the row nearest 0.3 m/s up and down in v_l, at the grid's
   speeds, so that each traced point can be checked against its row of the map;
3. the check: in each row, every grid cell below the traced μ* must have g > 0 and every one above it g <= 0;
   and the solves the trace used against a dense grid at the same resolution;
4. the same boundary point located in other parameters (v_l, k, c_l, ξ_C): at μ = μ*(0.3 m/s) the boundary
   must pass through the preset's value of each, within the error that μ*'s bracket implies there;
5. the picture: g over (μ, v_l) with the grid's zero contour and the traced points.

    python experiments/figures/regime_map.py --out out/regime-map            # ~2-3 min on 2 shared cores
    python experiments/figures/regime_map.py --out out/regime-map --quick    # 11 x 5 grid, 1 other parameter

Writes DIR/regime_map.json (every number), DIR/regime_map.npz (the grid), DIR/regime_map.png.
(The script's earlier version mapped the lift-off time around the 25 s lift-off jump μ* = 0.4721707; that
jump does not persist in v_l, see docs/bifurcation.md.)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import BifurcationError, get_param, locate_bifurcation, set_param, trace_boundary  # noqa: E402

MU, VL = "foundation.friction_coefficient", "hoist.speed"
MARGIN = "contact_margin[E]"
# Other parameters to cross the boundary in, at the traced point (μ*, v_l nearest 0.3 m/s): (path, relative
# half-width of the bracket around the preset's value)
OTHERS = [
    ("hoist.speed", 0.05),
    ("foundation.stiffness", 0.2),
    ("rope.stiffness", 0.2),
    ("load.mass_centre[0]", 0.05),
]


def _slope(b):
    """dg/dp at the evaluation nearest the located value (forward-mode, from the Newton history)."""
    h = [e for e in b.history if e[2] is not None and np.isfinite(e[2])]
    return min(h, key=lambda e: abs(e[0] - b.value))[2] if h else float("nan")


def _sign_changes(g):
    """Indices k with g[k] and g[k + 1] on opposite sides of 0 (g[k] > 0 >= g[k + 1] or the reverse)."""
    pos = g > 0.0
    return np.nonzero(pos[:-1] != pos[1:])[0]


def _trace(sc, bracket, speeds, kw):
    tr = trace_boundary(sc, MU, bracket, VL, speeds, MARGIN, level=0.0, **kw)
    rows = [{"hoist_speed": r["along_value"], "mu_star": r["value"], **r} for r in tr.rows()]
    for r in rows:
        print(f"  v_l = {r['hoist_speed']:.4f} m/s: μ* = {r['mu_star']!r}", flush=True)
    return rows, tr


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True)
    p.add_argument(
        "--quick",
        action="store_true",
        help="11 x 5 grid (the trace at the same 5 speeds), step 4 in the first other parameter only",
    )
    p.add_argument("--n-mu", type=int, default=None, help="μ values of the grid in [0.1, 0.6] (default 101)")
    p.add_argument("--n-v", type=int, default=None, help="speeds of the grid in [0.2, 0.42] m/s (default 23)")
    p.add_argument("--t1", type=float, default=0.6, help="horizon [s] (default 0.6)")
    p.add_argument("--dt-save", type=float, default=1e-4, help="spacing of the saved times [s]")
    p.add_argument("--tol", type=float, default=1e-6, help="|Δμ| of the traced points (default 1e-6)")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    n_mu = args.n_mu or (11 if args.quick else 101)
    n_v = args.n_v or (5 if args.quick else 23)
    mus = np.linspace(0.1, 0.6, n_mu)
    speeds = np.linspace(0.2, 0.42, n_v)
    ts = np.linspace(0.0, args.t1, int(round(args.t1 / args.dt_save)) + 1)
    kw = dict(ts=ts, rtol=1e-8, atol=1e-10, max_steps=400_000)
    # the locator's solves: Tsit5 (its default solver) at the same tolerances
    lkw = dict(
        times=jh.Times(ts=ts),
        options=jh.SolverOptions(diffrax.Tsit5(), rtol=1e-8, atol=1e-10, max_steps=400_000),
    )
    sc = jh.load_scenario("paper-4.2")
    rec: dict = {
        "scenario": sc.name,
        "command": [sys.executable, *sys.argv],
        "indicator": "g = contact_margin[E] = min_{t in [0, t1]} f_E(t) / k [m]; > 0: E stays on the "
        "ground, <= 0: it hops; level 0",
        "t1": args.t1,
        "n_save": ts.size,
        "rtol": kw["rtol"],
        "atol": kw["atol"],
        "tol": args.tol,
        "devices": [str(d) for d in jax.devices()],
    }

    # 1. the map
    t0 = time.perf_counter()
    res = jh.scan(
        sc,
        jh.Grid({MU: mus, VL: speeds}),
        observables={"g": MARGIN, "t_detach_E": "detachment_times[E]"},
        out_dir=out / "scan",
        progress=True,
        times=jh.Times(ts=ts),
        options=jh.SolverOptions(rtol=kw["rtol"], atol=kw["atol"], max_steps=kw["max_steps"]),
    )
    g = np.asarray(res["g"])  # (n_mu, n_v)
    np.savez(
        out / "regime_map.npz",
        mu=mus,
        hoist_speed=speeds,
        g=g,
        t_detach_E=np.asarray(res["t_detach_E"]),
        status=res.status,
    )
    rec["grid"] = {
        "n_mu": n_mu,
        "n_v": n_v,
        "n_failed": int(np.sum(~res.ok)),
        "wall_s": time.perf_counter() - t0,
        "timings_s": res.attrs["timings_s"],
    }
    print(f"grid {n_mu} x {n_v}: {rec['grid']['n_failed']} failed, {rec['grid']['wall_s']:.0f} s", flush=True)

    # 2. the boundary by continuation, from the row nearest 0.3 m/s outwards
    j0 = int(np.argmin(np.abs(speeds - 0.3)))
    ks = _sign_changes(g[:, j0])
    if ks.size != 1:
        raise SystemExit(f"row v_l = {speeds[j0]:.3f} m/s has {ks.size} sign changes of g, expected 1")
    bracket = (float(mus[ks[0]]), float(mus[ks[0] + 1]))
    tkw = dict(search=jh.SearchOptions(jh.Newton(), tol=args.tol), **lkw)
    t0 = time.perf_counter()
    print("tracing μ*(v_l) upwards ...", flush=True)
    up, tr_up = _trace(sc, bracket, speeds[j0:], tkw)
    print("tracing μ*(v_l) downwards ...", flush=True)
    down, tr_down = _trace(sc, bracket, speeds[j0::-1], tkw)
    trace = down[::-1][:-1] + up  # ascending v_l; the start point once (from the upward trace)
    n_solves = tr_up.n_solves + tr_down.n_solves
    fin = [r["mu_star"] for r in trace if r["mu_star"] is not None]
    span = max(fin + list(bracket)) - min(fin + list(bracket))
    n_dense = int(len(trace) * (np.ceil(span / args.tol) + 1))
    rec["trace"] = {
        "rows": trace,
        "n_solves": n_solves,
        "n_dense": n_dense,
        "start": {"hoist_speed": float(speeds[j0]), "bracket": list(bracket)},
        "wall_s": time.perf_counter() - t0,
    }
    print(
        f"traced {len(fin)} of {len(trace)} points with {n_solves} solves "
        f"(a dense grid at {args.tol:g} over the same μ span: {n_dense}), {rec['trace']['wall_s']:.0f} s"
    )

    # 3. the check, row by row: below the traced μ* every grid cell has g > 0 (E stays down), above it
    #    g <= 0 (E hops)
    agree, checks = 0, []
    for j, (v, row) in enumerate(zip(speeds, trace, strict=True)):
        m = row["mu_star"]
        ok = m is not None and bool(np.all(g[mus < m, j] > 0.0) and np.all(g[mus > m, j] <= 0.0))
        agree += ok
        n_wrong = None if m is None else int(np.sum(g[mus < m, j] <= 0.0) + np.sum(g[mus > m, j] > 0.0))
        checks.append({"hoist_speed": float(v), "mu_star": m, "cells_on_the_wrong_side": n_wrong, "ok": ok})
        print(f"  v_l = {v:.4f} m/s: μ* = {m!r}, grid cells on the wrong side of it: {n_wrong}")
    rec["check"] = {"rows": checks, "ok": agree, "of": len(trace)}
    print(f"rows whose every grid cell is on the side of μ* that its g says: {agree} of {len(trace)}")

    # 4. the same boundary point, located in other parameters: at μ = μ*(0.3 m/s) the boundary must pass
    #    through the preset's value of each of them, up to the error that μ*'s bracket implies there,
    #    |dμ*/dq|^-1 x half its width (slopes by forward mode), and the new bracket's half-width
    start = trace[j0]
    mu0, w_mu = start["mu_star"], start["width"]
    d_mu = _slope(tr_up.points[0])  # the traced point at speeds[j0], from its Newton history
    sc_j0 = set_param(sc, VL, speeds[j0])  # the speed at which μ* was located
    sc0 = set_param(sc_j0, MU, mu0)
    others, n_ok = [], 0
    # each other parameter is a program of its own: quick locates in the first one only
    others_run = OTHERS[:1] if args.quick else OTHERS
    for path, rel in others_run:
        q0 = float(get_param(sc_j0, path))
        tol_q = args.tol * abs(q0)
        try:
            b = locate_bifurcation(
                sc0,
                path,
                MARGIN,
                (q0 * (1 - rel), q0 * (1 + rel)),
                level=0.0,
                search=jh.SearchOptions(tol=tol_q),
                **lkw,
            )
        except BifurcationError as e:
            others.append({"param": path, "preset": q0, "error": str(e)})
            print(f"  {path}: {e}")
            continue
        d_q = _slope(b)
        bound = abs(d_mu / d_q) * 0.5 * w_mu + 0.5 * b.width
        ok = abs(b.value - q0) <= bound
        n_ok += ok
        others.append(
            {
                "param": path,
                "unit": b.unit,
                "preset": q0,
                "located": b.value,
                "difference": b.value - q0,
                "bound": bound,
                "ok": ok,
                "dg_dq": d_q,
                "n_solves": b.n_solves,
                "n_uniform": b.n_uniform,
            }
        )
        print(
            f"  {path}: located {b.value:.9g} {b.unit} against the traced point's {q0:.9g} (difference "
            f"{b.value - q0:.2g}, allowed {bound:.2g}: {'ok' if ok else 'OFF'}); {b.n_solves} solves, "
            f"{b.n_uniform} for a uniform grid"
        )
    rec["other_parameters"] = {"mu": mu0, "dg_dmu": d_mu, "rows": others, "ok": n_ok, "of": len(others_run)}
    (out / "regime_map.json").write_text(json.dumps(rec, indent=1, default=float) + "\n")

    # 5. the picture
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.colors as mcolors
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.8), layout="constrained")
    gm = g * 1e3
    lim = float(np.nanmax(np.abs(gm)))
    norm = mcolors.SymLogNorm(linthresh=0.1, vmin=-lim, vmax=lim)
    pc = ax.pcolormesh(mus, speeds, gm.T, shading="nearest", cmap="RdBu", norm=norm)
    ticks = [t for t in (-100, -10, -1, -0.1, 0, 0.1, 1, 10, 100) if abs(t) <= lim]
    fig.colorbar(pc, ax=ax, label="g = min f_E / k [mm] (symlog)", ticks=ticks)
    ax.contour(mus, speeds, gm.T, levels=[0.0], colors="k", linewidths=0.8, linestyles="--")
    v_tr = np.array([r["hoist_speed"] for r in trace if r["mu_star"] is not None])
    mu_tr = np.array(fin)
    ax.plot(mu_tr, v_tr, "o-", color="gold", mec="k", lw=1.5, ms=5, label="μ*(v_l) by continuation")
    ax.plot([], [], "k--", lw=0.8, label="g = 0 interpolated on the grid")
    ax.text(0.13, 0.22, "E stays down", fontsize=9, color="navy")
    ax.text(0.45, 0.33, "E hops", fontsize=9, color="w")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("friction coefficient μ [-]")
    ax.set_ylabel("hoist speed v_l [m/s]")
    ax.set_title(f"paper-4.2: does corner E leave the ground within {args.t1:g} s?")
    fig.savefig(out / "regime_map.png", dpi=110)
    print(f"wrote {out}/regime_map.png, regime_map.json, regime_map.npz")
    return 0 if agree == len(trace) and n_ok == len(others_run) else 1


if __name__ == "__main__":
    sys.exit(main())
