"""Sweeps of the rigid-ground model (paper §2, `simulate_rigid`) around its presets: every run must complete,
and its energy balance must close.

    python experiments/figures/rigid_sweep.py --out out/rigid_sweep --quick     # a minute or two: 4 runs
    python experiments/figures/rigid_sweep.py --out out/rigid_sweep  # the full sweep (hours on 2 cores)
    # figures from what is done so far
    python experiments/figures/rigid_sweep.py --out out/rigid_sweep --plot-only
    # one run, its record
    python experiments/figures/rigid_sweep.py --out out/one --one paper-2.3,elastic,0.30,17
    python experiments/figures/rigid_sweep.py --out out/rigid_elastic --elastic # rigid vs elastic, k = 1.5e9
    # ... where cycles were
    python experiments/figures/rigid_sweep.py --out out/rigid_chatter --elastic-chatter

Full sweep: μ = 0.10, 0.105, ..., 0.50 (81 values) on `paper-2.3` and `paper-4.1`, each with the elastic rope
(2.14) and the inextensible rope (2.15), to the preset's t1 (20 s and 70 s); plus, at the preset's μ, the
hoist speed v_l times 0.5 and 2, and the rope point B moved by ±0.25 m along ξ and η on the top face (clipped
to the face). The variants run first (seconds each at the presets' μ), then μ coarse to fine (every 0.02
first, then every 0.01 and 0.005), so an interrupted sweep covers the whole range.
Each finished run is appended to `runs.jsonl` at once (a restarted sweep skips the runs already there):
completed or the error, the number of phases (records) and of phase solves, how many contact choices and
impacts needed a resolution step beyond consistency (`PhaseRecord.choice`, impact notes; see
docs/rigid-model.md, "Resolution"), the largest |energy residual| [J], the hoist work and the impact losses
[J], and the wall time [s]. A run "closes" when max |residual| <= 1e-6 x the hoist work (the
tolerance of `tests/test_rigid.py`) or <= 2.5e-3 x the impact losses (a rocking train of impacts on
paper-2.3 leaves about that: 0.027 J against 11 J of impact losses; the residual of the rigid model grows with
the number of impacts in a rocking train, not with the solver tolerance). Figures: `rigid_sweep.png`
(completion, phase counts and the energy residual over its tolerance, over μ, per preset and rope).

`--elastic`: the elastic model at k = 1.5e9 N/m per corner (critically damped, h = sqrt(k m)), ε = 1e-4 m/s,
p_0 = 1e-6 m (the stiffest row of the convergence table in docs/rigid-model.md) against the rigid model on
paper-2.3 at μ = 0.252, 0.255, 0.27 (the landings that raised "non-uniqueness") and 0.26 (the grazing
impact), each to just past that moment (`ELASTIC_CASES`), saved every 2 ms: max |Δr_C| and, after every
resolved contact choice, which corners carry load in each model. Writes `rigid_elastic.json`.
`--elastic-chatter`: the same at `CHATTER_CASES` (paper-2.3 μ = 0.30 to 17 s, 0.32 to 12.4 s, paper-4.1
μ = 0.38 to 20 s), where the rigid model used to stop in a sustained cycle and now passes it by the
persistent-contact rule or a compliant phase; also records those episodes. Writes
`rigid_elastic_chatter.json`.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
import traceback
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist  # noqa: E402
from jaxhoist import simulate_rigid  # noqa: E402

PRESETS = ("paper-2.3", "paper-4.1")
ROPES = ("elastic", "inextensible")
MUS = np.round(np.arange(0.10, 0.50 + 1e-9, 0.005), 3)
N_SAVE = 501
CLOSE = 1e-6  # a run closes when max |energy residual| <= CLOSE x hoist work (tests/test_rigid.py)
#: The commit each run used (recorded per run: a resumed sweep may span commits).
COMMIT = subprocess.run(
    ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=Path(__file__).parent
).stdout.strip()
CLOSE_IMPACT = 2.5e-3  # ... or <= CLOSE_IMPACT x impact losses (paper-2.3's rocking train: 0.027 J / 11 J)


def _model(rope: str) -> jaxhoist.RigidGround:
    """The rigid model with the rope named "elastic" (2.14) or "inextensible" (2.15)."""
    ropes = {"elastic": jaxhoist.ElasticRope(), "inextensible": jaxhoist.InextensibleRope()}
    return jaxhoist.RigidGround(rope=ropes[rope])


def closes(r: dict) -> bool:
    """The energy balance of run record `r` closes to today's tolerance (see the module docstring)."""
    return r["residual_J"] <= max(CLOSE * r["hoist_work_J"], CLOSE_IMPACT * r["impact_loss_J"])


def coarse_to_fine(values):
    """The values reordered so that every prefix covers the range: every 4th first, then every 2nd, then
    the rest."""
    idx = np.arange(len(values))
    order = sorted(idx, key=lambda i: (i % 4 != 0, i % 2 != 0, i))
    return [values[i] for i in order]


def variants(preset: str):
    """(name, {field: value}) of the non-μ variations around `preset`."""
    sc = jaxhoist.load_scenario(preset)
    v = float(sc.hoist.speed)
    a, b, c = (float(x) for x in sc.load.size)
    B = np.asarray(sc.rope.attachment, dtype=float)
    out = [(f"v_l x{f:g}", {"hoist.speed": f * v}) for f in (0.5, 2.0)]
    for axis, name, top in ((0, "xi", a), (1, "eta", b)):
        for d in (-0.25, 0.25):
            Bn = B.copy()
            Bn[axis] = min(max(Bn[axis] + d, 0.0), top)
            if not np.allclose(Bn, B):
                out.append((f"B {name}{d:+g} m", {"rope.attachment": Bn.tolist()}))
    return out


def variant_runs():
    """The runs of `variants` around each preset at its μ, both ropes."""
    runs = []
    for preset in PRESETS:
        mu0 = float(jaxhoist.load_scenario(preset).foundation.friction_coefficient)
        for name, changes in variants(preset):
            for rope in ROPES:
                runs.append(dict(preset=preset, rope=rope, mu=mu0, variant=name, changes=changes, t1=None))
    return runs


def run_list(quick: bool):
    """Every run of the sweep as a dict (key, preset, rope, mu, variant, changes, t1)."""
    runs = []
    if quick:
        for preset, rope, mu, t1 in (
            ("paper-2.3", "elastic", 0.252, 11.1),
            ("paper-2.3", "elastic", 0.27, 11.1),
            ("paper-4.1", "elastic", 0.3, 10.0),
            ("paper-4.1", "inextensible", 0.3, 5.0),
        ):
            # 101 saved times, as every quick rigid run of paper-2.3 and paper-4.1 (one program in CI's cache)
            runs.append(dict(preset=preset, rope=rope, mu=mu, variant="", changes={}, t1=t1, n_save=101))
    else:
        runs += variant_runs()  # first: at the presets' μ they take seconds each
        for mu in coarse_to_fine(list(MUS)):
            for preset in PRESETS:
                for rope in ROPES:
                    runs.append(dict(preset=preset, rope=rope, mu=float(mu), variant="", changes={}, t1=None))
    for r in runs:
        r["key"] = f"{r['preset']}|{r['rope']}|{r['mu']:.3f}|{r['variant']}|{r['t1']}"
    return runs


def one_run(r: dict) -> dict:
    sc = jaxhoist.load_scenario(r["preset"]).replace(
        **{"foundation.friction_coefficient": r["mu"], **r["changes"]}
    )
    t1 = float(sc.t1) if r["t1"] is None else r["t1"]
    t0 = time.perf_counter()
    out = dict(r, t1=t1)
    try:
        tr = simulate_rigid(sc, jaxhoist.Times(t1, n=r.get("n_save", N_SAVE)), model=_model(r["rope"]))
        resid = float(np.max(np.abs(np.asarray(tr.energy_residual()))))
        hoist = float(np.asarray(tr.hoist_work)[-1])
        choices = [p.choice for p in tr.phases if p.choice]
        impact_notes = [
            p.end
            for p in tr.phases
            if "impact" in p.end and ("dropped" in p.end or "projected" in p.end or "dissipation" in p.end)
        ]
        out.update(
            completed=True,
            error="",
            phases=len(tr.phases),
            solves=int(np.max(tr.phase_index)) + 1,
            merged=sum(p.end.count("=>") for p in tr.phases),
            resolved=len(choices),
            resolved_impacts=len(impact_notes),
            notes=sorted({c.split(":")[0] for c in choices}),
            impact_notes=impact_notes[:5],
            residual_J=resid,
            hoist_work_J=hoist,
            impact_loss_J=float(np.asarray(tr.impact_loss)[-1]),
            closes=bool(resid <= max(CLOSE * hoist, CLOSE_IMPACT * float(np.asarray(tr.impact_loss)[-1]))),
            steps=int(tr.num_accepted_steps),
            compliant=[f"{p.t_start:.6f}" for p in tr.phases if p.choice.startswith("compliant phase")],
            stalls=sum(p.choice.count("stalled") for p in tr.phases),
        )
    except Exception as err:  # the sweep records failures instead of stopping
        out.update(
            completed=False,
            error=f"{type(err).__name__}: {err}"[:2000],
            traceback=traceback.format_exc()[-2000:],
        )
    out["wall_s"] = time.perf_counter() - t0
    out["commit"] = COMMIT
    return out


def load_done(path: Path) -> dict:
    done = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                rec = json.loads(line)
                done[rec["key"]] = rec
    return done


def plot(out: Path, records: list[dict]):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 7.5), layout="constrained")
    axs = fig.subplots(3, 2, sharex=True)
    colors = {"elastic": "tab:blue", "inextensible": "tab:orange"}
    for j, preset in enumerate(PRESETS):
        for rope in ROPES:
            rs = sorted(
                [r for r in records if r["preset"] == preset and r["rope"] == rope and not r["variant"]],
                key=lambda r: r["mu"],
            )
            if not rs:
                continue
            mu = np.array([r["mu"] for r in rs])
            ok = np.array([r["completed"] for r in rs])
            c = colors[rope]
            axs[0, j].plot(
                mu[ok],
                np.full(ok.sum(), 1.0 if rope == "elastic" else 0.0),
                "o",
                ms=3,
                color=c,
                label=f"{rope} rope: {ok.sum()}/{ok.size} complete",
            )
            axs[0, j].plot(
                mu[~ok], np.full((~ok).sum(), 1.0 if rope == "elastic" else 0.0), "x", ms=6, color="k"
            )
            ph = np.array([r.get("phases", np.nan) for r in rs], dtype=float)
            rv = np.array([r.get("resolved", 0) + r.get("resolved_impacts", 0) for r in rs], dtype=float)
            axs[1, j].semilogy(mu[ok], ph[ok], "o-", ms=3, color=c, label=f"{rope}: phases")
            axs[1, j].semilogy(
                mu[ok],
                np.maximum(rv[ok], 0.5),
                "s:",
                ms=3,
                color=c,
                alpha=0.6,
                label=f"{rope}: resolution steps (0 drawn at 0.5)",
            )
            rel = np.array(
                [
                    r["residual_J"] / max(CLOSE * r["hoist_work_J"], CLOSE_IMPACT * r["impact_loss_J"])
                    if r["completed"]
                    else np.nan
                    for r in rs
                ]
            )
            axs[2, j].semilogy(mu[ok], rel[ok], "o-", ms=3, color=c, label=rope)
        t1s = sorted({r["t1"] for r in records if r["preset"] == preset and not r["variant"]})
        axs[0, j].set_title(f"{preset}, t1 = {', '.join(f'{t:g}' for t in t1s)} s")
        axs[0, j].set_yticks([0.0, 1.0], ["inextensible", "elastic"])
        axs[0, j].set_ylim(-0.5, 1.5)
        axs[0, j].legend(fontsize=7, loc="center right")
        axs[1, j].set_ylabel("count [-]")
        axs[1, j].legend(fontsize=7)
        axs[2, j].axhline(1.0, color="k", lw=0.8, ls="--")
        axs[2, j].set_ylabel("max |residual| / tolerance [-]")
        axs[2, j].legend(fontsize=7)
        axs[2, j].set_xlabel("friction coefficient μ [-]")
    fig.suptitle("Rigid model over μ: completion (x: failed), phase counts, energy balance", fontsize=10)
    fig.savefig(out / "rigid_sweep.png", dpi=110)


def summary(records: list[dict]) -> str:
    lines = []
    for preset in PRESETS:
        for rope in ROPES:
            rs = [r for r in records if r["preset"] == preset and r["rope"] == rope]
            if not rs:
                continue
            ok = [r for r in rs if r["completed"]]
            closing = [r for r in ok if closes(r)]
            worst = max(ok, key=lambda r: r["residual_J"] / r["hoist_work_J"], default=None)
            lines.append(
                f"{preset:9s} {rope:12s}: {len(ok)}/{len(rs)} complete, {len(closing)}/{len(ok)} close "
                f"(|resid| <= {CLOSE:g} W_hoist or {CLOSE_IMPACT:g} W_impact), "
                f"phases {min((r['phases'] for r in ok), default=0)}-"
                f"{max((r['phases'] for r in ok), default=0)}, resolution steps in "
                f"{sum(1 for r in ok if r['resolved'] or r['resolved_impacts'])} runs"
                + (
                    f", worst resid {worst['residual_J']:.3g} J = "
                    f"{worst['residual_J'] / worst['hoist_work_J']:.2g}"
                    f" W_hoist (μ = {worst['mu']}, {worst['variant'] or 'preset'})"
                    if worst
                    else ""
                )
            )
            for r in rs:
                if not r["completed"]:
                    lines.append(
                        f"    FAILED μ = {r['mu']} {r['variant']}: {r['error'].splitlines()[0][:160]}"
                    )
    return "\n".join(lines)


# ------------------------------------------------------------------------------ rigid vs elastic


#: (μ, t1 [s]) of the elastic comparison: the landings that raised "non-uniqueness" (0.252: 11.004 s,
#: 0.255: 11.046 s, 0.27: 9.665 s) and the grazing impact of E (0.26: 16.916 s).
ELASTIC_CASES = ((0.252, 11.3), (0.255, 11.3), (0.27, 10.0), (0.26, 17.2))


def resolved_phases(tr) -> list[int]:
    """Indices of the phases whose configuration needed a resolution step: a `choice` note, or the phase
    after an impact resolved by a fallback."""
    out = []
    for k, p in enumerate(tr.phases):
        if p.choice:
            out.append(k)
        elif k > 0 and ("friction dropped" in tr.phases[k - 1].end or "projected" in tr.phases[k - 1].end):
            out.append(k)
    return out


#: (preset, μ, t1 [s]) of the sustained cycles that the persistent-contact rule and the compliant
#: phase pass (docs/rigid-model.md, "Sustained cycles"): stalls at 16.13 s, F-H chatter from 10.8 s, chatter
#: at 15.7 s (each used to end the run).
CHATTER_CASES = (("paper-2.3", 0.30, 17.0), ("paper-2.3", 0.32, 12.4), ("paper-4.1", 0.38, 20.0))


def elastic_check(
    out: Path,
    cases=ELASTIC_CASES,
    k=1.5e9,
    eps=1e-4,
    dt=0.002,
    preset_name="paper-2.3",
    name="rigid_elastic.json",
):
    """Rigid vs elastic (k, critically damped, ε, p_0 = 1e-4 m x 1.5e7/k) on paper-2.3 at the `cases`:
    the mass-centre distance, and in a window of 50 ms to 0.2 s after each resolved choice (from 10 ms
    after its start) the corners that carry load (mean N > 1e-3 G) in both models."""
    preset = jaxhoist.load_scenario(preset_name)
    rows = []
    for mu, t1 in cases:
        ts = np.linspace(0.0, t1, int(round(t1 / dt)) + 1)
        sc = preset.replace(**{"foundation.friction_coefficient": mu})
        G = float(sc.load.mass) * float(sc.gravity)
        rig = simulate_rigid(sc, jaxhoist.Times(t1, ts=ts))
        el_sc = sc.replace(
            **{
                "foundation.stiffness": k,
                "foundation.damping": math.sqrt(k * float(sc.load.mass)),
                "foundation.friction.regularisation_velocity": eps,
                "foundation.damping_onset": 1e-4 * 1.5e7 / k,
            }
        )
        t0 = time.perf_counter()
        el = jax.block_until_ready(
            jaxhoist.simulate(
                el_sc, jaxhoist.Times(ts=ts), throw=False, options=jaxhoist.SolverOptions(max_steps=4_000_000)
            )
        )
        wall = time.perf_counter() - t0
        d = np.linalg.norm(np.asarray(el.position) - np.asarray(rig.position), axis=-1)
        row = dict(
            preset=preset_name,
            mu=mu,
            t1=t1,
            phases=len(rig.phases),
            residual_J=float(np.max(np.abs(np.asarray(rig.energy_residual())))),
            compliant=[str(p) for p in rig.phases if p.choice.startswith("compliant phase")],
            persistent=sum("persistent contact" in p.end for p in rig.phases),
            dr_mm_every_s={f"{t:g}": float(np.interp(t, ts, d) * 1e3) for t in np.arange(1.0, t1, 1.0)},
            k=k,
            eps=eps,
            elastic_status=int(el.status),
            elastic_wall_s=wall,
            max_dr_mm=float(d.max() * 1e3),
            t_of_max_s=float(ts[np.argmax(d)]),
            rms_dr_mm=float(np.sqrt(np.mean(d**2)) * 1e3),
            checks=[],
        )
        for i in resolved_phases(rig):
            p = rig.phases[i]
            # Up to 0.2 s of the phase (at least 50 ms, into the phases that follow a short one), after its
            # first 10 ms (contact transients of the elastic model).
            t_end = min(max(p.t_end, p.t_start + 0.05), p.t_start + 0.2)
            lead = min(0.01, 0.25 * (t_end - p.t_start))
            w = (ts > p.t_start + lead) & (ts < t_end - lead)
            if not w.any():
                continue
            n_el = np.asarray(el.normal_forces)[w].mean(axis=0)
            n_rig = np.asarray(rig.normal_forces)[w].mean(axis=0)
            loaded_rig = "".join(c for c, n in zip("DEFH", n_rig, strict=True) if n > 1e-3 * G)
            loaded_el = "".join(c for c, n in zip("DEFH", n_el, strict=True) if n > 1e-3 * G)
            row["checks"].append(
                dict(
                    phase=str(p),
                    after=rig.phases[i - 1].end,
                    window_s=[float(ts[w][0]), float(ts[w][-1])],
                    mean_N_rigid=n_rig.round(1).tolist(),
                    mean_N_elastic=n_el.round(1).tolist(),
                    loaded_rigid=loaded_rig,
                    loaded_elastic=loaded_el,
                    same=loaded_rig == loaded_el,
                    max_dr_before_mm=float(d[ts <= p.t_start].max() * 1e3),
                    max_dr_window_mm=float(d[w].max() * 1e3),
                )
            )
        rows.append(row)
        print(json.dumps(row), flush=True)
    (out / name).write_text(json.dumps(rows, indent=1))
    return rows


def chatter_check(out: Path):
    """`elastic_check` at the `CHATTER_CASES`: rigid (with the persistent-contact rule and the compliant
    phase) vs the elastic model at k = 1.5e9; writes `rigid_elastic_chatter.json`."""
    rows = []
    for preset, mu, t1 in CHATTER_CASES:
        rows += elastic_check(out, cases=((mu, t1),), preset_name=preset, name=f"chatter_{preset}_{mu}.json")
    (out / "rigid_elastic_chatter.json").write_text(json.dumps(rows, indent=1))
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="4 short runs (a minute or two)")
    p.add_argument("--plot-only", action="store_true", help="figures and summary from runs.jsonl")
    p.add_argument("--elastic", action="store_true", help="rigid vs elastic at k = 1.5e9 N/m (see above)")
    p.add_argument(
        "--elastic-chatter",
        action="store_true",
        help="rigid vs elastic at k = 1.5e9 N/m where sustained cycles were (CHATTER_CASES)",
    )
    p.add_argument(
        "--shard",
        default="0/1",
        help="i/n: run every n-th of the runs still to do, from the "
        "i-th (parallel processes, each with its own --out; concatenate their runs.jsonl)",
    )
    p.add_argument(
        "--one",
        default=None,
        help="PRESET,ROPE,MU,T1: one run (e.g. paper-2.3,elastic,0.30,17), its record printed and "
        "appended to one.jsonl; with the phases that stalled or were compliant (the stall benchmark of "
        "docs/rigid-model.md)",
    )
    p.add_argument("--only-preset", default=None, help="run only this preset")
    p.add_argument("--mus", default=None, help="comma-separated μ values: run only these (first)")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jaxhoist.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.elastic:
        elastic_check(out)
        return 0
    if args.elastic_chatter:
        chatter_check(out)
        return 0
    if args.one:
        preset, rope, mu, t1 = args.one.split(",")
        r = dict(preset=preset, rope=rope, mu=float(mu), variant="", changes={}, t1=float(t1))
        r["key"] = f"{preset}|{rope}|{float(mu):.3f}||{float(t1)}"
        rec = one_run(r)
        with (out / "one.jsonl").open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(json.dumps({k: v for k, v in rec.items() if k != "traceback"}, indent=1))
        return 0 if rec["completed"] else 1
    path = out / "runs.jsonl"
    done = load_done(path)
    if not args.plot_only:
        runs = run_list(args.quick)
        todo = [
            r
            for r in runs
            if r["key"] not in done and (args.only_preset is None or r["preset"] == args.only_preset)
        ]
        if args.mus:
            wanted = {round(float(m), 3) for m in args.mus.split(",")}
            todo = [r for r in todo if round(r["mu"], 3) in wanted and not r["variant"]]
        i_shard, n_shard = (int(x) for x in args.shard.split("/"))
        todo = todo[i_shard::n_shard]
        print(f"{len(runs)} runs, {len(runs) - len(todo)} already done", flush=True)
        for n, r in enumerate(todo):
            rec = one_run(r)
            done[rec["key"]] = rec
            with path.open("a") as f:
                f.write(json.dumps(rec) + "\n")
            status = (
                f"{rec['phases']} phases, resid {rec['residual_J']:.3g} J, "
                f"{rec['resolved']}+{rec['resolved_impacts']} resolved"
                if rec["completed"]
                else f"FAILED {rec['error'][:160]}"
            )
            print(
                f"[{n + 1}/{len(todo)}] {r['preset']} {r['rope']} μ={r['mu']:.3f} {r['variant']} "
                f"t1={rec['t1']:g}: "
                f"{status} ({rec['wall_s']:.1f} s)",
                flush=True,
            )
    records = list(done.values())
    text = summary(records)
    print(text)
    (out / "summary.txt").write_text(text + "\n")
    plot(out, records)
    return 0 if all(r["completed"] for r in records) else 1


if __name__ == "__main__":
    sys.exit(main())
