"""Where does the motion change character? The public names of the bifurcation tools, from the modules that
hold them:

- `bifurcation_jumps`: `find_jumps`, `find_crossings` and their `Jump` brackets on a 1-D scan;
- `bifurcation_locate`: `locate_bifurcation` (refinement of one bracket to a tolerance, with
  derivative-accelerated root finding) and `locate_jumps` (every candidate of a scan);
  `bifurcation_multisection` its vmapped multisection rounds; `bifurcation_eval` the indicator and the
  compiled solves;
- `bifurcation_trace`: `trace_boundary` (continuation of a two-parameter boundary);
- `bifurcation_options`: `SearchOptions` and the methods `Newton`, `Bisection`, `Multisection`;
- `bifurcation_result`: `Bifurcation`, `Boundary`, `BifurcationError`;
- `bifurcation_cli`: the `jaxhoist bifurcation` command.

    import jaxhoist as jh
    from jaxhoist import observables as obs
    b = jh.locate_bifurcation(sc, "load.mass_centre[0]", obs.detachment_time_difference("E", "D"),
                              (0.4, 0.6), search=jh.SearchOptions(tol=1e-6), times=jh.Times(0.2, n=101))
    print(b.summary())
"""

from .bifurcation_cli import configure_parser as configure_parser
from .bifurcation_cli import run_cli as run_cli
from .bifurcation_jumps import Jump as Jump
from .bifurcation_jumps import find_crossings as find_crossings
from .bifurcation_jumps import find_jumps as find_jumps
from .bifurcation_locate import locate_bifurcation as locate_bifurcation
from .bifurcation_locate import locate_jumps as locate_jumps
from .bifurcation_options import AbstractSearchMethod as AbstractSearchMethod
from .bifurcation_options import Bisection as Bisection
from .bifurcation_options import Multisection as Multisection
from .bifurcation_options import Newton as Newton
from .bifurcation_options import SearchOptions as SearchOptions
from .bifurcation_result import Bifurcation as Bifurcation
from .bifurcation_result import BifurcationError as BifurcationError
from .bifurcation_result import Boundary as Boundary
from .bifurcation_trace import trace_boundary as trace_boundary
