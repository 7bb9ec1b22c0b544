"""`jaxhoist.lift_risk` (`_apps/planning/`): uncertain inputs, hazards and risk maps, and the observables they
read (`ground_slide`, `ground_tilt`, `swing_amplitude`).

The load is a low 2 m x 2 m x 0.5 m box of 1000 kg with the rope at the middle of its top face, hoisted at
0.2 m/s through a soft rope (30 kN/m) from a boom tip 8 m above it and `tip_x - 1` m to the side: with the
tip 3 m aside the pull slides the box towards the boom (about 1 m in 2.5 s at μ = 0.3, less for larger μ)
long before it could tip or lift; 0.5 m aside it is dragged a little, lifts at 1.65 s and swings; straight
above it lifts at 1.54 s. Every risk run below uses the same three paths (the boom tip's x, μ and the mass
centre's ξ), the same hazards, saved times and chunk shape, so they share one compiled scan.
"""

import jax

jax.config.update("jax_enable_x64", True)  # tests/conftest.py also does this

import json  # noqa: E402
import math  # noqa: E402
import re  # noqa: E402
from unittest import mock  # noqa: E402

import _inputs  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy import stats  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._apps.planning import risk as risk_mod  # noqa: E402

TIP = "boom.tip_position[0]"
MU = "foundation.friction_coefficient"
MC = "load.mass_centre[0]"
T1 = 2.5
TIMES = jh.Times(T1, n=126)
BATCH = jh.BatchOptions(lanes=8, chunk_size=64)
SLIDE_D = 1.1  # [m]
# Input-like observables: hazards on them have probabilities known in closed form.
MU_OBS = jh.Observable("mu", lambda traj, sc: sc.foundation.friction_coefficient, "-", "μ of the member")
MC_OBS = jh.Observable("mc_x", lambda traj, sc: sc.load.mass_centre[0], "m", "ξ_C of the member")
HAZARDS = (
    jh.slide(SLIDE_D),
    jh.tilt(degrees=3.0),
    jh.strike(),
    jh.overload(9000.0),
    jh.swing(0.3),
    jh.no_liftoff(T1),
    jh.Hazard("low_mu", MU_OBS, 0.3, above=False),
    jh.Hazard("mc_right", MC_OBS, 1.05),
)
KW = dict(times=TIMES, batch=BATCH)


def drag_box(tip_x: float = 4.0) -> jh.Scenario:
    """The box of docs/lift-planning.md with the boom tip at x = `tip_x` [m], on the horizon `T1`."""
    return _inputs.drag_box(tip_x, t1=T1)


def observables_of(hazards) -> dict:
    """The observables `lift_risk` scans for these hazards (so a reference scan shares its compiled core)."""
    return {h.observable_name: h.observable for h in hazards}


@pytest.fixture(scope="module")
def box():
    return drag_box()


@pytest.fixture(scope="module")
def shifted(box):
    """μ uniform on [0.2, 0.4] and on [0.3, 0.5] (the same scrambles), the tip mirrored about the box
    (x = -1 and 3) and 3 m aside at 4, the mass centre at the middle."""
    design = jh.Sweep(TIP, [-1.0, 3.0, 4.0])
    out = {}
    for lo in (0.2, 0.3):
        unc = {MU: jh.Uniform(lo, lo + 0.2), MC: jh.Fixed(1.0)}
        out[lo] = jh.lift_risk(box, unc, HAZARDS, design, samples=64, seed=3, **KW)
    return out


# ------------------------------------------------------------------------------------------ distributions


def test_distributions_map_uniforms_through_their_inverse_cdf():
    u = np.array([0.025, 0.5, 0.975])
    np.testing.assert_allclose(jh.Uniform(0.2, 0.6).ppf(u), [0.21, 0.4, 0.59])
    np.testing.assert_allclose(jh.Normal(1.0, 0.1).ppf(u), 1.0 + 0.1 * stats.norm.ppf(u))
    tn = jh.TruncatedNormal(0.3, 0.2, 0.1, 0.5).ppf(np.linspace(0.001, 0.999, 50))
    assert tn.min() >= 0.1 and tn.max() <= 0.5
    ln = jh.LogNormal(2.0, 0.1)
    np.testing.assert_allclose(ln.ppf(0.5), 2.0)
    np.testing.assert_allclose(ln.ppf(stats.norm.cdf(1.0)), 2.0 * math.exp(0.1))
    np.testing.assert_allclose(jh.Fixed(7.0).ppf(u), 7.0)
    for d in (jh.Uniform(0.2, 0.6), jh.Normal(1.0, 0.1), jh.LogNormal(2.0, 0.1)):
        np.testing.assert_allclose(d.cdf(d.ppf(u)), u, rtol=1e-12)


def test_samples_are_repeatable_and_have_the_right_moments():
    unc = {MU: jh.Uniform(0.2, 0.4), MC: jh.Normal(1.0, 0.05), "hoist.speed": jh.Fixed(0.2)}
    a = risk_mod.sample(unc, 1024, 8, seed=1)
    b = risk_mod.sample(unc, 1024, 8, seed=1)
    c = risk_mod.sample(unc, 1024, 8, seed=2)
    assert all(np.array_equal(a[p], b[p]) for p in unc) and not np.array_equal(a[MU], c[MU])
    assert a[MU].shape == (8, 128)
    # scrambled Sobol points in each replicate: 128 points, one in each 1/128 stratum of μ
    for r in range(8):
        strata = np.floor((a[MU][r] - 0.2) / 0.2 * 128).astype(int)
        assert sorted(strata) == list(range(128))
    assert abs(a[MC].mean() - 1.0) < 1e-3 and abs(a[MC].std() - 0.05) < 1e-3
    assert np.all(a["hoist.speed"] == 0.2)
    # the replicates are independent scrambles: different points
    assert not np.array_equal(np.sort(a[MU][0]), np.sort(a[MU][1]))


# ------------------------------------------------------------------------------------------ observables


@pytest.fixture(scope="module")
def solves():
    """Single solves of the box with the tip straight above, 0.5 m aside either way, and 3 m aside."""
    return {x: jh.simulate(drag_box(x), TIMES) for x in (1.0, 0.5, 1.5, 4.0)}


def _obs(name, traj, tip_x):
    return float(jh.get_observable(name)(traj, drag_box(tip_x)))


def test_ground_slide_is_the_drag_over_the_ground(solves):
    # straight pull: nothing slides
    assert _obs("ground_slide", solves[1.0], 1.0) < 1e-9
    # 3 m aside: still dragged at t1 (no lift-off), monotonically, so the largest drag is the final one
    tr = solves[4.0]
    assert math.isinf(_obs("liftoff_time", tr, 4.0))
    assert 0.9 < _obs("ground_slide", tr, 4.0) == pytest.approx(_obs("slide_distance", tr, 4.0), rel=1e-12)
    assert np.all(np.diff(np.asarray(tr.position[:, 0])) >= -1e-9)
    # 0.5 m aside: dragged a little, then it swings: the drag is the distance up to the last contact only,
    # there included (interpolated linearly between the saved times)
    tr = solves[1.5]
    ts, on, t_cross = _contact_events(tr, 1.5)
    assert t_cross.size == 1 and t_cross[0] == pytest.approx(_obs("last_contact_time", tr, 1.5), rel=1e-12)
    d = np.linalg.norm(np.asarray(tr.position[:, :2] - tr.position[0, :2]), axis=-1)
    ref = max(np.max(d[on]), np.interp(t_cross[0], ts, d))
    assert _obs("ground_slide", tr, 1.5) == pytest.approx(ref, rel=1e-12)
    assert _obs("ground_slide", tr, 1.5) < 0.1 < _obs("slide_distance", tr, 1.5)


def _contact_events(tr, tip_x):
    """(saved times, whether some corner is in contact at each, the times at which that changes): the
    zeros of max_i f_i (the public contact function), interpolated linearly between the saved times."""
    ts = np.asarray(tr.ts)
    f = np.max(np.asarray(jh.observables.contact_function(tr, drag_box(tip_x))), axis=-1)
    on = f > 0.0
    assert np.array_equal(on, np.max(np.asarray(tr.normal_forces), axis=-1) > 0.0)
    k = np.flatnonzero(on[:-1] != on[1:])
    return ts, on, ts[k] + f[k] / (f[k] - f[k + 1]) * (ts[k + 1] - ts[k])


def test_contact_observables_are_continuous_and_differentiable_across_the_saved_times():
    """The largest value while on the ground includes the contact's end between saved times, interpolated
    linearly: for a signal x(t) = t and a contact function F(t) = a - t (contact until t = a), both linear,
    the interpolation is exact, so the value is a and its derivative in a is 1 wherever a lies among the
    saved times; read at the saved times alone it would be the last saved time before a, a staircase with
    derivative 0."""
    from jaxhoist._numerics.observables import _max_on_ground

    ts = jnp.linspace(0.0, 1.0, 11)

    def value(a):
        return _max_on_ground(ts, a - ts)

    for a in (0.123, 0.3, 0.3 + 1e-12, 0.3 - 1e-12, 0.95):
        v, dv = jax.jvp(value, (jnp.asarray(a),), (jnp.asarray(1.0),))
        assert float(v) == pytest.approx(a, rel=1e-12) and float(dv) == pytest.approx(1.0, rel=1e-12)

    # a second contact, from t = 0.62 s to b, linear in t across both its ends: its end counts, exactly
    def two_episodes(b):
        return _max_on_ground(ts, jnp.maximum(0.25 - ts, jnp.minimum(ts - 0.62, b - ts)))

    v, dv = jax.jvp(two_episodes, (jnp.asarray(0.88),), (jnp.asarray(1.0),))
    assert float(v) == pytest.approx(0.88, rel=1e-12) and float(dv) == pytest.approx(1.0, rel=1e-12)


def test_swing_amplitude_is_the_release_offset_of_a_pendulum(solves):
    # straight above: it rises without swinging; still on the ground: no swing at all
    assert _obs("swing_amplitude", solves[1.0], 1.0) < 1e-6
    assert _obs("swing_amplitude", solves[4.0], 4.0) == 0.0
    # 0.5 m aside: the load leaves the ground nearly at rest, hanging off the vertical through A by the
    # horizontal distance it has not been dragged: a pendulum released there swings back to that distance
    for x in (0.5, 1.5):
        tr = solves[x]
        t_off = _obs("last_contact_time", tr, x)
        k = int(np.searchsorted(np.asarray(tr.ts), t_off))
        release = float(np.linalg.norm(np.asarray(tr.position[k, :2] - tr.tip_position[k, :2])))
        assert 0.3 < release
        assert _obs("swing_amplitude", tr, x) == pytest.approx(release, rel=0.05)
    # and mirrored tips give the same swing
    a, b = (_obs("swing_amplitude", solves[x], x) for x in (0.5, 1.5))
    assert a == pytest.approx(b, rel=1e-3)


def test_ground_tilt_is_the_tilt_while_a_corner_touches_the_ground(solves):
    """`ground_tilt` against the same quantity from the trajectory's public outputs: the tilt from the Euler
    angles (R = R_Z(ψ) R_Y(ϑ) R_X(φ): body ζ makes the angle arccos(cos φ cos ϑ) with the vertical) at the
    saved times at which some N_i > 0. Pulled 0.5 m aside the box barely rolls on the ground but swings
    after lift-off, so `max_tilt` (which `tilt` reads) sees the swing and `ground_tilt` (which `tip` reads)
    does not."""
    for x in (1.0, 1.5, 4.0):
        tr = solves[x]
        phi, _, theta = np.asarray(tr.euler).T
        angle = np.arccos(np.clip(np.cos(phi) * np.cos(theta), -1.0, 1.0))
        ts, on, t_cross = _contact_events(tr, x)
        assert on.any()
        ref = max([np.max(angle[on]), *np.interp(t_cross, ts, angle)])
        assert _obs("ground_tilt", tr, x) == pytest.approx(ref, rel=1e-6, abs=1e-9)
    assert _obs("ground_tilt", solves[1.0], 1.0) < 1e-9  # straight up: level until it leaves the ground
    tr = solves[1.5]
    assert not np.all(np.max(np.asarray(tr.normal_forces), axis=-1) > 0.0)  # it does leave the ground
    assert _obs("ground_tilt", tr, 1.5) < math.radians(0.5) < math.radians(3.0) < _obs("max_tilt", tr, 1.5)
    assert jh.tip(degrees=3.0) == jh.Hazard("tip", "ground_tilt", math.radians(3.0))


# ------------------------------------------------------------------------------------------ risk


def test_fixed_inputs_give_the_single_solves_outcome(box, solves):
    """Zero-width inputs: every member is the single solve, so each probability is 0 or 1, the one the
    solve itself gives, with the exact binomial interval for 16 of 16 (or 0 of 16) members."""
    r = jh.lift_risk(box, {MU: jh.Fixed(0.3), MC: 1.0}, HAZARDS, {TIP: [4.0]}, samples=16, replicates=2, **KW)
    tr = solves[4.0]
    edge = 0.025 ** (1 / 16)
    seen = set()
    for h in HAZARDS:
        value = np.asarray(h.resolve()(tr, box))
        happens = bool(np.any(value > h.threshold if h.above else value < h.threshold))
        p = float(r.probability(h)[0])
        assert p == float(happens), h.name
        lo, hi = (float(v[0]) for v in r.interval(h))
        assert (lo, hi) == pytest.approx((edge, 1.0) if happens else (0.0, 1 - edge)), h.name
        seen.add(happens)
    assert seen == {True, False}  # both kinds of outcome are checked
    np.testing.assert_allclose(r.quantile("ground_slide", 0.5)[0], _obs("ground_slide", tr, 4.0), rtol=1e-6)
    assert int(r.n_failed[0]) == 0 and r.shape == (1,)


def test_probabilities_of_inputs_are_recovered(shifted):
    """P(μ < 0.3) for μ ~ U(0.2, 0.4) is 1/2, for U(0.3, 0.5) 0; the scrambled Sobol points stratify μ, so
    every replicate has exactly half its points below 0.3."""
    a, b = shifted[0.2], shifted[0.3]
    np.testing.assert_allclose(a.probability("low_mu"), 0.5, atol=1e-12)
    np.testing.assert_allclose(b.probability("low_mu"), 0.0)
    assert np.all(a.n_failed == 0) and np.all(b.n_failed == 0)


def test_more_friction_never_slides_further(shifted):
    """Moving the whole μ distribution up by 0.1 (the same scrambles: every member's μ + 0.1) cannot make a
    slide more likely, and makes it less likely where the box is dragged (on a pull below tipping)."""
    a, b = shifted[0.2], shifted[0.3]
    pa, pb = a.probability("slide"), b.probability("slide")
    assert np.all(pb <= pa)
    assert pb[2] < pa[2]  # 3 m aside: dragged about 1.1 m, less with more friction
    for level in (0.05, 0.5, 0.95):
        assert np.all(b.quantile("ground_slide", level) <= a.quantile("ground_slide", level) + 1e-9)


def test_mirrored_tips_give_a_mirrored_map(shifted):
    """The box, its mass centre and the rope point are symmetric about x = 1: tips at x = -1 and 3 give
    the same probabilities (to one member of 64: the solver's rounding, rtol 1e-3, differs between the
    mirrored solves) and the same quantiles."""
    for r in shifted.values():
        for h in HAZARDS:
            p = r.probability(h)
            assert abs(p[0] - p[1]) <= 1 / 64 + 1e-12, h.name
        np.testing.assert_allclose(
            r.quantiles["ground_slide"][0], r.quantiles["ground_slide"][1], rtol=1e-3, atol=1e-4
        )


def test_monotone_slide_against_a_brute_force_scan(box, shifted):
    """P(ground slide > 1.1 m) with the tip 3 m aside and μ ~ U(0.2, 0.4): the slide shrinks as μ grows, so
    the probability is the share of [0.2, 0.4] below the μ* where it is 1.1 m, found on a fine μ-scan."""
    mus = np.linspace(0.2, 0.4, 64)
    ref = jh.scan(
        box,
        jh.Points({TIP: np.full(64, 4.0), MU: mus, MC: np.ones(64)}),
        TIMES,
        observables=observables_of(HAZARDS),
        batch=BATCH,
    )
    s = ref["ground_slide"]
    assert np.all(ref.ok) and np.all(np.diff(s) < 0)
    assert s[0] > SLIDE_D > s[-1]
    k = int(np.flatnonzero(s < SLIDE_D)[0])
    mu_star = mus[k - 1] + (s[k - 1] - SLIDE_D) / (s[k - 1] - s[k]) * (mus[k] - mus[k - 1])
    p_true = (mu_star - 0.2) / 0.2
    r = shifted[0.2]
    p, (lo, hi) = r.probability("slide")[2], (v[2] for v in r.interval("slide"))
    assert lo <= p_true <= hi
    assert abs(p - p_true) < 1 / 16  # 8 replicates of 8 stratified points: each off by less than 1/8


@pytest.fixture(scope="module")
def two_inputs(box):
    unc = {MU: jh.Uniform(0.2, 0.5), MC: jh.Normal(1.0, 0.05)}
    return unc, jh.lift_risk(box, unc, HAZARDS, {TIP: [2.0, 4.0]}, samples=64, seed=11, **KW)


def test_normal_input_probability_is_recovered(two_inputs):
    """P(ξ_C > 1.05) for ξ_C ~ N(1, 0.05) is 1 - Φ(1) = 0.1587: inside the 95 % interval."""
    _, r = two_inputs
    lo, hi = r.interval("mc_right")
    p_true = 1 - stats.norm.cdf(1.0)
    assert np.all(lo <= p_true) and np.all(p_true <= hi)
    assert np.all(np.abs(r.probability("mc_right") - p_true) < 0.05)
    lo, hi = r.interval("low_mu")
    assert np.all(lo <= 1 / 3) and np.all(1 / 3 <= hi)  # P(μ < 0.3) for μ ~ U(0.2, 0.5)


def test_agrees_with_plain_monte_carlo(box, two_inputs):
    """The RQMC estimates (64 members, 8 scrambles) against plain Monte Carlo of 256 independent draws: the
    difference is within 3 combined standard errors for every hazard and design point."""
    unc, r = two_inputs
    rng = np.random.default_rng(5)
    n = 256
    draws = {p: d.ppf(rng.uniform(size=n)) for p, d in unc.items()}
    cols = {TIP: np.repeat([2.0, 4.0], n), MU: np.tile(draws[MU], 2), MC: np.tile(draws[MC], 2)}
    mc = jh.scan(box, jh.Points(cols), TIMES, observables=observables_of(HAZARDS), batch=BATCH)
    assert np.all(mc.ok)
    t = stats.t.ppf(0.975, r.replicates - 1)
    tested = 0
    for h in HAZARDS:
        v = mc[h.observable_name].reshape(2, n)
        p_mc = np.mean(v > h.threshold if h.above else v < h.threshold, axis=1)
        se_mc = np.sqrt(np.maximum(p_mc * (1 - p_mc), 1 / n) / n)
        lo, hi = r.interval(h)
        se_rqmc = (hi - lo) / (2 * t)
        assert np.all(np.abs(r.probability(h) - p_mc) <= 3 * np.hypot(se_mc, se_rqmc) + 1e-12), h.name
        tested += int(np.sum((p_mc > 0.05) & (p_mc < 0.95)))
    assert tested >= 4  # several hazards lie strictly between "never" and "always"


def test_failed_members_are_counted_apart(box):
    """μ ~ N(0.1, 0.1) draws negative friction coefficients: those members are invalid, counted in
    `n_failed`, left out of the probabilities (over the rest), and too many of them give NaN."""
    unc = {MU: jh.Normal(0.1, 0.1), MC: jh.Fixed(1.0)}
    r = jh.lift_risk(box, unc, HAZARDS, {TIP: [4.0]}, samples=64, max_failed=0.5, **KW)
    n_neg = int(np.sum(r.draws[MU] < 0))
    assert 0 < n_neg < 32 and int(r.n_failed[0]) == n_neg
    mu = r.draws[MU]  # (replicates, samples / replicates), the same at every design point
    ok = mu >= 0
    assert np.sum(ok) == int(r.n_ok[0])
    # P(μ < 0.3) over the valid members of each replicate, then their mean
    expect = np.sum(ok & (mu < 0.3), axis=1) / np.sum(ok, axis=1)
    np.testing.assert_allclose(r.replicate_probabilities("low_mu")[0], expect, rtol=1e-12)
    assert r.probability("low_mu")[0] == pytest.approx(np.mean(expect), rel=1e-12)
    # the default limit, 5 % failed members: too many here
    r2 = jh.lift_risk(box, unc, HAZARDS, {TIP: [4.0]}, samples=64, **KW)
    assert np.isnan(r2.probability("slide")[0]) and np.all(np.isnan(r2.interval("slide")[0]))
    assert np.all(np.isnan(r2.quantile("ground_slide", 0.5)))
    # the summary says why: the failures counted by status, the first one's reason, and why there are NaNs
    first = r.scan.failures()[0]
    assert first["params"][MU] < 0 and f"failed {n_neg}/64" in r.summary()
    assert f"failed members: invalid_parameter {n_neg}; the first (" in r.summary()
    assert f"{MU} = {first['params'][MU]:g}" in r.summary()
    assert first["reason"] in r.summary() and "NaN where" not in r.summary()
    assert "NaN where more than max_failed = 0.05" in r2.summary()


def test_netcdf_file(tmp_path, shifted):
    from scipy.io import netcdf_file

    r = shifted[0.2]
    path = r.to_netcdf(tmp_path / "risk.nc")
    with netcdf_file(path, "r", mmap=False) as f:
        np.testing.assert_array_equal(f.variables["p_slide"][:], r.probability("slide"))
        np.testing.assert_array_equal(f.variables["p_slide_lower"][:], r.interval("slide")[0])
        assert f.variables["q_ground_slide"].shape == (3, 3)
        np.testing.assert_array_equal(f.variables["boom.tip_position_0_"][:], [-1.0, 3.0, 4.0])
        np.testing.assert_array_equal(f.variables["n_failed"][:], [0, 0, 0])


# ------------------------------------------------------------------------------------------ validation


def _trap(*args, **kwargs):
    raise AssertionError("the scan was reached with invalid lift_risk inputs")


GOOD_UNC = {MU: jh.Uniform(0.2, 0.4)}


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: jh.Uniform(0.5, 0.2), "low"),
        (lambda: jh.Uniform(0.2, float("inf")), "high"),
        (lambda: jh.Normal(0.3, 0.0), "std"),
        (lambda: jh.Normal(float("nan"), 0.1), "mean"),
        (lambda: jh.TruncatedNormal(0.3, 0.1, 0.5, 0.2), "low"),
        (lambda: jh.TruncatedNormal(0.3, -0.1, 0.0, 1.0), "std"),
        (lambda: jh.LogNormal(-1.0, 0.1), "median"),
        (lambda: jh.LogNormal(1.0, 0.0), "sigma"),
        (lambda: jh.Fixed(float("nan")), "value"),
        (lambda: jh.slide(-0.5), "distance"),
        (lambda: jh.tilt(degrees=0.0), "degrees"),
        (lambda: jh.tilt(0.1, degrees=5.0), "degrees"),
        (lambda: jh.tip(degrees=190.0), "below pi"),
        (lambda: jh.tip(-0.1), "angle"),
        (lambda: jh.Hazard("t", "ground_tilt", -0.1), "threshold"),
        (lambda: jh.overload(float("nan")), "safe_working_load"),
        (lambda: jh.Hazard("t", "max_tilt", -0.1), "threshold"),
        (lambda: jh.Hazard("t", "max_tlt", 0.1), "max_tlt"),
        (lambda: jh.Hazard("", "max_tilt", 0.1), "name"),
    ],
)
def test_bad_objects_are_refused_on_construction(make, field):
    with pytest.raises(jh.ScenarioError, match=field) as info:
        make()
    assert "\n" not in str(info.value)


# an observable of the caller's called like the built-in `ground_slide`: the final x of C [m]
OWN_SLIDE = jh.Observable("ground_slide", lambda traj: traj.position[-1, 0], "m")
OWN_X_END = jh.Observable("x_end", lambda traj: traj.position[-1, 0], "m")  # a name no built-in has


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        (dict(uncertain={"foundation.friction_coefficent": jh.Uniform(0.2, 0.4)}), "friction_coefficient"),
        (dict(uncertain={"load.mass_centre[3]": jh.Normal(1.0, 0.1)}), "load.mass_centre"),
        (dict(uncertain={}), "uncertain"),
        (dict(uncertain={MU: (0.2, 0.4)}), "uncertain"),
        (dict(hazards=[]), "hazards"),
        (dict(hazards=[jh.slide(0.5), jh.slide(1.0)]), "distinct"),
        (dict(design={MU: [0.3]}), "design"),
        (dict(design={"boom.tip_positon[0]": [1.0]}), "tip_position"),
        (dict(samples=60), "samples"),
        (dict(replicates=1), "replicates"),
        (dict(confidence=1.0), "confidence"),
        (dict(quantiles=[0.5, 1.5]), "quantiles"),
        (dict(hazards=[jh.no_liftoff(5.0)]), "t1"),
        (dict(hazards=[jh.slide(0.5), jh.Hazard("x_end", OWN_SLIDE, 0.5)]), "called 'ground_slide'; rename"),
        (dict(hazards=[jh.Hazard("x_end", OWN_X_END, 0.5)], observables=["x_end"]), "called 'x_end'; rename"),
    ],
)
def test_bad_lift_risk_inputs_fail_before_compiling(box, kwargs, field):
    args = dict(uncertain=GOOD_UNC, hazards=[jh.slide(0.5)], samples=64, times=TIMES) | kwargs
    with mock.patch.object(risk_mod, "scan", _trap), pytest.raises(jh.ScenarioError, match=field) as info:
        jh.lift_risk(box, **args)
    assert "\n" not in str(info.value)


# ------------------------------------------------------------------------------------------ layouts


def _fake_scan(scenario, points, times, *, observables, **kwargs):
    """A stand-in for `scan` (nothing solved): observable `mu` is the member's μ, `hoist_speed` its hoist
    speed (the box's 0.2 m/s if not a design path), `mu_plus_mc` μ + ξ_C, every other observable 0; members
    with μ > 0.45 fail."""
    vals = points.values
    n = points.size
    status = np.where(vals[MU] > 0.45, int(jh.ScanStatus.MAX_STEPS), 0).astype(np.int32)
    known = {
        "mu": vals[MU],
        "hoist_speed": vals.get("hoist.speed", np.full(n, 0.2)),
        "mu_plus_mc": vals[MU] + vals[MC],
    }
    data = {name: np.where(status == 0, known.get(name, np.zeros(n)), np.nan) for name in observables}
    return jh.ScanResult(
        params=tuple(vals),
        mode="points",
        coords=vals,
        shape=(n,),
        data=data,
        components={k: None for k in data},
        status=status,
        reasons={},
        num_accepted_steps=np.zeros(n),
        num_rejected_steps=np.zeros(n),
        ts=None,
        histories={},
        units={k: "-" for k in data},
        descriptions={k: "" for k in data},
        attrs={},
    )


SPEED_OBS = jh.Observable("hoist_speed", lambda traj, sc: sc.hoist.speed, "m/s")


def test_grid_design_and_no_design_lay_out_the_map(box):
    """A 2 x 3 grid (tip x by hoist speed) and no design at all, with the scan replaced by a stand-in whose
    observables are the inputs: the probabilities are those of the inputs, on the grid's axes."""
    unc = {MU: jh.Uniform(0.2, 0.5), MC: jh.Fixed(1.0)}
    hz = [jh.Hazard("low_mu", MU_OBS, 0.3, above=False), jh.Hazard("fast", SPEED_OBS, 0.25)]
    grid = jh.Grid({TIP: [2.0, 4.0], "hoist.speed": [0.1, 0.2, 0.3]})
    with mock.patch.object(risk_mod, "scan", _fake_scan):
        r = jh.lift_risk(box, unc, hz, grid, samples=128, max_failed=0.5, **KW)
        r0 = jh.lift_risk(box, unc, hz, samples=128, max_failed=0.5, **KW)
    assert r.shape == (2, 3) and r0.shape == ()
    # μ > 0.45 fails (1/6 of the members): P(μ < 0.3 | μ <= 0.45) = 0.1 / 0.25
    n_fail = int(np.sum(r.draws[MU] > 0.45))
    assert np.all(r.n_failed == n_fail) and int(r0.n_failed) == n_fail
    np.testing.assert_allclose(r.probability("low_mu"), 0.4, atol=0.02)
    np.testing.assert_allclose(float(r0.probability("low_mu")), float(r.probability("low_mu")[0, 0]))
    np.testing.assert_array_equal(r.probability("fast"), [[0, 0, 1], [0, 0, 1]])
    assert float(r0.probability("fast")) == 0.0
    np.testing.assert_array_equal(r.quantile("hoist_speed", 0.5), [[0.1, 0.2, 0.3], [0.1, 0.2, 0.3]])
    assert "hoist.speed = 0.3" in r.summary() and "failed" in r0.summary()


@pytest.mark.parametrize("samples", [64, 256])
def test_intervals_cover_the_truth(box, samples):
    """Over 200 seeds the 95 % intervals of P(μ + ξ_C < 1.27), μ ~ U(0.2, 0.4), ξ_C ~ N(1, 0.05), hold the
    exact value (a quadrature) in at least 90 % of the runs (nothing solved: the stand-in scan)."""
    obs = jh.Observable(
        "mu_plus_mc", lambda traj, sc: sc.foundation.friction_coefficient + sc.load.mass_centre[0]
    )
    hz = [jh.Hazard("low", obs, 1.27, above=False)]
    unc = {MU: jh.Uniform(0.2, 0.4), MC: jh.Normal(1.0, 0.05)}
    mu = np.linspace(0.2, 0.4, 20001)
    truth = np.trapezoid(stats.norm.cdf((1.27 - mu - 1.0) / 0.05), mu) / 0.2
    cover, width = 0, []
    with mock.patch.object(risk_mod, "scan", _fake_scan):
        for seed in range(200):
            r = jh.lift_risk(box, unc, hz, samples=samples, seed=seed, **KW)
            lo, hi = (float(v) for v in r.interval("low"))
            cover += lo <= truth <= hi
            width.append(hi - lo)
    assert cover >= 180, cover
    # and the intervals are narrower than plain Monte Carlo's binomial ones of the same size
    assert np.mean(width) < 2 * 1.96 * np.sqrt(truth * (1 - truth) / samples)


# ------------------------------------------------------------------------------------------ command line


def test_cli_specs_parse_to_the_library_objects():
    from jaxhoist._apps.cli.risk import parse_distribution, parse_hazard

    assert parse_distribution("uniform(0.2, 0.4)") == jh.Uniform(0.2, 0.4)
    assert parse_distribution("normal(1,0.05)") == jh.Normal(1.0, 0.05)
    assert parse_distribution("truncnormal(1,0.05,0.8,1.2)") == jh.TruncatedNormal(1.0, 0.05, 0.8, 1.2)
    assert parse_distribution("lognormal(2,0.1)") == jh.LogNormal(2.0, 0.1)
    assert parse_distribution("0.3") == parse_distribution("fixed(0.3)") == jh.Fixed(0.3)
    assert parse_hazard("slide=0.5") == jh.slide(0.5)
    assert parse_hazard("tilt=10deg") == jh.tilt(degrees=10.0)
    assert parse_hazard("tilt=0.1") == jh.tilt(0.1)
    assert parse_hazard("tip=30deg") == jh.tip(degrees=30.0)
    assert parse_hazard("tip=0.5") == jh.tip(0.5)
    assert parse_hazard("strike") == jh.strike()
    assert parse_hazard("overload=12000") == jh.overload(12000.0)
    assert parse_hazard("no-liftoff=2.5") == jh.no_liftoff(2.5)
    assert parse_hazard("edge:contact_margin[E]<0") == jh.Hazard(
        "edge", "contact_margin[E]", 0.0, above=False
    )
    for bad, field in [
        ("uniform(0.4,0.2)", "low"),
        ("gauss(1,2)", "no distribution"),
        ("normal(1)", "number of arguments"),
        ("normal(a,1)", "numbers"),
    ]:
        with pytest.raises(jh.ScenarioError, match=re.escape(field)):
            parse_distribution(bad)
    for bad, field in [
        ("slide", "expected"),
        ("tilt=xdeg", "not a number"),
        ("tip=", "expected"),
        ("x:max_tilt>-1", "threshold"),
    ]:
        with pytest.raises(jh.ScenarioError, match=field):
            parse_hazard(bad)


CLI_ARGS = ["--uncertain", "foundation.friction_coefficient=uniform(0.2,0.4)", "--hazard", "slide=1.1"]


@pytest.mark.parametrize(
    ("extra", "field"),
    [
        (["--uncertain", "foundation.friction_coefficient=uniform(0.4,0.2)"], "low"),
        (["--uncertain", "load.mass_centre[7]=normal(1,0.1)"], "load.mass_centre"),
        (["--hazard", "tilt=-3deg"], "degrees"),
        (["--design", "boom.tip_position[0]"], "--design"),
        (["--samples", "30"], "samples"),
    ],
)
def test_cli_bad_input_exits_2_before_compiling(tmp_path, capsys, extra, field):
    from jaxhoist._apps import cli

    toml = _inputs.DRAG_BOX
    with mock.patch.object(risk_mod, "scan", _trap):
        code = cli.main(["risk", str(toml), *CLI_ARGS, *extra, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and field in err, err


def test_cli_writes_the_map(tmp_path, capsys):
    """Two tip positions, μ uniform: the table, risk.json, risk.nc and one map per hazard; the slide 3 m
    aside is likelier than 1 m aside."""
    from jaxhoist._apps import cli

    toml = _inputs.DRAG_BOX
    out = tmp_path / "out"
    args = ["risk", str(toml), "--t1", str(T1), *CLI_ARGS, "--hazard", "tilt=3deg", "--n-save", "126"]
    args += ["--design", "boom.tip_position[0]=2,4", "--samples", "16", "--replicates", "2", "--quiet"]
    args += ["--out", str(out)]
    assert cli.main(args) == 0
    printed = capsys.readouterr().out
    assert "boom.tip_position[0] = 4" in printed and "failed 0/16" in printed
    summary = json.loads((out / "risk.json").read_text())
    p = summary["hazards"]["slide"]["probability"]
    assert summary["shape"] == [2] and 0.0 <= p[0] < p[1]
    assert (
        (out / "risk.nc").is_file()
        and (out / "risk_slide.png").is_file()
        and (out / "risk_tilt.png").is_file()
    )


def test_xarray_dataset_holds_the_map(shifted):
    """`LiftRisk.to_xarray()`: every probability, interval bound, replicate estimate and quantile equals the
    result's own, on the design dimension with the tip positions as coordinate (units kept), and the
    dataset's replicate mean is the probability."""
    pytest.importorskip("xarray")
    r = shifted[0.2]
    ds = r.to_xarray()
    assert ds.sizes["design"] == 3 and ds.sizes["replicate"] == r.replicates
    np.testing.assert_array_equal(ds[TIP].values, [-1.0, 3.0, 4.0])
    assert ds[TIP].attrs["units"] == "m"
    for h in HAZARDS:
        np.testing.assert_array_equal(ds[f"p_{h.name}"].values, r.probability(h))
        lo, hi = r.interval(h)
        np.testing.assert_array_equal(ds[f"p_{h.name}_lower"].values, lo)
        np.testing.assert_array_equal(ds[f"p_{h.name}_upper"].values, hi)
        reps = ds[f"p_{h.name}_replicates"]
        assert reps.dims == ("design", "replicate")
        np.testing.assert_allclose(reps.mean("replicate").values, r.probability(h), rtol=1e-12, atol=1e-15)
    q = ds["q_ground_slide"]
    assert q.dims == ("design", "quantile") and q.attrs["units"] == "m"
    np.testing.assert_array_equal(q.sel(quantile=0.5).values, r.quantile("ground_slide", 0.5))
    np.testing.assert_array_equal(ds["n_failed"].values, r.n_failed)
    assert ds.attrs["samples"] == r.samples
