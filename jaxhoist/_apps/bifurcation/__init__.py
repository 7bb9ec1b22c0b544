"""Where does the motion change character? The public names of the bifurcation tools, from the modules that
hold them:

- `jumps`: `find_jumps`, `find_crossings` and their `Jump` brackets on a 1-D scan;
- `locate`: `locate_bifurcation` (refinement of one bracket to a tolerance, with derivative-accelerated
  root finding) and `locate_jumps` (every candidate of a scan); `multisection` its vmapped multisection
  rounds; `eval` the indicator and the compiled solves;
- `trace`: `trace_boundary` (continuation of a two-parameter boundary);
- `options`: `SearchOptions` and the methods `Newton`, `Bisection`, `Multisection`;
- `result`: `Bifurcation`, `Boundary`, `BifurcationError`;
- `classify`: `classify_change`, `classify_samples`, `ChangeClass` (what a located change is).

The `jaxhoist bifurcation` command lives in `_apps/cli/bifurcation.py`.

    import jaxhoist as jh
    from jaxhoist import observables as obs
    b = jh.locate_bifurcation(sc, "load.mass_centre[0]", obs.detachment_time_difference("E", "D"),
                              (0.4, 0.6), search=jh.SearchOptions(tol=1e-6), times=jh.Times(0.2, n=101))
    print(b.summary())
"""

from .classify import ChangeClass as ChangeClass
from .classify import classify_change as classify_change
from .classify import classify_samples as classify_samples
from .jumps import Jump as Jump
from .jumps import find_crossings as find_crossings
from .jumps import find_jumps as find_jumps
from .locate import locate_bifurcation as locate_bifurcation
from .locate import locate_jumps as locate_jumps
from .options import AbstractSearchMethod as AbstractSearchMethod
from .options import Bisection as Bisection
from .options import Multisection as Multisection
from .options import Newton as Newton
from .options import SearchOptions as SearchOptions
from .result import Bifurcation as Bifurcation
from .result import BifurcationError as BifurcationError
from .result import Boundary as Boundary
from .trace import trace_boundary as trace_boundary
