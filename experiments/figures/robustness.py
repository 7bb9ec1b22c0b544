"""Robustness of the default solver on random plausible scenarios: each is solved by the default solver
(Rosenbrock-W, default tolerances) and by a tight reference (Tsit5 at rtol 1e-9, atol 1e-10); every member
either agrees with the reference within 1 cm (the load's mass-centre path, max over the saved times) or is
marked by its status (max_steps, non-finite, energy_balance, ...). A member with status ok that is more
than 1 cm off is counted as "silently off".

The scenarios vary around paper-4.2: friction 0.05-0.9, ground 1e6-1e9 N/m, regularisation velocity
1e-4-1e-2 m/s, rope 1e6-1e8 N/m, hoist 0.05-1 m/s, boom stiffness 1e6-5e7 N/m, the mass centre inside the
box and the boom tip's position.

    PYTHONPATH=$PWD python experiments/robustness.py --quick   # 1 seed x 6 scenarios over 2 s (minutes)
    PYTHONPATH=$PWD python experiments/robustness.py           # 4 seeds x 48 scenarios over 8 s (heavy)
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

TOLERANCE = 0.01  # [m]: agreement of the mass-centre path with the reference
REFERENCE = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-9, atol=1e-10, max_steps=2_000_000)


def random_scenarios(base: jh.Scenario, n: int, seed: int) -> list[tuple[dict, jh.Scenario]]:
    """`n` random plausible scenarios around `base` (paper-4.2), with the values drawn."""
    rng = np.random.default_rng(seed)

    def log_uniform(a, b):
        return float(10 ** rng.uniform(np.log10(a), np.log10(b)))

    out = []
    for _ in range(n):
        values = {
            "foundation.friction_coefficient": rng.uniform(0.05, 0.9),
            "foundation.stiffness": log_uniform(1e6, 1e9),
            "foundation.friction.regularisation_velocity": log_uniform(1e-4, 1e-2),
            "rope.stiffness": log_uniform(1e6, 1e8),
            "hoist.speed": rng.uniform(0.05, 1.0),
            "boom.stiffness": log_uniform(1e6, 5e7),
            "load.mass_centre": rng.uniform([0.6, 1.5, 0.6], [1.9, 4.5, 1.9]),
            "boom.tip_position": rng.uniform([1.0, 2.0, 8.0], [5.0, 6.0, 14.0]),
        }
        out.append((values, base.replace(**values)))
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 seed x 6 scenarios over 2 s")
    ap.add_argument("--seeds", type=int, default=4, help="number of seeds (full mode)")
    args = ap.parse_args(argv)
    seeds, n, t1 = ((0,), 6, 2.0) if args.quick else (tuple(range(args.seeds)), 48, 8.0)
    base = jh.load_scenario("paper-4.2")
    times = jh.Times(t1, n=201)
    counts = {"agree": 0, "marked": 0, "silently off": 0}
    head = ("seed", "i", "status", "ref", "max |dC| m", "energy", "verdict", "s")
    print("{:>4s} {:>3s} {:14s} {:10s} {:>11s} {:>9s} {:12s} {:>6s}".format(*head))
    for seed in seeds:
        for i, (_, sc) in enumerate(random_scenarios(base, n, seed)):
            t0 = time.perf_counter()
            tr = jh.simulate(sc, times, throw=False)
            ref = jh.simulate(sc, times, options=REFERENCE, throw=False)
            status = jh.SolveStatus(int(tr.status)).name.lower()
            ref_status = jh.SolveStatus(int(ref.status)).name.lower()
            diff = float(np.max(np.linalg.norm(np.asarray(tr.position) - np.asarray(ref.position), axis=-1)))
            if status != "ok":
                verdict = "marked"
            elif diff <= TOLERANCE:
                verdict = "agree"
            else:
                verdict = "silently off"
            counts[verdict] += 1
            print(
                f"{seed:4d} {i:3d} {status:14s} {ref_status:10s} {diff:11.2e} "
                f"{float(tr.energy_check()):9.1e} {verdict:12s} {time.perf_counter() - t0:6.1f}",
                flush=True,
            )
    total = sum(counts.values())
    print(f"{total} scenarios over {t1:g} s: " + ", ".join(f"{k} {v}" for k, v in counts.items()))


if __name__ == "__main__":
    main()
