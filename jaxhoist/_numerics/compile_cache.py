"""The one ahead-of-time compile cache of the package: `compiled(kind, key, lower)` lowers and compiles once
per `(kind, key)` and keeps the executable for the process's lifetime, so repeated calls (scan chunks, the
command line's `main()` called again in one process, identification starts) compile once and can time the
compilation apart from the run. `structure_key` is the usual key: pytree structure, leaf shapes and dtypes.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable
from typing import Any

import equinox as eqx
import jax

_CACHE: dict[tuple[str, Hashable], Any] = {}


def structure_key(*trees) -> tuple:
    """The pytree structure of `trees` with each array leaf as (shape, dtype) and other leaves as they are
    (hashable static values): what decides whether a compiled executable can be reused."""
    leaves, treedef = jax.tree_util.tree_flatten(trees)
    return (treedef, tuple((x.shape, str(x.dtype)) if eqx.is_array(x) else x for x in leaves))


def is_cached(kind: str, key: Hashable) -> bool:
    return (kind, key) in _CACHE


def compiled(kind: str, key: Hashable, lower: Callable[[], Any]) -> tuple[Any, float]:
    """The executable cached under `(kind, key)`, else `lower().compile()` stored there. **Returns**
    `(executable, seconds spent compiling now)` (0.0 on a hit)."""
    return remember(kind, key, lambda: lower().compile())


def remember(kind: str, key: Hashable, make: Callable[[], Any]) -> tuple[Any, float]:
    """The executable cached under `(kind, key)`, else `make()` stored there (for executables made another
    way than `lower().compile()`, e.g. loaded by `stored_programs`). **Returns** `(executable, seconds spent
    making it now)` (0.0 on a hit)."""
    full = (kind, key)
    if full in _CACHE:
        return _CACHE[full], 0.0
    t0 = time.perf_counter()
    _CACHE[full] = exe = make()
    return exe, time.perf_counter() - t0


def count(kind: str) -> int:
    """How many executables of `kind` are cached (tests check that a second call compiles nothing)."""
    return sum(1 for k in _CACHE if k[0] == kind)


def clear(kind: str | None = None) -> None:
    """Forget the executables of `kind` (all if None)."""
    for k in [k for k in _CACHE if kind is None or k[0] == kind]:
        del _CACHE[k]
