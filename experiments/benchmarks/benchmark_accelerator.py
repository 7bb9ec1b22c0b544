"""The default scan on whatever device JAX finds (4096 and 65 536 members, with the
device named), and the check of its results on this machine afterwards.

    python experiments/benchmarks/benchmark_accelerator.py --out DIR                      # on the GPU machine
    python experiments/benchmarks/benchmark_accelerator.py --out DIR --runs 4096,4096@256,65536
    python experiments/benchmarks/benchmark_accelerator.py --check DIR  # afterwards, on a CPU
    # smoke check: 16 members, 2 s, checked
    python experiments/benchmarks/benchmark_accelerator.py --out DIR --quick

Each run is the **default call** of `jaxhoist.scan` on paper-4.2 as shipped (ε = 1e-3 m/s, Rosenbrock-W,
rtol 1e-3, atol 1e-5, the default group width for the device: `apps.scan_layout.adaptive_lanes`), μ evenly
spaced in [0.1, 0.6], 25 s, observables final position and Euler angles. A run is named by its member count,
optionally with `@LANES` (that group width instead of the default), `:eps=V` (another regularisation
velocity [m/s]) or `:deriv` (forward sensitivities, `derivatives=True`): `4096`, `4096@256`,
`4096:eps=1e-4`, `4096:deriv`; `:tsit5` is not a scan but the baseline, a plain
`jax.jit(jax.vmap(diffrax.diffeqsolve(Tsit5, PIDController(1e-6, 1e-8))))` over the members in one lock
step. Runs go in the order given; once `--budget` seconds have passed, the rest are skipped (the device
machine is lent by the minute). Per run: compile and compute time, ms per trajectory, steps (median,
max), failed members, the group width, the device's peak memory; DIR/accelerator.json after every run, and
DIR/finals_<run>.npz (μ, final position, status, steps) for the check.

`--check DIR` reads those files on any machine and compares every saved run's final positions on `--ref-n`
evenly spaced members with adaptive Tsit5 at rtol 1e-10 (atol 1e-12) solved here, and the 4096-member
default run with the same scan solved here (CPU against GPU: same method, other rounding and lock-step
groups).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import jax

# on a CPU, every core by default (--devices N to change), set before JAX starts its backend; an accelerator
# is JAX's default backend whatever this says
jax.config.update(
    "jax_num_cpu_devices",
    int(sys.argv[sys.argv.index("--devices") + 1]) if "--devices" in sys.argv else (os.cpu_count() or 1),
)
jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402

MU = "foundation.friction_coefficient"
EPS = "foundation.friction.regularisation_velocity"
OBS = ["final_position", "final_euler"]


def parse_run(spec: str) -> dict:
    """'4096@256:eps=1e-4:deriv' -> {n, lanes, eps, deriv, tag}."""
    head, *mods = spec.split(":")
    n, _, lanes = head.partition("@")
    run = {"n": int(n), "lanes": int(lanes) if lanes else None, "eps": None, "deriv": False, "tsit5": False}
    for m in mods:
        if m in ("deriv", "tsit5"):
            run[m] = True
        elif m.startswith("eps="):
            run["eps"] = float(m[4:])
        else:
            raise SystemExit(f"unknown run modifier {m!r} in {spec!r}")
    run["tag"] = spec.replace("@", "_lanes").replace(":", "_").replace("=", "")
    return run


def device_peak_bytes() -> int | None:
    stats = jax.devices()[0].memory_stats() or {}
    return stats.get("peak_bytes_in_use")


def plain_vmap_tsit5(sc, mus, t1: float) -> tuple[dict, dict]:
    """The baseline: one `jax.vmap` of `diffeqsolve(Tsit5, PIDController(1e-6, 1e-8))` over all `mus`."""
    sol_fn = jax.jit(
        jax.vmap(lambda mu: tsit5_final(sc, mu, t1, diffrax.PIDController(rtol=1e-6, atol=1e-8)))
    )
    x = jax.numpy.asarray(mus)
    t0 = time.perf_counter()
    compiled = sol_fn.lower(x).compile()
    tc = time.perf_counter() - t0
    t0 = time.perf_counter()
    pos, steps, result = jax.block_until_ready(compiled(x))
    wall = time.perf_counter() - t0
    ok = np.asarray(result)
    rec = {
        "members": len(mus),
        "lanes": len(mus),
        "solver": "Tsit5, PIDController(rtol 1e-6, atol 1e-8), plain jax.vmap",
        "compile_s": tc,
        "compute_s": wall,
        "total_s": tc + wall,
        "ms_per_trajectory": 1e3 * wall / len(mus),
        "steps_median": int(np.median(steps)),
        "steps_max": int(np.max(steps)),
        "rejected_median": None,
        "failed": int(np.sum(~ok)),
        "device_peak_bytes": device_peak_bytes(),
    }
    finals = {"mu": mus, "final_position": np.asarray(pos), "status": (~ok).astype(np.int32), "steps": steps}
    return rec, finals


def tsit5_final(sc, mu, t1: float, controller, max_steps: int = 1_000_000):
    """(final mass-centre position [m], accepted steps, success) of one Tsit5 solve at μ."""
    s = eqx.tree_at(lambda x: x.foundation.friction_coefficient, sc, mu)
    y0, c = jh.initial_state(s)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(jh.vector_field),
        diffrax.Tsit5(),
        0.0,
        t1,
        None,
        y0,
        (s, c),
        stepsize_controller=controller,
        max_steps=max_steps,
        saveat=diffrax.SaveAt(t1=True),
        throw=False,
    )
    assert sol.stats is not None and sol.ys is not None
    ok = (sol.result == diffrax.RESULTS.successful) & jnp.all(jnp.isfinite(sol.ys.position[-1]))
    return sol.ys.position[-1], sol.stats["num_accepted_steps"], ok


def run_one(sc, run: dict, t1: float) -> tuple[dict, dict]:
    mus = np.linspace(0.1, 0.6, run["n"])
    s = sc if run["eps"] is None else sc.replace(**{EPS: run["eps"]})
    if run["tsit5"]:
        rec, finals = plain_vmap_tsit5(s, mus, t1)
        return {"run": run, **rec}, finals
    batch = jh.BatchOptions() if run["lanes"] is None else jh.BatchOptions(lanes=run["lanes"])
    r = jh.scan(s, {MU: mus}, jh.Times(t1, n=2), observables=OBS, batch=batch, derivatives=run["deriv"])
    t = r.attrs["timings_s"]
    rec = {
        "run": run,
        "members": run["n"],
        "lanes": r.attrs["lanes"],
        "solver": r.attrs["solver"],
        "compile_s": t["compile"],
        "compute_s": t["compute"],
        "total_s": t["total"],
        "ms_per_trajectory": 1e3 * t["compute"] / run["n"],
        "steps_median": int(np.median(r.num_accepted_steps)),
        "steps_max": int(np.max(r.num_accepted_steps)),
        "rejected_median": int(np.median(r.num_rejected_steps)),
        "failed": int(np.sum(~r.ok)),
        "device_peak_bytes": device_peak_bytes(),
    }
    finals = {
        "mu": mus,
        "final_position": np.asarray(r["final_position"]),
        "status": np.asarray(r.status),
        "steps": np.asarray(r.num_accepted_steps),
    }
    return rec, finals


def bench(args) -> None:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    import importlib.metadata as md

    dev = jax.devices()[0]
    rec: dict = {
        "device": f"{dev.platform}: {dev.device_kind}",
        "devices": [str(d) for d in jax.devices()],
        "versions": {p: md.version(p) for p in ("jax", "jaxlib", "diffrax", "equinox")},
        "command": [sys.executable, *sys.argv],
        "t1": args.t1,
        "runs": [],
        "skipped": [],
    }
    print(f"device {rec['device']} ({len(jax.devices())}), versions {rec['versions']}", flush=True)
    sc = jh.load_scenario("paper-4.2")
    start = time.perf_counter()
    for spec in args.runs.split(","):
        if time.perf_counter() - start > args.budget:
            rec["skipped"].append(spec)
            print(f"  {spec}: skipped (budget of {args.budget:g} s spent)", flush=True)
            continue
        run = parse_run(spec)
        r, finals = run_one(sc, run, args.t1)
        rec["runs"].append(r)
        np.savez(out / f"finals_{run['tag']}.npz", **finals)
        (out / "accelerator.json").write_text(json.dumps(rec, indent=1) + "\n")
        peak = r["device_peak_bytes"]
        print(
            f"  {spec}: lanes {r['lanes']}, compile {r['compile_s']:.1f} s, compute {r['compute_s']:.2f} s, "
            f"{r['ms_per_trajectory']:.4f} ms per trajectory, steps median {r['steps_median']} max "
            f"{r['steps_max']}, rejected median {r['rejected_median']}, failed {r['failed']}, device peak "
            f"{'?' if peak is None else f'{peak / 2**20:.0f} MiB'}",
            flush=True,
        )
    (out / "accelerator.json").write_text(json.dumps(rec, indent=1) + "\n")


def reference(sc, mus, t1) -> np.ndarray:
    """Final positions of adaptive Tsit5 at rtol 1e-10, atol 1e-12, vmapped over groups of 8 members."""
    controller = diffrax.PIDController(rtol=1e-10, atol=1e-12)
    f = jax.jit(jax.vmap(lambda mu: tsit5_final(sc, mu, t1, controller, max_steps=5_000_000)))
    outs = [f(jax.numpy.asarray(c)) for c in np.array_split(mus, max(1, len(mus) // 8))]
    if not all(bool(np.all(np.asarray(o[2]))) for o in outs):
        raise RuntimeError("a reference solve failed")
    return np.concatenate([np.asarray(o[0]) for o in outs])


def check(args) -> None:
    src = Path(args.check)
    rec = json.loads((src / "accelerator.json").read_text())
    sc = jh.load_scenario("paper-4.2")
    t1 = rec["t1"]
    print(f"results of {rec['device']} ({rec['versions']}), t1 = {t1:g} s; checked on {jax.devices()[0]}")
    report = {"device": rec["device"], "runs": {}}
    refs: dict[bytes, np.ndarray] = {}  # runs of the same members share one reference
    for r in rec["runs"]:
        run = r["run"]
        if run["eps"] is not None or run["deriv"]:  # other physics, or the same solves as a plain run
            continue
        z = np.load(src / f"finals_{run['tag']}.npz")
        idx = np.unique(np.linspace(0, run["n"] - 1, args.ref_n).round().astype(int))
        t0 = time.perf_counter()
        mus = z["mu"][idx]
        if mus.tobytes() not in refs:
            refs[mus.tobytes()] = reference(sc, mus, t1)
        ref = refs[mus.tobytes()]
        err = np.linalg.norm(z["final_position"][idx] - ref, axis=-1)
        row = {
            "members_checked": int(idx.size),
            "fraction_within_1cm": float(np.mean(err < 0.01)),
            "median_cm": float(100 * np.median(err)),
            "max_cm": float(100 * np.max(err)),
            "failed": int(np.sum(z["status"] != 0)),
        }
        print(
            f"  {run['tag']}: {100 * row['fraction_within_1cm']:.1f} % of {idx.size} within 1 cm of Tsit5 "
            f"rtol 1e-10, median {row['median_cm']:.3g} cm, max {row['max_cm']:.3g} cm, failed "
            f"{row['failed']} (reference {time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
        if run["n"] == 4096 and run["lanes"] is None:
            here = jh.scan(sc, {MU: z["mu"]}, jh.Times(t1, n=2), observables=OBS)
            d = np.linalg.norm(z["final_position"] - here["final_position"], axis=-1)
            row["vs_this_machine_default_scan"] = {
                "median_cm": float(100 * np.median(d)),
                "max_cm": float(100 * np.max(d)),
                "steps_median_here": int(np.median(here.num_accepted_steps)),
                "lanes_here": here.attrs["lanes"],
            }
            print(
                f"    against the default scan here ({here.attrs['lanes']} lanes): median "
                f"{100 * np.median(d):.3g} cm, max {100 * np.max(d):.3g} cm",
                flush=True,
            )
        report["runs"][run["tag"]] = row
    (src / "check.json").write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {src / 'check.json'}")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", help="output folder (the benchmark)")
    p.add_argument("--check", help="a folder written by the benchmark: check its final positions here")
    p.add_argument("--runs", default="4096,65536", help="comma-separated runs (see above)")
    p.add_argument("--t1", type=float, default=25.0, help="horizon [s] (default 25, paper-4.2's)")
    p.add_argument("--devices", type=int, default=None, help="host CPU devices (default: one per core)")
    p.add_argument("--budget", type=float, default=float("inf"), help="start no run after this many s")
    p.add_argument("--ref-n", type=int, default=512, help="members checked against the reference (--check)")
    p.add_argument("--quick", action="store_true", help="smoke check: 16 members, 2 s, 4 checked")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
        if not args.out:
            p.error("--quick needs --out DIR")
        args.runs, args.t1, args.ref_n = "16", 2.0, 4
        bench(args)
        args.check = args.out
        check(args)
    elif args.check:
        check(args)
    elif args.out:
        bench(args)
    else:
        p.error("give --out DIR (benchmark) or --check DIR")


if __name__ == "__main__":
    main()
