"""Analogues of Figs 7-9 of Grabski & Strzałko (2003), §4.2: the eccentrically loaded container on the elastic
foundation, dragged, tipped and lifted by an oblique rope (preset `paper-4.2`).

    python experiments/figures/fig07_09_container.py --out out/fig07_09           # 25 s, 1001 saved times
    # 6 s, 251 saved times (smoke check)
    python experiments/figures/fig07_09_container.py --out out/fig07_09 --quick

Writes into --out:
- `fig07_motion.png`: mass-centre coordinates x, y, z and Euler angles φ, ψ, ϑ vs t (Fig. 7);
- `fig08_corner_forces.png`: per corner D, E, F, H, the friction-force magnitude |T_i| and normal force N_i
  vs t (Fig. 8; a corner off the ground has N_i = |T_i| = 0);
- `fig09_corner_tracks.png`: the corner tracks seen from above with friction-force directions (Fig. 9);
- `fig06_forces.png`, `energy.png`: rope tension and ground reaction; the energy balance;
- `trajectory.npz` + `trajectory.json`: every output array, with units and the scenario.
It prints the compile and solve times and the corner detachment times.
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
from jaxhoist import plots  # noqa: E402


def corner_detach_times(ts, normal_forces) -> list[float | None]:
    """Per corner D, E, F, H: the first saved time [s] with N_i = 0, or None."""
    off = np.asarray(normal_forces) <= 0.0
    return [float(ts[np.argmax(off[:, i])]) if off[:, i].any() else None for i in range(off.shape[-1])]


def liftoff_time(ts, normal_forces) -> float | None:
    """The first saved time [s] at which every corner's normal force N_i is zero, or None."""
    off = np.all(np.asarray(normal_forces) <= 0.0, axis=-1)
    return float(ts[np.argmax(off)]) if off.any() else None


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="short horizon (6 s) and few saved times")
    p.add_argument("--dpi", type=int, default=100)
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jaxhoist.enable_compilation_cache()
    out = Path(args.out)
    # quick: 251 saved times, as bench_single's paper-4.2 (one program in CI's compilation cache)
    t1, n_save = (6.0, 251) if args.quick else (25.0, 1001)

    scenario = jaxhoist.load_scenario("paper-4.2")
    t0 = time.perf_counter()
    traj = jaxhoist.simulate(scenario, jaxhoist.Times(t1, n=n_save), throw=False)
    jax.block_until_ready(traj)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    traj = jax.block_until_ready(jaxhoist.simulate(scenario, jaxhoist.Times(t1, n=n_save), throw=False))
    t_second = time.perf_counter() - t0
    stem = jaxhoist.save_trajectory(
        out / "trajectory",
        traj,
        scenario,
        command=[sys.executable, *sys.argv],
        options={"solver": "Tsit5", "rtol": 1e-6, "atol": 1e-8, "t1": t1, "n_save": n_save},
    )[0]
    d = jaxhoist.load_trajectory(stem)  # every output as a numpy array, the form the plots take
    status = jaxhoist.SolveStatus(int(d["status"]))
    print(
        f"paper-4.2, t1 = {t1:g} s, {n_save} saved times: status {status.name.lower()}, "
        f"{int(d['num_accepted_steps'])} accepted / {int(d['num_rejected_steps'])} rejected steps"
    )
    print(f"first call (compile + solve) {t_first:.2f} s, second call (solve) {t_second:.3f} s")
    lift = liftoff_time(d["ts"], d["normal_forces"])
    detach = corner_detach_times(d["ts"], d["normal_forces"])
    print(
        "first saved time with N_i = 0: "
        + ", ".join(f"{c} {'-' if t is None else f'{t:g} s'}" for c, t in zip("DEFH", detach, strict=True))
        + f"; lift-off (all N_i = 0): {'-' if lift is None else f'{lift:g} s'}"
    )
    print(f"max |energy residual| {np.max(np.abs(d['energy_residual'])):.3g} J")

    figs = {
        "fig07_motion.png": plots.plot_motion(
            d, title="Fig. 7 analogue: motion of the lifted container (paper-4.2)"
        ),
        "fig08_corner_forces.png": plots.plot_corner_forces(
            d, title="Fig. 8 analogue: friction |T_i| and normal N_i forces at the corners"
        ),
        "fig09_corner_tracks.png": plots.plot_corner_tracks(
            d, title="Fig. 9 analogue: corner tracks from above, arrows along the friction force"
        ),
        "fig06_forces.png": plots.plot_forces(d, title="Rope tension S and ground reaction R (paper-4.2)"),
        "energy.png": plots.plot_energy(d, title="Energy balance (paper-4.2)"),
    }
    for name, fig in figs.items():
        path = plots.save_figure(fig, out / name, dpi=args.dpi)
        print(f"wrote {path} ({path.stat().st_size / 1e3:.0f} kB)")
    return 0 if status == jaxhoist.SolveStatus.OK else 1


if __name__ == "__main__":
    raise SystemExit(main())
