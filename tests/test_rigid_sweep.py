"""The rigid model near its presets: friction values around paper-2.3 that used to raise
`RigidContactError` now complete, with the contact choice the stiff-foundation limit makes, the grazing
impact resolved by the documented fallback (recorded in the phase log), and the energy balance closed.

The full sweep (μ = 0.10-0.50, both presets, both ropes, v_l and the rope point varied) is
`experiments/figures/rigid_sweep.py`; these are its fast subset. Every preset run here saves `N_SAVE` times
and, but for the stall test's run without the rule, uses `RigidOptions()`, so one compiled phase solve (and
one compliant-phase chunk solve) serves them all (`simulate_rigid` compiles for any preset's labels alike).
"""

from pathlib import Path

import numpy as np
import pytest

import jaxhoist as jh
from jaxhoist._numerics.rigid.solve import simulate_rigid

N_SAVE = 201


def _run(mu: float, t1: float):
    sc = jh.load_scenario("paper-2.3").replace(**{"foundation.friction_coefficient": mu})
    return simulate_rigid(sc, jh.Times(t1, n=N_SAVE))


def _closes(tr) -> bool:
    """The energy balance closes to the tolerance of tests/test_rigid.py: 1e-6 of the hoist work."""
    resid = np.abs(np.asarray(tr.energy_residual()))
    return bool(resid.max() < 1e-6 * float(np.asarray(tr.hoist_work)[-1]))


@pytest.mark.parametrize("mu", [0.252, 0.255, 0.27])
def test_landing_on_three_corners_follows_the_stiff_foundation_limit(mu):
    """After the load drops back onto D and E (paper-2.3, t ≈ 9.7-11.0 s), the rigid contact problem has
    two consistent three-corner configurations (D or E free). The linear corner-load law (2.3) of the
    flat landing gives D a negative load, so the stiff-foundation rule frees D and the box is carried on E,
    F, H, as the stiff elastic foundation carries it (no "non-uniqueness" error)."""
    tr = _run(mu, 11.1)
    ph = tr.phases
    assert ph[-1].end == "t1" and float(tr.ts[-1]) == pytest.approx(11.1)
    landing = [k for k, p in enumerate(ph) if "stiff-foundation rule" in p.choice]
    assert landing, tr.phase_log()
    p = ph[landing[0]]
    assert p.contact == ("free", "slide", "slide", "slide")
    assert "impact:DE" in ph[landing[0] - 1].end or "normal:D" in ph[landing[0] - 1].end
    # While it lasts, D is off the ground and E, F, H carry the load.
    idx = np.asarray(tr.phase_index) == landing[0]
    if idx.any():
        N = np.asarray(tr.normal_forces)[idx]
        G = 9.81 * float(jh.load_scenario("paper-2.3").load.mass)
        assert np.all(N[:, 0] == 0.0) and np.all(N[:, 1:] >= -1e-6 * G)
    assert min(q.t_end - q.t_start for q in ph) >= 1e-6
    assert _closes(tr)


def test_grazing_impact_drops_friction_and_is_logged(monkeypatch):
    """μ = 0.26 without the persistent-contact rule (with it, H is held on the ground after its impact at
    10.76 s and the path differs): the load pivots on F (sticking) and corner E grazes the ground at
    16.92 s (under 2 µm of travel). No Coulomb impulse is consistent with F sticking; the documented
    fallback takes the frictionless impulse, books its (small) loss and notes it in the phase log; the lift
    goes on."""
    from jaxhoist._numerics.rigid import run as rigid_run

    monkeypatch.setattr(rigid_run, "PERSISTENT_CONTACT", False)
    tr = _run(0.26, 17.0)
    ph = tr.phases
    assert ph[-1].end == "t1"
    grazing = [p for p in ph if "friction dropped" in p.end or "projected" in p.end]
    assert grazing and 16.8 < grazing[0].t_end < 17.0, tr.phase_log()
    k = ph.index(grazing[0])
    loss = float(grazing[0].end.split("impact:")[1].split("(")[1].split(" J")[0])
    assert 0.0 <= loss < 1.0  # J: a touch, not a drop
    assert ph[k + 1].contact[2] != "free"  # still on F afterwards
    assert np.all(np.diff(np.asarray(tr.impact_loss)) >= 0.0)
    assert _closes(tr)


# ------------------------------------------------------------------------------ sustained cycles


def test_chatter_rule_detects_dense_non_decaying_impacts_only():
    """The detection of `ChatterRule`: at least `min_impacts` impacts within `window` whose losses do not
    decay (or four times as many, decaying or not); a decaying train of a settling load is left alone."""
    from jaxhoist._numerics.rigid.compliant import ChatterRule

    rule = ChatterRule(window=0.05, min_impacts=12, decay=0.5)
    steady = [(10.0 + 1.7e-3 * k, 0.13) for k in range(20)]  # paper-2.3's F-H chatter: 0.13 J every 1.7 ms
    assert "20 impacts" in rule.detect(steady, steady[-1][0])
    assert rule.detect(steady[:11], steady[10][0]) == ""  # too few yet
    sparse = [(10.0 + 0.01 * k, 0.13) for k in range(20)]  # 5 in any 50 ms
    assert rule.detect(sparse, sparse[-1][0]) == ""
    settling = [(10.0 + 2e-3 * k, 0.5 * 0.8**k) for k in range(20)]  # losses fall by 0.8 per impact
    assert rule.detect(settling, settling[-1][0]) == ""
    dense = [(10.0 + 5e-4 * k, 0.5 * 0.95**k) for k in range(60)]  # 60 in 30 ms: passed even though decaying
    assert rule.detect(dense, dense[-1][0]) != ""
    # Contact changes without impacts (a see-saw between two configurations every few µs): 48 in 50 ms.
    seesaw = [2.0927 + 2e-6 * k for k in range(48)]
    assert "48 contact changes" in rule.detect_switching(seesaw, seesaw[-1])
    assert rule.detect_switching(seesaw[:47], seesaw[46]) == ""
    assert rule.detect_switching([0.1 * k for k in range(60)], 5.9) == ""  # spread over 6 s
    # Bad settings: one clear line naming the field.
    with pytest.raises(jh.ScenarioError, match="ChatterRule.stiffness"):
        jh.RigidOptions(chatter=ChatterRule(stiffness=-1.0))
    with pytest.raises(jh.ScenarioError, match="ChatterRule.max_regularised"):
        jh.RigidOptions(chatter=ChatterRule(max_regularised=0))


def test_compliant_phase_passes_a_rocking_train_and_hands_back_at_rest():
    """The compliant phase on a small case: the tall box of tests/test_rigid.py falls back after tipping and
    would rock on alternate edges; with a rule that triggers at the first impact, the train is integrated
    on the stiff, critically damped corner springs instead, the box settles flat on them, the state is
    handed back (all four corners on the ground) and the rigid model rests. The phase log records the
    compliant phase; the energy balance closes with the hand-back booked with the impact losses."""
    import math

    from jaxhoist._numerics.rigid.compliant import ChatterRule

    sc = jh.Scenario(
        load=jh.Load([1.0, 1.0, 2.0], 1000.0),
        foundation=jh.Foundation(1e7, 1e5, 0.9),
        rope=jh.Rope(2e5, 2e4, [0.5, 0.0, 2.0]),
        hoist=jh.RampedHoist(0.05, 0.0, 0.018),
        boom=jh.Boom([0.5, -6.0, 10.0], 10.0, 1e9, 2e5),
        name="rigid-test",
        t1=1.5,
    )
    rule = ChatterRule(window=1.0, min_impacts=1, decay=0.0)
    tr = simulate_rigid(sc, jh.Times(1.5, n=61), options=jh.RigidOptions(chatter=rule))
    ph = tr.phases
    comp = [k for k, p in enumerate(ph) if p.choice.startswith("compliant phase")]
    assert len(comp) == 1, tr.phase_log()
    p = ph[comp[0]]
    assert "impact:FH" in ph[comp[0] - 1].end  # the first impact triggered it
    assert p.contact == ("spring",) * 4 and "loaded DEFH" in p.end
    hand_back = float(p.end.split("hand-back ")[1].split(" J")[0])
    assert abs(hand_back) < 1e-3  # J: the corners moved by ~G/4k = 1.6e-8 m
    assert ph[-1].rest and ph[-1].end == "t1"
    # Inside the compliant phase the corner springs carry the load; the samples report their forces.
    idx = np.asarray(tr.phase_index) == comp[0]
    assert idx.any()
    G = 1000.0 * float(sc.gravity)
    assert np.all(np.asarray(tr.ground_reaction)[idx] > 0.2 * G)
    # At rest again, flat, and the energy balance closes (the impact losses include the hand-back).
    np.testing.assert_allclose(np.asarray(tr.corners)[-1, :, 2], 0.0, atol=1e-8)
    loss = np.asarray(tr.impact_loss)
    resid = np.abs(np.asarray(tr.energy_residual()))
    assert resid.max() < 1e-4 * loss[-1] + 1e-6 * float(np.asarray(tr.hoist_work)[-1]), resid.max()
    assert math.isfinite(float(loss[-1]))


def test_persistent_contact_holds_a_corner_the_impact_would_lift():
    """μ = 0.26: H strikes at 10.76 s while the load pivots on F. The impulse would lift F at 0.1 mm/s
    (below `Settings.rest_velocity`), which used to start a train of alternating F and H impacts; the
    persistent-contact rule removes that normal velocity (plastic for both) and the load goes on on F and H
    together, as the stiff elastic foundation carries it (docs/rigid-model.md, "Persistent contact")."""
    tr = _run(0.26, 17.0)
    ph = tr.phases
    held = [k for k, p in enumerate(ph) if "persistent contact (F held" in p.end]
    assert held, tr.phase_log()
    k = held[0]
    assert "impact:H" in ph[k].end and 10.7 < ph[k].t_end < 10.8
    assert ph[k + 1].contact[2:] == ("slide", "slide")  # F and H both on the ground afterwards
    v_n = float(ph[k].end.split("|v_n| <= ")[1].split(" m/s")[0])
    assert v_n < 1e-3
    assert ph[-1].end == "t1" and _closes(tr)


def test_stall_rule_finds_a_stalled_phase_after_thousands_of_steps():
    """paper-4.2 (elastic rope): the first sliding phase (all four corners, 0.305 ms) stalls, its mean step
    falling to about 1e-7 s. The `StallRule` (mean step under 2e-7 s over 5000 step attempts) ends it after
    5000 attempts, where without it the phase runs to `max_steps` (here 12 000 instead of the default
    200 000, to stay cheap); either way the stalled solve is
    dropped and the phase is chosen again from its start without that configuration, so the trajectory is
    the same sample for sample and only the steps spent differ. The run with the rule has the default
    `max_steps`, which changes nothing there (its one stall note is the rule's, so no phase of it reaches
    12 000 steps): it is the phase solve of the other tests here."""
    sc = jh.load_scenario("paper-4.2")
    t1 = 0.1
    n = 12_000  # max_steps of the run without the rule
    fast = simulate_rigid(sc, jh.Times(t1, n=N_SAVE))
    slow = simulate_rigid(sc, jh.Times(t1, n=N_SAVE), options=jh.RigidOptions(max_steps=n, stall=None))
    notes = [p.choice for p in fast.phases if "stalled" in p.choice]
    assert len(notes) == 1 and "stalled (mean step < 2e-07 s over 5000 steps)" in notes[0], fast.phase_log()
    assert any("stalled at max_steps" in p.choice for p in slow.phases), slow.phase_log()
    np.testing.assert_array_equal(np.asarray(fast.position), np.asarray(slow.position))
    np.testing.assert_array_equal(np.asarray(fast.normal_forces), np.asarray(slow.normal_forces))
    assert [str(p).split("[")[0] for p in fast.phases] == [str(p).split("[")[0] for p in slow.phases]
    # The stalled solve cost at most one window of 5000 attempts (all attempts counted, the accepted ones
    # reported) instead of max_steps: the slow run spent at least max_steps - 5000 more (measured 13 130).
    spent = int(slow.num_accepted_steps) - int(fast.num_accepted_steps)
    assert spent > n - 5_000, (int(slow.num_accepted_steps), int(fast.num_accepted_steps))


def test_stall_rule_rejects_invalid_values():
    from jaxhoist._numerics.rigid.solve import StallRule

    for bad in (StallRule(window=0), StallRule(min_step=0.0), StallRule(min_step=float("nan"))):
        with pytest.raises(jh.ScenarioError, match="StallRule"):
            jh.RigidOptions(stall=bad)


# ------------------------------------------------------------------- no consistent configuration, repeatedly

EDGE_STATE = Path(__file__).parent / "data" / "rigid_edge_state.npz"


def _edge_run(chatter, max_phases: int, span: float):
    """The rigid model (elastic rope, `RigidOptions()` otherwise) from the stored state of paper-4.1 with the
    rope point B at ξ = 0.25 m, resting on its edge F-H at t0 = 47.976 s (`tests/data/
    make_rigid_edge_state.py`), for `span` seconds, with the `ChatterRule` `chatter` and `max_phases`."""
    import jax.numpy as jnp

    from jaxhoist._numerics.rigid.compiled import Options
    from jaxhoist._numerics.rigid.driver import Driver
    from jaxhoist._numerics.rigid.options import DRIVER_TOLERANCES
    from jaxhoist._numerics.rigid.run import Run
    from jaxhoist._physics import rigid
    from jaxhoist._physics.elastic import State

    sc = jh.load_scenario("paper-4.1").replace(**{"rope.attachment": [0.25, 0.0, 2.5]})
    sc = sc.unlabelled()  # as simulate_rigid gives its kernels: the phase solve of the other runs here
    with np.load(EDGE_STATE) as z:
        t0 = float(z["t"])
        y0 = State(**{k: jnp.asarray(z[k]) for k in z.files if k != "t"})
    _, c = rigid.initial_state(sc)
    o, settings = jh.RigidOptions(), rigid.Settings()
    assert o.stall is not None
    opt = Options(o.rtol, o.atol, o.max_steps, 1e-10, o.stall.window, o.stall.min_step)  # as simulate_rigid
    drv = Driver(sc, c, settings, opt, 0.0, dict(DRIVER_TOLERANCES))
    # N_SAVE saved times, as every run here: the same compiled phase and chunk solves
    run = Run(drv, np.linspace(t0, t0 + span, N_SAVE), t0 + span, max_phases, o.max_steps, chatter, False)
    run.resume(t0, y0)
    while run.step():
        pass
    return run.result(c, settings)


def test_repeated_least_violation_choice_goes_compliant_until_a_configuration_is_consistent():
    """paper-4.1, B at ξ = 0.25 m, on the edge F-H: no configuration passes the consistency check (F and H
    sticking need |T_H| = 4.4 kN > μN_H = 2.6 kN with the minimum-norm split of their tangential forces), so
    fallback 3 runs F:stick H:stick as a regularised phase; H's friction guard ends it within microseconds
    and the same choice follows. Without the rule this went on (48 times, then 40 ms compliant, then again)
    until `max_phases` (the sweep, at 47.2 s); with it, the fourth such choice in a row hands over to the
    compliant phase, which is extended while its end would need the fallback again. The log says why; the
    energy balance closes."""
    from jaxhoist._numerics.rigid.compliant import ChatterRule
    from jaxhoist._numerics.rigid.records import RigidContactError

    with pytest.raises(RigidContactError, match="max_phases = 20"):
        _edge_run(ChatterRule(max_regularised=10**6), max_phases=20, span=0.1)

    tr = _edge_run(ChatterRule(), max_phases=20, span=0.1)
    ph = tr.phases
    comp = [k for k, p in enumerate(ph) if p.choice.startswith("compliant phase")]
    assert comp == [1], tr.phase_log()
    # Three regularised F:stick H:stick phases of about 1 µs (one record: sub-µs phases are merged).
    first = ph[0]
    assert first.choice.startswith("regularised: no consistent configuration"), tr.phase_log()
    assert first.contact == ("free", "free", "stick", "stick") and "=> 2 phases < 1 µs" in first.end
    p = ph[1]
    assert "no consistent configuration 4 times in a row" in p.choice and "|T_H|" in p.choice
    assert "extended 1 time:" in p.choice and p.contact == ("free", "free", "spring", "spring")
    assert p.t_end - p.t_start > 0.07  # s: two episodes (each >= 30 ms steady, in 10 ms chunks)
    # Then a consistent configuration: H slides, F sticks, to t1.
    assert ph[2].contact == ("free", "free", "stick", "slide") and ph[2].choice == "" and ph[2].end == "t1"
    resid = np.abs(np.asarray(tr.energy_residual()))
    assert resid.max() < 1e-6 * float(np.asarray(tr.hoist_work)[-1]), resid.max()
