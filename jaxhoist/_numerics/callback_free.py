"""Compiled cores without host callbacks: `callback_free` and `raise_on_status`.

A compiled program that calls back into Python (a progress meter, `jax.debug.print`, or equinox's runtime
check `error_if`, which raises through `jax.pure_callback`) cannot be stored by JAX's persistent compilation
cache, so every run compiles it again. jaxhoist's cores check their inputs on the host before compiling and
return a failed solve as a status value, so the runtime checks that diffrax traces into `diffeqsolve`
(`saveat.ts must be increasing`, `saveat.ts must lie between t0 and t1`) only repeat host checks.
`callback_free` traces them with equinox's `on_error="nan"` behaviour instead of `"raise"`: a check that
failed would turn its value into NaN (and the solve's status into a failure) rather than call Python. It
changes nothing while no check fails. An `EQX_ON_ERROR` other than the default `raise` (for example
`breakpoint` while debugging) is left as it is.

`raise_on_status` turns a failed status into an exception on the host, where the status is a concrete
array, and through `equinox.branched_error_if` only under the caller's own `jax.jit`/`jax.vmap`.
"""

from __future__ import annotations

import contextlib
import functools
import threading
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

import equinox as eqx
import jax
import numpy as np

_F = TypeVar("_F", bound=Callable[..., Any])
_LOCK = threading.Lock()
_DEPTH = [0]
_SAVED: list[Any] = [None]
_NAME = "EQX_ON_ERROR"


def _errors_module():
    from equinox import _errors  # equinox reads `_errors.EQX_ON_ERROR` when it traces an `error_if`

    return _errors if hasattr(_errors, _NAME) else None


@contextlib.contextmanager
def checks_as_nan() -> Iterator[None]:
    """Within the block, equinox `error_if` checks traced with the default `on_error` return NaN on
    failure instead of raising through a host callback (re-entrant, thread-safe; the earlier setting is
    restored on exit). Where `EQX_ON_ERROR` is not `raise`, nothing changes."""
    mod = _errors_module()
    if mod is None:
        yield
        return
    with _LOCK:
        if _DEPTH[0] == 0:
            _SAVED[0] = getattr(mod, _NAME)
            if _SAVED[0] == "raise":
                setattr(mod, _NAME, "nan")
        _DEPTH[0] += 1
    try:
        yield
    finally:
        with _LOCK:
            _DEPTH[0] -= 1
            if _DEPTH[0] == 0:
                setattr(mod, _NAME, _SAVED[0])


def callback_free(fn: _F) -> _F:
    """`fn` traced under `checks_as_nan`: put on the traceable core (the function a `jit` traces), so that
    every program built from it (`jit`, `lower`, `vmap`, `grad`) carries no runtime-check callback."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with checks_as_nan():
            return fn(*args, **kwargs)

    return wrapper  # pyright: ignore[reportReturnType]  # same signature as fn


def raise_on_status(tree, status, ok: int, messages: Sequence[str]):
    """`tree` unchanged if every `status` equals `ok`, else an `equinox.EquinoxRuntimeError` with the
    message `messages[status]` (the worst status of a batch). A concrete status is checked on the host (no
    compiled program); a traced one (under the caller's `jax.jit` or `jax.vmap`) through
    `equinox.branched_error_if`.

    **Raises** `equinox.EquinoxRuntimeError` naming the failure."""
    try:
        st = np.asarray(status)
    except jax.errors.TracerArrayConversionError:
        return eqx.branched_error_if(tree, status != ok, status, messages)
    if np.any(st != ok):
        raise eqx.EquinoxRuntimeError(messages[int(np.max(st))])
    return tree
