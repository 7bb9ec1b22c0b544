"""Calibrate paper-4.3 to the paper's §4.3 μ* = 0.3635 and measure how μ* depends on what the paper omits.

The paper gives no mass centre for its "eccentrically loaded" container, no rope fixture and no boom. The
maps behind this script (docs/bifurcation.md, "Calibrating to the paper's μ*") found, near μ = 0.3635, one
kind of change that moves the whole final attitude at once: a resolved ramp (width ~4e-3 in μ) in which the
final pitch ϑ(t1) falls from ~19.5° to ~10.5° while ψ(t1), φ(t1) and y(t1) move with it, next to a jump of the
lift-off time. Its location is taken as the crossing of ϑ(t1) = 15° (mid-way down the ramp), a continuous
indicator. With η_C = 3.18 m, ζ_C = 0.83 m and the corner fixture of paper-4.2 it crosses μ = 0.3635 at
ξ_C ≈ 1.159 m. This script

1. locates ξ_C* at μ = 0.3635 (bisection, |Δξ| <= 1e-6 m) and μ* at the preset (paper-4.3);
2. traces μ*(ξ_C) by continuation (`trace_boundary`) over ξ_C = 1.14 ... 1.17 m, the path from
   uncalibrated values to the fitted one;
3. dμ*/dq from the implicit-function theorem, dμ*/dq = -(∂ϑ/∂q)/(∂ϑ/∂μ), for q = ξ_C, η_C, ζ_C and the
   fixture's position along the top edges (rope.attachment[0], [1]); the partials are central differences
   (forward-mode sensitivities of ϑ(t1) over these 25 s come out ~1e45, see docs), checked against the
   continuation's secant in ξ_C;
4. μ* at ε = 1e-2, 1e-4 m/s and with the bristle law (δ = 1 mm), from brackets found on 5e-4 grids;
5. classifies the located change (`classify_change`): a steep ramp, and its 10-90 % width.

    python experiments/figures/bifurcation_calibrate.py --out out/bif-calibrate  # ~15 min on 2 shared cores
    python experiments/figures/bifurcation_calibrate.py --out out/bif-calibrate --quick  # mu* only, coarse

Writes `calibration.json` and resumes from it (steps already there are not redone); prints every located
value.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import get_param, set_param  # noqa: E402

MU = "foundation.friction_coefficient"
XI = "load.mass_centre[0]"
EPS = "foundation.friction.regularisation_velocity"
OBS = "final_theta"
LEVEL = float(np.radians(15.0))
KW = dict(times=jh.Times(25.0, n=2501), level=LEVEL)
MU_PAPER = 0.3635


def json_safe(x):
    """Plain JSON values: tuples to lists, numpy scalars to floats, ±inf/NaN to strings."""
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return str(x)
    return x


def _row(b):
    return dict(
        value=b.value,
        bracket=list(b.bracket),
        y_lo=b.y_lo,
        y_hi=b.y_hi,
        kind=b.kind,
        n_solves=b.n_solves,
        wall_time=b.wall_time,
    )


def _trace(sc, along, values, bracket, tol):
    t = time.perf_counter()
    search = jh.SearchOptions(jh.Bisection(), tol, initial_half_width=1e-3)
    bd = jh.trace_boundary(sc, MU, bracket, along, values, OBS, search=search, **KW)
    rows = [
        dict(q=float(q), mu_star=float(v), width=float(w))
        for q, v, w in zip(bd.along_values, bd.values, bd.widths, strict=True)
    ]
    for r in rows:
        print(f"  {along} = {r['q']:.6g}: mu* = {r['mu_star']:.7f} (width {r['width']:.2g})", flush=True)
    good = [(r["q"], r["mu_star"]) for r in rows if np.isfinite(r["mu_star"])]
    slope = None
    if len(good) >= 2:
        (q0, p0), (q1, p1) = good[-2], good[-1]
        slope = (p1 - p0) / (q1 - q0)
    return dict(
        along=along, rows=rows, n_solves=bd.n_solves, wall_time=time.perf_counter() - t, secant_slope=slope
    )


IFT_STEPS = {
    MU: 1e-5,
    XI: 1e-4,
    "load.mass_centre[1]": 1e-4,
    "load.mass_centre[2]": 1e-4,
    "rope.attachment[0]": 1e-4,
    "rope.attachment[1]": 1e-4,
}


def _ift(sc, mu_star):
    """dμ*/dq = -(∂ϑ/∂q)/(∂ϑ/∂μ) at (μ*, preset), partials by central differences (one-sided for the
    fixture, which sits on the box's edges); one scan of 12 points."""
    sc = set_param(sc, MU, mu_star)
    base = {p: float(np.asarray(get_param(sc, p))) for p in IFT_STEPS}
    pts = {p: [] for p in IFT_STEPS}
    for q, h in IFT_STEPS.items():
        # the fixture sits on the box's edge (0 along both top edges): a one-sided difference into the box
        offsets = (0.0, h) if q.startswith("rope.attachment") else (-h, h)
        for off in offsets:
            for p in IFT_STEPS:
                pts[p].append(base[p] + (off if p == q else 0.0))
    r = jh.scan(
        sc,
        jh.Points({p: np.array(v) for p, v in pts.items()}),
        jh.Times(25.0, n=2501),
        observables=[OBS],
        batch=jh.BatchOptions(sort=False),
    )
    if not np.all(r.ok):
        raise SystemExit(f"IFT solves failed: {r.failures()[:2]}")
    th = np.asarray(r[OBS])
    d = {}
    for k, (q, h) in enumerate(IFT_STEPS.items()):
        span = h if q.startswith("rope.attachment") else 2 * h
        d[q] = float((th[2 * k + 1] - th[2 * k]) / span)
    out = {"partials_rad_per_unit": d, "dmu_star_dq": {q: -d[q] / d[MU] for q in IFT_STEPS if q != MU}}
    for q, v in out["dmu_star_dq"].items():
        print(f"  dmu*/d{q} = {v:.5g} per m (IFT, differenced partials)", flush=True)
    return out


def _done(ift) -> bool:
    """An implicit-function record with every slope finite."""
    return bool(ift) and all(isinstance(v, float) for v in ift["dmu_star_dq"].values())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--tol", type=float, default=1e-6)
    p.add_argument(
        "--quick", action="store_true", help="smoke check: only mu* at the preset, tol 1e-3, 251 saved times"
    )
    p.add_argument("--skip", default="", help="comma-separated steps to skip: fit,trace,slopes,eps,classify")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    skip = set(filter(None, args.skip.split(",")))
    if args.quick:  # one locate on a coarse tolerance and grid (the full run's code path, one compile)
        KW["times"] = jh.Times(25.0, n=251)
        args.tol = max(args.tol, 1e-3)
        skip |= {"trace", "slopes", "eps", "classify"}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rec: dict = {"mu_paper": MU_PAPER, "observable": OBS}
    if (out / "calibration.json").exists():  # resume: keep what an earlier run located
        rec.update(json.loads((out / "calibration.json").read_text()))
    sc = jh.load_scenario("paper-4.3")

    search = jh.SearchOptions(jh.Bisection(), args.tol)

    def save():
        (out / "calibration.json").write_text(json.dumps(json_safe(rec), indent=1))

    if "fit" not in skip and "mu_star" not in rec:  # 1. ξ_C* at μ = 0.3635, then μ* at the preset
        if not args.quick:
            b = jh.locate_bifurcation(set_param(sc, MU, MU_PAPER), XI, OBS, (1.15, 1.17), search=search, **KW)
            print("xi_C* at mu = 0.3635:", b.summary(), flush=True)
            rec["xi_fit"] = _row(b)
        b = jh.locate_bifurcation(sc, MU, OBS, (0.362, 0.365), search=search, **KW)
        print("mu* at paper-4.3:", b.summary(), flush=True)
        rec["mu_star"] = _row(b)
        save()
    mu_star = rec.get("mu_star", {}).get("value", MU_PAPER)
    if "slopes" not in skip and not _done(rec.get("ift")):  # 3. implicit-function derivatives
        rec["ift"] = _ift(sc, mu_star)
        save()
    if "trace" not in skip and "trace_xi" not in rec:  # 2. the continuation path in ξ_C
        print("trace mu*(xi_C):", flush=True)
        rec["trace_xi"] = _trace(
            set_param(sc, XI, 1.14), XI, [1.14, 1.15, 1.1587788, 1.17], (0.368, 0.374), args.tol
        )
        save()
    if "eps" not in skip:  # 4. the friction closure
        laws = [
            ("eps=1e-2", set_param(sc, EPS, 1e-2), (0.3685, 0.370)),
            ("eps=1e-4", set_param(sc, EPS, 1e-4), (0.3625, 0.364)),
            (
                "bristle delta=1e-3",
                eqx.tree_at(
                    lambda s: s.foundation.friction,
                    sc,
                    jh.BristleFriction(deflection=1e-3, breakaway_ratio=0.5, relaxation_time=0.01),
                ),
                (0.362, 0.368),
            ),
        ]
        rec.setdefault("eps", {})["eps=1e-3"] = rec.get("mu_star")
        for name, s, b0 in laws:
            if rec["eps"].get(name):
                continue
            options = jh.SolverOptions(diffrax.Tsit5(), max_steps=2_000_000)
            b = jh.locate_bifurcation(s, MU, OBS, b0, search=search, options=options, **KW)
            print(f"{name}:", b.summary(), flush=True)
            rec["eps"][name] = _row(b)
            save()
    if "classify" not in skip:  # 5. what the change is
        lo, hi = rec.get("mu_star", {}).get("bracket", (MU_PAPER - 5e-7, MU_PAPER + 5e-7))
        c = jh.classify_change(
            sc,
            param=MU,
            bracket=(lo, hi),
            observable=OBS,
            half_window=6e-3,
            n_window=49,
            times=jh.Times(25.0, n=2501),
        )
        print("classified:", c.summary(), flush=True)
        rec["classified"] = c.to_dict()
        save()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
