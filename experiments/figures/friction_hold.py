"""A load held by a steady pull below μN: drift and solver steps for both friction laws.

    python experiments/figures/friction_hold.py --out out/friction_hold [--quick]

A uniform 37.5 t box is pulled horizontally through a rope at mid-height of its η = 0 face; a ramped hoist
takes in 66 mm of rope and stops at t ≈ 1.8 s, leaving a pull of about 0.5 μmg for the rest of the run.
"""

import argparse
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU = 0.3


def scenario(law, t1):
    return jh.Scenario(
        load=jh.Load([2.5, 6.0, 2.5], density=1000.0),
        foundation=jh.Foundation(1.5e7, 2e5, MU, law),
        rope=jh.Rope(1e6, 1e4, [1.25, 0.0, 1.25]),
        hoist=jh.RampedHoist(0.05, 0.5, 0.066),
        boom=jh.Boom([1.25, -20.0, 1.244], 500.0, 5e6, 5e3),
        t1=t1,
    )


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/friction_hold")
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    t1 = 6.0 if args.quick else 10.0
    ts = np.linspace(0.0, t1, int(t1 * 20) + 1)
    lines = [
        f"Hold of a 37.5 t box at T ~ 0.5 mu m g, t1 = {t1} s (`python experiments/figures/friction_hold.py"
        f"{' --quick' if args.quick else ''}`)",
        "",
        "| law | drift of C, window [2.5,3] s -> [t1-0.5,t1] s [mm] | predicted creep [mm] | accepted steps |"
        " wall after compile [s] |",
        "|---|---|---|---|---|",
    ]
    for name, law in [
        ("RegularisedCoulomb(1e-3)", jh.RegularisedCoulomb(1e-3)),
        ("BristleFriction()", jh.BristleFriction()),
    ]:
        sc = scenario(law, t1)
        jax.block_until_ready(jh.simulate(sc, jh.Times(ts=ts)))
        t0 = time.perf_counter()
        tr = jax.block_until_ready(jh.simulate(sc, jh.Times(ts=ts)))
        wall = time.perf_counter() - t0
        y = np.asarray(tr.position[:, 1])
        r = np.asarray(tr.rope_tension) / (MU * np.asarray(tr.ground_reaction))
        w1, w2 = (ts >= 2.5) & (ts <= 3.0), ts >= t1 - 0.5
        drift = y[w2].mean() - y[w1].mean()
        c = (ts >= 2.75) & (ts <= t1 - 0.25)
        pred = -np.trapezoid(1e-3 * r[c] / np.sqrt(1 - r[c] ** 2), ts[c]) if "Coulomb" in name else 0.0
        lines.append(
            f"| {name} | {drift * 1e3:.3g} | {pred * 1e3:.3g} | {int(tr.num_accepted_steps)} | {wall:.2f} |"
        )
        print(lines[-1], flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "friction_hold.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
