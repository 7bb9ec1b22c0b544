"""The forward sensitivities' augmented system with its W stages in a loop or unrolled: compile and run time.

`RosenbrockW(stage_loop=True)` runs the stages after the first as a `jax.lax.fori_loop`, so the augmented
vector field (a Jacobian-vector product of the model) is traced and compiled once for them instead of once
per stage (`jaxhoist/_numerics/rosenbrock.py`, `w_step`). `numerics.sensitivity.augmented_solver` takes the
loop. This script times `scan(derivatives=True)` of paper-4.2 (N μ in [0.1, 0.6], T s, default options in
forward mode) with the loop and with the unrolled stages, alternating, in one process (every compile cache
cleared before each variant), and compares the two variants' sensitivities (they differ by the solver's
tolerance: a different rounding changes the accepted steps).

    python experiments/w_stage_loop.py --n 64 --t1 25 --rounds 2
"""

from __future__ import annotations

import argparse
import dataclasses

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._numerics import batch, compile_cache, sensitivity  # noqa: E402

MU = "foundation.friction_coefficient"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=64)
    p.add_argument("--t1", type=float, default=25.0)
    p.add_argument("--rounds", type=int, default=2)
    args = p.parse_args(argv)
    sc = jh.load_scenario("paper-4.2")
    mus = np.linspace(0.1, 0.6, args.n)
    options = jh.SolverOptions(adjoint=diffrax.ForwardMode())
    original = sensitivity.augmented_solver
    derivs = {}
    try:
        for _ in range(args.rounds):
            for name, loop in (("unrolled", False), ("loop", True)):

                def patched(solver, many=False, loop=loop):
                    return dataclasses.replace(original(solver, many), stage_loop=loop)

                sensitivity.augmented_solver = patched
                compile_cache.clear()
                jax.clear_caches()
                batch.chunk_fn.cache_clear()
                times = []
                for _ in range(2):  # the first call compiles, the second reuses it
                    r = jh.scan(
                        sc, jh.Grid({MU: mus}), jh.Times(args.t1, n=2), observables=["final_position"],
                        derivatives=True, options=options, progress=False,
                    )  # fmt: skip
                    times.append(r.attrs["timings_s"])
                derivs[name] = np.asarray(r["d_final_position"]).reshape(args.n, -1)
                print(
                    f"{name}: compile {times[0]['compile']:.1f} s, compute "
                    f"{1e3 * times[0]['compute'] / args.n:.1f} / {1e3 * times[1]['compute'] / args.n:.1f} ms "
                    f"per trajectory",
                    flush=True,
                )
    finally:
        sensitivity.augmented_solver = original
    a, b = derivs["unrolled"], derivs["loop"]
    rel = np.linalg.norm(b - a, axis=-1) / np.maximum(np.linalg.norm(a, axis=-1), 1e-3)
    print(f"loop against unrolled, d(final position)/dμ: median {np.median(rel):.2e}, max {rel.max():.2e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
