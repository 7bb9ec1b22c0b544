"""Record the state that `tests/test_rigid_sweep.py` starts from to test the rule for a repeated
least-violation choice (docs/rigid-model.md, "Resolution of contact choices and impacts").

paper-4.1 (μ = 0.15) with the rope point B moved to ξ = 0.25 m and the elastic rope: from about 35 s the load
rests on its edge F-H, and at times no contact configuration passes the consistency check (F and H sticking
would need |T_H| > μN_H with the minimum-norm split of their tangential forces). This script runs the rigid
model to the first choice after `T_FROM` that needs fallback 3 (the least-violating configuration) and stores
the state there, before that choice, in `tests/data/rigid_edge_state.npz` (t [s] and the `State` fields in SI
units). About 2 minutes on one core.

    PYTHONPATH=$PWD python tests/data/make_rigid_edge_state.py
"""

from __future__ import annotations

from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._numerics.rigid.solve import simulate_rigid  # noqa: E402

OUT = Path(__file__).parent / "rigid_edge_state.npz"
T_FROM = 46.0  # [s]
T1 = 70.0  # [s]: the preset's t1, as in experiments/figures/rigid_sweep.py


def scenario() -> jh.Scenario:
    """paper-4.1 with B at ξ = 0.25 m on the top face (the sweep's variant "B xi+0.25 m")."""
    return jh.load_scenario("paper-4.1").replace(**{"rope.attachment": [0.25, 0.0, 2.5]})


def main() -> None:
    from jaxhoist._numerics.rigid import run as rigid_run

    found: dict = {}
    step = rigid_run.Run.step

    class _Found(Exception):
        pass

    def watching(run):  # after each phase: the state the next choice was made at, if it is fallback 3
        more = step(run)
        if run.drv.regularised and run.t >= T_FROM and "t" not in found:
            found.update(t=run.t, y=run.y)  # run.y: the event state the choice was made at
            raise _Found
        return more

    rigid_run.Run.step = watching
    try:
        simulate_rigid(scenario(), jh.Times(T1, n=501))
    except _Found:
        pass
    finally:
        rigid_run.Run.step = step
    y = found["y"]
    fields = {k: np.asarray(getattr(y, k)) for k in y.__dataclass_fields__}
    np.savez(OUT, t=np.float64(found["t"]), **fields)
    print(f"t = {found['t']!r} s -> {OUT}")


if __name__ == "__main__":
    main()
