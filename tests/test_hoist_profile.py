"""`jaxhoist.KnotHoist`, a hoist speed profile through knots whose values are array leaves: the law against
the other hoist laws and an independent monotone interpolation, its shortening against its speed, the
forward sensitivities of a scan with respect to a knot speed against central differences, the scenario
file's `law = "knots"`, a knot speed as a design path of `optimise_lift`, and the checks made before
anything is compiled.

The solves use a low 2 m x 2 m x 0.5 m box of 1000 kg on a soft rope (30 kN/m) at the middle of its top
face, the boom tip 0.6 m aside and 8.5 m up, hoisted for 2 s along a profile that ramps to 0.25 m/s in
0.5 s and then speeds up to 0.4 m/s: the box is dragged and lifts a corner within the 2 s.
"""

import jax

jax.config.update("jax_enable_x64", True)  # tests/conftest.py also does this

import _inputs  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.interpolate import CubicHermiteSpline, PchipInterpolator  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._io.scenario import scenario_from_dict  # noqa: E402

TIMES = [0.0, 0.5, 1.5, 3.0]
SPEEDS = [0.0, 0.25, 0.4, 0.3]
T1 = 2.0


def profile(**over) -> jh.KnotHoist:
    kw = dict(times=TIMES, speeds=SPEEDS) | over
    return jh.KnotHoist(**kw)


def box(hoist) -> jh.Scenario:
    return jh.Scenario(
        load=jh.Load([2.0, 2.0, 0.5], 1000.0),
        foundation=jh.Foundation(1.5e7, 2.0e5, 0.3, jh.RegularisedCoulomb(1e-3)),
        rope=jh.Rope(3e4, 3e3, [1.0, 1.0, 0.5]),
        hoist=hoist,
        boom=jh.Boom([1.6, 1.0, 8.5], 500.0, 5.0e6, 5.0e3),
        name="drag-box",
        t1=T1,
    )


def _grid(t0=0.0, t1=5.0, n=2001):
    return np.linspace(t0, t1, n)


def test_equal_knots_after_a_ramp_reproduce_the_constant_speed_hoist():
    """Knots (0, 0), (T, v), (3, v), (6, v): after the ramp the speed is v exactly and the shortening is
    v t less the v T / 2 the smoothstep ramp lags behind (so the law is RampedHoist(v, T) at every t, and
    ConstantSpeedHoist(v) shifted by v T / 2 after T); equal knots from t = 0 are ConstantSpeedHoist(v)."""
    v, T = 0.3, 1.2
    t = _grid(0.0, 9.0)
    ramp = jh.KnotHoist([0.0, T, 3.0, 6.0], [0.0, v, v, v])
    const, ramped = jh.ConstantSpeedHoist(v), jh.RampedHoist(v, T)
    s, s_c, s_r = (np.asarray(h.shortening(jnp.asarray(t))) for h in (ramp, const, ramped))
    after = t >= T
    np.testing.assert_allclose(s[after], s_c[after] - v * T / 2, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.asarray(ramp.rate(jnp.asarray(t[after]))), v, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s, s_r, rtol=0, atol=1e-14)
    flat = jh.KnotHoist([0.0, 2.0, 5.0], [v, v, v])
    np.testing.assert_allclose(np.asarray(flat.shortening(jnp.asarray(t))), s_c, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.asarray(flat.rate(jnp.asarray(t))), v, rtol=0, atol=1e-15)


def test_speed_is_the_monotone_interpolant_and_the_shortening_its_integral():
    """The speed passes through the knots, has the interior slopes of scipy's PCHIP (and 0 at the ends), so
    it equals scipy's cubic Hermite spline with those slopes; it never leaves the range of its two
    neighbouring knots; the shortening's derivative (forward mode and central differences) is the speed,
    and its value is the spline's exact integral."""
    h = profile()
    t = _grid(0.0, 4.0)
    v = np.asarray(h.speed_at(jnp.asarray(t)))
    slopes = PchipInterpolator(TIMES, SPEEDS).derivative()(TIMES)
    slopes[0] = slopes[-1] = 0.0
    ref = CubicHermiteSpline(TIMES, SPEEDS, slopes)
    inside = t <= TIMES[-1]
    np.testing.assert_allclose(v[inside], ref(t[inside]), rtol=0, atol=1e-14)
    np.testing.assert_allclose(v[~inside], SPEEDS[-1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(h.speed_at(jnp.asarray(TIMES))), SPEEDS, atol=1e-15)
    for a, b, va, vb in zip(TIMES[:-1], TIMES[1:], SPEEDS[:-1], SPEEDS[1:], strict=True):
        seg = v[(t >= a) & (t <= b)]
        assert seg.min() >= min(va, vb) - 1e-15 and seg.max() <= max(va, vb) + 1e-15
    ds = np.asarray(jax.vmap(jax.grad(h.shortening))(jnp.asarray(t)))
    np.testing.assert_allclose(ds, v, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.asarray(h.rate(jnp.asarray(t))), v, rtol=0, atol=1e-15)
    eps = 1e-6
    fd = (np.asarray(h.shortening(jnp.asarray(t + eps))) - np.asarray(h.shortening(jnp.asarray(t - eps)))) / (
        2 * eps
    )
    np.testing.assert_allclose(fd, v, rtol=0, atol=1e-8)
    for tt in (0.3, 1.0, 2.2, 3.7):  # scipy's exact integral of the spline, then the last knot's speed
        q = ref.integrate(0.0, min(tt, TIMES[-1])) + SPEEDS[-1] * max(tt - TIMES[-1], 0.0)
        assert float(h.shortening(jnp.asarray(tt))) == pytest.approx(q, rel=1e-13, abs=1e-15)


def test_travel_stops_the_hoist():
    """With travel L the shortening is min(s(t), L) and the rate drops to 0 where the rope reaches it."""
    h = profile(travel=0.5)
    free = profile()
    t = _grid()
    s, s_free = (np.asarray(x.shortening(jnp.asarray(t))) for x in (h, free))
    np.testing.assert_allclose(s, np.minimum(s_free, 0.5), rtol=0, atol=1e-15)
    r = np.asarray(h.rate(jnp.asarray(t)))
    assert np.all(r[s_free > 0.5] == 0.0)
    np.testing.assert_allclose(r[s_free < 0.5], np.asarray(free.rate(jnp.asarray(t)))[s_free < 0.5])


def test_knot_speed_sensitivities_agree_with_central_differences():
    """A scan over `hoist.speeds[2]` (the third knot, 0.4 m/s at 1.5 s) with forward sensitivities: d/dv of
    the final position (x, z) and of the ground slide, against central differences of the same scan at
    v ± 1e-4 m/s, solved at rtol 1e-8, atol 1e-10.

    Tolerance 0.1 %; measured 6e-8, 7e-9 and 3e-4 (relative). The ground slide is read at the end of
    contact interpolated between the saved times (every 50 ms here), a rational function of the contact
    function's values there: its derivative in v changes sign within ±4e-3 m/s, so wider steps measure
    the curvature (h = 2e-3: 11 % off; the quotient converges to the sensitivity as h², 2e-5 at
    h = 2e-5). At the default tolerances (rtol 5e-4,
    atol 1e-5) the solver's noise in the values, some 1e-4 m, spoils the difference quotients of the
    final x by 4 to 11 % for h = 5e-3 to 1e-3 (measured), while the sensitivities themselves change
    smoothly with v (by 4 % over ±1e-2); tight tolerances make the quotient the derivative's. A
    sensitivity that missed the knot's effect on the rope's rate or length would be off by far more: the
    knot changes the shortening by 1.03 m per m/s at t = 2 s."""
    sc = box(profile())
    path, v, h = "hoist.speeds[2]", 0.4, 1e-4
    res = jh.scan(
        sc,
        jh.Points({path: [v, v + h, v - h]}),
        jh.Times(T1, n=41),
        observables=("final_x", "final_z", "ground_slide"),
        derivatives=True,
        options=jh.SolverOptions(rtol=1e-8, atol=1e-10, max_steps=200_000),
    )
    assert np.all(res.ok)
    for name in ("final_x", "final_z", "ground_slide"):
        vals = np.asarray(res[name])
        fd = (vals[1] - vals[2]) / (2 * h)
        d = float(np.asarray(res[f"d_{name}"])[0, 0])
        assert abs(d) > 1e-2, (name, d)  # the knot moves the box
        assert d == pytest.approx(fd, rel=1e-3), (name, d, fd)


def test_scenario_file_reads_the_knots():
    data = {
        "t1": T1,
        "load": {"size": [2.0, 2.0, 0.5], "mass": 1000.0},
        "foundation": {"stiffness": 1.5e7, "damping": 2.0e5, "friction_coefficient": 0.3},
        "rope": {"stiffness": 3e4, "damping": 3e3, "attachment": [1.0, 1.0, 0.5]},
        "hoist": {"law": "knots", "times": TIMES, "speeds": SPEEDS, "max_speed": 0.5, "travel": 4.0},
        "boom": {"tip_position": [1.6, 1.0, 8.5], "tip_mass": 500.0, "stiffness": 5e6},
    }
    sc = scenario_from_dict(data, "knots.toml")
    assert isinstance(sc.hoist, jh.KnotHoist)
    np.testing.assert_array_equal(np.asarray(sc.hoist.speeds), SPEEDS)
    assert float(sc.hoist.max_speed) == 0.5 and float(sc.hoist.travel) == 4.0
    assert jh.param_unit(sc, "hoist.speeds[1]") == "m/s"
    assert float(jh.get_param(sc, "hoist.speeds[1]")) == 0.25
    moved = jh.set_param(sc, "hoist.speeds[1]", 0.3)
    assert float(moved.hoist.speeds[1]) == 0.3 and float(moved.hoist.speeds[2]) == 0.4
    bad = [
        ({"times": [0.0, 1.0, 1.0, 3.0]}, "hoist.times must increase strictly, got times[2]"),
        ({"times": [0.5, 1.0, 2.0, 3.0]}, "hoist.times must start at 0 s"),
        ({"speeds": [0.0, -0.1, 0.4, 0.3]}, "hoist.speeds (v_k) must be >= 0"),
        ({"speeds": [0.0, 0.25, 0.6, 0.3]}, "hoist.speeds[2] = 0.6 m/s is above hoist.max_speed"),
        ({"speeds": [0.0, 0.25, 0.4]}, "hoist.speeds must hold one speed per knot time (4)"),
        ({"times": 3.0}, "hoist.times must be a list of numbers"),
        ({"speeds": [0.0, "fast", 0.4, 0.3]}, "hoist.speeds must be a number"),
        ({"speed": 0.3}, "unknown field 'hoist.speed'"),
        ({"speeds": [0.0, 25.0, 0.4, 0.3], "max_speed": float("inf")}, "hoist.speeds = "),
    ]
    for change, message in bad:
        d = {**data, "hoist": {**data["hoist"], **change}}
        with pytest.raises(jh.ScenarioError) as e:
            scenario_from_dict(d, "knots.toml")
        assert message in str(e.value) and "knots.toml" in str(e.value), (change, str(e.value))
        assert "\n" not in str(e.value)


def _trap(*args, **kwargs):
    raise AssertionError("the scan was reached with an invalid knot")


def _optimise(bounds):
    """`optimise_lift` of the peak rope tension under uncertain μ, with the design `bounds`."""
    mu = {"foundation.friction_coefficient": jh.Uniform(0.2, 0.4)}
    return lambda sc: jh.optimise_lift(sc, mu, "max_rope_tension", bounds)


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (_optimise({"hoist.speeds[2]": (0.2, 0.6)}), "hoist.speeds[2] = 0.6 m/s is above hoist.max_speed"),
        (_optimise({"hoist.times[1]": (0.5, 2.0)}), "hoist.times must increase strictly"),
        (
            lambda sc: jh.lift_risk(
                sc,
                {"foundation.friction_coefficient": jh.Uniform(0.2, 0.4)},
                [jh.slide(0.5)],
                {"hoist.speeds[1]": [0.2, -0.1]},
            ),
            "hoist.speeds (v_k) must be >= 0",
        ),
    ],
)
def test_bad_knots_fail_before_compiling(monkeypatch, call, field):
    from jaxhoist._apps.planning import optimise as opt_mod
    from jaxhoist._apps.planning import risk as risk_mod

    monkeypatch.setattr(opt_mod, "scan", _trap)
    monkeypatch.setattr(risk_mod, "scan", _trap)
    sc = box(profile(max_speed=0.5))
    with pytest.raises(jh.ScenarioError) as e:
        call(sc)
    assert field in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_hoist_time_of_a_profile_and_its_gradient():
    """`optimise_lift`'s "hoist_time" term for a `KnotHoist`: the root T of s(T) = d (checked against the
    closed form of a constant speed after a smoothstep ramp, d / v + T_ramp / 2) and its gradient in two
    knot speeds against central differences of T."""
    from jaxhoist._apps.planning import optimise as opt_mod

    ramp = jh.KnotHoist([0.0, 1.2, 3.0], [0.0, 0.3, 0.3])
    assert opt_mod.reel_time(ramp, 2.0) == pytest.approx(2.0 / 0.3 + 0.6, rel=1e-13)
    assert opt_mod.reel_time(jh.KnotHoist([0.0, 1.0], [0.2, 0.0]), 1.0) == float("inf")
    paths = ("hoist.speeds[1]", "hoist.speeds[2]")
    problem = opt_mod._prepare(
        box(profile()),
        {"foundation.friction_coefficient": jh.Uniform(0.2, 0.4)},
        {"max_rope_tension": 1e-4, "hoist_time": 0.1},
        {p: (0.1, 0.5) for p in paths},
        hazard_limits=None,
        samples=4,
        seed=0,
        times=T1,
        x0=None,
        hoist_distance=0.8,
        penalty=0.0,
        penalty_width=0.1,
        starts=1,
        max_iterations=5,
        tolerance=1e-4,
        check_samples=8,
        check_replicates=2,
        check_seed=None,
        confidence=0.95,
        options=None,
        batch=None,
    )["problem"]
    x = np.array([0.25, 0.4])
    T, g = problem._hoist_value(x)
    assert float(box(profile()).hoist.shortening(jnp.asarray(T))) == pytest.approx(0.8, rel=1e-13)
    h = 1e-5
    fd = [
        (problem._hoist_value(x + e)[0] - problem._hoist_value(x - e)[0]) / (2 * h)
        for e in (np.array([h, 0.0]), np.array([0.0, h]))
    ]
    assert np.all(np.asarray(g) < 0)  # faster knots reel the rope in sooner
    np.testing.assert_allclose(g, fd, rtol=1e-6)
    with pytest.raises(jh.ScenarioError, match="never reels in hoist_distance = 1 m"):
        opt_mod._check_hoist_time(box(jh.KnotHoist([0.0, 1.0], [0.2, 0.0])), 0.1, 1.0)


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["risk", "--design", "hoist.speeds[1]=-0.1,0.2", "--hazard", "slide=0.5"], "hoist.speeds (v_k)"),
        (["risk", "--design", "hoist.speeds[4]=0.1,0.2", "--hazard", "slide=0.5"], "index 4 out of range"),
        (
            ["optimise-lift", "--bound", "hoist.speeds[2]=0.2:0.7", "--objective", "max_rope_tension"],
            "above hoist.max_speed",
        ),
    ],
)
def test_cli_knot_designs_are_checked_before_compiling(tmp_path, capsys, monkeypatch, args, field):
    from jaxhoist._apps import cli
    from jaxhoist._apps.planning import optimise as opt_mod
    from jaxhoist._apps.planning import risk as risk_mod

    monkeypatch.setattr(opt_mod, "scan", _trap)
    monkeypatch.setattr(risk_mod, "scan", _trap)
    toml = _inputs.write_knot_box(tmp_path / "knots.toml")
    unc = ["--uncertain", "foundation.friction_coefficient=uniform(0.2,0.4)"]
    code = cli.main([args[0], str(toml), *unc, *args[1:], "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and field in err, err
