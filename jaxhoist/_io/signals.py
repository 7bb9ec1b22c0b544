"""Measurable signals and their units: the names a measurement file's columns may take (`SIGNALS`, after
the fields of `jaxhoist.Trajectory`), the accepted unit spellings (`UNITS`) and the checks on both, raising
`MeasurementError` (split off `io/measurement.py`, which re-exports every name)."""

from __future__ import annotations

import dataclasses
import difflib
import math
from collections.abc import Iterable

from .._errors import ScenarioError


class MeasurementError(ScenarioError):
    """A measurement file or measured signal is invalid; the message names the file, column and line."""


# ------------------------------------------------------------------------------------------ signals


@dataclasses.dataclass(frozen=True)
class SignalSpec:
    """Where a scalar signal lives in a `Trajectory`: `getattr(traj, field)[:, *index]`, and its SI unit."""

    field: str
    index: tuple[int, ...]
    unit: str
    description: str


def _build_signals() -> dict[str, SignalSpec]:
    xyz, corners = ("x", "y", "z"), ("D", "E", "F", "H")
    out: dict[str, SignalSpec] = {}
    for i, c in enumerate(xyz):
        out[f"position_{c}"] = SignalSpec("position", (i,), "m", f"mass centre C, world {c}")
        out[f"velocity_{c}"] = SignalSpec("velocity", (i,), "m/s", f"velocity of C, world {c}")
        out[f"tip_position_{c}"] = SignalSpec("tip_position", (i,), "m", f"boom tip A, world {c}")
    for i, a in enumerate(("phi", "psi", "theta")):
        out[f"euler_{a}"] = SignalSpec("euler", (i,), "rad", f"Euler angle {a}")
    for i, a in enumerate(("xi", "eta", "zeta")):
        out[f"angular_velocity_{a}"] = SignalSpec("angular_velocity", (i,), "rad/s", f"ω, body {a}")
    for j, k in enumerate(corners):
        for i, c in enumerate(xyz):
            out[f"corners_{k}_{c}"] = SignalSpec("corners", (j, i), "m", f"corner {k}, world {c}")
            out[f"friction_forces_{k}_{c}"] = SignalSpec(
                "friction_forces", (j, i), "N", f"friction force at corner {k}, world {c}"
            )
        out[f"normal_forces_{k}"] = SignalSpec(
            "normal_forces", (j,), "N", f"ground normal force N at corner {k}"
        )
    out["ground_reaction"] = SignalSpec("ground_reaction", (), "N", "total ground reaction R = Σ N_i")
    out["rope_tension"] = SignalSpec("rope_tension", (), "N", "rope tension S")
    return out


SIGNALS: dict[str, SignalSpec] = _build_signals()
"""Every measurable signal: name -> `SignalSpec` (Trajectory field, index, SI unit)."""

# SI unit -> {accepted unit spelling: factor to SI}
UNITS: dict[str, dict[str, float]] = {
    "s": {"s": 1.0, "ms": 1e-3, "min": 60.0},
    "m": {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "km": 1e3},
    "m/s": {"m/s": 1.0, "mm/s": 1e-3, "cm/s": 1e-2, "km/h": 1.0 / 3.6},
    "rad": {"rad": 1.0, "deg": math.pi / 180.0, "°": math.pi / 180.0},
    "rad/s": {"rad/s": 1.0, "deg/s": math.pi / 180.0},
    "N": {"N": 1.0, "kN": 1e3, "MN": 1e6},
}


def signal_groups(name: str) -> list[str]:
    """The signals a name stands for: a signal name itself, or a group prefix (`position` ->
    position_x, position_y, position_z; `corners_D`; `normal_forces`). Empty if it names nothing."""
    if name in SIGNALS:
        return [name]
    return [s for s in SIGNALS if s.startswith(name + "_")]


def hint(word: str, options: Iterable[str]) -> str:
    close = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def check_signal_names(names: Iterable[str], where: str, *, groups: bool = False) -> None:
    """Raise `MeasurementError` for a name that is no signal (nor, with `groups`, a group of signals)."""
    for name in names:
        if signal_groups(name) if groups else name in SIGNALS:
            continue
        options = list(SIGNALS)
        if groups:
            options += sorted({s.rsplit("_", 1)[0] for s in SIGNALS})
        raise MeasurementError(
            f"{where}: unknown signal {name!r}{hint(name, options)}; "
            f"known signals are e.g. position_x, euler_phi, corners_D_z, normal_forces_E, "
            f"rope_tension (all: jaxhoist._io.measurement.SIGNALS)"
        )


def unit_factor(unit: str, si_unit: str, where: str) -> float:
    """The factor that converts `unit` into `si_unit`, or a `MeasurementError` naming `where`."""
    table = UNITS[si_unit]
    u = unit.strip()
    if u in table:
        return table[u]
    dims = [si for si, t in UNITS.items() if u in t]
    if dims:
        raise MeasurementError(
            f"{where}: wrong unit {u!r} (a unit of {dims[0]}); expected {si_unit} "
            f"(or {', '.join(k for k in table if k != si_unit)})"
        )
    raise MeasurementError(
        f"{where}: unknown unit {u!r}; expected {si_unit} (or {', '.join(k for k in table if k != si_unit)})"
    )
