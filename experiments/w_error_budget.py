"""What sets the default solver's steps? The error estimate of the Rosenbrock-W steps, by state component
(issue 10: why a W step cannot be longer on paper-4.2 at the preset's ε).

1. **Budget.** For each μ of --mus: one solve of paper-4.2 to --t1 with the default solver (rtol 1e-3,
   atol 1e-5), saving every accepted step; each step is then repeated from its start to get its embedded
   error estimate e, and the share of each state leaf in the controller's squared norm
   Σ (e / (atol + rtol max(|y0|, |y1|)))² is averaged over the steps. Also the steps per second in time
   windows.
2. **Weights.** A vmapped solve of --n μ in [0.1, 0.6] to --t1 with the boom tip's leaves (tip position and
   velocity) weighted by w in the error norm (w = 1: the default norm), for each w of --weights: steps,
   rejected share, and the final mass centre's distance from Tsit5 at rtol 1e-10.

    python experiments/w_error_budget.py --mus 0.15,0.3,0.5 --n 16 --t1 25 --weights 1,0.3,0.1,0.03,0
    python experiments/w_error_budget.py --mus 0.3 --n 16 --t1 25 --weights 1,0.3 --time-derivative

Measured 2026-11-26 (Intel machine, commit a5860b2), the command above:

    μ = 0.3: 3 845 steps (164 rejected); shares of the error norm: tip velocity 0.979 (x 0.53, y 0.45,
    z 0.02), angular velocity 0.014, velocity 0.007, everything else < 0.001

    w      steps median   max    rejected   final mass centre vs Tsit5 1e-10: median   max
    1          3 832     4 319     5.0 %                                  0.035 cm   0.074 cm
    0.3        2 592     2 925     7.5 %                                  0.087 cm   0.217 cm
    0.1        1 809     2 025    10.6 %                                  0.215 cm   0.527 cm
    0.03       1 276     1 373    17.2 %                                  0.514 cm   1.284 cm
    0            982     1 094    43.0 %                                  1.055 cm   4.531 cm

(the budgets of the other μ are in docs/performance.md). The boom tip's horizontal velocity carries nearly all
of the estimate, and weighting it less cuts the steps but lets the load's error grow as fast as a looser
tolerance would: the tip's error reaches the load through the rope. Most of that error was the solver's
own, not a physical ringing to resolve: with `--time-derivative` (`RosenbrockW(time_derivative=True)`, the
∂f/∂t of the hoist law in the stages, and diffrax's PI controller 0.3/0.3) see docs/performance.md, "The
time derivative".
"""

from __future__ import annotations

import argparse
import dataclasses

import jax

jax.config.update("jax_num_cpu_devices", 2)
jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import initial_state, vector_field  # noqa: E402
from jaxhoist._numerics.rosenbrock import RosenbrockW, w_step  # noqa: E402  (internal: one step's error estimate)

MU = "foundation.friction_coefficient"
RTOL, ATOL = 1e-3, 1e-5  # the default solver's tolerances (SolverOptions())
TIP = ("tip_position", "tip_velocity")


def member(mu: float):
    sc = jh.set_param(jh.load_scenario("paper-4.2"), MU, mu)
    y0, c = initial_state(sc)
    return y0, (sc, c)


def controller(pi: bool, norm=None):
    """The default solver's step-size control (`SolverOptions()`: diffrax's integral controller), or with
    `pi` the PI controller of `--time-derivative` (pcoeff = icoeff = 0.3); with the error norm `norm` if
    given."""
    kw = {} if norm is None else {"norm": norm}
    if pi:
        kw.update(pcoeff=0.3, icoeff=0.3)
    return diffrax.PIDController(rtol=RTOL, atol=ATOL, **kw)


def solve(mu, t1, solver, controller, saveat, max_steps=200_000):
    y0, args = member(mu)
    return diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field), solver, 0.0, t1, 1e-4, y0, args=args, saveat=saveat,
        stepsize_controller=controller, max_steps=max_steps, throw=False,
    )  # fmt: skip


def budget(mu: float, t1: float, solver: RosenbrockW, pi: bool) -> None:
    """Part 1: the error norm's shares by state leaf over one member's accepted steps."""
    sol = solve(mu, t1, solver, controller(pi), diffrax.SaveAt(steps=True))
    n = int(sol.stats["num_accepted_steps"])
    ts = np.asarray(sol.ts)[:n]
    ys = jax.tree_util.tree_map(lambda x: x[:n], sol.ys)
    y0, args = member(mu)
    starts = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b[:-1]]), y0, ys)
    t_start = np.concatenate([[0.0], ts[:-1]])

    @jax.jit
    @jax.vmap
    def scaled_sq(t, y, h):
        f0 = vector_field(t, y, args)
        y1, e, _ = w_step(
            vector_field, solver.linearise, solver.tableau, t, y, h, args, f0, solver.quadrature,
            time_derivative=solver.time_derivative,
        )  # fmt: skip
        return jax.tree_util.tree_map(
            lambda a, b, ee: (ee / (ATOL + RTOL * jnp.maximum(jnp.abs(a), jnp.abs(b)))) ** 2, y, y1, e
        )

    sq = scaled_sq(jnp.asarray(t_start), starts, jnp.asarray(ts - t_start))
    fields = [f.name for f in dataclasses.fields(sq)]
    per = {k: np.asarray(getattr(sq, k)).reshape(n, -1) for k in fields}
    total = sum(v.sum(axis=1) for v in per.values())
    print(f"μ = {mu}: {n} steps ({int(sol.stats['num_rejected_steps'])} rejected); shares of the error norm:")
    for k, v in sorted(per.items(), key=lambda kv: -kv[1].sum()):
        if v.size == 0:
            continue
        share = (v.sum(axis=1) / np.maximum(total, 1e-300)).mean()
        if share >= 1e-3:
            comps = ", ".join(f"{s:.2f}" for s in (v / np.maximum(total, 1e-300)[:, None]).mean(axis=0))
            print(f"  {k:18s} {share:.3f}  (components {comps})")
    edges = np.linspace(0.0, t1, 6)
    rate = [int(((ts > a) & (ts <= b)).sum() / (b - a)) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    print(f"  steps per second in {len(rate)} windows of {t1 / len(rate):g} s: {rate}")


def weighted_norm(w: float):
    """diffrax's RMS norm over every state component, with the boom tip's leaves weighted by w."""

    def norm(e):
        total, count = 0.0, 0
        for f in dataclasses.fields(e):
            x = jnp.asarray(getattr(e, f.name))
            scale = w if f.name in TIP else 1.0
            total = total + scale * scale * jnp.sum(x * x)
            count += x.size
        return jnp.sqrt(total / count)

    return norm


def weights(n: int, t1: float, ws: list[float], solver: RosenbrockW, pi: bool) -> None:
    """Part 2: steps and accuracy with the boom tip's error weighted by w."""
    mus = jnp.linspace(0.1, 0.6, n)
    final = diffrax.SaveAt(t1=True)

    def run(solver, controller, max_steps):
        sol = jax.vmap(lambda m: solve(m, t1, solver, controller, final, max_steps))(mus)
        return sol.ys.position[:, -1], sol.stats  # pyright: ignore[reportOptionalMemberAccess]  # saved at t1

    tight = diffrax.PIDController(rtol=1e-10, atol=1e-12)
    ref, _ = jax.jit(lambda: run(diffrax.Tsit5(), tight, 10_000_000))()
    print("w      steps median   max    rejected   final mass centre vs Tsit5 1e-10: median   max")
    for w in ws:
        ctrl = controller(pi, weighted_norm(w))
        pos, stats = jax.jit(lambda c=ctrl: run(solver, c, 200_000))()
        acc, rej = np.asarray(stats["num_accepted_steps"]), np.asarray(stats["num_rejected_steps"])
        err = 100 * np.linalg.norm(np.asarray(pos) - np.asarray(ref), axis=-1)
        print(
            f"{w:<6g} {np.median(acc):9.0f} {acc.max():9d} {100 * rej.sum() / acc.sum():8.1f} %"
            f"{np.median(err):38.3f} cm {err.max():8.3f} cm"
        )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--mus", default="0.3", help="μ of the budget's single solves, comma-separated")
    p.add_argument("--n", type=int, default=16, help="members of the weight sweep (0: skip it)")
    p.add_argument("--t1", type=float, default=25.0, help="end time [s]")
    p.add_argument("--weights", default="1,0.3,0.1,0", help="weights w of the boom tip's error")
    p.add_argument(
        "--time-derivative",
        action="store_true",
        help="the solver with the ∂f/∂t term in its stages (RosenbrockW(time_derivative=True)) and "
        "diffrax's PI controller (pcoeff = icoeff = 0.3) instead of the default solver",
    )
    a = p.parse_args(argv)
    solver = RosenbrockW(time_derivative=a.time_derivative)
    for mu in (float(m) for m in a.mus.split(",") if m):
        budget(mu, a.t1, solver, a.time_derivative)
    if a.n:
        weights(a.n, a.t1, [float(w) for w in a.weights.split(",")], solver, a.time_derivative)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
