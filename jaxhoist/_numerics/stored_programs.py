"""Compiled programs stored whole on disk, next to JAX's persistent compilation cache: a later process
loads the executable without tracing or lowering the program first. `compile_cache.program` is the way
in: `simulate`'s solve core (the Python API with concrete inputs, and the command line), a scan's group
program where the scan runs on host CPU, the bifurcation locator's solves (with and without the
derivative), `identify`'s fit pieces (its start and one Levenberg-Marquardt step) and, through
`compile_cache.stored_jit`, the rigid model's phase solve and phase-driver pieces.

JAX's persistent cache is keyed by the lowered program's text, so every process still traces the Python
function into JAX's form and lowers it before it can look the program up (for `simulate`'s solve core that is
most of a warm run's time). Here the key is what decides the program before any tracing: the inputs' pytree
structure, the array leaves' shapes and dtypes, the static (non-array) leaves (a dataclass such as a scan's
`BatchSpec` field by field; a function of jaxhoist by its name, or, where it is a lambda or made inside
another function such as an observable's factory, by its code and the values it captured), the versions of
jaxhoist (a digest of its source files), JAX, jaxlib, equinox, diffrax, lineax, optimistix and numpy, the
backend and its kind of device (not the number of devices: a stored program runs on one, and its compiled form
is the same in a process of one host device or several), the JAX settings that change a trace, the compiler
options it is compiled with (`xla_options`) and the environment's `XLA_FLAGS`. A hit deserialises the
executable (`jax.experimental.serialize_executable`); a miss traces, lowers and compiles and stores the result
instead of JAX's cache entry (which would only double the folder's size). Where JAX's cache already holds the
program (written by plain `jit` use), its executable is used but not stored: loaded from JAX's cache, it
serialises without its machine code. A loaded program needs nothing set up by lowering except jaxlib's CPU
LAPACK routines, which `load` sets up.

A stored program is never trusted blindly: each file carries a SHA-256 digest of its content and the full
key it was compiled for; a file whose digest or key does not match, or that fails to load, is compiled
again and overwritten. A key that cannot be written down stably (a static leaf without a stable text, such
as a user's own observable, whose code the key does not cover) stores nothing: the program is compiled as
usual. Like JAX's cache, the folder is trusted otherwise (loading an executable can run code), so keep it
private.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import hashlib
import io
import os
import pickle
import sys
import types
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import numpy as np

from . import xla_options

#: The stored programs' subfolder of the cache folder.
SUBFOLDER = "programs"
_MAGIC = b"jaxhoist-stored-program-1\n"
_SOURCE_DIGEST: list[str] = []


def _source_digest() -> str:
    """SHA-256 of jaxhoist's Python source files (paths and contents), computed once per process."""
    if not _SOURCE_DIGEST:
        root = Path(__file__).resolve().parents[1]
        h = hashlib.sha256()
        for p in sorted(root.rglob("*.py")):
            h.update(p.relative_to(root).as_posix().encode() + b"\0")
            h.update(p.read_bytes() + b"\0")
        _SOURCE_DIGEST.append(h.hexdigest())
    return _SOURCE_DIGEST[0]


def _versions() -> str:
    mods = ("jax", "jaxlib", "equinox", "diffrax", "lineax", "optimistix", "numpy")
    parts = [f"python {sys.version.split()[0]}", f"jaxhoist source {_source_digest()}"]
    for name in mods:
        mod = sys.modules.get(name)
        if mod is None:
            try:
                mod = __import__(name)
            except ImportError:
                parts.append(f"{name} absent")
                continue
        parts.append(f"{name} {getattr(mod, '__version__', '?')}")
    return "\n".join(parts)


# Packages whose code is covered by the key (jaxhoist by its source digest, the others by their versions):
# a class or function from anywhere else (a user's own friction law, say) may change without the key
# changing, so a program that depends on one is not stored.
_COVERED = frozenset(
    ("jaxhoist", "jax", "jaxlib", "equinox", "diffrax", "lineax", "optimistix", "numpy", "builtins")
)


def _qualified(obj) -> str | None:
    """`module.qualname` of a class or function from a covered package, else None."""
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if not module or not qualname or "<" in qualname or module.split(".")[0] not in _COVERED:
        return None  # a lambda, a local, or code the key does not cover
    return f"{module}.{qualname}"


def _function(fn: types.FunctionType) -> str | None:
    """A stable text of a function: its qualified name where that names it (a module-level function of a
    covered package, whose source the key covers); for a lambda or a function made inside another (an
    observable's factory), the name, first line and a digest of its code, with the stable texts of its
    closure's cells and defaults; None for code outside the covered packages or a cell without one."""
    named = _qualified(fn)
    if named is not None:
        return named
    module, code = getattr(fn, "__module__", None), getattr(fn, "__code__", None)
    if not module or module.split(".")[0] not in _COVERED or code is None:
        return None
    try:
        captured = [c.cell_contents for c in fn.__closure__ or ()]
    except ValueError:  # an empty cell
        return None
    consts = [_stable(c) for c in code.co_consts if not isinstance(c, types.CodeType)]
    inner = [_stable(v) for v in (*captured, *(fn.__defaults__ or ()), *(fn.__kwdefaults__ or {}).items())]
    if None in consts or None in inner:
        return None
    digest = hashlib.sha256(code.co_code + repr((consts, code.co_names)).encode()).hexdigest()[:16]
    return f"{module}.{fn.__qualname__}@{code.co_firstlineno}:{digest}({', '.join(map(str, inner))})"


def _stable(x) -> str | None:
    """A text for a static value that is the same in every process and differs for values that compile
    differently, or None where there is none. A dataclass (an `equinox.Module`, an `Observable`, a
    `BatchSpec`) is described field by field, an array by its dtype, shape and a digest of its values."""
    if x is None or isinstance(x, (bool, int, float, complex, str, bytes, np.generic, np.dtype)):
        return f"{type(x).__name__}:{x!r}"
    if isinstance(x, enum.Enum):
        owner = _qualified(type(x))
        return None if owner is None else f"{owner}.{x.name}"
    if isinstance(x, types.FunctionType):
        return _function(x)
    if isinstance(x, (type, types.BuiltinFunctionType)):
        return _qualified(x)
    if isinstance(x, (np.ndarray, jax.Array)):
        a = np.asarray(x)
        return f"array {a.dtype} {a.shape} {hashlib.sha256(a.tobytes()).hexdigest()}"
    if isinstance(x, (tuple, list)):
        inner = [_stable(v) for v in x]
        return None if None in inner else f"{type(x).__name__}({', '.join(map(str, inner))})"
    if isinstance(x, (set, frozenset)):
        inner = [_stable(v) for v in x]
        return None if None in inner else f"{type(x).__name__}({', '.join(sorted(map(str, inner)))})"
    if isinstance(x, dict):
        inner = [(_stable(k), _stable(v)) for k, v in x.items()]
        return (
            None
            if None in [t for kv in inner for t in kv]
            else f"dict({', '.join(f'{k}: {v}' for k, v in inner)})"
        )
    owner = _qualified(type(x))
    if owner is not None and dataclasses.is_dataclass(x):
        fields = [(f.name, _stable(getattr(x, f.name, None))) for f in dataclasses.fields(x)]
        if any(t is None for _, t in fields):
            return None
        return f"{owner}({', '.join(f'{n}={t}' for n, t in fields)})"
    text = repr(x)
    return None if owner is None or " at 0x" in text else f"{owner}:{text}"


def _describe(treedef) -> str | None:
    """A stable text of a pytree structure: every node's class (module-qualified) and its static data."""
    node = treedef.node_data()
    if node is None:
        return "*"
    kind, data = _qualified(node[0]), _stable(node[1])
    children = [_describe(c) for c in treedef.children()]
    if kind is None or data is None or None in children:
        return None
    return f"{kind}[{data}]({', '.join(map(str, children))})"


def _split(args: tuple):
    """(array leaves, their treedef, the static rest) of `args`, as `equinox.filter_jit` splits them."""
    dynamic, static = eqx.partition(args, eqx.is_array)
    leaves, in_def = jax.tree_util.tree_flatten(dynamic)
    return leaves, in_def, static


# The environment variables that change a trace or a compile (equinox's and diffrax's settings, XLA's flags).
_KEY_ENVIRONMENT = ("EQX_", "DIFFRAX_", "XLA_FLAGS")


def program_key(name: str, args: tuple) -> str | None:
    """The full key of the program `name` called with `args`: everything that decides its compiled form.
    None where a part of it has no stable text (then nothing is stored)."""
    leaves, in_def, static = _split(args)
    static_leaves, static_def = jax.tree_util.tree_flatten(static)
    texts = [_stable(x) for x in static_leaves]
    structure = [_describe(in_def), _describe(static_def)]
    if None in texts or None in structure:
        return None
    config = ("jax_enable_x64", "jax_default_matmul_precision", "jax_numpy_dtype_promotion")
    lines = [
        f"program {name}",
        _versions(),
        f"backend {jax.default_backend()} {jax.devices()[0].device_kind}",
        xla_options.describe(),
        *(f"{c} {getattr(jax.config, c, None)!r}" for c in config),
        *(f"env {k}={v}" for k, v in sorted(os.environ.items()) if k.startswith(_KEY_ENVIRONMENT)),
        *map(str, structure),
        *(f"leaf {x.shape} {x.dtype} weak={getattr(x, 'weak_type', False)}" for x in leaves),
        *(f"static {t}" for t in texts),
    ]
    return "\n".join(lines)


def program_path(folder: Path, name: str, key: str) -> Path:
    """Where the program `name` with the full key `key` is stored under the cache folder `folder`."""
    return Path(folder) / SUBFOLDER / f"{name}-{hashlib.sha256(key.encode()).hexdigest()[:40]}-cache"


class StoredProgram:
    """A compiled program called like the traced function: `program(*args)` with the arrays of `args` as
    inputs (its static parts must be those it was compiled for) returns the function's output pytree."""

    def __init__(self, executable, out_def, in_def):
        self.executable, self.out_def, self.in_def = executable, out_def, in_def

    def __call__(self, *args):
        leaves, in_def, _ = _split(args)
        if in_def != self.in_def:
            raise TypeError(
                f"the inputs' structure differs from the compiled program's: {in_def} != {self.in_def}"
            )
        return self.call_leaves(leaves)

    def call_leaves(self, leaves: list):
        """The output pytree for the arguments' array leaves, in their flattened order (the caller split
        them, e.g. `compile_cache.stored_jit`, which flattens its arguments once per call)."""
        return jax.tree_util.tree_unflatten(self.out_def, self.executable(*leaves))


def _prepare_runtime() -> None:
    """Set up what lowering would have set up before a loaded program runs: jaxlib's CPU LAPACK kernels
    (linear solves) find their routines when a program using them is lowered, not when one is loaded."""
    try:
        from jaxlib import lapack

        lapack.prepare_lapack_call("getrf", np.float64)
    except (ImportError, AttributeError):  # another jaxlib layout: lower a tiny linear solve instead
        jax.jit(jax.numpy.linalg.solve).lower(np.eye(2), np.ones(2))


def load(folder: Path, name: str, args: tuple) -> StoredProgram | None:
    """The stored program `name` for `args`, or None where none is stored, its key has no stable text, or
    the stored file is damaged or stale (its digest or key does not match) or fails to load (a warning
    says so; the caller compiles it again)."""
    key = program_key(name, args)
    if key is None:
        return None
    path = program_path(folder, name, key)
    try:
        data = path.read_bytes()
    except OSError:
        return None
    try:
        body = data[len(_MAGIC) + 32 :]
        if (
            not data.startswith(_MAGIC)
            or hashlib.sha256(body).digest() != data[len(_MAGIC) : len(_MAGIC) + 32]
        ):
            raise ValueError("its content does not match its digest")
        stored = _loads(body)
        if stored["key"] != key:
            raise ValueError("it was compiled for another key")
        from jax.experimental.serialize_executable import deserialize_and_load

        _prepare_runtime()
        exe = deserialize_and_load(
            stored["executable"], stored["in_tree"], stored["out_tree"], execution_devices=[jax.devices()[0]]
        )
        return StoredProgram(exe, stored["out_def"], _split(args)[1])
    except Exception as e:  # noqa: BLE001  (any failure means: compile it again)
        warnings.warn(
            f"jaxhoist: stored program {path.name} not used ({e}); compiling it again", stacklevel=2
        )
        return None


def compile_and_store(folder: Path | None, name: str, fn: Callable[..., Any], args: tuple) -> StoredProgram:
    """Trace, lower and compile `fn(*args)` and, where `folder` is not None and the key has a stable text,
    store the executable there (a failure to store only warns). `name` identifies `fn` in the key, so it
    must name one function of jaxhoist (whose source the key covers). The program is named
    `jit_<fn's name>` in JAX's logs."""
    leaves, in_def, static = _split(args)
    out_defs = []

    def flat(*arrays):
        out = fn(*eqx.combine(jax.tree_util.tree_unflatten(in_def, arrays), static))
        out_leaves, out_def = jax.tree_util.tree_flatten(out)
        out_defs.append(out_def)
        return out_leaves

    flat.__name__ = flat.__qualname__ = getattr(fn, "__name__", name)
    lowered = jax.jit(flat).lower(*leaves)
    options = xla_options.compiler_options()
    key = program_key(name, args) if folder is not None else None
    if folder is None or key is None:
        return StoredProgram(lowered.compile(compiler_options=options), out_defs[0], in_def)
    with _fresh_compile() as loaded_from_jax_cache:
        exe = lowered.compile(compiler_options=options)
    # An executable that JAX loaded from its own cache serialises without its machine code (it would fail
    # to run in another process): only a freshly compiled one is stored.
    if not loaded_from_jax_cache:
        try:
            _store(program_path(folder, name, key), key, exe, out_defs[0])
        except (
            OSError,
            ValueError,
            NotImplementedError,
            pickle.PicklingError,
            TypeError,
            AttributeError,
        ) as e:
            warnings.warn(f"jaxhoist: compiled program {name} not stored: {e}", stacklevel=2)
    return StoredProgram(exe, out_defs[0], in_def)


@contextlib.contextmanager
def _fresh_compile():
    """Within the block, JAX's persistent cache stores nothing (the stored program replaces its entry,
    which would only double the folder's size); yields a list that is non-empty where a compilation
    within the block was loaded from JAX's cache instead."""
    hits: list[str] = []

    def listen(event: str, **kwargs) -> None:
        if event == "/jax/compilation_cache/cache_hits":
            hits.append(event)

    option = "jax_persistent_cache_min_compile_time_secs"
    saved = getattr(jax.config, option)
    jax.monitoring.register_event_listener(listen)
    jax.config.update(option, float("inf"))
    try:
        yield hits
    finally:
        jax.config.update(option, saved)
        jax.monitoring.unregister_event_listener(listen)


def _sentinels() -> dict[str, Any]:
    """Objects that pytree structures compare by identity, so that pickling must not copy them: equinox's
    marker of a module without static fields."""
    try:
        from equinox._module._flatten import MISSING
    except ImportError:
        return {}
    return {"equinox-missing": MISSING}


class _Pickler(pickle.Pickler):
    def persistent_id(self, obj):  # pyright: ignore[reportIncompatibleMethodOverride]
        for name, sentinel in _sentinels().items():
            if obj is sentinel:
                return name
        return None


class _Unpickler(pickle.Unpickler):
    def persistent_load(self, pid):
        found = _sentinels().get(pid)
        if found is None:
            raise pickle.UnpicklingError(f"unknown object {pid!r}")
        return found


def _dumps(obj) -> bytes:
    buffer = io.BytesIO()
    _Pickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(obj)
    return buffer.getvalue()


def _loads(data: bytes):
    return _Unpickler(io.BytesIO(data)).load()


def _store(path: Path, key: str, exe, out_def) -> None:
    from jax.experimental.serialize_executable import serialize

    serialized, in_tree, out_tree = serialize(exe)
    body = _dumps(
        {"key": key, "executable": serialized, "in_tree": in_tree, "out_tree": out_tree, "out_def": out_def}
    )
    if _loads(body)["out_def"] != out_def:  # a structure that does not survive pickling is not stored
        raise ValueError("its output structure does not survive pickling")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(_MAGIC + hashlib.sha256(body).digest() + body)
    os.replace(tmp, path)  # atomic: a reader sees the old file or the whole new one


def load_or_compile(
    folder: Path | None,
    name: str,
    fn: Callable[..., Any],
    args: tuple,
    step: Callable[[str], contextlib.AbstractContextManager] | None = None,
):
    """`(program, loaded)`: the stored program for `args` from `folder` if there is a good one (`loaded`
    True), else `fn` compiled for `args` and stored (`loaded` False). `folder` None: compiled, not stored.
    `step`, if given, is called with what is done now ("loading the compiled program" where a file is
    stored for `args`, "compiling") and returns a context manager around it."""
    if step is None:
        step = lambda label: contextlib.nullcontext()  # noqa: E731
    if folder is not None:
        key = program_key(name, args)
        if key is not None and program_path(folder, name, key).is_file():
            with step("loading the compiled program"):
                program = load(folder, name, args)
            if program is not None:
                return program, True
    with step("compiling"):
        return compile_and_store(folder, name, fn, args), False
