"""The batch core of a scan: one member's solve and observables, a lock-step group of members (the
one compiled program, the same for any member count, chunk size and device count, and without derivatives
for any swept parameters: `group_spec`), the groups of a chunk on each device one after another, and the
devices in parallel (failing group mates isolated: `CompiledChunk`). Pure: no I/O, no printing; a member's
failure is its status, never an exception. `apps.scan` lays the members out and runs the chunks.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import enum
import functools
from collections.abc import Mapping

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import SolveStatus
from .._physics.equilibrium import initial_state
from .._physics.paths import set_param
from . import compile_cache, lockstep, xla_options
from . import fixed_step as fixed_mod
from .options import SolverOptions
from .sensitivity import uses_tangent_solve
from .solve import outputs, solve, solve_joint, solve_status, step_size_controller


class ScanStatus(enum.IntEnum):
    """Outcome of one member of a scan (0-4 are the `SolveStatus` codes, `ENERGY_BALANCE` included: a
    member whose energy balance does not close is a failed member, its values NaN like any other's)."""

    OK = 0
    MAX_STEPS = 1
    NONFINITE = 2
    SOLVER_FAILED = 3
    ENERGY_BALANCE = 4
    INVALID_PARAMETER = 5
    NAN_OBSERVABLE = 6

    @property
    def message(self) -> str:
        if self.value in SolveStatus._value2member_map_:
            return SolveStatus(self.value).message
        return {
            ScanStatus.INVALID_PARAMETER: "invalid parameter values (not solved)",
            ScanStatus.NAN_OBSERVABLE: "the solve succeeded but an observable is NaN",
        }[self]


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


def member_scenario(scenario, row, paths: tuple[str, ...]):
    """The scenario of one member: `scenario` with each of `paths` set to its value in `row`."""
    for k, p in enumerate(paths):
        scenario = set_param(scenario, p, row[k])
    return scenario


def member_scenarios(scenario, values, paths: tuple[str, ...]):
    """The scenarios of a group's members, `values` (L, P): `member_scenario` of each row, every array leaf
    with a leading member axis (the leaves no path sets repeated), as `lock_step_group` takes them."""
    return eqx.filter_vmap(lambda row: member_scenario(scenario, row, paths))(values)


def member(scenario, ts, row, options: SolverOptions, spec: BatchSpec):
    """One member's outputs, solved under `options` (`group_options`: the spec's, the tolerances as values;
    `spec.options` is not used). With `spec.derivatives` and the Rosenbrock-W solver in forward mode, its
    values and sensitivities come from one augmented solve per parameter (`solve_joint`), the values from the
    first parameter's: they agree with a scan without derivatives to the solver's tolerance, not bit for
    bit."""
    opts = options
    joint = spec.derivatives and uses_tangent_solve(opts)  # Rosenbrock-W: never the lean loop's explicit RK
    lean = opts.fixed_step and fixed_mod.supports(opts.solver)
    core = fixed_mod.solve_fixed if lean else solve_joint if joint else solve

    def run(row):
        sc = member_scenario(scenario, row, spec.paths)
        traj = core(sc, ts, opts)
        obs = {o.name: o(traj, sc) for o in spec.observables}
        return obs, (obs, traj)

    if spec.derivatives and len(spec.paths) == 1:
        # one parameter: one `jax.jvp`, its tangent as the Jacobian's last axis. `jax.jacfwd` would `vmap`
        # the tangent solve over a batch of one inside the group's vmap, which took 1.5x the tracing and
        # 1.25x the XLA compile (CPU time, paper-4.2, 16 lanes: bench_compile_phases.py)
        _, tangent, (obs, traj) = jax.jvp(run, (row,), (jnp.ones_like(row),), has_aux=True)
        jac = {k: v[..., None] for k, v in tangent.items()}
    elif joint:  # one joint solve per parameter, batched; the values are the first one's
        _, tangents, aux = jax.vmap(lambda d: jax.jvp(run, (row,), (d,), has_aux=True))(jnp.eye(row.shape[0]))
        obs, traj = jax.tree_util.tree_map(lambda x: x[0], aux)
        jac = {k: jnp.moveaxis(v, 0, -1) for k, v in tangents.items()}
    elif spec.derivatives:  # forward-mode sensitivities d observable / d parameter, one tangent per parameter
        jac, (obs, traj) = jax.jacfwd(run, has_aux=True)(row)
    else:
        _, (obs, traj) = run(row)
        jac = {}
    return checked_outputs(obs, jac, traj, spec)


def checked_outputs(obs: dict, jac: dict, traj, spec: BatchSpec) -> dict:
    """A member's outputs from its observables, their sensitivities (`jac`, maybe empty) and its
    `Trajectory`: the member's status (a NaN observable or a non-finite sensitivity of a solve that succeeded
    is `NAN_OBSERVABLE`, never silent; the values are kept), and NaN values for a failed member."""
    ok = traj.status == SolveStatus.OK
    checked = [jnp.isnan(v) for v in obs.values()] + [~jnp.isfinite(v) for v in jac.values()]
    nan_obs = jnp.any(jnp.stack([jnp.any(v) for v in checked])) if checked else False
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


def in_lock_step(spec: BatchSpec, ts) -> bool:
    """Whether `group_fn` solves the group with `lockstep.solve_group` (one while loop over the lanes): a
    scan without derivatives, with an adaptive solver under diffrax's PID controller (the default; constant
    steps take the lean fixed-step loop or `solve`)."""
    opts = spec.options
    controller = step_size_controller(opts, ts)
    return not spec.derivatives and lockstep.supports(opts.solver, controller, opts.progress_meter)


def group_spec(spec: BatchSpec, ts) -> BatchSpec:
    """The spec that the group program of `spec` is compiled for: without the step-size controller's
    tolerances, which the program takes as values (`group_options`), and for `in_lock_step` specs without
    the swept paths, since that program takes the members' scenarios (`member_scenarios`, a small program
    of its own), not their values. So a scan at other tolerances, and without derivatives a scan of another
    parameter or of several, with the same observables, solver, group width and saved times runs the same
    compiled group program (in this process, or loaded from the cache folder)."""
    ctrl = spec.options.stepsize_controller
    if isinstance(ctrl, diffrax.PIDController):
        ctrl = eqx.tree_at(lambda c: (c.rtol, c.atol), ctrl, (None, None), is_leaf=lambda x: x is None)
        spec = dataclasses.replace(spec, options=spec.options.replace(stepsize_controller=ctrl))
    return dataclasses.replace(spec, paths=()) if in_lock_step(spec, ts) else spec


def group_options(spec: BatchSpec) -> SolverOptions:
    """The options that the group program of `spec` takes as an argument: `spec.options` with a
    `PIDController`'s `rtol` and `atol` as float64 arrays (`SolverOptions.traced_tolerances`; the steps and
    results are bit for bit those of the tolerances compiled in)."""
    return spec.options.traced_tolerances()


def lock_step_group(scenarios, ts, options: SolverOptions, spec: BatchSpec):
    """The group program of `in_lock_step` specs: from the members' scenarios (`member_scenarios`: every
    array leaf with a leading member axis) each member's initial state, one `lockstep.solve_group` for the
    group under `options` (`group_options`: the tolerances are values of the program), then each member's
    outputs and observables as `member` makes them. `spec.paths` and `spec.options` are not used."""
    opts = options
    y0s, cs = eqx.filter_vmap(initial_state)(scenarios)
    sol = lockstep.solve_group(
        opts.solver, step_size_controller(opts, ts), ts, y0s, (scenarios, cs), opts.dt0, opts.max_steps
    )

    def finish(sc, c, ys, result, accepted, rejected):
        y1 = jax.tree_util.tree_map(lambda x: x[-1], ys)
        stats = {"num_accepted_steps": accepted, "num_rejected_steps": rejected}
        traj = outputs(ts, ys, sc, c, solve_status(result, y1), stats)
        obs = {o.name: o(traj, sc) for o in spec.observables}
        return checked_outputs(obs, {}, traj, spec)

    return eqx.filter_vmap(finish)(
        scenarios, cs, sol.ys, sol.result, sol.num_accepted_steps, sol.num_rejected_steps
    )


def group_fn(scenario, ts, values, options: SolverOptions, spec: BatchSpec):
    """values (L, P) -> outputs with leading (L,): one lock-step group, solved under `options`
    (`group_options`; `spec.options` is not used). Without derivatives, with the
    default adaptive solve, one while loop over the lanes (`lock_step_group` of `member_scenarios`,
    `in_lock_step`): a `jax.vmap` of `member` would batch the solve's while loop several times in tracing.
    Otherwise a `jax.vmap` of `member`. (A scan compiles the lock-step route as two programs,
    `member_scenarios` and `lock_step_group`, so that the large one does not depend on the swept paths:
    `group_spec`.)"""
    if in_lock_step(spec, ts):
        return lock_step_group(member_scenarios(scenario, values, spec.paths), ts, options, spec)
    return jax.vmap(lambda row: member(scenario, ts, row, options, spec))(values)


def _to_device(tree, device):
    """The array leaves of `tree` committed to `device` (other leaves, static for `eqx.filter_jit`, kept)."""
    return jax.tree_util.tree_map(lambda x: jax.device_put(x, device) if eqx.is_array(x) else x, tree)


def execution_targets(devices: tuple) -> tuple:
    """The device that runs each device's share of a chunk. Host CPU "devices" (`jax_num_cpu_devices`) are
    one pool of cores: their shares all run on the first of them, one host thread each, so one compiled
    program serves them (two threads running one executable run concurrently, measured 0.20 s for two
    groups against 0.175 s for one). Accelerators run their own shares, each with its own copy of the
    program."""
    if devices and all(d.platform == "cpu" for d in devices):
        return (devices[0],) * len(devices)
    return tuple(devices)


def describe_devices(devices: tuple) -> list[str]:
    """What ran a chunk, for scan.json and the manifest: e.g. `["TFRT_CPU_0 (2 threads)"]` or the list of
    accelerators."""
    targets = execution_targets(devices)
    if len(set(targets)) == 1 and len(targets) > 1:
        return [f"{targets[0]} ({len(targets)} threads)"]
    return [str(d) for d in targets]


class CompiledChunk:
    """One chunk's computation, compiled: `(scenario, ts, values (G, L, P), active (G,))` -> outputs with
    leading (G, L) as numpy arrays (an inactive group's outputs are zeros).

    **One program whatever the member count, chunk size and device count**: the compiled program solves
    one group (`group_fn`). The G groups are split into equal contiguous shares, one per device; each share
    runs in its own host thread, which calls the program on the share's active groups one after another,
    so the shares run concurrently (`execution_targets`: on host CPU devices one compiled program serves
    every share; an accelerator gets its own compiled copy). The groups are a host loop rather than a
    loop inside the program (`lax.map`), so that a scan of another size reuses the compiled group, and
    the group is traced once (a `lax.cond` skipping inactive groups needed the group's output shapes, a
    second trace). A partitioned SPMD program
    (`shard_map` over a mesh of two or more devices) goes through XLA's partitioning pass pipeline and
    rounded differently from the one-device program (2.6e-7 m with Tsit5, 4.7e-6 m with the Rosenbrock-W
    solver on paper-4.2 after 3 s): with one single-device program, a member's result does not depend on
    how many devices share the scan, nor on the chunk size.

    **Failing group mates are isolated**. A lock-step group is one solve of all its lanes; a member that
    fails (exhausts its steps, blows up) can perturb its healthy group mates through the vectorised
    arithmetic they share (seen with Tsit5: 3e-8 rad and one step more for a group mate of a rope of
    stiffness 1e16 N/m on a tip of 1e-12 kg). So every group with both failed and healthy members is solved
    a second time with each failed member replaced by a copy of its group's first healthy member, and the
    healthy members' outputs are taken from that second solve: they are bit-for-bit what a group without
    the failure gives. The failed members keep their first-pass status (and NaN values).
    """

    def __init__(self, spec: BatchSpec, executables: dict):
        self.spec = spec
        self.executables = executables  # target device -> compiled program

    def _run(self, scenario, ts, values, active) -> dict:
        values, active = np.asarray(values), np.asarray(active)
        targets = execution_targets(self.spec.devices)
        if values.shape[0] % len(targets):
            raise ValueError(f"{values.shape[0]} groups do not split evenly over {len(targets)} devices")
        g = values.shape[0] // len(targets)

        def share(k):
            groups = [i for i in range(k * g, (k + 1) * g) if active[i]]
            if not groups:
                return None
            exe = self.executables[targets[k]]
            sc, t = _to_device((scenario, ts), targets[k])
            outs = {i: exe(sc, t, jax.device_put(values[i], targets[k])) for i in groups}
            return {i: jax.tree_util.tree_map(np.asarray, o) for i, o in outs.items()}

        if len(targets) == 1:
            shares = [share(0)]
        else:
            with concurrent.futures.ThreadPoolExecutor(len(targets)) as pool:
                shares = list(pool.map(share, range(len(targets))))
        outs = {i: o for s in shares if s is not None for i, o in s.items()}
        zeros = jax.tree_util.tree_map(np.zeros_like, next(iter(outs.values())))
        return jax.tree_util.tree_map(
            lambda *xs: np.stack(xs), *[outs.get(i, zeros) for i in range(values.shape[0])]
        )

    def __call__(self, scenario, ts, values, active) -> dict:
        active = np.asarray(active)
        if not active.any():
            raise ValueError("a chunk with no active group")
        out = self._run(scenario, ts, values, active)
        failed = (out["status"] != ScanStatus.OK) & (out["status"] != ScanStatus.NAN_OBSERVABLE)
        mixed = active & failed.any(axis=1) & ~failed.all(axis=1)
        if not mixed.any():
            return out
        values = np.array(values)
        for gi in np.flatnonzero(mixed):
            values[gi, failed[gi]] = values[gi, np.argmin(failed[gi])]  # the first healthy member
        again = self._run(scenario, ts, values, mixed)
        take = mixed[:, None] & ~failed  # the healthy members of the mixed groups

        def merge(a, b):
            return np.where(take.reshape(take.shape + (1,) * (a.ndim - 2)), b, a)

        return jax.tree_util.tree_map(merge, out, again)


class _LoweredChunk:
    def __init__(self, spec: BatchSpec, lowered: dict, wrap=None):
        self.spec, self.lowered, self.wrap = spec, lowered, wrap

    def compile(self) -> CompiledChunk:
        items = list(self.lowered.items())

        def compile_one(item):
            device, lowered = item
            return lowered.compile(compiler_options=xla_options.compiler_options(device.platform))

        if len(items) == 1:
            exes = {items[0][0]: compile_one(items[0])}
        else:  # XLA compiles without holding the GIL: one thread per accelerator
            with concurrent.futures.ThreadPoolExecutor(len(items)) as pool:
                exes = dict(zip([d for d, _ in items], pool.map(compile_one, items), strict=True))
        if self.wrap is not None:
            exes = {d: self.wrap(d, exe) for d, exe in exes.items()}
        return CompiledChunk(self.spec, exes)


class ChunkProgram:
    """The batch core for one `BatchSpec`, with the ahead-of-time interface of a jitted function:
    `chunk_fn(spec).lower(scenario, ts, values, active).compile()` gives a `CompiledChunk` for any number
    of groups G (what is lowered and compiled is one group, `group_fn`, of the shape of `values[0]`; for
    `in_lock_step` specs `lock_step_group` of the members' scenarios, `member_scenarios` running before it
    as a program of its own). G (the leading axis of `values`) must be a multiple of the number of
    devices."""

    def __init__(self, spec: BatchSpec):
        self.spec = spec
        self.members = eqx.filter_jit(functools.partial(member_scenarios, paths=spec.paths))

    def lower(self, scenario, ts, values, active) -> _LoweredChunk:
        n_dev = len(self.spec.devices)
        n_groups = int(np.shape(values)[0])
        if n_groups % n_dev:
            raise ValueError(f"{n_groups} groups do not split evenly over {n_dev} devices")
        values = np.asarray(values)
        targets = dict.fromkeys(execution_targets(self.spec.devices))
        if not in_lock_step(self.spec, ts):
            fn = eqx.filter_jit(functools.partial(group_fn, spec=group_spec(self.spec, ts)))
            lowered, options = {}, {}
            for d in targets:
                sc, t, v, options[d] = _to_device((scenario, ts, values[0], group_options(self.spec)), d)
                lowered[d] = fn.lower(sc, t, v, options[d])
            return _LoweredChunk(self.spec, lowered, wrap=lambda d, exe: _GroupCall(exe, options[d]))
        group = eqx.filter_jit(functools.partial(lock_step_group, spec=group_spec(self.spec, ts)))
        lowered, options = {}, {}
        for d in targets:
            sc, t, v, options[d] = _to_device((scenario, ts, values[0], group_options(self.spec)), d)
            lowered[d] = group.lower(self.members(sc, v), t, options[d])
        return _LoweredChunk(
            self.spec, lowered, wrap=lambda d, exe: _LockStepCall(self.members, exe, options[d])
        )


@functools.lru_cache(maxsize=32)
def chunk_fn(spec: BatchSpec) -> ChunkProgram:
    return ChunkProgram(spec)


def stores_whole(spec: BatchSpec) -> bool:
    """Whether the group program of `spec` goes through `compile_cache.program` (and so, with the persistent
    compilation cache on, is stored whole and loaded by a later process without tracing): where every
    share of a chunk runs on one host CPU device, the default device. Accelerators (one copy of the
    program per device) are compiled by `ChunkProgram` (JAX's persistent cache stores their XLA compile)."""
    targets = set(execution_targets(spec.devices))
    if len(targets) != 1:
        return False
    (target,) = targets
    return target.platform == "cpu" and target == jax.devices()[0]


def compiled_chunk(spec: BatchSpec, scenario, ts, values, active) -> tuple[CompiledChunk, float, str]:
    """The `CompiledChunk` of `spec` for chunks shaped like `values` (G, L, P), made once per process (for
    `in_lock_step` specs the group program once for every `spec` of the same `group_spec`, whatever the
    swept paths).

    **Returns** `(chunk, seconds spent making its programs now, how)`: how the group program was had,
    "compiled", "loaded" (from the persistent compilation cache's folder, `compile_cache.program`) or
    "reused" (compiled earlier in this process)."""
    if stores_whole(spec):
        (target,) = set(execution_targets(spec.devices))
        sc, t, v = _to_device((scenario, ts, np.asarray(values)[0]), target)
        gspec, opts = group_spec(spec, ts), _to_device(group_options(spec), target)
        if not in_lock_step(spec, ts):
            args = (sc, t, v, opts, gspec)
            exe, seconds, loaded = compile_cache.program("scan", "scan-group", group_fn, args)
            call = _GroupCall(lambda sc, t, v, o: exe(sc, t, v, o, gspec), opts)
            return CompiledChunk(spec, {target: call}), seconds, _how(seconds, loaded)
        members, s_members, _ = compile_cache.program(
            "scan-members", "scan-members", member_scenarios, (sc, v, spec.paths)
        )
        group, s_group, loaded = compile_cache.program(
            "scan-lock-step",
            "scan-lock-step-group",
            lock_step_group,
            (members(sc, v, spec.paths), t, opts, gspec),
        )
        call = _LockStepCall(
            lambda sc, v: members(sc, v, spec.paths), lambda scs, t, o: group(scs, t, o, gspec), opts
        )
        return CompiledChunk(spec, {target: call}), s_members + s_group, _how(s_group, loaded)
    program = chunk_fn(spec)
    if not in_lock_step(spec, ts):  # keyed by what it is compiled for (not the tolerances)
        key = (group_spec(spec, ts), *compile_cache.structure_key(scenario, ts, jnp.asarray(values[0])))
        chunk, seconds = compile_cache.compiled(
            "scan", key, lambda: program.lower(scenario, ts, values, active)
        )
        opts = group_options(spec)
        calls = {d: _GroupCall(c.exe, _to_device(opts, d)) for d, c in chunk.executables.items()}
        return CompiledChunk(spec, calls), seconds, _how(seconds, False)
    # the group programs, keyed by what they are compiled for (not the paths), each device's wrapped with this
    # spec's members program
    scenarios = eqx.filter_eval_shape(program.members, scenario, np.asarray(values)[0])
    key = (group_spec(spec, ts), *compile_cache.structure_key(scenarios, ts))
    chunk, seconds = compile_cache.compiled(
        "scan-lock-step", key, lambda: program.lower(scenario, ts, values, active)
    )
    calls = {
        d: _LockStepCall(program.members, call.group, _to_device(group_options(spec), d))
        for d, call in chunk.executables.items()
    }
    return CompiledChunk(spec, calls), seconds, _how(seconds, False)


def _how(seconds: float, loaded: bool) -> str:
    return "loaded" if loaded else "compiled" if seconds else "reused"


class _GroupCall:
    """`call(scenario, ts, values)` for the program of `group_fn`: `exe(scenario, ts, values, options)`
    (`group_options`, on the program's device)."""

    def __init__(self, exe, options):
        self.exe, self.options = exe, options

    def __call__(self, scenario, ts, values):
        return self.exe(scenario, ts, values, self.options)


class _LockStepCall:
    """`call(scenario, ts, values)` for the lock-step route: `members(scenario, values)` gives the members'
    scenarios (`member_scenarios`), `group(scenarios, ts, options)` runs the group program
    (`lock_step_group`) under `options` (`group_options`, on the program's device)."""

    def __init__(self, members, group, options):
        self.members, self.group, self.options = members, group, options

    def __call__(self, scenario, ts, values):
        return self.group(self.members(scenario, values), ts, self.options)


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
