"""Analogues of the paper's Figs 10-12 (§4.3): histories of the calibrated container (preset paper-4.3) across
its located change at μ* = 0.3635.

- `fig10_x_y.png`: mass-centre x and y against t for μ = 0.30, 0.33, 0.36, 0.39, 0.42 (a wide sweep, Fig. 10a)
  and for μ = 0.363, 0.3635, 0.364, 0.365 (Fig. 10b);
- `fig11_y_phi.png`: y and φ for μ = 0.363, 0.3635, 0.364, 0.365 (Fig. 11), with μ = 0.360 and 0.367 (the
  ends of the ramp) thin and grey;
- `fig12_theta_psi.png`: ϑ and ψ for the same μ (Fig. 12).

Each panel marks every history's last contact (the real lift-off) with a dot. In paper-4.3 the change at
μ* = 0.3635 is a resolved ramp of the final attitude (ϑ(t1) from ~19.5° to ~10.5°, ψ(t1), φ(t1), y(t1) with
it, over ~4e-3 in μ) next to a jump of the lift-off time: the histories agree until the load leaves the
ground (~19-20 s) and separate after it (docs/bifurcation.md, "Calibrating to the paper's μ*").

    python experiments/figures/fig10_12_bifurcation.py --out docs/img       # ~1 min
    python experiments/figures/fig10_12_bifurcation.py --out out/fig10_12 --quick   # smoke check: 3 s

Prints, for every μ, the first all-off time, the last contact and the final state.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU = "foundation.friction_coefficient"
NEAR = (0.363, 0.3635, 0.364, 0.365)
ENDS = (0.360, 0.367)  # the ends of the ramp, drawn thin and grey
WIDE = (0.30, 0.33, 0.36, 0.39, 0.42)


def histories(sc, mus, t1, n_save):
    """Mass-centre position, Euler angles (φ, ψ, ϑ), first all-off and last contact time per μ."""
    res = jh.scan(
        sc,
        {MU: np.asarray(mus)},
        jh.Times(t1, n=n_save),
        batch=jh.BatchOptions(sort=False),
        observables=["liftoff_time", "last_contact_time", "final_position", "final_euler"],
        histories=["position", "euler"],
    )
    if not np.all(res.ok):
        raise SystemExit(f"solves failed: {res.failures()[:2]}")
    return res


def _panel(ax, ts, res, key, comp, mus, scale, ylabel, styles):
    lc = np.asarray(res["last_contact_time"])
    h = np.asarray(res.histories[key])[..., comp] * scale
    for i, m in enumerate(ENDS if len(h) > len(mus) else ()):
        ax.plot(ts, h[len(mus) + i], "-", color="0.6", lw=0.6, label=f"μ = {m:g} (ramp's ends)")
    for i, m in enumerate(mus):
        (line,) = ax.plot(ts, h[i], styles[i % len(styles)], lw=1.0, label=f"μ = {m:g}")
        if np.isfinite(lc[i]):
            ax.plot([lc[i]], [np.interp(lc[i], ts, h[i])], "o", color=line.get_color(), ms=4)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--t1", type=float, default=25.0)
    p.add_argument("--n-save", type=int, default=2501)
    p.add_argument("--dpi", type=int, default=90)
    p.add_argument("--quick", action="store_true", help="smoke check: 3 s, 151 saved times")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
        args.t1, args.n_save = 3.0, 151
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = jh.load_scenario("paper-4.3")
    near = histories(sc, NEAR + ENDS, args.t1, args.n_save)
    wide = histories(sc, WIDE, args.t1, args.n_save)
    ts = np.asarray(near.ts)
    for res, mus in ((wide, WIDE), (near, NEAR + ENDS)):
        for i, m in enumerate(mus):
            pos = np.asarray(res["final_position"])[i]
            eul = np.degrees(np.asarray(res["final_euler"])[i])
            t_off = float(np.asarray(res["liftoff_time"])[i])
            t_last = float(np.asarray(res["last_contact_time"])[i])
            print(
                f"mu = {m:<7g} first all-off {t_off:7.3f} s, last contact {t_last:7.3f} s; at t1 "
                f"x, y = {pos[0]:.3f}, {pos[1]:.3f} m, phi, psi, theta = {eul[0]:.1f}, {eul[1]:.1f}, "
                f"{eul[2]:.1f} deg"
            )
    styles = ["-", "--", "-.", ":", "-"]
    deg = np.degrees(1.0)
    # Fig. 10: x and y, a wide sweep (left) and across μ* (right)
    fig, axes = plt.subplots(2, 2, figsize=(12, 7), sharex=True)
    for col, (res, mus) in enumerate(((wide, WIDE), (near, NEAR))):
        _panel(axes[0, col], ts, res, "position", 0, mus, 1.0, "x [m]", styles)
        _panel(axes[1, col], ts, res, "position", 1, mus, 1.0, "y [m]", styles)
        axes[1, col].set_xlabel("t [s]")
        axes[0, col].legend(fontsize=8)
    axes[0, 0].set_title("(a) several μ")
    axes[0, 1].set_title("(b) across μ* = 0.3635")
    fig.suptitle("Fig. 10 analogue (paper-4.3): mass-centre x and y; dots: last contact")
    fig.tight_layout()
    fig.savefig(out / "fig10_x_y.png", dpi=args.dpi)
    for name, title, panels in (
        (
            "fig11_y_phi.png",
            "Fig. 11 analogue: y and φ across μ* = 0.3635",
            [("position", 1, 1.0, "y [m]"), ("euler", 0, deg, "φ [°]")],
        ),
        (
            "fig12_theta_psi.png",
            "Fig. 12 analogue: ϑ and ψ across μ* = 0.3635",
            [("euler", 2, deg, "ϑ [°]"), ("euler", 1, deg, "ψ [°]")],
        ),
    ):
        fig, axes = plt.subplots(2, 2, figsize=(12, 7), sharex="col", gridspec_kw={"width_ratios": [2, 1]})
        for row, (key, comp, scale, label) in enumerate(panels):
            for col in range(2):
                _panel(axes[row, col], ts, near, key, comp, NEAR, scale, label, styles)
            axes[row, 1].set_xlim(17.0, args.t1)
        axes[0, 0].legend(fontsize=8)
        axes[0, 1].set_title("from 17 s")
        for ax in axes[1]:
            ax.set_xlabel("t [s]")
        fig.suptitle(f"{title} (paper-4.3); dots: last contact")
        fig.tight_layout()
        fig.savefig(out / name, dpi=args.dpi)
    plt.close("all")
    names = ("fig10_x_y.png", "fig11_y_phi.png", "fig12_theta_psi.png")
    print("wrote", ", ".join(str(out / n) for n in names))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
