"""Steps of the default Rosenbrock-W solver against an earlier linearisation (issue 10).

`physics/linearise.py` puts into W the stiffness in the orientation that comes from the corner velocities
turning with the body at fixed generalised velocities (δu_i = -R [ω x ρ_i]x δθ, through the friction slope
μN/ε while a corner sticks). This script solves paper-4.2 over --t1 for --n friction coefficients μ in
[0.1, 0.6] (one vmapped solve per variant, default tolerances, --n-save saved times as in a scan) with

- `current`: the linearisation as checked out;
- `baseline`: `jaxhoist/_physics/linearise.py` as it was at git revision --baseline (default 01e8863, before
  the term), everything else as checked out;
- `dense` (with --dense MU): W = the full Jacobian of the vector field by `jax.jacfwd` at every step, for
  one member (the reference for what a W can do);

Prints steps attempted (sum, median, max: a lock-step group's cost follows its slowest member), the
share rejected, and the largest distance of the final mass centre from Tsit5 at rtol 1e-9.

    python experiments/w_orientation.py --n 32 --t1 25 --dense 0.55
    python experiments/w_orientation.py --n 16 --t1 25 --eps 1e-4
    python experiments/w_orientation.py --n 16 --t1 25 --eps 1e-4 --atol 3e-5 --baseline 3bc0e4f

Step counts do not depend on the machine's load.
"""

from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from bench_w_step import _module_at  # noqa: E402  (the module of a git revision, imported beside the package)
from jax.flatten_util import ravel_pytree  # noqa: E402
from w_controller import solve_mus, step_report  # noqa: E402  (the same solve and report as the controller comparison)

import jaxhoist as jh  # noqa: E402
from jaxhoist import set_param, vector_field  # noqa: E402
from jaxhoist._numerics.rosenbrock import RosenbrockW  # noqa: E402  (internal: a W with another linearisation)
from jaxhoist._numerics.solve import as_float64_leaves  # noqa: E402  (internal: strongly typed leaves, one compile)


class _Dense(eqx.Module):
    """W = the full Jacobian J of the flattened state; (I/(hγ) - J) u = r by LU."""

    J: jax.Array
    unravel: object = eqx.field(static=True)

    def factor(self, hg):
        return jax.scipy.linalg.lu_factor(jnp.eye(self.J.shape[0]) / hg - self.J)

    def solve(self, lu, r, hg):
        return self.unravel(jax.scipy.linalg.lu_solve(lu, ravel_pytree(r)[0]))


def _dense_linearise(t, y, args):
    flat, unravel = ravel_pytree(y)
    J = jax.jacfwd(lambda v: ravel_pytree(vector_field(t, unravel(v), args))[0])(flat)
    return _Dense(J, unravel)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=32, help="members, μ evenly in [0.1, 0.6]")
    p.add_argument("--t1", type=float, default=25.0, help="end time [s]")
    p.add_argument("--n-save", type=int, default=201, help="saved times (the steps land on each)")
    p.add_argument("--baseline", default="01e8863", help="git revision of the linearisation without the term")
    p.add_argument(
        "--eps", type=float, default=None, help="friction regularisation ε [m/s] (default the preset's)"
    )
    p.add_argument("--dense", type=float, default=None, metavar="MU", help="also the full-Jacobian W at MU")
    p.add_argument("--atol", type=float, default=None, help="absolute tolerance (default SolverOptions')")
    a = p.parse_args(argv)
    sc = jh.load_scenario("paper-4.2")
    if a.eps is not None:
        sc = set_param(sc, "foundation.friction.regularisation_velocity", a.eps)
    sc = as_float64_leaves(sc)
    mus, ts = jnp.linspace(0.1, 0.6, a.n), jnp.linspace(0.0, a.t1, a.n_save)

    def run(options, members):
        return solve_mus(sc, members, ts, options)

    ref_options = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-9, atol=1e-11, max_steps=2_000_000)
    ref = run(ref_options, mus)
    old = _module_at(a.baseline, "jaxhoist/_physics/linearise.py", "jaxhoist._physics")
    variants = {
        "current": (RosenbrockW(), mus, ref),
        f"baseline {a.baseline}": (RosenbrockW(linearise=old.linearise), mus, ref),
    }
    if a.dense is not None:
        one = jnp.asarray([a.dense])
        variants[f"dense J, mu {a.dense}"] = (
            RosenbrockW(linearise=_dense_linearise),
            one,
            run(ref_options, one),
        )
        variants[f"current, mu {a.dense}"] = (RosenbrockW(), one, variants[f"dense J, mu {a.dense}"][2])
        variants[f"baseline, mu {a.dense}"] = (
            RosenbrockW(linearise=old.linearise),
            one,
            variants[f"dense J, mu {a.dense}"][2],
        )
    for name, (solver, members, r) in variants.items():
        kw = {} if a.atol is None else {"atol": a.atol}
        step_report(name, run(jh.SolverOptions(solver, **kw), members), r, width=26)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
