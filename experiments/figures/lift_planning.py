"""Plan the lift of the paper's §4.2 container (preset `paper-4.2`) under uncertainty: hazard maps over the
boom tip's position, and a lift optimised over the tip and a hoist speed profile against the preset's
constant-speed lift and against a grid search over the same design family and sample.

    python experiments/figures/lift_planning.py --out out/lift_planning          # 9 x 9 tips, 64 samples
    python experiments/figures/lift_planning.py --out out/lift_planning --quick  # 2 s, 2 x 2 tips, 4 samples

Uncertain inputs: the friction coefficient μ ~ U(0.2, 0.5) and the mass centre's ξ_C (`load.mass_centre[0]`)
~ N(1.0 m, 0.1 m). Hazards:
- `slide`: the container is dragged more than 0.5 m over the ground (`ground_slide`);
- `tip`: it tilts more than 70° while a corner still touches the ground (`ground_tilt`: the largest angle
  between the body ζ axis and the vertical at the saved times with a corner in contact). The
  corner fixture lifts the container by a corner: it hangs at 61° (nominal mass centre), so every lift
  tilts it that far on its way up; beyond 70° it has rolled further over an edge than the lift needs;
- `strike`: a corner lands again after it left the ground (`impacts`);
- `overload`: the peak rope tension exceeds 1.2 m g (`max_rope_tension`).

1. `lift_risk` maps each hazard's probability over a grid of boom-tip positions (x, y) at the preset's
   height and hoist speed (every tip sees the same samples).
2. The design family: the tip's (x, y) and a hoist speed profile, a `KnotHoist` with knots at 0, 8 and 20 s
   whose three speeds are design values in [0.15, 0.45] m/s (the hoist's maximum speed 0.45 m/s; a
   monotone C¹ curve between the knots, the last speed held after 20 s). All three knots at 0.3 m/s is the
   preset's constant-speed lift, which is the start. `optimise_lift` minimises
   E[peak tension] / (m g) + E[ground slide] / (1 m) + (time to reel in 6 m of rope) / (60 s), plus a
   softplus penalty of the slide and overload observables over their thresholds, over a fixed sample
   (common random numbers), and checks the hazard limits at the preset and the optimum on a fresh sample.
3. The same objective over the same fixed sample on a grid of the design family (`--grid` points per
   axis, 5 axes), against the optimum: the best grid point's J and the solves each spent.
4. The optimum's gradient (forward sensitivities averaged over the sample) against central differences of
   the sample-average objective J.

Writes into --out: `risk_maps.png` (the four probability maps, the preset's tip and the optimum's marked),
`outcomes.png` (histograms of the peak tension, the ground slide and the ground tilt over the fresh sample,
the preset's lift against the optimised one, and both hoist speed profiles), `risk_map.nc` (the map as
netCDF), `results.json` (the optimum, the objective's terms, the limits, the grid search, the gradient
check, solve counts and times), and prints the summaries.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_num_cpu_devices", os.cpu_count())  # every core a device, as in the README's set-up

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

TIP_X, TIP_Y = "boom.tip_position[0]", "boom.tip_position[1]"
KNOT_TIMES = (0.0, 8.0, 20.0)  # [s]
KNOTS = tuple(f"hoist.speeds[{k}]" for k in range(len(KNOT_TIMES)))
SPEED_BOUNDS = (0.15, 0.45)  # [m/s]; the upper one is the hoist's maximum speed
MU, XI = "foundation.friction_coefficient", "load.mass_centre[0]"
# The tip hazard reads the built-in `ground_tilt`'s function in an `Observable` of this script's own:
# `optimise_lift` penalises the limited hazards on built-in smooth observables, never on a caller's own, and
# this lift's J, that of the run in docs/lift-optimisation.md, penalises the slide and the overload only;
# the tip limit is still checked on the fresh sample.
TILT_ON_GROUND = jh.Observable(
    "tilt_on_ground", jh.get_observable("ground_tilt").fn, "rad", "ground_tilt, not penalised in J"
)


def settings(quick: bool) -> dict:
    if quick:  # a smoke run: every step of the full run on 2 s of the lift and the smallest samples
        return dict(t1=2.0, n_save=41, nx=2, ny=2, map_samples=4, map_rep=2, opt_samples=2, iters=1,
                    check_samples=4, check_rep=2, max_steps=20_000, grid=2, fd_h=0.01, lanes=4)  # fmt: skip
    return dict(t1=25.0, n_save=501, nx=9, ny=9, map_samples=64, map_rep=8, opt_samples=32, iters=20,
                check_samples=256, check_rep=8, max_steps=200_000, grid=3, fd_h=0.01)  # fmt: skip


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="2 s, 2 x 2 tips, 4 samples, 1 iteration (smoke run)")
    p.add_argument("--grid", type=int, default=None, help="grid-search points per design axis (5 axes)")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = settings(args.quick)
    if args.grid is not None:
        cfg["grid"] = args.grid
    sc = jh.load_scenario("paper-4.2")
    mass, g = float(sc.load.mass), float(sc.gravity)
    weight = mass * g
    times = jh.Times(cfg["t1"], n=cfg["n_save"])
    options = jh.SolverOptions(max_steps=cfg["max_steps"])
    # quick: one group width for every scan, so that the forward scans of the optimisation's check, the grid
    # search and the central differences share one compiled program (the full run: the default widths)
    batch = jh.BatchOptions(lanes=cfg["lanes"]) if "lanes" in cfg else None
    uncertain = {MU: jh.Uniform(0.2, 0.5), XI: jh.Normal(1.0, 0.1)}
    hazards = [
        jh.slide(0.5),
        jh.Hazard("tip", TILT_ON_GROUND, math.radians(70.0)),
        jh.strike(),
        jh.overload(1.2 * weight),
    ]
    xs = np.linspace(0.0, 4.0, cfg["nx"])
    ys = np.linspace(0.0, 6.0, cfg["ny"])
    report: dict = {"settings": cfg, "quick": bool(args.quick)}

    # 1. the hazard maps over the boom tip's (x, y)
    t0 = time.perf_counter()
    risk = jh.lift_risk(
        sc,
        uncertain,
        hazards,
        jh.Grid({TIP_X: xs, TIP_Y: ys}),
        samples=cfg["map_samples"],
        replicates=cfg["map_rep"],
        times=times,
        seed=0,
        options=options,
        batch=batch,
        progress=True,
    )
    t_map = time.perf_counter() - t0
    print(risk.summary())
    risk.to_netcdf(out / "risk_map.nc")
    report["map"] = {
        "wall_s": round(t_map, 1),
        "solves": int(risk.samples * np.prod(risk.shape)),
        "failed": int(np.sum(risk.n_failed)),
        "max_accepted_steps": int(np.max(risk.scan.num_accepted_steps)),
        "median_ground_tilt_deg": np.degrees(risk.quantile("tilt_on_ground", 0.5)).round(1).tolist(),
    }
    print(f"map: {report['map']}")

    # 2. the optimised lift (tip and hoist profile) against the preset's constant speed
    v0 = float(sc.hoist.speed)
    sc_knots = eqx.tree_at(
        lambda s: s.hoist, sc, jh.KnotHoist(KNOT_TIMES, [v0] * len(KNOT_TIMES), max_speed=SPEED_BOUNDS[1])
    )
    objective = {"max_rope_tension": 1.0 / weight, "ground_slide": 1.0, "hoist_time": 1.0 / 60.0}
    bounds = {TIP_X: (0.0, 4.0), TIP_Y: (0.0, 6.0)} | {k: SPEED_BOUNDS for k in KNOTS}
    kw = dict(
        hazard_limits={hazards[0]: 0.1, hazards[1]: 0.1, hazards[2]: 0.2, hazards[3]: 0.05},
        hoist_distance=6.0,
        penalty=1.0,
        samples=cfg["opt_samples"],
        seed=0,
        times=times,
        check_samples=cfg["check_samples"],
        check_replicates=cfg["check_rep"],
        options=options,
        batch=batch,
    )
    t0 = time.perf_counter()
    res = jh.optimise_lift(
        sc_knots, uncertain, objective, bounds, max_iterations=cfg["iters"], progress=True, **kw
    )
    t_opt = time.perf_counter() - t0
    print(res.summary())
    opt_solves = (res.evaluations + len(res.screened)) * cfg["opt_samples"]
    report["optimised"] = {
        "design": res.design,
        "start": res.start,
        "value": res.value,
        "start_value": res.start_value,
        "terms": res.terms,
        "start_terms": res.start_terms,
        "gradient": res.gradient,
        "iterations": res.iterations,
        "evaluations": res.evaluations,
        "solves": opt_solves,
        "check_solves": res.solves - opt_solves,
        "converged": res.converged,
        "message": res.message,
        "limits": res.limit_table(),
        "wall_s": round(t_opt, 1),
    }

    # 3. a grid search over the same design family, same objective, same fixed sample; 4. the gradient
    # check. Internal: `_prepare` builds the very J (sample, scans, terms) that optimise_lift minimised.
    from jaxhoist._apps.planning.optimise import _prepare  # noqa: PLC0415

    problem = _prepare(
        sc_knots, uncertain, objective, bounds, x0=None, starts=1, max_iterations=1, tolerance=1e-4,
        penalty_width=0.1, check_seed=None, confidence=0.95, **kw,
    )["problem"]  # fmt: skip
    axes = [np.linspace(a, b, cfg["grid"]) for a, b in bounds.values()]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(bounds))
    t0 = time.perf_counter()
    values = np.array([e["value"] if e["n_failed"] == 0 else np.inf for e in problem.evaluate(grid)])
    t_grid = time.perf_counter() - t0
    best = int(np.argmin(values))
    report["grid_search"] = {
        "points_per_axis": cfg["grid"],
        "best_value": float(values[best]),
        "best_design": dict(zip(bounds, grid[best].tolist(), strict=True)),
        "solves": int(grid.shape[0] * cfg["opt_samples"]),
        "optimum_value": res.value,
        "optimum_no_worse": bool(res.value <= values[best] + 1e-4 * abs(values[best])),
        "wall_s": round(t_grid, 1),
    }
    print(
        f"grid search ({cfg['grid']} per axis): best J = {values[best]:.6g} at "
        f"{grid[best].round(3).tolist()}, "
        f"{report['grid_search']['solves']} solves; optimise_lift: J = {res.value:.6g}, {opt_solves} solves"
    )
    x = np.array([res.design[p] for p in bounds])
    h = cfg["fd_h"]
    span = np.array([b - a for a, b in bounds.values()])
    steps = np.diag(h * span)  # h as a share of each bound's span, kept inside the box
    xc = np.clip(x, problem.lo + h * span, problem.hi - h * span)
    got = problem.evaluate(xc, derivatives=True)[0]
    ev = problem.evaluate(np.vstack([xc + steps, xc - steps]))
    d = len(bounds)
    fd = np.array([(ev[k]["value"] - ev[d + k]["value"]) / (2 * h * span[k]) for k in range(d)])
    rel = float(np.linalg.norm((got["grad"] - fd) * span) / max(np.linalg.norm(fd * span), 1e-300))
    report["gradient_check"] = {
        "at": dict(zip(bounds, xc.tolist(), strict=True)),
        "h_share_of_span": h,
        "gradient": got["grad"].tolist(),
        "central_differences": fd.tolist(),
        "relative_error_in_unit_box": rel,
    }
    print(
        f"gradient check at the optimum: |g - fd| / |fd| = {rel:.3g} (in the unit box, h = {h} of each span)"
    )
    (out / "results.json").write_text(json.dumps(report, indent=2) + "\n")
    plot_maps(out / "risk_maps.png", risk, xs, ys, hazards, sc, res, weight)
    plot_outcomes(out / "outcomes.png", res, weight, sc_knots, cfg["t1"])
    print(f"wrote {out}/risk_maps.png, outcomes.png, risk_map.nc, results.json", file=sys.stderr)
    return 0


def plot_maps(path, risk, xs, ys, hazards, sc, res, weight) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    titles = {
        "slide": "P(slide > 0.5 m)",
        "tip": "P(tilt > 70° on the ground)",
        "strike": "P(corner strike)",
        "overload": f"P(peak rope tension > 1.2 m g = {1.2 * weight / 1e3:.0f} kN)",
    }
    fig, axes = plt.subplots(2, 2, figsize=(10, 9), constrained_layout=True)
    size = np.asarray(sc.load.size)
    tip0 = np.asarray(sc.boom.tip_position)
    for ax, h in zip(axes.flat, hazards, strict=True):
        p = risk.probability(h)  # (nx, ny)
        m = ax.pcolormesh(xs, ys, p.T, vmin=0.0, vmax=1.0, cmap="magma_r", shading="nearest")
        fig.colorbar(m, ax=ax, label="probability [-]")
        box = plt.Rectangle((0, 0), size[0], size[1], fill=False, ec="tab:cyan", lw=1.5, label="container")
        ax.add_patch(box)
        ax.plot(*tip0[:2], "*", ms=14, mfc="white", mec="k", label="preset tip")
        opt = (res.design[TIP_X], res.design[TIP_Y])
        ax.plot(*opt, "o", ms=9, mfc="tab:green", mec="k", label="optimised tip")
        ax.set_title(titles[h.name])
        ax.set_xlabel("boom tip x [m]")
        ax.set_ylabel("boom tip y [m]")
        ax.set_aspect("equal")
    axes.flat[0].legend(loc="upper left", fontsize=8, framealpha=0.8)
    n = risk.samples
    fig.suptitle(
        f"paper-4.2 container over {float(risk.scan.ts[-1]):g} s: hazard probabilities over the boom tip "
        f"(z = {tip0[2]:g} m, v_l = {float(sc.hoist.speed):g} m/s)\n"
        f"μ ~ U(0.2, 0.5), ξ_C ~ N(1.0 m, 0.1 m); {n} samples per tip; the optimised tip has its own speed"
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_outcomes(path, res, weight, sc_knots, t1) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    chk = res.check
    s = chk.scan
    n = chk.samples
    ok = (np.asarray(s.status) == 0).reshape(2, n)
    series = [
        ("max_rope_tension", 1.0 / weight, "peak rope tension / (m g) [-]", 1.2),
        ("ground_slide", 1.0, "ground slide [m]", 0.5),
        ("tilt_on_ground", 180.0 / math.pi, "largest tilt on the ground [deg]", 70.0),
    ]
    fig, axes = plt.subplots(1, 4, figsize=(18, 4.3), constrained_layout=True)
    tips = {k: (d[TIP_X], d[TIP_Y]) for k, d in (("start", res.start), ("opt", res.design))}
    labels = (
        "preset: tip ({:.2f}, {:.2f}) m, 0.3 m/s".format(*tips["start"]),
        "optimised: tip ({:.2f}, {:.2f}) m, profile".format(*tips["opt"]),
    )
    for ax, (name, scale, xlabel, thr) in zip(axes, series, strict=False):
        v = np.asarray(s.data[name]).reshape(2, n) * scale
        finite = v[ok & np.isfinite(v)]
        lo, hi = (finite.min(), finite.max()) if finite.size else (0.0, 1.0)
        bins = np.linspace(lo, hi if hi > lo else lo + 1e-9, 21)
        for k, (lab, col) in enumerate(zip(labels, ("tab:red", "tab:green"), strict=True)):
            ax.hist(v[k][ok[k]], bins=bins, alpha=0.55, color=col, label=lab)
        ax.axvline(thr, color="k", ls="--", lw=1, label="hazard threshold")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("members [-]")
        ax.set_title(xlabel.split(" [")[0].split(" /")[0])
    axes[0].legend(fontsize=8)
    ax = axes[3]
    t = np.linspace(0.0, t1, 400)
    for design, lab, col in ((res.start, labels[0], "tab:red"), (res.design, labels[1], "tab:green")):
        hoist = eqx.tree_at(lambda h: h.speeds, sc_knots.hoist, jnp.asarray([design[k] for k in KNOTS]))
        ax.plot(t, np.asarray(hoist.speed_at(jnp.asarray(t))), color=col, label=lab.split(":")[0])
        ax.plot(KNOT_TIMES, [design[k] for k in KNOTS], "o", color=col)
    ax.axhline(SPEED_BOUNDS[1], color="k", ls=":", lw=1, label="maximum speed")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("hoist speed [m/s]")
    ax.set_title("hoist speed profile")
    ax.legend(fontsize=8)
    fig.suptitle(
        f"paper-4.2 over {float(s.ts[-1]):g} s: outcomes of the preset and the optimised lift over a fresh "
        f"sample of {n} (μ, ξ_C); design = tip (x, y) and the hoist speeds at "
        f"{', '.join(f'{k:g}' for k in KNOT_TIMES)} s"
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
