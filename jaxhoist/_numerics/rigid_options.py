"""The numerical settings of the rigid model's phase driver as one object, `RigidOptions`, and the
conversion of `simulate_rigid`'s earlier keyword arguments (`restitution=`, `rope=`, `rtol=`, ...) to it
and to the model object `RigidGround`."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import numpy as np

from .._deprecated import warn_moved
from .._errors import ScenarioError
from .._physics.rigid_contact import Settings
from .options import ElasticRope, InextensibleRope, RigidGround
from .rigid_compiled import StallRule
from .rigid_compliant import ChatterRule

#: The phase driver's tolerances (lengths in L, velocities in V, forces in G, accelerations in g, times in s).
DRIVER_TOLERANCES = dict(
    z=1e-7,  # a corner is on the ground if Z < z L
    v=1e-6,  # ... and |v_z| < v V; it rests if also |v_h| < v V
    force=1e-7,  # consistency tolerance on forces [G]
    accel=1e-7,  # consistency tolerance on accelerations [g]
    rest=1e-9,  # tolerance of the rest conditions (dimensionless guards)
    guard_start=1e-9,  # every guard starts at least this positive (offsets)
    min_phase=1e-6,  # [s] a phase shorter than this is merged into the previous record (`_merge`)
    trigger=1e-6,  # guards within this of zero at an event count as fired
    lookahead=1e-5,  # the look-ahead runs until the fired guards are below -lookahead
    align=1e-2,  # a corner sliding from rest must accelerate along its sliding direction (relative)
    jump=1e-3,  # normal-force jumps closer than this [G] count as equally continuous
    bounce=1e-4,  # impacts slower than bounce V are plastic (no restitution): avoids Zeno bouncing
    relax=1e3,  # fallback 1 of the configuration choice: tolerances times this (degenerate contacts)
)


class RigidOptions(eqx.Module):
    """How `simulate_rigid` integrates the rigid model (paper §2).

    - `rtol`, `atol`: the tolerances of each phase's Tsit5 solve (relative; absolute in the SI unit of each
      state component).
    - `max_steps`: the step budget of each phase solve.
    - `max_phases`: guard against Zeno sequences (counts phase solves, merged sub-microsecond ones
      included).
    - `settings`: `physics.rigid.Settings` (Baumgarte β [1/s], slip blend velocity [m/s], pseudo-inverse
      cut-off, stop and rest velocities [m/s]); default (None): `Settings()`.
    - `chatter`: a `ChatterRule`: when a sustained cycle of impacts (or a phase that stalls twice) is passed
      by a compliant phase (`numerics.rigid_compliant`; recorded in the phase log); None: never (such a run
      ends at `max_phases`, or raises at the second stall).
    - `stall`: a `StallRule`: a phase solve whose mean step over `stall.window` step attempts falls below
      `stall.min_step` [s] has stalled (as one that reaches `max_steps`, found after thousands of steps
      instead of `max_steps`); None: only `max_steps` ends a stalled phase (the behaviour before the rule).

    **Raises** `ScenarioError` for a non-positive tolerance, a budget below 1 or an invalid `ChatterRule`
    or `StallRule`.
    """

    rtol: float = eqx.field(default=1e-8, static=True)
    atol: float = eqx.field(default=1e-9, static=True)
    max_steps: int = eqx.field(default=200_000, static=True)
    max_phases: int = eqx.field(default=2000, static=True)
    settings: Settings | None = None
    chatter: ChatterRule | None = eqx.field(default=ChatterRule(), static=True)
    stall: StallRule | None = eqx.field(default=StallRule(), static=True)

    def __check_init__(self):
        for name in ("rtol", "atol"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0):
                raise ScenarioError(f"rigid option {name} must be a positive number, got {v}")
        for name in ("max_steps", "max_phases"):
            if int(getattr(self, name)) < 1:
                raise ScenarioError(f"rigid option {name} must be >= 1, got {getattr(self, name)}")
        if self.settings is not None and not isinstance(self.settings, Settings):
            raise ScenarioError(
                f"settings must be a physics.rigid.Settings, got {type(self.settings).__name__}"
            )
        if self.chatter is not None:
            if not isinstance(self.chatter, ChatterRule):
                raise ScenarioError(
                    f"chatter must be a ChatterRule or None, got {type(self.chatter).__name__}"
                )
            self.chatter.check()
        if self.stall is not None:
            if not isinstance(self.stall, StallRule):
                raise ScenarioError(f"stall must be a StallRule or None, got {type(self.stall).__name__}")
            self.stall.check()


_MODEL_KW = ("restitution", "rope")
_OPTIONS_KW = ("rtol", "atol", "max_steps", "max_phases", "settings", "chatter")


def convert_legacy(
    old: dict[str, Any],
    model: RigidGround | None,
    options: RigidOptions | None,
    stacklevel: int = 4,
    moved: dict[str, str] | None = None,
) -> tuple[RigidGround, RigidOptions]:
    """`(model, options)` from `simulate_rigid`'s earlier keywords in `old` (`restitution`, `rope` ->
    `RigidGround`; `rtol`, `atol`, `max_steps`, `max_phases`, `settings`, `chatter` -> `RigidOptions`),
    with one `DeprecationWarning` naming the new spelling of these and of `moved` (old name -> new
    spelling: the saved times' keywords, converted by the caller; `stacklevel` as in `warn_moved`, from the
    caller of this function); the defaults where neither is given.

    **Raises** `TypeError` for an unknown keyword, `ScenarioError` for an old keyword given with the object
    that replaces it, an unknown rope name or a restitution outside [0, 1].
    """
    unknown = sorted(set(old) - {*_MODEL_KW, *_OPTIONS_KW})
    if unknown:
        raise TypeError(f"simulate_rigid() got unexpected keyword argument(s): {', '.join(unknown)}")
    model_kw = {k: old[k] for k in _MODEL_KW if k in old}
    options_kw = {k: old[k] for k in _OPTIONS_KW if k in old}
    moved = dict(moved or {})
    moved.update({k: f"model=RigidGround({k}=...)" for k in model_kw})
    moved.update({k: f"options=RigidOptions({k}=...)" for k in options_kw})
    if model_kw:
        if model is not None:
            raise ScenarioError(f"give either model or {', '.join(model_kw)}, not both")
        ropes = {"elastic": ElasticRope(), "inextensible": InextensibleRope()}
        rope = model_kw.get("rope", "elastic")
        if rope not in ropes:
            raise ScenarioError(f"rope must be one of {', '.join(map(repr, ropes))}, got {rope!r}")
        model = RigidGround(rope=ropes[rope], restitution=model_kw.get("restitution", 0.0))
    if options_kw:
        if options is not None:
            raise ScenarioError(f"give either options or {', '.join(options_kw)}, not both")
        options = RigidOptions(**options_kw)
    warn_moved("simulate_rigid", moved, stacklevel=stacklevel)
    return RigidGround() if model is None else model, RigidOptions() if options is None else options
