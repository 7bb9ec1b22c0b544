"""`jaxhoist._apps.bifurcation.classify`: each kind of located change recognised on synthetic samples, the
10-90 % ramp width against its closed form, the `last_contact_time` observable against `liftoff_time`,
and one cheap real case."""

import math

import jax

jax.config.update("jax_enable_x64", True)  # tests/conftest.py also does this

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from _inputs import SYMMETRIC_LIFT  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._apps.bifurcation.classify import classify_change, classify_samples, ramp_width  # noqa: E402
from jaxhoist._numerics import observables as O  # noqa: E402

BR = (0.4999995, 0.5000005)  # a located bracket of width 1e-6 around p* = 0.5


def window(n=41, half=0.01):
    """Parameter values over p* ± `half`, with the two bracket ends among them."""
    return np.unique(np.concatenate([np.linspace(0.5 - half, 0.5 + half, n), BR]))


def smooth(x, **extra):
    """Final state and event times that vary slowly and linearly with p (no change of character)."""
    d = x - 0.5
    s = dict(
        final_x=3.0 + 0.1 * d,
        final_y=4.0 - 0.2 * d,
        final_phi=-1.0 + 0.5 * d,
        final_theta=0.4 + 0.3 * d,
        final_psi=1.0 + 0.9 * d,
        liftoff_time=19.5 + 2.0 * d,
        last_contact_time=19.6 + 2.0 * d,
        impacts=np.full_like(x, 5.0),
    )
    s.update(extra)
    return s


def test_final_state_jump():
    """ψ(t1) and y(t1) step by 3 rad and 0.3 m between the bracket ends: a jump, with the fraction ~1."""
    x = window()
    up = x >= BR[1]
    s = smooth(x, final_psi=1.0 + 3.0 * up, final_y=4.0 + 0.3 * up, impacts=5.0 + up)
    c = classify_samples(x, s, BR, observable="final_psi", param="mu")
    assert c.kind == "final-state jump"
    assert "event-count change" in c.facets  # the impacts step too: a facet, not the kind
    assert c.jump_fractions["final_psi"] > 0.99 and c.jump_fractions["final_y"] > 0.99
    assert c.width is None and c.count_change == (5.0, 6.0)
    assert "final-state jump" in c.summary()


def test_steep_ramp_and_its_width():
    """ψ = 1.5 tanh((p - p*)/s): a resolved ramp; its 10-90 % width is 2 atanh(0.8) s."""
    s_w = 5e-4
    x = np.unique(np.concatenate([np.linspace(0.49, 0.51, 401), BR]))
    psi = 1.5 * np.tanh((x - 0.5) / s_w)
    c = classify_samples(x, smooth(x, final_psi=psi), BR, observable="final_psi")
    assert c.kind == "steep ramp"
    assert c.ramp_observable == "final_psi"
    expected = 2 * math.atanh(0.8) * s_w  # 1.0986e-3
    assert c.width == pytest.approx(expected, rel=0.02)
    assert c.jump_fractions["final_psi"] < 0.01  # almost none of it inside the 1e-6 bracket
    assert f"{c.width:.2g}" in c.summary()


def test_ramp_width_closed_form():
    x = np.linspace(0.0, 1.0, 1001)
    assert ramp_width(x, x) == pytest.approx(0.8, abs=1e-9)  # linear: from 0.1 to 0.9
    assert math.isnan(ramp_width(x, np.ones_like(x)))


def test_event_count_change_with_a_continuous_final_state():
    """A corner lands once more above p*: the impact count steps, nothing else does."""
    x = window()
    c = classify_samples(x, smooth(x, impacts=5.0 + (x >= BR[1])), BR, observable="impacts")
    assert c.kind == "event-count change" and c.facets == ["event-count change"]
    assert c.count_change == (5.0, 6.0)


def test_event_definition_change():
    """The first all-off instant jumps 0.5 s earlier (a momentary lift-off appears) while the last contact
    and the final state stay continuous: only which instant is called lift-off moves."""
    x = window()
    lift = 19.6 - 0.5 * (x >= BR[1])
    s = smooth(x, liftoff_time=lift, impacts=5.0 + (x >= BR[1]))
    c = classify_samples(x, s, BR, observable="liftoff_time")
    assert c.kind == "event-definition change"
    assert "event-count change" in c.facets  # the extra all-off episode also counts a landing
    assert c.event_jumps["liftoff_time"] == pytest.approx(-0.5)
    assert abs(c.event_jumps["last_contact_time"]) < 1e-4
    # the same samples located on the impact count: the count is the kind, the definition a facet
    c2 = classify_samples(x, s, BR, observable="impacts")
    assert c2.kind == "event-count change" and "event-definition change" in c2.facets


def test_a_real_lift_off_jump_is_not_a_definition_change():
    """Last contact and first all-off jump together: not an event-definition change."""
    x = window()
    step = 0.7 * (x >= BR[1])
    s = smooth(x, liftoff_time=19.6 - step, last_contact_time=19.6 - step)
    c = classify_samples(x, s, BR, observable="liftoff_time")
    assert "event-definition change" not in c.facets
    assert c.kind == "continuous crossing"  # final state continuous, count unchanged


def test_continuous_crossing():
    x = window()
    c = classify_samples(x, smooth(x), BR, observable="final_psi")
    assert c.kind == "continuous crossing" and c.facets == ["continuous crossing"]
    assert c.to_dict()["kind"] == "continuous crossing"


def test_bracket_ends_must_be_sampled():
    x = np.linspace(0.49, 0.51, 11)
    with pytest.raises(jh.ScenarioError, match="both ends of the bracket"):
        classify_samples(x, smooth(x), BR)


def test_last_down_crossing():
    """The last fall of a contact function through 0 (interpolated); +inf if still in contact at the end;
    the first fall is `first_down_crossing`'s."""
    ts = jnp.linspace(0.0, 10.0, 11)
    f = jnp.array([1.0, 1.0, -1.0, -1.0, 1.0, 1.0, 1.0, -3.0, -1.0, -1.0, -1.0])
    assert float(O.first_down_crossing(ts, f)) == pytest.approx(1.5)
    assert float(O.last_down_crossing(ts, f)) == pytest.approx(6.25)
    assert math.isinf(float(O.last_down_crossing(ts, jnp.abs(f))))
    assert float(O.last_down_crossing(ts, -jnp.abs(f))) == 0.0


def test_classify_change_real_case():
    """A cheap real case: the corner-order swap of the symmetric lift (tests/test_bifurcation.py) at
    ξ_C* = 0.5 m is a continuous crossing of t_E - t_D; over 0.2 s the final state and event times move
    smoothly, nothing jumps, and the last contact is not before the first all-off instant. The window's
    41 points (42 members: groups of 32) and the 101 saved times are those of the classification in
    `test_cli_bifurcation_classify` of the same change, so the two share one compiled scan."""
    sc = jh.Scenario(
        load=jh.Load([1.0, 1.0, 1.0], 1000.0, mass_centre=[0.5, 0.5, 0.5]),
        foundation=jh.Foundation(1.5e7, 2.0e5, 0.3, jh.RegularisedCoulomb(1e-3)),
        rope=jh.Rope(1.5e7, 1.3e4, [0.5, 0.5, 1.0]),
        hoist=jh.ConstantSpeedHoist(0.05),
        boom=jh.Boom([0.5, 0.5, 11.0], 500.0, 5.0e6, 5.0e3),
        name="symmetric-lift",
    )
    c = classify_change(
        sc,
        param="load.mass_centre[0]",
        bracket=(0.4999995, 0.5000005),
        observable="final_x",
        half_window=0.02,
        n_window=41,
        times=jh.Times(0.2, n=101),
    )
    assert c.kind == "continuous crossing", c.summary()
    # 41 window points less the midpoint (inside the bracket), plus the bracket's two ends
    assert c.n_samples == 42 and c.window == pytest.approx((0.48, 0.52))
    # fractions of coordinates that are even in ξ_C - 0.5 (y, φ) are ratios of two tiny numbers: only the
    # odd, materially changing ones say anything; none changes by 1 cm / 1° inside the bracket
    assert not any("jumping" in n for n in c.notes)
    assert c.jump_fractions["final_x"] < 0.01


def test_classify_change_passes_its_times_to_scan(monkeypatch):
    """`classify_change`'s `times` reach `scan` as given (a `Times` with n or ts), with its `options`; the
    default is 2501 saved times (the scan replaced by a recorder: no solves)."""
    import diffrax

    from jaxhoist._apps.scan import run as scan_mod

    seen = []

    class Recorded(Exception):
        pass

    def record(scenario, sweep, times, **kw):
        seen.append((times, kw["options"]))
        raise Recorded

    monkeypatch.setattr(scan_mod, "scan", record)
    sc = jh.load_scenario("paper-4.2")
    args = dict(param="foundation.friction_coefficient", bracket=(0.3, 0.31))
    options = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-7)
    ts = np.linspace(0.0, 0.2, 5)
    for kw in (
        dict(times=jh.Times(0.2, n=201), options=options),
        dict(times=jh.Times(ts=ts), options=options),
        dict(options=options),
    ):
        with pytest.raises(Recorded):
            classify_change(sc, **args, **kw)
    assert seen[0] == (jh.Times(0.2, n=201), options)
    assert seen[1][0].ts is ts
    assert seen[2][0] == jh.Times(n=2501)


def test_paper_43_preset_is_paper_42_with_the_fitted_mass_centre():
    """paper-4.3 changes only what the calibration fitted or chose (mass centre, μ) and keeps its mass
    centre inside the plausibility bounds of docs/bifurcation.md."""
    import tomllib
    from importlib import resources

    pkg = resources.files("jaxhoist._io.presets")
    d42 = tomllib.loads(pkg.joinpath("paper-4.2.toml").read_text())
    d43 = tomllib.loads(pkg.joinpath("paper-4.3.toml").read_text())
    assert d43["foundation"]["friction_coefficient"] == 0.3635  # paper §4.3
    xi, eta, zeta = d43["load"]["mass_centre"]
    assert 0.75 <= xi <= 1.75 and 1.5 <= eta <= 4.5 and 0.6 <= zeta <= 1.25
    for d in (d42, d43):
        for k in ("name", "description"):
            d.pop(k)
        d["load"].pop("mass_centre")
        d["foundation"].pop("friction_coefficient")
    assert d42 == d43
    sc = jh.load_scenario("paper-4.3")
    assert float(sc.foundation.friction_coefficient) == 0.3635


def test_cli_bifurcation_classify(tmp_path, capsys):
    """`jaxhoist bifurcation ... --classify` names the located change and records it in bifurcation.json:
    the corner-order swap of the symmetric lift (the sign change of t_E - t_D at ξ_C* = a/2), located by
    the command of tests/test_bifurcation.py's `test_scan_and_bifurcation_commands` (the same flags: its
    compiled locator is loaded), is a continuous crossing, as `test_classify_change_real_case` finds in
    Python on the same window scan."""
    import json

    from jaxhoist._apps.cli import app as cli

    xi = "load.mass_centre[0]"
    out = tmp_path / "bif"
    args = ["bifurcation", str(SYMMETRIC_LIFT), "--param", xi, "--bracket", "0.46", "0.57", "--observable",
            "detach:E-D", "--level", "0", "--method", "bisection", "--tol", "1e-4", "--t1", "0.2",
            "--n-save", "101", "--set", "hoist.speed=0.05"]  # fmt: skip
    code = cli.main([*args, "--classify", "--quiet", "--no-plots", "--out", str(out)])
    assert code == 0
    assert "continuous crossing" in capsys.readouterr().out
    rec = json.loads((out / "bifurcation.json").read_text())
    c = rec["bifurcations"][0]["classification"]
    assert c["kind"] == "continuous crossing" and c["param"] == xi
    assert c["bracket"] == rec["bifurcations"][0]["bracket"]
    assert abs(rec["bifurcations"][0]["value"] - 0.5) <= 1e-4


def test_a_jump_just_outside_the_bracket_is_found_and_noted():
    """Re-solved in another vmapped group, a 25 s event jump can land a few cells from the located bracket:
    the jump cell is classified instead, with a note; a ramp is never moved."""
    x = window()
    cut = x[25]  # a few cells above the bracket
    lift = 19.6 - 0.5 * (x >= cut)
    c = classify_samples(x, smooth(x, liftoff_time=lift), BR, observable="liftoff_time")
    assert c.kind == "event-definition change"
    assert c.bracket == (x[24], x[25]) and "does not jump across the given bracket" in c.notes[0]
    psi = 1.5 * np.tanh((x - 0.5) / 2e-3)
    c2 = classify_samples(x, smooth(x, final_psi=psi), BR, observable="final_psi")
    assert c2.bracket == BR and not c2.notes


def test_a_gradual_change_across_the_window_is_not_a_ramp():
    """ψ(t1) changing by 30° linearly over the window: material, but spread out (10-90 % over 80 % of the
    window): a continuous crossing, with a note."""
    x = window()
    c = classify_samples(x, smooth(x, final_psi=1.0 + 26.0 * (x - 0.5)), BR, observable="final_psi")
    assert c.kind == "continuous crossing" and c.width is None
    assert any("gradually" in n for n in c.notes)
