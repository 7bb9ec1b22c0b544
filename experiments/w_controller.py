"""Which step-size controller for the default Rosenbrock-W solver? (issue 10)

A vmapped solve of paper-4.2 over --n friction coefficients μ in [0.1, 0.6] to --t1 with the default solver
at its default tolerances (rtol 1e-3, atol 1e-5) and each controller below; prints the steps (attempted:
sum, median, max, which sets a lock-step group's cost), the share rejected, and the error of the final mass
centre against Tsit5 at rtol 1e-9. Step counts do not depend on the machine's load, so the comparison holds
on a shared machine.

    python experiments/w_controller.py --n 32 --t1 25                 # steps land on t1 only
    python experiments/w_controller.py --n 8 --t1 25 --n-save 2501   # steps land on every 10 ms

Measured (2026-11-24), --n 32 --t1 25 (no saved times in between):

    I (0, 1), diffrax's default  steps 242 182, median 4 433, max 19 204, rejected 24 %, max error 0.52 cm
    PI (0.3, 0.3)                steps 213 856, median 4 668, max 14 570, rejected  6 %, max error 0.55 cm
    PI (0.2, 0.4)                steps 206 766, median 4 480, max 14 407, rejected  8 %, max error 0.68 cm
    PI (0.4, 0.3)                steps 210 058, median 4 656, max 14 589, rejected  6 %, max error 0.54 cm
    PI (0.1, 0.3)                steps 209 234, median 4 658, max 13 937, rejected  6 %, max error 0.59 cm

and --n 8 --t1 25 --n-save 2501 (what `jaxhoist simulate` saved then; the solver's dense output was linear, so
its steps landed on every saved time):

    I (0, 1), diffrax's default  steps  67 508, median 5 842, max 15 762, rejected 20 %, max error 0.50 cm
    PI (0.2, 0.4)                steps  68 880, median 7 084, max 13 023, rejected  3 %, max error 0.32 cm
    PI (0.4, 0.3)                steps  75 723, median 7 954, max 13 419, rejected  2 %, max error 0.24 cm

(the PI coefficients are those diffrax's `PIDController` documentation suggests for error estimates that do
not vary smoothly.) A PI controller cuts the rejections from a quarter to a few per cent and the slowest
member's steps by a sixth to a quarter, but where the steps are clipped to dense saved times it grows the
step back more slowly after each clipped step and takes 2-12 % more steps in all: not adopted as the default
yet. A dense output of the solver's own order (so that steps need not land on saved times) would remove
that interaction.

Measured again 2026-11-25, after the W fix (corner velocities turning with the body) and with the cubic
Hermite dense output (steps no longer land on saved times), --n 32 --t1 25 --n-save 201:

    I (0, 1), diffrax's default  steps 132 622, median 4 077, max 4 538, rejected 5 %, max error 0.12 cm
    PI (0.3, 0.3)                steps 143 864, median 4 448, max 4 860, rejected 2 %, max error 0.07 cm
    PI (0.2, 0.4)                steps 139 532, median 4 300, max 4 742, rejected 3 %, max error 0.09 cm
    PI (0.4, 0.3)                steps 143 755, median 4 450, max 4 874, rejected 2 %, max error 0.12 cm
    PI (0.1, 0.3)                steps 144 466, median 4 478, max 4 860, rejected 2 %, max error 0.09 cm

so the integral controller stays.
"""

from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import set_param  # noqa: E402
from jaxhoist._numerics.solve import as_float64_leaves, solve  # noqa: E402  (internal: the bare solve core under vmap)

CONTROLLERS = {
    "I (0, 1), diffrax's default": (0.0, 1.0),
    "PI (0.3, 0.3)": (0.3, 0.3),
    "PI (0.2, 0.4)": (0.2, 0.4),
    "PI (0.4, 0.3)": (0.4, 0.3),
    "PI (0.1, 0.3)": (0.1, 0.3),
}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=32, help="members, μ evenly in [0.1, 0.6]")
    p.add_argument("--t1", type=float, default=25.0, help="end time [s]")
    p.add_argument("--n-save", type=int, default=2, help="saved times (the steps land on each)")
    p.add_argument("--only", default="", help="controller names to run, separated by ';'")
    a = p.parse_args(argv)
    sc = as_float64_leaves(jh.load_scenario("paper-4.2"))
    mus, ts = jnp.linspace(0.1, 0.6, a.n), jnp.linspace(0.0, a.t1, a.n_save)

    def run(options):
        return solve_mus(sc, mus, ts, options)

    ref = run(jh.SolverOptions(diffrax.Tsit5(), rtol=1e-9, atol=1e-11, max_steps=400_000))
    for name, (pc, ic) in CONTROLLERS.items():
        if a.only and name not in a.only.split(";"):
            continue
        ctrl = diffrax.PIDController(rtol=1e-3, atol=1e-5, pcoeff=pc, icoeff=ic)
        step_report(name, run(jh.SolverOptions(stepsize_controller=ctrl)), ref, width=28)
    return 0


def solve_mus(sc, mus, ts, options):
    """One jitted, vmapped solve of the scenario `sc` over the friction coefficients `mus` [-], saved at
    `ts` [s], with `options` (the bare solve core, status per member, no exception): a `Trajectory` with a
    leading member axis."""
    one = lambda mu: solve(set_param(sc, "foundation.friction_coefficient", mu), ts, options)  # noqa: E731
    return jax.block_until_ready(jax.jit(jax.vmap(one))(mus))


def step_report(name: str, tr, ref, width: int) -> None:
    """Print the steps attempted by the vmapped solves `tr` (sum, median, max), the share rejected, the
    largest distance [cm] of the final mass centre from `ref`'s, and the failed members."""
    st = np.asarray(tr.num_accepted_steps + tr.num_rejected_steps)
    err = np.linalg.norm(np.asarray(tr.position[:, -1] - ref.position[:, -1]), axis=-1)
    rej = np.asarray(tr.num_rejected_steps).sum() / st.sum()
    failed = int(np.sum(np.asarray(tr.status) != 0))
    print(
        f"{name:{width}s} steps {st.sum():8d}, median {np.median(st):6.0f}, max {st.max():6d}, rejected "
        f"{rej:4.0%}, max error {100 * err.max():.2f} cm, failed {failed}",
        flush=True,
    )


if __name__ == "__main__":
    raise SystemExit(main())
