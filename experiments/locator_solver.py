"""Which solver should `locate_bifurcation` default to? (issue 10, point 3)

Locates the paper's §4.3 change on the paper-4.3 preset (25 s, the crossing of the final pitch ϑ(t1) = 15°
in μ over the bracket (0.362, 0.365), as in experiments/bifurcation_calibrate.py) with safeguarded Newton
(forward-mode slopes) and each solver below, one process, and prints for each: μ*, its distance from the
reference μ* (Tsit5 at rtol 1e-10, atol 1e-12, bisection), solves, derivative solves, accepted steps, wall
time after compilation (a second, identical call), and the first call's time (with compilation).

    python experiments/locator_solver.py                      # the paper's bracket, default saved times
    python experiments/locator_solver.py --tol 1e-7 --only w  # one candidate

The candidates: Tsit5 at rtol 1e-6 (the locator's default) and the Rosenbrock-W solver in
forward mode (`SolverOptions(adjoint=diffrax.ForwardMode())`: Newton's slopes are the error-controlled
sensitivities of `_numerics/sensitivity.py`): as it was until 2026-11-27 (no ∂f/∂t term, integral
controller, rtol 1e-3, atol 1e-5), at its default now (the term, PI controller, rtol 5e-4, atol 1e-5) and
at tighter tolerances (the term and the PI controller, atol = rtol / 100).

Measured 2026-11-25 at 65642d2 (load average 2-3): reference μ* = 0.3635004;
    tsit5 rtol 1e-6   0.3635002 (-1.4e-7), 4 solves,  6.4 s
    w rtol 1e-3       0.3635064 (+6.1e-6), 5 solves, 11.8 s
    w rtol 1e-4       0.3635015 (+1.1e-6), 5 solves, 26.9 s
and before the W fix (01e8863): w rtol 1e-3 +1.4e-5 in 13.2 s, rtol 1e-5 -7.9e-8 in 44.0 s (Tsit5 6.4 s).

Measured 2026-11-27 at 61d5f46 (the ∂f/∂t term and the PI controller the W default; Intel machine, nothing
else running): reference μ* = 0.3635004 (30.0 s);
    tsit5 rtol 1e-6          0.3635002 (-1.4e-7), 4 solves, 123 946 steps,  8.46 s (first call 12.6 s)
    w before (rtol 1e-3)     0.3634944 (-6.0e-6), 5 solves,  21 038 steps, 10.66 s (first call 28.1 s)
    w default (rtol 5e-4)    0.3634937 (-6.6e-6), 9 solves,  15 157 steps,  7.01 s (first call 29.3 s)
    w rtol 1e-4              0.3634998 (-5.9e-7), 4 solves,  13 445 steps,  5.87 s (first call 27.5 s)
    w rtol 1e-5              0.3635002 (-1.4e-7), 4 solves,  27 851 steps, 16.49 s (first call 57.7 s)
W at rtol 1e-4 is now 1.4x faster than Tsit5 after compilation but 4x less accurate, and its first call
(what a user of `locate_bifurcation` waits for) takes 2.2x Tsit5's: the locator keeps Tsit5.

Measured 2026-11-27 at 9de8159 (the sensitivities' W stages in a loop; `--only tsit5 --no-reference` and
`--only "w default" --no-reference`, a process each, Intel machine):
    tsit5 rtol 1e-6          0.3635002, 4 solves, 123 946 steps, 7.80 s (first call 13.3 s)
    w default (rtol 5e-4)    0.3634941, 7 solves,  11 801 steps, 6.20 s (first call 24.1 s)
W's first call is still 1.8x Tsit5's, and μ* 6.3e-6 off: the locator keeps Tsit5.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU = "foundation.friction_coefficient"
OBS = "final_theta"
LEVEL = float(np.radians(15.0))
BRACKET = (0.362, 0.365)

CANDIDATES = {
    "tsit5 rtol 1e-6": lambda: jh.SolverOptions(diffrax.Tsit5()),
    "w before 2026-11-27 (rtol 1e-3)": lambda: jh.SolverOptions(
        jh.RosenbrockW(time_derivative=False),
        diffrax.PIDController(rtol=1e-3, atol=1e-5),
        adjoint=diffrax.ForwardMode(),
    ),
    "w default (rtol 5e-4)": lambda: jh.SolverOptions(adjoint=diffrax.ForwardMode()),
    "w rtol 1e-4": lambda: jh.SolverOptions(adjoint=diffrax.ForwardMode(), rtol=1e-4, atol=1e-6),
    "w rtol 1e-5": lambda: jh.SolverOptions(adjoint=diffrax.ForwardMode(), rtol=1e-5, atol=1e-7),
}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tol", type=float, default=1e-6, help="final bracket width in μ (default 1e-6)")
    p.add_argument("--only", default="", help="run only candidates whose name contains this text")
    p.add_argument("--no-reference", action="store_true", help="skip the rtol 1e-10 reference")
    p.add_argument("--out", default=None, help="write DIR/locator_solver.json")
    a = p.parse_args(argv)
    sc = jh.load_scenario("paper-4.3")
    rows = {}
    ref = None
    if not a.no_reference:
        t0 = time.perf_counter()
        r = jh.locate_bifurcation(
            sc,
            MU,
            OBS,
            BRACKET,
            level=LEVEL,
            search=jh.SearchOptions(jh.Bisection(), tol=a.tol),
            options=jh.SolverOptions(diffrax.Tsit5(), rtol=1e-10, atol=1e-12, max_steps=2_000_000),
        )
        ref = r.value
        wall = time.perf_counter() - t0
        print(f"reference (Tsit5 rtol 1e-10, bisection): mu* = {ref:.7f}, {wall:.1f} s", flush=True)
    for name, make in CANDIDATES.items():
        if a.only and a.only not in name:
            continue
        kw = dict(level=LEVEL, search=jh.SearchOptions(tol=a.tol), options=make())
        t0 = time.perf_counter()
        jh.locate_bifurcation(sc, MU, OBS, BRACKET, **kw)  # compiles
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        b = jh.locate_bifurcation(sc, MU, OBS, BRACKET, **kw)
        wall = time.perf_counter() - t0
        row = dict(
            mu_star=b.value,
            error=None if ref is None else b.value - ref,
            converged=b.converged,
            n_solves=b.n_solves,
            n_derivative_solves=b.n_derivative_solves,
            steps=b.steps,
            wall_s=wall,
            first_call_s=first,
        )
        rows[name] = row
        err = "" if ref is None else f", error {row['error']:+.1e}"
        print(
            f"{name:34s} mu* = {b.value:.7f}{err}, {b.n_solves} solves "
            f"({b.n_derivative_solves} with slopes), "
            f"{b.steps} steps, {wall:.2f} s (first call {first:.1f} s), converged {b.converged}",
            flush=True,
        )
    if a.out:
        out = Path(a.out)
        out.mkdir(parents=True, exist_ok=True)
        rec = dict(reference=ref, tol=a.tol, candidates=rows, load_average=list(os.getloadavg()))
        (out / "locator_solver.json").write_text(json.dumps(rec, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
