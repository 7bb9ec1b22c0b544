"""Hazards: named, thresholded outcomes of one lift, each built on an observable.

    import jaxhoist as jh
    hazards = [
        jh.slide(0.5),                 # the load is dragged more than 0.5 m over the ground
        jh.tilt(degrees=10.0),         # it tilts more than 10 degrees, on the ground or in the air
        jh.tip(degrees=30.0),          # it rolls over more than 30 degrees while a corner is on the ground
        jh.strike(),                   # a corner lands again after it left the ground
        jh.overload(12e3),             # the rope tension exceeds a safe working load of 12 kN
        jh.swing(0.3),                 # after lift-off it swings more than 0.3 m from under the boom tip
        jh.no_liftoff(2.0),            # it has not left the ground by t = 2 s
        jh.Hazard("late", "last_contact_time", 1.5),   # any observable and threshold
    ]

A hazard happens in a member when its observable is above the threshold (`above=True`, value > threshold) or
below it (`above=False`, value < threshold); for a vector observable (one value per corner) when any
component does. Observables are read on the saved grid: choose the saved times fine enough for the events
that matter (see `jaxhoist._numerics.observables`).
"""

from __future__ import annotations

import dataclasses
import math

from ..._errors import ScenarioError
from ..._numerics import observables as obs_mod

#: Built-in observables that count or time events (a time possibly inf).
EVENTS = frozenset(
    {"liftoff_time", "last_contact_time", "detachment_times", "impact_times", "impact_counts", "impacts"}
)
#: Built-in observables that never take a negative value: a threshold below 0 on one of them is a mistake
#: (a hazard that always or never happens).
NONNEGATIVE = EVENTS | {
    "max_tilt",
    "slide_distance",
    "ground_slide",
    "ground_tilt",
    "swing_amplitude",
    "max_rope_tension",
    "contact_time",
    "configuration_time",
}


@dataclasses.dataclass(frozen=True)
class Hazard:
    """A named outcome of one lift: `observable` above (or below) `threshold`.

    - `name`: the label in results (distinct among the hazards of one `lift_risk`).
    - `observable`: a built-in observable's name (`"max_tilt"`, `"contact_margin[E]"`) or an `Observable`.
    - `threshold`: in the observable's unit (SI: m, rad, N, s, ...).
    - `above`: True: the hazard happens when the value is > threshold; False: when it is < threshold. For
      a vector observable, when any component is.

    **Raises** `ScenarioError` (a `ValueError`) for an empty name, an unknown observable, a threshold that
    is not a finite number, or a negative threshold on an observable that is never negative.
    """

    name: str
    observable: str | obs_mod.Observable
    threshold: float
    above: bool = True

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise ScenarioError(f"Hazard: name must be a non-empty string, got {self.name!r:.60}")
        what = f"Hazard {self.name!r}"
        if isinstance(self.observable, str):
            try:
                obs_mod.get(self.observable)
            except ValueError as e:
                raise ScenarioError(f"{what}: {e}") from None
        elif not isinstance(self.observable, obs_mod.Observable):
            raise ScenarioError(
                f"{what}: observable must be a built-in observable's name or an Observable, got "
                f"{type(self.observable).__name__}"
            )
        try:
            thr = float(self.threshold)
        except (TypeError, ValueError, OverflowError):
            raise ScenarioError(f"{what}: threshold must be a number, got {self.threshold!r:.60}") from None
        if not math.isfinite(thr):
            raise ScenarioError(f"{what}: threshold must be finite, got {thr}")
        if thr < 0 and self.observable_name.partition("[")[0] in NONNEGATIVE:
            raise ScenarioError(
                f"{what}: threshold must be >= 0 for {self.observable_name} (never negative), got {thr}"
            )
        object.__setattr__(self, "threshold", thr)
        object.__setattr__(self, "above", bool(self.above))

    @property
    def observable_name(self) -> str:
        """The name of the observable (the key of its values in the scan)."""
        o = self.observable
        return o if isinstance(o, str) else o.name

    def resolve(self) -> obs_mod.Observable:
        """The `Observable` that this hazard reads."""
        o = self.observable
        return obs_mod.get(o) if isinstance(o, str) else o

    def describe(self) -> str:
        return f"{self.observable_name} {'>' if self.above else '<'} {self.threshold:g}"


def _positive(kind: str, name: str, value, unit: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ScenarioError(f"{kind}: {name} must be a number [{unit}], got {value!r:.60}") from None
    if not (math.isfinite(x) and x > 0):
        raise ScenarioError(f"{kind}: {name} must be a finite number > 0 [{unit}], got {x}")
    return x


def slide(distance: float, name: str = "slide") -> Hazard:
    """The load is dragged more than `distance` [m] over the ground: the `ground_slide` observable (the
    largest horizontal distance of the mass centre from its start while a corner touches the ground).

    **Raises** `ScenarioError` unless `distance` > 0."""
    return Hazard(name, "ground_slide", _positive("slide", "distance", distance, "m"))


def tilt(angle: float | None = None, *, degrees: float | None = None, name: str = "tilt") -> Hazard:
    """The load tilts more than `angle` [rad] (or `degrees` [deg]; give one) at any time, on the ground or
    hanging in the air: the `max_tilt` observable (the largest angle between the body ζ axis and the
    vertical). A load lifted off-centre hangs tilted; for a roll-over on the ground use `tip`.

    **Raises** `ScenarioError` unless exactly one of `angle`, `degrees` is given, > 0 and below π rad."""
    return Hazard(name, "max_tilt", _angle("tilt", angle, degrees))


def tip(angle: float | None = None, *, degrees: float | None = None, name: str = "tip") -> Hazard:
    """The load tips: it tilts more than `angle` [rad] (or `degrees` [deg]; give one) while a corner still
    touches the ground (the `ground_tilt` observable); the tilt it hangs at after lift-off does not count.
    A load pivoting on an edge falls over beyond the tilt at which its mass centre passes over that edge:
    atan(b / h) from level, b [m] the mass centre's horizontal distance from the edge, h [m] its height.

    **Raises** `ScenarioError` unless exactly one of `angle`, `degrees` is given, > 0 and below π rad."""
    return Hazard(name, "ground_tilt", _angle("tip", angle, degrees))


def _angle(kind: str, angle, degrees) -> float:
    """The angle [rad] of `tilt` or `tip` from `angle` [rad] or `degrees` [deg], checked."""
    if (angle is None) == (degrees is None):
        raise ScenarioError(f"{kind}: give exactly one of angle [rad] or degrees [deg]")
    rad = (
        _positive(kind, "angle", angle, "rad")
        if degrees is None
        else math.radians(_positive(kind, "degrees", degrees, "deg"))
    )
    if rad >= math.pi:
        raise ScenarioError(f"{kind}: the angle must be below pi rad (180 deg), got {rad} rad")
    return rad


def strike(name: str = "strike") -> Hazard:
    """A corner strikes the ground: it lands again after it has left the ground (the `impacts` observable,
    counted on the saved grid, is at least 1).

    The observables hold no impact speed; a corner strike here is any re-contact after detachment."""
    return Hazard(name, "impacts", 0.5)


def overload(safe_working_load: float, name: str = "overload") -> Hazard:
    """The rope tension exceeds `safe_working_load` [N] at some saved time (`max_rope_tension`).

    **Raises** `ScenarioError` unless `safe_working_load` > 0."""
    return Hazard(
        name, "max_rope_tension", _positive("overload", "safe_working_load", safe_working_load, "N")
    )


def swing(amplitude: float, name: str = "swing") -> Hazard:
    """After the last contact with the ground the load's mass centre moves more than `amplitude` [m]
    horizontally away from the boom tip (`swing_amplitude`).

    **Raises** `ScenarioError` unless `amplitude` > 0."""
    return Hazard(name, "swing_amplitude", _positive("swing", "amplitude", amplitude, "m"))


def no_liftoff(by: float, name: str = "no_liftoff") -> Hazard:
    """The load has not left the ground by time `by` [s] (`liftoff_time` > by; it is +inf when the load
    never leaves the ground before the end of the solve, so `by` = t1 means "no lift-off at all").

    **Raises** `ScenarioError` unless `by` > 0; `lift_risk` also refuses `by` beyond its t1."""
    return Hazard(name, "liftoff_time", _positive("no_liftoff", "by", by, "s"))
