"""Lift-planning map from the rigid-ground statics (paper §2.1, conditions 2.9): for every boom-tip position A
on a horizontal grid, what happens first to the resting load as the rope force grows along A - B (the
rope direction at the start of the lift), and at which pull.

    python experiments/lift_planning_map.py --out out/lift_map            # 121 x 121 grid, preset paper-4.1
    python experiments/lift_planning_map.py --out out/lift_map --quick         # 31 x 31 grid
    python experiments/lift_planning_map.py --out out/lift_map --mu 0.6 --slip     # a rougher ground

For each A the rope-force magnitudes at which the load lifts (N = 0), slides (T = μN), twists, or tips
(R leaves the base, about an edge or a corner) come from `jaxhoist.physics.statics` in closed form; the
smallest one names the first failure. The rope point B is on the box, so the friction resultant's line of
action always crosses the base and the paper's twist condition never fails first (checked, not assumed:
`twist_threshold` is evaluated where B lies outside the footprint). With `--slip` the exact corner-friction
limit ρ* = 1 is also computed (1-D root finding per grid point; slower), and the map shows where it comes
before the paper's T = μN.

Writes `lift_map.png` (first failure and the pull at which it happens, in units of the weight G),
`lift_map.npz`, and prints the shares of the map and the numbers at the preset's own boom tip.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist  # noqa: E402
from jaxhoist.physics import statics  # noqa: E402

KINDS = ("slide", "tip-edge", "tip-corner", "lift", "twist", "none")


def first(scenario, A, B, with_slip: bool, inside: bool):
    e = np.asarray(A, float) - B
    th = {"lift": statics.lift_threshold(scenario, e), "slide": statics.slide_threshold(scenario, e)}
    s_tip, kind, _ = statics.tip_threshold(scenario, e)
    th[kind or "tip-edge"] = s_tip
    th["twist"] = math.inf if inside else statics.twist_threshold(scenario, e)
    name = min(th, key=th.get)
    s = th[name]
    slip = statics.slip_threshold(scenario, e) if with_slip else math.nan
    return ("none" if not math.isfinite(s) else name), s, th["slide"], slip


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="31 x 31 grid instead of 121 x 121")
    p.add_argument("--preset", default="paper-4.1")
    p.add_argument("--height", type=float, default=None,
                   help="boom-tip height Z_A [m] (default: the preset's)")
    p.add_argument("--extent", type=float, default=15.0, help="half-width of the grid around the load [m]")
    p.add_argument("--mu", type=float, default=None, help="friction coefficient μ (default: the preset's)")
    p.add_argument("--slip", action="store_true", help="also the exact corner-friction limit (slow)")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = jaxhoist.load_scenario(args.preset)
    if args.mu is not None:
        sc = sc.replace(**{"foundation.friction_coefficient": args.mu})
    size = np.asarray(sc.load.size)
    B = np.asarray(sc.rope.attachment)
    A0 = np.asarray(sc.boom.tip_position)
    z = A0[2] if args.height is None else args.height
    G = float(sc.load.mass * sc.gravity)
    n = 31 if args.quick else 121
    if args.slip:
        n = min(n, 41)
    cx, cy = size[0] / 2, size[1] / 2
    xs = np.linspace(cx - args.extent, cx + args.extent, n)
    ys = np.linspace(cy - args.extent, cy + args.extent, n)
    inside = bool(0 <= B[0] <= size[0] and 0 <= B[1] <= size[1])

    t0 = time.perf_counter()
    kind = np.zeros((n, n), dtype=int)
    pull = np.full((n, n), np.nan)
    slide = np.full((n, n), np.nan)
    slip = np.full((n, n), np.nan)
    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            name, s, s_slide, s_slip = first(sc, [x, y, z], B, args.slip, inside)
            kind[j, i] = KINDS.index(name)
            pull[j, i] = s / G
            slide[j, i] = s_slide / G
            slip[j, i] = s_slip / G
    elapsed = time.perf_counter() - t0

    name0, s0, sl0, sp0 = first(sc, A0, B, True, inside)
    mu = float(sc.foundation.friction_coefficient)
    print(f"{args.preset}: load {size.tolist()} m, G = {G:.6g} N, μ = {mu}, "
          f"rope point B = {B.tolist()} m, boom tip height {z:g} m; {n} x {n} grid in {elapsed:.1f} s")
    for k, nm in enumerate(KINDS):
        share = float(np.mean(kind == k))
        if share > 0:
            print(f"  first failure {nm:10s}: {100 * share:5.1f} % of the map")
    print(f"at the preset's tip A = {A0.tolist()}: first '{name0}' at |S| = {s0:.6g} N = {s0 / G:.4f} G "
          f"(slide {sl0 / G:.4f} G; exact corner-friction slip {sp0 / G:.4f} G)")
    if args.slip:
        ok = np.isfinite(slip) & np.isfinite(slide)
        share = 100 * np.mean(slip[ok] < slide[ok] * (1 - 1e-9))
        print(f"  exact slip before T = μN on {share:.1f} % of the "
              f"sliding points, by up to {100 * np.nanmax(1 - slip[ok] / slide[ok]):.1f} %")
    np.savez(out / "lift_map.npz", xs=xs, ys=ys, z=z, kind=kind, kinds=np.array(KINDS), pull_G=pull,
             slide_G=slide, slip_G=slip, B=B, size=size)

    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    colours = ["tab:blue", "tab:orange", "tab:red", "tab:green", "tab:purple", "0.8"]
    ncol = 3 if args.slip else 2
    fig = Figure(figsize=(5.2 * ncol, 5.0), layout="constrained")
    ax = fig.subplots(1, ncol)
    ext = (xs[0], xs[-1], ys[0], ys[-1])
    ax[0].imshow(kind, origin="lower", extent=ext, cmap=ListedColormap(colours), vmin=-0.5,
                 vmax=len(KINDS) - 0.5, interpolation="nearest")
    for k, nm in enumerate(KINDS):
        if np.any(kind == k):
            ax[0].plot([], [], "s", color=colours[k], label=nm)
    ax[0].legend(fontsize=8, loc="upper left")
    ax[0].set_title("first failure of the rest conditions (2.9)")
    cs = ax[1].contourf(xs, ys, pull, levels=20, cmap="viridis")
    fig.colorbar(cs, ax=ax[1], label="|S| at the first failure [G]")
    ax[1].set_title("rope pull at which the load first moves [G]")
    if args.slip:
        cs = ax[2].contourf(xs, ys, 100 * (1 - slip / slide), levels=20, cmap="magma")
        fig.colorbar(cs, ax=ax[2], label="[%]")
        ax[2].set_title("exact slip pull below μN-slide pull")
    for a in ax:
        a.add_patch(__import__("matplotlib.patches", fromlist=["Rectangle"]).Rectangle(
            (0, 0), size[0], size[1], fill=False, color="k", lw=1.2))
        a.plot(*B[:2], "k^", ms=6)
        a.plot(*A0[:2], "w*", ms=10, mec="k")
        a.set_xlabel("boom tip X_A [m]")
        a.set_ylabel("boom tip Y_A [m]")
        a.set_aspect("equal")
    fig.suptitle(f"{args.preset}: lift-planning map at boom-tip height Z_A = {z:g} m "
                 f"(box: load footprint, ▲: rope point B, ★: preset tip)")
    fig.savefig(out / "lift_map.png", dpi=110)
    print(f"wrote {out}/lift_map.png, lift_map.npz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
