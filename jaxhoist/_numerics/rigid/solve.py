"""The rigid model's phase driver (paper §2): `simulate_rigid(scenario, times)`.

The motion is a sequence of phases, each a fixed contact configuration (`physics.rigid.Phase`). A phase
is integrated by one compiled `diffrax.diffeqsolve` (the phase is an array argument, so every phase reuses
the same compilation) that stops at the first zero of the phase's guards (`diffrax.Event` with bisection
root finding). Between phases, on the host:

1. the guards that fired are identified;
2. a free corner reaching the ground with a downward velocity is an impact: the velocity jump is solved
   with Newton's restitution law at the striking corner (coefficient `restitution`), zero normal velocity
   after the impact at the other corners on the ground, and Coulomb friction impulses (sticking if the
   sticking impulse lies in the friction cone, else sliding against the pre-impact slip);
3. otherwise the old phase is continued a short time past the event (the *look-ahead*, until the fired
   guards are clearly negative) and the next contact configuration is chosen there: every combination of
   modes (free / slide / stick) of the corners on the ground is evaluated, and the ones that are
   consistent (N_i >= 0, friction of sticking corners within μN_i, sliding from rest in the direction of the
   resulting acceleration, free corners on the ground not accelerating into it, or, for a load at rest on
   all four corners, the rest conditions of `statics`) are kept. Among them the resolution rule
   (`_Driver._rank`) picks one: the most contacts, then the most continuous normal forces, then the
   stiff-foundation rule (free the corners whose load is most negative when every corner on the ground is
   in contact: the linear law (2.3) on four corners), then the most sticking corners, then least
   constraint (Gauss). The next phase starts from the event state.

Where no configuration is consistent, documented fallbacks take over, in order: the tolerances relaxed
(degenerate contacts), a tangential impact of the sliding corners on the ground (Painlevé-type
inconsistency; "dynamic jamming"), the least-violating configuration as a short phase. Impacts with no
consistent Coulomb impulse (a grazing touch) take the frictionless one; several consistent impulses, the
most dissipative. A phase that stalls (its mean step over a window of steps falls below a floor,
`StallRule`; or it reaches `max_steps`) is chosen again once without its configuration.
Each such step is recorded in the phase log (`PhaseRecord.choice`, or the impact's
`end`); see docs/rigid-contact.md, "Resolution of contact choices and impacts". `RigidContactError` is left
for inputs that cannot be continued: too many phases, a failed phase solve, an impact that would gain
energy with the given restitution, an inextensible rope that cannot start.

A sustained cycle of impacts or contact changes, or a phase that stalls twice, is passed by a compliant
phase (`compliant`), recorded in the phase log. Modules: this one (`simulate_rigid`); `run`
(the phase loop `_Run`); `records` (`PhaseRecord`, `RigidTrajectory`, `RigidContactError`,
importable from here), `driver` (`_Driver`: solves, projections, configuration choice),
`impacts`, `coulomb`, `compiled`.
"""

from __future__ import annotations

import numpy as np

from ..._errors import ScenarioError, require_x64
from ..._physics import rigid
from ..._physics.params import Scenario
from ..._physics.rigid.model import InextensibleRope, RigidGround
from ..solve import checked_scenario
from ..times import TimesLike, as_times
from .compiled import (
    OUTPUT_CHUNK,
    Options,
    StallRule,
)
from .compliant import ChatterRule
from .coulomb import coulomb_pattern
from .driver import Driver
from .options import DRIVER_TOLERANCES, RigidOptions
from .records import PhaseRecord, RigidContactError, RigidTrajectory
from .run import Run

__all__ = [
    "ChatterRule",
    "PhaseRecord",
    "RigidContactError",
    "RigidOptions",
    "RigidTrajectory",
    "StallRule",
    "simulate_rigid",
    "OUTPUT_CHUNK",
    "coulomb_pattern",
]


#: The number of saved times when `Times.n` is None.
DEFAULT_N = 501


def simulate_rigid(
    scenario: Scenario,
    times: TimesLike = None,
    model: RigidGround | None = None,
    options: RigidOptions | None = None,
    *,
    verbose: bool | str = False,
) -> RigidTrajectory:
    """Simulate a lift with the rigid-body-on-rigid-ground model (paper §2) from rest at t = 0 to t1.

    Not differentiable and not vmappable (the phase sequence is decided on the host).

    **Arguments**
    - `scenario`: a `Scenario`; the foundation's stiffness, damping and friction law are not used (the
      ground is rigid, friction is exact Coulomb with μ = `foundation.friction_coefficient`).
    - `times`: the saved times, a `Times(t1, n, ts)`: end time t1 [s] (default `ts[-1]` if `ts` is given,
      else `scenario.t1`), `n` equally spaced times from 0 to t1 (default 501) or the saved times `ts` [s]
      (start 0, end t1). A number is t1 [s], a 1-D array is ts [s]. Default `Times()`.
    - `model`: `RigidGround(rope=..., restitution=...)` (default `RigidGround()`): `restitution` is Newton's
      coefficient e [-] of corner impacts (0: plastic); `rope` is `ElasticRope()` (the rope law (2.14),
      default) or `InextensibleRope()` (the constraint (2.15) with the boom-tip motion (2.13): |AB| = l(t)
      while taut, tension S >= 0 solved with the contact forces; the rope goes slack when S reaches 0 and
      snaps taut again with a plastic jerk when |AB| reaches l(t); `rope.stiffness`, `rope.damping` and
      `rope.damping_onset` are not used). A hoist whose speed jumps at t = 0 (`ConstantSpeedHoist`,
      `RampedHoist` with ramp_time 0) jerks the taut rope at the start: the jerk's loss is booked in
      `impact_loss` (see docs/rigid-model.md, "Inextensible rope (2.15)"); `RampedHoist(v, ramp_time > 0)`
      starts without one.
    - `options`: `RigidOptions` (phase tolerances and step budget, `max_phases`, contact `settings`, the
      `chatter` rule, the `stall` rule); default `RigidOptions()`.
    - `verbose`: print each phase as it ends.

    **Returns** a `RigidTrajectory` (with the phase log in `.phases`).

    **Raises** `ScenarioError` for invalid input, `RigidContactError` for inconsistent or ambiguous
    contact situations and solver failures.
    """
    require_x64()
    times = as_times(times)
    model = RigidGround() if model is None else model
    options = RigidOptions() if options is None else options
    if not isinstance(model, RigidGround):
        raise ScenarioError(f"model must be RigidGround(...), got {type(model).__name__}")
    if not isinstance(options, RigidOptions):
        raise ScenarioError(f"options must be RigidOptions(...), got {type(options).__name__}")
    scenario = checked_scenario(scenario)
    t1, ts = times.resolve(scenario, DEFAULT_N)
    t1 = float(t1)
    if times.ts is None:  # the rigid model's grid, linspace(0, t1, n): it rounds differently from resolve's
        ts = np.linspace(0.0, t1, times.count(DEFAULT_N))
    ts = np.asarray(ts, dtype=np.float64)
    if ts.ndim != 1 or ts.size < 2 or ts[0] != 0.0 or np.any(np.diff(ts) <= 0) or abs(ts[-1] - t1) > 1e-12:
        raise ScenarioError("ts must be a 1-D, strictly increasing array from 0 to t1 [s]")
    settings = rigid.Settings() if options.settings is None else options.settings
    stall = options.stall
    phase_options = Options(
        rtol=float(options.rtol),
        atol=float(options.atol),
        max_steps=int(options.max_steps),
        event_atol=1e-10,
        stall_window=0 if stall is None else int(stall.window),
        stall_step=0.0 if stall is None else float(stall.min_step),
    )
    scenario = scenario.unlabelled()  # one compiled program per phase kernel for any scenario's labels
    y0, c = rigid.initial_state(scenario)
    drv = Driver(scenario, c, settings, phase_options, float(model.restitution), dict(DRIVER_TOLERANCES))
    drv.debug = verbose == "debug"
    drv.inextensible = isinstance(model.rope, InextensibleRope)

    run = Run(drv, ts, t1, int(options.max_phases), int(options.max_steps), options.chatter, verbose)
    run.start(y0)
    while run.step():
        pass
    return run.result(c, settings)
