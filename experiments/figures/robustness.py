"""Robustness of the default solver on random plausible scenarios: each seed's scenarios are run as ONE scan
of `Points` members by the default solver (Rosenbrock-W, default tolerances, the scan's accuracy check forced
on: `AccuracyCheck(members=16)`, the 8 members with the most solver steps and 8 drawn at random re-solved at a
1000x tighter tolerance, 16 more by step count while the largest difference is within 4x of 1 cm, up to 64),
and compared with a tight reference (Tsit5 at rtol 1e-9, atol 1e-10, one member per lane). Every member
either agrees with the reference within 1 cm (the load's mass-centre path, max over the saved times) or is
marked by its status (max_steps, non-finite, energy_balance, ...), or its scan's accuracy report says that
differences above 1 cm occur. A member with status ok that is more than 1 cm off while its scan's report has
no member over 1 cm is "silent".

The scenarios vary around paper-4.2: friction 0.05-0.9, ground 1e6-1e9 N/m, regularisation velocity
1e-4-1e-2 m/s, rope 1e6-1e8 N/m, hoist 0.05-1 m/s, boom stiffness 1e6-5e7 N/m, the mass centre inside the
box and the boom tip's position.

    python experiments/figures/robustness.py --quick   # 1 seed x 6 scenarios over 2 s (minutes)
    python experiments/figures/robustness.py           # 3 seeds x 48 scenarios over 8 s (heavy)
    python experiments/figures/robustness.py --first-seed 3 --seeds 1 --cache ref/   # one seed; the
        # reference's paths kept in ref/ for the next run with the same members
"""

from __future__ import annotations

import argparse
import hashlib
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._apps.scan.accuracy import summary  # noqa: E402
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


def reference_positions(
    base, sweep: jh.Points, times: jh.Times, cache: Path | None
) -> tuple[np.ndarray, np.ndarray]:
    """The reference's mass-centre paths [m] (members x saved times x 3) and ok flags, read from `cache` (a
    folder) where an earlier run stored them for the same members, times and reference options."""
    key = hashlib.sha1(
        repr(
            (sorted(sweep.values), REFERENCE.describe(), np.asarray(times.resolve(base, 201)[1]).tolist())
        ).encode()
        + np.concatenate([np.asarray(v, dtype=float).ravel() for v in sweep.values.values()]).tobytes()
    ).hexdigest()[:16]
    path = None if cache is None else Path(cache) / f"reference-{key}.npz"
    if path is not None and path.exists():
        with np.load(path) as z:
            return z["position"], z["ok"]
    ref = jh.scan(
        base,
        sweep,
        times,
        options=REFERENCE,
        batch=jh.BatchOptions(lanes=1),
        accuracy=False,
        observables=["final_position"],
        histories=("position",),
    )
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, position=ref["position"], ok=ref.ok)
    return ref["position"], ref.ok


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 seed x 6 scenarios over 2 s")
    ap.add_argument("--seeds", type=int, default=3, help="number of seeds (full mode)")
    ap.add_argument("--first-seed", type=int, default=0, help="the first seed (full mode)")
    ap.add_argument("--n", type=int, default=48, help="scenarios per seed (full mode)")
    ap.add_argument("--t1", type=float, default=8.0, help="horizon [s] (full mode)")
    ap.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="a folder for the reference's paths: a second run with the same members reads them from there",
    )
    args = ap.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
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
    head = (
        "seed",
        "members",
        "failed",
        "within 1 cm",
        "off > 1 cm",
        "re-solved",
        "report over",
        "silent",
        "s",
    )
    print("{:>4s} {:>7s} {:>6s} {:>11s} {:>10s} {:>9s} {:>11s} {:>6s} {:>5s}".format(*head))
    totals = np.zeros(6, dtype=int)
    for seed in seeds:
        t0 = time.perf_counter()
        sweep = members(random_scenarios(base, n, seed))
        res = jh.scan(
            base, sweep, times, accuracy=check, observables=["final_position"], histories=("position",)
        )
        ref_position, ref_ok = reference_positions(base, sweep, times, args.cache)
        diff = np.max(np.linalg.norm(res["position"] - ref_position, axis=-1), axis=-1)
        report = res.accuracy or {}
        flagged = report.get("over_target", 0) > 0
        ok = res.ok
        marked = ~ok
        agree = ok & (diff <= TOLERANCE)
        off = ok & ~(diff <= TOLERANCE)  # NaN (reference failed) counts as off
        silent = off if not flagged else np.zeros_like(off)
        row = [n, marked.sum(), agree.sum(), off.sum(), report.get("over_target", 0), silent.sum()]
        totals += np.array(row)
        print(
            f"{seed:4d} {n:7d} {row[1]:6d} {row[2]:11d} {row[3]:10d} {report.get('members', 0):9d} "
            f"{row[4]:11d} {row[5]:6d} {time.perf_counter() - t0:5.0f}",
            flush=True,
        )
        print(f"       accuracy report: {summary(res.accuracy)}", flush=True)
        chosen = report.get("chosen", {})
        for i in np.flatnonzero(off | marked):
            how = (
                "re-solved for its steps"
                if int(i) in chosen.get("most_steps", ())
                else "re-solved at random"
                if int(i) in chosen.get("random", ())
                else "re-solved in a further round"
                if int(i) in chosen.get("more", ())
                else "not re-solved"
            )
            print(
                f"       member {i}: status {res.reason(int(i))}, reference "
                f"{'ok' if ref_ok[i] else 'failed'}, max |dC| {diff[i]:.2e} m, {how}",
                flush=True,
            )
    print(
        f"{totals[0]} scenarios over {t1:g} s: failed {totals[1]}, within 1 cm {totals[2]}, ok but more than "
        f"1 cm off {totals[3]}, members over 1 cm in the accuracy reports {totals[4]}, silent {totals[5]}"
    )


if __name__ == "__main__":
    main()
