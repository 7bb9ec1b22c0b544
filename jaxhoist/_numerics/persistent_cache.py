"""JAX's persistent compilation cache for jaxhoist's programs: `enable_compilation_cache`.

With the cache on, jaxhoist's own programs (`simulate`'s solve core, a scan's group program on host CPU,
the bifurcation locator's solves, `identify`'s fit pieces, the rigid model's phase solve and the pieces its
phase driver evaluates between phases) are stored whole in the folder's `programs` subfolder
(`stored_programs`, through `compile_cache.program`): a later process that needs the same program (the
same call with other parameter values, which are arguments of the program, not constants) loads the
executable without tracing, lowering or compiling it. Every other program XLA compiles (the scan's
copies on accelerators, a user's own `jax.jit` around `simulate`) goes to JAX's cache in the folder
itself, keyed by the program's text, the compile options, the device and the JAX/XLA versions: a later
process traces and lowers it, then loads it instead of compiling. jaxhoist's compiled cores carry
no host callback, which neither would store (`callback_free`).

The command line switches the cache on for every run (`--no-cache` or `JAXHOIST_CACHE_DIR=""` to switch
it off); a library never changes JAX's global configuration on import, so Python users call
`jaxhoist.enable_compilation_cache()` once.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: The environment variable that moves the cache folder; set to an empty string, it switches the cache off.
ENV_VAR = "JAXHOIST_CACHE_DIR"

#: The default bound on the cache folder's size [bytes]: when it is exceeded, `enable_compilation_cache`
#: deletes the least recently used entries until the folder holds at most 80 % of it.
DEFAULT_MAX_BYTES = 1 << 30

_ENABLED: list[Path | None] = [None]


def default_cache_dir() -> Path | None:
    """The folder of the persistent compilation cache: `$JAXHOIST_CACHE_DIR` if set (None if it is set to
    an empty string: the cache is off), else the platform's per-user cache folder: `$XDG_CACHE_HOME/jaxhoist`
    or `~/.cache/jaxhoist` on Linux and other Unix systems, `~/Library/Caches/jaxhoist` on macOS,
    `%LOCALAPPDATA%\\jaxhoist\\Cache` on Windows."""
    env = os.environ.get(ENV_VAR)
    if env is not None:
        return Path(env).expanduser() if env.strip() else None
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA")
        root = Path(base) if base else Path.home() / "AppData" / "Local"
        return root / "jaxhoist" / "Cache"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "jaxhoist"
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".cache") / "jaxhoist"


def _entries(folder: Path) -> list[Path]:
    """The cache's entries: JAX's (`*-cache` files in `folder`) and the stored programs' (the same names in
    its `programs` subfolder, `stored_programs`)."""
    found = [p for p in folder.iterdir() if p.is_file() and p.name.endswith("-cache")]
    programs = folder / "programs"
    if programs.is_dir():
        found += [p for p in programs.iterdir() if p.is_file() and p.name.endswith("-cache")]
    return found


def enabled_folder() -> Path | None:
    """The folder `enable_compilation_cache` switched on in this process, or None."""
    return _ENABLED[0]


def prune(folder: Path, max_bytes: int) -> int:
    """Delete the least recently used cache entries of `folder` (by access or modification time, whichever
    is later) while its entries hold more than `max_bytes`, down to 80 % of it. **Returns** the number of
    entries deleted. Entries that vanish or cannot be deleted meanwhile are skipped."""
    sized = []
    for p in _entries(folder):
        try:
            st = p.stat()
        except OSError:
            continue
        sized.append((max(st.st_atime, st.st_mtime), st.st_size, p))
    total = sum(s for _, s, _ in sized)
    if total <= max_bytes:
        return 0
    removed = 0
    for _, size, p in sorted(sized, key=lambda e: e[0]):
        if total <= 0.8 * max_bytes:
            break
        try:
            p.unlink()
        except OSError:
            continue
        total -= size
        removed += 1
    return removed


def enable_compilation_cache(path: str | os.PathLike | None = None, *, max_bytes: int = DEFAULT_MAX_BYTES):
    """Switch on the persistent compilation cache for this process, so that compiled programs are stored on
    disk and later processes load them instead of compiling. `simulate`'s solve core, a scan's group
    program (where the scan runs on host CPU: plain and `derivatives=True`), `locate_bifurcation`'s
    solves, `identify`'s fit pieces and the rigid model's phase solve and phase-driver pieces are stored
    whole in the folder's `programs` subfolder (`stored_programs`): a later process loads the executable
    without tracing or lowering it (for `simulate`, about 10 s of tracing and compiling on a 2-core
    machine become a load of about half a second). Every other program goes to JAX's own cache in the
    folder, which saves the XLA compile; a later process still traces and lowers it. Call it once, before
    the first compilation.

    Sets JAX's `jax_compilation_cache_dir` to the folder and `jax_persistent_cache_min_compile_time_secs` to
    0 (every program is stored, the small ones too), and keeps the folder below `max_bytes` by deleting the
    least recently used entries when it is called. A damaged entry is not trusted: JAX fails to decompress
    it, warns and compiles the program again. The folder is trusted otherwise (as JAX's documentation
    says: whoever can write to it can run code in your process), so keep it private to you.

    **Arguments**
    - `path`: the cache folder; default `default_cache_dir()`: `$JAXHOIST_CACHE_DIR`, else the platform's
      per-user cache folder (`~/.cache/jaxhoist` on Linux, `~/Library/Caches/jaxhoist` on macOS,
      `%LOCALAPPDATA%\\jaxhoist\\Cache` on Windows).
    - `max_bytes`: the bound on the folder's size [bytes] (default 1 GiB).

    **Returns** the cache folder as a `Path`, or None where the cache stays off: `JAXHOIST_CACHE_DIR` is set
    to an empty string (and no `path` given), or the folder cannot be created (a warning says why).
    """
    import warnings

    import jax

    folder = Path(path).expanduser() if path is not None else default_cache_dir()
    if folder is None:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        prune(folder, max_bytes)
    except OSError as e:
        warnings.warn(f"jaxhoist: compilation cache off, cannot use {folder}: {e}", stacklevel=2)
        return None
    if _ENABLED[0] is not None and _ENABLED[0] != folder.resolve():
        _reset_jax_cache()  # JAX opens its cache folder once per process: reopen it at the new place
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    _ENABLED[0] = folder.resolve()
    return folder


def _reset_jax_cache() -> None:
    try:
        from jax._src import compilation_cache

        compilation_cache.reset_cache()
    except (ImportError, AttributeError):
        pass
