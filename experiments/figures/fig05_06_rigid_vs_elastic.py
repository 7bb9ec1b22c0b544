"""Analogues of Figs 5-6 of Grabski & Strzałko (2003), §4.1: the container slid and lifted by an oblique rope
(preset `paper-4.1`), computed with both models: the rigid body on the rigid ground (`simulate_rigid`, §2)
and the rigid body on the elastic foundation (`jaxhoist.simulate`, §3).

    python experiments/figures/fig05_06_rigid_vs_elastic.py --out out/fig05_06  # 70 s (the preset's t1)
    python experiments/figures/fig05_06_rigid_vs_elastic.py --out out/fig05_06 --quick    # 5 s (smoke check)

Writes into --out:
- `fig05_mass_centre.png`: x_C and z_C of both models vs t (Fig. 5), plus y_C and ψ;
- `fig06_forces.png`: rope tension S and ground reaction R = ΣN_i of both models vs t (Fig. 6);
- `phases.txt`: the rigid model's phase log; `rigid.npz`, `elastic.npz`: the arrays.
It prints compile+solve and solve-only times of both models and the largest differences between them.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist  # noqa: E402
from jaxhoist import simulate_rigid  # noqa: E402

KEYS = ("ts", "position", "euler", "normal_forces", "ground_reaction", "rope_tension", "hoist_work")


def _arrays(tr) -> dict[str, np.ndarray]:
    d = {k: np.asarray(getattr(tr, k)) for k in KEYS}
    d["energy_residual"] = np.asarray(tr.energy_residual())
    return d


def _timed(f):
    t0 = time.perf_counter()
    r = jax.block_until_ready(f())
    t1 = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = jax.block_until_ready(f())
    return r, t1, time.perf_counter() - t0


def plot(rig: dict, ela: dict, phases, out: Path, t1: float) -> None:
    from matplotlib.figure import Figure

    style = {"rigid": dict(color="k", lw=1.3), "elastic": dict(color="tab:red", lw=1.0, ls="--")}
    fig = Figure(figsize=(8.0, 8.0), layout="constrained")
    ax = fig.subplots(4, 1, sharex=True)
    for name, d in (("rigid", rig), ("elastic", ela)):
        ax[0].plot(d["ts"], d["position"][:, 0], label=f"{name} foundation", **style[name])
        ax[1].plot(d["ts"], d["position"][:, 2], **style[name])
        ax[2].plot(d["ts"], d["position"][:, 1], **style[name])
        ax[3].plot(d["ts"], np.degrees(d["euler"][:, 1]), **style[name])
    for a, lab in zip(ax, ("x_C [m]", "z_C [m]", "y_C [m]", "ψ [deg]"), strict=True):
        a.set_ylabel(lab)
        a.grid(alpha=0.3)
    ax[0].legend(fontsize=8)
    ax[3].set_xlabel("t [s]")
    fig.suptitle(f"paper-4.1: mass centre, rigid vs elastic foundation (Fig. 5), t1 = {t1:g} s")
    fig.savefig(out / "fig05_mass_centre.png", dpi=110)

    fig = Figure(figsize=(8.0, 5.5), layout="constrained")
    ax = fig.subplots(2, 1, sharex=True)
    for name, d in (("rigid", rig), ("elastic", ela)):
        ax[0].plot(d["ts"], d["rope_tension"] / 1e3, label=f"{name} foundation", **style[name])
        ax[1].plot(d["ts"], d["ground_reaction"] / 1e3, **style[name])
    ax[0].set_ylabel("S [kN]")
    ax[1].set_ylabel("R = ΣN_i [kN]")
    ax[1].set_xlabel("t [s]")
    for a in ax:
        for p in phases[1:]:
            a.axvline(p.t_start, color="0.85", lw=0.6)
        a.grid(alpha=0.3)
    ax[0].legend(fontsize=8)
    fig.suptitle("paper-4.1: rope tension and ground reaction (Fig. 6); grey: rigid-model phase changes")
    fig.savefig(out / "fig06_forces.png", dpi=110)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="5 s instead of the preset's 70 s")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jaxhoist.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = jaxhoist.load_scenario("paper-4.1")
    t1, n_save = (5.0, 101) if args.quick else (sc.t1, 701)

    rig_tr, rig_first, rig_second = _timed(lambda: simulate_rigid(sc, jaxhoist.Times(t1, n=n_save)))
    ela_tr, ela_first, ela_second = _timed(
        lambda: jaxhoist.simulate(sc, jaxhoist.Times(t1, n=n_save), throw=False)
    )
    rig, ela = _arrays(rig_tr), _arrays(ela_tr)
    print(f"paper-4.1, t1 = {t1:g} s, {n_save} saved times")
    print(
        f"rigid ground:      first call {rig_first:6.1f} s, second call {rig_second:6.2f} s, "
        f"{len(rig_tr.phases)} phases, {int(rig_tr.num_accepted_steps)} steps, "
        f"energy residual {np.abs(rig['energy_residual']).max():.3g} J"
    )
    print(
        f"elastic foundation: first call {ela_first:6.1f} s, second call {ela_second:6.2f} s, "
        f"status {jaxhoist.SolveStatus(int(ela_tr.status)).name.lower()}, "
        f"{int(ela_tr.num_accepted_steps)} steps, "
        f"energy residual {np.abs(ela['energy_residual']).max():.3g} J"
    )
    for k, lab, unit, scale in (
        ("position", "mass centre", "m", 1.0),
        ("rope_tension", "rope tension", "kN", 1e3),
        ("ground_reaction", "ground reaction", "kN", 1e3),
    ):
        diff = np.abs(rig[k] - ela[k]).max() / scale
        print(f"  max |rigid - elastic| {lab}: {diff:.4g} {unit}")
    log = rig_tr.phase_log()
    print("rigid-model phases:\n" + log)
    (out / "phases.txt").write_text(log + "\n")
    np.savez(out / "rigid.npz", **rig)
    np.savez(out / "elastic.npz", **ela)
    plot(rig, ela, rig_tr.phases, out, t1)
    print(f"wrote {out}/fig05_mass_centre.png, fig06_forces.png, phases.txt, rigid.npz, elastic.npz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
