"""jaxhoist: a differentiable, vectorised simulator of a crane lifting a 3D load off the ground,
after Grabski & Strzałko, "Dynamic analysis of the load hoisting process" (2003)."""

import importlib.metadata as _metadata

from ._errors import Float64Error as Float64Error
from ._errors import ScenarioError as ScenarioError
from ._errors import SolveStatus as SolveStatus
from .apps.bifurcation import Bifurcation as Bifurcation
from .apps.bifurcation import find_crossings as find_crossings
from .apps.bifurcation import find_jumps as find_jumps
from .apps.bifurcation import locate_bifurcation as locate_bifurcation
from .apps.bifurcation import trace_boundary as trace_boundary
from .apps.classify import ChangeClass as ChangeClass
from .apps.classify import classify_change as classify_change
from .apps.classify import classify_samples as classify_samples
from .apps.identify import identify as identify
from .io.scenario import load_scenario as load_scenario
from .io.scenario import scenario_from_dict as scenario_from_dict
from .numerics.observables import Observable as Observable
from .numerics.options import ElasticFoundation as ElasticFoundation
from .numerics.options import ElasticRope as ElasticRope
from .numerics.options import InextensibleRope as InextensibleRope
from .numerics.options import RigidGround as RigidGround
from .numerics.options import SolverOptions as SolverOptions
from .numerics.rigid_solve import RigidContactError as RigidContactError
from .numerics.rigid_solve import RigidTrajectory as RigidTrajectory
from .numerics.rigid_solve import simulate_rigid as simulate_rigid
from .numerics.rosenbrock import RosenbrockW as RosenbrockW
from .numerics.scan import ScanResult as ScanResult
from .numerics.scan import ScanStatus as ScanStatus
from .numerics.scan import scan as scan
from .numerics.solve import Trajectory as Trajectory
from .numerics.solve import simulate as simulate
from .physics.elastic import State as State
from .physics.energy import Energy as Energy
from .physics.equilibrium import initial_state as initial_state
from .physics.equilibrium import linear_corner_loads as linear_corner_loads
from .physics.params import AbstractFrictionLaw as AbstractFrictionLaw
from .physics.params import AbstractHoistLaw as AbstractHoistLaw
from .physics.params import Boom as Boom
from .physics.params import BristleFriction as BristleFriction
from .physics.params import ConstantSpeedHoist as ConstantSpeedHoist
from .physics.params import Foundation as Foundation
from .physics.params import Load as Load
from .physics.params import ProfileHoist as ProfileHoist
from .physics.params import RampedHoist as RampedHoist
from .physics.params import RegularisedCoulomb as RegularisedCoulomb
from .physics.params import Rope as Rope
from .physics.params import Scenario as Scenario
from .physics.statics import rest_statics as rest_statics

try:  # the one version source is pyproject.toml, read from the installed package's metadata
    __version__ = _metadata.version("jaxhoist")
except _metadata.PackageNotFoundError:  # a source tree used without installing it
    __version__ = "unknown"  # as the result files write it (io.results)
