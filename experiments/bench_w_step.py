"""Cost of one integrator step in a vmapped loop: the vector field alone, an explicit Bosh3 step, the
linearisation with its factorisation and one solve, and a full Rosenbrock-W (ROS34PW2) step, each as a
`fori_loop` of `--steps` steps of 1 ms over `--lanes` members of paper-4.2 (μ spread over [0.1, 0.6]).

    python experiments/bench_w_step.py --lanes 256
    python experiments/bench_w_step.py --lanes 64 --kinds f,w

Prints compile time and µs per step per trajectory (best of 3 calls after compiling), one device.
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import initial_state, vector_field  # noqa: E402
from jaxhoist._numerics import fixed_step  # noqa: E402  (internal: times one RK step)
from jaxhoist._numerics.rosenbrock import ROS34PW2, w_step  # noqa: E402  (internal: times one W step)
from jaxhoist._physics.linearise import linearise  # noqa: E402  (internal: times the linearisation)

H = 1e-3


def loop(kind: str, n_steps: int):
    def one(y0, args):
        if kind == "f":  # one evaluation per step, folded into the state so that XLA keeps it

            def body(i, y):
                return jax.tree_util.tree_map(lambda a, b: a + 1e-9 * b, y, vector_field(i * H, y, args))

        elif kind == "bosh3":
            tab = diffrax.Bosh3.tableau

            def body(i, c):
                return fixed_step.rk_step(vector_field, tab, i * H, c[0], c[1], H, args)

            return jax.lax.fori_loop(0, n_steps, body, (y0, vector_field(0.0, y0, args)))[0]
        elif kind == "lin":

            def body(i, y):
                lin = linearise(i * H, y, args)
                hg = H * ROS34PW2.gamma
                u = lin.solve(lin.factor(hg), y, hg)
                return jax.tree_util.tree_map(lambda a, b: a + 1e-12 * b, y, u)

        elif kind == "w":

            def body(i, y):
                return w_step(vector_field, linearise, ROS34PW2, i * H, y, H, args)[0]

        else:
            raise SystemExit(f"unknown kind {kind!r}")
        return jax.lax.fori_loop(0, n_steps, body, y0)

    return jax.jit(jax.vmap(one))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--lanes", type=int, default=256, help="members in the vmap (default 256)")
    p.add_argument("--steps", type=int, default=500, help="steps per call (default 500)")
    p.add_argument("--kinds", default="f,bosh3,lin,w", help="what to time (default f,bosh3,lin,w)")
    args = p.parse_args(argv)
    sc = jh.load_scenario("paper-4.2")

    def member(mu):
        s = eqx.tree_at(lambda s: s.foundation.friction_coefficient, sc, mu)
        y0, c = initial_state(s)
        return y0, (s, c)

    y0s, argss = jax.vmap(member)(jnp.linspace(0.1, 0.6, args.lanes))
    for kind in args.kinds.split(","):
        f = loop(kind, args.steps)
        t0 = time.perf_counter()
        jax.block_until_ready(f(y0s, argss))
        compile_s = time.perf_counter() - t0
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            jax.block_until_ready(f(y0s, argss))
            best = min(best, time.perf_counter() - t0)
        us = 1e6 * best / args.steps / args.lanes
        print(f"{kind:6s} lanes {args.lanes}: compile {compile_s:.1f} s, {us:.3f} us per step per trajectory")


if __name__ == "__main__":
    main()
