"""Does keeping the Rosenbrock-W linearisation for several steps pay? (issue 10, a candidate that lost)

The default solver re-linearises the stiff forces (`physics.linearise`, 2.7 µs per step per trajectory of
about 6-12 µs at 16 lanes, `experiments/bench_w_step.py`) on every step. A W-method keeps its order for any
W, so the linearisation could be kept for `refresh` accepted steps (refreshed for the whole lock-step group
at once, so that under `vmap` the `lax.cond` skips the work). This script is that variant (`StaleW`, defined
here only) against the default, on a μ-scan of paper-4.2 (same tolerances), with the error of the final
mass-centre position against Tsit5 at rtol 1e-9:

    python experiments/w_stale_jacobian.py --n 64 --t1 10 --refresh 1,2,4,8

Measured (2026-11-24, 64 μ in [0.1, 0.6], 10 s, 2 devices, machine loaded by other work): median steps
2060 / 2902 / 3186 / 3467 for refresh 1 / 2 / 4 / 8, rejected 28 % / 39 % / 39 % / 38 %, max error 0.15 /
0.13 / 0.15 / 0.46 cm; time per trajectory within the noise of the default (47-67 ms against 34-62 ms over
two rounds). The friction slope μN/ε changes as corners stick and slip, so a stale W costs steps as fast as
it saves linearisations: not adopted.
"""

from __future__ import annotations

import argparse

import jax

jax.config.update("jax_num_cpu_devices", 2)
jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import equinox.internal as eqxi  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._numerics._tree import lin_comb  # noqa: E402  (internal: re-implements the W step)

MU = "foundation.friction_coefficient"


def w_step_with(f, lin, tab, t, y, h, args, f0, quadrature):
    """`numerics.rosenbrock.w_step` with the linearisation given (not taken at (t, y))."""
    hg = h * tab.gamma
    lin, lu = jax.lax.optimization_barrier((lin, lin.factor(hg)))
    us = []
    for i in range(len(tab.m)):
        if i == 0:
            fi = f0
        else:
            yi = lin_comb([(tab.a[i][j], us[j]) for j in range(i)], base=y)
            fi = f(t + float(tab.alpha[i]) * h, yi, args)
        if i == 0:
            f_start = fi
        if i:
            cu = lin_comb([(tab.c[i][j], us[j]) for j in range(i)], like=y)
            fi = jax.tree_util.tree_map(lambda fl, cl: fl + cl / h, fi, cu)
        us.append(jax.lax.optimization_barrier(lin.solve(lu, fi, hg)))
    y1 = lin_comb(list(zip(tab.m, us, strict=True)), base=y)
    err = lin_comb(list(zip(tab.m_err, us, strict=True)), like=y)
    f1 = f(t + h, y1, args)
    trapezoid = jax.tree_util.tree_map(
        lambda q, g0, g1: q + 0.5 * h * (g0 + g1), quadrature(y), quadrature(f_start), quadrature(f1)
    )
    y1 = eqx.tree_at(quadrature, y1, trapezoid)
    err = eqx.tree_at(quadrature, err, jax.tree_util.tree_map(jnp.zeros_like, quadrature(err)))
    return y1, err, f1


class StaleW(jh.RosenbrockW):
    """RosenbrockW keeping its linearisation for `refresh` accepted steps (the whole vmapped group
    refreshes when any member's linearisation is that old)."""

    refresh: int = eqx.field(static=True, default=4)

    def init(self, terms, t0, t1, y0, args):
        lin = jax.lax.stop_gradient(self.linearise(t0, y0, args))
        return terms.vf(t0, y0, args), lin, jnp.array(0, dtype=jnp.int32)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        f0, lin_old, age = solver_state
        need = eqxi.unvmap_any(age >= self.refresh)
        lin = jax.lax.cond(need, lambda: jax.lax.stop_gradient(self.linearise(t0, y0, args)), lambda: lin_old)
        age = jnp.where(need, 1, age + 1)
        y1, err, f1 = w_step_with(terms.vf, lin, self.tableau, t0, y0, t1 - t0, args, f0, self.quadrature)
        return y1, err, dict(y0=y0, y1=y1), (f1, lin, age), diffrax.RESULTS.successful


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=64, help="members, μ evenly in [0.1, 0.6]")
    p.add_argument("--t1", type=float, default=10.0, help="end time [s]")
    p.add_argument("--refresh", default="1,2,4,8", help="refresh intervals to try (1: the default solver)")
    p.add_argument("--rounds", type=int, default=2, help="timing rounds (the machine is shared)")
    a = p.parse_args(argv)
    sc = jh.load_scenario("paper-4.2")
    mus = np.linspace(0.1, 0.6, a.n)
    kw = dict(observables=["final_position"])
    times = jh.Times(a.t1, n=2)
    ref = jh.scan(
        sc, {MU: mus}, times, options=jh.SolverOptions(diffrax.Tsit5(), rtol=1e-9, atol=1e-11), **kw
    )
    for _ in range(a.rounds):
        for k in (int(x) for x in a.refresh.split(",")):
            extra = {} if k == 1 else dict(options=jh.SolverOptions(StaleW(refresh=k), rtol=1e-3, atol=1e-5))
            r = jh.scan(sc, {MU: mus}, times, **kw, **extra)
            tm, st = r.attrs["timings_s"], r.num_accepted_steps + r.num_rejected_steps
            err = np.linalg.norm(r["final_position"] - ref["final_position"], axis=-1)
            rej = r.num_rejected_steps.sum() / st.sum()
            print(
                f"refresh {k}: {1e3 * tm['compute'] / a.n:.2f} ms per trajectory, steps median "
                f"{np.median(st):.0f} max {st.max()}, rejected {rej:.2f}, "
                f"max error {100 * err.max():.3f} cm, failed {(r.status != 0).sum()}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
