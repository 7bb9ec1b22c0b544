"""A lean fixed-step explicit Runge-Kutta integrator for large vmapped scans.

`diffrax.diffeqsolve` with `ConstantStepSize` pays, on every step, for machinery a scan at constant steps
does not need (step-size control, dense output, event and progress hooks, a loop over the stages with
dynamically indexed tableau rows). Here one step is the tableau unrolled in Python: the stages of
`physics.elastic.vector_field` (the same function `solve` uses) and their linear combinations, one
`lax.fori_loop` over the steps between two saved times and a `lax.scan` over the saved times. Only the
states at the saved times are kept.

The tableau is taken from a diffrax explicit Runge-Kutta solver (`Bosh3`, `Tsit5`, `Dopri5`, ...), so a
solve here and `diffeqsolve(..., stepsize_controller=ConstantStepSize())` with the same solver and step
take the same steps and agree to round-off when every saved time is a multiple of the step (tested in
`tests/test_fixed_step.py`). Between two saved times t_k < t_{k+1} the integrator takes
n = ⌈(t_{k+1} - t_k)/dt⌉ equal steps of (t_{k+1} - t_k)/n ≤ dt, so it lands on every saved time instead of
interpolating (diffrax interpolates there; the two differ only when the saved times are not multiples of
dt, by the truncation error).

Works under `jax.vmap` (all members take the same steps: no lock-step waste) and `jax.jvp`/`jax.jacfwd`
(forward-mode sensitivities). Reverse mode through the dynamic-length loops is not supported: use
`numerics.solve` with a checkpointed adjoint for `jax.grad`.
"""

from __future__ import annotations

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import SolveStatus
from .._physics.elastic import vector_field
from .._physics.equilibrium import initial_state
from .._physics.params import Scenario
from ._tree import lin_comb
from .solve import outputs


def supports(solver) -> bool:
    """True if `solver` is a diffrax explicit Runge-Kutta method with a single Butcher tableau."""
    tab = getattr(type(solver), "tableau", None)
    return (
        isinstance(solver, diffrax.AbstractERK)
        and isinstance(tab, diffrax.ButcherTableau)
        and not tab.implicit
    )


def _scale(h, f):
    return jax.tree_util.tree_map(lambda x: h * x, f)


def rk_step(f, tableau: diffrax.ButcherTableau, t, y, f0, h, args):
    """One explicit Runge-Kutta step of size h from (t, y) with f0 = f(t, y, args).

    Stages k_i = h f(t + c_i h, y + Σ_j a_ij k_j) as in diffrax. **Returns** (y1, f(t + h, y1)): for an FSAL
    tableau (last stage at y1, c = 1) the last stage is that value; otherwise it is evaluated.
    """
    a_lower = [np.asarray(a, dtype=np.float64) for a in tableau.a_lower]
    c = np.asarray(tableau.c, dtype=np.float64)
    b = np.asarray(tableau.b_sol, dtype=np.float64)
    ks = [_scale(h, f0)]
    fs = [f0]
    for i, (a_row, c_i) in enumerate(zip(a_lower, c, strict=True)):
        yi = lin_comb([(float(a), k) for a, k in zip(a_row, ks, strict=True)], base=y)
        fi = f(t + float(c_i) * h, yi, args)
        fs.append(fi)
        if i + 1 < len(c) or not tableau.fsal:
            ks.append(_scale(h, fi))
    if tableau.fsal:  # the last stage was evaluated at y1 = y + Σ b_j k_j (same coefficients)
        return yi, fs[-1]
    y1 = lin_comb([(float(bj), k) for bj, k in zip(b, ks, strict=True)], base=y)
    return y1, f(t + h, y1, args)


def integrate(f, solver, ts: Float[Array, " n_t"], y0, args, dt: float):
    """Integrate dy/dt = f(t, y, args) from ts[0] with explicit RK steps of at most `dt`, landing on every
    saved time.

    **Returns** `(ys, num_steps)`: the states at `ts` (leading axis n_t) and the number of steps taken.
    """
    if not supports(solver):
        raise TypeError(f"fixed-step integration needs a diffrax explicit Runge-Kutta solver, got {solver!r}")
    tableau = type(solver).tableau
    dt = float(dt)

    def interval(carry, k):
        y, fy = carry
        t0 = ts[k]
        span = ts[k + 1] - t0
        # Round the step count up, but not for a span that is a multiple of dt up to round-off.
        n = jnp.maximum(jnp.ceil(span / dt - 1e-9), 1.0)
        h = span / n

        def body(i, c):
            return rk_step(f, tableau, t0 + i.astype(h.dtype) * h, c[0], c[1], h, args)  # strict promotion

        y, fy = jax.lax.fori_loop(0, n.astype(jnp.int32), body, (y, fy))
        return (y, fy), (y, n.astype(jnp.int32))

    f0 = f(ts[0], y0, args)
    _, (ys, ns) = jax.lax.scan(interval, (y0, f0), jnp.arange(ts.shape[0] - 1))
    ys = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), y0, ys)
    return ys, jnp.sum(ns)


def solve_fixed(scenario: Scenario, ts: Float[Array, " n_t"], options):
    """The fixed-step counterpart of `numerics.solve.solve` (same `Trajectory`, never raises): the initial
    state, `integrate` with `options.solver` at steps of at most `options.dt0`, the outputs at `ts`.

    The status is `MAX_STEPS` if the steps needed exceed `options.max_steps` (the solve still runs; callers
    should refuse such requests on the host), `NONFINITE` if the final state is not finite.
    """
    y0, c = initial_state(scenario)
    ys, n = integrate(vector_field, options.solver, ts, y0, (scenario, c), options.dt0)
    # Finite motion state at t1 (the energy integrals follow from it): checking only these leaves lets XLA
    # drop the energy integrals from the step loop when no observable reads them (~30 % of a step's cost).
    y1 = jax.tree_util.tree_map(lambda x: x[-1], ys)
    motion = (
        y1.position,
        y1.velocity,
        y1.quaternion,
        y1.angular_velocity,
        y1.tip_position,
        y1.tip_velocity,
        y1.friction_state,
    )
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in motion]))
    status = jnp.where(
        n > options.max_steps, SolveStatus.MAX_STEPS, jnp.where(finite, SolveStatus.OK, SolveStatus.NONFINITE)
    ).astype(jnp.int32)
    stats = {"num_accepted_steps": n, "num_rejected_steps": jnp.zeros_like(n)}
    return outputs(ts, ys, scenario, c, status, stats)


def steps_needed(ts, dt: float) -> int:
    """Host-side count of the steps `integrate` takes on the concrete saved times `ts`."""
    span = np.diff(np.asarray(ts, dtype=np.float64))
    return int(np.sum(np.maximum(np.ceil(span / float(dt) - 1e-9), 1.0)))
