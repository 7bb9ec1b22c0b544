"""Analogue of Fig. 3 of Grabski & Strzałko (2003), §2.3: the container pulled along the rigid ground by a
rope fixed at its corner (preset `paper-2.3`), with the rigid-ground model (`simulate_rigid`).

    python experiments/figures/fig03_sliding.py --out out/fig03            # 20 s (the preset's t1)
    python experiments/figures/fig03_sliding.py --out out/fig03 --quick    # 3 s (smoke check)

Writes into --out:
- `fig03_sliding.png`: X_C, Y_C, ψ (the paper's plotted quantities) and the ground reaction N, friction
  resultant T = |ΣT_i| and rope tension S vs t, with the phase boundaries;
- `fig03_tracks.png`: the corners' paths seen from above;
- `phases.txt`: the phase log; `trajectory.npz`: the arrays.
It prints the compile+solve time of the first call, the time of a second call, and the phase log.
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

CORNERS = ("D", "E", "F", "H")


def _arrays(tr) -> dict[str, np.ndarray]:
    return {
        k: np.asarray(getattr(tr, k))
        for k in (
            "ts",
            "position",
            "velocity",
            "euler",
            "corners",
            "normal_forces",
            "friction_forces",
            "ground_reaction",
            "rope_tension",
            "hoist_work",
            "damping_loss",
            "friction_work",
            "impact_loss",
        )
    } | {"energy_residual": np.asarray(tr.energy_residual())}


def plot(d: dict, phases, out: Path, title: str) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.0, 8.0), layout="constrained")
    ax = fig.subplots(4, 1, sharex=True)
    t = d["ts"]
    ax[0].plot(t, d["position"][:, 0], label="X_C")
    ax[0].plot(t, d["position"][:, 1], label="Y_C")
    ax[0].set_ylabel("[m]")
    ax[1].plot(t, np.degrees(d["euler"][:, 1]), color="k")
    ax[1].set_ylabel("ψ [deg]")
    ax[2].plot(t, d["position"][:, 2], color="k")
    ax[2].set_ylabel("Z_C [m]")
    T = np.linalg.norm(d["friction_forces"].sum(axis=1)[:, :2], axis=1)
    ax[3].plot(t, d["ground_reaction"] / 1e3, label="N = ΣN_i")
    ax[3].plot(t, T / 1e3, label="T = |ΣT_i|")
    ax[3].plot(t, d["rope_tension"] / 1e3, label="S")
    ax[3].set_ylabel("[kN]")
    ax[3].set_xlabel("t [s]")
    for a in ax:
        for p in phases[1:]:
            a.axvline(p.t_start, color="0.8", lw=0.6)
        a.grid(alpha=0.3)
    ax[0].legend(fontsize=8)
    ax[3].legend(fontsize=8)
    fig.suptitle(title)
    fig.savefig(out / "fig03_sliding.png", dpi=110)

    fig = Figure(figsize=(6.0, 6.0), layout="constrained")
    a = fig.subplots()
    for i, c in enumerate(CORNERS):
        a.plot(d["corners"][:, i, 0], d["corners"][:, i, 1], label=c)
    a.set_aspect("equal")
    a.set_xlabel("X [m]")
    a.set_ylabel("Y [m]")
    a.legend()
    a.set_title("corner paths seen from above")
    fig.savefig(out / "fig03_tracks.png", dpi=110)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="3 s instead of the preset's 20 s")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jaxhoist.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = jaxhoist.load_scenario("paper-2.3")
    # quick: 101 saved times, as every quick rigid run of paper-2.3 and paper-4.1 (one program in CI's cache)
    t1, n_save = (3.0, 101) if args.quick else (sc.t1, 401)

    t0 = time.perf_counter()
    tr = simulate_rigid(sc, jaxhoist.Times(t1, n=n_save))
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    tr = simulate_rigid(sc, jaxhoist.Times(t1, n=n_save))
    t_second = time.perf_counter() - t0
    d = _arrays(tr)
    print(
        f"paper-2.3 rigid model, t1 = {t1:g} s: {len(tr.phases)} phases, "
        f"{int(tr.num_accepted_steps)} accepted / {int(tr.num_rejected_steps)} rejected steps"
    )
    print(f"first call (compile + solve) {t_first:.1f} s, second call {t_second:.2f} s")
    print(
        f"energy balance residual max {np.abs(d['energy_residual']).max():.3g} J "
        f"(hoist work {d['hoist_work'][-1]:.4g} J, impacts {d['impact_loss'][-1]:.4g} J)"
    )
    log = tr.phase_log()
    print(log)
    (out / "phases.txt").write_text(log + "\n")
    np.savez(out / "trajectory.npz", **d)
    plot(d, tr.phases, out, f"paper-2.3, rigid ground: sliding of the container (μ = 0.25), t1 = {t1:g} s")
    print(f"wrote {out}/fig03_sliding.png, fig03_tracks.png, phases.txt, trajectory.npz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
