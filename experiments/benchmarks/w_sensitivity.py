"""Forward-mode sensitivities through the Rosenbrock-W solver: cost and accuracy.

For each tangent weight w (`RosenbrockW(tangent_weight=w)`, `jaxhoist/_numerics/sensitivity.py`), a
`scan(derivatives=True)` of paper-4.2 over N μ in [0.1, 0.6] to T s, against the plain scan of the same
members in the same process (the target: a time ratio <= 2), and d(final mass-centre position)/dμ
of REF members against central differences (h = 1e-4) of Tsit5 solves at rtol 1e-10 (their error is
below 1e-6 m). With `--discrete`, the same for the derivative of the steps themselves (the earlier
forward mode: `tangent_weight=None` is not an option, so it differentiates a Tsit5 scan at rtol 1e-6,
the earlier default of `scan(derivatives=True)`).

    python experiments/benchmarks/w_sensitivity.py --out out/w-sensitivity --n 64 --t1 25 --ref 8 \\
        --weights 0.01,0.1,1
    python experiments/benchmarks/w_sensitivity.py --out out/w-sensitivity --quick   # smoke check
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU = "foundation.friction_coefficient"


def timed(sc, mus, t1, **kw):
    r = jh.scan(
        sc, jh.Grid({MU: mus}), jh.Times(t1, n=2), observables=["final_position"], progress=False, **kw
    )
    t = r.attrs["timings_s"]
    return r, t["compute"], t["compile"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--n", type=int, default=64)
    p.add_argument("--t1", type=float, default=25.0)
    p.add_argument("--ref", type=int, default=8, help="members checked against central differences")
    p.add_argument("--weights", default="0.01,0.1,1")
    p.add_argument("--discrete", action="store_true", help="also the earlier Tsit5 forward mode")
    p.add_argument("--quick", action="store_true", help="smoke check: 4 members, 1 s, weight 0.1")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
        args.n, args.t1, args.ref, args.weights = 4, 1.0, 2, "0.1"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = jh.load_scenario("paper-4.2")
    mus = np.linspace(0.1, 0.6, args.n)
    pick = np.linspace(0, args.n - 1, args.ref).round().astype(int)

    tight = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-10, atol=1e-12, max_steps=10_000_000)
    ts = np.array([0.0, args.t1])
    ref_fn = jax.jit(
        lambda m: jh.simulate(jh.set_param(sc, MU, m), jh.Times(ts=ts), options=tight).position[-1]
    )
    h = 1e-4
    t0 = time.perf_counter()
    cd = np.stack([(np.asarray(ref_fn(mus[k] + h)) - np.asarray(ref_fn(mus[k] - h))) / (2 * h) for k in pick])
    print(f"central differences of {len(pick)} members: {time.perf_counter() - t0:.1f} s", flush=True)

    plain, plain_s, _ = timed(sc, mus, args.t1)
    rows = []
    cases = [
        (
            f"W, w = {w}",
            jh.SolverOptions(jh.RosenbrockW(tangent_weight=float(w)), adjoint=diffrax.ForwardMode()),
        )
        for w in args.weights.split(",")
    ]
    if args.discrete:
        cases.append(
            (
                "Tsit5 rtol 1e-6, steps differentiated",
                jh.SolverOptions(diffrax.Tsit5(), adjoint=diffrax.ForwardMode()),
            )
        )
    for name, opts in cases:
        r, s, comp = timed(sc, mus, args.t1, derivatives=True, options=opts)
        d = np.asarray(r["d_final_position"])[pick].reshape(len(pick), -1)
        err = np.linalg.norm(d - cd, axis=-1) / np.maximum(np.linalg.norm(cd, axis=-1), 1e-3)
        row = dict(
            case=name,
            ratio=s / plain_s,
            ms_per_trajectory=1e3 * s / args.n,
            plain_ms_per_trajectory=1e3 * plain_s / args.n,
            compile_s=comp,
            failed=int(np.sum(~r.ok)),
            rel_err_median=float(np.median(err)),
            rel_err_max=float(np.max(err)),
            worst_mu=float(mus[pick][int(np.argmax(err))]),
        )
        rows.append(row)
        print(json.dumps(row), flush=True)
    (out / "w_sensitivity.json").write_text(json.dumps(dict(args=vars(args), rows=rows), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
