"""Parameter scans: many solves of one scenario with some float leaves swept, as one compiled, vmapped,
sharded computation per chunk, with per-member status, resumable chunk files and a progress report.

    import jaxhoist as jh
    sc = jh.load_scenario("paper-4.2")
    res = jh.scan(sc, jh.Sweep("foundation.friction_coefficient", np.linspace(0.1, 0.6, 4000)), 25.0,
                  observables=["final_psi", "liftoff_time"], out_dir="out/mu-scan", progress=True)
    res["final_psi"], res.status, res.coords["foundation.friction_coefficient"]

Where the parts live: the members (`scan.sweep`), the pure batch core (`numerics.batch`: a lock-step group of
`lanes` members, the groups of a chunk on each device, the devices in parallel), the chunk loop and the
assembly of the `ScanResult` (this module, `scan.result`), the files in `out_dir` (`io.scan_store`),
progress reports (`apps.scan.progress`).

How the work is laid out (and why results do not depend on the chunk size or the device count):

- members (parameter points) are sorted by their values, so that neighbours take similar numbers of
  steps, and split into *groups* of `lanes` consecutive members (the last one padded by repeating its
  last member). A group is solved in lock step, one while loop over its members that runs diffrax's step
  and step-size control for each (`numerics.lockstep`; with derivatives, one `jax.vmap` of the traceable
  core `numerics.solve.solve`): it costs what its slowest member costs, which sorting keeps close to the
  others;
- a *chunk* is a whole number of groups per device; on each device the chunk's groups run one after the
  other (calls of the one compiled group program), and the devices' shares run in parallel, one host
  thread each, so a slow group on one device does not hold up the other (`numerics.batch.CompiledChunk`);
- each group is the same single-device compiled computation on the same inputs whatever the chunk size
  and the number of devices (never a partitioned SPMD program, which rounds differently), so the results
  are bit-for-bit identical; a healthy member is also bit-for-bit what it is without a failing group mate.
- several processes (hosts) under `jax.distributed`: every process runs the chunks k with
  k mod process_count = process_index on its own local devices and writes them to `out_dir`, which must
  be a folder all processes share; then each reads the others' chunks and assembles the same result
  (process 0 writes `scan.npz`). No collective communication is needed.
- with constant steps (`SolverOptions(solver, diffrax.ConstantStepSize(), dt0=...)`) every member takes
  the same steps (`numerics.fixed_step`, a lean Runge-Kutta loop for diffrax's explicit tableaus): nothing
  waits in lock step, so groups can be wide (hundreds of lanes), which spreads the fixed cost of each loop
  iteration over many members.

(`lanes` is a numerical setting, like the tolerances: XLA may round differently in a vmap of another
width, so changing it can move results by about the solver tolerance.)

Failures are data: a member whose solve fails (step budget, non-finite state) gets its `ScanStatus` and
NaN observables, and every other member is computed exactly as in a clean scan. A member whose parameter
values are invalid (checked on the host, e.g. μ = NaN or a negative stiffness) is not solved: its status
is `INVALID_PARAMETER` and `ScanResult.reason(i)` gives the message.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._errors import ScenarioError, require_x64
from ..._io.scan_store import ScanStore, fingerprint
from ..._numerics import fixed_step as fixed_mod
from ..._numerics import observables as obs_mod
from ..._numerics.batch import (
    HISTORY_UNITS,
    BatchSpec,
    ScanStatus,
    compiled_chunk,
    describe_devices,
    flatten_out,
)
from ..._numerics.options import SolverOptions
from ..._numerics.solve import checked_scenario
from ..._numerics.times import Times, TimesLike, as_times
from ..._physics.params import Scenario
from ..._physics.paths import check_path, param_unit
from . import accuracy as accuracy_mod
from . import layout
from . import progress as progress_mod
from .accuracy import AccuracyCheck
from .layout import BatchOptions, scan_solver_options
from .progress import Progress
from .result import ScanResult
from .sweep import AbstractSweep, Grid, Points, Sweep, as_sweep

#: The number of saved times of `scan` when `Times.n` is None.
DEFAULT_N = 201

__all__ = [
    "AccuracyCheck",
    "BatchOptions",
    "Grid",
    "Points",
    "Progress",
    "ScanResult",
    "ScanStatus",
    "Sweep",
    "scan",
]


def scan(
    scenario: Scenario,
    sweep: AbstractSweep | Mapping[str, Any] | None = None,
    times: TimesLike = None,
    *,
    observables=None,
    options: SolverOptions | None = None,
    histories: Sequence[str] = (),
    derivatives: bool = False,
    batch: BatchOptions | None = None,
    out_dir: str | Path | None = None,
    resume: bool = True,
    progress: bool | Callable[[Progress], None] | None = None,
    accuracy: AccuracyCheck | bool | None = None,
) -> ScanResult:
    """Solve `scenario` for many values of some of its float leaves and evaluate observables of each solve.

    **Arguments**
    - `scenario`: the base `Scenario`.
    - `sweep`: the members: `Sweep(path, values)` (one parameter), `Grid({path: values, ...})` (every
      combination: one data axis per parameter) or `Points({path: values, ...})` (equally long lists
      zipped together: one data axis); a plain mapping `{path: values}` is a `Sweep` for one parameter and
      a `Grid` for several. A path is a dotted field name, with `[i]` for one component of a vector leaf:
      `"foundation.friction_coefficient"`, `"hoist.speed"`, `"load.mass_centre[0]"`. Values are
      array-like or a string `"start:stop:num"` / `"v1,v2,..."`; units are those of the field (SI).
    - `times`: the saved times, a `Times(t1, n, ts)`: end time t1 [s] (default `scenario.t1`), `n` equally
      spaced times from 0 to t1 (default 201) or the saved times `ts` [s] starting at 0; observables such
      as event times are interpolated on this grid. A number is t1 [s], a 1-D array is ts [s].
    - `observables`: names of built-in observables (`jaxhoist._numerics.observables`), callables
      `fn(traj[, scenario])`, `Observable`s, or a dict name -> any of these.
    - `options`: `SolverOptions` (solver, step-size controller, dt0, step budget: one for every member);
      default `SolverOptions()` (Rosenbrock-W; with `derivatives` in forward mode).
      Constant steps (`SolverOptions(solver, diffrax.ConstantStepSize(), dt0=...)`) with an explicit
      Runge-Kutta solver (e.g. `diffrax.Bosh3()`) run the lean loop of `numerics.fixed_step` (same numbers
      as diffrax's `ConstantStepSize` to round-off when the saved times are multiples of `dt0`; other
      solvers use diffrax's); every member takes the same steps. Check the accuracy against an adaptive
      solve (`experiments/benchmarks/benchmark_scan.py` does; see docs/performance.md).
    - `histories`: `Trajectory` fields to keep at every saved time, e.g. `("position", "euler")`.
    - `derivatives`: also compute forward-mode sensitivities of every observable with respect to the swept
      parameters (forward mode, through `diffrax.ForwardMode` or the fixed-step loop), stored as `d_<name>`
      with a last axis over the parameters [unit of the observable per unit of the parameter]. Through the
      default Rosenbrock-W solver each member's state and its sensitivities are solved together, as one
      error-controlled system (`numerics/sensitivity.py`), and the values are that solve's: they agree with
      a scan without derivatives to the solver's tolerance, not bit for bit (with several parameters, one
      such solve per parameter, the values from the first). With fixed steps, or another solver, the steps
      are differentiated and the values are the plain scan's.
    - `batch`: `BatchOptions` (lanes, chunk size, memory cap [B], devices, sort order, wait for other
      processes [s]); default `BatchOptions()`.
    - `out_dir`: write each finished chunk there (`chunk_#####.npz` + `manifest.json`) and the final
      `scan.npz` + `scan.json` and the same dataset as netCDF, `scan.nc`; with `resume=True` an
      interrupted scan continues from the chunks on disk.
    - Several processes: after `jax.distributed.initialize(...)` on every host, call `scan` with the same
      arguments in each process and an `out_dir` on a shared file system; the chunks are shared out
      between the processes, and every process returns the whole result.
    - `progress`: True to print a line per chunk on stderr, or a callable receiving a `Progress`.
    - `accuracy`: an `AccuracyCheck`: re-solve a subset of the healthy members (16 by default: the 8 with
      the most solver steps and 8 drawn at random, seeded; 16 more, the next by step count, while the
      largest difference is within 4x of its target, up to 64) at a 1000x tighter tolerance, as a small
      `Points` scan, and report the differences of every observable and kept history (median, max, members
      over 1 cm for lengths, over 1 % relative for the others) in `ScanResult.accuracy` and `scan.json`.
      Default (None): on for scans of 1024 members or more (`scan.accuracy.AUTO_MIN_MEMBERS`; it costs
      about 6x the time of the members it re-solves, plus one compile), off below; True: `AccuracyCheck()`;
      False: off.

    **Returns** a `ScanResult`.

    **Raises** `ScenarioError` for invalid paths, values or options (before compiling); a member with an
    invalid value is marked `INVALID_PARAMETER` instead, unless every member is invalid.
    """
    require_x64()
    if sweep is None:
        raise TypeError("scan() missing the sweep: Sweep(path, values), Grid({...}) or Points({...})")
    return _scan(
        scenario,
        as_sweep(sweep),
        as_times(times),
        observables=observables,
        options=scan_solver_options(options, derivatives),
        histories=histories,
        derivatives=bool(derivatives),
        batch=BatchOptions() if batch is None else batch,
        out_dir=out_dir,
        resume=resume,
        progress=progress,
        accuracy=accuracy,
    )


def _scan(
    scenario: Scenario,
    sweep: AbstractSweep,
    times: Times,
    *,
    observables,
    options: SolverOptions,
    histories,
    derivatives: bool,
    batch: BatchOptions,
    out_dir,
    resume: bool,
    progress,
    accuracy: AccuracyCheck | bool | None = None,
) -> ScanResult:
    """`scan` with every choice an object (the sweep, the saved times, the solver options with forward mode
    if `derivatives`, the batch options): the entry point for the package's own callers."""
    wall0 = time.perf_counter()
    scenario, coords, shape, members, obs, histories, ts, (invalid, order, solve_rows) = _checked(
        scenario, sweep, times, observables, options, histories, batch
    )
    paths = tuple(coords)
    devs = tuple(jax.local_devices() if batch.devices is None else batch.devices)
    n_proc, proc = jax.process_count(), jax.process_index()
    if n_proc > 1 and out_dir is None:
        raise ScenarioError(
            f"this is process {proc} of {n_proc} (jax.distributed): a scan over several processes needs "
            f"out_dir, a folder on a file system that all of them share"
        )
    n = members.shape[0]
    check = accuracy_mod.resolve(accuracy, n)
    lanes = batch.lanes_for(options, n, devs)
    chunk = layout.chunk_size(n, lanes, len(devs), len(ts), histories, batch)
    spec = BatchSpec(
        paths=paths,
        observables=obs,
        histories=histories,
        options=options,
        lanes=lanes,
        devices=devs,
        derivatives=derivatives,
    )
    fp = _fingerprint(scenario, spec, members, ts, batch.sort)
    store, done_chunks = None, {}
    if out_dir is not None:
        store = ScanStore(out_dir, fp, proc=proc, n_proc=n_proc, wait_timeout=batch.wait_timeout)
        header = {
            "n_members": n,
            "params": list(paths),
            "mode": sweep.mode,
            "t1": float(ts[-1]),
            "lanes": lanes,
        }
        chunk, done_chunks = store.open(order, chunk, header, resume)
    # the compiled chunks get the scenario without its labels: one program for any scenario's labels
    run = _Run(spec, scenario.unlabelled(), ts, solve_rows, order, chunk, store, done_chunks, wall0)
    flat, timings = run.chunks(progress_mod.resolve(progress))
    result = _assemble(
        scenario,
        spec,
        flat,
        order,
        invalid,
        mode=sweep.mode,
        coords=coords,
        shape=shape,
        ts=ts,
        attrs={
            "scenario": scenario.name,
            "t1": float(ts[-1]),
            "n_save": int(len(ts)),
            "solver": options.describe(),
            "lanes": lanes,
            "chunk_size": chunk,
            "devices": [str(d) for d in devs],
            "chunk_devices": {str(k): run.chunk_devices[k] for k in sorted(run.chunk_devices)},
            "sorted": bool(batch.sort),
            "timings_s": {**timings, "total": round(time.perf_counter() - wall0, 4)},
            "group_program": run.program,
            "fingerprint": fp,
        },
    )
    if check is not None:
        t_check = time.perf_counter()
        result.attrs["accuracy"] = accuracy_mod.check_accuracy(
            result,
            check,
            scenario=scenario,
            ts=ts,
            observables=obs,
            options=options,
            run_scan=lambda sc, sw, t, *, observables, options, histories: _scan(
                sc,
                sw,
                t,
                observables=observables,
                options=options,
                histories=histories,
                derivatives=False,
                batch=BatchOptions(devices=batch.devices),
                out_dir=None,
                resume=False,
                progress=None,
                accuracy=False,
            ),
        )
        result.attrs["timings_s"]["accuracy"] = round(time.perf_counter() - t_check, 4)
        result.attrs["timings_s"]["total"] = round(time.perf_counter() - wall0, 4)
    if store is not None and proc == 0:
        store.finish(run.chunk_devices)
        result.save(store.out / "scan")
        result.to_netcdf(store.out / "scan.nc")
    return result


def _checked(
    scenario, sweep: AbstractSweep, times: Times, observables, options: SolverOptions, histories, batch
):
    """The host-side checks of `_scan`, before anything is compiled or written: the scenario, the swept
    paths, the observables and histories, the saved times against a constant step's budget, and each
    member's values (`layout.order`: refused where every member is invalid). **Returns** `(scenario
    checked, coords, shape, members, observables, histories, ts, (invalid, order, solve_rows))`.
    **Raises** `ScenarioError` naming what is wrong."""
    if not isinstance(batch, BatchOptions):
        raise ScenarioError(f"batch must be a jaxhoist.BatchOptions, got {type(batch).__name__}")
    scenario = checked_scenario(scenario)
    coords, shape, members = dict(sweep.values), sweep.shape, sweep.members()
    for p in coords:
        check_path(scenario, p)
    obs, histories = _observables(observables, histories)
    _, ts = times.resolve(scenario, DEFAULT_N)
    _check_fixed_steps(options, ts)
    ts = jnp.asarray(ts, dtype=jnp.float64)
    laid_out = layout.order(scenario, tuple(coords), members, batch.sort)
    return scenario, coords, shape, members, obs, histories, ts, laid_out


def check_inputs(
    scenario: Scenario,
    sweep: AbstractSweep,
    times: Times,
    *,
    observables,
    options: SolverOptions,
    histories,
    batch: BatchOptions,
    accuracy: AccuracyCheck | bool | None = None,
) -> None:
    """Every check that `scan` makes of these arguments before it compiles or writes anything, and nothing
    else (nothing is solved or written): the command line runs it before it claims its output folder, so
    that a refused scan leaves an earlier scan's results there in place. **Raises** `ScenarioError` naming
    what is wrong."""
    members = _checked(scenario, sweep, times, observables, options, histories, batch)[3]
    accuracy_mod.resolve(accuracy, members.shape[0])


def _check_fixed_steps(options: SolverOptions, ts) -> None:
    """Refuse constant steps of `dt0` that need more than `max_steps` steps to reach the last saved time."""
    if options.fixed_step and fixed_mod.supports(options.solver):
        dt0, max_steps = options.dt0, options.max_steps
        need = fixed_mod.steps_needed(ts, dt0)  # pyright: ignore[reportArgumentType]  # fixed_step checks dt0
        if need > int(max_steps):
            raise ScenarioError(
                f"fixed steps of dt0 = {dt0} s to t1 = {float(np.asarray(ts)[-1])} s need {need} steps, more "
                f"than max_steps = {max_steps}: raise max_steps or dt0"
            )


def _observables(observables, histories) -> tuple[tuple, tuple[str, ...]]:
    """The resolved `Observable`s and the checked history names."""
    try:
        obs = obs_mod.resolve(observables)
    except (ValueError, TypeError) as e:
        raise ScenarioError(str(e)) from None
    histories = (histories,) if isinstance(histories, str) else tuple(histories)  # one name, or several
    for h in histories:
        if h not in HISTORY_UNITS:
            raise ScenarioError(
                f"history {h!r} is not a Trajectory output; choose from {sorted(HISTORY_UNITS)}"
            )
    return tuple(obs), histories


def _settings(spec: BatchSpec, sort: bool) -> tuple:
    """The plain settings that enter the store's fingerprint (with the scenario, values, times, code)."""
    o = spec.options
    return (
        spec.paths,
        spec.histories,
        spec.lanes,
        sort,
        # the solver's and the controller's fields that differ from their defaults (no memory addresses:
        # functions print by name), so that e.g. `RosenbrockW(time_derivative=False)` or other PI
        # coefficients at the same tolerances do not reuse the chunks of another setting
        eqx.tree_pformat(o.solver),
        eqx.tree_pformat(o.stepsize_controller),
        o.rtol,
        o.atol,
        o.dt0,
        o.max_steps,
        spec.derivatives,
    ) + ((("fixed_step", o.fixed_step),) if o.fixed_step else ())


def _fingerprint(scenario, spec: BatchSpec, members, ts, sort: bool) -> str:
    """The store's fingerprint of this scan (the same in every process)."""
    functions = [(o.name, o.fn) for o in spec.observables]
    return fingerprint(scenario, members, ts, _settings(spec, sort), functions)


@dataclasses.dataclass
class _Run:
    """The chunk loop of one scan: compute (or read back, or wait for) every chunk, report progress."""

    spec: BatchSpec
    scenario: Scenario
    ts: Any
    solve_rows: np.ndarray
    order: np.ndarray
    chunk: int
    store: ScanStore | None
    done_chunks: dict
    wall0: float
    chunk_devices: dict = dataclasses.field(default_factory=dict)
    compile_time: float = 0.0
    compute_time: float = 0.0
    computed: int = 0
    program: str | None = None  # how the group program was made: "compiled", "loaded", "reused"

    def _here(self) -> list[str]:
        """Which devices computed a chunk: this run's, named by process with several."""
        here = describe_devices(self.spec.devices)
        if jax.process_count() == 1:
            return here
        return [f"process {jax.process_index()}: {d}" for d in here]

    def _compute(self, k: int, idx: np.ndarray) -> dict[str, np.ndarray]:
        """Solve chunk k (members `idx`), in groups of `lanes`, padded to whole groups on every device."""
        lanes, n_dev = self.spec.lanes, len(self.spec.devices)
        # Groups per compiled call: the chunk's, rounded up to a multiple of the device count (a chunk laid
        # out by a resumed run with fewer devices); the extra groups are inactive and cost nothing.
        groups = math.ceil(self.chunk // lanes / n_dev) * n_dev
        rows = self.solve_rows[idx]
        pad = groups * lanes - rows.shape[0]
        rows_p = np.concatenate([rows, np.repeat(rows[-1:], pad, axis=0)]) if pad else rows
        active = np.arange(groups) < math.ceil(rows.shape[0] / lanes)
        vals = rows_p.reshape(groups, lanes, len(self.spec.paths))
        t_start = time.perf_counter()
        # one compiled group serves any number of groups (`numerics.batch.CompiledChunk`)
        fn, dt, how = compiled_chunk(self.spec, self.scenario, self.ts, vals, active)
        if self.program is None:
            self.program = how
        if dt:
            self.compile_time += dt
            t_start = time.perf_counter()
        res = flatten_out(jax.block_until_ready(fn(self.scenario, self.ts, vals, active)), rows.shape[0])
        self.computed += rows.shape[0]
        self.compute_time += time.perf_counter() - t_start
        if self.store is not None:
            lo = k * self.chunk
            record = {
                "members": [lo, lo + rows.shape[0]],
                "devices": self._here(),
                "wall_s": round(time.perf_counter() - t_start, 4),
            }
            self.store.write(k, res, idx, record)
        return res

    def chunks(self, report) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Every chunk's arrays, concatenated in solve order, and the timings."""
        n, chunk = self.order.shape[0], self.chunk
        n_chunks = math.ceil(n / chunk)
        n_proc, proc = jax.process_count(), jax.process_index()
        resumed = set(self.done_chunks)
        results, failed = {}, 0
        for k in range(n_chunks):
            idx = self.order[k * chunk : min(n, (k + 1) * chunk)]
            loaded = k in self.done_chunks
            if not loaded and k % n_proc != proc:  # another process's chunk: wait for its file
                assert self.store is not None  # several processes need out_dir (checked in scan)
                self.done_chunks[k] = self.store.chunk(k, idx)
                loaded = True
            results[k] = self.done_chunks[k] if loaded else self._compute(k, idx)
            if not loaded:
                self.chunk_devices[k] = self._here()
            elif k % n_proc != proc and k not in resumed:
                self.chunk_devices[k] = [f"process {k % n_proc}"]
            else:
                assert self.store is not None
                self.chunk_devices[k] = self.store.recorded_devices(k)
            failed += int(np.sum(results[k]["status"] != 0))
            if report is not None:
                report(self._progress(k, n_chunks, loaded, failed))
        flat = {key: np.concatenate([results[k][key] for k in range(n_chunks)]) for key in results[0]}
        timings = {
            "compile": round(self.compile_time, 4),
            "compute": round(self.compute_time, 4),
            "members_computed": self.computed,
        }
        return flat, timings

    def _progress(self, k: int, n_chunks: int, loaded: bool, failed: int) -> Progress:
        n, chunk = self.order.shape[0], self.chunk
        rate = self.computed / self.compute_time if self.compute_time > 0 else None
        remaining = sum(
            min(n, (j + 1) * chunk) - j * chunk for j in range(k + 1, n_chunks) if j not in self.done_chunks
        )
        eta = remaining / rate if rate else (0.0 if remaining == 0 else None)
        return Progress(
            chunk=k,
            n_chunks=n_chunks,
            done=min(n, (k + 1) * chunk),
            total=n,
            elapsed=time.perf_counter() - self.wall0,
            eta=eta,
            rate=rate,
            loaded=loaded,
            compile_time=self.compile_time,
            failed=failed,
        )


def _masked(flat, key: str, bad: np.ndarray, shape: tuple) -> np.ndarray:
    v = flat[key].astype(np.float64)
    v[bad] = np.nan
    return v.reshape(*shape, *v.shape[1:])


def _assemble(
    scenario, spec: BatchSpec, flat, order, invalid, *, mode, coords, shape, ts, attrs
) -> ScanResult:
    """The `ScanResult` in the original member order: failed members NaN, with units and descriptions."""
    n = order.shape[0]
    inv = np.empty(n, dtype=np.int64)
    inv[order] = np.arange(n)
    flat = {key: v[inv] for key, v in flat.items()}
    status = flat["status"].astype(np.int32)
    reasons: dict[int, str] = {}
    for i, msg in invalid.items():
        status[i] = ScanStatus.INVALID_PARAMETER
        reasons[i] = msg
    bad = status != ScanStatus.OK
    obs, paths = spec.observables, spec.paths
    data = {o.name: _masked(flat, f"obs:{o.name}", bad, shape) for o in obs}
    if spec.derivatives:
        data.update({f"d_{o.name}": _masked(flat, f"obs:d_{o.name}", bad, shape) for o in obs})
    hist = {h: _masked(flat, f"hist:{h}", bad, shape) for h in spec.histories}
    for i in np.flatnonzero(bad):
        if int(i) not in reasons:
            reasons[int(i)] = ScanStatus(int(status[i])).message
    units = {p: param_unit(scenario, p) for p in paths}
    units.update({o.name: o.unit for o in obs})
    units.update({h: HISTORY_UNITS[h] for h in spec.histories})
    descriptions = {o.name: o.description for o in obs}
    components = {o.name: o.components for o in obs}
    if spec.derivatives:
        for o in obs:
            units[f"d_{o.name}"] = " | ".join(f"{o.unit} per {units[p]}" for p in paths)
            descriptions[f"d_{o.name}"] = (
                f"forward-mode sensitivity of {o.name} to each swept parameter "
                f"(last axis: {', '.join(paths)})"
            )
            components[f"d_{o.name}"] = paths
    return ScanResult(
        params=paths,
        mode=mode,
        coords=coords,
        shape=shape,
        data=data,
        components=components,
        status=status.reshape(shape),
        reasons=reasons,
        num_accepted_steps=flat["num_accepted_steps"].reshape(shape),
        num_rejected_steps=flat["num_rejected_steps"].reshape(shape),
        ts=np.asarray(ts),
        histories=hist,
        units=units,
        descriptions=descriptions,
        attrs=attrs,
    )
