"""Model parameters as `eqx.Module` pytrees: every physical number is a float64 array leaf, in SI units.

Frames (paper Fig. 1, eqs. 2.1-2.8): world X, Y horizontal, Z up, ground at Z = 0. Body axes ξηζ run along
the box edges a, b, c from the bottom corner D. At t = 0 the bottom corners D, E, F, H stand near
(0, 0), (a, 0), (a, b), (0, b). Corner order is always D, E, F, H.

Host-side checks (`check()`) run on concrete values only, so the modules stay transparent to
`jax.jit`, `jax.vmap` and `jax.grad`; `simulate` re-checks a scenario before compiling, because
`eqx.tree_at` does not run `__init__`.
"""

from __future__ import annotations

import copy
import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ScenarioError, require_x64
from .._typing import Rot33, Scalar, Vec3
from .checks import check_plausible, check_value, concrete, f64, plausible, show
from .friction import AbstractFrictionLaw as AbstractFrictionLaw
from .friction import BristleFriction as BristleFriction
from .friction import RegularisedCoulomb as RegularisedCoulomb
from .hoist import AbstractHoistLaw as AbstractHoistLaw
from .hoist import ConstantSpeedHoist as ConstantSpeedHoist
from .hoist import KnotHoist as KnotHoist
from .hoist import ProfileHoist as ProfileHoist
from .hoist import RampedHoist as RampedHoist
from .paths import replace_leaves, unit

# --------------------------------------------------------------------------------------------- load


def _check_load_size(size) -> None:
    check_value("load.size", size, unit="m", shape=(3,), low=0.0, low_open=True, symbol="a, b, c")


class Load(eqx.Module):
    """The lifted load: a rigid box a×b×c with an eccentric mass centre (paper §2, Fig. 1).

    - `size`: (a, b, c), edge lengths along ξ, η, ζ [m].
    - `mass`: m [kg] (give `mass` or `density` ρ [kg/m³] to the constructor; m = ρabc, computed once:
      replacing `size` later keeps the mass, so change both if you mean a bigger box of the same material).
    - `mass_centre`: C = (ξ_C, η_C, ζ_C) in the body frame, measured from corner D [m]; default the box
      centre.
    - `inertia`: J, the inertia tensor about C in body axes [kg m²] with the sign convention of (2.11)
      (off-diagonal entries are -J_ξη etc.), or None: then the uniform-box tensor about its centre,
      carried to C by the parallel-axis theorem (our choice; give J explicitly for a measured load).
    """

    size: Vec3 = eqx.field(
        metadata=unit("m")
        | plausible(1e-2, 1e3, "a box from 1 cm to 1 km: the largest loads lifted measure ~200 m")
    )
    mass: Scalar = eqx.field(
        metadata=unit("kg")
        | plausible(1e-2, 1e8, "the heaviest crane lifts are ~2e7 kg; a load under 10 g is no crane's")
    )
    mass_centre: Vec3 = eqx.field(metadata=unit("m"))
    inertia: Rot33 | None = eqx.field(metadata=unit("kg m²"))

    def __init__(self, size, mass=None, *, density=None, mass_centre=None, inertia=None):
        size = f64(size)
        if (mass is None) == (density is None):
            raise ScenarioError("load: give exactly one of `mass` [kg] or `density` [kg/m^3]")
        if density is not None:
            # the size first: a bad size must be reported as such, not as the implausible mass it gives
            _check_load_size(size)
            check_value("load.density", f64(density), unit="kg/m^3", low=0.0, low_open=True, symbol="ρ")
            mass = f64(density) * size[0] * size[1] * size[2]
            m = concrete(mass)
            if m is not None and not np.all(np.isfinite(m)):
                raise ScenarioError(
                    f"load.density (ρ) = {show(np.asarray(density))} kg/m^3 is not plausible: the mass "
                    f"ρabc = {show(m)} kg overflows"
                )
        self.size = size
        self.mass = f64(mass)
        self.mass_centre = 0.5 * size if mass_centre is None else f64(mass_centre)
        self.inertia = None if inertia is None else f64(inertia)

    def inertia_tensor(self) -> Rot33:
        """J about C in body axes [kg m²] (the explicit `inertia`, or the parallel-axis default)."""
        if self.inertia is not None:
            return self.inertia
        a, b, c = self.size
        m = self.mass
        j_g = (m / 12.0) * jnp.diag(jnp.stack([b**2 + c**2, a**2 + c**2, a**2 + b**2]))
        d = self.mass_centre - 0.5 * self.size
        return j_g + m * (jnp.dot(d, d) * jnp.eye(3) - jnp.outer(d, d))

    def check(self) -> None:
        _check_load_size(self.size)
        check_value("load.mass", self.mass, unit="kg", low=0.0, low_open=True, symbol="m")
        check_value("load.mass_centre", self.mass_centre, unit="m", shape=(3,), symbol="ξ_C, η_C, ζ_C")
        s, c = concrete(self.size), concrete(self.mass_centre)
        if s is not None and c is not None and np.any((c <= 0) | (c >= s)):
            raise ScenarioError(
                f"load.mass_centre must lie strictly inside the box 0 < C < size = {show(s)} m, "
                f"got {show(c)} m"
            )
        if self.inertia is not None:
            check_value("load.inertia", self.inertia, unit="kg m^2", shape=(3, 3), symbol="J")
            j = concrete(self.inertia)
            if j is not None and j.ndim == 2:
                if not np.allclose(j, j.T, rtol=1e-12, atol=0.0):
                    raise ScenarioError("load.inertia (J) must be symmetric")
                ev = np.linalg.eigvalsh(j)
                if ev[0] <= 0 or ev[2] > ev[0] + ev[1] + 1e-9 * ev[2]:
                    raise ScenarioError(
                        f"load.inertia (J) must be positive definite with principal moments obeying the "
                        f"triangle inequality, got principal moments {ev.tolist()} kg m^2"
                    )


# ------------------------------------------------------------------------------- foundation, rope, boom


class Foundation(eqx.Module):
    """Elastic, damped ground under the four bottom corners (paper §3, eqs. 3.1-3.3).

    - `stiffness`: k, vertical spring per corner [N/m].
    - `damping`: h, vertical damper per corner [N s/m].
    - `friction_coefficient`: μ [-].
    - `friction`: the friction law (default `RegularisedCoulomb(1e-3)`, see README "Friction laws").
    - `damping_onset`: p_0, the penetration over which the damper builds up [m] (our addition; 0 gives
      the paper's (3.1) exactly, whose force jumps to h dp/dt at touch-down).

    N_i = max(0, k p_i + h min(p_i/p_0, 1) dp_i/dt) for a corner below the ground by p_i > 0, else 0: the
    ground pushes, never pulls, and the force is continuous at touch-down.
    """

    stiffness: Scalar = eqx.field(
        metadata=unit("N/m")
        | plausible(1e2, 1e13, "per corner: soft soil ~1e6, concrete ~1e10; beyond 1e13 the ground is rigid")
    )
    damping: Scalar = eqx.field(
        metadata=unit("N s/m")
        | plausible(0.0, 1e11, "beyond 1e11 the ground is overdamped for any load up to 1e8 kg")
    )
    friction_coefficient: Scalar = eqx.field(
        metadata=unit("-") | plausible(0.0, 3.0, "dry friction of real surfaces is below ~1.5")
    )
    friction: AbstractFrictionLaw
    damping_onset: Scalar = eqx.field(
        metadata=unit("m") | plausible(0.0, 0.1, "a penetration of millimetres; 0 gives the paper's (3.1)")
    )

    def __init__(self, stiffness, damping, friction_coefficient, friction=None, damping_onset=1e-4):
        self.stiffness = f64(stiffness)
        self.damping = f64(damping)
        self.friction_coefficient = f64(friction_coefficient)
        self.friction = RegularisedCoulomb(1e-3) if friction is None else friction
        self.damping_onset = f64(damping_onset)

    def check(self):
        check_value("foundation.stiffness", self.stiffness, unit="N/m", low=0.0, low_open=True, symbol="k")
        check_value("foundation.damping", self.damping, unit="N s/m", low=0.0, symbol="h")
        check_value(
            "foundation.friction_coefficient", self.friction_coefficient, unit="-", low=0.0, symbol="μ"
        )
        check_value("foundation.damping_onset", self.damping_onset, unit="m", low=0.0, symbol="p_0")
        self.friction.check()


class Rope(eqx.Module):
    """Elastic, damped hoist rope, eq. (2.14); a slack rope carries no force and the rope never pushes.

    - `stiffness`: c_l, tension per metre of stretch [N/m].
    - `damping`: b_l, tension per metre per second of stretch rate [N s/m].
    - `attachment`: point B in the body frame ξηζ, measured from corner D [m]; on or inside the box.
    - `slack`: rope length at t = 0 minus the distance |AB| [m]; 0 means just taut.
    - `damping_onset`: δ_0, the stretch over which the damper builds up [m] (our addition; 0: the
      damper acts in full as soon as the rope is taut, and S jumps when a slack rope snaps taut).

    S = max(0, c_l δ + b_l min(δ/δ_0, 1) dδ/dt) for stretch δ = |AB| - l(t) > 0, else 0.
    """

    stiffness: Scalar = eqx.field(
        metadata=unit("N/m")
        | plausible(1e3, 1e12, "EA/l of steel or fibre hoist ropes and their falls: ~1e5 to 1e9")
    )
    damping: Scalar = eqx.field(
        metadata=unit("N s/m")
        | plausible(0.0, 1e10, "beyond 1e10 the rope is overdamped for any load up to 1e8 kg")
    )
    attachment: Vec3 = eqx.field(metadata=unit("m"))
    slack: Scalar = eqx.field(metadata=unit("m") | plausible(0.0, 100.0, "more than the rope's length"))
    damping_onset: Scalar = eqx.field(
        metadata=unit("m") | plausible(0.0, 0.1, "a stretch of millimetres; 0 gives (2.14) as is")
    )

    def __init__(self, stiffness, damping, attachment, slack=0.0, damping_onset=1e-4):
        self.stiffness = f64(stiffness)
        self.damping = f64(damping)
        self.attachment = f64(attachment)
        self.slack = f64(slack)
        self.damping_onset = f64(damping_onset)

    def check(self):
        check_value("rope.stiffness", self.stiffness, unit="N/m", low=0.0, low_open=True, symbol="c_l")
        check_value("rope.damping", self.damping, unit="N s/m", low=0.0, symbol="b_l")
        check_value("rope.attachment", self.attachment, unit="m", shape=(3,), symbol="B")
        check_value("rope.slack", self.slack, unit="m", low=0.0)
        check_value("rope.damping_onset", self.damping_onset, unit="m", low=0.0, symbol="δ_0")


class Boom(eqx.Module):
    """The boom tip as a particle on three axis-aligned springs (paper eqs. 2.12-2.13).

    - `tip_position`: A, where the tip rests at t = 0 under its own weight with the rope slack [m].
    - `tip_mass`: m_0 [kg]; its weight G_0 = m_0 g acts on the tip.
    - `stiffness`: (k_X, k_Y, k_Z), equivalent boom stiffnesses [N/m].
    - `damping`: (c_X, c_Y, c_Z), equivalent boom damping [N s/m] (our addition; 0 is the paper's model).
    """

    tip_position: Vec3 = eqx.field(
        metadata=unit("m") | plausible(-1e4, 1e4, "the tallest cranes reach ~250 m")
    )
    tip_mass: Scalar = eqx.field(
        metadata=unit("kg")
        | plausible(1e-3, 1e7, "hook block and boom share: kg to t; under 1 g the tip's sqrt(k/m_0) explodes")
    )
    stiffness: Vec3 = eqx.field(
        metadata=unit("N/m") | plausible(1e3, 1e12, "crane booms: ~1e5 to 1e9; beyond 1e12 the boom is rigid")
    )
    damping: Vec3 = eqx.field(
        metadata=unit("N s/m")
        | plausible(0.0, 1e10, "beyond 1e10 the boom is overdamped for any tip mass up to 1e7 kg")
    )

    def __init__(self, tip_position, tip_mass, stiffness, damping=(0.0, 0.0, 0.0)):
        self.tip_position = f64(tip_position)
        self.tip_mass = f64(tip_mass)
        self.stiffness = f64(stiffness) * jnp.ones(3)
        self.damping = f64(damping) * jnp.ones(3)

    def check(self):
        check_value("boom.tip_position", self.tip_position, unit="m", shape=(3,), symbol="A")
        check_value("boom.tip_mass", self.tip_mass, unit="kg", low=0.0, low_open=True, symbol="m_0")
        check_value(
            "boom.stiffness",
            self.stiffness,
            unit="N/m",
            shape=(3,),
            low=0.0,
            low_open=True,
            symbol="k_X, k_Y, k_Z",
        )
        check_value("boom.damping", self.damping, unit="N s/m", shape=(3,), low=0.0)


# ---------------------------------------------------------------------------------------- scenario


class Scenario(eqx.Module):
    """Everything that defines one lift. A pytree: change a leaf with `eqx.tree_at` or `Scenario.replace`.

    - `load`, `foundation`, `rope`, `hoist`, `boom`: see their classes.
    - `gravity`: g [m/s²].
    - `name`: a label (static).
    - `t1`: default end time of a simulation [s] (static).
    - `description`: free text (static).
    - `allow_implausible`: accept values outside the parameters' plausible ranges (static, default False;
      each field's range and its reason are in its metadata, `jaxhoist._physics.checks.plausible`). Without
      it, `check()` refuses such a value (a typo like 1e16 for 1e6) before compiling; with it, the value
      is solved, and the solve's own checks (`SolveStatus`) still mark a result that is wrong.
    """

    load: Load
    foundation: Foundation
    rope: Rope
    hoist: AbstractHoistLaw
    boom: Boom
    gravity: Scalar = eqx.field(
        metadata=unit("m/s²") | plausible(0.1, 100.0, "the Moon 1.6, the Earth 9.81, Jupiter 24.8")
    )
    name: str = eqx.field(static=True)
    t1: float = eqx.field(static=True)
    description: str = eqx.field(static=True)
    allow_implausible: bool = eqx.field(static=True)

    def __init__(
        self,
        load,
        foundation,
        rope,
        hoist,
        boom,
        gravity=9.81,
        name="custom",
        t1=10.0,
        description="",
        allow_implausible=False,
    ):
        require_x64()
        self.load = load
        self.foundation = foundation
        self.rope = rope
        self.hoist = hoist
        self.boom = boom
        self.gravity = f64(gravity)
        self.name = name
        self.t1 = float(t1)
        self.description = str(description)
        self.allow_implausible = bool(allow_implausible)

    def __check_init__(self):
        self.check()

    def check(self) -> None:
        """Raise `ScenarioError` naming the first invalid field (concrete leaves only).

        Besides each field's hard limits, shape and dtype, the box geometry (C inside the box, B on or in
        it), the plausible range of every parameter (its field's `plausible` metadata: a value outside is
        refused unless `allow_implausible`), and the static sinking of the ground under the load's weight,
        m g / (4 k), less than the box height c (always: else the initial static state is absurd, the box
        would rest below the ground).
        """
        self.load.check()
        self.foundation.check()
        self.rope.check()
        self.hoist.check()
        self.boom.check()
        check_value("gravity", self.gravity, unit="m/s^2", low=0.0, symbol="g")
        if not (np.isfinite(self.t1) and self.t1 > 0):
            raise ScenarioError(f"t1 must be a positive finite time [s], got {self.t1}")
        s, b = concrete(self.load.size), concrete(self.rope.attachment)
        if s is not None and b is not None and np.any((b < -1e-12) | (b > s + 1e-12)):
            raise ScenarioError(
                f"rope.attachment (B) must lie on or inside the box 0 <= B <= size = {show(s)} m, "
                f"got {show(b)} m"
            )
        if not self.allow_implausible:
            check_plausible(self)
        m, g, k = (concrete(x) for x in (self.load.mass, self.gravity, self.foundation.stiffness))
        if s is not None and m is not None and g is not None and k is not None:
            with np.errstate(all="ignore"):
                sink = m * g / (4.0 * k)
            c = s[..., 2]
            if np.any(~np.isfinite(sink) | (sink >= c)):
                raise ScenarioError(
                    f"foundation.stiffness (k) = {show(k)} N/m is not plausible for load.mass m = "
                    f"{show(m)} kg: the load's weight would press the ground in by m g / (4 k) = "
                    f"{show(sink)} m, at least the box height c = {show(c)} m (stiffen the ground or "
                    f"lighten the load)"
                )

    def unlabelled(self) -> Scenario:
        """This scenario with its static labels (`name`, `t1`, `description`) set to fixed values: what a
        compiled solve is given, so that scenarios that differ only in their labels (the presets, a copy
        renamed in a notebook) share one compiled program instead of compiling again. No solve reads the
        labels (the saved times are resolved from `t1` before compiling). `allow_implausible` is set too:
        it is a setting of the host-side check, which the caller has run on the scenario already, so an
        opted-in scenario shares the compiled program of the others."""
        return dataclasses.replace(self, name="scenario", t1=1.0, description="", allow_implausible=True)

    def replace(self, **leaves) -> Scenario:
        """A copy with leaves replaced by dotted path.

        **Arguments**
        - `allow_implausible` (keyword, not a leaf): set the copy's `allow_implausible` (default: keep
          this scenario's).
        - `leaves`: `{dotted path: value}`, e.g. `replace(**{"foundation.friction_coefficient": 0.3})`;
          a value has the leaf's shape or broadcasts to it (a number for a 3-vector), in the leaf's unit.

        **Returns** the new `Scenario` (not checked: `simulate` and `check()` do that).

        **Raises** `ScenarioError` naming the path for a field that does not exist (with the closest
        field's name), a static setting (`t1`, `name`), a value that is not numeric or whose shape does
        not fit the leaf.
        """
        allow_implausible = leaves.pop("allow_implausible", None)
        new = replace_leaves(self, leaves)
        if allow_implausible is not None and bool(allow_implausible) != new.allow_implausible:
            new = copy.copy(new)  # a static field, set without running the checks (like the leaves)
            object.__setattr__(new, "allow_implausible", bool(allow_implausible))
        return new
