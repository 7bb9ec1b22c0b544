"""The rigid-ground model of the paper's §2: contact forces, the phase driver, and motions with known answers.

Every scenario here has the same pytree structure, name and t1 (static fields), and every solve saves the
same number of times, so the compiled phase solves are shared by all tests of this file.
"""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxhoist as jh
from jaxhoist._numerics.rigid.solve import RigidContactError, simulate_rigid
from jaxhoist._physics import rigid, statics

N_SAVE = 61
T1 = 1.5


def _scenario(
    *,
    size=(1.0, 1.0, 1.0),
    mass=1000.0,
    mu=0.3,
    attachment=(0.5, 0.0, 0.5),
    tip=(0.5, -10.0, 0.5),
    rope_stiffness=1e5,
    rope_damping=1e4,
    speed=0.1,
    travel=math.inf,
) -> jh.Scenario:
    """A box pulled by a soft rope from a stiff, light boom tip (tip deflection ~ S / 1e9 m); the hoist
    runs at `speed` from t = 0+ and stops dead after taking in `travel` metres of rope."""
    return jh.Scenario(
        load=jh.Load(list(size), mass),
        foundation=jh.Foundation(1e7, 1e5, mu),  # only μ is used by the rigid model
        rope=jh.Rope(rope_stiffness, rope_damping, list(attachment)),
        hoist=jh.RampedHoist(speed, 0.0, travel),
        boom=jh.Boom(list(tip), 10.0, 1e9, 2e5),
        name="rigid-test",
        t1=T1,
    )


# ---------------------------------------------------------------------------------- contact forces


def test_minimum_norm_corner_forces_are_the_linear_law(paper42):
    """Four coplanar sticking corners are statically indeterminate (12 force components, 6 equations). The
    minimum-norm solution of the equilibrium equations has the normal forces of the linear law (2.3),
    and the rigid model's contact solve returns exactly those."""
    sc = paper42.replace(**{"hoist.speed": 0.0})  # eccentric mass centre; no rope damping force at t = 0
    G = float(sc.load.mass * sc.gravity)
    S = np.array([0.07, 0.11, 0.35]) * G
    a, b, _ = np.asarray(sc.load.size)
    xy = np.array([[0, 0], [a, 0], [a, b], [0, b]])
    C, B = np.asarray(sc.load.mass_centre), np.asarray(sc.rope.attachment)
    # Equilibrium of forces and of moments about D, unknowns (T_x, T_y, N) per corner; numpy pinv.
    E = np.zeros((6, 12))
    for i, (x, y) in enumerate(xy):
        E[0:3, 3 * i : 3 * i + 3] = np.eye(3)
        E[3:6, 3 * i : 3 * i + 3] = np.array([[0, 0, y], [0, 0, -x], [-y, x, 0]])  # r × F with r = (x, y, 0)
    rhs = np.concatenate([-S + [0, 0, G], -np.cross(B, S) + np.cross(C, [0, 0, -G]) * -1.0])
    lam = np.linalg.pinv(E) @ rhs
    lin = np.asarray(statics.rest_statics_jit(sc, jnp.asarray(S)).corner_loads)
    np.testing.assert_allclose(lam[2::3], lin, rtol=1e-10)

    # The rigid model, load at rest, rope force S: put the boom tip where the rope carries exactly S.
    y0, c = rigid.initial_state(sc)
    e = S / np.linalg.norm(S)
    L = float(c.rope_length) + np.linalg.norm(S) / float(sc.rope.stiffness)
    y = eqx.tree_at(lambda s: s.tip_position, y0, jnp.asarray(B + L * e))
    ct = jax.jit(rigid.contact_dynamics)(0.0, y, sc, c, rigid.make_phase([rigid.STICK] * 4), rigid.Settings())
    assert float(ct.loads.rope_tension) == pytest.approx(np.linalg.norm(S), rel=1e-9)
    np.testing.assert_allclose(np.asarray(ct.force[:, 2]), lin, rtol=1e-8)
    np.testing.assert_allclose(np.asarray(ct.force).reshape(-1), lam, rtol=1e-6, atol=1e-8 * G)
    np.testing.assert_allclose(np.asarray(ct.accel), 0.0, atol=1e-9)


# ---------------------------------------------------------------------------------- sliding


def _analytic_slide(t, m, mu, g, c_l, b_l, v):
    """Displacement u(t) >= 0 of a box pulled through a horizontal rope l(t) = l0 - v t from a fixed point
    (tension c_l (v t - u) + b_l (v - du/dt)) against Coulomb friction μ m g, from rest: it starts at
    t_s = (μ m g - b_l v) / (c_l v) and then m ü + b_l u̇ + c_l u = c_l v t + b_l v - μ m g.
    With τ = t - t_s: u = v τ - 2ζv/ω + e^{-ζωτ}(A cos ω_d τ + B sin ω_d τ) (underdamped); the slip
    velocity is v times a second-order step response, so it never returns to zero (no sticking)."""
    t_s = (mu * m * g - b_l * v) / (c_l * v)
    w = math.sqrt(c_l / m)
    z = b_l / (2 * m * w)
    wd = w * math.sqrt(1 - z * z)
    A = 2 * z * v / w
    Bc = (-v + z * w * A) / wd
    tau = np.maximum(t - t_s, 0.0)
    u = v * tau - A + np.exp(-z * w * tau) * (A * np.cos(wd * tau) + Bc * np.sin(wd * tau))
    return np.where(t > t_s, u, 0.0), t_s


def _reference_slide(ts, m, mu, g, c_l, b_l, v, m0, k, c):
    """The same pull with the boom tip as a mass m0 on a spring k and damper c along the rope (the exact
    one-dimensional reduction of the 3-D model for this symmetric set-up), by scipy at tight tolerances.
    Returns u(ts) and the start of sliding."""
    from scipy.integrate import solve_ivp

    def tension(t, u, du, xa, dxa):
        return max(0.0, c_l * (v * t - u - xa) + b_l * (v - du - dxa))

    def rhs(t, y, sliding):
        u, du, xa, dxa = y
        S = tension(t, u, du, xa, dxa)
        acc = (S - mu * m * g) / m if sliding else 0.0
        return [du if sliding else 0.0, acc, dxa, (S - k * xa - c * dxa) / m0]

    onset = lambda t, y, sliding: tension(t, *y) - mu * m * g  # noqa: E731
    onset.terminal, onset.direction = True, 1
    kw = dict(method="DOP853", rtol=1e-12, atol=1e-14)
    a = solve_ivp(rhs, (0.0, ts[-1]), [0.0] * 4, args=(False,), events=onset, dense_output=True, **kw)
    t_s = float(a.t_events[0][0])
    b = solve_ivp(rhs, (t_s, ts[-1]), a.y_events[0][0], args=(True,), dense_output=True, **kw)
    assert np.all(b.y[1] >= 0.0)  # it keeps sliding
    return np.where(ts <= t_s, 0.0, b.sol(np.maximum(ts, t_s))[0]), t_s


@pytest.fixture(scope="module")
def slide_run():
    sc = _scenario()
    return sc, simulate_rigid(sc, jh.Times(T1, n=N_SAVE))


def test_sliding_under_steady_pull_matches_analytic_motion(slide_run):
    """A 1000 kg cube pulled horizontally through the middle of a face (no yaw, no tipping): it rests until
    the pull reaches μmg, then slides with the motion of the damped, ramp-forced oscillator."""
    sc, tr = slide_run
    m, mu, g = 1000.0, 0.3, 9.81
    ts = np.asarray(tr.ts)
    u_ref, t_s = _reference_slide(ts, m, mu, g, 1e5, 1e4, 0.1, 10.0, 1e9, 2e5)
    u_rigid_boom, t_s0 = _analytic_slide(ts, m, mu, g, 1e5, 1e4, 0.1)
    # Phases: rest until the pull reaches μ m g (the statics slide threshold), then all four corners slide.
    ph = tr.phases
    assert ph[0].rest and ph[0].end == "rest:slip"
    assert ph[0].t_end == pytest.approx(t_s, abs=1e-7)  # the phase solves run at rtol 1e-8
    assert ph[1].contact == ("slide",) * 4
    assert all(p.contact == ("slide",) * 4 for p in ph[1:]) and ph[-1].end == "t1"
    # Pure translation along -Y, as the one-dimensional reference to 1e-8 m over 0.13 m of sliding.
    y = np.asarray(tr.position[:, 1])
    np.testing.assert_allclose(0.5 - y, u_ref, atol=1e-8)
    assert float(0.5 - y[-1]) > 0.1
    np.testing.assert_allclose(np.asarray(tr.position[:, 0]), 0.5, atol=1e-9)
    np.testing.assert_allclose(np.asarray(tr.position[:, 2]), 0.5, atol=1e-9)
    np.testing.assert_allclose(np.asarray(tr.euler), 0.0, atol=1e-8)
    # The closed form for a rigid boom: the boom tip's deflection S/k ~ 3 µm (and its rate, through the rope
    # damper) delays the start by 4e-5 s and shifts the motion by < 3e-5 m.
    assert t_s - t_s0 == pytest.approx(3.9e-5, abs=0.2e-5)
    np.testing.assert_allclose(0.5 - y, u_rigid_boom, atol=3e-5)
    # Coulomb friction while sliding: Σ|T_i| = μ N with N = m g (horizontal rope), along +Y.
    sliding = ts > t_s + 1e-3
    T = np.asarray(tr.friction_forces)
    np.testing.assert_allclose(T[sliding, :, 1].sum(axis=1), mu * m * g, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(tr.ground_reaction), m * g, rtol=1e-9)
    # Friction work = μ m g × distance, and the energy balance closes.
    np.testing.assert_allclose(np.asarray(tr.friction_work)[-1], mu * m * g * (0.5 - y[-1]), rtol=1e-6)
    resid = np.abs(np.asarray(tr.energy_residual()))
    assert resid.max() < 1e-6 * float(np.asarray(tr.hoist_work)[-1])


def test_outputs_of_any_size(slide_run):
    """100 001 saved times on the 1.5 s pull (the outputs are evaluated in chunks; one vmap over 25 001
    samples never returned): every sample is the same motion as the 61-sample run's phases and follows the
    one-dimensional reference, and the per-sample forces and the energy balance are those of sliding."""
    sc, ref = slide_run
    n = 100_001
    tr = simulate_rigid(sc, jh.Times(T1, n=n))
    ts = np.asarray(tr.ts)
    assert ts.shape == (n,) and np.asarray(tr.normal_forces).shape == (n, 4)
    assert [(p.contact, p.rest) for p in tr.phases] == [(p.contact, p.rest) for p in ref.phases]
    assert tr.phases[0].t_end == pytest.approx(ref.phases[0].t_end, abs=1e-9)
    u_ref, t_s = _reference_slide(ts, 1000.0, 0.3, 9.81, 1e5, 1e4, 0.1, 10.0, 1e9, 2e5)
    np.testing.assert_allclose(0.5 - np.asarray(tr.position[:, 1]), u_ref, atol=1e-8)
    # The last chunk is padded: its samples are still the right ones (the final state, at t1).
    np.testing.assert_allclose(np.asarray(tr.position)[-1], np.asarray(ref.position)[-1], atol=1e-9)
    np.testing.assert_allclose(np.asarray(tr.ground_reaction), 1000.0 * 9.81, rtol=1e-9)
    # Coulomb friction μN once the slip is well under way (the first ms after the start, at slip speeds
    # below 1e-8 m/s, the slip direction still blends with the phase's starting hint).
    sliding = ts > t_s + 0.05
    np.testing.assert_allclose(
        np.asarray(tr.friction_forces)[sliding, :, 1].sum(axis=1), 0.3 * 1000.0 * 9.81, rtol=1e-9
    )
    assert np.all(np.asarray(tr.phase_index)[ts < t_s - 1e-3] == 0)
    resid = np.abs(np.asarray(tr.energy_residual()))
    assert resid.max() < 1e-6 * float(np.asarray(tr.hoist_work)[-1])


def _tall_box(**over):
    """A tall box (1 x 1 x 2 m, μ = 0.9) pulled obliquely upwards from the middle of its top front edge;
    `over`: further keywords of `_scenario`."""
    return _scenario(
        size=(1.0, 1.0, 2.0),
        mu=0.9,
        attachment=(0.5, 0.0, 2.0),
        tip=(0.5, -6.0, 10.0),
        rope_stiffness=2e5,
        rope_damping=2e4,
        speed=0.05,
        **over,
    )


def test_tipping_about_an_edge_at_the_statics_threshold():
    """A tall box with high friction, pulled obliquely upwards from the middle of its top front edge, tips
    about its front bottom edge DE (F, H lift) when the pull reaches the statics tip threshold."""
    sc = _tall_box()
    tr = simulate_rigid(sc, jh.Times(T1, n=N_SAVE))
    ph = tr.phases
    assert ph[0].rest and ph[0].end == "rest:tip"
    assert ph[1].contact == ("stick", "stick", "free", "free") and not ph[1].rest
    # The rope force at the end of the rest phase is the tipping pull of statics for its direction.
    ld = jax.jit(rigid.loads)(ph[0].t_end, ph[0].state_end, sc, rigid.initial_state(sc)[1])
    S = float(ld.rope_tension)
    s_tip, kind, edges = statics.tip_threshold(sc, np.asarray(ld.rope_direction))
    assert (kind, edges) == ("tip-edge", ("DE",))
    assert S == pytest.approx(s_tip, rel=1e-6)
    # Then it rotates about DE (pitch φ about the body ξ axis), the edge stays put and F, H rise.
    late = np.asarray(tr.ts) > ph[1].t_start + 0.2
    corners = np.asarray(tr.corners)
    assert np.all(corners[late, 2:, 2] > 1e-4)
    np.testing.assert_allclose(corners[late, :2, 2], 0.0, atol=1e-9)
    resid = np.abs(np.asarray(tr.energy_residual()))
    assert resid.max() < 1e-6 * float(np.asarray(tr.hoist_work)[-1])


def _rocking_box():
    """A tall box (1 x 1 x 2 m, μ = 0.9) whose hoist stops dead just after it starts to tip about DE."""
    return _tall_box(travel=0.018)


def test_rocking_impacts_settle_and_the_energy_balance_closes():
    """The hoist stops dead (the rope loses its damping force b_l v at once) just after the tall box has
    started to tip about DE: it falls back, edge FH strikes the ground, the box rocks on alternate edges
    with plastic impacts (restitution 0) losing energy at each, and settles flat. The energy lost in the
    impacts closes the balance E(t) - E(0) = W_hoist - D_damping - W_friction - W_impact."""
    sc = _rocking_box()
    tr = simulate_rigid(sc, jh.Times(T1, n=N_SAVE))
    ph = tr.phases
    assert ph[0].end == "rest:tip" and ph[1].contact == ("stick", "stick", "free", "free")
    impacts = [p for p in ph if "impact" in p.end]
    assert len(impacts) >= 3
    assert "impact:FH" in impacts[0].end and "impact:DE" in impacts[1].end  # rocking on alternate edges
    assert ph[-1].rest and ph[-1].end == "t1" and "settled" in ph[-2].end
    loss = np.asarray(tr.impact_loss)
    assert np.all(np.diff(loss) >= 0) and loss[-1] > 0.03  # J; the first impact alone takes 0.038 J
    resid = np.abs(np.asarray(tr.energy_residual()))
    assert resid.max() < 1e-4 * loss[-1]
    # At rest again, flat: all four corners on the ground, the load still.
    np.testing.assert_allclose(np.asarray(tr.corners)[-1, :, 2], 0.0, atol=1e-8)
    np.testing.assert_allclose(np.asarray(tr.velocity)[-1], 0.0, atol=1e-12)


def test_errors_are_raised_not_guessed():
    with pytest.raises(jh.ScenarioError, match=r"restitution \(e\) must be in \[0, 1\], got 1.5"):
        jh.RigidGround(restitution=1.5)
    # A phase budget too small for the rocking sequence: a clear error naming the last phases.
    sc = _rocking_box()
    with pytest.raises(RigidContactError, match="(?s)max_phases = 3.*impact:FH"):
        simulate_rigid(sc, jh.Times(T1, n=N_SAVE), options=jh.RigidOptions(max_phases=3))


def test_model_switch_and_cli_reach_the_rigid_driver(slide_run, tmp_path):
    """`simulate(..., model=RigidGround())` and `jaxhoist simulate --model rigid` run the same phase driver:
    the same sliding motion (bit for bit: same solver, same settings), and the CLI's energy residual includes
    the impact losses."""
    from jaxhoist._apps.cli.app import main
    from jaxhoist._io.results import load_trajectory

    sc, ref = slide_run
    opts = jh.SolverOptions(rtol=1e-8, atol=1e-9)
    tr = jh.simulate(sc, jh.Times(T1, n=N_SAVE), model=jh.RigidGround(), options=opts)
    assert isinstance(tr, jh.RigidTrajectory)
    assert isinstance(tr, jh.Trajectory) and bool(tr.ok)  # one trajectory type: the rigid one is a subclass
    np.testing.assert_array_equal(np.asarray(tr.position), np.asarray(ref.position))
    with pytest.raises(jh.ScenarioError, match="model"):
        fixed = jh.SolverOptions(diffrax.Tsit5(), diffrax.ConstantStepSize(), dt0=1e-3)
        jh.simulate(sc, T1, model=jh.RigidGround(), options=fixed)

    path = tmp_path / "rigid.toml"
    a, b, c = (float(x) for x in sc.load.size)
    # Same name and t1 (static fields) as `_scenario`, so the CLI reuses the phase solve compiled above.
    path.write_text(f"""
name = "rigid-test"
t1 = {T1}
[load]
size = [{a}, {b}, {c}]
mass = {float(sc.load.mass)}
[foundation]
stiffness = {float(sc.foundation.stiffness)}
damping = {float(sc.foundation.damping)}
friction_coefficient = {float(sc.foundation.friction_coefficient)}
[rope]
stiffness = {float(sc.rope.stiffness)}
damping = {float(sc.rope.damping)}
attachment = {np.asarray(sc.rope.attachment).tolist()}
[hoist]
law = "ramped"
speed = {float(sc.hoist.speed)}
ramp_time = 0.0
[boom]
tip_position = {np.asarray(sc.boom.tip_position).tolist()}
tip_mass = {float(sc.boom.tip_mass)}
stiffness = {np.asarray(sc.boom.stiffness).tolist()}
damping = {np.asarray(sc.boom.damping).tolist()}
""")
    assert (
        main(
            [
                "simulate",
                str(path),
                "--model",
                "rigid",
                "--n-save",
                str(N_SAVE),
                "--rtol",
                "1e-8",
                "--atol",
                "1e-9",
                "--out",
                str(tmp_path / "out"),
                "--no-plots",
                "--quiet",
            ]
        )
        == 0
    )
    arrays = load_trajectory(tmp_path / "out" / "trajectory")
    np.testing.assert_allclose(arrays["position"], np.asarray(ref.position), atol=1e-12)
    np.testing.assert_allclose(arrays["energy_residual"], np.asarray(ref.energy_residual()), atol=1e-9)
