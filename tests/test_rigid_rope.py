"""The rigid model's inextensible rope (paper eq. 2.15): lift-off against the hand derivation, the rope jerk
at an impulsive start and at re-tensioning, the energy balance with the jerk losses, the elastic rope's
convergence to it as c_l grows, and the switch's errors.

The scenarios share the pytree structure, name and t1 of `tests/test_rigid.py` (and the same number of
saved times), so the compiled phase solve is shared with that file.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

import jaxhoist as jh
from jaxhoist._numerics.rigid.solve import simulate_rigid

N_SAVE = 61
T1 = 1.5
#: The rigid model with the inextensible rope (2.15).
INEXTENSIBLE = jh.RigidGround(rope=jh.InextensibleRope())
M, M0, G = 1000.0, 10.0, 9.81  # load and boom-tip masses [kg], gravity [m/s²]
K_Z, C_Z = 1e6, 2e3  # boom stiffness [N/m] and damping [N s/m] in Z (X, Y: 1e9 N/m, rigid)
V = 0.1  # hoist speed [m/s]
RAMP = 0.2  # hoist speed-up time [s]
V_JERK = 0.2  # hoist speed of the jerk tests: the jerk gives the load 2e-3 m/s > Settings.rest_velocity


def _scenario(*, ramp=RAMP, speed=V, rope_stiffness=1e5, slack=0.0, boom_damping=C_Z) -> jh.Scenario:
    """A 1 m cube of 1000 kg lifted by a vertical rope through its mass centre (B on the top face above C)
    from a boom tip 9 m above B; the tip is rigid in X, Y and sprung (k_Z, c_Z) in Z."""
    return jh.Scenario(
        load=jh.Load([1.0, 1.0, 1.0], M),
        foundation=jh.Foundation(1e7, 1e5, 0.3),  # only μ is used by the rigid model
        rope=jh.Rope(rope_stiffness, 0.0, [0.5, 0.5, 1.0], slack=slack),
        hoist=jh.RampedHoist(speed, ramp),
        boom=jh.Boom([0.5, 0.5, 10.0], M0, [1e9, 1e9, K_Z], [0.0, 0.0, boom_damping]),
        name="rigid-test",
        t1=T1,
    )


def _hand_tension(sc: jh.Scenario):
    """S(t) [N] of the inextensible rope while the load rests: the tip is driven down by s(t), so
    S = k_Z s + c_Z ds/dt + m_0 d²s/dt² (eq. 2.13 with Z_A = Z_A(0) - s(t), the springs holding m_0 g at
    t = 0)."""
    h = sc.hoist

    def S(t):
        t = jnp.asarray(t, dtype=jnp.float64)
        s, s_dot = h.shortening(t), h.rate(t)
        s_ddot = jax.jvp(h.rate, (t,), (jnp.ones_like(t),))[1]
        return float(K_Z * s + C_Z * s_dot + M0 * s_ddot)

    return S


@pytest.fixture(scope="module")
def ramped_lift():
    sc = _scenario()
    return sc, simulate_rigid(sc, jh.Times(T1, n=N_SAVE), model=INEXTENSIBLE)


def test_inextensible_lift_off_matches_the_hand_derivation(ramped_lift):
    """Ramped hoist (no jerk): the load rests while the rope drives the boom tip down; S follows the tip's
    equation of motion and the load lifts off when S = m g."""
    sc, tr = ramped_lift
    S_hand = _hand_tension(sc)
    t_lift = brentq(lambda t: S_hand(t) - M * G, 1e-3, T1, xtol=1e-14)
    ph = tr.phases
    assert ph[0].rest and ph[0].rope == "taut" and ph[0].end == "rest:tip"
    assert ph[0].t_end == pytest.approx(t_lift, abs=1e-8)  # phase solves at rtol 1e-8
    assert ph[1].contact == ("free",) * 4 and ph[1].rope == "taut"
    ts = np.asarray(tr.ts)
    resting = ts < ph[0].t_end
    S = np.asarray(tr.rope_tension)
    np.testing.assert_allclose(S[resting], [S_hand(t) for t in ts[resting]], rtol=1e-7, atol=1e-6 * M * G)
    # While taut the rope keeps its length l(t) = l0 - s(t) (Baumgarte-stabilised constraint).
    st = tr.states
    AB = np.linalg.norm(np.asarray(st.tip_position) - (np.asarray(st.position) + [0.0, 0.0, 0.5]), axis=1)
    length = 9.0 - np.asarray(jax.vmap(sc.hoist.shortening)(tr.ts))
    np.testing.assert_allclose(AB, length, atol=1e-8)
    # After lift-off the load rises; the rope never pushes; the energy balance closes (no losses here).
    assert np.all(S >= -1e-6 * M * G) and float(tr.position[-1, 2]) > 0.6
    assert float(tr.impact_loss[-1]) == 0.0
    resid = np.abs(np.asarray(tr.energy_residual()))
    assert resid.max() < 1e-7 * float(tr.hoist_work[-1])


def test_elastic_rope_converges_to_the_inextensible_one(ramped_lift):
    """The same lift with the elastic rope (2.14) of growing stiffness c_l (no rope damping) approaches the
    inextensible rope's, at first order in 1/c_l. At lift-off both ropes carry m g; the elastic one is then
    stretched by m g / c_l, and its stretch rate k_Z v / c_l slows the tip and its damper, c_Z v / c_l less
    force: the hoist needs (m g + c_Z v) / (c_l v) longer (quasi-statically; the tip-rope oscillation adds
    0.2 % here)."""
    sc, ref = ramped_lift
    t_ref = ref.phases[0].t_end
    ts = np.asarray(ref.ts)
    dt, dS, dz = [], [], []
    c_ls = (1e7, 1e8, 1e9)
    for c_l in c_ls:
        tr = simulate_rigid(_scenario(rope_stiffness=c_l), jh.Times(T1, n=N_SAVE))
        assert tr.phases[0].rest and tr.phases[0].end == "rest:tip" and len(tr.phases) == 2
        dt.append(tr.phases[0].t_end - t_ref)
        before = ts < t_ref  # both still resting
        dS.append(np.max(np.abs(np.asarray(tr.rope_tension)[before] - np.asarray(ref.rope_tension)[before])))
        dz.append(np.max(np.abs(np.asarray(tr.position)[:, 2] - np.asarray(ref.position)[:, 2])))
    for c_l, d in zip(c_ls, dt, strict=True):
        assert d == pytest.approx((M * G + C_Z * V) / (c_l * V), rel=5e-3)
    # Tension while resting and the load's height over the whole lift: differences shrink like 1/c_l.
    assert dS[0] / dS[1] > 8.0 and dS[1] / dS[2] > 8.0 and dS[2] < 1e-3 * M * G
    assert dz[0] / dz[1] > 8.0 and dz[1] / dz[2] > 8.0 and dz[2] < 1e-4


@pytest.fixture(scope="module")
def jerk_runs():
    """The hoist at full speed from t = 0 (ramp 0): the taut rope jerks at the start (at V_JERK, and at V,
    slow enough to settle); and at V_JERK with the rope 5 mm slack at t = 0: it snaps taut at 0.025 s."""
    runs = {}
    for key, sc in [
        ("start", _scenario(ramp=0.0, speed=V_JERK)),
        ("settle", _scenario(ramp=0.0)),
        ("slack", _scenario(ramp=0.0, speed=V_JERK, slack=0.005)),
    ]:
        runs[key] = simulate_rigid(sc, jh.Times(T1, n=N_SAVE), model=INEXTENSIBLE)
    return runs


def test_rope_jerk_at_the_start_and_at_re_tension(jerk_runs):
    """The plastic rope jerk shares the impulse P = μ v_l (μ = m m_0/(m + m_0)) between the tip and the
    load (the ground cannot hold the load down): the load leaves with v_l m_0/(m + m_0), the hoist does
    P v_l and ½ μ v_l² is lost. Slack at the start: the same jerk when |AB| reaches l(t), at
    t = slack / v_l. A jerk that would move the load slower than `Settings.rest_velocity` (1e-3 m/s) leaves
    it at rest (the settling rule of the corner impacts): then only the tip jerks and ½ m_0 v_l² is lost."""
    mu, v = M * M0 / (M + M0), V_JERK
    tr = jerk_runs["start"]
    assert float(tr.velocity[0, 2]) == pytest.approx(v * M0 / (M + M0), rel=1e-9)
    assert float(tr.tip_position[0, 2]) == pytest.approx(10.0, abs=1e-12)
    assert float(tr.states.tip_velocity[0, 2]) == pytest.approx(-v * M / (M + M0), rel=1e-9)
    assert float(tr.impact_loss[0]) == pytest.approx(0.5 * mu * v**2, rel=1e-9)
    assert float(tr.hoist_work[0]) == pytest.approx(mu * v**2, rel=1e-9)

    tr = jerk_runs["settle"]
    assert float(tr.velocity[0, 2]) == 0.0 and tr.phases[0].rest and tr.phases[0].rope == "taut"
    assert float(tr.states.tip_velocity[0, 2]) == pytest.approx(-V, rel=1e-12)
    assert float(tr.impact_loss[0]) == pytest.approx(0.5 * M0 * V**2, rel=1e-12)

    ph = jerk_runs["slack"].phases
    assert ph[0].rest and ph[0].rope == "slack" and "rope:taut rope-jerk" in ph[0].end
    assert ph[0].t_end == pytest.approx(0.005 / v, abs=1e-9)
    assert ph[1].rope == "taut"
    # The jerk's loss (the log gives 4 digits), then a few much smaller bounces and jerks.
    jerk = 0.5 * mu * v**2
    assert f"rope-jerk ({jerk:.4g} J)" in ph[0].end
    loss = np.asarray(jerk_runs["slack"].impact_loss)
    after = np.asarray(jerk_runs["slack"].ts) > ph[0].t_end
    assert np.all(loss[~after] == 0.0)
    assert np.all(loss[after] >= jerk * (1 - 1e-9)) and np.all(loss[after] <= 1.02 * jerk)


def test_energy_balance_closes_with_the_rope_jerk_losses(jerk_runs):
    """E(t) - E(0) = W_hoist - D_damping - W_friction - W_impact with the jerk's loss in W_impact (and the
    later bounces of the load on the ground and re-tension jerks). Without booking the jerk the residual
    would be ½ μ v_l² (0.05 to 0.2 J)."""
    for tr in jerk_runs.values():
        loss = np.asarray(tr.impact_loss)
        assert np.all(np.diff(loss) >= 0) and loss[-1] >= 0.049
        resid = np.abs(np.asarray(tr.energy_residual()))
        assert resid.max() < 2e-2 * loss[-1]
        assert resid.max() < 1e-6 * float(tr.hoist_work[-1])
        assert float(tr.position[-1, 2]) > 0.55  # lifted in the end


def test_rope_switch_errors():
    from jaxhoist._apps.cli.app import main

    assert main(["simulate", "paper-4.1", "--rope", "inextensible", "--quiet", "--no-plots"]) == 2
    with pytest.raises(SystemExit):
        main(["simulate", "paper-4.1", "--model", "rigid", "--rope", "chain"])


def test_model_switch_reaches_the_inextensible_rope(ramped_lift):
    """`jaxhoist.simulate(..., model=RigidGround(rope=InextensibleRope()))` is
    `simulate_rigid(..., model=RigidGround(rope=InextensibleRope()))`: the same lift."""
    sc, ref = ramped_lift
    # simulate and simulate_rigid share their defaults (max_steps is static in the compiled solve: the same
    # value reuses it).
    model = jh.RigidGround(rope=jh.InextensibleRope())
    tr = jh.simulate(sc, jh.Times(T1, n=N_SAVE), model=model, options=jh.SolverOptions(rtol=1e-8, atol=1e-9))
    np.testing.assert_array_equal(np.asarray(tr.position), np.asarray(ref.position))
    assert [p.rope for p in tr.phases] == [p.rope for p in ref.phases]
    assert math.isfinite(float(tr.rope_tension[-1]))


def test_cli_runs_the_inextensible_rope(ramped_lift, tmp_path):
    """`jaxhoist simulate FILE --model rigid --rope inextensible` gives the same lift."""
    from jaxhoist._apps.cli.app import main
    from jaxhoist._io.results import load_trajectory

    _, ref = ramped_lift
    path = tmp_path / "rope.toml"
    path.write_text(f"""
name = "rigid-test"
t1 = {T1}
[load]
size = [1.0, 1.0, 1.0]
mass = {M}
[foundation]
stiffness = 1e7
damping = 1e5
friction_coefficient = 0.3
[rope]
stiffness = 1e5
damping = 0.0
attachment = [0.5, 0.5, 1.0]
[hoist]
law = "ramped"
speed = {V}
ramp_time = {RAMP}
[boom]
tip_position = [0.5, 0.5, 10.0]
tip_mass = {M0}
stiffness = [1e9, 1e9, {K_Z}]
damping = [0.0, 0.0, {C_Z}]
""")
    args = ["simulate", str(path), "--model", "rigid", "--rope", "inextensible", "--n-save", str(N_SAVE)]
    args += ["--rtol", "1e-8", "--atol", "1e-9", "--out", str(tmp_path / "out")]
    assert main([*args, "--no-plots", "--quiet"]) == 0
    arrays = load_trajectory(tmp_path / "out" / "trajectory")
    np.testing.assert_allclose(arrays["position"], np.asarray(ref.position), atol=1e-12)
    np.testing.assert_allclose(arrays["rope_tension"], np.asarray(ref.rope_tension), atol=1e-6)


def test_no_phase_shorter_than_a_microsecond():
    """A container (paper-4.2's box and mass, centred mass centre) lifted straight up through C by the
    inextensible rope: all four corners let go at once. The contact choice just past lift-off may keep a
    diagonal pair that carries no load (D, F sticking), which its own guards end a few nanoseconds later;
    such a sub-microsecond phase is merged into the previous record (`min_phase`, 1 µs), so the log goes
    from rest straight to flight. The motion itself is the symmetric lift: level, all corners rising
    together, the energy balance closing with the start's jerk losses."""
    a, b, c = 2.5, 6.0, 2.5
    sc = jh.Scenario(
        load=jh.Load([a, b, c], 31875.0),
        foundation=jh.Foundation(1e7, 1e5, 0.3),
        rope=jh.Rope(1e5, 0.0, [a / 2, b / 2, c]),
        hoist=jh.RampedHoist(0.3, 0.0),
        boom=jh.Boom([a / 2, b / 2, 10.0], 500.0, [5e6, 5e6, 5e6], [0.0, 0.0, 2e3]),
        name="rigid-test",
        t1=T1,
    )
    tr = simulate_rigid(sc, jh.Times(T1, n=N_SAVE), model=INEXTENSIBLE)
    ph = tr.phases
    assert min(p.t_end - p.t_start for p in ph) >= 1e-6
    lift = [k for k, p in enumerate(ph) if p.rest and "rest:tip" in p.end]
    assert len(lift) == 1 and ph[lift[0] + 1].contact == ("free",) * 4 and ph[-1].end == "t1"
    # Records are contiguous in time and every saved sample points at the record that covers it.
    assert all(p.t_end == q.t_start for p, q in zip(ph[:-1], ph[1:], strict=True))
    ts, idx = np.asarray(tr.ts), np.asarray(tr.phase_index)
    starts, ends = np.array([p.t_start for p in ph]), np.array([p.t_end for p in ph])
    assert np.all(np.diff(idx) >= 0) and np.all((starts[idx] <= ts) & (ts <= ends[idx]))
    # Symmetric lift: level (no tilt), the four corners at one height, rising after lift-off.
    late = ts > ph[lift[0]].t_end + 0.1
    np.testing.assert_allclose(np.asarray(tr.euler)[:, :2], 0.0, atol=1e-8)
    z = np.asarray(tr.corners)[:, :, 2]
    np.testing.assert_allclose(z - z[:, :1], 0.0, atol=1e-9)
    assert np.all(z[late] > 1e-4)
    resid = np.abs(np.asarray(tr.energy_residual()))
    assert resid.max() < 1e-6 * float(tr.hoist_work[-1])
