"""The on-disk store of a scan (`scan(..., out_dir=...)`): one `chunk_#####.npz` per finished chunk and a
`manifest.json` naming the scan (its fingerprint), its layout and every verified chunk (checksum, members,
devices, wall time). An interrupted scan resumes from the chunks whose fingerprint, members and checksum
check out; a damaged, foreign or stale file is recomputed with a `ScanStoreWarning`. Several processes
(`jax.distributed`) hand chunks to each other through this folder: each writes its own chunks and waits for
the others' files. No JAX computation here; `apps.scan` runs the chunks.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import time
import types
import warnings
import zipfile
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

from .._errors import ScenarioError

FORMAT = "jaxhoist-scan/1"
MANIFEST = "manifest.json"


class DifferentScanError(ScenarioError):
    """The output folder holds the chunks of a different scan (another scenario, values, times, observables
    or solver options) and `resume` is on."""


class ScanStoreWarning(UserWarning):
    """A chunk file or the manifest in a scan's `out_dir` was damaged, foreign or stale; it is recomputed."""


def json_default(x):
    """`json.dumps(default=...)` for numpy values (as lists / numbers) and anything else (its repr)."""
    if isinstance(x, np.ndarray | np.generic):
        return x.tolist()
    return repr(x)


# ------------------------------------------------------------------------------------------ fingerprint

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
    for c in code.co_consts:  # constants: `+ 1.0` -> `+ 2.0` keeps the bytecode
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


def fingerprint(
    scenario, members: np.ndarray, ts, settings: tuple, functions: Sequence[tuple[str, Callable]]
) -> str:
    """What identifies a scan's chunks, the same in every process: the scenario's structure and values, the
    member values, the saved times, the `settings` (a tuple of plain values: paths, solver options, ...) and
    the code of each named function (observables)."""
    h = hashlib.sha256()
    leaves, treedef = jax.tree_util.tree_flatten(scenario)
    h.update(str(treedef).encode())
    for x in leaves:
        h.update(np.ascontiguousarray(np.asarray(x)).tobytes())
    h.update(np.ascontiguousarray(members).tobytes())
    h.update(np.ascontiguousarray(np.asarray(ts)).tobytes())
    h.update(repr(settings).encode())
    for name, fn in functions:
        h.update(f"{name}|{getattr(fn, '__module__', '')}.{getattr(fn, '__qualname__', '')}".encode())
        _hash_function(h, fn)
    return h.hexdigest()[:32]


# ------------------------------------------------------------------------------------------- files


def write_atomic_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    """`np.savez` to a temporary file, then rename: a file that exists is complete."""
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **arrays)  # pyright: ignore[reportArgumentType]  # numpy's stubs read **arrays as allow_pickle
    os.replace(tmp, path)


def file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_chunk(path: Path, fingerprint: str, members: np.ndarray, sha256: str | None = None):
    """A finished chunk file's arrays, checked, as `(arrays, None)`, or `(None, why)`: missing, unreadable
    (truncated, empty, not an npz), its content changed since it was written (`sha256` from the manifest),
    or written for another scan or other members (a chunk copied over another). Chunk files are written
    atomically, so a file that exists was complete when written."""
    if not path.exists():
        return None, "missing"
    try:
        if sha256 is not None and file_sha256(path) != sha256:
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


def wait_for(get, timeout: float, what: str, poll: float = 0.5):
    """Poll `get()` until it returns something truthy (another process's file), at most `timeout` s."""
    t0 = time.perf_counter()
    while True:
        got = get()
        if got:
            return got
        if time.perf_counter() - t0 > timeout:
            raise TimeoutError(f"waited {timeout:g} s for {what}; is every process running the same scan?")
        time.sleep(poll)


# ------------------------------------------------------------------------------------------- the store


class ScanStore:
    """The folder `out` of one scan, identified by `fingerprint`, as seen by process `proc` of `n_proc`.

    `open` reads back what an earlier run left (the layout and the verified chunks) and writes the
    manifest; `chunk` waits for another process's chunk; `write` stores a computed chunk; `finish` records
    every chunk once all are on disk (several processes).
    """

    def __init__(
        self,
        out: str | Path,
        fingerprint: str,
        *,
        proc: int = 0,
        n_proc: int = 1,
        wait_timeout: float = 24 * 3600.0,
    ):
        self.out = Path(out)
        self.fingerprint = fingerprint
        self.proc, self.n_proc = proc, n_proc
        self.wait_timeout = wait_timeout
        self.manifest: dict[str, Any] = {}

    def path(self, k: int) -> Path:
        return self.out / f"chunk_{k:05d}.npz"

    def _write_manifest(self) -> None:
        tmp = self.out / (MANIFEST + ".tmp")
        tmp.write_text(json.dumps(self.manifest, indent=1, default=json_default) + "\n")
        os.replace(tmp, self.out / MANIFEST)

    def _old_manifest(self, resume: bool) -> dict | None:
        mpath, fp = self.out / MANIFEST, self.fingerprint
        if self.n_proc > 1 and self.proc != 0:
            wait_for(
                lambda: mpath.exists() and json.loads(mpath.read_text()).get("fingerprint") == fp,
                self.wait_timeout,
                f"process 0's {mpath} of this scan",
            )
        if not (mpath.exists() and resume):
            return None
        try:
            old = json.loads(mpath.read_text())
            int(old["chunk_size"])
        except (OSError, ValueError, KeyError, TypeError) as e:
            warnings.warn(
                f"{mpath} is unreadable ({type(e).__name__}); the scan starts afresh",
                ScanStoreWarning,
                stacklevel=4,
            )
            return None
        if old.get("fingerprint") != self.fingerprint:
            raise DifferentScanError(
                f"{self.out} holds chunks of a different scan (other scenario, values, times, "
                f"observables or solver options): use another out_dir, or resume=False to "
                f"overwrite it"
            )
        return old

    def open(self, order: np.ndarray, chunk: int, header: Mapping[str, Any], resume: bool):
        """Read back an earlier run's verified chunks (members `order[k*chunk:(k+1)*chunk]` in chunk k; the
        files' chunk size wins over `chunk`) and write the manifest (`header`: n_members, params, mode, t1,
        lanes). **Returns** `(chunk size, {k: arrays})`."""
        from .validate import mark_folder, marker_command

        self.out.mkdir(parents=True, exist_ok=True)
        if marker_command(self.out) is None:  # a scan's folder, as `jaxhoist scan` marks it
            mark_folder(self.out, "scan")
        old = self._old_manifest(resume)
        done: dict[int, dict[str, np.ndarray]] = {}
        if old is not None:
            chunk = int(old["chunk_size"])  # the files' layout wins
            for k_str, entry in old.get("chunks", {}).items():
                k = int(k_str)
                res, why = read_chunk(
                    self.path(k),
                    self.fingerprint,
                    order[k * chunk : (k + 1) * chunk],
                    (entry or {}).get("sha256"),
                )
                if res is not None:
                    done[k] = res
                elif why != "missing":
                    warnings.warn(f"{self.path(k)}: {why}; recomputed", ScanStoreWarning, stacklevel=3)
        self.manifest = {
            "format": FORMAT + "-manifest",
            "fingerprint": self.fingerprint,
            "chunk_size": chunk,
            **header,
            "chunks": {  # the verified chunks keep their records (checksum included)
                str(k): (old or {}).get("chunks", {}).get(str(k)) or {"file": f"chunk_{k:05d}.npz"}
                for k in sorted(done)
            },
        }
        if self.proc == 0:
            self._write_manifest()
        return chunk, done

    def chunk(self, k: int, members: np.ndarray) -> dict[str, np.ndarray]:
        """Another process's chunk k (members `members`), once its file is there."""
        path_k = self.path(k)
        return wait_for(
            lambda: read_chunk(path_k, self.fingerprint, members)[0],
            self.wait_timeout,
            f"{path_k} from process {k % self.n_proc}",
        )

    def write(self, k: int, arrays: Mapping[str, np.ndarray], members: np.ndarray, record: dict) -> None:
        """Store computed chunk k (members `members`) and record it in the manifest (`record`: members range,
        devices, wall time)."""
        path_k = self.path(k)
        write_atomic_npz(path_k, {**arrays, "_members": members, "_fingerprint": np.array(self.fingerprint)})
        self.manifest["chunks"][str(k)] = {"file": path_k.name, "sha256": file_sha256(path_k), **record}
        if self.n_proc == 1:  # with several processes the chunk files themselves are the record
            self._write_manifest()

    def recorded_devices(self, k: int) -> list[str]:
        """The devices the manifest names for chunk k (written by an earlier run)."""
        recorded = self.manifest.get("chunks", {}).get(str(k)) or {}
        return recorded.get("devices", ["not recorded (an earlier run)"])

    def finish(self, chunk_devices: Mapping[int, list[str]]) -> None:
        """With several processes, process 0 records every chunk once all are on disk."""
        if self.n_proc > 1 and self.proc == 0:
            self.manifest["chunks"] = {
                str(k): {"file": f"chunk_{k:05d}.npz", "devices": d} for k, d in sorted(chunk_devices.items())
            }
            self._write_manifest()
