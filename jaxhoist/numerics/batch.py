"""The batch core of a scan: one member's solve and observables, a vmapped lock-step group of members, the
groups of a chunk on each device (`lax.map`) and the devices in parallel (`shard_map` over a 1-D mesh, one
code path for any device count). Pure: no I/O, no printing; a member's failure is its status, never an
exception. `numerics.scan` lays the members out and runs the chunks.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import SolveStatus
from . import fixed_step as fixed_mod
from .options import SolverOptions
from .paths import set_param
from .solve import solve


class ScanStatus(enum.IntEnum):
    """Outcome of one member of a scan (0-3 are the `SolveStatus` codes)."""

    OK = 0
    MAX_STEPS = 1
    NONFINITE = 2
    SOLVER_FAILED = 3
    INVALID_PARAMETER = 4
    NAN_OBSERVABLE = 5

    @property
    def message(self) -> str:
        if self.value < 4:
            return SolveStatus(self.value).message
        return {
            4: "invalid parameter values (not solved)",
            5: "the solve succeeded but an observable is NaN",
        }[self.value]


HISTORY_UNITS = {
    "position": "m",
    "velocity": "m/s",
    "euler": "rad",
    "angular_velocity": "rad/s",
    "corners": "m",
    "normal_forces": "N",
    "friction_forces": "N",
    "ground_reaction": "N",
    "rope_tension": "N",
    "tip_position": "m",
    "hoist_work": "J",
    "damping_loss": "J",
    "friction_work": "J",
}


def hist_shape(name: str) -> tuple[int, ...]:
    return {
        "corners": (4, 3),
        "friction_forces": (4, 3),
        "normal_forces": (4,),
        "ground_reaction": (),
        "rope_tension": (),
        "hoist_work": (),
        "damping_loss": (),
        "friction_work": (),
    }.get(name, (3,))


@dataclasses.dataclass(frozen=True)
class BatchSpec:
    """Everything static about one scan's compiled computation."""

    paths: tuple[str, ...]
    observables: tuple  # tuple[Observable, ...]
    histories: tuple[str, ...]
    options: SolverOptions
    lanes: int
    devices: tuple
    derivatives: bool = False


def member(scenario, ts, row, spec: BatchSpec):
    def run(row):
        sc = scenario
        for k, p in enumerate(spec.paths):
            sc = set_param(sc, p, row[k])
        o = spec.options
        lean = o.fixed_step and fixed_mod.supports(o.solver)
        traj = fixed_mod.solve_fixed(sc, ts, o) if lean else solve(sc, ts, o)
        obs = {o.name: o(traj, sc) for o in spec.observables}
        return obs, (obs, traj)

    if spec.derivatives:  # forward-mode sensitivities d observable / d parameter, one tangent per parameter
        jac, (obs, traj) = jax.jacfwd(run, has_aux=True)(row)
    else:
        _, (obs, traj) = run(row)
        jac = {}
    ok = traj.status == SolveStatus.OK
    # a NaN observable or sensitivity of a solve that succeeded is flagged, never silent (values are kept)
    checked = [*obs.values(), *jac.values()]
    nan_obs = jnp.any(jnp.stack([jnp.any(jnp.isnan(v)) for v in checked])) if checked else False
    status = jnp.where(ok & nan_obs, ScanStatus.NAN_OBSERVABLE, traj.status).astype(jnp.int32)
    obs = {k: jnp.where(ok, v, jnp.nan) for k, v in obs.items()}
    obs.update({f"d_{k}": jnp.where(ok, v, jnp.nan) for k, v in jac.items()})
    hist = {h: jnp.where(ok, getattr(traj, h), jnp.nan) for h in spec.histories}
    return {
        "obs": obs,
        "hist": hist,
        "status": status,
        "num_accepted_steps": traj.num_accepted_steps.astype(jnp.int32),
        "num_rejected_steps": traj.num_rejected_steps.astype(jnp.int32),
    }


def device_fn(scenario, ts, values, active, spec: BatchSpec):
    """values (G, L, P), active (G,) -> outputs with leading (G, L). Groups run one after another."""
    group = jax.vmap(lambda row: member(scenario, ts, row, spec))
    shapes = jax.eval_shape(group, values[0])

    def body(args):
        v, a = args
        return jax.lax.cond(
            a, group, lambda _: jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes), v
        )

    return jax.lax.map(body, (values, active))


@functools.lru_cache(maxsize=32)
def chunk_fn(spec: BatchSpec):
    # One code path for any device count: a mesh of one device too. XLA compiles a plain jit of the same
    # function with other fusion decisions, which rounded differently (1e-5 relative in final Euler angles on
    # paper-4.2, issue 14; 1.6e-7 m with the Rosenbrock-W solver).
    from jax.sharding import Mesh
    from jax.sharding import PartitionSpec as P

    mesh = Mesh(np.array(spec.devices), ("members",))
    f = jax.shard_map(
        lambda sc, ts, v, a: device_fn(sc, ts, v, a, spec),
        mesh=mesh,
        in_specs=(P(), P(), P("members"), P("members")),
        out_specs=P("members"),
        check_vma=False,
    )
    return eqx.filter_jit(f)


def flatten_out(out: Mapping, n: int) -> dict[str, np.ndarray]:
    """Device output {obs:{}, hist:{}, ...} with leading (G, L) -> flat numpy arrays, first n members."""
    flat: dict[str, np.ndarray] = {}
    for k, v in out["obs"].items():
        flat[f"obs:{k}"] = np.asarray(v).reshape(-1, *np.shape(v)[2:])[:n]
    for k, v in out["hist"].items():
        flat[f"hist:{k}"] = np.asarray(v).reshape(-1, *np.shape(v)[2:])[:n]
    for k in ("status", "num_accepted_steps", "num_rejected_steps"):
        flat[k] = np.asarray(out[k]).reshape(-1)[:n]
    return flat
