"""Robustness of the default solver on random plausible scenarios: each seed's scenarios are run as ONE scan
of `Points` members by the default solver (Rosenbrock-W, default tolerances, the scan's accuracy check forced
on: 16 members re-solved at a 1000x tighter tolerance) and as one scan by a tight reference (Tsit5 at rtol
1e-9, atol 1e-10, one member per lane). Every member either agrees with the reference within 1 cm (the load's
mass-centre path, max over the saved times) or is marked by its status (max_steps, non-finite,
energy_balance, ...), or its scan's accuracy report says that differences above 1 cm occur. A member with
status ok that is more than 1 cm off while its scan's report has no member over 1 cm is "silent".

The scenarios vary around paper-4.2: friction 0.05-0.9, ground 1e6-1e9 N/m, regularisation velocity
1e-4-1e-2 m/s, rope 1e6-1e8 N/m, hoist 0.05-1 m/s, boom stiffness 1e6-5e7 N/m, the mass centre inside the
box and the boom tip's position.

    python experiments/figures/robustness.py --quick   # 1 seed x 6 scenarios over 2 s (minutes)
    python experiments/figures/robustness.py           # 3 seeds x 48 scenarios over 8 s (heavy)
    python experiments/figures/robustness.py --seeds 1 --n 16   # what fits a busy machine
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._physics.paths import get_leaf  # noqa: E402

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


def members(scenarios: list[tuple[dict, jh.Scenario]]) -> jh.Points:
    """The drawn values as one `Points` sweep (a vector leaf as one path per component, as each scenario
    holds it: a number drawn for a vector leaf is every component)."""
    cols: dict[str, list[float]] = {}
    for values, sc in scenarios:
        for path in values:
            v = np.asarray(get_leaf(sc, path), dtype=float)
            if v.ndim == 0:
                cols.setdefault(path, []).append(float(v))
            else:
                for j, x in enumerate(v):
                    cols.setdefault(f"{path}[{j}]", []).append(float(x))
    return jh.Points(cols)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 seed x 6 scenarios over 2 s")
    ap.add_argument("--seeds", type=int, default=3, help="number of seeds (full mode)")
    ap.add_argument("--first-seed", type=int, default=0, help="the first seed (full mode)")
    ap.add_argument("--n", type=int, default=48, help="scenarios per seed (full mode)")
    ap.add_argument("--t1", type=float, default=8.0, help="horizon [s] (full mode)")
    args = ap.parse_args(argv)
    seeds, n, t1 = (
        ((0,), 6, 2.0)
        if args.quick
        else (
            tuple(range(args.first_seed, args.first_seed + args.seeds)),
            args.n,
            args.t1,
        )
    )
    base = jh.load_scenario("paper-4.2")
    times = jh.Times(t1, n=201)
    check = jh.AccuracyCheck(members=16, length_target=TOLERANCE)
    head = ("seed", "members", "ok", "marked", "agree 1 cm", "off, flagged", "silent", "report max m", "s")
    print("{:>4s} {:>7s} {:>4s} {:>6s} {:>10s} {:>12s} {:>6s} {:>12s} {:>6s}".format(*head))
    totals = np.zeros(6, dtype=int)
    for seed in seeds:
        t0 = time.perf_counter()
        sweep = members(random_scenarios(base, n, seed))
        common = {"observables": ["final_position"], "histories": ("position",)}
        res = jh.scan(base, sweep, times, accuracy=check, **common)
        ref = jh.scan(
            base, sweep, times, options=REFERENCE, batch=jh.BatchOptions(lanes=1), accuracy=False, **common
        )
        diff = np.max(np.linalg.norm(res["position"] - ref["position"], axis=-1), axis=-1)
        report = res.accuracy or {}
        flagged = report.get("over_target", 0) > 0
        ok = res.ok
        marked = ~ok
        agree = ok & (diff <= TOLERANCE)
        off = ok & ~(diff <= TOLERANCE)  # NaN (reference failed) counts as off
        silent = off if not flagged else np.zeros_like(off)
        row = [n, ok.sum(), marked.sum(), agree.sum(), (off & ~silent).sum(), silent.sum()]
        totals += np.array(row)
        fp = report.get("observables", {}).get("final_position", {})
        print(
            f"{seed:4d} {n:7d} {row[1]:4d} {row[2]:6d} {row[3]:10d} {row[4]:12d} {row[5]:6d} "
            f"{fp.get('max') or float('nan'):12.2e} {time.perf_counter() - t0:6.0f}",
            flush=True,
        )
        for i in np.flatnonzero(off | marked):
            print(
                f"       member {i}: status {res.reason(int(i))}, reference "
                f"{ref.reason(int(i))}, max |dC| {diff[i]:.2e} m",
                flush=True,
            )
    print(
        f"{totals[0]} scenarios over {t1:g} s: ok {totals[1]}, marked by status {totals[2]}, agree within "
        f"1 cm {totals[3]}, off but flagged by the accuracy report {totals[4]}, silent {totals[5]}"
    )


if __name__ == "__main__":
    main()
