"""Lock-step group width (`lanes`) of the default adaptive solver (Rosenbrock-W) in a μ-scan of paper-4.2:
compute time per trajectory, steps, lock-step efficiency, and how far the final positions move against the
narrowest width (lanes is a numerical setting: a wider group takes the steps its hardest member needs).

    python experiments/w_lanes.py --out out/w-lanes                       # 128 μ, 25 s, lanes 8..128
    python experiments/w_lanes.py --out out/w-lanes --n 64 --t1 10 --lanes 16,64 --rounds 1
    python experiments/w_lanes.py --out out/w-lanes-dense --grid 4096 --windows 0.2,0.4,0.55 --n 256

`--grid N --windows a,b,...`: instead of n members spread over [0.1, 0.6], take --n consecutive members of
the N-point grid over [0.1, 0.6] starting at each μ in the list (a large scan's density, where a group's
members are close neighbours, at a fraction of its cost).

Every width runs in one process, one host device, in `--rounds` rounds (order reversed every other round),
so each ratio is against a run made under the same load. Lock-step efficiency = mean over members of their
own step count / the group's largest, i.e. the share of evaluated lanes that a member actually needed.
Writes DIR/w_lanes.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU = "foundation.friction_coefficient"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--n", type=int, default=128, help="members, μ evenly in [0.1, 0.6]")
    p.add_argument("--t1", type=float, default=25.0, help="horizon [s]")
    p.add_argument("--lanes", default="8,16,32,64,128", help="comma-separated group widths")
    p.add_argument("--rounds", type=int, default=2, help="timed rounds per width")
    p.add_argument("--grid", type=int, default=None, help="points of the full grid over [0.1, 0.6]")
    p.add_argument("--windows", default=None, help="comma-separated start μ of --n-member windows of --grid")
    a = p.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = jh.load_scenario("paper-4.2")
    if a.grid:
        full = np.linspace(0.1, 0.6, a.grid)
        starts = [int(np.searchsorted(full, float(m))) for m in a.windows.split(",")]
        mus = np.concatenate([full[i : i + a.n] for i in starts])
    else:
        mus = np.linspace(0.1, 0.6, a.n)
    n = len(mus)
    widths = [int(x) for x in a.lanes.split(",")]
    dev = jax.devices()[:1]
    rows: dict[int, dict] = {w: {"lanes": w, "compute_s": []} for w in widths}
    finals: dict[int, np.ndarray] = {}
    for rnd in range(a.rounds):
        for w in widths if rnd % 2 == 0 else widths[::-1]:
            t0 = time.perf_counter()
            batch = jh.BatchOptions(lanes=w, devices=dev)
            r = jh.scan(
                sc, jh.Sweep(MU, mus), jh.Times(a.t1, n=2), observables=["final_position"], batch=batch
            )
            wall = time.perf_counter() - t0
            t = r.attrs["timings_s"]
            row = rows[w]
            row["compute_s"].append(t["compute"])
            if "compile_s" not in row:
                row["compile_s"] = t["compile"]
                steps = r.num_accepted_steps + r.num_rejected_steps
                groups = [steps[i : i + w] for i in range(0, len(steps), w)]
                row["steps_median"] = int(np.median(r.num_accepted_steps))
                row["steps_max"] = int(np.max(r.num_accepted_steps))
                row["rejected_share"] = float(np.sum(r.num_rejected_steps) / np.sum(steps))
                row["lockstep_efficiency"] = float(np.mean([np.mean(g) / np.max(g) for g in groups]))
                row["failed"] = int(np.sum(~r.ok))
                finals[w] = np.asarray(r["final_position"])
            print(f"round {rnd} lanes {w:4d}: compute {t['compute']:.2f} s (wall {wall:.1f} s)", flush=True)
    base = widths[0]
    for w in widths:
        row = rows[w]
        row["ms_per_trajectory"] = 1e3 * min(row["compute_s"]) / n
        row["ratio_to_first"] = min(row["compute_s"]) / min(rows[base]["compute_s"])
        row["max_dpos_vs_first_cm"] = float(100 * np.max(np.linalg.norm(finals[w] - finals[base], axis=-1)))
        print(
            f"lanes {w:4d}: {row['ms_per_trajectory']:7.2f} ms/traj ({row['ratio_to_first']:.2f}x lanes "
            f"{base}), steps median {row['steps_median']} max {row['steps_max']}, "
            f"rejected {row['rejected_share']:.0%}, "
            f"lock-step efficiency {row['lockstep_efficiency']:.2f}, compile {row['compile_s']:.1f} s, "
            f"max |Δr_C| vs lanes {base} {row['max_dpos_vs_first_cm']:.3f} cm, failed {row['failed']}"
        )
    rec = {"n": n, "grid": a.grid, "windows": a.windows, "t1": a.t1, "rounds": a.rounds}
    rec |= {"device": str(dev[0]), "rows": list(rows.values())}
    (out / "w_lanes.json").write_text(json.dumps(rec, indent=1))


if __name__ == "__main__":
    main()
