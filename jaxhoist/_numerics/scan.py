"""Deprecated location of the scan (issue 11 moved it): `scan`, `ScanResult` and `Progress` now live in
`jaxhoist._apps.scan` (public: `jaxhoist.scan`, `jaxhoist.ScanResult`), the chunk files in
`jaxhoist._io.scan_store`, the parameter paths in `jaxhoist._numerics.paths`. This module forwards the old
names, with a `DeprecationWarning` for those that moved up to `apps` (the numerics layer imports nothing
from apps, so they are looked up only when asked for)."""

from __future__ import annotations

import importlib
import warnings

from .batch import ScanStatus as ScanStatus
from .paths import check_path as check_path
from .paths import get_param as get_param
from .paths import param_unit as param_unit
from .paths import parse_path as parse_path
from .paths import set_param as set_param

_MOVED = {
    "scan": "jaxhoist._apps.scan",
    "ScanResult": "jaxhoist._apps.scan_result",
    "Progress": "jaxhoist._apps.progress",
    "print_progress": "jaxhoist._apps.progress",
    "parse_values": "jaxhoist._apps.sweep",
    "ScanStoreWarning": "jaxhoist._io.scan_store",
}


def __getattr__(name: str):
    if name not in _MOVED:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(
        f"jaxhoist._numerics.scan.{name} moved to {_MOVED[name]}.{name} (issue 11)",
        DeprecationWarning,
        stacklevel=2,
    )
    return getattr(importlib.import_module(_MOVED[name]), name)
