"""The two friction laws under a sustained pull below μN: the bristle law sticks, the regularised
Coulomb law creeps at the speed its regularisation predicts.

Set-up: a uniform 37.5 t box pulled horizontally through a rope at mid-height of its η = 0 face; a ramped
hoist takes in 66 mm of rope and stops at t ≈ 1.8 s, leaving a steady pull of about half of μmg.
"""

import numpy as np
import pytest

import jaxhoist as jh

MU = 0.3
TS = np.linspace(0.0, 6.0, 121)


def _scenario(law):
    return jh.Scenario(
        load=jh.Load([2.5, 6.0, 2.5], density=1000.0),
        foundation=jh.Foundation(1.5e7, 2e5, MU, law),
        rope=jh.Rope(1e6, 1e4, [1.25, 0.0, 1.25]),
        hoist=jh.RampedHoist(0.05, 0.5, 0.066),
        boom=jh.Boom([1.25, -20.0, 1.244], 500.0, 5e6, 5e3),
        t1=6.0,
    )


@pytest.fixture(scope="module", params=["bristle", "coulomb"])
def held(request):
    law = jh.BristleFriction() if request.param == "bristle" else jh.RegularisedCoulomb(1e-3)
    tr = jh.simulate(_scenario(law), jh.Times(ts=TS))
    return request.param, tr


def _window_mean(x, lo, hi):
    m = (TS >= lo) & (TS <= hi)
    return x[m].mean()


def test_hold_below_breakaway(held):
    name, tr = held
    y = np.asarray(tr.position[:, 1])
    ratio = np.asarray(tr.rope_tension) / (MU * np.asarray(tr.ground_reaction))
    # The pull is well below sliding (T/μN ~ 0.5) for the whole hold.
    assert 0.3 < _window_mean(ratio, 2.5, 6.0) < 0.7
    drift = _window_mean(y, 5.5, 6.0) - _window_mean(y, 2.5, 3.0)
    if name == "bristle":
        # Truly sticks: the elastic bristles hold the load; 1 µm is far below any physical scale here
        # (the bristle deflection is 1 mm; measured drift ~1e-9 m).
        assert abs(drift) < 1e-6
    else:
        # Creeps at the speed where the regularised law balances the pull: ε r / sqrt(1 - r²), r = T/(μN).
        eps = 1e-3
        v = eps * ratio / np.sqrt(1.0 - ratio**2)
        centre = (TS >= 2.75) & (TS <= 5.75)
        predicted = -np.trapezoid(v[centre], TS[centre])
        # 10 %: the window means and the trapezoid rule on 0.05 s samples, not the physics, limit agreement.
        assert drift == pytest.approx(predicted, rel=0.1)
        assert drift < -1e-3
