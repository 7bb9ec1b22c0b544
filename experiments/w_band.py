"""Steps and accuracy of the default Rosenbrock-W solver against the width k of W's band-entry friction slope
(issue 10; `physics.linearise.band_entry_slope`: corners slower than about k ε get the secant slope |T|/|u|
along their sliding direction).

Solves paper-4.2 over --t1 for --n friction coefficients μ in [0.1, 0.6] (one vmapped solve per width,
default tolerances unless --atol, 201 saved times) and prints per width the steps attempted (sum, median,
max), the share rejected, and the distance [cm] of the final mass centre from Tsit5 at rtol 1e-9 (worst,
median, and the three worst members). Width 0 is W without the band-entry slope (the exact slope).

    python experiments/w_band.py --n 16 --t1 25 --eps 1e-4 --widths 0,2,3,4
    python experiments/w_band.py --n 32 --t1 25 --widths 0,2,3,4

The Tsit5 reference is cached under --cache (it takes minutes). Step counts do not depend on the machine's
load.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from w_controller import solve_mus, step_report  # noqa: E402  (the same solve and report as the controller comparison)

import jaxhoist as jh  # noqa: E402
from jaxhoist import set_param  # noqa: E402
from jaxhoist._numerics.rosenbrock import RosenbrockW  # noqa: E402  (internal: the default solver's class)
from jaxhoist._numerics.solve import as_float64_leaves  # noqa: E402  (internal: strongly typed leaves, one compile)
from jaxhoist._physics import linearise as lin  # noqa: E402  (internal: the width is a module constant)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=16, help="members, μ evenly in [0.1, 0.6]")
    p.add_argument("--t1", type=float, default=25.0, help="end time [s]")
    p.add_argument(
        "--eps", type=float, default=None, help="friction regularisation ε [m/s] (default preset's)"
    )
    p.add_argument("--atol", type=float, default=None, help="absolute tolerance (default SolverOptions')")
    p.add_argument("--widths", default="0,2", help="comma-separated k [-]; 0: without the band-entry slope")
    p.add_argument("--cache", default="/tmp/w_band", help="folder for the cached Tsit5 reference")
    a = p.parse_args(argv)
    sc = jh.load_scenario("paper-4.2")
    if a.eps is not None:
        sc = set_param(sc, "foundation.friction.regularisation_velocity", a.eps)
    sc = as_float64_leaves(sc)
    mus, ts = jnp.linspace(0.1, 0.6, a.n), jnp.linspace(0.0, a.t1, 201)

    def run(options):
        return solve_mus(sc, mus, ts, options)

    cache = Path(a.cache) / f"ref_n{a.n}_t{a.t1}_eps{a.eps}.npy"
    if cache.exists():
        ref_pos = np.load(cache)
    else:
        ref = run(jh.SolverOptions(diffrax.Tsit5(), rtol=1e-9, atol=1e-11, max_steps=2_000_000))
        ref_pos = np.asarray(ref.position)
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.save(cache, ref_pos)

    class _Ref:
        position = ref_pos

    exact, width0 = lin.band_entry_slope, lin.BAND_ENTRY_WIDTH
    kw = {} if a.atol is None else {"atol": a.atol}
    for k in (float(x) for x in a.widths.split(",")):
        # Read when the solve is traced; a new linearise function per width, so that the jitted solve core
        # (whose cache key holds the solver) is traced again.
        lin.band_entry_slope = (lambda law, mu, n, u, cx, cy: (cx, cy)) if k == 0 else exact
        lin.BAND_ENTRY_WIDTH = k if k else width0

        def linearise(t, y, args):
            return lin.linearise(t, y, args)

        t0 = time.perf_counter()
        tr = run(jh.SolverOptions(RosenbrockW(linearise=linearise), **kw))
        step_report(f"k = {k:g} ({time.perf_counter() - t0:.0f} s)", tr, _Ref, width=16)
        err = 100 * np.linalg.norm(np.asarray(tr.position[:, -1]) - ref_pos[:, -1], axis=-1)
        worst = np.argsort(err)[::-1][:3]
        print(
            f"    error median {np.median(err):.3f} cm; worst at mu {np.asarray(mus)[worst].round(3)}: "
            f"{err[worst].round(3)} cm",
            flush=True,
        )
    lin.band_entry_slope, lin.BAND_ENTRY_WIDTH = exact, width0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
