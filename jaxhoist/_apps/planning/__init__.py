"""Lift planning under uncertainty: distributions over scenario inputs (`uncertain`), named thresholded
outcomes (`hazards`), the probability of each at every point of a design grid (`risk`), and the design
that minimises a smooth expected outcome within bounds (`optimise`)."""

from .hazards import Hazard as Hazard
from .hazards import no_liftoff as no_liftoff
from .hazards import overload as overload
from .hazards import slide as slide
from .hazards import strike as strike
from .hazards import swing as swing
from .hazards import tilt as tilt
from .hazards import tip as tip
from .optimise import OptimisedLift as OptimisedLift
from .optimise import optimise_lift as optimise_lift
from .risk import LiftRisk as LiftRisk
from .risk import lift_risk as lift_risk
from .uncertain import AbstractDistribution as AbstractDistribution
from .uncertain import Fixed as Fixed
from .uncertain import LogNormal as LogNormal
from .uncertain import Normal as Normal
from .uncertain import TruncatedNormal as TruncatedNormal
from .uncertain import Uniform as Uniform
