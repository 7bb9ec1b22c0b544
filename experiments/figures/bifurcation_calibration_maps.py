"""The maps behind paper-4.3's calibration: where, over the unknowns the paper omits (mass centre, rope
fixture among the top corners), the 25 s history of the §4.2 container changes character near μ = 0.3635.

Four scans (all at the preset's ε = 1e-3 m/s, Tsit5 rtol 1e-6, saves every 10 ms, 25 s; resumable with
the same --out), and one figure:

- `corners`: 4 fixtures × ξ_C ∈ {0.75 ... 1.75} × η_C ∈ {2 ... 4} × ζ_C ∈ {0.75, 1, 1.25} m (300 combinations)
  × 61 μ over [0.30, 0.45]: 18 300 solves;
- `xi-ramp`: paper-4.2's mass centre with ξ_C ∈ [1.0, 1.25] (21) × 151 μ over [0.30, 0.45]: the preset's
  steep ψ(t1) ramp at μ = 0.4547 followed down in μ as ξ_C grows;
- `xi-theta`: η_C = 3.18, ζ_C = 0.83 m, ξ_C ∈ [1.05, 1.30] (26) × 71 μ over [0.345, 0.38]: the ramp of the
  final attitude that paper-4.3 puts at μ* = 0.3635;
- `random`: 480 mass centres drawn uniformly from the plausible box (ξ_C ∈ [0.75, 1.75], η_C ∈ [1.5, 4.5],
  ζ_C ∈ [0.6, 1.25] m) with a random top-corner fixture, each at 20 μ over [0.354, 0.373] (Δμ = 1e-3):
  how often any plausible choice has a sharp final-state change near 0.3635 (9 600 solves).

`calibration_maps.png`: (a) ψ(t1) over (μ, ξ_C) of `xi-ramp`, (b) ϑ(t1) over (μ, ξ_C) of `xi-theta` with
the ϑ(t1) = 15° contour and paper-4.3's point, (c) the largest final-state step between neighbouring μ of each
`random` combination (a step is max(|Δx|, |Δy| in 0.1 m, |Δφ|, |Δϑ|, |Δψ| in degrees)).

    XLA_FLAGS=--xla_force_host_platform_device_count=16 JAX_PLATFORMS=cpu \\
        python experiments/figures/bifurcation_calibration_maps.py --out out/cal-maps  # 16 cores: ~6 min
        python experiments/figures/bifurcation_calibration_maps.py --out out/cal-maps --quick  # smoke check

Measured on 16 CPU host devices: corners 194 s, xi-ramp 30 s, xi-theta 20 s, random 83 s; on this project's
2 shared cores expect ~10x that.
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import ScanResult, set_param  # noqa: E402

MU = "foundation.friction_coefficient"
C = "load.mass_centre"
A = "rope.attachment"
OBS = [
    "final_x",
    "final_y",
    "final_phi",
    "final_theta",
    "final_psi",
    "liftoff_time",
    "last_contact_time",
    "impacts",
]
FIXTURES = [(0.0, 0.0), (2.5, 0.0), (0.0, 6.0), (2.5, 6.0)]  # top corners above D, E, H, F (body axes)
KW = dict(observables=OBS, progress=True)
TIMES = jh.Times(25.0, n=2501)  # every 10 ms over the 25 s lift


def step_size(res, n_mu):
    """Largest final-state step between neighbouring μ per combination (members laid out μ fastest)."""
    n = res.ok.size // n_mu
    s = np.zeros((n, n_mu - 1))
    for k, scale in [
        ("final_x", 10.0),
        ("final_y", 10.0),
        ("final_phi", np.degrees(1)),
        ("final_theta", np.degrees(1)),
        ("final_psi", np.degrees(1)),
    ]:
        y = np.asarray(res[k]).reshape(n, n_mu)
        s = np.maximum(s, np.abs(np.diff(y, axis=1)) * scale)
    return s


def run(which, out, base, quick=False):
    if which == "corners":
        mus = np.linspace(0.30, 0.45, 61)
        rows = list(
            itertools.product(
                FIXTURES, [0.75, 1.0, 1.25, 1.5, 1.75], [2.0, 2.5, 3.0, 3.5, 4.0], [0.75, 1.0, 1.25]
            )
        )
        pts = {MU: [], f"{C}[0]": [], f"{C}[1]": [], f"{C}[2]": [], f"{A}[0]": [], f"{A}[1]": []}
        for (fa, fb), x, e, z in rows:
            for m in mus:
                for k, v in zip(pts, (m, x, e, z, fa, fb), strict=True):
                    pts[k].append(v)
        return jh.scan(
            base, jh.Points({k: np.array(v) for k, v in pts.items()}), TIMES, out_dir=out / which, **KW
        )
    if which == "xi-ramp":
        return jh.scan(
            base,
            jh.Grid({MU: np.linspace(0.30, 0.45, 151), f"{C}[0]": np.linspace(1.0, 1.25, 21)}),
            TIMES,
            out_dir=out / which,
            **KW,
        )
    if which == "xi-theta":
        sc = set_param(set_param(base, f"{C}[1]", 3.18), f"{C}[2]", 0.83)
        return jh.scan(
            sc,
            jh.Grid(
                {
                    MU: np.linspace(0.345, 0.38, 4 if quick else 71),
                    f"{C}[0]": np.linspace(1.05, 1.30, 3 if quick else 26),
                }
            ),
            jh.Times(2.0, n=21) if quick else TIMES,
            out_dir=out / which,
            **KW,
        )
    if which == "random":
        rng = np.random.default_rng(13)
        n = 480
        x, e, z = rng.uniform(0.75, 1.75, n), rng.uniform(1.5, 4.5, n), rng.uniform(0.6, 1.25, n)
        f = rng.integers(0, 4, n)
        mus = np.round(np.arange(0.354, 0.3731, 1e-3), 6)
        m = mus.size
        pts = {
            MU: np.tile(mus, n),
            f"{C}[0]": np.repeat(x, m),
            f"{C}[1]": np.repeat(e, m),
            f"{C}[2]": np.repeat(z, m),
            f"{A}[0]": np.repeat(np.array(FIXTURES)[f, 0], m),
            f"{A}[1]": np.repeat(np.array(FIXTURES)[f, 1], m),
        }
        return jh.scan(base, jh.Points(pts), TIMES, out_dir=out / which, **KW)
    raise SystemExit(f"unknown map {which!r}")


def figure(res, out, dpi):
    fig, axes = plt.subplots(1, 3, figsize=(18, 5.2))
    if "xi-ramp" in res:
        r = res["xi-ramp"]
        mus, xs = r.coords[MU], r.coords[f"{C}[0]"]
        im = axes[0].pcolormesh(
            mus, xs, np.degrees(np.asarray(r["final_psi"])).T, shading="nearest", cmap="twilight"
        )
        fig.colorbar(im, ax=axes[0], label="ψ(t1) [°]")
        axes[0].set(
            xlabel="μ",
            ylabel="ξ_C [m]",
            title="(a) paper-4.2's ψ(t1) ramp (μ = 0.4547 at ξ_C = 1)\nmoves down and widens as ξ_C grows",
        )
        axes[0].axvline(0.3635, color="r", lw=0.8)
    if "xi-theta" in res:
        r = res["xi-theta"]
        mus, xs = r.coords[MU], r.coords[f"{C}[0]"]
        th = np.degrees(np.asarray(r["final_theta"])).T
        im = axes[1].pcolormesh(mus, xs, th, shading="nearest", cmap="viridis")
        fig.colorbar(im, ax=axes[1], label="ϑ(t1) [°]")
        axes[1].contour(mus, xs, th, levels=[15.0], colors="w", linewidths=1.0)
        sc = jh.load_scenario("paper-4.3")
        axes[1].plot([0.3635], [float(sc.load.mass_centre[0])], "r*", ms=12, label="paper-4.3")
        axes[1].legend(loc="upper right")
        axes[1].set(
            xlabel="μ",
            ylabel="ξ_C [m]",
            title="(b) η_C = 3.18, ζ_C = 0.83 m: ϑ(t1), 15° contour\n"
            "(the ramp paper-4.3 puts at μ* = 0.3635)",
        )
    if "random" in res:
        s = step_size(res["random"], 20)
        mx = s.max(axis=1)
        axes[2].hist(mx, bins=np.logspace(-2, 2.5, 46))
        axes[2].set_xscale("log")
        axes[2].axvline(50, color="r", lw=0.8)
        axes[2].set(
            xlabel="largest final-state step between neighbouring μ (Δμ = 1e-3) [° or 0.1 m]",
            ylabel="mass centres / fixtures",
            title=f"(c) 480 random plausible choices, μ ∈ [0.354, 0.373]:\n"
            f"{int((mx > 20).sum())} with a step > 20, {int((mx > 50).sum())} > 50",
        )
    fig.tight_layout()
    path = out / "calibration_maps.png"
    fig.savefig(path, dpi=dpi)
    print("wrote", path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--maps", default="corners,xi-ramp,xi-theta,random")
    p.add_argument("--dpi", type=int, default=80)
    p.add_argument(
        "--load",
        default="",
        help="name=path.npz,...: read a map saved by ScanResult.save "
        "instead of scanning (e.g. one run elsewhere)",
    )
    p.add_argument("--quick", action="store_true", help="smoke check: xi-theta, 4 x 3 members, 2 s")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
        args.maps = "xi-theta"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base = jh.load_scenario("paper-4.2")
    loaded = dict(kv.split("=", 1) for kv in args.load.split(",") if kv)
    names = [w for w in args.maps.split(",") if w]
    res = {w: ScanResult.load(loaded[w]) if w in loaded else run(w, out, base, args.quick) for w in names}
    if "corners" in res:
        s = step_size(res["corners"], 61)
        mus = np.linspace(0.30, 0.45, 61)
        near = (mus[1:] > 0.355) & (mus[:-1] < 0.372)
        print(
            f"corners: combinations with a final-state step > 30 [° or 0.1 m] between neighbouring μ "
            f"anywhere: {int((s.max(axis=1) > 30).sum())} of {s.shape[0]}; within [0.355, 0.372]: "
            f"{int((s[:, near].max(axis=1) > 30).sum())}"
        )
    figure(res, out, args.dpi)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
