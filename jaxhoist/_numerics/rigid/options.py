"""The numerical settings of the rigid model's phase driver as one object, `RigidOptions`."""

from __future__ import annotations

import equinox as eqx
import numpy as np

from ..._errors import ScenarioError
from ..._physics.rigid.contact import Settings
from .compiled import StallRule
from .compliant import ChatterRule

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
      by a compliant phase (`numerics.rigid.compliant`; recorded in the phase log); None: never (such a run
      ends at `max_phases`, or raises at the second stall).
    - `stall`: a `StallRule`: a phase solve whose mean step over `stall.window` step attempts falls below
      `stall.min_step` [s] has stalled (as one that reaches `max_steps`, found after thousands of steps
      instead of `max_steps`); None: only `max_steps` ends a stalled phase.

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
