"""Which default tolerances for the Rosenbrock-W solver? (issue 10: every member of the default scan within
1 cm of an rtol 1e-10 reference, at the least cost)

A vmapped solve of paper-4.2 over --n friction coefficients μ in [--lo, --hi] to --t1 (201 saved times, as
`scan` saves) with the default solver at each (rtol, atol) of --tols; prints the steps attempted (sum,
median, max: a lock-step group's cost follows its slowest member), the share rejected, and the distance of
the mass centre from Tsit5 at rtol 1e-9 (atol 1e-11): at t1 (median, max, at which μ) and the largest at
any saved time. Step counts do not depend on the machine's load.

    python experiments/w_tolerance.py --n 32 --t1 25          # from experiments/, or with it on PYTHONPATH
    python experiments/w_tolerance.py --n 128 --t1 25 --tols "1e-3,1e-5;1e-3,2e-5;1e-3,3e-5"

Measured 2026-11-25 (the W with the turning-corner term, cubic dense output), --n 32 --t1 25 (steps
attempted; rej.: share rejected; final: largest error at t1; any t: largest at any saved time):

  rtol 1e-3 atol 1e-5   steps 132 622, median 4 077, max 4 538, rej. 4.7 %, final 0.116 cm, any t 0.155 cm
  rtol 2e-3 atol 1e-5   steps 122 967, median 3 812, max 4 225, rej. 5.4 %, final 0.144 cm, any t 0.325 cm
  rtol 1e-3 atol 2e-5   steps 115 680, median 3 596, max 3 997, rej. 6.0 %, final 0.248 cm, any t 0.330 cm
  rtol 1e-3 atol 3e-5   steps 105 010, median 3 248, max 3 624, rej. 7.3 %, final 0.240 cm, any t 0.338 cm
  rtol 2e-3 atol 2e-5   steps 109 608, median 3 434, max 3 793, rej. 7.0 %, final 0.258 cm, any t 0.329 cm
  rtol 5e-4 atol 5e-5   steps  94 990, median 2 948, max 3 239, rej. 8.8 %, final 0.274 cm, any t 0.474 cm
  rtol 1e-3 atol 5e-5   steps  94 150, median 2 932, max 3 571, rej. 8.9 %, final 0.287 cm, any t 0.863 cm
  rtol 2e-3 atol 5e-5   steps  93 105, median 2 954, max 3 322, rej. 10.2 %, final 0.421 cm, any t 1.051 cm
  rtol 3e-3 atol 3e-5   steps  98 382, median 3 112, max 3 550, rej. 8.8 %, final 0.381 cm, any t 0.965 cm
  rtol 1e-3 atol 1e-4   steps  89 951, median 2 700, max 5 420, rej. 15.0 %, final 1.591 cm, any t 4.264 cm

and --n 128: atol 1e-5 max 4 537 steps, final 0.169 cm; 2e-5 4 051, 0.458 cm; 3e-5 3 655, 0.426 cm
(any t 0.468 cm). The atol sets the steps more than the rtol does (at atol 1e-5, rtol 2e-3 takes 7 % fewer
steps than 1e-3; at rtol 1e-3, atol 3e-5 takes 21 % fewer than 1e-5); beyond atol 5e-5 the error grows
fast. atol 3e-5 passed the 512-member check of `benchmark_scan.py` (max 0.50 cm) but was not kept: at
ε = 1e-4 it put members 1-5.6 cm off, and with W's band-entry slope the first 2 s of paper-4.2 0.39 mm
off Tsit5 (docs/performance.md, "Looser default tolerances"). The default stays rtol 1e-3, atol 1e-5.
"""

from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from w_controller import solve_mus, step_report  # noqa: E402  (the same solve and report as the controller comparison)

import jaxhoist as jh  # noqa: E402
from jaxhoist._numerics.solve import as_float64_leaves  # noqa: E402  (internal: strongly typed leaves, one compile)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=32, help="members, μ evenly in [--lo, --hi]")
    p.add_argument("--lo", type=float, default=0.1, help="smallest μ")
    p.add_argument("--hi", type=float, default=0.6, help="largest μ")
    p.add_argument("--t1", type=float, default=25.0, help="end time [s]")
    p.add_argument(
        "--tols", default="1e-3,1e-5;2e-3,1e-5;1e-3,2e-5;1e-3,3e-5;1e-3,5e-5", help="'rtol,atol;...'"
    )
    a = p.parse_args(argv)
    sc = as_float64_leaves(jh.load_scenario("paper-4.2"))
    mus, ts = jnp.linspace(a.lo, a.hi, a.n), jnp.linspace(0.0, a.t1, 201)

    def run(options):
        return solve_mus(sc, mus, ts, options)

    ref = run(jh.SolverOptions(diffrax.Tsit5(), rtol=1e-9, atol=1e-11, max_steps=400_000))
    for tol in a.tols.split(";"):
        rtol, atol = map(float, tol.split(","))
        tr = run(jh.SolverOptions(rtol=rtol, atol=atol))
        step_report(f"rtol {rtol:g} atol {atol:g}", tr, ref, width=22)
        dist = np.linalg.norm(np.asarray(tr.position - ref.position), axis=-1)  # (n, saved times)
        final = dist[:, -1]
        print(
            f"    final error median {100 * np.median(final):.3f} cm, worst at μ "
            f"{float(mus[final.argmax()]):.3f}; any saved time {100 * dist.max():.3f} cm",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
