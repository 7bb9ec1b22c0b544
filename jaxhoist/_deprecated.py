"""The one warning for arguments that moved (issue 11): the earlier keywords keep working, converted to the
new objects exactly, with one `DeprecationWarning` per call that names the new spelling."""

from __future__ import annotations

import sys
import warnings

#: Modules whose frames wrap a function without being its caller (run-time type checking under pytest).
_WRAPPERS = ("jaxtyping", "beartype")


def _caller(frame, stacklevel: int):
    """The frame `stacklevel` calls up from `frame` (`warn_moved`'s: 1) counting only frames outside
    `_WRAPPERS`, and its level counting every frame (what `warnings.warn` counts)."""
    level, real = 1, 1
    while real < stacklevel and frame.f_back is not None:
        frame, level = frame.f_back, level + 1
        if not frame.f_globals.get("__name__", "").startswith(_WRAPPERS):
            real += 1
    return frame, level


def warn_moved(function: str, moved: dict[str, str], stacklevel: int = 3) -> None:
    """Warn once that `function` was called with the earlier keywords `moved` (old name -> new spelling).

    `stacklevel` counts as in `warnings.warn` from this function's frame, not counting wrappers such as
    jaxtyping's run-time checks: 3 points at the code that called `function` when `function` calls this
    directly. The package's own modules pass the new objects (under pytest's `filterwarnings = error` a
    call that does not fails the tests).
    """
    if not moved:
        return
    frame, level = _caller(sys._getframe(0), stacklevel)
    spelled = "; ".join(f"{old} -> {new}" for old, new in moved.items())
    warnings.warn(
        f"{function}(): these arguments moved (issue 11) and will be removed: {spelled}",
        DeprecationWarning,
        stacklevel=level,
    )


def _importer_level() -> int:
    """The `warnings.warn` stack level of the first frame outside jaxhoist and the import machinery: the
    user's `import` statement, so that Python's default filter shows the warning in a script. Frames of
    `importlib._bootstrap` are not counted (`warnings.warn` skips them too)."""
    frame, level = sys._getframe(1), 1
    while frame.f_back is not None:
        frame = frame.f_back
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            continue
        level += 1
        name = frame.f_globals.get("__name__", "")
        if not (name == "jaxhoist" or name.startswith("jaxhoist.")):
            break
    return level


def alias_moved_package(old: str, new: str) -> None:
    """Let the package path `old` (the layout before 0.2) name the modules of its private successor `new`.

    Called from `old`'s `__init__.py`: warns once (`DeprecationWarning`) and registers every module of `new`
    under `old` too, so `from jaxhoist.physics.params import Load` gives the same class object as
    `jaxhoist.Load` (no module is loaded twice).
    """
    import importlib
    import pkgutil

    warnings.warn(
        f"{old} moved to the private package {new} (issue 11); import the public names from `jaxhoist` "
        f"(and plots from `jaxhoist.plots`); {old} will be removed",
        DeprecationWarning,
        stacklevel=_importer_level(),
    )
    old_package, new_package = sys.modules[old], importlib.import_module(new)
    for info in pkgutil.iter_modules(new_package.__path__):
        module = importlib.import_module(f"{new}.{info.name}")
        sys.modules[f"{old}.{info.name}"] = module
        setattr(old_package, info.name, module)
