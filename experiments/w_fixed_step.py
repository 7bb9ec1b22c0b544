"""The Rosenbrock-W step at constant step sizes on paper-4.2: error of the final mass centre against Tsit5
at rtol 1e-10 (why the default solver keeps error control; docs/performance.md).

    python experiments/w_fixed_step.py --mu 0.1,0.3,0.5,0.6 --dt 0.002,0.004,0.00625
"""

from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--mu", default="0.1,0.3,0.5,0.6", help="friction coefficients (comma-separated)")
    p.add_argument("--dt", default="0.002,0.004,0.00625", help="constant steps [s] (comma-separated)")
    p.add_argument("--t1", type=float, default=25.0, help="horizon [s] (default 25)")
    args = p.parse_args(argv)
    for mu in (float(x) for x in args.mu.split(",")):
        sc = jh.load_scenario("paper-4.2").replace(**{"foundation.friction_coefficient": mu})
        tight = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-10, atol=1e-12, max_steps=10**6)
        ref = jh.simulate(sc, jh.Times(args.t1, n=11), options=tight)
        row = []
        for dt in (float(x) for x in args.dt.split(",")):
            opts = jh.SolverOptions(jh.RosenbrockW(), diffrax.ConstantStepSize(), dt0=dt, max_steps=10**6)
            tr = jh.simulate(sc, jh.Times(args.t1, n=11), options=opts, throw=False)
            err = 100 * float(np.max(np.abs(np.asarray(tr.position[-1] - ref.position[-1]))))
            row.append(
                f"dt {1e3 * dt:g} ms: "
                + (f"{err:.3f} cm" if int(tr.status) == 0 else jh.SolveStatus(int(tr.status)).name.lower())
            )
        print(f"mu {mu:g}: " + " | ".join(row), flush=True)


if __name__ == "__main__":
    main()
