"""The first derivative of docs/getting-started.md three ways: d x_C(t1)/dμ of paper-4.2 at μ = 0.3 by forward
mode (`jax.jvp` with `SolverOptions(adjoint=diffrax.ForwardMode())`: the sensitivities solved beside the state
under error control), by reverse mode (`jax.grad`, the default adjoint: the derivative of the Rosenbrock-W
steps, once as is and once with every step checkpointed), all at the default tolerances, against central
differences of Tsit5 solves at rtol 1e-10 (two steps h, whose agreement says the reference is converged).

    python experiments/figures/derivative_modes.py --out out/derivative_modes           # t1 = 1 s
    python experiments/figures/derivative_modes.py --out out/derivative_modes --quick   # 0.2 s, grad as is

Prints one line per way (the derivative [m] and its relative difference to the reference) and writes the
same table to `derivative_modes.txt` in --out. The quick run's numbers are not the documented ones.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU = 0.3  # the friction coefficient of the example [-]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="out/derivative_modes", help="folder for derivative_modes.txt")
    p.add_argument("--quick", action="store_true", help="t1 = 0.2 s, reverse mode as is only (a smoke check)")
    a = p.parse_args()
    if a.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    t1 = 0.2 if a.quick else 1.0
    scenario = jh.load_scenario("paper-4.2")
    times = jh.Times(t1, n=2)

    def x_end(mu, options=None):  # x_C(t1) [m] as a function of μ
        sc = scenario.replace(**{"foundation.friction_coefficient": mu})
        return jh.simulate(sc, times, options=options).position[-1, 0]

    forward = jh.SolverOptions(adjoint=diffrax.ForwardMode())
    checkpointed = jh.SolverOptions(
        max_steps=4096, adjoint=diffrax.RecursiveCheckpointAdjoint(checkpoints=4096)
    )
    tight = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-10, atol=1e-12)

    def central(h):
        return float((x_end(MU + h, tight) - x_end(MU - h, tight)) / (2 * h))

    ref = {h: central(h) for h in (1e-3, 1e-4)}
    rows = [
        ("central differences, Tsit5 rtol 1e-10, h = 1e-3", ref[1e-3]),
        ("central differences, Tsit5 rtol 1e-10, h = 1e-4", ref[1e-4]),
        (
            "forward mode (jax.jvp, ForwardMode)",
            float(jax.jvp(lambda m: x_end(m, forward), (MU,), (1.0,))[1]),
        ),
        ("reverse mode (jax.grad, default adjoint)", float(jax.grad(x_end)(MU))),
    ]
    if not a.quick:  # a third reverse-mode program: the full run only
        rows.append(
            ("reverse mode, every step checkpointed", float(jax.grad(lambda m: x_end(m, checkpointed))(MU)))
        )
    lines = [f"d x_C({t1:g} s)/dμ of paper-4.2 at μ = {MU}, default tolerances unless said [m]"]
    lines += [f"{name:<50} {value:10.6f}  {value / ref[1e-4] - 1.0:+9.2e}" for name, value in rows]
    lines.append(f"command: python {' '.join(sys.argv)}")
    print("\n".join(lines))
    Path(a.out).mkdir(parents=True, exist_ok=True)
    Path(a.out, "derivative_modes.txt").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
