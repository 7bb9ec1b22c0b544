"""Parameter scans: many solves of one scenario with some float leaves swept, as one compiled, vmapped,
sharded computation per chunk, with per-member status, resumable chunk files and a progress report.

    import jaxhoist as jh
    sc = jh.load_scenario("paper-4.2")
    res = jh.scan(sc, {"foundation.friction_coefficient": np.linspace(0.1, 0.6, 4000)}, 25.0,
                  observables=["final_psi", "liftoff_time"], out_dir="out/mu-scan", progress=True)
    res["final_psi"], res.status, res.coords["foundation.friction_coefficient"]

How the work is laid out (and why results do not depend on the chunk size or the device count):

- members (parameter points) are sorted by their values, so that neighbours take similar numbers of
  steps, and split into *groups* of `lanes` consecutive members (the last one padded by repeating its
  last member). A group is solved by one `jax.vmap` of the traceable core `numerics.solve.solve`, in lock
  step: it costs what its slowest member costs, which sorting keeps close to the others;
- a *chunk* is a whole number of groups per device; on each device the chunk's groups run one after the
  other (`lax.map`), and the devices (a 1-D mesh over `jax.devices()`, via `shard_map`) run in parallel,
  each with its own loop, so a slow group on one device does not hold up the other;
- each group is the same compiled computation on the same inputs whatever the chunk size and the number
  of devices, so the results are bit-for-bit identical.
- several processes (hosts) under `jax.distributed`: every process runs the chunks k with
  k mod process_count = process_index on its own local devices and writes them to `out_dir`, which must
  be a folder all processes share; then each reads the others' chunks and assembles the same result
  (process 0 writes `scan.npz`). No collective communication is needed.
- with `fixed_step=True` every member takes the same constant steps (`numerics.fixed_step`, a lean
  Runge-Kutta loop for diffrax's explicit tableaus): nothing waits in lock step, so groups can be wide
  (hundreds of lanes), which spreads the fixed cost of each loop iteration over many members.

(`lanes` is a numerical setting, like the tolerances: XLA may round differently in a vmap of another
width, so changing it can move results by about the solver tolerance.)

Failures are data: a member whose solve fails (step budget, non-finite state) gets its `ScanStatus` and
NaN observables, and every other member is computed exactly as in a clean scan. A member whose parameter
values are invalid (checked on the host, e.g. μ = NaN or a negative stiffness) is not solved: its status
is `INVALID_PARAMETER` and `ScanResult.reason(i)` gives the message.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import sys
import time
import types
import warnings
import zipfile
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import ScenarioError, require_x64
from ..physics.params import Scenario, get_leaf
from . import fixed_step as fixed_mod
from .batch import HISTORY_UNITS as _HISTORY_UNITS
from .batch import BatchSpec as _Spec
from .batch import ScanStatus as ScanStatus
from .batch import chunk_fn as _chunk_fn
from .batch import flatten_out as _flatten_out
from .batch import hist_shape as _hist_shape
from .options import SolverOptions
from .paths import _getter
from .paths import check_path as check_path
from .paths import get_param as get_param
from .paths import param_unit as param_unit
from .paths import parse_path as parse_path
from .paths import set_param as set_param
from .solve import saved_times

FORMAT = "jaxhoist-scan/1"
MANIFEST = "manifest.json"


# ------------------------------------------------------------------------------------ parameter paths

def parse_values(spec) -> np.ndarray:
    """Values of a swept parameter: an array-like, or a string `"start:stop:num"` (inclusive, like
    `numpy.linspace`) or `"v1,v2,..."`."""
    if isinstance(spec, str):
        s = spec.strip()
        try:
            if ":" in s:
                a, b, n = s.split(":")
                if int(n) < 1:
                    raise ValueError
                return np.linspace(float(a), float(b), int(n))
            return np.array([float(x) for x in s.split(",") if x.strip()])
        except ValueError:
            raise ScenarioError(
                f"parameter values {spec!r}: expected 'start:stop:num' or 'v1,v2,...'"
            ) from None
    a = np.asarray(spec, dtype=np.float64)
    if a.ndim == 0:
        a = a[None]
    if a.ndim != 1:
        raise ScenarioError(f"parameter values must be 1-D, got shape {a.shape}")
    return a


def _members(params: Mapping[str, Any], mode: str | None):
    """-> (mode, coords, shape, member values (n, P))."""
    names = list(params)
    if not names:
        raise ScenarioError("scan needs at least one parameter to sweep")
    vals = [parse_values(params[p]) for p in names]
    for p, v in zip(names, vals, strict=True):
        if v.size == 0:
            raise ScenarioError(f"scan parameter {p!r} has no values")
    if mode is None:
        mode = "sweep" if len(names) == 1 else None
    if mode == "sweep":
        if len(names) != 1:
            raise ScenarioError(
                f"mode='sweep' sweeps one parameter, got {len(names)}: use mode='grid' "
                f"(every combination) or mode='points' (zipped lists)"
            )
        return mode, {names[0]: vals[0]}, (vals[0].size,), vals[0][:, None]
    if mode == "grid":
        mesh = np.meshgrid(*vals, indexing="ij")
        return (
            mode,
            dict(zip(names, vals, strict=True)),
            tuple(v.size for v in vals),
            np.stack([m.ravel() for m in mesh], axis=1),
        )
    if mode == "points":
        n = {v.size for v in vals}
        if len(n) != 1:
            raise ScenarioError(
                f"mode='points' needs equally long value lists, got lengths "
                f"{dict(zip(names, [v.size for v in vals], strict=True))}"
            )
        return mode, dict(zip(names, vals, strict=True)), (vals[0].size,), np.stack(vals, axis=1)
    if mode is None:
        raise ScenarioError(
            "several parameters: say mode='grid' (every combination) or mode='points' (zipped)"
        )
    raise ScenarioError(f"mode must be 'sweep', 'grid' or 'points', got {mode!r}")


def _validate_members(scenario: Scenario, paths: Sequence[str], members: np.ndarray) -> dict[int, str]:
    """Host-side check of every member's parameter values. Returns {member index: error message}."""

    def check(rows: np.ndarray) -> None:
        sc = scenario
        for k, p in enumerate(paths):
            dotted, index = parse_path(p)
            leaf = np.asarray(get_leaf(scenario, dotted))
            if index is None:
                new = rows[:, k]
            else:
                new = np.broadcast_to(leaf, (rows.shape[0], *leaf.shape)).copy()
                new[:, index] = rows[:, k]
            sc = eqx.tree_at(_getter(dotted), sc, jnp.asarray(new))
        sc.check()

    bad: dict[int, str] = {}
    try:
        check(members)  # every member at once: the checks broadcast over a leading axis
        return bad
    except ScenarioError:
        pass
    for i in range(members.shape[0]):
        try:
            check(members[i : i + 1])
        except ScenarioError as e:
            bad[i] = str(e)
    return bad


# ---------------------------------------------------------------------------------------- the core


# ------------------------------------------------------------------------------------------ results


def _json_default(x):
    if isinstance(x, np.ndarray | np.generic):
        return x.tolist()
    return repr(x)


class ScanResult:
    """A labelled scan dataset: parameter coordinates × observables (× optional time histories).

    - `params`: the swept parameter paths, in order; `mode`: "sweep", "grid" or "points".
    - `coords`: path -> values. For a grid, the axis values (the data have one axis per parameter);
      otherwise the value of that parameter for each member (one data axis).
    - `shape`: the shape of the member axes.
    - `data`: observable name -> array of shape `shape + observable shape` (NaN where a member failed).
    - `components`: observable name -> labels of its last axis (or None).
    - `status`: `ScanStatus` codes, shape `shape`; `reasons`: flat member index -> message for failures.
    - `num_accepted_steps`, `num_rejected_steps`: solver steps per member.
    - `ts`, `histories`: saved times [s] and name -> array of shape `shape + (n_t, ...)` if requested.
    - `units`: name -> SI unit for every parameter, observable and history; `descriptions` likewise.
    - `attrs`: JSON-able metadata (scenario, t1, solver options, lanes, devices, timings).
    """

    def __init__(
        self,
        *,
        params,
        mode,
        coords,
        shape,
        data,
        components,
        status,
        reasons,
        num_accepted_steps,
        num_rejected_steps,
        ts,
        histories,
        units,
        descriptions,
        attrs,
    ):
        self.params = tuple(params)
        self.mode = mode
        self.coords = {k: np.asarray(v) for k, v in coords.items()}
        self.shape = tuple(shape)
        self.data = {k: np.asarray(v) for k, v in data.items()}
        self.components = dict(components)
        self.status = np.asarray(status)
        self.reasons = {int(k): str(v) for k, v in reasons.items()}
        self.num_accepted_steps = np.asarray(num_accepted_steps)
        self.num_rejected_steps = np.asarray(num_rejected_steps)
        self.ts = None if ts is None else np.asarray(ts)
        self.histories = {k: np.asarray(v) for k, v in (histories or {}).items()}
        self.units = dict(units)
        self.descriptions = dict(descriptions)
        self.attrs = dict(attrs)

    # ---- access
    def __getitem__(self, name: str) -> np.ndarray:
        if name in self.data:
            return self.data[name]
        if name in self.histories:
            return self.histories[name]
        if name in self.params:
            return self.values(name)
        raise KeyError(
            f"{name!r}: not an observable, history or parameter of this scan "
            f"(observables {list(self.data)}, histories {list(self.histories)})"
        )

    def values(self, path: str) -> np.ndarray:
        """The value of parameter `path` for every member, shape `shape`."""
        if self.mode != "grid":
            return self.coords[path]
        axes = [self.coords[p] for p in self.params]
        return np.meshgrid(*axes, indexing="ij")[self.params.index(path)]

    @property
    def ok(self) -> np.ndarray:
        """True where the member was solved and every observable is defined."""
        return self.status == ScanStatus.OK

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def reason(self, i) -> str:
        """Why member i (flat index, or an index tuple for a grid) failed ("ok" if it did not)."""
        flat = int(np.ravel_multi_index(i, self.shape)) if isinstance(i, tuple) else int(i)
        code = ScanStatus(int(self.status.ravel()[flat]))
        return self.reasons.get(flat, code.message)

    def failures(self) -> list[dict[str, Any]]:
        """One dict per failed member: flat index, parameter values, status name and reason."""
        out = []
        for flat in np.flatnonzero(self.status.ravel() != ScanStatus.OK):
            out.append(
                {
                    "index": int(flat),
                    "params": {p: float(self.values(p).ravel()[flat]) for p in self.params},
                    "status": ScanStatus(int(self.status.ravel()[flat])).name.lower(),
                    "reason": self.reason(int(flat)),
                }
            )
        return out

    def __repr__(self) -> str:
        n_fail = int(np.sum(~self.ok))
        return (
            f"ScanResult(mode={self.mode!r}, params={list(self.params)}, shape={self.shape}, "
            f"observables={list(self.data)}, histories={list(self.histories)}, failed={n_fail})"
        )

    # ---- files
    def _arrays(self) -> tuple[dict[str, np.ndarray], dict[str, tuple[str, str]]]:
        arrays: dict[str, np.ndarray] = {}
        units: dict[str, tuple[str, str]] = {}
        for p in self.params:
            arrays[f"coord:{p}"] = self.coords[p]
            units[f"coord:{p}"] = (self.units.get(p, "?"), f"swept parameter {p}")
        for k, v in self.data.items():
            arrays[f"obs:{k}"] = v
            units[f"obs:{k}"] = (self.units.get(k, "?"), self.descriptions.get(k, ""))
        for k, v in self.histories.items():
            arrays[f"hist:{k}"] = v
            units[f"hist:{k}"] = (self.units.get(k, "?"), f"time history of {k} at the saved times ts")
        arrays["status"] = self.status
        units["status"] = ("-", "ScanStatus: " + ", ".join(f"{s.value} {s.name.lower()}" for s in ScanStatus))
        arrays["num_accepted_steps"] = self.num_accepted_steps
        units["num_accepted_steps"] = ("-", "accepted solver steps")
        arrays["num_rejected_steps"] = self.num_rejected_steps
        units["num_rejected_steps"] = ("-", "rejected solver steps")
        if self.ts is not None:
            arrays["ts"] = self.ts
            units["ts"] = ("s", "saved times")
        return arrays, units

    def save(self, path: str | Path) -> tuple[Path, Path]:
        """Write `<stem>.npz` (plain arrays: `coord:<path>`, `obs:<name>`, `hist:<name>`, `status`, ...) and a
        self-describing `<stem>.json` sidecar (units, meanings, shapes, parameters, failures, metadata)."""
        from ..io.results import save_arrays

        arrays, units = self._arrays()
        meta = {
            "scan": {
                "mode": self.mode,
                "params": list(self.params),
                "shape": list(self.shape),
                "components": {k: (list(v) if v else None) for k, v in self.components.items()},
                "reasons": {str(k): v for k, v in self.reasons.items()},
                "units": self.units,
                "descriptions": self.descriptions,
            },
            "attrs": self.attrs,
        }
        return save_arrays(
            path, arrays, units, json.loads(json.dumps(meta, default=_json_default)), kind=FORMAT
        )

    @classmethod
    def load(cls, path: str | Path) -> ScanResult:
        """Read a result written by `save` (give the `.npz`, the `.json` or the stem)."""
        from ..io.results import load_arrays, load_metadata

        arrays, meta = load_arrays(path), load_metadata(path)
        s = meta["scan"]
        return cls(
            params=s["params"],
            mode=s["mode"],
            coords={p: arrays[f"coord:{p}"] for p in s["params"]},
            shape=tuple(s["shape"]),
            data={k[4:]: v for k, v in arrays.items() if k.startswith("obs:")},
            components={k: (tuple(v) if v else None) for k, v in s["components"].items()},
            status=arrays["status"],
            reasons=s["reasons"],
            num_accepted_steps=arrays["num_accepted_steps"],
            num_rejected_steps=arrays["num_rejected_steps"],
            ts=arrays.get("ts"),
            histories={k[5:]: v for k, v in arrays.items() if k.startswith("hist:")},
            units=s["units"],
            descriptions=s["descriptions"],
            attrs=meta.get("attrs", {}),
        )

    def axes(self, name: str) -> list[tuple[str, int, tuple[str, ...] | None]]:
        """The trailing (per-member) axes of observable `name`: (dimension name, length, labels or None).
        A vector observable's first axis is `<name>_component` (labelled by its components); a sensitivity
        `d_<name>` has the axes of `<name>` and then `parameter` (labelled by the swept paths)."""
        v = self.data[name]
        trailing = v.shape[len(self.shape) :]
        if name.startswith("d_") and name[2:] in self.data:
            return [*self.axes(name[2:]), ("parameter", trailing[-1], tuple(self.params))]
        out = []
        for i, n in enumerate(trailing):
            labels = self.components.get(name) if i == 0 else None
            d = f"{name}_component" if i == 0 else f"{name}_dim{i}"
            out.append((d, n, tuple(labels) if labels and len(labels) == n else None))
        return out

    def _layout(self):
        """The labelled-dataset view shared by `to_xarray` and `to_netcdf`: (dimension sizes, coordinates,
        data variables), each variable as (name, dimension names, values, attributes); text coordinates
        (component labels) are lists of str."""
        dims: dict[str, int] = {}
        member_dims = list(self.params) if self.mode == "grid" else ["member"]
        for d, n in zip(member_dims, self.shape, strict=True):
            dims[d] = n
        coords = []
        for p in self.params:
            cdims = (p,) if self.mode == "grid" else ("member",)
            attrs = {"units": self.units.get(p, "?"), "description": self.descriptions.get(p, "")}
            coords.append((p, cdims, self.coords[p], attrs))
        if self.ts is not None:
            dims["t"] = self.ts.size
            coords.append(("t", ("t",), self.ts, {"units": "s", "description": "saved times"}))
        variables = []
        labelled: set[str] = set()
        for k, v in self.data.items():
            extra = []
            for d, n, labels in self.axes(k):
                dims[d], extra = n, [*extra, d]
                if labels is not None and d not in labelled:
                    labelled.add(d)
                    coords.append((d, (d,), list(labels), {}))
            attrs = {"units": self.units.get(k, "?"), "description": self.descriptions.get(k, "")}
            variables.append((k, (*member_dims, *extra), v, attrs))
        for k, v in self.histories.items():
            extra = ["t"]
            for i, n in enumerate(v.shape[len(self.shape) + 1 :]):
                dims[f"{k}_dim{i}"] = n
                extra.append(f"{k}_dim{i}")
            variables.append((f"history_{k}", (*member_dims, *extra), v, {"units": self.units.get(k, "?")}))
        flags = {  # CF flags: what each status code means
            "flag_values": np.array([c.value for c in ScanStatus], dtype=np.int32),
            "flag_meanings": " ".join(c.name.lower() for c in ScanStatus),
        }
        variables.append(("status", tuple(member_dims), self.status, flags))
        variables.append(("num_accepted_steps", tuple(member_dims), self.num_accepted_steps, {"units": "1"}))
        return dims, coords, variables

    def to_xarray(self):
        """An `xarray.Dataset` (only if xarray is installed; it is not a dependency of jaxhoist)."""
        try:
            import xarray as xr  # pyright: ignore[reportMissingImports]  # xarray is optional
        except ImportError:
            raise ImportError(
                "to_xarray() needs xarray, which jaxhoist does not depend on: "
                "`pip install xarray`, use to_netcdf() and open the file with any netCDF reader, or use "
                "ScanResult.data / .coords directly"
            ) from None
        _, coords, variables = self._layout()
        return xr.Dataset(
            {k: (d, v, a) for k, d, v, a in variables},
            coords={k: (d, v, a) for k, d, v, a in coords},
            attrs={"format": FORMAT},
        )

    def to_netcdf(self, path: str | Path) -> Path:
        """Write the dataset as a classic netCDF file (64-bit offsets), readable by xarray, NCO, ncview,
        MATLAB and the like: one dimension per grid parameter (or `member`), `t` for histories, one
        component dimension per vector observable (labels in a text coordinate), units and descriptions as
        attributes, failure reasons and the scan's metadata as JSON text in global attributes. Names that
        netCDF does not allow (brackets) become '_' (`"load.mass_centre[0]"` -> `load.mass_centre_0_`); the
        original path is kept in the `path` attribute."""
        from ..io.netcdf import nc_name, write_netcdf

        dims, coords, variables = self._layout()
        nc_dims = {nc_name(d): n for d, n in dims.items()}
        # CF: the parameters along `member` are auxiliary coordinates of every variable on that dimension
        aux = " ".join(nc_name(p) for p in self.params) if self.mode != "grid" else ""
        out = []
        for k, d, v, a in [*coords, *variables]:
            a = {**a, "path": k} if nc_name(k) != k else dict(a)
            if aux and "member" in d and k not in self.params:
                a["coordinates"] = aux
            dd = tuple(nc_name(x) for x in d)
            if isinstance(v, list):  # text labels -> (n, strlen) characters
                width = max(1, *(len(x.encode("utf-8")) for x in v))
                nc_dims[f"{dd[0]}_strlen"] = width
                chars = np.array([list(x.encode("utf-8").ljust(width, b"\0")) for x in v], dtype=np.uint8)
                v, dd = chars.view("S1").reshape(len(v), width), (*dd, f"{dd[0]}_strlen")
                a["_Encoding"] = "utf-8"  # read back as text, not bytes
            out.append((nc_name(k), dd, np.asarray(v), a))
        attrs = {
            "title": f"jaxhoist scan of {self.attrs.get('scenario', '?')}",
            "format": FORMAT,
            "scan_mode": self.mode,
            "params": ", ".join(self.params),
            "reasons_json": json.dumps({str(k): v for k, v in self.reasons.items()}),
            "attrs_json": json.dumps(self.attrs, default=_json_default),
        }
        return write_netcdf(path, nc_dims, out, attrs)


# ------------------------------------------------------------------------------------------ progress


@dataclasses.dataclass(frozen=True)
class Progress:
    """What a progress callback receives after each chunk.

    - `chunk`, `n_chunks`: the chunk just finished (0-based) and the total.
    - `done`, `total`: members finished (incl. those loaded from disk) and in all.
    - `elapsed`: wall time of this call so far [s]; `eta`: estimated time left [s] (None before the first
      computed chunk); `rate`: members per second over the computed chunks.
    - `loaded`: True if the chunk was read from `out_dir` rather than computed.
    - `compile_time`: time spent compiling [s] (0 until the first computed chunk).
    """

    chunk: int
    n_chunks: int
    done: int
    total: int
    elapsed: float
    eta: float | None
    rate: float | None
    loaded: bool
    compile_time: float
    failed: int


def _fmt_time(s: float | None) -> str:
    if s is None or not np.isfinite(s):
        return "?"
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def print_progress(p: Progress, stream=None) -> None:
    """The default progress report: one line per chunk on stderr."""
    stream = sys.stderr if stream is None else stream
    rate = f"{p.rate:.3g} members/s" if p.rate else "-"
    src = " (loaded)" if p.loaded else ""
    print(
        f"scan: chunk {p.chunk + 1}/{p.n_chunks}{src}  {p.done}/{p.total} members  "
        f"{100.0 * p.done / p.total:5.1f}%  elapsed {_fmt_time(p.elapsed)}  left ~{_fmt_time(p.eta)}  "
        f"{rate}  failed {p.failed}",
        file=stream,
        flush=True,
    )


# ------------------------------------------------------------------------------------------ the scan


_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")


def _hash_value(h, v, depth: int = 0) -> None:
    """Feed a constant or closed-over value into `h` the same way in every process: arrays by their bytes,
    functions by their code (recursively), anything else by its repr without memory addresses."""
    if depth > 8:
        return
    if isinstance(v, np.ndarray | jax.Array):
        h.update(np.ascontiguousarray(np.asarray(v)).tobytes())
    elif isinstance(v, types.CodeType):
        _hash_code(h, v, depth + 1)
    elif callable(v) and hasattr(v, "__code__"):
        _hash_function(h, v, depth + 1)
    elif isinstance(v, tuple | list):
        for x in v:
            _hash_value(h, x, depth + 1)
    else:
        h.update(_ADDRESS.sub("", repr(v)).encode())


def _hash_code(h, code, depth: int = 0) -> None:
    h.update(code.co_code)
    for c in code.co_consts:  # constants: `+ 1.0` -> `+ 2.0` keeps the bytecode (issue 14)
        _hash_value(h, c, depth)


def _hash_function(h, fn, depth: int = 0) -> None:
    """A function's bytecode, constants, defaults and closed-over values (what a changed custom observable
    changes), independent of the process (no memory addresses)."""
    code = getattr(fn, "__code__", None)
    if code is None:
        return
    _hash_code(h, code, depth)
    _hash_value(h, getattr(fn, "__defaults__", None), depth)
    for cell in getattr(fn, "__closure__", None) or ():
        try:
            _hash_value(h, cell.cell_contents, depth)
        except ValueError:  # an empty cell
            continue


def _fingerprint(scenario, spec: _Spec, members, ts, sort) -> str:
    h = hashlib.sha256()
    leaves, treedef = jax.tree_util.tree_flatten(scenario)
    h.update(str(treedef).encode())
    for x in leaves:
        h.update(np.ascontiguousarray(np.asarray(x)).tobytes())
    h.update(np.ascontiguousarray(members).tobytes())
    h.update(np.ascontiguousarray(np.asarray(ts)).tobytes())
    o = spec.options
    h.update(
        repr(
            (
                spec.paths,
                spec.histories,
                spec.lanes,
                sort,
                type(o.solver).__name__,
                o.rtol,
                o.atol,
                o.dt0,
                o.max_steps,
                spec.derivatives,
            )
            + ((("fixed_step", o.fixed_step),) if o.fixed_step else ())
        ).encode()
    )
    for ob in spec.observables:
        h.update(
            f"{ob.name}|{getattr(ob.fn, '__module__', '')}.{getattr(ob.fn, '__qualname__', '')}".encode()
        )
        _hash_function(h, ob.fn)
    return h.hexdigest()[:32]


def _write_atomic_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **arrays)  # pyright: ignore[reportArgumentType]  # numpy's stubs read **arrays as the allow_pickle keyword
    os.replace(tmp, path)


class ScanStoreWarning(UserWarning):
    """A chunk file or the manifest in a scan's `out_dir` was damaged, foreign or stale; it is recomputed."""


def _file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _read_chunk(path: Path, fingerprint: str, members: np.ndarray, sha256: str | None = None):
    """A finished chunk file's arrays, checked, as `(arrays, None)`, or `(None, why)`: missing, unreadable
    (truncated, empty, not an npz), its content changed since it was written (`sha256` from the manifest),
    or written for another scan or other members (a chunk copied over another). Chunk files are written
    atomically, so a file that exists was complete when written."""
    if not path.exists():
        return None, "missing"
    try:
        if sha256 is not None and _file_sha256(path) != sha256:
            return None, "its content changed since it was written (checksum)"
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        return None, f"unreadable ({type(e).__name__})"
    if str(arrays.pop("_fingerprint", "")) != fingerprint:
        return None, "written for another scan"
    if not np.array_equal(arrays.pop("_members", np.array([-1])), members):
        return None, "holds other members (copied over from another chunk?)"
    return arrays, None


def _wait_for(get, timeout: float, what: str, poll: float = 0.5):
    """Poll `get()` until it returns something truthy (another process's file), at most `timeout` s."""
    t0 = time.perf_counter()
    while True:
        got = get()
        if got:
            return got
        if time.perf_counter() - t0 > timeout:
            raise TimeoutError(f"waited {timeout:g} s for {what}; is every process running the same scan?")
        time.sleep(poll)


def _write_manifest(out: Path, manifest: dict) -> None:
    tmp = out / (MANIFEST + ".tmp")
    tmp.write_text(json.dumps(manifest, indent=1, default=_json_default) + "\n")
    os.replace(tmp, out / MANIFEST)


def scan(
    scenario: Scenario,
    params: Mapping[str, Any],
    t1: float | None = None,
    *,
    mode: str | None = None,
    observables=None,
    histories: Sequence[str] = (),
    ts=None,
    n_save: int = 201,
    solver: diffrax.AbstractSolver | None = None,
    rtol: float | None = None,
    atol: float | None = None,
    dt0: float | None = None,
    max_steps: int = 200_000,
    fixed_step: bool = False,
    lanes: int | None = None,
    chunk_size: int | None = None,
    max_memory: float = 1e9,
    devices: Sequence | None = None,
    sort: bool = True,
    derivatives: bool = False,
    out_dir: str | Path | None = None,
    resume: bool = True,
    progress: bool | Callable[[Progress], None] | None = None,
    wait_timeout: float = 24 * 3600.0,
) -> ScanResult:
    """Solve `scenario` for many values of some of its float leaves and evaluate observables of each solve.

    **Arguments**
    - `scenario`: the base `Scenario`.
    - `params`: parameter path -> values. A path is a dotted field name, with `[i]` for one component of a
      vector leaf: `"foundation.friction_coefficient"`, `"hoist.speed"`, `"load.mass_centre[0]"`. Values are
      array-like or a string `"start:stop:num"` / `"v1,v2,..."`; units are those of the field (SI).
    - `t1`: end time [s] (default `scenario.t1`); `ts`: saved times [s] starting at 0 (default `n_save`
      equally spaced times; observables such as event times are interpolated on this grid).
    - `mode`: "sweep" (one parameter, the default), "grid" (every combination: one data axis per
      parameter) or "points" (equally long lists zipped together: one data axis).
    - `observables`: names of built-in observables (`jaxhoist.numerics.observables`), callables
      `fn(traj[, scenario])`, `Observable`s, or a dict name -> any of these.
    - `histories`: `Trajectory` fields to keep at every saved time, e.g. `("position", "euler")`.
    - `solver`, `rtol`, `atol`, `dt0`, `max_steps`: as in `simulate` (one budget for every member).
    - `fixed_step`: constant steps of at most `dt0` (no error control) with an explicit Runge-Kutta
      `solver` (e.g. `diffrax.Bosh3()`), integrated by the lean loop of `numerics.fixed_step` (same numbers
      as diffrax's `ConstantStepSize` to round-off when the saved times are multiples of `dt0`); other
      solvers fall back to diffrax's `ConstantStepSize`. Every member takes the same steps. Check the
      accuracy against an adaptive solve (`experiments/benchmark_scan.py` does; see docs/performance.md).
    - `lanes`: members solved together in one vmapped, lock-step solve (a numerical setting: results
      are independent of the chunk size and devices, not of `lanes`); capped at the number of members.
      Default 16 (adaptive steps: lock-step waste grows with the width) or 256 with `fixed_step`.
    - `chunk_size`: members per compiled call (rounded up to whole groups on every device); default: up
      to 8 groups per device, fewer if the saved histories would exceed `max_memory` bytes.
    - `devices`: the JAX devices of this process to shard over (default all of `jax.local_devices()`).
    - Several processes: after `jax.distributed.initialize(...)` on every host, call `scan` with the same
      arguments in each process and an `out_dir` on a shared file system; the chunks are shared out
      between the processes, and every process returns the whole result. `wait_timeout` [s] bounds how
      long a process waits for another's chunk file.
    - `sort`: solve members in order of their parameter values (cuts lock-step waste; no effect on results
      beyond the grouping).
    - `derivatives`: also compute forward-mode sensitivities of every observable with respect to the swept
      parameters (`jax.jacfwd`, through `diffrax.ForwardMode` or the fixed-step loop), stored as `d_<name>`
      with a last axis over the parameters. The default solver is then `diffrax.Tsit5()` (rtol 1e-6):
      through the Rosenbrock-W solver sensitivities are not reliable yet at high friction. Cost for one
      parameter, measured in `experiments/benchmark_scan.py`: 1.3-2x a plain scan with adaptive steps,
      3.1-3.8x with fixed steps (docs/performance.md).
    - `out_dir`: write each finished chunk there (`chunk_#####.npz` + `manifest.json`) and the final
      `scan.npz` + `scan.json` and the same dataset as netCDF, `scan.nc`; with `resume=True` an
      interrupted scan continues from the chunks on disk.
    - `progress`: True to print a line per chunk on stderr, or a callable receiving a `Progress`.

    **Returns** a `ScanResult`.

    **Raises** `ScenarioError` for invalid paths, values or options (before compiling); a member with an
    invalid value is marked `INVALID_PARAMETER` instead, unless every member is invalid.
    """
    from . import observables as obs_mod

    require_x64()
    wall0 = time.perf_counter()
    if not isinstance(scenario, Scenario):
        raise TypeError(f"scenario must be a jaxhoist.Scenario, got {type(scenario).__name__}")
    scenario.check()
    mode, coords, shape, members = _members(params, mode)
    paths = tuple(coords)
    for p in paths:
        check_path(scenario, p)
    try:
        obs = obs_mod.resolve(observables)
    except (ValueError, TypeError) as e:
        raise ScenarioError(str(e)) from None
    histories = tuple(histories)
    for h in histories:
        if h not in _HISTORY_UNITS:
            raise ScenarioError(
                f"history {h!r} is not a Trajectory output; choose from {sorted(_HISTORY_UNITS)}"
            )
    if derivatives and solver is None:
        # Tsit5: forward-mode sensitivities through the default Rosenbrock-W solver are not reliable yet at
        # high friction (they grow without bound over 25 s of paper-4.2 at mu >= 0.5; docs/performance.md)
        solver = diffrax.Tsit5()
    options = SolverOptions(
        solver=solver,
        rtol=rtol,
        atol=atol,
        dt0=dt0,
        max_steps=max_steps,
        adjoint="forward" if derivatives else "reverse",
        fixed_step=bool(fixed_step),
    )
    t1, ts = saved_times(scenario, t1, ts, n_save)
    if fixed_step and fixed_mod.supports(options.solver):
        need = fixed_mod.steps_needed(ts, dt0)  # pyright: ignore[reportArgumentType]  # fixed_step checks dt0 before
        if need > int(max_steps):
            raise ScenarioError(
                f"fixed steps of dt0 = {dt0} s to t1 = {float(np.asarray(ts)[-1])} s need {need} steps, more "
                f"than max_steps = {max_steps}: raise max_steps or dt0"
            )
    ts = jnp.asarray(ts, dtype=jnp.float64)
    if lanes is None:
        lanes = 256 if fixed_step else 16
    if int(lanes) < 1:
        raise ScenarioError(f"lanes must be >= 1, got {lanes}")
    devs = tuple(jax.local_devices() if devices is None else devices)
    n_proc, proc = jax.process_count(), jax.process_index()
    if n_proc > 1 and out_dir is None:
        raise ScenarioError(
            f"this is process {proc} of {n_proc} (jax.distributed): a scan over several processes needs "
            f"out_dir, a folder on a file system that all of them share"
        )
    n = members.shape[0]
    n_dev = len(devs)
    lanes = int(min(int(lanes), 1 << max(0, math.ceil(math.log2(n)))))

    # Host-side validation: invalid members are marked, and solved with a valid neighbour's values.
    invalid = _validate_members(scenario, paths, members)
    if len(invalid) == n:
        raise ScenarioError(f"every member of the scan is invalid; the first: {invalid[0]}")
    order = np.lexsort(members.T[::-1]) if sort else np.arange(n)
    solve_rows = members.copy()
    if invalid:
        valid_sorted = [i for i in order if i not in invalid]
        pos = {int(i): k for k, i in enumerate(order)}
        vpos = np.array([pos[int(i)] for i in valid_sorted])
        for i in invalid:
            nearest = valid_sorted[int(np.argmin(np.abs(vpos - pos[i])))]
            solve_rows[i] = members[nearest]

    # Layout: groups of `lanes` members; chunks of whole groups on every device.
    n_groups = math.ceil(n / lanes)
    hist_bytes = 8 * len(ts) * sum(int(np.prod(_hist_shape(h))) for h in histories)
    if chunk_size is None:
        per_dev = max(1, min(8, math.ceil(n_groups / n_dev)))
        mem_groups = max(1, int(max_memory // max(1, (hist_bytes + 4096) * lanes * n_dev)))
        per_dev = min(per_dev, mem_groups)
    else:
        if int(chunk_size) < 1:
            raise ScenarioError(f"chunk_size must be >= 1, got {chunk_size}")
        per_dev = max(1, math.ceil(int(chunk_size) / (lanes * n_dev)))
    chunk = per_dev * lanes * n_dev
    spec = _Spec(
        paths=paths,
        observables=obs,
        histories=histories,
        options=options,
        lanes=lanes,
        devices=devs,
        derivatives=bool(derivatives),
    )
    fp = _fingerprint(scenario, spec, members, ts, sort)

    # Resume from disk.
    out = Path(out_dir) if out_dir is not None else None
    done_chunks: dict[int, dict[str, np.ndarray]] = {}
    manifest: dict[str, Any] = {}
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        mpath = out / MANIFEST
        if n_proc > 1 and proc != 0:
            _wait_for(
                lambda: mpath.exists() and json.loads(mpath.read_text()).get("fingerprint") == fp,
                wait_timeout,
                f"process 0's {mpath} of this scan",
            )
        old = None
        if mpath.exists() and resume:
            try:
                old = json.loads(mpath.read_text())
                int(old["chunk_size"])
            except (OSError, ValueError, KeyError, TypeError) as e:
                warnings.warn(
                    f"{mpath} is unreadable ({type(e).__name__}); the scan starts afresh", ScanStoreWarning,
                    stacklevel=2,
                )
                old = None
        if old is not None:
            if old.get("fingerprint") != fp:
                raise ScenarioError(
                    f"{out} holds chunks of a different scan (other scenario, values, times, "
                    f"observables or solver options): use another out_dir, or resume=False to "
                    f"overwrite it"
                )
            chunk = int(old["chunk_size"])  # the files' layout wins
            for k_str, entry in old.get("chunks", {}).items():
                k = int(k_str)
                path_k = out / f"chunk_{k:05d}.npz"
                res, why = _read_chunk(
                    path_k, fp, order[k * chunk : (k + 1) * chunk], (entry or {}).get("sha256")
                )
                if res is not None:
                    done_chunks[k] = res
                elif why != "missing":
                    warnings.warn(f"{path_k}: {why}; recomputed", ScanStoreWarning, stacklevel=2)
        manifest = {
            "format": FORMAT + "-manifest",
            "fingerprint": fp,
            "chunk_size": chunk,
            "n_members": n,
            "params": list(paths),
            "mode": mode,
            "t1": float(ts[-1]),
            "lanes": lanes,
            "chunks": {  # the verified chunks keep their records (checksum included)
                str(k): (old or {}).get("chunks", {}).get(str(k)) or {"file": f"chunk_{k:05d}.npz"}
                for k in sorted(done_chunks)
            },
        }
        if proc == 0:
            _write_manifest(out, manifest)

    n_chunks = math.ceil(n / chunk)
    # which devices computed each chunk (issue 14): this run's, or as recorded by the run that wrote it
    here = [str(d) for d in devs] if n_proc == 1 else [f"process {proc}: {d}" for d in devs]
    chunk_devices: dict[int, list[str]] = {}
    resumed = set(done_chunks)
    # Groups per compiled call: the chunk's, rounded up to a multiple of the device count (a chunk laid out
    # by a resumed run with fewer devices); the extra groups are inactive and cost nothing.
    groups_per_chunk = math.ceil(chunk // lanes / n_dev) * n_dev
    fn = _chunk_fn(spec)
    results: dict[int, dict[str, np.ndarray]] = {}
    report = print_progress if progress is True else (progress if callable(progress) else None)
    compile_time = 0.0
    computed = 0
    compute_time = 0.0
    failed = 0
    for k in range(n_chunks):
        lo, hi = k * chunk, min(n, (k + 1) * chunk)
        idx = order[lo:hi]
        t_start = time.perf_counter()
        loaded = k in done_chunks
        if not loaded and k % n_proc != proc:  # another process's chunk: wait for its file
            path_k = out / f"chunk_{k:05d}.npz"  # pyright: ignore[reportOptionalOperand]  # out is set when several processes share out_dir
            done_chunks[k] = _wait_for(
                lambda: _read_chunk(path_k, fp, idx)[0], wait_timeout, f"{path_k} from process {k % n_proc}"
            )
            loaded = True
        if loaded:
            res = done_chunks[k]
        else:
            rows = solve_rows[idx]
            pad = groups_per_chunk * lanes - rows.shape[0]
            rows_p = np.concatenate([rows, np.repeat(rows[-1:], pad, axis=0)]) if pad else rows
            n_active = math.ceil(rows.shape[0] / lanes)
            active = np.arange(groups_per_chunk) < n_active
            vals = jnp.asarray(rows_p.reshape(groups_per_chunk, lanes, len(paths)))
            key = _cache_key(spec, scenario, ts, vals)
            if key not in _COMPILED:
                t_c = time.perf_counter()
                _COMPILED[key] = fn.lower(scenario, ts, vals, jnp.asarray(active)).compile()
                compile_time += time.perf_counter() - t_c
                t_start = time.perf_counter()
            fn_c = _COMPILED[key]
            dev_out = jax.block_until_ready(fn_c(scenario, ts, vals, jnp.asarray(active)))
            res = _flatten_out(dev_out, rows.shape[0])
            computed += rows.shape[0]
            compute_time += time.perf_counter() - t_start
            if out is not None:
                path_k = out / f"chunk_{k:05d}.npz"
                _write_atomic_npz(path_k, {**res, "_members": idx, "_fingerprint": np.array(fp)})
                manifest["chunks"][str(k)] = {
                    "file": path_k.name,
                    "sha256": _file_sha256(path_k),
                    "members": [lo, hi],
                    "devices": here,
                    "wall_s": round(time.perf_counter() - t_start, 4),
                }
                if n_proc == 1:  # with several processes the chunk files themselves are the record
                    _write_manifest(out, manifest)
        results[k] = res
        if not loaded:
            chunk_devices[k] = here
        elif k % n_proc != proc and k not in resumed:
            chunk_devices[k] = [f"process {k % n_proc}"]
        else:
            recorded = manifest.get("chunks", {}).get(str(k)) or {}
            chunk_devices[k] = recorded.get("devices", ["not recorded (an earlier run)"])
        failed += int(np.sum(res["status"] != 0))
        if report is not None:
            done = min(n, (k + 1) * chunk)
            rate = computed / compute_time if compute_time > 0 else None
            remaining = sum(
                min(n, (j + 1) * chunk) - j * chunk for j in range(k + 1, n_chunks) if j not in done_chunks
            )
            eta = remaining / rate if rate else (0.0 if remaining == 0 else None)
            report(
                Progress(
                    chunk=k,
                    n_chunks=n_chunks,
                    done=done,
                    total=n,
                    elapsed=time.perf_counter() - wall0,
                    eta=eta,
                    rate=rate,
                    loaded=loaded,
                    compile_time=compile_time,
                    failed=failed,
                )
            )

    # Assemble in the original member order.
    keys = list(results[0])
    flat = {key: np.concatenate([results[k][key] for k in range(n_chunks)]) for key in keys}
    inv = np.empty(n, dtype=np.int64)
    inv[order] = np.arange(n)
    flat = {key: v[inv] for key, v in flat.items()}
    status = flat["status"].astype(np.int32)
    reasons: dict[int, str] = {}
    for i, msg in invalid.items():
        status[i] = ScanStatus.INVALID_PARAMETER
        reasons[i] = msg
    bad = status != ScanStatus.OK
    data = {}
    for o in obs:
        v = flat[f"obs:{o.name}"].astype(np.float64)
        v[bad] = np.nan
        data[o.name] = v.reshape(*shape, *v.shape[1:])
    if derivatives:
        for o in obs:
            v = flat[f"obs:d_{o.name}"].astype(np.float64)
            v[bad] = np.nan
            data[f"d_{o.name}"] = v.reshape(*shape, *v.shape[1:])
    hist = {}
    for h in histories:
        v = flat[f"hist:{h}"].astype(np.float64)
        v[bad] = np.nan
        hist[h] = v.reshape(*shape, *v.shape[1:])
    for i in np.flatnonzero(bad):
        if int(i) not in reasons:
            reasons[int(i)] = ScanStatus(int(status[i])).message
    units = {p: param_unit(scenario, p) for p in paths}
    units.update({o.name: o.unit for o in obs})
    units.update({h: _HISTORY_UNITS[h] for h in histories})
    descriptions = {o.name: o.description for o in obs}
    components = {o.name: o.components for o in obs}
    if derivatives:
        for o in obs:
            units[f"d_{o.name}"] = " | ".join(f"{o.unit} per {units[p]}" for p in paths)
            descriptions[f"d_{o.name}"] = (
                f"forward-mode sensitivity of {o.name} to each swept parameter "
                f"(last axis: {', '.join(paths)})"
            )
            components[f"d_{o.name}"] = paths
    attrs = {
        "scenario": scenario.name,
        "t1": float(ts[-1]),
        "n_save": int(len(ts)),
        "solver": options.describe(),
        "lanes": lanes,
        "chunk_size": chunk,
        "devices": [str(d) for d in devs],
        "chunk_devices": {str(k): chunk_devices[k] for k in sorted(chunk_devices)},
        "sorted": bool(sort),
        "timings_s": {
            "compile": round(compile_time, 4),
            "compute": round(compute_time, 4),
            "total": round(time.perf_counter() - wall0, 4),
            "members_computed": computed,
        },
        "fingerprint": fp,
    }
    result = ScanResult(
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
    if out is not None and proc == 0:
        if n_proc > 1:  # record every chunk, now that all are on disk
            manifest["chunks"] = {
                str(k): {"file": f"chunk_{k:05d}.npz", "devices": chunk_devices[k]} for k in range(n_chunks)
            }
            _write_manifest(out, manifest)
        result.save(out / "scan")
        result.to_netcdf(out / "scan.nc")
    return result


_COMPILED: dict = {}


def _cache_key(spec, scenario, ts, vals):
    leaves, treedef = jax.tree_util.tree_flatten(scenario)
    return (spec, treedef, tuple(np.shape(x) for x in leaves), ts.shape, vals.shape)


# ---------------------------------------------------------------------------------------------- CLI
