"""The one ahead-of-time compile cache of the package. `program(kind, name, fn, args)` gives the executable of
`fn(*args)`: from the process's cache, else (with the persistent compilation cache on) loaded whole from
the cache folder without tracing or lowering (`stored_programs`), else traced, lowered and compiled (and
stored there). `compiled(kind, key, lower)` lowers and compiles once per `(kind, key)` for programs made
another way (an accelerator's copies of a scan's group program). Either keeps the executable for the
process's lifetime, so repeated calls (scan chunks, the command line's `main()` called again in one
process, identification starts) compile once and can time the compilation apart from the run.
`structure_key` is the usual key: pytree structure, leaf shapes, dtypes and weak types. `stored_jit(name)`
compiles a function called many times from the host (the rigid model's phase driver) through `program`,
as `equinox.filter_jit` would compile it.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import time
from collections.abc import Callable, Hashable
from typing import Any

import equinox as eqx
import jax

from . import persistent_cache, stored_programs
from .times import is_tracer

_CACHE: dict[tuple[str, Hashable], Any] = {}


def structure_key(*trees) -> tuple:
    """The pytree structure of `trees` with each array leaf as (shape, dtype, weak type) and other leaves as
    they are (hashable static values): what decides whether a compiled executable can be reused."""
    leaves, treedef = jax.tree_util.tree_flatten(trees)
    return _leaves_key(treedef, leaves, [eqx.is_array(x) for x in leaves])


def _leaves_key(treedef: Any, leaves: list, arrays: list[bool]) -> tuple:
    return (
        treedef,
        tuple((x.shape, x.dtype, getattr(x, "weak_type", False)) if a else x for x, a in zip(leaves, arrays)),
    )


def compiled(kind: str, key: Hashable, lower: Callable[[], Any]) -> tuple[Any, float]:
    """The executable cached under `(kind, key)`, else `lower().compile()` stored there. **Returns**
    `(executable, seconds spent compiling now)` (0.0 on a hit)."""
    full = (kind, key)
    if full in _CACHE:
        return _CACHE[full], 0.0
    t0 = time.perf_counter()
    _CACHE[full] = exe = lower().compile()
    return exe, time.perf_counter() - t0


def _quiet(label: str) -> contextlib.AbstractContextManager:
    return contextlib.nullcontext()


def program(
    kind: str,
    name: str,
    fn: Callable[..., Any],
    args: tuple,
    *,
    step: Callable[[str], contextlib.AbstractContextManager] = _quiet,
) -> tuple[Callable[..., Any], float, bool]:
    """The executable of `fn(*args)`, called as `exe(*args)` (arrays of the same shapes, dtypes and weak
    types, the same static parts): the one cached in this process under `kind` and the structure of `args`
    (`structure_key`), else, where `persistent_cache.enable_compilation_cache` is on, the program stored
    whole in its folder (`stored_programs.load`: nothing traced or lowered), else `fn` traced, lowered and
    compiled (and stored there where the cache is on and `args` have a stable key).

    **Arguments**
    - `kind`: the in-process cache's name for `fn` (one function per kind).
    - `name`: the stored programs' name for `fn`: it must name one function of jaxhoist, whose source the
      stored program's key covers.
    - `fn`, `args`: the function and its arguments (arrays are the program's inputs; everything else is
      static, part of the program).
    - `step`: called with what is done now ("loading the compiled program", "compiling", "compiling (cached
      in this process)"), returns a context manager around it (the command line's progress lines).

    **Returns** `(executable, seconds spent making it now, loaded)`: 0.0 seconds on a hit of this process's
    cache; `loaded` True where it was loaded from the cache folder now.
    """
    full = (kind, structure_key(*args))
    if full in _CACHE:
        with step("compiling (cached in this process)"):
            return _CACHE[full], 0.0, False
    t0 = time.perf_counter()
    exe, loaded = stored_programs.load_or_compile(persistent_cache.enabled_folder(), name, fn, args, step)
    _CACHE[full] = exe
    return exe, time.perf_counter() - t0, loaded


class _StoredJit:
    """`fn` called through `program` (kind and stored name `name`): see `stored_jit`. A repeated call (the
    rigid driver's pieces are called thousands of times per run) flattens its arguments once and looks
    its executable up in `program`'s table directly."""

    def __init__(self, fn: Callable[..., Any], name: str):
        self.fn, self.name = fn, name
        self.signature = inspect.signature(fn)
        kinds = {p.kind for p in self.signature.parameters.values()}
        if kinds - {inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD}:
            raise TypeError(f"stored_jit({name!r}): only positional parameters are supported")
        self.positional = len(self.signature.parameters)
        functools.update_wrapper(self, fn)

    def __call__(self, *args, **kwargs):
        if kwargs or len(args) != self.positional:
            bound = self.signature.bind(*args, **kwargs)
            bound.apply_defaults()
            args = bound.args
        leaves, treedef = jax.tree_util.tree_flatten(args)
        if any(map(is_tracer, leaves)):  # under a caller's trace: traced inline
            return self.fn(*args)
        arrays = [eqx.is_array(x) for x in leaves]
        exe = _CACHE.get((self.name, _leaves_key(treedef, leaves, arrays)))  # `program`'s key: structure_key
        if exe is None:
            exe = program(self.name, self.name, self.fn, args)[0]
        return exe.call_leaves([x for x, a in zip(leaves, arrays) if a])


def stored_jit(name: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """A decorator: the function compiled as `equinox.filter_jit` compiles it (array leaves of the
    arguments are the program's inputs, everything else is static), through `program`, so that where the
    persistent compilation cache is on the executable is stored whole and a later process loads it without
    tracing or lowering. Keyword arguments are bound to their positions first and defaults filled in, so a
    call written either way is one program. `name` is the program's kind and stored name: one per
    function. Meant for functions called from the host: under a caller's `jit`, `vmap` or `grad` (a tracer
    among the arguments) the function is traced into the caller's program instead. Positional parameters
    only."""

    def wrap(fn: Callable[..., Any]) -> Callable[..., Any]:
        return _StoredJit(fn, name)

    return wrap


def count(kind: str) -> int:
    """How many executables of `kind` are cached (tests check that a second call compiles nothing)."""
    return sum(1 for k in _CACHE if k[0] == kind)


def clear(kind: str | None = None) -> None:
    """Forget the executables of `kind` (all if None), those of `stored_jit` functions among them."""
    for k in [k for k in _CACHE if kind is None or k[0] == kind]:
        del _CACHE[k]
