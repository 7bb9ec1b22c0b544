"""The rigid-ground model's phase driver (paper §2): `simulate_rigid` (`solve`), its host-side phase loop
(`run`), the choice of contact configurations (`driver`), impacts and rope jerks (`impacts`), Coulomb
patterns (`coulomb`), the compliant phase (`compliant`), the compiled phase solves (`compiled`), the phase
log and trajectory (`records`) and `RigidOptions` (`options`). The elastic core does not import it."""

from .compiled import StallRule as StallRule
from .compliant import ChatterRule as ChatterRule
from .options import RigidOptions as RigidOptions
from .records import PhaseRecord as PhaseRecord
from .records import RigidContactError as RigidContactError
from .records import RigidTrajectory as RigidTrajectory
from .solve import simulate_rigid as simulate_rigid
