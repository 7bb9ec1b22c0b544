"""Lift-planning map from the rigid-ground statics (paper §2.1, conditions 2.9): over the rope's direction
and the friction coefficient μ, which motion the resting load starts first as the rope is tensioned —
sliding, tipping about an edge, tipping about a corner, or a clean lift — and at which pull; a sample of
the map is confirmed by simulating both models (the rigid one of §2 and the elastic one of §3).

    python experiments/figures/lift_planning_map.py --out out/lift_map  # 4 μ x 91 x 72 directions
    python experiments/figures/lift_planning_map.py --out out/lift_map --quick         # coarse grid, 4 checks
    # B centred
    python experiments/figures/lift_planning_map.py --out out/lift_map_centre --attachment 1.25 3.0 2.5

The rope direction is B -> A at t = 0: its angle θ from the vertical and its azimuth α in the load's
base, measured from the edge DE (the body ξ axis) towards DH (η); the boom tip A is placed at the preset's
distance |AB| from the rope point B along it. For each direction and μ, the rope-force magnitudes at which
the load lifts (N = 0), slides (T = μN), twists or tips (R leaves the base, about an edge or a corner) come
from `jaxhoist._physics.statics` in closed form; the smallest one names the first motion. Sliding starts
where the exact corner-friction utilisation ρ* reaches 1 (`statics.friction_utilisation`; bisection on the
pull, vectorised over all directions), which is what the rigid dynamics uses: the paper's T = μN ignores
the moment that the friction must also resist, and names a different first motion where the map is
hatched (there a slip about a pivot comes before the tipping the paper's conditions predict).

Checks: for up to `--checks` directions per μ and predicted motion, chosen away from the map's
boundaries, the preset is hoisted with A along that direction, and the first motion is read from
- the rigid model (`simulate_rigid`): the first phase after rest: all four corners on the ground (sliding
  or sticking) = slide, two = tip about an edge, one = tip about a corner, none = lift;
- the elastic model (`jaxhoist.simulate`): whichever comes first, a corner rising 5 mm above the ground
  (then the number of corners above 2.5 mm names edge, corner or lift) or a corner on the ground slipping
  5 mm horizontally (slide).

Writes `lift_map.png` (first motion per μ panel, hatched where the paper's T = μN disagrees; the pull
at which it happens in units of the weight G; the checked directions marked ○ when both models agree with
the statics, ✕ otherwise), `lift_map.npz`, `checks.json`, and prints the shares of each motion and the
checks.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist  # noqa: E402
from jaxhoist import simulate_rigid  # noqa: E402

KINDS = ("slide", "tip-edge", "tip-corner", "lift", "twist", "none")
COLOURS = ("tab:blue", "tab:orange", "tab:red", "tab:green", "tab:purple", "0.8")


def direction(theta: float, alpha: float) -> np.ndarray:
    """Unit rope direction B -> A for angle θ from the vertical and azimuth α [rad] (unrotated load)."""
    return np.array([math.sin(theta) * math.cos(alpha), math.sin(theta) * math.sin(alpha), math.cos(theta)])


def thresholds(scenario, e: np.ndarray, inside: bool) -> dict[str, float]:
    """|S| [N] at which each condition of (2.9) fails first for a pull along unit `e` (closed forms)."""
    th = {"lift": jaxhoist.lift_threshold(scenario, e), "slide": jaxhoist.slide_threshold(scenario, e)}
    s_tip, kind, _ = jaxhoist.tip_threshold(scenario, e)
    th[kind or "tip-edge"] = s_tip
    # The friction resultant's line of action crosses the base when B is above it: twist cannot come first.
    th["twist"] = math.inf if inside else jaxhoist.twist_threshold(scenario, e)
    return th


@jax.jit
def _utilisation(scenario, forces):
    return jax.vmap(lambda S: jaxhoist.rest_statics(scenario, S).friction_utilisation)(forces)


def slip_thresholds(scenario, e: np.ndarray, s_hi: np.ndarray, iterations: int = 40) -> np.ndarray:
    """|S| [N] at which the exact corner-friction utilisation ρ* reaches 1, for many unit pulls `e` (n, 3)
    at once, by bisection on [0, s_hi] (inf where ρ* <= 1 up to s_hi). ρ* grows with the pull along a ray
    (checked at the end: the bracket's ends must straddle 1)."""
    s_hi = np.where(np.isfinite(s_hi), s_hi, 0.0)
    at_hi = np.asarray(_utilisation(scenario, jnp.asarray(e * s_hi[:, None])))
    lo, hi = np.zeros_like(s_hi), s_hi.copy()
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        over = np.asarray(_utilisation(scenario, jnp.asarray(e * mid[:, None]))) > 1.0
        hi, lo = np.where(over, mid, hi), np.where(over, lo, mid)
    return np.where((at_hi > 1.0) & (s_hi > 0), hi, np.inf)


def rigid_first(tr) -> tuple[str, float]:
    """The first motion in a rigid-model phase log, and when it starts [s]."""
    for rec in tr.phases:
        if rec.rest:
            continue
        n_contact = sum(m != "free" for m in rec.contact)
        kind = {4: "slide", 3: "slide", 2: "tip-edge", 1: "tip-corner", 0: "lift"}[n_contact]
        if n_contact == 3 and "slide" not in rec.contact:  # a corner unloaded, nothing moves yet
            continue
        return kind, rec.t_start
    return "none", math.inf


def elastic_first(tr, rise: float = 5e-3, slip: float = 5e-3) -> tuple[str, float]:
    """The first motion of an elastic-model trajectory: a corner rising `rise` [m] or a grounded corner
    slipping `slip` [m] horizontally, whichever comes first (on the saved grid)."""
    ts = np.asarray(tr.ts)
    z = np.asarray(tr.corners[..., 2])  # (n_t, 4)
    xy = np.asarray(tr.corners[..., :2])
    moved = np.linalg.norm(xy - xy[0], axis=-1)
    up = np.nonzero(np.any(z > rise, axis=1))[0]
    sl = np.nonzero(np.any((moved > slip) & (z <= 0.5 * rise), axis=1))[0]
    k_up = up[0] if up.size else len(ts)
    k_sl = sl[0] if sl.size else len(ts)
    if min(k_up, k_sl) == len(ts):
        return "none", math.inf
    if k_sl < k_up:
        return "slide", float(ts[k_sl])
    n_up = int(np.sum(z[k_up] > 0.5 * rise))
    return {1: "tip-corner", 2: "tip-edge", 3: "tip-corner", 4: "lift"}[n_up], float(ts[k_up])


def pick_checks(kind: np.ndarray, n_per_kind: int, rng) -> list[tuple[int, int]]:
    """Grid cells (i_theta, j_alpha) whose 8 neighbours have the same motion, up to n per motion."""
    picks = []
    nt, na = kind.shape
    for k in np.unique(kind):
        if KINDS[k] == "none":
            continue
        cells = [
            (i, j)
            for i in range(nt)
            for j in range(na)
            if all(
                kind[i + di, (j + dj) % na] == k for di in (-1, 0, 1) for dj in (-1, 0, 1) if 0 <= i + di < nt
            )
        ]
        for c in rng.permutation(len(cells))[:n_per_kind]:
            picks.append(cells[c])
    return picks


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--quick", action="store_true", help="31 x 24 directions, one check per motion")
    p.add_argument("--preset", default="paper-4.1")
    p.add_argument(
        "--mu",
        type=float,
        nargs="+",
        default=[0.15, 0.4, 0.6, 0.8],
        help="friction coefficients [-], one panel each",
    )
    p.add_argument("--theta-max", type=float, default=80.0, help="largest angle from the vertical [deg]")
    p.add_argument(
        "--checks",
        type=int,
        default=None,
        help="simulated directions per μ and predicted motion (default 2; quick 1; 0: none)",
    )
    p.add_argument(
        "--attachment",
        type=float,
        nargs=3,
        default=None,
        help="rope point B in the body frame from D [m] (default: the preset's)",
    )
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jaxhoist.enable_compilation_cache()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base = jaxhoist.load_scenario(args.preset)
    if args.attachment is not None:
        base = base.replace(**{"rope.attachment": args.attachment})
        base.check()
    size = np.asarray(base.load.size)
    B = np.asarray(base.rope.attachment)  # body frame = world frame for the unrotated load at t = 0
    A0 = np.asarray(base.boom.tip_position)
    L = float(np.linalg.norm(A0 - B))
    G = float(base.load.mass * base.gravity)
    inside = bool(0 <= B[0] <= size[0] and 0 <= B[1] <= size[1])
    n_t, n_a = (31, 24) if args.quick else (91, 72)
    n_checks = args.checks if args.checks is not None else (1 if args.quick else 2)
    # the checks' saved times: quick 101, as every quick run of paper-2.3 and paper-4.1 (one program each in
    # CI's cache; the elastic first motion then on a coarser grid); the full run 2 for the rigid model (the
    # first motion is read from its phases) and 2001 for the elastic one
    n_rig, n_ela = (101, 101) if args.quick else (2, 2001)
    thetas = np.radians(np.linspace(0.0, args.theta_max, n_t))
    alphas = np.radians(np.arange(n_a) * 360.0 / n_a)
    rng = np.random.default_rng(args.seed)

    kind = np.zeros((len(args.mu), n_t, n_a), dtype=int)  # with the exact slip limit ρ* = 1
    kind_paper = np.zeros((len(args.mu), n_t, n_a), dtype=int)  # with the paper's T = μN
    pull = np.full((len(args.mu), n_t, n_a), np.nan)
    t0 = time.perf_counter()
    dirs = np.array([[direction(th, al) for al in alphas] for th in thetas]).reshape(-1, 3)
    for m, mu in enumerate(args.mu):
        sc = base.replace(**{"foundation.friction_coefficient": mu})
        ths = [thresholds(sc, e, inside) for e in dirs]
        names = [min(th, key=th.get) for th in ths]
        kind_paper[m] = np.array(
            [KINDS.index(n if math.isfinite(th[n]) else "none") for n, th in zip(names, ths, strict=True)]
        ).reshape(n_t, n_a)
        # The exact slip limit replaces T = μN; it can only come before the other motions.
        others = np.array([min(v for k, v in th.items() if k != "slide") for th in ths])
        slip = slip_thresholds(sc, dirs, others)
        for k, th in enumerate(ths):
            th = {**{n: v for n, v in th.items() if n != "slide"}, "slide": slip[k]}
            name = min(th, key=th.get)
            kind.reshape(len(args.mu), -1)[m, k] = KINDS.index(name if math.isfinite(th[name]) else "none")
            pull.reshape(len(args.mu), -1)[m, k] = th[name] / G
    elapsed = time.perf_counter() - t0
    print(
        f"{args.preset}: load {size.tolist()} m, G = {G:.6g} N, rope point B = {B.tolist()} m, "
        f"|AB| = {L:.3f} m; {len(args.mu)} μ x {n_t} x {n_a} directions in {elapsed:.1f} s"
    )
    for m, mu in enumerate(args.mu):
        shares = ", ".join(
            f"{nm} {100 * np.mean(kind[m] == k):.1f} %" for k, nm in enumerate(KINDS) if np.any(kind[m] == k)
        )
        differ = 100 * np.mean(kind[m] != kind_paper[m])
        print(f"  μ = {mu:g}: {shares}; the paper's T = μN names another first motion on {differ:.1f} %")

    # Checks by simulation.
    checks = []
    if n_checks > 0:
        c_rope, k_boom = float(base.rope.stiffness), float(np.min(np.asarray(base.boom.stiffness)))
        rate = float(base.hoist.speed) / (1.0 / c_rope + 1.0 / k_boom)  # quasi-static dS/dt [N/s]
        for m, mu in enumerate(args.mu):
            for i, j in pick_checks(kind[m], n_checks, rng):
                th, al = float(thetas[i]), float(alphas[j])
                predicted, s = KINDS[kind[m, i, j]], pull[m, i, j] * G
                A = B + L * direction(th, al)
                sc = base.replace(**{"foundation.friction_coefficient": mu, "boom.tip_position": A})
                t_end = 1.5 * s / rate + 0.5
                c0 = time.perf_counter()
                rig, t_rig = rigid_first(simulate_rigid(sc, jaxhoist.Times(t_end, n=n_rig)))
                c1 = time.perf_counter()
                ela, t_ela = elastic_first(jaxhoist.simulate(sc, jaxhoist.Times(t_end, n=n_ela)))
                c2 = time.perf_counter()
                rec = dict(
                    mu=mu,
                    theta_deg=math.degrees(th),
                    alpha_deg=math.degrees(al),
                    predicted=predicted,
                    pull_G=s / G,
                    t_predicted=s / rate,
                    rigid=rig,
                    t_rigid=t_rig,
                    elastic=ela,
                    t_elastic=t_ela,
                    wall_rigid_s=c1 - c0,
                    wall_elastic_s=c2 - c1,
                )
                checks.append(rec)
                print(
                    f"  check μ = {mu:g}, θ = {rec['theta_deg']:5.1f}°, α = {rec['alpha_deg']:5.1f}°: "
                    "statics "
                    f"{predicted:10s} ({s / G:.3f} G, ~{s / rate:.2f} s) | rigid {rig:10s} at {t_rig:.3f} s"
                    f" | elastic {ela:10s} at {t_ela:.3f} s",
                    flush=True,
                )
        agree_r = sum(c["rigid"] == c["predicted"] for c in checks)
        agree_e = sum(c["elastic"] == c["predicted"] for c in checks)
        print(
            f"checks: rigid model agrees with the statics in {agree_r}/{len(checks)}, "
            f"elastic model in {agree_e}/{len(checks)}"
        )
    record = dict(command=[sys.executable, *sys.argv], preset=args.preset, mu=args.mu, checks=checks)
    (out / "checks.json").write_text(json.dumps(record, indent=1) + "\n")
    np.savez(
        out / "lift_map.npz",
        theta=thetas,
        alpha=alphas,
        mu=np.asarray(args.mu),
        kind=kind,
        kind_paper=kind_paper,
        kinds=np.array(KINDS),
        pull_G=pull,
        B=B,
        size=size,
        rope_length=L,
    )
    plot(out, args, thetas, alphas, kind, kind_paper, pull, checks)
    print(f"wrote {out}/lift_map.png, lift_map.npz, checks.json")
    return 0


def plot(out: Path, args, thetas, alphas, kind, kind_paper, pull, checks) -> None:
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    n_mu = len(args.mu)
    fig = Figure(figsize=(3.6 * n_mu, 7.0), layout="constrained")
    ax = fig.subplots(2, n_mu, squeeze=False)
    al, th = np.degrees(alphas), np.degrees(thetas)
    d_al = al[1] - al[0]
    ext = (al[0] - d_al / 2, al[-1] + d_al / 2, th[0], th[-1])
    vmax = np.nanpercentile(pull[np.isfinite(pull)], 99)
    for m, mu in enumerate(args.mu):
        a = ax[0, m]
        a.imshow(
            kind[m],
            origin="lower",
            extent=ext,
            aspect="auto",
            cmap=ListedColormap(COLOURS),
            vmin=-0.5,
            vmax=len(KINDS) - 0.5,
            interpolation="nearest",
        )
        differ = (kind[m] != kind_paper[m]).astype(float)
        if differ.any():
            a.contourf(al, th, differ, levels=[0.5, 1.5], hatches=["////"], colors="none")
        a.set_title(f"first motion, μ = {mu:g}")
        b = ax[1, m]
        cs = b.imshow(pull[m], origin="lower", extent=ext, aspect="auto", cmap="viridis", vmin=0, vmax=vmax)
        b.set_title(f"pull at the first motion [G], μ = {mu:g}")
        for c in checks:
            if c["mu"] != mu:
                continue
            ok = c["rigid"] == c["predicted"] and c["elastic"] == c["predicted"]
            for x in (a, b):
                x.plot(
                    c["alpha_deg"],
                    c["theta_deg"],
                    "o" if ok else "x",
                    ms=7,
                    mfc="none",
                    mec="k" if ok else "m",
                    mew=1.5,
                )
        for x in (a, b):
            x.set_xlabel("azimuth α from DE towards DH [deg]")
        a.set_ylabel("angle of the rope from the vertical θ [deg]")
        b.set_ylabel("θ [deg]")
    fig.colorbar(cs, ax=ax[1, -1], label="|S| / G")
    for k, nm in enumerate(KINDS):
        if np.any(kind == k):
            ax[0, 0].plot([], [], "s", color=COLOURS[k], label=nm)
    ax[0, 0].fill([], [], hatch="////", fc="none", label="paper's T = μN says otherwise")
    ax[0, 0].plot([], [], "ko", mfc="none", label="checked: both models agree")
    ax[0, 0].plot([], [], "mx", label="checked: a model disagrees")
    ax[0, 0].legend(fontsize=7, loc="lower left")
    fig.suptitle(f"{args.preset}: what the resting load does first as the rope is tensioned (statics 2.9)")
    fig.savefig(out / "lift_map.png", dpi=100)


if __name__ == "__main__":
    sys.exit(main())
