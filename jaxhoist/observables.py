"""Outcomes of one lift for scans and bifurcation maps (public).

    import jaxhoist as jh
    from jaxhoist import observables as obs

    obs.names()                                        # the named observables ("final_psi", ...)
    jh.scan(sc, jh.Grid({"foundation.friction_coefficient": mus}), 10.0,
            observables=["final_psi", obs.detachment_time_difference("E", "D")])

An observable is a pure JAX function `fn(traj, scenario)` of one trajectory wrapped in an `Observable` with
its name, unit and component labels; see the "Observables" section of the bifurcation guide.
"""

from ._numerics.observables import CORNERS as CORNERS
from ._numerics.observables import Observable as Observable
from ._numerics.observables import contact_function as contact_function
from ._numerics.observables import detachment_time_difference as detachment_time_difference
from ._numerics.observables import first_down_crossing as first_down_crossing
from ._numerics.observables import first_return as first_return
from ._numerics.observables import get as get
from ._numerics.observables import last_down_crossing as last_down_crossing
from ._numerics.observables import names as names
