"""Two-parameter regime map of paper-4.2 in (μ, v_l) around the lift-off-time jump that
`experiments/bifurcation_mu.py` locates and continues in the hoist speed: a grid scan of the lift-off time
behind the boundary μ*(v_l) traced by continuation (`trace_boundary`), which should separate the two regimes.

    python experiments/bifurcation_mu.py --out out/bifurcation-mu     # first: locates μ* and traces μ*(v_l)
    python experiments/regime_map.py --out out/regime-map --trace out/bifurcation-mu/bifurcation_mu.json
    python experiments/regime_map.py --out out/regime-map --quick     # 8 x 3 grid over 4 s, no trace file

The grid uses the diagram's settings (25 s, 2501 saved times, rtol 1e-6, atol 1e-8, the preset's ε), so
its cells agree with the diagram's scan. Writes `regime_map.png`, `regime_map.npz` (the scan) and prints
how many grid cells lie on the side of the traced boundary that their lift-off time says.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU, VL = "foundation.friction_coefficient", "hoist.speed"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--trace", default=None, help="bifurcation_mu.json with a 'trace' of μ*(v_l)")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--n-mu", type=int, default=None, help="μ values (default 41; quick 8)")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = jh.load_scenario("paper-4.2")
    trace = None
    if args.trace:
        trace = json.loads(Path(args.trace).read_text())["trace"]
        v_tr, mu_tr = np.array(trace["hoist_speed"]), np.array(trace["mu_star"])
        order = np.argsort(v_tr)
        v_tr, mu_tr = v_tr[order], mu_tr[order]
        speeds = np.unique(v_tr)
        spread = max(mu_tr.max() - mu_tr.min(), 1e-5)
        mus = np.linspace(mu_tr.min() - 1.5 * spread, mu_tr.max() + 1.5 * spread, args.n_mu or 41)
        t1, n_save = 25.0, 2501
    else:
        speeds = np.array([0.26, 0.3, 0.34])
        mus = np.linspace(0.45, 0.5, args.n_mu or 8)
        t1, n_save = (4.0, 401) if args.quick else (25.0, 2501)
    res = jh.scan(
        sc,
        {MU: mus, VL: speeds},
        t1,
        mode="grid",
        observables=["liftoff_time"],
        n_save=n_save,
        rtol=1e-6,
        atol=1e-8,
        out_dir=out / "scan",
        progress=True,
    )
    t_lift = res["liftoff_time"]  # (n_mu, n_v)
    np.savez(out / "regime_map.npz", mu=mus, hoist_speed=speeds, liftoff_time=t_lift, status=res.status)
    print(
        f"{mus.size} x {speeds.size} grid, {int(np.sum(~res.ok))} failed, "
        f"{res.attrs['timings_s']['total']:.0f} s (compile {res.attrs['timings_s']['compile']:.0f} s)"
    )

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5), layout="constrained")
    pc = ax.pcolormesh(mus, speeds, t_lift.T, shading="nearest", cmap="viridis")
    fig.colorbar(pc, ax=ax, label="lift-off time [s]")
    if trace is not None:
        ax.plot(mu_tr, v_tr, "o-", color="w", mec="k", lw=1.5, label="μ*(v_l), traced by continuation")
        ax.legend(loc="upper left", fontsize=8)
        # Which side of the boundary each cell is on, against what its lift-off time says (the jump is a
        # drop of the lift-off time as μ crosses μ*): split each row at its largest drop.
        agree = 0
        for j, v in enumerate(speeds):
            row = t_lift[:, j]
            k = int(np.nanargmin(np.diff(row)))  # the largest drop between neighbours
            mu_split = 0.5 * (mus[k] + mus[k + 1])
            mu_star = float(np.interp(v, v_tr, mu_tr))
            same = abs(mu_split - mu_star) <= 0.5 * (mus[1] - mus[0]) + 1e-12
            agree += same
            print(
                f"  v_l = {v:.3f} m/s: largest drop of the lift-off time between μ = {mus[k]:.7f} and "
                f"{mus[k + 1]:.7f} ({row[k]:.3f} -> {row[k + 1]:.3f} s); traced μ* = {mu_star:.7f} "
                f"({'inside' if same else 'OUTSIDE'} that cell)"
            )
        print(f"the traced boundary lies in the cell of the largest drop on {agree} of {speeds.size} rows")
    ax.set_xlabel("friction coefficient μ [-]")
    ax.set_ylabel("hoist speed v_l [m/s]")
    ax.set_title("paper-4.2: lift-off time over (μ, v_l) and the traced boundary")
    fig.savefig(out / "regime_map.png", dpi=110)
    print(f"wrote {out}/regime_map.png, regime_map.npz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
