"""What the rigid model's phase driver returns (paper §2): the phase log (`PhaseRecord`), the trajectory
(`RigidTrajectory`) and `RigidContactError`. All are importable from `numerics.rigid.solve` as well."""

from __future__ import annotations

import dataclasses

import equinox as eqx
from jaxtyping import Array, Float, Int

from ..._physics import rigid
from ..._physics.elastic import State
from ..trajectory import Trajectory


class RigidContactError(RuntimeError):
    """The rigid model cannot continue with these inputs: more than `max_phases` phases (a Zeno sequence),
    a phase solve that failed (`max_steps`, tolerances), an impact that would gain energy with the given
    restitution, or an inextensible rope whose start has no consistent jerk. The message names what to
    change. Ambiguous or inconsistent contact problems are resolved, not raised (module docstring)."""


@dataclasses.dataclass(frozen=True)
class PhaseRecord:
    """One phase of a rigid-model solve.

    - `t_start`, `t_end`: [s]; `contact`: mode per corner D, E, F, H ("free", "slide", "stick"; in a
      compliant phase "spring" for the corners loaded at its end, else "free");
    - `rest`: the load rested on all four corners (held fixed);
    - `end`: why the phase ended: the guards that fired (e.g. "normal:D", "tangential:E", "rest:slip",
      "rope:slack"), "impact:F" when an impact followed, "rope-jerk" when the inextensible rope snapped
      taut, or "t1".
    - `state_end`: the state at `t_end` (before any impact).
    - `rope`: "elastic" (2.14), or the inextensible rope (2.15) "taut" or "slack" ("compliant" in a
      compliant phase, where a stiff elastic rope stands in for it; `numerics.rigid.compliant`).
    - `choice`: how the configuration was chosen where that needed more than consistency (several
      consistent configurations: the rule that picked it; none: the regularised fallback; a compliant
      phase: what triggered it and its parameters), else "".
    - `merged`: how many sub-microsecond phases were merged into this record (below).

    A phase that lasted less than 1 µs (`min_phase`) has no record of its own: it is merged into the
    previous one, whose `end` then reads "<its end> => <the short configuration> (<duration> s) -> <the
    short phase's end>" (see `_merge`).
    """

    t_start: float
    t_end: float
    contact: tuple[str, str, str, str]
    rest: bool
    end: str
    state_end: State | None = dataclasses.field(default=None, compare=False, repr=False)
    rope: str = "elastic"
    choice: str = ""
    merged: int = 0

    def __str__(self) -> str:
        modes = (
            "rest"
            if self.rest
            else " ".join(f"{c}:{m}" for c, m in zip(rigid.CORNERS, self.contact, strict=True))
        )
        if self.rope != "elastic":
            modes += f"  rope:{self.rope}"
        choice = f"  [{self.choice}]" if self.choice else ""
        return f"{self.t_start:10.6f} - {self.t_end:10.6f} s  {modes:40s} -> {self.end}{choice}"


class RigidTrajectory(Trajectory):
    """Outputs of `simulate_rigid` at the saved times: a `Trajectory` (every field and method of it, so code
    written for `Trajectory` reads this too) with the rigid model's impact losses and phase log.

    - `ts`, `position`, `velocity`, `euler`, `angular_velocity`, `corners`, `normal_forces`,
      `friction_forces`, `ground_reaction`, `rope_tension`, `tip_position`, `energy`, `hoist_work`,
      `damping_loss`, `friction_work`, `states`, `status`, `num_accepted_steps`, `num_rejected_steps`:
      as in `Trajectory` (`energy.ground_spring` is 0 on the rigid ground).
    - `impact_loss`: kinetic energy lost in impacts up to each saved time [J].
    - `phase_index`: index into `phases` of the phase each saved time belongs to.
    - `phases`: the phase log, a tuple of `PhaseRecord` (static).
    """

    impact_loss: Float[Array, " n_t"]
    phase_index: Int[Array, " n_t"]
    phases: tuple = eqx.field(static=True)

    def energy_residual(self) -> Float[Array, " n_t"]:
        """E(t) - E(0) - [W_hoist - D_damping - W_friction - W_impact](t) [J]: zero up to solver error
        (`Trajectory.energy_residual` with the impact losses)."""
        e = self.energy
        mech = e.kinetic + e.potential + e.ground_spring + e.rope_spring + e.boom_spring
        supplied = self.hoist_work - self.damping_loss - self.friction_work - self.impact_loss
        return (mech - mech[..., :1]) - (supplied - supplied[..., :1])

    def phase_log(self) -> str:
        """The phase log, one `PhaseRecord` a line."""
        return "\n".join(str(p) for p in self.phases)


def merge(previous: PhaseRecord, short: PhaseRecord) -> PhaseRecord:
    """One record for `previous` followed by a phase `short` that lasted less than `min_phase` (1 µs): two
    events closer than the phase solves resolve time (their event root finder works to 1e-10 s, the
    solution to rtol 1e-8) are one event of the log. The merged record keeps the previous phase's contact
    modes and start, ends where `short` ended (its state and reason), and its `end` names both events and
    the short configuration in between: "rest:tip => D:stick E:free F:stick H:free (4.1e-09 s) ->
    normal:D,normal:F". The short phase is still solved and its impacts and losses are booked as usual;
    only the log (and `RigidTrajectory.phase_index`) merge it."""
    between = (
        "rest"
        if short.rest
        else " ".join(f"{c}:{m}" for c, m in zip(rigid.CORNERS, short.contact, strict=True))
    )
    n = previous.merged + 1
    first = previous.end if n == 1 else previous.end.split(" => ")[0]
    dt = short.t_end - short.t_start
    what = f"{between} ({dt:.2g} s)" if n == 1 else f"{n} phases < 1 µs, last {between}"
    end = f"{first} => {what} -> {short.end}"
    return dataclasses.replace(previous, t_end=short.t_end, end=end, state_end=short.state_end, merged=n)


def fmt(combo) -> str:
    return " ".join(f"{c}:{rigid.MODE_NAMES[int(m)]}" for c, m in zip(rigid.CORNERS, combo, strict=True))
