"""Convergence of the elastic-foundation model (paper §3, `jaxhoist.simulate`) to the rigid-ground model
(paper §2, `simulate_rigid`) as the foundation stiffness k grows, with critically damped corner springs.

    python experiments/figures/rigid_convergence.py --out out/rigid_convergence  # full run (t1 = 170 s)
    python experiments/figures/rigid_convergence.py --out out/rigid_convergence --quick    # 5 s smoke check

The full run takes about 15 min on a shared 2-core machine (6 of it the ε = 1e-5 run, 6.8 M steps); the
results and their discussion are in docs/rigid-model.md, "Convergence of the elastic model to the rigid one".

Scenario: the preset `paper-4.1` (the §4.1 container of Figs 5-6, the paper's own rigid-vs-elastic
comparison), with t1 raised from the preset's 70 s to 170 s. Within 70 s the load only slides, yaws and
tips up onto corner F; the hoist (v_l = 0.04 m/s) then turns it about F until its mass centre comes under
the rope and it leaves the ground near 152 s, so 170 s covers every phase of a lift:
rest, sliding with yaw, a corner unloading and reloading, tipping onto a corner, pivoting (sliding, then
sticking) on it, lift-off and the first swing on the rope. No other value of the preset is changed except
those named below.

"Critically damped". The foundation is k, h per corner (N_i = k p_i + h ṗ_i). For the load resting flat on
its four corners with its mass centre above the centre of the base (as in paper-4.1), vertical bounce obeys
m z'' + 4h z' + 4k z = 0, which is critically damped for (4h)^2 = 4 m (4k), i.e.

    h = sqrt(k m)    (= 2 sqrt(k m/4): each corner spring critically damps the quarter mass it carries).

We use this h for every k (k = 1.5e7 N/m, the paper's value, has h = 7.5e5 N s/m, 3.75 times the paper's
2e5). The other contact modes then have fixed damping ratios, independent of k: rocking about the two
horizontal body axes through C (springs at ±b/2 resp. ±a/2) ζ = (b/2) sqrt(m/J_ξ) = 1.60 and
(a/2) sqrt(m/J_η) = 1.22, and a single corner bouncing with the effective mass of the box at that corner
ζ = sqrt(m/m_eff)/2 = 1.12 (the script prints these). Since every ζ is fixed, the elastic family is
self-similar in k: the static penetration scales like 1/k and the contact time scale like 1/sqrt(k), so
the differences to the rigid limit should shrink roughly like 1/k to 1/sqrt(k).

Two additions of the elastic model are not part of the rigid one and are varied explicitly:
- friction: the elastic model uses regularised Coulomb friction (ε = `foundation.friction.
  regularisation_velocity`, preset 1e-3 m/s), which creeps at v ~ ε while "sticking"; the rigid model has
  exact Coulomb friction. Variant "eps" repeats the k sweep with a smaller ε (default 1e-4 m/s).
- `foundation.damping_onset` p_0 (preset 1e-4 m): the damper builds up over the first p_0 of penetration.
  At k = 1.5e9 the load's static penetration (mg/4k = 61 µm flat, N_F/k ~ 130 µm on one corner) is about
  p_0, so the damper never builds up fully and the modes are no longer critically damped. Variant "p0"
  scales p_0 with the penetration, p_0 = 1e-4 m × (1.5e7/k), together with the smaller ε.
- Variant "fine": ε = 1e-5 m/s (`--eps-fine`) and p_0 ∝ 1/k at the stiffest k only (10× the steps of
  ε = 1e-4), to see whether the ε = 1e-4 differences at k = 1.5e9 are still limited by ε (they are).

Per run it reports: the lift-off time (elastic: `observables` "liftoff_time", the first zero of the
largest corner contact function, interpolated linearly on the saved times, which include a 1 ms grid within
±0.5 s of the rigid lift-off (the 20 ms grid alone gave errors up to 9 ms); rigid: the start of the first
phase with all four corners free, located by the event root finder), the max and RMS distance
|r_C,elastic - r_C,rigid| of the mass centres at the common (uniform) saved times over [0, t1] and over
[0, rigid lift-off], the largest z difference, the elastic solver's accepted/rejected steps and wall time (the
first elastic run is done twice and its second call timed, so no time includes compilation; the machine is
shared, times are noisy).

Writes into --out: `rigid_convergence.json` (all numbers, the settings and the rigid phase log),
`rigid_convergence.png` (mass-centre paths of the rigid model and the elastic runs with the preset ε and p_0,
distance to the rigid path vs t for ε = 1e-3 and 1e-4, convergence vs k), `paths.npz` (the mass-centre paths
on the uniform grid).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist  # noqa: E402
from jaxhoist import get_observable, simulate_rigid  # noqa: E402

KS = (1.5e7, 1.5e8, 1.5e9)
K_REF = 1.5e7  # [N/m] the paper's k; p_0 of the "p0" variant is the preset's at this k


def critical_damping(scenario, k):
    """h [N s/m] per corner that critically damps the vertical bounce of the flat load: sqrt(k m)."""
    return math.sqrt(k * float(scenario.load.mass))


def damping_ratios(scenario):
    """Damping ratios of the contact modes for h = sqrt(k m) (independent of k)."""
    m = float(scenario.load.mass)
    J = np.asarray(scenario.load.inertia_tensor())
    a, b, _ = np.asarray(scenario.load.size)
    c = np.asarray(scenario.load.mass_centre)
    r = np.array([0.0, 0.0, 0.0]) - c  # corner D relative to C, body axes
    rxn = np.cross(r, [0.0, 0.0, 1.0])
    m_eff = 1.0 / (1.0 / m + rxn @ np.linalg.solve(J, rxn))
    return {
        "vertical bounce (4 corners)": 1.0,
        "rocking about xi (springs at +-b/2)": float((b / 2) * math.sqrt(m / J[0, 0])),
        "rocking about eta (springs at +-a/2)": float((a / 2) * math.sqrt(m / J[1, 1])),
        "one corner (D) alone, effective mass": float(math.sqrt(m / m_eff) / 2),
        "m_eff_corner_kg": float(m_eff),
    }


def rigid_liftoff(tr) -> float:
    for p in tr.phases:
        if not p.rest and all(m == "free" for m in p.contact):
            return float(p.t_start)
    return math.inf


def path_stats(ts, r_el, r_rig, t_end):
    sel = ts <= t_end + 1e-12
    d = np.linalg.norm(r_el[sel] - r_rig[sel], axis=-1)
    dz = np.abs(r_el[sel, 2] - r_rig[sel, 2])
    return {
        "max_m": float(d.max()),
        "rms_m": float(np.sqrt(np.mean(d**2))),
        "max_dz_m": float(dz.max()),
        "t_of_max_s": float(ts[sel][np.argmax(d)]),
    }


def variant_scenario(sc, k, eps, p0):
    return sc.replace(
        **{
            "foundation.stiffness": k,
            "foundation.damping": critical_damping(sc, k),
            "foundation.friction.regularisation_velocity": eps,
            "foundation.damping_onset": p0,
        }
    )


def run_elastic(sc, ts, max_steps):
    t0 = time.perf_counter()
    tr = jax.block_until_ready(
        jaxhoist.simulate(
            sc, jaxhoist.Times(ts=ts), throw=False, options=jaxhoist.SolverOptions(max_steps=max_steps)
        )
    )
    return tr, time.perf_counter() - t0


def plot(out: Path, ts, r_rig, t_lift_rig, runs, rows, title):
    from matplotlib.figure import Figure

    colors = {KS[0]: "tab:red", KS[1]: "tab:orange", KS[2]: "tab:blue"}
    fig = Figure(figsize=(9.0, 6.6), layout="constrained")
    ax = fig.subplots(2, 2)
    a0, a1, a2, a3 = ax[0, 0], ax[0, 1], ax[1, 0], ax[1, 1]
    a0.plot(r_rig[:, 0], r_rig[:, 1], color="k", lw=2.2, label="rigid ground")
    a1.plot(ts, r_rig[:, 2], color="k", lw=2.2, label="rigid ground")
    eps = {r["variant"]: r["eps"] for r in rows}
    for (v, k), r in runs.items():
        c = colors.get(k, None)
        if v == "base":
            a0.plot(r[:, 0], r[:, 1], color=c, lw=0.9, ls="--", label=f"elastic k = {k:.1e}")
            a1.plot(ts, r[:, 2], color=c, lw=0.9, ls="--")
        d = np.maximum(np.linalg.norm(r - r_rig, axis=-1), 1e-9)
        if v == "eps":
            a2.semilogy(ts, d, color=c, lw=0.8, label=f"k = {k:.1e}, ε = {eps[v]:.0e}")
        else:
            a2.semilogy(ts, d, color=c, lw=0.5, alpha=0.45, ls=":", label=f"k = {k:.1e}, ε = {eps[v]:.0e}")
    a0.set_xlabel("x_C [m]")
    a0.set_ylabel("y_C [m]")
    a0.set_title("mass centre from above", fontsize=9)
    a0.legend(fontsize=7)
    a1.set_xlabel("t [s]")
    a1.set_ylabel("z_C [m]")
    a1.set_title("mass-centre height", fontsize=9)
    a2.set_xlabel("t [s]")
    a2.set_ylabel("|r_C,elastic - r_C,rigid| [m]")
    a2.set_title("distance to the rigid path", fontsize=9)
    a2.legend(fontsize=6, ncol=2)
    for a in (a1, a2):
        if math.isfinite(t_lift_rig):
            a.axvline(t_lift_rig, color="0.6", lw=0.7, ls=":")
    markers = {"base": "o", "eps": "s", "p0": "^", "fine": "*"}
    for v in ("base", "eps", "fine"):
        rr = [r for r in rows if r["variant"] == v]
        if not rr:
            continue
        lab = f"ε = {rr[0]['eps']:.0e}" + (", p_0 ∝ 1/k" if v == "fine" else "")
        ks = np.array([r["k"] for r in rr])
        a3.loglog(
            ks,
            [r["path_all"]["max_m"] for r in rr],
            marker=markers.get(v, "x"),
            color="tab:blue",
            lw=0.8,
            label=f"max |Δr_C| [m], {lab}",
        )
        dt = [abs(r["liftoff_diff_s"]) if math.isfinite(r["liftoff_diff_s"]) else np.nan for r in rr]
        a3.loglog(
            ks,
            dt,
            marker=markers.get(v, "x"),
            color="tab:red",
            lw=0.8,
            ls="--",
            label=f"|Δt_lift-off| [s], {lab}",
        )
    kk = np.array([KS[0], KS[-1]])
    a3.loglog(kk, 0.1 * (kk / KS[0]) ** -1.0, color="0.6", lw=0.6, ls=":", label="∝ 1/k")
    a3.loglog(kk, 0.1 * (kk / KS[0]) ** -0.5, color="0.3", lw=0.6, ls=":", label="∝ 1/sqrt(k)")
    a3.set_xlabel("foundation stiffness k per corner [N/m]")
    a3.set_title("convergence (h = sqrt(k m))", fontsize=9)
    a3.legend(fontsize=6)
    for a in ax.flat:
        a.grid(alpha=0.3, which="both")
    fig.suptitle(title, fontsize=10)
    fig.savefig(out / "rigid_convergence.png", dpi=85)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="5 s, 101 saved times, base variant only")
    p.add_argument("--t1", type=float, default=170.0, help="end time [s] (full run)")
    p.add_argument("--dt-save", type=float, default=0.02, help="spacing of the saved times [s] (full run)")
    p.add_argument("--eps", type=float, default=1e-4, help="ε [m/s] of the 'eps' and 'p0' variants")
    p.add_argument("--eps-fine", type=float, default=1e-5, help="ε [m/s] of the 'fine' variant (stiffest k)")
    p.add_argument(
        "--variants", default="base,eps,p0,fine", help="comma-separated subset of base,eps,p0,fine"
    )
    p.add_argument("--max-steps", type=int, default=20_000_000)
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jaxhoist.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc0 = jaxhoist.load_scenario("paper-4.1")
    if args.quick:
        t1, n_save, variants = 5.0, 101, ["base"]
    else:
        t1 = args.t1
        n_save = int(round(t1 / args.dt_save)) + 1
        variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    ts = np.linspace(0.0, t1, n_save)
    eps0 = float(sc0.foundation.friction.regularisation_velocity)
    p00 = float(sc0.foundation.damping_onset)
    settings = {
        "base": lambda k: (eps0, p00),
        "eps": lambda k: (args.eps, p00),
        "p0": lambda k: (args.eps, p00 * K_REF / k),
        "fine": lambda k: (args.eps_fine, p00 * K_REF / k),
    }
    ks_of = {v: (KS[-1:] if v == "fine" else KS) for v in settings}
    zetas = damping_ratios(sc0)
    print(f"paper-4.1, t1 = {t1:g} s, {n_save} saved times; m = {float(sc0.load.mass):g} kg; h = sqrt(k m)")
    print("damping ratios for h = sqrt(k m): " + ", ".join(f"{n}: {z:.3g}" for n, z in _named(zetas)))

    t0 = time.perf_counter()
    # quick: the default options, as every quick rigid run of paper-4.1 (one program in CI's cache)
    rig_options = jaxhoist.RigidOptions() if args.quick else jaxhoist.RigidOptions(max_steps=1_000_000)
    rig = simulate_rigid(sc0, jaxhoist.Times(t1, ts=ts), options=rig_options)
    rig_wall = time.perf_counter() - t0
    r_rig = np.asarray(rig.position)
    t_lift_rig = rigid_liftoff(rig)
    print(
        f"rigid: {len(rig.phases)} phases, {int(rig.num_accepted_steps)} steps, wall {rig_wall:.1f} s "
        f"(incl. compilation), lift-off {t_lift_rig:.6f} s"
    )
    print(rig.phase_log())
    # Elastic saved times: the uniform grid (for the path comparison) plus 1 ms spacing within ±0.5 s of the
    # rigid lift-off, where the elastic lift-off time is interpolated.
    ts_el, on_grid = ts, np.ones(n_save, dtype=bool)
    if math.isfinite(t_lift_rig):
        dense = np.arange(max(t_lift_rig - 0.5, 0.0), min(t_lift_rig + 0.5, t1), 1e-3)
        ts_el = np.union1d(ts, dense)
        on_grid = np.isin(ts_el, ts)
        assert on_grid.sum() == n_save

    rows, runs, warm = [], {}, False
    for v in variants:
        for k in ks_of[v]:
            eps, p0 = settings[v](k)
            sc = variant_scenario(sc0, k, eps, p0)
            tr, wall = run_elastic(sc, ts_el, args.max_steps)
            if not warm:  # time the second call: no compilation in any reported wall time
                first = wall
                tr, wall = run_elastic(sc, ts_el, args.max_steps)
                warm = True
                print(f"(first elastic call incl. compilation: {first:.1f} s)")
            status = jaxhoist.SolveStatus(int(tr.status)).name.lower()
            r_el = np.asarray(tr.position)[on_grid]
            t_lift = float(get_observable("liftoff_time")(tr, sc))
            t_cmp = t_lift_rig if math.isfinite(t_lift_rig) else t1
            row = {
                "variant": v,
                "k": k,
                "h": critical_damping(sc0, k),
                "eps": eps,
                "p0": p0,
                "status": status,
                "liftoff_elastic_s": t_lift,
                "liftoff_rigid_s": t_lift_rig,
                "liftoff_diff_s": t_lift - t_lift_rig,
                "path_all": path_stats(ts, r_el, r_rig, t1),
                "path_before_liftoff": path_stats(ts, r_el, r_rig, t_cmp),
                "accepted_steps": int(tr.num_accepted_steps),
                "rejected_steps": int(tr.num_rejected_steps),
                "wall_s": wall,
                "detachment_times_s": [
                    float(x) for x in np.asarray(get_observable("detachment_times")(tr, sc))
                ],
            }
            rows.append(row)
            if v in ("base", "eps"):
                runs[v, k] = r_el
            pa, pb = row["path_all"], row["path_before_liftoff"]
            print(
                f"{v:5s} k = {k:.1e} h = {row['h']:.3g} ε = {eps:.0e} p0 = {p0:.0e}: {status}, "
                f"lift-off {t_lift:.4f} s (Δ {row['liftoff_diff_s']:+.4f} s), |Δr_C| max {pa['max_m']:.3e} "
                f"rms {pa['rms_m']:.3e} m (before lift-off: max {pb['max_m']:.3e} rms {pb['rms_m']:.3e}), "
                f"max |Δz| {pa['max_dz_m']:.2e} m, {row['accepted_steps']} steps, {wall:.1f} s",
                flush=True,
            )

    result = {
        "scenario": "paper-4.1",
        "t1_s": t1,
        "n_save": n_save,
        "mass_kg": float(sc0.load.mass),
        "damping_rule": "h = sqrt(k m) per corner (critical damping of the vertical bounce on four springs)",
        "damping_ratios": zetas,
        "rigid": {
            "liftoff_s": t_lift_rig,
            "phases": len(rig.phases),
            "accepted_steps": int(rig.num_accepted_steps),
            "wall_s_incl_compilation": rig_wall,
            "phase_log": rig.phase_log().splitlines(),
        },
        "elastic": rows,
        "command": "python experiments/figures/rigid_convergence.py "
        + " ".join(sys.argv[1:] if argv is None else argv),
        "versions": {"jax": jax.__version__, "jaxhoist": getattr(jaxhoist, "__version__", "?")},
    }
    (out / "rigid_convergence.json").write_text(json.dumps(_finite(result), indent=1))
    np.savez(
        out / "paths.npz", ts=ts, rigid=r_rig, **{f"elastic_{v}_k{k:.1e}": r for (v, k), r in runs.items()}
    )
    plot(
        out,
        ts,
        r_rig,
        t_lift_rig,
        runs,
        rows,
        f"paper-4.1 (t1 = {t1:g} s): elastic foundation with h = sqrt(k m) vs rigid ground",
    )
    print(f"wrote {out}/rigid_convergence.json, rigid_convergence.png, paths.npz")
    return 0


def _finite(x):
    """JSON-safe copy: inf/nan (an event that did not happen before t1) become null."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _named(z):
    return [(n, v) for n, v in z.items() if not n.endswith("_kg")]


if __name__ == "__main__":
    sys.exit(main())
