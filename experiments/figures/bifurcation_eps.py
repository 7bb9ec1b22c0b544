"""The friction law's effect on a change of character of paper-4.2: μ* against the regularisation velocity ε
of the regularised Coulomb law, its ε -> 0 limit, and μ* for the sticking (bristle) law.

**The change of character.** paper-4.2 is pulled by a rope at the top corner above D: D leaves the ground at
~0.12 s, H at ~0.19 s. Whether corner E then *also* leaves the ground briefly (a hop at t ~ 0.25-0.3 s,
a fraction of a millimetre high, ending in an impact) or stays down until the load tips, seconds later,
depends on μ: below μ* E stays down, above it E hops (a grazing bifurcation of E's contact). The indicator
is continuous in μ:

    g(μ) = min over t in [0, t1] of f_E(t) / k    [m],   f_E = k p_E + h w(p_E) min(ṗ_E, 0),

E's contact function (positive exactly when N_E > 0) divided by the foundation stiffness: g > 0 if E stays
on the ground throughout [0, t1], g <= 0 if it leaves. t1 = 0.4 s, saved every 0.1 ms, so the boundary is
located on a short, well-conditioned horizon (not after 25 s of chaotic swinging), with Newton steps on
forward-mode slopes.

**What the script does.**
1. a coarse scan of g over μ in [0.1, 0.6] for the largest and smallest ε and for the bristle law, to show
   that g changes sign exactly once there (one boundary);
2. μ* to |Δμ| <= 1e-6 at ε = 1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4 m/s by continuation along ε
   (`trace_boundary`: secant predictor + safeguarded Newton corrector), so it is the same boundary at
   every ε;
3. a check of each final bracket: E's first detachment time at its two ends (inf within t1 below μ*, ~0.25 s
   above) and the time of E's closest approach to lift-off (varies smoothly with ε);
4. the ε -> 0 limit: least-squares fits of μ*(ε) = μ0 + a ε (+ b ε²), μ0 + a ε + b ε ln ε and
   μ0 + A ε^p over the 3, 4, 5 and all smallest ε, Richardson extrapolation of neighbouring pairs, with
   residuals; the reported limit is the power law over the 5 smallest ε (it fits them to ~2e-7, i.e.
   within the 1e-6 brackets; the polynomial fits leave residuals 100x larger), with the spread of the
   models over the same points as its uncertainty;
5. μ* for BristleFriction (deflection δ = 1e-3 m, breakaway ratio 0.5, relaxation time 0.01 s: the
   defaults) and by continuation along δ = 1e-3 ... 1e-4 m;
6. an accuracy check at the preset ε = 1e-3: rtol 1e-10 and twice as many saved times;
7. PNGs: μ* against ε with the fit, the limit and the bristle values; f_E/k against t across μ*.

    python experiments/figures/bifurcation_eps.py --out out/bifurcation-eps  # ~10 min on 2 shared cores
    python experiments/figures/bifurcation_eps.py --out out/bifurcation-eps --quick    # 3 ε, 1 δ, no checks
    # fits + plot from the JSON
    python experiments/figures/bifurcation_eps.py --out out/bifurcation-eps --refit

Writes DIR/bifurcation_eps.json (every number) and DIR/mu_star_vs_eps.png, DIR/contact_E_across_mu_star.png.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import diffrax  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import (  # noqa: E402
    Observable,
    contact_function,
    get_observable,
    locate_bifurcation,
    scan,
    set_param,
    trace_boundary,
)

MU = "foundation.friction_coefficient"
#: The search method of each `--method` name.
METHODS = {"newton": jh.Newton, "bisection": jh.Bisection, "multisection": jh.Multisection}
EPS = "foundation.friction.regularisation_velocity"
DELTA = "foundation.friction.deflection"
E = 1  # corner order D, E, F, H


def _t_margin(traj, sc):
    return traj.ts[jnp.argmin(contact_function(traj, sc)[:, E])]


def _f_e(traj, sc):
    return contact_function(traj, sc)[:, E] / sc.foundation.stiffness


MARGIN = get_observable("contact_margin[E]")  # min over the saved times of f_E / k [m]
T_MARGIN = Observable("E_margin_time", _t_margin, "s", "saved time at which E's contact function is smallest")
F_E = Observable("f_E_over_k", _f_e, "m", "E's contact function / k at every saved time")


def _with_law(sc, law):
    return eqx.tree_at(lambda s: s.foundation.friction, sc, law)


def _sign_changes(mus, g):
    s = np.sign(g)
    idx = np.nonzero(s[:-1] * s[1:] < 0)[0]
    return [(float(mus[i]), float(mus[i + 1])) for i in idx]


def _residuals(res) -> dict:
    """The residuals of a fit, their largest magnitude and their rms."""
    return {
        "residuals": res.tolist(),
        "max_abs_residual": float(np.max(np.abs(res))),
        "rms_residual": float(np.sqrt(np.mean(res**2))),
    }


def _fit(eps, mu, deg):
    """Least-squares μ*(ε) = μ0 + a ε (+ b ε²): coefficients, residuals, rms and max residual."""
    eps, mu = np.asarray(eps), np.asarray(mu)
    A = np.vander(eps, deg + 1, increasing=True)
    coef, *_ = np.linalg.lstsq(A, mu, rcond=None)
    res = mu - A @ coef
    dof = len(eps) - (deg + 1)
    return {
        "degree": deg,
        "eps_used": eps.tolist(),
        "mu0": float(coef[0]),
        "coefficients": coef.tolist(),
        **_residuals(res),
        "dof": dof,
    }


def _fit_power(eps, mu):
    """Least-squares μ*(ε) = μ0 + A ε^p: linear in (μ0, A) for each p on a grid (step 5e-4) over [0.2, 2]."""
    eps, mu = np.asarray(eps), np.asarray(mu)
    best = None
    for pw in np.arange(0.2, 2.0, 5e-4):
        A = np.stack([np.ones_like(eps), eps**pw], axis=1)
        coef, *_ = np.linalg.lstsq(A, mu, rcond=None)
        res = mu - A @ coef
        if best is None or np.sum(res**2) < best[0]:
            best = (float(np.sum(res**2)), float(pw), coef, res)
    _, pw, coef, res = best
    return {
        "model": "mu0 + A eps^p",
        "eps_used": eps.tolist(),
        "mu0": float(coef[0]),
        "A": float(coef[1]),
        "p": pw,
        **_residuals(res),
        "dof": len(eps) - 3,
    }


def _fit_elog(eps, mu):
    """Least-squares μ*(ε) = μ0 + a ε + b ε ln ε."""
    eps, mu = np.asarray(eps), np.asarray(mu)
    A = np.stack([np.ones_like(eps), eps, eps * np.log(eps)], axis=1)
    coef, *_ = np.linalg.lstsq(A, mu, rcond=None)
    res = mu - A @ coef
    return {
        "model": "mu0 + a eps + b eps ln eps",
        "eps_used": eps.tolist(),
        "mu0": float(coef[0]),
        "coefficients": coef.tolist(),
        **_residuals(res),
        "dof": len(eps) - 3,
    }


def _model(f, e):
    e = np.asarray(e, dtype=np.float64)
    if f.get("model") == "mu0 + A eps^p":
        return f["mu0"] + f["A"] * e ** f["p"]
    if f.get("model") == "mu0 + a eps + b eps ln eps":
        c = f["coefficients"]
        return c[0] + c[1] * e + c[2] * e * np.log(np.where(e > 0, e, 1.0))
    return np.polyval(f["coefficients"][::-1], e)


def _limit(rows, key="eps"):
    """Fits of μ*(ε) over the smallest 3, 4, 5, ... ε values (`key`: "eps", or "deflection" for the bristle
    law's δ), Richardson pairs, and the reported limit: the power law over the 5 smallest values (or all, if
    fewer); the spread of the models over those points is `model_spread`."""
    sym = "ε" if key == "eps" else "δ"
    ok = sorted((r[key], r["mu_star"]) for r in rows if r["mu_star"] is not None)
    e_ok, m_ok = np.array([x[0] for x in ok]), np.array([x[1] for x in ok])
    fits = {}
    for n_pts in sorted({3, 4, 5, len(e_ok)}):
        if 2 <= n_pts <= len(e_ok):
            fits[f"linear, {n_pts} smallest {sym}"] = _fit(e_ok[:n_pts], m_ok[:n_pts], 1)
        if 3 <= n_pts <= len(e_ok):
            fits[f"quadratic, {n_pts} smallest {sym}"] = _fit(e_ok[:n_pts], m_ok[:n_pts], 2)
            fits[f"ε ln ε, {n_pts} smallest {sym}"] = _fit_elog(e_ok[:n_pts], m_ok[:n_pts])
        if 4 <= n_pts <= len(e_ok):  # three parameters: fit only with at least one degree of freedom
            fits[f"power law, {n_pts} smallest {sym}"] = _fit_power(e_ok[:n_pts], m_ok[:n_pts])
    rich = []
    for i in range(len(e_ok) - 1):  # linear extrapolation through neighbouring pairs (Richardson, order 1)
        e1, e2, m1, m2 = e_ok[i], e_ok[i + 1], m_ok[i], m_ok[i + 1]
        rich.append({"eps": [float(e1), float(e2)], "mu0": float(m1 - e1 * (m2 - m1) / (e2 - e1))})
    k = min(5, len(e_ok))
    reported = fits.get(f"power law, {k} smallest {sym}") or fits.get(f"quadratic, {k} smallest {sym}")
    reported = reported or next(iter(fits.values()))
    same_pts = [
        f["mu0"]
        for name, f in fits.items()
        if name.endswith(f", {k} smallest {sym}") and "linear" not in name
    ]
    return {
        "fits": fits,
        "richardson_pairs": rich,
        "reported": reported,
        "reported_name": next(n for n, f in fits.items() if f is reported),
        "model_spread": [min(same_pts), max(same_pts)] if same_pts else None,
    }


def _plot_eps(rec, out):
    ok = sorted((r["eps"], r["mu_star"]) for r in rec["regularised"]["rows"] if r["mu_star"] is not None)
    e_ok, m_ok = np.array([x[0] for x in ok]), np.array([x[1] for x in ok])
    best, name = rec["limit"]["reported"], rec["limit"]["reported_name"]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4), sharey=True)
    for ax, logx in zip(axes[:2], (False, True), strict=True):
        ax.plot(e_ok, m_ok, "o", color="C0", label="regularised Coulomb: located μ*")
        ee = np.geomspace(e_ok[0] / 3, e_ok.max(), 300) if logx else np.linspace(0.0, e_ok.max(), 300)
        ax.plot(ee, _model(best, ee), "-", color="C0", lw=0.8, label=f"fit: {name}")
        if not logx:
            ax.plot([0.0], [best["mu0"]], "*", color="C3", ms=12, label=f"ε → 0: μ0 = {best['mu0']:.5f}")
        else:
            ax.axhline(best["mu0"], color="C3", lw=0.8, ls=":", label="ε → 0 limit")
        for k, r in enumerate(rec["bristle"]["rows"]):
            if r["mu_star"] is not None:
                ax.axhline(
                    r["mu_star"],
                    color=f"C{2 + k}",
                    ls="--",
                    lw=0.8,
                    label=f"bristle δ = {r['deflection']:g} m, r_b = {r['breakaway_ratio']:g}: "
                    f"{r['mu_star']:.5f}",
                )
        ax.set_xlabel("regularisation velocity ε [m/s]")
        ax.set_ylabel("μ* [-]")
        if logx:
            ax.set_xscale("log")
    axes[0].legend(fontsize=7)
    ax = axes[2]
    brows = [r for r in rec["bristle"]["rows"] if r["mu_star"] is not None]
    ds = np.array([r["deflection"] for r in brows])
    ax.plot(ds, [r["mu_star"] for r in brows], "s", color="C2", label="bristle law: located μ*")
    bl = rec["bristle"].get("limit")
    if bl:
        dd = np.geomspace(ds.min() / 3, ds.max(), 300)
        ax.plot(dd, _model(bl["reported"], dd), "-", color="C2", lw=0.8, label=f"fit: {bl['reported_name']}")
        ax.axhline(
            bl["reported"]["mu0"], color="C2", ls=":", lw=0.8, label=f"δ → 0: {bl['reported']['mu0']:.5f}"
        )
    ax.axhline(best["mu0"], color="C3", ls=":", lw=0.8, label=f"regularised ε → 0: {best['mu0']:.5f}")
    ax.set_xscale("log")
    ax.set_xlabel("bristle deflection δ [m] (r_b = 0.5, τ = 0.01 s)")
    ax.legend(fontsize=7)
    fig.suptitle(f"{rec['scenario']}: μ* above which corner E hops off the ground at t ≈ 0.25 s")
    fig.tight_layout()
    fig.savefig(out / "mu_star_vs_eps.png", dpi=100)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True)
    p.add_argument("--quick", action="store_true", help="3 ε, 1 δ, no coarse scans or accuracy checks")
    p.add_argument(
        "--eps", default=None, help="comma-separated ε [m/s] (default 1e-2,5e-3,2e-3,1e-3,5e-4,2e-4,1e-4)"
    )
    p.add_argument(
        "--deltas", default=None, help="comma-separated bristle δ [m] (default 1e-3,5e-4,2e-4,1e-4)"
    )
    p.add_argument("--t1", type=float, default=0.4, help="horizon [s] (default 0.4)")
    p.add_argument(
        "--dt-save", type=float, default=1e-4, help="spacing of the saved times [s] (default 1e-4)"
    )
    p.add_argument("--tol", type=float, default=1e-6, help="|Δμ| of the final brackets (default 1e-6)")
    p.add_argument("--rtol", type=float, default=1e-8)
    p.add_argument("--atol", type=float, default=1e-10)
    p.add_argument("--method", choices=("newton", "bisection"), default="newton")
    p.add_argument(
        "--refit",
        action="store_true",
        help="no solves: recompute the ε -> 0 fits and mu_star_vs_eps.png from DIR/bifurcation_eps.json",
    )
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    if args.refit:
        path = Path(args.out) / "bifurcation_eps.json"
        rec = json.loads(path.read_text())
        rec["limit"] = _limit(rec["regularised"]["rows"])
        rec["bristle"]["limit"] = _limit(rec["bristle"]["rows"], "deflection")
        path.write_text(json.dumps(rec, indent=1, default=float) + "\n")
        _plot_eps(rec, Path(args.out))
        for k, f in rec["limit"]["fits"].items():
            print(f"{k}: μ0 = {f['mu0']:.7f}, max |residual| {f['max_abs_residual']:.1e}")
        print(f"reported: {rec['limit']['reported_name']}, μ0 = {rec['limit']['reported']['mu0']:.7f}")
        bl = rec["bristle"].get("limit")
        if bl:
            print(f"bristle δ -> 0: {bl['reported_name']}, μ0 = {bl['reported']['mu0']:.7f}")
        return
    q = args.quick
    eps_list = [
        float(x)
        for x in (args.eps or ("1e-2,5e-3,2e-3" if q else "1e-2,5e-3,2e-3,1e-3,5e-4,2e-4,1e-4")).split(",")
    ]
    delta_list = [float(x) for x in (args.deltas or ("1e-3" if q else "1e-3,5e-4,2e-4,1e-4")).split(",")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t1, tol = args.t1, args.tol
    n_save = int(round(t1 / args.dt_save)) + 1
    ts = np.linspace(0.0, t1, n_save)
    scan_kw = dict(
        times=jh.Times(ts=ts), options=jh.SolverOptions(rtol=args.rtol, atol=args.atol, max_steps=400_000)
    )

    def locator_kw(ts=ts, rtol=args.rtol, atol=args.atol) -> dict:
        """The locator's settings: `args.method` to `tol`; Tsit5 at the scans' tolerances."""
        options = jh.SolverOptions(diffrax.Tsit5(), rtol=rtol, atol=atol, max_steps=400_000)
        search = jh.SearchOptions(METHODS[args.method](), tol)
        return dict(times=jh.Times(ts=ts), search=search, options=options)

    base = jh.load_scenario("paper-4.2")
    bristle = jh.BristleFriction(deflection=delta_list[0], breakaway_ratio=0.5, relaxation_time=0.01)
    sc_b = _with_law(base, bristle)
    wall0 = time.perf_counter()
    rec: dict = {
        "scenario": base.name,
        "command": [sys.executable, *sys.argv],
        "indicator": "g(μ) = min_{t in [0, t1]} f_E(t) / k [m]; g > 0: corner E stays on the ground, "
        "g <= 0: it "
        "leaves early; level 0",
        "t1": t1,
        "n_save": n_save,
        "tol": tol,
        "rtol": args.rtol,
        "atol": args.atol,
        "method": args.method,
        "preset_eps": float(base.foundation.friction.regularisation_velocity),
        "devices": [str(d) for d in jax.devices()],
    }
    path = out / "bifurcation_eps.json"

    def write(stage):
        rec["stage"] = stage
        rec["wall_total_s"] = time.perf_counter() - wall0
        path.write_text(json.dumps(rec, indent=1, default=float) + "\n")

    # 1. one sign change of g over [0.1, 0.6]
    bracket = (0.2, 0.36)
    if not q:
        coarse = {}
        mus = np.linspace(0.1, 0.6, 26)
        for label, sc in [
            (f"coulomb eps={eps_list[0]:g}", set_param(base, EPS, eps_list[0])),
            (f"coulomb eps={eps_list[-1]:g}", set_param(base, EPS, eps_list[-1])),
            (f"bristle delta={delta_list[0]:g}", sc_b),
        ]:
            t0 = time.perf_counter()
            r = scan(sc, {MU: mus}, observables={"g": MARGIN, "t_detach": "detachment_times[1]"}, **scan_kw)
            g = np.asarray(r["g"])
            coarse[label] = {
                "mu": mus.tolist(),
                "g_m": g.tolist(),
                "t_detach_E": np.asarray(r["t_detach"]).tolist(),
                "sign_changes": _sign_changes(mus, g),
                "n_failed": int(np.sum(~r.ok)),
                "wall_s": time.perf_counter() - t0,
            }
            print(f"coarse {label}: sign changes of g in {coarse[label]['sign_changes']}", flush=True)
        rec["coarse_scan"] = coarse
        sc0 = coarse[f"coulomb eps={eps_list[0]:g}"]["sign_changes"]
        if len(sc0) == 1:
            bracket = sc0[0]
        write("coarse")

    # 2. μ*(ε) by continuation along ε
    t0 = time.perf_counter()
    tr = trace_boundary(base, MU, bracket, EPS, eps_list, MARGIN, level=0.0, **locator_kw())
    rows = [{"eps": r["along_value"], "mu_star": r["value"], **r} for r in tr.rows()]
    for r in rows:
        extra = (
            f" ({r['n_solves']} solves, {r['steps']} steps, {r['wall_time']:.1f} s)"
            if "n_solves" in r
            else ""
        )
        print(f"ε = {r['eps']:g} m/s: μ* = {r['mu_star']!r}{extra}", flush=True)
    rec["regularised"] = {
        "rows": rows,
        "n_solves": tr.n_solves,
        "n_dense": tr.n_dense,
        "wall_s": time.perf_counter() - t0,
    }
    write("eps")

    # 3. check the final brackets: E's detachment time at both ends, time of the closest approach
    ok = [r for r in rows if r["mu_star"] is not None]
    pts_eps = [r["eps"] for r in ok for _ in range(2)]
    pts_mu = [m for r in ok for m in r["bracket"]]
    chk = scan(
        base,
        jh.Points({EPS: pts_eps, MU: pts_mu}),
        observables={"g": MARGIN, "t_min": T_MARGIN, "t_detach": "detachment_times"},
        batch=jh.BatchOptions(sort=False),
        **scan_kw,
    )
    for k, r in enumerate(ok):
        r["check"] = {
            "g_at_ends_m": [float(chk["g"][2 * k]), float(chk["g"][2 * k + 1])],
            "t_closest_s": [float(chk["t_min"][2 * k]), float(chk["t_min"][2 * k + 1])],
            "t_detach_E_at_ends_s": [float(chk["t_detach"][2 * k, E]), float(chk["t_detach"][2 * k + 1, E])],
            "t_detach_DEFH_above_s": chk["t_detach"][2 * k + 1].tolist(),
        }
    write("check")

    # 4. ε -> 0
    rec["limit"] = _limit(rec["regularised"]["rows"])
    for k, f in rec["limit"]["fits"].items():
        print(f"{k}: μ0 = {f['mu0']:.7f}, max |residual| {f['max_abs_residual']:.1e}", flush=True)
    write("limit")
    m_ok = np.array(sorted((r["eps"], r["mu_star"]) for r in ok))[:, 1]

    # 5. the sticking law (bracket: the coarse scan's sign change, else around the regularised limit)
    sc_coarse = rec.get("coarse_scan", {}).get(f"bristle delta={delta_list[0]:g}", {}).get("sign_changes", [])
    bracket_b = tuple(sc_coarse[0]) if len(sc_coarse) == 1 else (m_ok[0] - 0.03, m_ok[0] + 0.03)
    t0 = time.perf_counter()
    trb = trace_boundary(
        sc_b,
        MU,
        bracket_b,
        DELTA,
        delta_list,
        MARGIN,
        level=0.0,
        **locator_kw(),
    )
    brows = [
        {
            "deflection": r["along_value"],
            "breakaway_ratio": float(bristle.breakaway_ratio),
            "relaxation_time": float(bristle.relaxation_time),
            "mu_star": r["value"],
            **r,
        }
        for r in trb.rows()
    ]
    for r in brows:
        print(f"bristle δ = {r['deflection']:g} m: μ* = {r['mu_star']!r}", flush=True)
    rec["bristle"] = {"rows": brows, "n_solves": trb.n_solves, "wall_s": time.perf_counter() - t0}
    if len(brows) >= 2:
        rec["bristle"]["limit"] = _limit(brows, "deflection")
    write("bristle")

    # 6. accuracy at the preset ε
    if not q and any(r["eps"] == rec["preset_eps"] for r in ok):
        ref = next(r for r in ok if r["eps"] == rec["preset_eps"])
        sc = set_param(base, EPS, rec["preset_eps"])
        br = (ref["mu_star"] - 20 * tol, ref["mu_star"] + 20 * tol)
        acc = {}
        for label, kk in [
            ("rtol 1e-10, atol 1e-12", locator_kw(rtol=1e-10, atol=1e-12)),
            (f"saved every {args.dt_save / 2:g} s", locator_kw(ts=np.linspace(0.0, t1, 2 * n_save - 1))),
        ]:
            b = locate_bifurcation(sc, MU, MARGIN, br, level=0.0, **kk)
            acc[label] = {
                "mu_star": b.value,
                "minus_reference": b.value - ref["mu_star"],
                "n_solves": b.n_solves,
            }
            print(f"accuracy, {label}: μ* = {b.value:.8f} ({b.value - ref['mu_star']:+.1e})", flush=True)
        rec["accuracy_at_preset_eps"] = acc
        write("accuracy")

    # 7a. μ* against ε
    _plot_eps(rec, out)

    # 7b. E's contact function across μ* at the preset ε (the grazing)
    ref_eps = rec["preset_eps"] if any(r["eps"] == rec["preset_eps"] for r in ok) else ok[-1]["eps"]
    ref = next(r for r in ok if r["eps"] == ref_eps)
    mus_h = ref["mu_star"] + np.array([-0.01, -0.002, 0.0, 0.002, 0.01])
    hist = scan(
        set_param(base, EPS, ref_eps),
        {MU: mus_h},
        observables={"f": F_E},
        batch=jh.BatchOptions(sort=False),
        **scan_kw,
    )
    fig, ax = plt.subplots(figsize=(7, 4))
    for k, m in enumerate(mus_h):
        ax.plot(ts, 1e3 * hist["f"][k], lw=1.0, label=f"μ = μ* {m - ref['mu_star']:+.3f}")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlim(0.18, min(0.36, t1))
    ax.set_ylim(-0.3, 0.6)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("f_E / k [mm]   (> 0: E on the ground)")
    ax.set_title(f"corner E across μ* = {ref['mu_star']:.6f} (ε = {ref_eps:g} m/s)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "contact_E_across_mu_star.png", dpi=100)
    plt.close(fig)

    write("done")
    print(f"wrote {path} and PNGs in {out} ({rec['wall_total_s']:.0f} s in all)")


if __name__ == "__main__":
    main()
