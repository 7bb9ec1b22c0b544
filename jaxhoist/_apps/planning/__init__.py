"""Lift planning under uncertainty: distributions over scenario inputs (`uncertain`), named thresholded
outcomes (`hazards`) and the probability of each at every point of a design grid (`risk`)."""

from .hazards import Hazard as Hazard
from .hazards import no_liftoff as no_liftoff
from .hazards import overload as overload
from .hazards import slide as slide
from .hazards import strike as strike
from .hazards import swing as swing
from .hazards import tilt as tilt
from .risk import LiftRisk as LiftRisk
from .risk import lift_risk as lift_risk
from .uncertain import AbstractDistribution as AbstractDistribution
from .uncertain import Fixed as Fixed
from .uncertain import LogNormal as LogNormal
from .uncertain import Normal as Normal
from .uncertain import TruncatedNormal as TruncatedNormal
from .uncertain import Uniform as Uniform
