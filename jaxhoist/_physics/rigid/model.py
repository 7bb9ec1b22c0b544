"""The rigid-ground model of paper §2 as a choice of `simulate`: `RigidGround` and its rope, `ElasticRope`
(2.14) or `InextensibleRope` (2.15)."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx

from ..._errors import ScenarioError
from ..elastic import AbstractModel


class AbstractRope(eqx.Module):
    """How the rigid-ground model treats the rope (the elastic model always has the elastic rope (2.14))."""

    name: ClassVar[str]


class ElasticRope(AbstractRope):
    """The elastic, damped rope of eq. (2.14)."""

    name: ClassVar[str] = "elastic"


class InextensibleRope(AbstractRope):
    """The inextensible rope of eq. (2.15): a constraint with the boom tip's motion (rigid model only)."""

    name: ClassVar[str] = "inextensible"


class RigidGround(AbstractModel):
    """The paper's §2 model: the box on a rigid ground, phases chosen by events (rest, sliding, tipping,
    flight, impacts); solved by the host-side phase driver `simulate_rigid` (not differentiable).

    - `rope`: `ElasticRope()` (2.14, default) or `InextensibleRope()` (2.15).
    - `restitution`: Newton's coefficient e [-] of corner impacts, in [0, 1] (0, the default: plastic).

    **Raises** `ScenarioError` for a restitution outside [0, 1].
    """

    rope: AbstractRope = ElasticRope()
    restitution: float = 0.0

    def __check_init__(self):
        if not isinstance(self.rope, AbstractRope):
            raise ScenarioError(f"rope must be ElasticRope() or InextensibleRope(), got {self.rope!r}")
        e = float(self.restitution)
        if not (0.0 <= e <= 1.0):
            raise ScenarioError(f"restitution (e) must be in [0, 1], got {self.restitution}")
