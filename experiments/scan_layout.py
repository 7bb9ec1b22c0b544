"""Do scan results depend on how the work is laid out? (issue 14)

Runs the same μ-scan of paper-4.2 on 1, 2 and 4 host CPU devices (this process starts JAX with 4) and in
two chunk sizes, with the default solver (Rosenbrock-W) and with Tsit5, and prints the largest difference of
every observable and history against the 1-device run, whether the step counts agree, and the compile and
compute times (one process, so the times are comparable with each other, not with another run).

    python experiments/scan_layout.py                 # 32 μ in [0.2, 0.4], 3 s, groups of 8
    python experiments/scan_layout.py --n 64 --t1 5

Every share of a chunk runs the same single-device program (numerics/batch.py, `CompiledChunk`), so every
difference printed must be 0.0.
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_num_cpu_devices", 4)
jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU = "foundation.friction_coefficient"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=32, help="members (μ evenly in [0.2, 0.4])")
    p.add_argument("--t1", type=float, default=3.0, help="end time [s]")
    p.add_argument("--lanes", type=int, default=8, help="members per lock-step group")
    a = p.parse_args(argv)
    sc = jh.load_scenario("paper-4.2")
    mus = np.linspace(0.2, 0.4, a.n)
    worst = 0.0
    for label, solver in (("default (Rosenbrock-W)", None), ("Tsit5", diffrax.Tsit5())):
        kw = dict(
            observables=["final_position", "final_euler"],
            histories=("position",),
            options=jh.SolverOptions(solver),
        )
        runs = {}
        for n_dev, chunk in ((1, None), (2, None), (4, None), (2, 2 * a.lanes)):
            t = time.perf_counter()
            batch = jh.BatchOptions(lanes=a.lanes, devices=jax.devices()[:n_dev], chunk_size=chunk)
            r = jh.scan(sc, {MU: mus}, jh.Times(a.t1, n=31), batch=batch, **kw)
            tm = r.attrs["timings_s"]
            runs[(n_dev, chunk)] = r
            print(
                f"{label:24s} {n_dev} device(s), chunk {r.attrs['chunk_size']:4d}: "
                f"compile {tm['compile']:6.2f} s, compute {tm['compute']:6.3f} s, "
                f"wall {time.perf_counter() - t:6.2f} s"
            )
        ref = runs[(1, None)]
        for key, r in runs.items():
            if key == (1, None):
                continue
            d = max(float(np.nanmax(np.abs(np.asarray(ref[k]) - np.asarray(r[k])))) for k in ref.data)
            h = float(np.nanmax(np.abs(ref.histories["position"] - r.histories["position"])))
            same = np.array_equal(ref.num_accepted_steps, r.num_accepted_steps)
            worst = max(worst, d, h)
            print(
                f"{label:24s} {key[0]} device(s), chunk {r.attrs['chunk_size']:4d} vs 1 device: max |diff| "
                f"observables {d:.3g}, histories {h:.3g}, step counts equal: {same}"
            )
    print(f"largest difference over all layouts: {worst:.3g}")
    return 0 if worst == 0.0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
