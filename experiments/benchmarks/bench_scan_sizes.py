"""Small scans against large ones, and the first derivative scan's compile: what a notebook user pays.

    python experiments/benchmarks/bench_scan_sizes.py --out out/scan-sizes  # 64, 256, 512, 4096 μ over 25 s
    python experiments/benchmarks/bench_scan_sizes.py --out out/scan-sizes --compare-lanes 16  # and 16 lanes
    python experiments/benchmarks/bench_scan_sizes.py --out out/scan-sizes --quick  # 16 and 32 μ over 1 s

What it runs:

1. **per-trajectory cost by member count**, in one process (every ratio against the largest scan measured
   under the same load): `scan(load_scenario("paper-4.2"), {μ: linspace(0.1, 0.6, n)}, Times(t1, n=2),
   observables=[final_position, final_euler])` for each n of --sizes with the default layout, every CPU
   core as a device (--devices to change); the solve only, compilation excluded (the scan's
   `timings_s["compute"]` / n); the group width and count; steps median / max; the ratio of the cost per
   trajectory to that of the largest scan. --repeat runs the whole list again (compiled programs reused);
   a run that compiled nothing also reports its CPU time per trajectory (user + system, every thread),
   the measure to compare on a machine whose other work takes the cores (wall time then measures the
   share of the cores the process got as much as the scan's own cost; on an idle machine compare wall
   times, which show the devices working in parallel).
   With --compare-lanes W, each size also runs with `BatchOptions(lanes=W)` (e.g. 16, the width that a scan
   of fewer than 512 members had by default before the width followed the devices too).
2. **the first derivative scan's compile**, cold and warm (--deriv-n members, 0 to skip): two fresh
   processes in turn, with the persistent compilation cache (`jh.enable_compilation_cache(DIR/cache)`)
   in an empty folder (cold), then the same folder (warm), each running `scan(..., derivatives=True)`; the
   scan's compile time (tracing, lowering, and compiling or loading) and the process's wall time.

Everything goes to DIR/bench_scan_sizes.json.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax  # noqa: E402

# every CPU core by default (--devices N to change), set before JAX starts its backend
jax.config.update(
    "jax_num_cpu_devices",
    int(sys.argv[sys.argv.index("--devices") + 1]) if "--devices" in sys.argv else (os.cpu_count() or 1),
)
jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU = "foundation.friction_coefficient"
OBS = ["final_position", "final_euler"]

_DERIV_CHILD = """
import sys, time
t0 = time.perf_counter()
import jax
jax.config.update("jax_num_cpu_devices", int(sys.argv[3]))
jax.config.update("jax_enable_x64", True)
import json
import numpy as np
import jaxhoist as jh
jh.enable_compilation_cache(sys.argv[1])
n, t1 = int(sys.argv[2]), float(sys.argv[4])
res = jh.scan(jh.load_scenario("paper-4.2"), {"foundation.friction_coefficient": np.linspace(0.1, 0.6, n)},
              jh.Times(t1, n=2), observables=["final_position", "final_euler"], derivatives=True)
t = res.attrs["timings_s"]
print(json.dumps({"compile_s": t["compile"], "compute_s": t["compute"], "wall_s": time.perf_counter() - t0,
                  "lanes": res.attrs["lanes"], "ok": int(res.ok.sum())}))
"""


def cpu_seconds() -> float:
    """User + system CPU time of this process, every thread [s]."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def scan_row(sc, n: int, t1: float, lanes: int | None) -> dict:
    """One scan of n μ evenly in [0.1, 0.6]: its layout, compile and per-trajectory solve time (wall), and
    the CPU time of the whole call (the solve's alone where nothing was compiled)."""
    cpu0 = cpu_seconds()
    res = jh.scan(
        sc,
        {MU: np.linspace(0.1, 0.6, n)},
        jh.Times(t1, n=2),
        observables=OBS,
        batch=jh.BatchOptions(lanes=lanes),
        accuracy=False,
    )
    cpu = cpu_seconds() - cpu0
    t = res.attrs["timings_s"]
    steps = np.asarray(res.num_accepted_steps)
    return {
        "n": n,
        "lanes": res.attrs["lanes"],
        "groups": -(-n // res.attrs["lanes"]),
        "chunk_size": res.attrs["chunk_size"],
        "compile_s": t["compile"],
        "compute_s": t["compute"],
        "ms_per_trajectory": 1e3 * t["compute"] / n,
        "cpu_ms_per_trajectory": 1e3 * cpu / n if t["compile"] == 0.0 else None,
        "steps_median": float(np.median(steps)),
        "steps_max": int(steps.max()),
        "failed": int((~res.ok).sum()),
    }


def deriv_compile(n: int, t1: float, n_dev: int, cache: Path) -> list[dict]:
    """The first derivative scan's compile in a fresh process with an empty cache folder, then again."""
    rows = []
    for case in ("cold", "warm"):
        out = subprocess.run(
            [sys.executable, "-c", _DERIV_CHILD, str(cache), str(n), str(n_dev), str(t1)],
            capture_output=True,
            text=True,
            check=True,
        )
        rows.append({"case": case, **json.loads(out.stdout.strip().splitlines()[-1])})
        print(f"  derivatives, {case} cache: {rows[-1]}", flush=True)
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="smoke run: 16 and 32 μ over 1 s, derivatives of 4")
    p.add_argument(
        "--sizes", default=None, help="member counts (default 64,256,512,4096; quick 16,32; 0: none)"
    )
    p.add_argument("--t1", type=float, default=None, help="horizon [s] (default 25, paper-4.2's; quick 1)")
    p.add_argument("--devices", type=int, default=None, help="host CPU devices (default: one per core)")
    p.add_argument("--repeat", type=int, default=1, help="how many times to run the list of sizes")
    p.add_argument("--compare-lanes", type=int, default=None, help="also run each size with this width")
    p.add_argument("--deriv-n", type=int, default=None, help="members of the derivative scan (16; quick 4)")
    p.add_argument("--deriv-t1", type=float, default=None, help="its horizon [s] (default 2; quick 0.5)")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    q = args.quick
    sizes = [int(s) for s in (args.sizes or ("16,32" if q else "64,256,512,4096")).split(",") if int(s) > 0]
    t1 = args.t1 if args.t1 is not None else (1.0 if q else 25.0)
    deriv_n = args.deriv_n if args.deriv_n is not None else (4 if q else 16)
    deriv_t1 = args.deriv_t1 if args.deriv_t1 is not None else (0.5 if q else 2.0)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    n_dev = len(jax.devices())
    sc = jh.load_scenario("paper-4.2")
    print(f"paper-4.2, μ evenly in [0.1, 0.6], {t1} s, {n_dev} CPU devices", flush=True)
    rows = []
    for rep in range(args.repeat):
        for lanes in (None,) if args.compare_lanes is None else (None, args.compare_lanes):
            for n in sizes:
                row = {"repeat": rep, "layout": "default" if lanes is None else f"lanes={lanes}"}
                row.update(scan_row(sc, n, t1, lanes))
                rows.append(row)
                print(f"  {row}", flush=True)
    print(
        "\n| members | layout | lanes x groups | ms per trajectory | / largest | CPU ms per trajectory | "
        "/ largest | steps median / max |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        big = max(  # the largest default scan of the same round
            (r for r in rows if r["repeat"] == row["repeat"] and r["layout"] == "default"),
            key=lambda r: r["n"],
        )
        row["ratio_to_largest"] = row["ms_per_trajectory"] / big["ms_per_trajectory"]
        cpu, big_cpu = row["cpu_ms_per_trajectory"], big["cpu_ms_per_trajectory"]
        row["cpu_ratio_to_largest"] = cpu / big_cpu if cpu is not None and big_cpu is not None else None
        cpu_cols = (
            "– | –"
            if row["cpu_ratio_to_largest"] is None
            else f"{cpu:.2f} | {row['cpu_ratio_to_largest']:.2f}x"
        )
        print(
            f"| {row['n']} | {row['layout']} (run {row['repeat'] + 1}) | {row['lanes']} x {row['groups']} | "
            f"{row['ms_per_trajectory']:.2f} | {row['ratio_to_largest']:.2f}x | {cpu_cols} | "
            f"{row['steps_median']:.0f} / {row['steps_max']} |"
        )
    deriv = []
    if deriv_n:
        print(f"\nscan(derivatives=True), {deriv_n} μ over {deriv_t1} s, fresh processes:", flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            deriv = deriv_compile(deriv_n, deriv_t1, n_dev, Path(tmp) / "cache")
    result = {
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "devices": n_dev,
        "t1": t1,
        "load_average": os.getloadavg(),
        "sizes": rows,
        "derivatives": {"n": deriv_n, "t1": deriv_t1, "runs": deriv},
        "time": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    (out / "bench_scan_sizes.json").write_text(json.dumps(result, indent=1))
    print(f"wrote {out / 'bench_scan_sizes.json'}")


if __name__ == "__main__":
    main()
