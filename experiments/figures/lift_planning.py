"""Plan the lift of the paper's §4.2 container (preset `paper-4.2`) under uncertainty: hazard maps over the
boom tip's position, and an optimised lift against the preset's.

    python experiments/lift_planning.py --out out/lift_planning            # 9 x 9 tips, 64 samples each
    python experiments/lift_planning.py --out out/lift_planning --quick    # 6 s, 3 x 3 tips, 4 samples

Uncertain inputs: the friction coefficient μ ~ U(0.2, 0.5) and the mass centre's ξ_C (`load.mass_centre[0]`)
~ N(1.0 m, 0.1 m). Hazards:
- `slide`: the container is dragged more than 0.5 m over the ground (`ground_slide`);
- `tip`: it tilts more than 70° while a corner still touches the ground (`ground_tilt`, defined here: the
  largest angle between the body ζ axis and the vertical at the saved times with a corner in contact). The
  corner fixture lifts the container by a corner: it hangs at 61° (nominal mass centre), so every lift
  tilts it that far on its way up; beyond 70° it has rolled further over an edge than the lift needs;
- `strike`: a corner lands again after it left the ground (`impacts`);
- `overload`: the peak rope tension exceeds 1.2 m g (`max_rope_tension`).

1. `lift_risk` maps each hazard's probability over a grid of boom-tip positions (x, y) at the preset's
   height and hoist speed (every tip sees the same samples).
2. `optimise_lift` chooses the tip's (x, y) and the hoist speed within bounds to minimise
   E[peak tension] / (m g) + E[ground slide] / (1 m) + (time to reel in 6 m of rope) / (60 s), plus a
   softplus penalty of the slide and overload observables over their thresholds, over a fixed sample
   (common random numbers), and checks the hazard limits at the preset and the optimum on a fresh sample.

Writes into --out: `risk_maps.png` (the four probability maps, the preset's tip and the optimum's marked),
`outcomes.png` (histograms of the peak tension, the ground slide and the ground tilt over the fresh sample,
the preset's lift against the optimised one), `risk_map.nc` (the map as netCDF), `results.json` (the
optimum, the objective's terms, the limits, solve counts and times), and prints the summaries.
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

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._numerics.observables import _tilt, contact_function  # noqa: E402  (internal helpers)

TIP_X, TIP_Y, SPEED = "boom.tip_position[0]", "boom.tip_position[1]", "hoist.speed"
MU, XI = "foundation.friction_coefficient", "load.mass_centre[0]"


def _ground_tilt(traj, scenario):
    """Largest tilt [rad] at the saved times at which some corner touches the ground."""
    on = jnp.max(contact_function(traj, scenario), axis=-1) > 0.0
    return jnp.max(jnp.where(on, _tilt(traj), 0.0))


GROUND_TILT = jh.Observable(
    "ground_tilt", _ground_tilt, "rad", "largest tilt while a corner touches the ground (saved times)"
)


def settings(quick: bool) -> dict:
    if quick:  # 6 s: the drag phase only; the full run's compiled programs, much shorter solves
        return dict(t1=6.0, n_save=121, nx=3, ny=3, map_samples=4, map_rep=2, opt_samples=4, iters=1,
                    check_samples=8, check_rep=2, max_steps=20_000)  # fmt: skip
    return dict(t1=25.0, n_save=501, nx=9, ny=9, map_samples=64, map_rep=8, opt_samples=32, iters=20,
                check_samples=256, check_rep=8, max_steps=200_000)  # fmt: skip


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="6 s, 3 x 3 tips, 4 samples, 1 iteration (smoke run)")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = settings(args.quick)
    sc = jh.load_scenario("paper-4.2")
    mass, g = float(sc.load.mass), float(sc.gravity)
    weight = mass * g
    times = jh.Times(cfg["t1"], n=cfg["n_save"])
    options = jh.SolverOptions(max_steps=cfg["max_steps"])
    uncertain = {MU: jh.Uniform(0.2, 0.5), XI: jh.Normal(1.0, 0.1)}
    hazards = [
        jh.slide(0.5),
        jh.Hazard("tip", GROUND_TILT, math.radians(70.0)),
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
        "median_ground_tilt_deg": np.degrees(risk.quantile("ground_tilt", 0.5)).round(1).tolist(),
    }
    print(f"map: {report['map']}")

    # 2. the optimised lift against the preset's
    t0 = time.perf_counter()
    res = jh.optimise_lift(
        sc,
        uncertain,
        {"max_rope_tension": 1.0 / weight, "ground_slide": 1.0, "hoist_time": 1.0 / 60.0},
        {TIP_X: (0.0, 4.0), TIP_Y: (0.0, 6.0), SPEED: (0.25, 0.45)},
        hazard_limits={hazards[0]: 0.1, hazards[1]: 0.1, hazards[2]: 0.2, hazards[3]: 0.05},
        hoist_distance=6.0,
        penalty=1.0,
        samples=cfg["opt_samples"],
        seed=0,
        times=times,
        max_iterations=cfg["iters"],
        check_samples=cfg["check_samples"],
        check_replicates=cfg["check_rep"],
        options=options,
        progress=True,
    )
    t_opt = time.perf_counter() - t0
    print(res.summary())
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
        "solves": res.solves,
        "converged": res.converged,
        "message": res.message,
        "limits": res.limit_table(),
        "wall_s": round(t_opt, 1),
    }
    (out / "results.json").write_text(json.dumps(report, indent=2) + "\n")
    plot_maps(out / "risk_maps.png", risk, xs, ys, hazards, sc, res, weight)
    plot_outcomes(out / "outcomes.png", res, weight)
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


def plot_outcomes(path, res, weight) -> None:
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
        ("ground_tilt", 180.0 / math.pi, "largest tilt on the ground [deg]", 70.0),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.3), constrained_layout=True)
    d0 = ", ".join(f"{v:.3g}" for v in res.start.values())
    d1 = ", ".join(f"{v:.3g}" for v in res.design.values())
    labels = (f"preset (x, y, v_l) = ({d0})", f"optimised ({d1})")
    for ax, (name, scale, xlabel, thr) in zip(axes, series, strict=True):
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
    fig.suptitle(
        f"paper-4.2 over {float(s.ts[-1]):g} s: outcomes of the preset and the optimised lift over a fresh "
        f"sample of {n} (μ, ξ_C); design = (tip x [m], tip y [m], hoist speed [m/s])"
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
