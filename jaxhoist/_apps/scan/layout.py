"""How a scan is laid out and run: `BatchOptions` (lanes, chunk size, memory cap, devices, sort order, the
wait for other processes), the solve order and the chunk size that follow from them, the scan's
`SolverOptions`."""

from __future__ import annotations

import math
from collections.abc import Sequence

import diffrax
import equinox as eqx
import numpy as np

from ..._errors import ScenarioError
from ..._numerics.batch import hist_shape
from ..._numerics.options import SolverOptions
from . import sweep as sweep_mod


def _as_tuple(devices) -> tuple | None:
    return None if devices is None else tuple(devices)


class BatchOptions(eqx.Module):
    """How a scan's members are laid out and run (none of these change a member's result, except `lanes`).

    - `lanes`: members solved together in one vmapped, lock-step solve (a numerical setting: results are
      independent of the chunk size and devices, not of `lanes`; XLA may round differently in a vmap of
      another width); capped at the number of members. Default (None): with adaptive steps on CPUs 16 to
      256, the width whose groups, shared out over the devices, cost least (`adaptive_lanes`: wide groups
      cost less per member, but wait for their slowest member, and every device should get a group); on
      accelerators (GPU, TPU) one group per device of up to 65 536 members; 256 with constant steps.
    - `chunk_size`: members per compiled call (rounded up to whole groups on every device); default (None):
      up to 8 groups per device, fewer if the saved histories would exceed `max_memory`.
    - `max_memory`: bytes of saved histories per chunk that the default chunk size keeps below [B].
    - `devices`: the JAX devices of this process to shard over (default None: all of `jax.local_devices()`).
    - `sort`: solve members in order of their parameter values (cuts lock-step waste; no effect on results
      beyond the grouping).
    - `wait_timeout`: with several processes (`jax.distributed`), how long a process waits for another's
      chunk file [s].

    **Raises** `ScenarioError` for `lanes` or `chunk_size` below 1 or a non-positive `max_memory` or
    `wait_timeout`.
    """

    lanes: int | None = eqx.field(default=None, static=True)
    chunk_size: int | None = eqx.field(default=None, static=True)
    max_memory: float = eqx.field(default=1e9, static=True)
    devices: tuple | None = eqx.field(default=None, static=True, converter=_as_tuple)
    sort: bool = eqx.field(default=True, static=True)
    wait_timeout: float = eqx.field(default=24 * 3600.0, static=True)

    def __check_init__(self):
        for name in ("lanes", "chunk_size"):
            v = getattr(self, name)
            if v is not None and int(v) < 1:
                raise ScenarioError(f"{name} must be >= 1, got {v}")
        for name in ("max_memory", "wait_timeout"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0):
                raise ScenarioError(f"{name} must be a positive number, got {v}")

    def lanes_for(self, options: SolverOptions, n: int, devices: tuple = ()) -> int:
        """The group width for `n` members on `devices`: `lanes` if given, else 256 with constant steps and
        `adaptive_lanes(n, len(devices), accelerator)` with adaptive ones (`accelerator`: every device is a
        GPU or TPU); capped at the next power of two >= n."""
        if self.lanes is not None:
            lanes = int(self.lanes)
        elif options.fixed_step:
            lanes = 256
        else:
            accelerator = bool(devices) and all(d.platform != "cpu" for d in devices)
            lanes = adaptive_lanes(n, max(1, len(devices)), accelerator=accelerator)
        return int(min(lanes, 1 << max(0, math.ceil(math.log2(n)))))


#: Bounds of the default group width with adaptive steps on CPUs (powers of two).
ADAPTIVE_LANES = (16, 256)
#: The cost of one lock-step iteration of a group that does not grow with its width, in members' worth
#: (a vmapped step of L members on a CPU costs about (STEP_OVERHEAD + L) times a member's share).
STEP_OVERHEAD = 48
#: The default group width with adaptive steps on accelerators (GPU, TPU): one group up to this many members.
ACCELERATOR_LANES = 65536


def adaptive_lanes(n: int, n_devices: int = 1, accelerator: bool = False) -> int:
    """The default group width of an adaptive scan of `n` members on `n_devices` devices.

    On CPUs: the power of two in `ADAPTIVE_LANES` for which the scan's groups, shared out over the
    devices, cost least, counting a group's lock-step iteration as `STEP_OVERHEAD` + its width; the
    narrower of equal costs (4096 members: 256 lanes on one device or two; 512: 256 on two; 256: 128 on
    two, 256 on one; 64: 32 on two, 64 on one). On accelerators (GPU, TPU): one group per device, up to
    `ACCELERATOR_LANES` members (the whole scan in one group on one device).

    Why: a vmapped step costs far less per member in a wide group (the per-kernel cost of the small
    per-member systems is shared), but a group takes as many steps as its slowest member, and a group runs
    on one device, so a scan of fewer groups than devices leaves devices idle. The width that keeps every
    device busy with the widest groups wins: 256 members of paper-4.2 over 25 s on two CPU devices cost
    0.97x the CPU time per trajectory of 4096 members in 2 groups of 128, against 1.57x in 16 groups of 16
    (`experiments/benchmarks/bench_scan_sizes.py --compare-lanes 16`, on a shared machine under load).
    The lock-step waste of wide groups is small where neighbours take about the same steps, as in a
    sorted scan of one parameter; a sparse scan of few, far-apart members loses some of the gain (64
    members over μ = 0.1-0.6 in one group of 64:
    1.25x the cost of groups of 16 at a lock-step efficiency of 0.39, with an earlier solver whose steps
    varied more), and so does a stiff friction law, whose members' steps spread (256 members at ε = 1e-4
    m/s: steps median 1 712, max 6 250; 3.2x the cost per trajectory of ε = 1e-3 in the default groups of
    128, 1.6x in groups of 32, docs/performance.md). The width is a numerical setting (XLA may round
    differently in a vmap of another width), and the default follows the device count: pin
    `BatchOptions(lanes=...)` for results that are the same bit for bit on any number of devices.
    On a GPU a step's kernels cost about the same for a few hundred members as for tens of thousands (they
    are bound by launches, not arithmetic), so groups run one after another waste the chip: one group, even
    at the lock-step efficiency of a whole scan, wins (docs/performance.md, "On a GPU").
    """
    if accelerator:  # one group per device
        per_device = math.ceil(n / max(1, n_devices))
        return (
            ACCELERATOR_LANES
            if n_devices <= 1
            else min(ACCELERATOR_LANES, 1 << math.ceil(math.log2(per_device)))
        )
    lo, hi = ADAPTIVE_LANES
    best, lanes = None, lo
    while lanes <= hi:
        rounds = math.ceil(math.ceil(n / lanes) / max(1, n_devices))
        cost = rounds * (STEP_OVERHEAD + lanes)
        if best is None or cost < best[0]:
            best = (cost, lanes)
        lanes *= 2
    assert best is not None
    return best[1]


def scan_solver_options(options: SolverOptions | None, derivatives: bool) -> SolverOptions:
    """The scan's `SolverOptions`: `options`, or the default `SolverOptions()` (the Rosenbrock-W solver); with
    `derivatives`, forward mode (`diffrax.ForwardMode`), in which the W solver integrates the sensitivities
    as their own error-controlled ODE (`_numerics/sensitivity.py`; differentiating the steps of an
    explicit solver such as Tsit5 gives sensitivities that grow without bound over 25 s of paper-4.2)."""
    if options is None:
        options = SolverOptions()
    elif not isinstance(options, SolverOptions):
        raise ScenarioError(f"options must be a jaxhoist.SolverOptions, got {type(options).__name__}")
    if derivatives and not options.forward_mode:
        options = options.replace(adjoint=diffrax.ForwardMode())
    return options


def order(scenario, paths: Sequence[str], members: np.ndarray, sort: bool):
    """Host-side validation and the solve order. **Returns** `(invalid {i: message}, order, rows to solve)`:
    invalid members are marked, and solved with a valid neighbour's values."""
    n = members.shape[0]
    invalid = sweep_mod.validate_members(scenario, paths, members)
    if len(invalid) == n:
        raise ScenarioError(f"every member of the scan is invalid; the first: {invalid[0]}")
    idx = np.lexsort(members.T[::-1]) if sort else np.arange(n)
    solve_rows = members.copy()
    if invalid:
        valid_sorted = [i for i in idx if i not in invalid]
        pos = {int(i): k for k, i in enumerate(idx)}
        vpos = np.array([pos[int(i)] for i in valid_sorted])
        for i in invalid:
            nearest = valid_sorted[int(np.argmin(np.abs(vpos - pos[i])))]
            solve_rows[i] = members[nearest]
    return invalid, idx, solve_rows


def chunk_size(n: int, lanes: int, n_dev: int, n_t: int, histories, batch: BatchOptions) -> int:
    """Members per chunk: whole groups of `lanes` on every device (see `apps.scan`'s module docstring)."""
    n_groups = math.ceil(n / lanes)
    hist_bytes = 8 * n_t * sum(int(np.prod(hist_shape(h))) for h in histories)
    if batch.chunk_size is None:
        per_dev = max(1, min(8, math.ceil(n_groups / n_dev)))
        mem_groups = max(1, int(batch.max_memory // max(1, (hist_bytes + 4096) * lanes * n_dev)))
        per_dev = min(per_dev, mem_groups)
    else:
        per_dev = max(1, math.ceil(int(batch.chunk_size) / (lanes * n_dev)))
    return per_dev * lanes * n_dev
