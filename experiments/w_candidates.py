"""Which stiff integrator for the default call? RosenbrockW, KenCarp, a semi-implicit Euler (issue 10)

One process solves paper-4.2 (ε = 1e-3 m/s) for --n friction coefficients μ evenly in [0.1, 0.6] to --t1,
each candidate as one vmapped, jitted group (`jax.jit(jax.vmap(...))`, lock-step), saving only t = 0 and t1:

- `rosw`: `jaxhoist.RosenbrockW()` at its default tolerances (rtol 1e-3, atol 1e-5), via `solve`;
- `kc4-split`: diffrax `KenCarp4` (IMEX ESDIRK) with `MultiTerm(explicit, implicit)`: implicit = the rates of
  the velocity-like leaves (velocity, angular_velocity, tip_velocity: every force, so the friction slope,
  dampers and springs), zeros elsewhere; explicit = the rest (kinematic rates, friction-law state,
  quadratures); f = explicit + implicit is checked. Root finder: diffrax's default, VeryChord (a chord
  iteration on the jacfwd Jacobian of the implicit term, one per step) at the controller's tolerances;
- `kc4-full`: KenCarp4 with the whole vector field implicit and a zero explicit term (an ESDIRK);
- `semi-h`: semi-implicit (linearly implicit) Euler at fixed step h with the project's structured W,
  y_{n+1} = y_n + u, (I/h - W(t_n, y_n)) u = f(t_n, y_n), in a `jax.lax.fori_loop`.

Prints per candidate: steps (accepted + rejected: sum, median, max), compile time, wall time per trajectory
of a second call after compilation, failed members (solver status or a non-finite end state), and the
max/median distance of the final mass centre from Tsit5 at rtol 1e-9, atol 1e-11.

    python experiments/w_candidates.py --n 8 --t1 25
    python experiments/w_candidates.py --n 8 --t1 25 --only rosw,kc4-split --kc-tol 1e-2,1e-4

Measured 2026-11-25 on the shared 2-core machine (load average 1.3 at the start; reference Tsit5 steps
median 47 639, max 110 117, 1312 ms per trajectory; f = explicit + implicit exactly, gap 0.0):

    candidate                   steps median    max   compile  ms/traj  ratio  error max / median  failed
    RosenbrockW (default)             4 100   4 522     9.9 s     38.3   1.0x  0.075 / 0.035 cm     0
    KenCarp4, IMEX split              1 908   2 205    17.4 s    131.3   3.4x  0.0062 / 0.0013 cm   0
    KenCarp4, all implicit            3 524   4 656    19.1 s    595.2  15.6x  0.032 / 0.0027 cm    0
    semi-implicit Euler h = 1 ms     25 000  25 000     3.4 s     59.7   1.6x  0.63 / 0.30 cm       0
    semi-implicit Euler h = 2 ms     12 500  12 500     3.9 s     29.4   0.8x  2.47 / 0.39 cm       0
    semi-implicit Euler h = 5 ms      5 000   5 000     3.4 s     12.2   0.3x  2.05 / 0.87 cm       0

and the second command (load 1.6, pyright beside it at the start): RosenbrockW 35.6 ms; KenCarp4 IMEX split
at rtol 1e-2, atol 1e-4 took *more* steps (median 3 103, max 3 501; 394 ms, 11.1x; error max 0.030 cm).
RosenbrockW stays: per lock-step iteration (ms per trajectory / max steps) a W step (four f, one
linearisation, one structured 6x6 factorisation) cost 8.5 µs per member, a KenCarp4 step (six stages, chord
iterations on the jacfwd Jacobian of the 22-component state, a dense LU) 60 µs (split) and 128 µs (all
implicit); KenCarp's half as many steps do not pay for that. The semi-implicit Euler is stable at every h
(W holds the stiff modes) but first order: within 1 cm only at h = 1 ms, at 1.6x the W's time; at 2 and
5 ms it is faster but 2-2.5 cm off.
"""

from __future__ import annotations

import argparse
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import initial_state, set_param, vector_field  # noqa: E402
from jaxhoist._numerics.solve import as_float64_leaves, solve  # noqa: E402  (internal: the bare solve core under vmap)
from jaxhoist._physics.linearise import linearise  # noqa: E402  (internal: the structured W of the semi-implicit Euler)

VELOCITY_LEAVES = ("velocity", "angular_velocity", "tip_velocity")


def split(y):
    """(implicit mask, explicit mask) as callables keeping the velocity-like leaves, resp. the rest."""

    def keep(names):
        def masked(d):
            return type(d)(**{k: (v if k in names else jnp.zeros_like(v)) for k, v in vars(d).items()})

        return masked

    rest = tuple(k for k in vars(y) if k not in VELOCITY_LEAVES)
    return keep(VELOCITY_LEAVES), keep(rest)


def kencarp_one(sc, mu, ts, full: bool, max_steps: int, rtol: float, atol: float):
    s = set_param(sc, "foundation.friction_coefficient", mu)
    y0, c = initial_state(s)
    if full:
        expl = lambda t, y, a: jax.tree_util.tree_map(jnp.zeros_like, y)  # noqa: E731
        impl = vector_field
    else:
        imask, emask = split(y0)
        expl = lambda t, y, a: emask(vector_field(t, y, a))  # noqa: E731
        impl = lambda t, y, a: imask(vector_field(t, y, a))  # noqa: E731
    sol = diffrax.diffeqsolve(
        diffrax.MultiTerm(diffrax.ODETerm(expl), diffrax.ODETerm(impl)),
        diffrax.KenCarp4(),
        t0=ts[0],
        t1=ts[-1],
        dt0=None,
        y0=y0,
        args=(s, c),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=max_steps,
        throw=False,
    )
    st = sol.stats
    ok = sol.result == diffrax.RESULTS.successful
    return sol.ys.position[-1], st["num_accepted_steps"] + st["num_rejected_steps"], ok  # pyright: ignore[reportOptionalMemberAccess]


def semi_implicit_one(sc, mu, t1: float, h: float):
    s = set_param(sc, "foundation.friction_coefficient", mu)
    y0, c = initial_state(s)
    args = (s, c)
    n = round(t1 / h)

    def body(i, y):
        t = i * h
        lin = linearise(t, y, args)
        lin, lu = jax.lax.optimization_barrier((lin, lin.factor(h)))
        u = lin.solve(lu, vector_field(t, y, args), h)
        return jax.tree_util.tree_map(jnp.add, y, u)

    y1 = jax.lax.fori_loop(0, n, body, y0)
    return y1.position, jnp.asarray(n), jnp.asarray(True)


def timed(fn, mus):
    """(result, compile s, wall s of a second call)."""
    t0 = time.perf_counter()
    compiled = jax.jit(jax.vmap(fn)).lower(mus).compile()
    t_compile = time.perf_counter() - t0
    jax.block_until_ready(compiled(mus))
    t0 = time.perf_counter()
    out = jax.block_until_ready(compiled(mus))
    return out, t_compile, time.perf_counter() - t0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=8, help="members, μ evenly in [0.1, 0.6]")
    p.add_argument("--t1", type=float, default=25.0, help="end time [s]")
    p.add_argument("--h", default="0.001,0.002,0.005", help="semi-implicit Euler steps [s], comma-separated")
    p.add_argument("--only", default="", help="rosw,kc4-split,kc4-full,semi or a subset")
    p.add_argument("--kc-tol", default="1e-3,1e-5", help="KenCarp rtol,atol (the default's: 1e-3,1e-5)")
    p.add_argument("--kc-max-steps", type=int, default=200_000, help="KenCarp step budget")
    a = p.parse_args(argv)
    only = set(a.only.split(",")) if a.only else {"rosw", "kc4-split", "kc4-full", "semi"}
    print(f"load average at start {os.getloadavg()}", flush=True)
    sc = as_float64_leaves(jh.load_scenario("paper-4.2"))
    with_mu = lambda mu: set_param(sc, "foundation.friction_coefficient", mu)  # noqa: E731
    mus, ts = jnp.linspace(0.1, 0.6, a.n), jnp.array([0.0, a.t1])

    # f = explicit + implicit, leaf by leaf, at the initial state and a perturbed one.
    y0, c0 = initial_state(sc)
    imask, emask = split(y0)
    y_pert = jax.tree_util.tree_map(lambda x: x + 1e-3 * jnp.cos(jnp.arange(x.size).reshape(x.shape)), y0)
    for y in (y0, y_pert):
        f = vector_field(0.3, y, (sc, c0))
        gap = jax.tree_util.tree_map(lambda u, v, w: jnp.abs(u - v - w).max(initial=0), f, emask(f), imask(f))
        gap = max(float(g) for g in jax.tree_util.tree_leaves(gap))
        print(f"max |f - (explicit + implicit)| = {gap:.1e}")

    ref_opts = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-9, atol=1e-11, max_steps=2_000_000)
    ref, t_c, t_w = timed(lambda mu: solve(with_mu(mu), ts, ref_opts), mus)
    ref_steps = np.asarray(ref.num_accepted_steps + ref.num_rejected_steps)
    ref_pos = np.asarray(ref.position[:, -1])
    print(
        f"reference Tsit5 rtol 1e-9: steps median {np.median(ref_steps):.0f}, max {ref_steps.max()}, "
        f"{1e3 * t_w / a.n:.0f} ms per trajectory, failed {int(np.sum(np.asarray(ref.status) != 0))}",
        flush=True,
    )

    kc_tol = tuple(map(float, a.kc_tol.split(",")))
    cands = {}
    if "rosw" in only:

        def rosw(mu):
            tr = solve(with_mu(mu), ts, jh.SolverOptions())
            return tr.position[-1], tr.num_accepted_steps + tr.num_rejected_steps, tr.status == 0

        cands["RosenbrockW (default)"] = rosw
    for full in (False, True):
        if ("kc4-full" if full else "kc4-split") in only:
            name = "KenCarp4, all implicit" if full else "KenCarp4, IMEX split"
            cands[name] = lambda mu, full=full: kencarp_one(sc, mu, ts, full, a.kc_max_steps, *kc_tol)
    if "semi" in only:
        for h in map(float, a.h.split(",")):
            semi = lambda mu, h=h: semi_implicit_one(sc, mu, a.t1, h)  # noqa: E731
            cands[f"semi-implicit Euler h={1e3 * h:g} ms"] = semi

    base_ms = None
    for name, fn in cands.items():
        (pos, steps, ok), t_c, t_w = timed(fn, mus)
        pos, steps, ok = np.asarray(pos), np.asarray(steps), np.asarray(ok)
        finite = np.all(np.isfinite(pos), axis=-1)
        failed = int(np.sum(~(ok & finite)))
        err = np.linalg.norm(pos - ref_pos, axis=-1)
        err = np.where(finite, err, np.inf)
        ms = 1e3 * t_w / a.n
        base_ms = ms if base_ms is None else base_ms
        print(
            f"{name:32s} steps {steps.sum():8d}, median {np.median(steps):7.0f}, max {steps.max():7d}; "
            f"compile {t_c:5.1f} s, {ms:8.2f} ms per trajectory ({ms / base_ms:6.1f}x); failed {failed}; "
            f"error max {100 * err.max():.3g} cm, median {100 * np.median(err):.3g} cm",
            flush=True,
        )
    print(f"load average at end {os.getloadavg()}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
