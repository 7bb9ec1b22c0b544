"""The compiled (jitted) pieces of the rigid model's phase driver: the phase solve, guards, candidate
configurations, impulses, rope state and outputs (`numerics.rigid_solve`), and small host helpers."""

from __future__ import annotations

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..physics import rigid


@dataclasses.dataclass(frozen=True)
class _Options:
    rtol: float
    atol: float
    max_steps: int
    event_atol: float


def _phase_solve(scenario, c, phase, settings, y0, t0, t1, ts, options: _Options, inextensible: bool = False):
    event = diffrax.Event(
        rigid.event_condition,
        root_finder=optx.Bisection(rtol=1e-14, atol=options.event_atol),
        direction=False,
    )
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rigid.vector_field),  # pyright: ignore[reportArgumentType]  # jaxtyping Scalar vs diffrax RealScalarLike
        diffrax.Tsit5(),
        t0=t0,
        t1=t1,
        dt0=None,
        y0=y0,
        args=(scenario, c, phase, settings) + ((True,) if inextensible else ()),
        saveat=diffrax.SaveAt(ts=ts, t1=True),
        stepsize_controller=diffrax.PIDController(rtol=options.rtol, atol=options.atol),
        max_steps=options.max_steps,
        event=event,
        throw=False,
    )
    return sol.ts, sol.ys, sol.result, sol.stats["num_accepted_steps"], sol.stats["num_rejected_steps"]


_phase_solve_jit = eqx.filter_jit(_phase_solve)
_raw_guards_jit = eqx.filter_jit(rigid.raw_guards)


@eqx.filter_jit
def _eval_candidates(t, y, scenario, c, settings, contact, hints, rope, inextensible=False):
    """Contact forces, corner accelerations, body accelerations and rope tension for a batch of
    configurations (rope mode `rope`, an integer array)."""

    def one(ct, h):
        ph = rigid.make_phase(ct, slip_hint=h, rope=rope)
        d = rigid.contact_dynamics(t, y, scenario, c, ph, settings, inextensible)
        return d.force, d.corner_accel, d.accel, d.loads.rope_tension

    return jax.vmap(one)(contact, hints)


@eqx.filter_jit
def _eval_rope_impulses(t, y, scenario, c, modes, slip_dirs, normal_target, rcond):
    return jax.vmap(lambda m, s: rigid.rope_impulse_response(t, y, scenario, c, m, s, normal_target, rcond))(
        modes, slip_dirs
    )


@eqx.filter_jit
def _eval_impulses(y, scenario, c, modes, slip_dirs, normal_target, rcond):
    return jax.vmap(lambda m, s: rigid.impulse_response(y, scenario, c, m, s, normal_target, rcond))(
        modes, slip_dirs
    )


_contact_matrices = eqx.filter_jit(rigid.contact_matrices)


@eqx.filter_jit
def _rope_direction(t, y, scenario, c):
    return rigid.loads(t, y, scenario, c).rope_direction


@eqx.filter_jit
def _rope_state(t, y, scenario, c):
    """|AB| - l(t) [m], d|AB|/dt - dl/dt [m/s] and ds/dt [m/s] of the inextensible rope."""
    ld = rigid.loads(t, y, scenario, c, inextensible=True)
    return ld.stretch, ld.rope_rate_error, ld.hoist_rate


class _Jam(Exception):
    """No consistent contact configuration while corners on the ground slide: resolve by a tangential
    impact (`_Driver.jam`), then choose again."""


class _RopeWouldPush(Exception):
    """No configuration (or impulse) with the taut inextensible rope has S >= 0: try the slack rope."""


@eqx.filter_jit
def _forces(t, y, scenario, c, phase, settings, inextensible=False):
    return rigid.contact_dynamics(t, y, scenario, c, phase, settings, inextensible).force


@eqx.filter_jit
def _outputs(ts, ys, scenario, c, phases, settings, inextensible=False):
    return jax.vmap(lambda t, y, ph: rigid.output(t, y, scenario, c, ph, settings, inextensible))(
        ts, ys, phases
    )


#: Saved samples per output evaluation (`_chunked_outputs`): one compiled shape serves every `n_save`.
OUTPUT_CHUNK = 1024


def _chunked_outputs(ts, states, phase_index, phases, scenario, c, settings, inextensible):
    """`rigid.output` at every saved time, in chunks of `OUTPUT_CHUNK` samples (the last one padded by
    repeating its final sample), concatenated on the host. One compiled evaluation of fixed shape serves
    every number of saved times; a single vmap over all of them (25 001 samples) did not return.

    **Arguments**
    - `ts` (n_t) [s]; `states`: the saved `State`, host arrays with a leading n_t axis; `phase_index` (n_t):
      index into `phases` of each sample's phase; `scenario`, `c`, `settings`, `inextensible`: as for
      `rigid.output`.

    **Returns** a `rigid.Output` with a leading n_t axis.
    """
    n_t = ts.size
    table = jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *phases)
    parts = []
    for start in range(0, n_t, OUTPUT_CHUNK):
        sel = np.minimum(np.arange(start, start + OUTPUT_CHUNK), n_t - 1)
        chunk_states = jax.tree_util.tree_map(lambda x: jnp.asarray(x[sel]), states)
        chunk_phases = jax.tree_util.tree_map(lambda x: jnp.asarray(x[phase_index[sel]]), table)
        out = _outputs(jnp.asarray(ts[sel]), chunk_states, scenario, c, chunk_phases, settings, inextensible)
        m = min(OUTPUT_CHUNK, n_t - start)
        parts.append(jax.tree_util.tree_map(lambda x: np.asarray(x)[:m], out))
    return jax.tree_util.tree_map(lambda *xs: jnp.asarray(np.concatenate(xs)), *parts)


def _tree_index(tree, i):
    return jax.tree_util.tree_map(lambda x: x[i], tree)


def _np(x):
    return np.asarray(x)
