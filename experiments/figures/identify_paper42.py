"""Identify μ, k, h, c_l and b_l of paper-4.2 from a synthetic measurement; compare solvers and scipy.

The measurement: the mass-centre path (position_x, _y, _z) sampled at 50 Hz with 5 mm Gaussian noise and the
rope tension with 1 % noise (standard deviation 1 % of its RMS value), simulated from the paper-4.2 preset
with Tsit5 at `--data-rtol` (default 1e-8, atol 1e-10). The fit starts from every parameter perturbed by
±30 % (alternating signs) and fits all five together with `jaxhoist.identify` (optimistix
Levenberg-Marquardt, forward-mode sensitivities), once per `--solver` (repeatable; NAME or NAME@RTOL with
NAME rosenbrock-w or tsit5, atol = RTOL/100; without @RTOL `--rtol`/`--atol`, else the solver's default
tolerances; without `--solver`, identify's default options). In the same process,
`scipy.optimize.least_squares` (trust-region reflective, 2-point finite-difference Jacobian) solves the same
weighted problem in the same log variables, through the compiled forward solve of the data's solver.

Printed and saved as markdown (DIR/identify_paper42.md): truth, start, estimate, standard error,
(estimate - truth)/SE, scipy's estimate; iterations, function/Jacobian evaluations and wall times (compile
apart); a check of each fit's Jacobian against central differences of the data's accurate solve at the
estimate; and, with several solvers, every fit's estimate against the first one's in units of its SE.

    # 3 s horizon, identify's default
    python experiments/figures/identify_paper42.py --out out/identify --quick
    python experiments/figures/identify_paper42.py --out out/identify --quick --no-scipy \\
        --solver tsit5 --solver rosenbrock-w --solver rosenbrock-w@1e-4
    python experiments/figures/identify_paper42.py --out out/identify           # the full 25 s horizon
"""

import argparse
import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import numpy as np  # noqa: E402
import scipy.optimize  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import identify, residual_function, synthetic_measurement, write_measurement  # noqa: E402
from jaxhoist._apps.identify.fit import plot_fit  # noqa: E402  (internal: the CLI's plotting helper)

PARAMS = ["mu", "k", "h", "c_l", "b_l"]
PATHS = {
    "mu": "foundation.friction_coefficient",
    "k": "foundation.stiffness",
    "h": "foundation.damping",
    "c_l": "rope.stiffness",
    "b_l": "rope.damping",
}
PERTURB = {"mu": 1.3, "k": 0.7, "h": 1.3, "c_l": 0.7, "b_l": 1.3}  # ±30 %, alternating


SOLVERS = {"rosenbrock-w": jh.RosenbrockW, "tsit5": diffrax.Tsit5}


def fit_options(spec: str | None, rtol, atol) -> tuple[str, jh.SolverOptions | None]:
    """`(label, options)` of a `--solver` spec NAME[@RTOL]; None: identify's default (options None)."""
    if spec is None:
        return "identify's default", None
    name, _, tol = spec.partition("@")
    if name not in SOLVERS:
        raise SystemExit(f"--solver {spec}: unknown solver {name!r} (choose from {', '.join(SOLVERS)})")
    if tol:
        rtol, atol = float(tol), float(tol) / 100
    opts = jh.SolverOptions(SOLVERS[name](), rtol=rtol, atol=atol, max_steps=1_000_000)
    ctl = opts.stepsize_controller
    return f"{name} rtol {ctl.rtol:g} atol {ctl.atol:g}", opts  # pyright: ignore[reportAttributeAccessIssue]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/identify_paper42")
    p.add_argument("--quick", action="store_true", help="3 s horizon instead of 25 s")
    p.add_argument("--t1", type=float, default=None, help="horizon [s] (overrides --quick)")
    p.add_argument("--seed", type=int, default=42)
    p.add_argument(
        "--solver",
        action="append",
        default=None,
        metavar="NAME[@RTOL]",
        help="the fit's solver, rosenbrock-w or tsit5, optionally with its rtol (atol = rtol/100; without it "
        "--rtol/--atol or the solver's defaults); repeatable: one fit per solver on the same data (default: "
        "identify's default options)",
    )
    p.add_argument("--rtol", type=float, default=None, help="ODE rtol of fits without @RTOL")
    p.add_argument("--atol", type=float, default=None, help="ODE atol of fits without @RTOL")
    p.add_argument(
        "--data-rtol",
        type=float,
        default=1e-8,
        help="rtol of the Tsit5 solve that makes the data and the central-difference Jacobian (atol "
        "rtol/100; default 1e-8)",
    )
    p.add_argument(
        "--diff-step",
        type=float,
        default=1e-4,
        help="scipy's relative finite-difference step in the log variables (default 1e-4)",
    )
    p.add_argument("--no-scipy", action="store_true")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    truth_sc = jh.load_scenario("paper-4.2")
    t1 = args.t1 if args.t1 is not None else (3.0 if args.quick else truth_sc.t1)
    t = np.round(np.arange(0.0, t1 + 1e-9, 0.02), 10)  # 50 Hz
    truth = {k: float(jh.get_param(truth_sc, PATHS[k])) for k in PARAMS}
    start = {k: truth[k] * PERTURB[k] for k in PARAMS}
    data_solver = jh.SolverOptions(
        diffrax.Tsit5(), rtol=args.data_rtol, atol=args.data_rtol / 100, max_steps=1_000_000
    )
    fits = [fit_options(spec, args.rtol, args.atol) for spec in (args.solver or [None])]

    w = time.perf_counter()
    meas = synthetic_measurement(
        truth_sc,
        t,
        ["position", "rope_tension"],
        noise={"position": 0.005, "rope_tension": "1%"},
        seed=args.seed,
        source="paper-4.2 synthetic",
        options=data_solver,
    )
    t_synth = time.perf_counter() - w
    csv = write_measurement(
        out / "measurement.csv",
        meas,
        units={"rope_tension": "kN"},
        description=f"paper-4.2, 0..{t1:g} s at 50 Hz, 5 mm position noise, 1 % tension noise, "
        f"seed {args.seed}",
    )
    print(
        f"measurement: {t.size} samples x {len(meas.names)} signals, 0..{t1:g} s -> {csv} "
        f"(simulated in {t_synth:.2f} s incl. compile)",
        flush=True,
    )
    # central differences of the accurate (data) solve: the reference for every fit's Jacobian
    fn_ref, _ = residual_function(truth_sc, csv, PARAMS, start=start, t1=t1, options=data_solver)

    # ---- jaxhoist: LM with forward-mode sensitivities, once per solver, on the same data
    results = []
    for label, solver in fits:
        print(f"--- fit with {label}", flush=True)
        res = identify(
            truth_sc, csv, PARAMS, start=start, t1=t1, options=solver, fit=jh.FitOptions(max_iterations=200)
        )
        print(res.summary(), flush=True)
        J_ad = res.jacobian
        J_fd = np.empty_like(J_ad)
        for i in range(len(PARAMS)):
            h = 1e-3 * res.values[i]
            tp, tm = res.values.copy(), res.values.copy()
            tp[i] += h
            tm[i] -= h
            J_fd[:, i] = (fn_ref(tp) - fn_ref(tm)) / (2 * h)
        jac_err = {
            k: float(np.linalg.norm(J_ad[:, i] - J_fd[:, i]) / np.linalg.norm(J_fd[:, i]))
            for i, k in enumerate(PARAMS)
        }
        results.append((label, solver, res, jac_err))
    label, _, res, jac_err = results[0]
    est = dict(zip(PARAMS, res.values, strict=True))
    se = dict(zip(PARAMS, res.std_errors, strict=True))

    # ---- scipy: the same whitened residuals, 2-point finite differences in z = log(θ/θ_start)
    sp = None
    if not args.no_scipy:
        # the accurate solve of the data: finite differences of Tsit5 at rtol 1e-6 were too noisy
        # for a relative step of 1e-4 (scipy stopped at the start, `xtol` satisfied, cost 83 685 against 285)
        fn, theta0 = fn_ref, np.array([start[k] for k in PARAMS])
        fn(theta0)  # the forward solve compiled outside the timing
        th0 = np.array([start[k] for k in PARAMS])
        nfev = [0]

        def fun(z):
            nfev[0] += 1
            r = fn(th0 * np.exp(z))
            return np.where(np.isfinite(r), r, 1e6)

        w = time.perf_counter()
        sol = scipy.optimize.least_squares(
            fun,
            np.zeros(len(PARAMS)),
            jac="2-point",
            diff_step=args.diff_step,
            method="trf",
            xtol=1e-8,
            ftol=1e-8,
            gtol=1e-8,
            max_nfev=400,
        )
        t_sp = time.perf_counter() - w
        sp = {
            "estimate": dict(zip(PARAMS, (th0 * np.exp(sol.x)).tolist(), strict=True)),
            "cost": float(sol.cost),
            "nfev": int(sol.nfev),
            "njev": int(sol.njev or 0),
            "residual_evaluations": nfev[0],
            "time_s": t_sp,
            "status": int(sol.status),
            "message": sol.message,
        }
        print(
            f"scipy least_squares (Tsit5 rtol {args.data_rtol:g}): {sol.message} cost {sol.cost:.6g}, "
            f"{sol.nfev} fev + {sol.njev} jev ({nfev[0]} forward solves), {t_sp:.2f} s",
            flush=True,
        )

    # ---- report
    rows = []
    for k in PARAMS:
        z = (est[k] - truth[k]) / se[k]
        rows.append(
            f"| {k} ({PATHS[k]}) | {truth[k]:.6g} | {start[k]:.6g} | {est[k]:.6g} | {se[k]:.3g} "
            f"({100 * se[k] / abs(est[k]):.2g} %) | {100 * (est[k] / truth[k] - 1):+.3f} % | {z:+.2f} | "
            + (
                f"{sp['estimate'][k]:.6g} ({100 * (sp['estimate'][k] / truth[k] - 1):+.3f} %) |"
                if sp
                else "- |"
            )
            + f" {100 * jac_err[k]:.2g} % |"
        )
    within = {k: abs(est[k] - truth[k]) <= 2 * se[k] for k in PARAMS}
    one_pct = {k: abs(est[k] / truth[k] - 1) <= 0.01 for k in ("mu", "c_l")}
    cmd = "python " + " ".join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])])
    md = [
        f"# Identification of μ, k, h, c_l, b_l on paper-4.2 ({'quick, ' if args.quick else ''}0..{t1:g} s)",
        "",
        f"Command: `{cmd}`  ",
        f"Data: {t.size} samples at 50 Hz of position_x/y/z (σ = 5 mm) and rope_tension (σ = 1 % of its RMS "
        f"= {meas.noise['rope_tension']:.4g} N), seed {args.seed}, simulated with Tsit5 rtol "
        f"{args.data_rtol:g}; the fit's solver: {label}.",
        "",
        "| parameter | truth | start (±30 %) | estimate | std error | error | (est - truth)/SE | "
        "scipy FD estimate | AD vs FD Jacobian |",
        "|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"| | jaxhoist LM (forward sensitivities, {label}) | scipy least_squares (2-point FD, Tsit5 rtol "
        f"{args.data_rtol:g}) |",
        "|---|---|---|",
        f"| iterations | {res.iterations} LM steps ({res.accepted_steps} accepted) | "
        + (
            f"{sp['nfev']} fev + {sp['njev']} Jacobians ({sp['residual_evaluations']} forward solves) |"
            if sp
            else "- |"
        ),
        f"| cost 0.5Σr² | {res.cost:.6g} | " + (f"{sp['cost']:.6g} |" if sp else "- |"),
        f"| wall time | {res.fit_time:.2f} s fit + {res.compile_time:.2f} s compile | "
        + (f"{sp['time_s']:.2f} s (forward solve compiled beforehand) |" if sp else "- |"),
        f"| outcome | {res.message}; χ²/dof = {res.chi2_reduced:.4g}; identifiable: {res.identifiable} | "
        + (f"{sp['message']} |" if sp else "- |"),
        "",
        f"Within 2 SE of the truth: {', '.join(f'{k}: {v}' for k, v in within.items())}.  ",
        f"μ and c_l within 1 %: {', '.join(f'{k}: {v}' for k, v in one_pct.items())}.  ",
        f"Condition number of JᵀJ (relative units): {res.condition_number:.3g}.  ",
        "AD vs FD Jacobian: ‖J_fwd - J_cd‖/‖J_cd‖ per column at the estimate (central differences of the "
        f"Tsit5 rtol {args.data_rtol:g} solve, relative step 1e-3).",
        "",
        "Correlations:",
        "",
        "| | " + " | ".join(PARAMS) + " |",
        "|---|" + "---|" * len(PARAMS),
        *[
            f"| {k} | " + " | ".join(f"{c:+.3f}" for c in res.correlation[i]) + " |"
            for i, k in enumerate(PARAMS)
        ],
    ]
    if res.warnings:
        md += ["", "Warnings:", "", *[f"- {w_}" for w_ in res.warnings]]
    if len(results) > 1:
        md += [
            "",
            f"Solvers on the same data: each fit's estimate minus the first one's ({label}), in units of the "
            "first one's standard error; wall time of the fit (compile apart) and of the compile; LM steps; "
            "the largest AD vs FD Jacobian error over the columns.",
            "",
            "| fit's solver | " + " | ".join(f"Δ{k}/SE" for k in PARAMS) + " | fit | compile | LM steps | "
            "cost | max Jacobian error |",
            "|---|" + "---|" * (len(PARAMS) + 5),
        ]
        for lab, _, r_, je in results:
            d = (r_.values - res.values) / res.std_errors
            md.append(
                f"| {lab} | "
                + " | ".join(f"{x:+.2g}" for x in d)
                + f" | {r_.fit_time:.2f} s | {r_.compile_time:.2f} s | {r_.iterations} ({r_.accepted_steps} "
                f"accepted) | {r_.cost:.6g} | {100 * max(je.values()):.2g} % |"
            )
    text = "\n".join(md) + "\n"
    print(text)
    name = "identify_paper42_quick" if args.quick else "identify_paper42"
    (out / f"{name}.md").write_text(text)
    (out / f"{name}.json").write_text(
        json.dumps(
            {
                "truth": truth,
                "start": start,
                "jaxhoist": res.to_dict(),
                "fits": [
                    {"solver": lab, "result": r_.to_dict(), "jacobian_rel_error": je}
                    for lab, _, r_, je in results
                ],
                "scipy": sp,
                "jacobian_rel_error": jac_err,
                "within_2se": within,
                "within_1pct": one_pct,
                "command": cmd,
            },
            indent=2,
            default=str,
        )
        + "\n"
    )
    fig = plot_fit(res)
    fig.savefig(out / f"{name}_fit.png", dpi=110)
    print(f"wrote {out / (name + '.md')}, {out / (name + '.json')}, {out / (name + '_fit.png')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
