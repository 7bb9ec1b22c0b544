"""Friction laws compared on paper-4.2: solver steps, wall time and accuracy against the Coulomb limit.

The reference is the regularised Coulomb law at a tiny ε with tight tolerances (the paper's Coulomb law
is the ε -> 0 limit). For each law we report accepted/rejected steps, wall time after compilation (as a
ratio to the ε = 1e-2 run of the same process), and the mass-centre distance from the reference at
t = 5 s and at the end.

    python experiments/figures/friction_laws.py --out out/friction            # full (25 s horizon)
    python experiments/figures/friction_laws.py --out out/friction --quick    # 5 s horizon, fewer laws
"""

import argparse
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402


def run(scenario, law, t1, rtol=1e-6, atol=1e-8):
    sc = eqx.tree_at(lambda s: s.foundation.friction, scenario, law)
    ts = np.linspace(0.0, t1, int(round(t1 * 10)) + 1)
    opts = jh.SolverOptions(rtol=rtol, atol=atol, max_steps=2_000_000)
    tr = jh.simulate(sc, jh.Times(ts=ts), options=opts)  # compile
    jax.block_until_ready(tr)
    t0 = time.perf_counter()
    tr = jax.block_until_ready(jh.simulate(sc, jh.Times(ts=ts), options=opts))
    return tr, time.perf_counter() - t0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/friction_laws")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--scenario", default="paper-4.2")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = jh.load_scenario(args.scenario)
    t1 = 5.0 if args.quick else sc.t1
    ref_eps = 1e-4 if not args.quick else 3e-4
    laws = [
        ("coulomb eps=1e-2", jh.RegularisedCoulomb(1e-2)),
        ("coulomb eps=1e-3", jh.RegularisedCoulomb(1e-3)),
        ("bristle d=1e-3 rb=0", jh.BristleFriction(1e-3, 0.0)),
        ("bristle d=1e-3 rb=0.5", jh.BristleFriction(1e-3, 0.5)),
    ]
    if not args.quick:
        laws += [
            ("coulomb eps=3e-3", jh.RegularisedCoulomb(3e-3)),
            ("coulomb eps=3e-4", jh.RegularisedCoulomb(3e-4)),
            ("bristle d=1e-3 rb=0.7", jh.BristleFriction(1e-3, 0.7)),
            ("bristle d=3e-4 rb=0.5", jh.BristleFriction(3e-4, 0.5)),
        ]
    ref, t_ref = run(sc, jh.RegularisedCoulomb(ref_eps), t1, rtol=1e-8, atol=1e-10)
    i5 = int(np.argmin(np.abs(np.asarray(ref.ts) - min(5.0, t1))))
    rows, base = [], None
    for name, law in laws:
        tr, wall = run(sc, law, t1)
        base = wall if base is None else base
        d5 = float(np.linalg.norm(np.asarray(tr.position[i5] - ref.position[i5])))
        d1 = float(np.linalg.norm(np.asarray(tr.position[-1] - ref.position[-1])))
        rows.append(
            (
                name,
                int(tr.num_accepted_steps),
                int(tr.num_rejected_steps),
                wall,
                wall / base,
                d5,
                d1,
                float(np.max(np.abs(np.asarray(tr.energy_residual())))),
            )
        )
        print(
            f"{name:24s} steps {rows[-1][1]:7d} rej {rows[-1][2]:6d} wall {wall:6.2f} s "
            f"({wall / base:4.2f}x) |dC|(t=5) {d5 * 100:7.3f} cm |dC|(t1) {d1 * 100:7.3f} cm",
            flush=True,
        )
    lines = [
        f"Friction laws on {args.scenario}, t1 = {t1} s, Tsit5 rtol 1e-6 atol 1e-8; reference: regularised "
        f"Coulomb eps = {ref_eps:g} m/s at rtol 1e-8 ({int(ref.num_accepted_steps)} steps, {t_ref:.1f} s).",
        "",
        "| law | accepted steps | rejected | wall [s] | wall / first row | dist. to ref. at 5 s [cm] "
        "| at t1 [cm] | max energy residual [J] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.2f} | {r[4]:.2f} | {r[5] * 100:.3f} | {r[6] * 100:.2f} "
            f"| {r[7]:.2e} |"
        )
    (out / "friction_laws.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
