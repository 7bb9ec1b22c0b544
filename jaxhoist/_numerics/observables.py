"""Scalar (or small fixed-shape) outcomes of one lift, for scans and bifurcation maps.

Every observable is a pure JAX function `fn(traj, scenario) -> Array` of a single `Trajectory` (no batch
axis) and the `Scenario` that produced it, so `jaxhoist.scan` can `jax.vmap` it and `locate_bifurcation`
can differentiate it with forward mode. Each is wrapped in an `Observable` that carries its name, unit and
the labels of its components:

    import jaxhoist as jh
    from jaxhoist import observables as obs
    res = jh.scan(sc, {"foundation.friction_coefficient": mus}, 10.0,
                  observables=["final_psi", "liftoff_time", obs.detachment_time_difference("E", "D")])

Events (lift-off, a corner leaving or returning to the ground) are read from the contact function of
each corner,

    f_i = k p_i + h w(p_i) min(dp_i/dt, 0),       p_i = -Z_i (how far corner i is below the ground),

which is continuous in time and positive exactly when the model's normal force
N_i = max(0, k p_i + h w(p_i) ṗ_i) (p_i > 0; w is the damper's onset ramp) is positive (eqs. 3.1-3.2).
Event times are its zero crossings, interpolated linearly between the saved times; they are continuous,
piecewise smooth functions of the parameters (so Newton steps on an event-time difference converge), and
accurate to O(Δt²) of the saved grid. An event that does not happen before t1 has time `+inf` (never
NaN). Counts (impacts, contact configurations) are read on the saved grid and miss events shorter than its
spacing.

User-defined observables: any callable `fn(traj)` or `fn(traj, scenario)` returning an array of fixed
shape; wrap it in `Observable(name, fn, unit)` to give it a unit.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp

from .._physics import forces, kinematics

CORNERS = ("D", "E", "F", "H")


@dataclasses.dataclass(frozen=True)
class Observable:
    """A named function of one solve.

    - `name`: label used in results and files.
    - `fn`: `fn(traj, scenario) -> Array` (or `fn(traj)`, detected from its signature), pure JAX, fixed shape.
    - `unit`: SI unit of the value, e.g. "s", "m", "rad", "-".
    - `description`: one line saying what it is.
    - `components`: labels of the last axis for a vector observable (e.g. ("x", "y", "z")), else None.
    """

    name: str
    fn: Callable
    unit: str = "?"
    description: str = ""
    components: tuple[str, ...] | None = None

    def __call__(self, traj, scenario):
        if _n_positional(self.fn) >= 2:
            return jnp.asarray(self.fn(traj, scenario), dtype=jnp.float64)
        return jnp.asarray(self.fn(traj), dtype=jnp.float64)


def _n_positional(fn) -> int:
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return 1
    n = 0
    for p in sig.parameters.values():
        if p.kind == p.VAR_POSITIONAL:
            return 2
        if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD):
            n += 1
    return n


# --------------------------------------------------------------------------------- contact function


def contact_function(traj, scenario):
    """f_i(t) [N] per corner D, E, F, H at the saved times, shape (n_t, 4): > 0 exactly when N_i > 0.

    f_i = k p_i + h w(p_i) min(ṗ_i, 0), with p_i = -Z_i and w the damper's onset ramp (the foundation's
    `damping_onset`; w = 1 for the paper's law); continuous in time (see the module docstring).
    """
    st = traj.states
    load = scenario.load
    rel = kinematics.bottom_corners(load.size) - load.mass_centre

    def one(v, q, w):
        R = kinematics.quat_to_matrix(q)
        return kinematics.points_velocity(v, R, w, rel)[:, 2]

    z_dot = jax.vmap(one)(st.velocity, st.quaternion, st.angular_velocity)
    p, p_dot = -traj.corners[..., 2], -z_dot
    fnd = scenario.foundation
    onset = getattr(fnd, "damping_onset", None)
    w = (p > 0.0).astype(p.dtype) if onset is None else forces.onset_ramp(p, onset)
    return fnd.stiffness * p + fnd.damping * w * jnp.minimum(p_dot, 0.0)


def first_down_crossing(ts, f):
    """First time [s] at which the continuous signal `f` (n_t,) goes from > 0 to <= 0, interpolated
    linearly between saved times; `ts[0]` if f(0) <= 0, `+inf` if it never does."""
    on = f > 0.0
    down = on[:-1] & ~on[1:]
    return jnp.where(~on[0], ts[0], _first_zero(ts, f, down))


def _first_zero(ts, f, steps):
    """The zero of `f`, interpolated linearly, in the first saved-time step where `steps` (n_t - 1,) is
    True (f changes sign across it); `+inf` if there is none. Safe under jvp: no 0/0 where none is found."""
    found = jnp.any(steps)
    j = jnp.argmax(steps)
    t = ts[j] + _zero_fraction(f[j], f[j + 1], found) * (ts[j + 1] - ts[j])
    return jnp.where(found, t, jnp.inf)


def _zero_fraction(f0, f1, crosses):
    """The fraction s of a saved-time step at which a signal going linearly from `f0` to `f1` is 0, where
    `crosses` (they lie on opposite sides of 0: s in [0, 1]); elsewhere a finite stand-in, with no 0/0
    under jvp. Every contact event and every value read at one is placed by it."""
    return f0 / jnp.where(crosses, f0 - f1, 1.0)


def last_down_crossing(ts, f):
    """Last time [s] at which the continuous signal `f` (n_t,) goes from > 0 to <= 0, interpolated linearly
    between saved times; `+inf` if f > 0 at the last saved time (still in contact at t1), `ts[0]` if f <= 0
    at every saved time."""
    found, j, s = _last_down_step(f)
    t = jnp.where(found, ts[j] + s * (ts[j + 1] - ts[j]), ts[0])
    return jnp.where(f[-1] > 0.0, jnp.inf, t)


def _last_down_step(f):
    """(whether `f` (n_t,) goes from > 0 to <= 0 at all, the saved-time step j of the last such crossing,
    its fraction s in (0, 1] of the step from ts[j]: f interpolated linearly is 0 there). Safe under jvp."""
    on = f > 0.0
    down = on[:-1] & ~on[1:]
    found = jnp.any(down)
    j = down.size - 1 - jnp.argmax(down[::-1])  # the last step with a down-crossing
    return found, j, _zero_fraction(f[j], f[j + 1], found)


def _down_crossings(ts, F):
    return jax.vmap(first_down_crossing, in_axes=(None, 1))(ts, F)


def first_return(ts, f):
    """First time [s] at which `f` (n_t,) goes from <= 0 back to > 0 after it first went <= 0 (a corner's
    first impact after its first detachment), interpolated linearly; `+inf` if it never does."""
    on = f > 0.0
    down = on[:-1] & ~on[1:]
    up = ~on[:-1] & on[1:]
    k = jnp.arange(down.size)
    j_down = jnp.where(jnp.any(down), jnp.argmax(down), down.size)  # the detachment step, if any
    j_down = jnp.where(on[0], j_down, -1)  # off the ground at t = 0: any return counts
    return _first_zero(ts, f, up & (k > j_down))


# ------------------------------------------------------------------------------------- observables


def _final_position(traj):
    return traj.position[-1]


def _final_velocity(traj):
    return traj.velocity[-1]


def _final_euler(traj):
    return traj.euler[-1]


def _tilt(traj):
    """Angle between the body ζ axis and the vertical at each saved time [rad]."""
    q = traj.states.quaternion
    q = q / jnp.sqrt(jnp.sum(q**2, axis=-1, keepdims=True))
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r_xz = 2 * (x * z + w * y)
    r_yz = 2 * (y * z - w * x)
    r_zz = 1 - 2 * (x * x + y * y)
    horiz2 = r_xz**2 + r_yz**2
    pos = horiz2 > 0.0
    horiz = jnp.where(pos, jnp.sqrt(jnp.where(pos, horiz2, 1.0)), 0.0)  # finite gradient at zero tilt
    return jnp.arctan2(horiz, r_zz)


def _max_tilt(traj):
    return jnp.max(_tilt(traj))


def _ground_contact(traj, scenario):
    """max_i f_i [N] at the saved times, (n_t,): > 0 exactly while some corner touches the ground."""
    return jnp.max(contact_function(traj, scenario), axis=-1)


def _liftoff_time(traj, scenario):
    return first_down_crossing(traj.ts, _ground_contact(traj, scenario))


def _last_contact_time(traj, scenario):
    return last_down_crossing(traj.ts, _ground_contact(traj, scenario))


def _detachment_times(traj, scenario):
    return _down_crossings(traj.ts, contact_function(traj, scenario))


def _impact_counts(traj, scenario):
    on = contact_function(traj, scenario) > 0.0
    return jnp.sum(~on[:-1] & on[1:], axis=0).astype(jnp.float64)


def _contact_margin(traj, scenario):
    return jnp.min(contact_function(traj, scenario), axis=0) / scenario.foundation.stiffness


def _impact_times(traj, scenario):
    return jax.vmap(first_return, in_axes=(None, 1))(traj.ts, contact_function(traj, scenario))


def _configuration_time(traj, scenario):
    on = contact_function(traj, scenario) > 0.0
    bits = jnp.array([1, 2, 4, 8])
    code = jnp.sum(on.astype(bits.dtype) * bits, axis=-1)  # bit i: corner i (D, E, F, H) in contact
    w = _trapezoid_weights(traj.ts)
    return jnp.stack([jnp.sum(jnp.where(code == m, w, 0.0)) for m in range(16)])


def _trapezoid_weights(ts):
    dt = jnp.diff(ts)
    return jnp.concatenate([dt[:1] * 0.5, 0.5 * (dt[:-1] + dt[1:]), dt[-1:] * 0.5])


def _contact_time(traj, scenario):
    n = jnp.sum(contact_function(traj, scenario) > 0.0, axis=-1)
    w = _trapezoid_weights(traj.ts)
    return jnp.stack([jnp.sum(jnp.where(n == m, w, 0.0)) for m in range(5)])


def _first_corner(traj, scenario):
    return jnp.argmin(_detachment_times(traj, scenario)).astype(jnp.float64)


def _slide_distance(traj):
    d = traj.position[-1, :2] - traj.position[0, :2]
    return jnp.sqrt(jnp.sum(d**2) + 1e-300)


def _max_on_ground(x, F):
    """Largest value of the continuous signal `x` (n_t,) while some corner is in contact (F = max_i f_i > 0,
    (n_t,)): over the saved times with F > 0 and over the zero crossings of F between saved times, where `x`
    is interpolated linearly at the crossing found as the contact events are (0 if F <= 0 throughout).

    With the crossings, the value is continuous where a saved time's contact state changes: as F at a saved
    time falls through 0 its value leaves the set and the crossing's interpolated value, which has reached
    it, takes its place; so the sensitivities of the solve give the value's derivative, the event's motion
    included."""
    on = F > 0.0
    cross = on[:-1] != on[1:]
    s = _zero_fraction(F[:-1], F[1:], cross)
    x_cross = x[:-1] + s * (x[1:] - x[:-1])
    return jnp.maximum(jnp.max(jnp.where(on, x, 0.0)), jnp.max(jnp.where(cross, x_cross, 0.0)))


def _horizontal_distance(a, b):
    """|a - b| over the first two components at each saved time [m], with a finite gradient at 0."""
    d2 = jnp.sum((a[..., :2] - b[..., :2]) ** 2, axis=-1)
    pos = d2 > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, d2, 1.0)), 0.0)


def _ground_slide(traj, scenario):
    """Largest horizontal distance of C from its start [m] while some corner is in contact (max_i f_i > 0;
    at the saved times and at the contact events between them, `_max_on_ground`): how far the load is
    dragged over the ground, not how far it swings when free."""
    return _max_on_ground(
        _horizontal_distance(traj.position, traj.position[:1]), _ground_contact(traj, scenario)
    )


def _ground_tilt(traj, scenario):
    """Largest angle between body ζ and the vertical [rad] while some corner is in contact (max_i f_i > 0; at
    the saved times and at the contact events between them, `_max_on_ground`): how far the load rolls over
    on the ground, not how it hangs in the air."""
    return _max_on_ground(_tilt(traj), _ground_contact(traj, scenario))


def _swing_amplitude(traj, scenario):
    """Largest horizontal distance [m] of C from the boom tip A after the last contact: at the saved times
    after it and at the last contact itself, interpolated linearly (so the value is continuous where the
    last contact passes a saved time); 0 if the load is still on the ground at t1."""
    F = _ground_contact(traj, scenario)
    d = _horizontal_distance(traj.position, traj.tip_position)
    found, j, s = _last_down_step(F)
    free = F[-1] <= 0.0
    at_release = jnp.where(found & free, d[j] + s * (d[j + 1] - d[j]), 0.0)
    after = jnp.arange(d.size) > jnp.where(found, j, 0)  # never on the ground: the saved times after t0
    return jnp.maximum(jnp.max(jnp.where(after & free, d, 0.0)), at_release)


def _component(fn, i):
    def get(traj, scenario):
        return _call(fn, traj, scenario)[i]

    return get


def _call(fn, traj, scenario):
    return fn(traj, scenario) if _n_positional(fn) >= 2 else fn(traj)


_XYZ = ("x", "y", "z")
_EUL = ("phi", "psi", "theta")

BUILTIN: dict[str, Observable] = {}


def _register(o: Observable) -> Observable:
    BUILTIN[o.name] = o
    return o


_register(Observable("final_position", _final_position, "m", "mass centre C at t1 (world x, y, z)", _XYZ))
_register(Observable("final_velocity", _final_velocity, "m/s", "velocity of C at t1", _XYZ))
_register(
    Observable(
        "final_angular_velocity",
        lambda traj: traj.angular_velocity[-1],
        "rad/s",
        "angular velocity ω at t1 in body axes ξ, η, ζ",
        ("xi", "eta", "zeta"),
    )
)
_register(
    Observable(
        "final_euler",
        _final_euler,
        "rad",
        "Euler angles (φ, ψ, ϑ) at t1, R = R_Z(ψ)R_Y(ϑ)R_X(φ), φ and ψ unwrapped",
        _EUL,
    )
)
for _i, _c in enumerate(_XYZ):
    _register(Observable(f"final_{_c}", _component(_final_position, _i), "m", f"mass centre {_c} at t1"))
for _i, _c in enumerate(_EUL):
    _register(
        Observable(f"final_{_c}", _component(_final_euler, _i), "rad", f"Euler angle {_c} at t1 (unwrapped)")
    )
_register(
    Observable(
        "max_tilt", _max_tilt, "rad", "largest angle between body ζ and the vertical over the saved times"
    )
)
_register(
    Observable(
        "liftoff_time", _liftoff_time, "s", "first time all four N_i are zero (interpolated; inf if never)"
    )
)
_register(
    Observable(
        "last_contact_time",
        _last_contact_time,
        "s",
        "last time any corner is in contact (max_i N_i goes to 0 for the last time; interpolated; inf if "
        "still in contact at t1): unlike liftoff_time it ignores a momentary all-off instant before the last "
        "contact",
    )
)
_register(
    Observable(
        "detachment_times",
        _detachment_times,
        "s",
        "per corner D, E, F, H: first time N_i = 0 (interpolated; inf if never)",
        CORNERS,
    )
)
_register(
    Observable(
        "contact_margin",
        _contact_margin,
        "m",
        "per corner: min over the saved times of f_i / k (> 0: never left the ground; continuous in the "
        "parameters, so a grazing detachment is located where it crosses 0)",
        CORNERS,
    )
)
_register(
    Observable(
        "impact_times",
        _impact_times,
        "s",
        "per corner: first time it returns to the ground after its first detachment, or its first landing "
        "if it starts off the ground (interpolated; inf if never)",
        CORNERS,
    )
)
_register(
    Observable(
        "impact_counts",
        _impact_counts,
        "-",
        "per corner: times it returned to the ground after leaving it (on the saved grid)",
        CORNERS,
    )
)
_register(
    Observable(
        "impacts",
        lambda traj, sc: jnp.sum(_impact_counts(traj, sc)),
        "-",
        "total number of corner impacts (on the saved grid)",
    )
)
_register(
    Observable(
        "contact_time",
        _contact_time,
        "s",
        "time spent with 0, 1, 2, 3, 4 corners in contact (trapezoid rule on the saved grid)",
        ("0", "1", "2", "3", "4"),
    )
)
_register(
    Observable(
        "configuration_time",
        _configuration_time,
        "s",
        "time spent in each of the 16 contact configurations, labelled by the corners in contact "
        "(trapezoid rule on the saved grid)",
        tuple("".join(c for i, c in enumerate(CORNERS) if m >> i & 1) or "none" for m in range(16)),
    )
)
_register(
    Observable(
        "first_corner",
        _first_corner,
        "-",
        "index (0=D, 1=E, 2=F, 3=H) of the corner that leaves the ground first",
    )
)
_register(
    Observable(
        "max_rope_tension",
        lambda traj: jnp.max(traj.rope_tension),
        "N",
        "largest rope tension S over the saved times",
    )
)
_register(Observable("slide_distance", _slide_distance, "m", "horizontal distance of C from its start at t1"))
_register(
    Observable(
        "ground_slide",
        _ground_slide,
        "m",
        "largest horizontal distance of C from its start while some corner touches the ground (at the saved "
        "times and the contact's events between them): the drag over the ground, not the swing in the air",
    )
)
_register(
    Observable(
        "ground_tilt",
        _ground_tilt,
        "rad",
        "largest angle between body ζ and the vertical while some corner touches the ground (at the saved "
        "times and the contact's events between them): how far the load rolls over on the ground, not how it "
        "hangs in the air",
    )
)
_register(
    Observable(
        "swing_amplitude",
        _swing_amplitude,
        "m",
        "largest horizontal distance of C from the boom tip A after the last contact (at the saved times "
        "after it and at the contact's end; 0 if still on the ground at t1)",
    )
)


def detachment_time_difference(first: str, second: str) -> Observable:
    """t_first - t_second [s]: the difference of two corners' first detachment times (e.g. "E", "D").

    Continuous in the parameters; it changes sign where the order in which the two corners leave the
    ground swaps, which makes it a good target for Newton steps in `locate_bifurcation`."""
    i, j = CORNERS.index(first.upper()), CORNERS.index(second.upper())

    def diff(traj, scenario):
        t = _detachment_times(traj, scenario)
        return t[i] - t[j]

    return Observable(
        f"detach_{first.upper()}_minus_{second.upper()}",
        diff,
        "s",
        f"first detachment time of corner {first.upper()} minus that of {second.upper()}",
    )


def _indexed(base: Observable, index: int, name: str | None = None) -> Observable:
    """Component `index` of `base`, called `name` as the user wrote it (`contact_margin[E]` stays that, not
    `contact_margin[1]`), or `base[index]`."""
    label = base.components[index] if base.components else str(index)
    return Observable(
        name or f"{base.name}[{index}]",
        _component(base.fn, index),
        base.unit,
        f"{base.description} [component {label}]",
    )


def closest_name(name: str, names) -> str | None:
    """The name among `names` closest to `name` by meaning first, then by spelling: the shortest name that
    starts with `name` (`final_pos` -> `final_position`), else the shortest that contains it (`tilt` ->
    `max_tilt`), else difflib's closest spelling, else None."""
    import difflib

    names = sorted(names, key=lambda n: (len(n), n))
    key = name.strip().lower()
    if key:
        for match in (lambda n: n.startswith(key), lambda n: key in n):
            hits = [n for n in names if match(n)]
            if hits:
                return hits[0]
    close = difflib.get_close_matches(name, names, n=1)
    return close[0] if close else None


def get(name: str) -> Observable:
    """The built-in observable called `name`; `name[i]` selects component i of a vector observable."""
    base, _, rest = name.partition("[")
    if base not in BUILTIN:
        close = closest_name(base, BUILTIN)
        hint = f" (did you mean {close!r}?)" if close else ""
        raise ValueError(f"unknown observable {name!r}{hint}; built-in observables are {sorted(BUILTIN)}")
    obs = BUILTIN[base]
    if rest:
        idx = rest.rstrip("]")
        if obs.components and idx in obs.components:
            i = obs.components.index(idx)
        else:
            try:
                i = int(idx)
            except ValueError:
                c = obs.components
                what = "the corners " if c == CORNERS else ""
                which = f"{what}{', '.join(c)} (or an index 0..{len(c) - 1})" if c else "an index"
                raise ValueError(
                    f"observable {name!r}: bad component {idx!r}; the components of {base} are {which}"
                ) from None
        n = len(obs.components) if obs.components else None
        if n is not None and not 0 <= i < n:
            raise ValueError(f"observable {name!r}: component index must be in 0..{n - 1}")
        return _indexed(obs, i, name)
    return obs


def resolve(spec) -> tuple[Observable, ...]:
    """Normalise an observables argument: a name, a callable, an `Observable`, a sequence of those, or a
    mapping name -> (name | callable | Observable). Returns a tuple of `Observable` with distinct names."""
    if spec is None:
        spec = ["final_position", "final_euler", "max_tilt", "liftoff_time"]
    if isinstance(spec, str | Observable) or callable(spec):
        spec = [spec]
    items: list[Observable] = []
    pairs = spec.items() if isinstance(spec, Mapping) else ((None, s) for s in spec)
    for name, s in pairs:
        if isinstance(s, Observable):
            o = s
        elif isinstance(s, str):
            o = get(s)
        elif callable(s):
            o = Observable(
                getattr(s, "__name__", "observable"),
                s,
                getattr(s, "unit", "?"),
                getattr(s, "__doc__", "") or "",
            )
        else:
            raise TypeError(
                f"an observable must be a name, a callable or an Observable, got {type(s).__name__}"
            )
        if name is not None and name != o.name:
            o = dataclasses.replace(o, name=str(name))
        items.append(o)
    names = [o.name for o in items]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"observable names must be distinct, got {dup} twice (pass a dict to rename)")
    if any(n == "<lambda>" for n in names):
        raise ValueError("give lambda observables a name: pass a dict {'name': fn} or an Observable")
    return tuple(items)


def names() -> Sequence[str]:
    """The names of the built-in observables."""
    return sorted(BUILTIN)
