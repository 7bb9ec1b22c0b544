"""Parameter identification (`jaxhoist._apps.identify.fit`) and measurement files
(`jaxhoist._io.measurement`).

One compiled problem serves every fit here: μ of paper-4.2 from the mass-centre path on 21 samples over
0.4 s (before the first corner touches down again: there the ground damper force jumps and the flow is not
differentiable, see docs/identification.md). The tests change data values only, so the cached core is reused.
"""

import dataclasses
import json
import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import scipy.stats  # noqa: E402
from conftest import N_SAVE, TSIT5_CAPPED  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._apps.identify import core as identify_core  # noqa: E402
from jaxhoist._apps.identify import fit as ident  # noqa: E402
from jaxhoist._apps.identify.fit import identify, synthetic_measurement  # noqa: E402
from jaxhoist._apps.identify.options import fit_solver_options  # noqa: E402
from jaxhoist._io.measurement import Measurement, MeasurementError, read_measurement, write_measurement  # noqa: E402
from jaxhoist._numerics import compile_cache  # noqa: E402

MU = 0.25  # paper-4.2's friction coefficient
T = np.linspace(0.0, 0.4, 21)  # 50 Hz
SIGMA = 0.005  # position noise [m]
TSIT5 = jh.SolverOptions(diffrax.Tsit5())  # rtol 1e-6, atol 1e-8


def _identify_programs() -> int:
    """How many of the fit's pieces (its start and its step) are compiled in this process."""
    return compile_cache.count("identify-init") + compile_cache.count("identify-step")


def _synthetic(scenario, t, tsit5=False):
    """`synthetic_measurement` of the noise-free mass-centre path at the 21 times `t` [s], sampled from a
    solve on N_SAVE equally spaced times over the same span (every tenth of them): that solve is the
    compiled core of other tests (default options: test_rosenbrock.py's `default_run`; with `tsit5`,
    `TSIT5_CAPPED`: its stiff member's Tsit5 solve, whose step budget of 10 000 is far above the few hundred
    steps of 0.4 s here, and whose steps are those of `TSIT5`, the same rtol 1e-6, atol 1e-8), instead of
    one of its own for 21 times. Neither solver's steps depend on the saved times (dense output)."""
    assert t.size == 21 and t[0] == 0.0
    fine = np.linspace(0.0, t[-1], N_SAVE)
    m = synthetic_measurement(scenario, fine, ["position"], options=TSIT5_CAPPED if tsit5 else None)
    return Measurement(t, {k: v[::10] for k, v in m.signals.items()}, m.noise, m.source)


@pytest.fixture(scope="session")
def scenario():
    return jh.load_scenario("paper-4.2")


@pytest.fixture(scope="session")
def clean(scenario):
    """Noise-free mass-centre path of paper-4.2 (the same solver settings as `identify`'s defaults: the
    Rosenbrock-W solver at rtol 5e-4)."""
    return _synthetic(scenario, T)


def _noisy(clean, seed):
    rng = np.random.default_rng(seed)
    return Measurement(
        clean.t,
        {k: v + rng.normal(0.0, SIGMA, v.shape) for k, v in clean.signals.items()},
        {k: SIGMA for k in clean.signals},
        f"draw {seed}",
    )


# ------------------------------------------------------------------------------------------ fitting


def test_mu_recovered_noise_free(scenario):
    """Noise-free data of the fit's own model: μ comes back to 1e-6. That asks a model error below 1e-6 of
    the data and of the fit, which Tsit5 at rtol 1e-6 gives; the default W solver at rtol 5e-4 gives μ̂
    4.6e-4 off (the data's plain solve and the fit's augmented solve take different steps), 0.01 standard
    errors at this test's noise (the other fits here use the default)."""
    clean = _synthetic(scenario, T, tsit5=True)
    res = identify(
        scenario,
        clean,
        ["mu"],
        start={"mu": 0.3},
        noise={"position": SIGMA},
        options=TSIT5,
        fit=jh.FitOptions(lm_rtol=1e-10, lm_atol=1e-10),
    )
    assert res.converged
    assert res.solve_status == jh.SolveStatus.OK
    assert abs(res.estimates["foundation.friction_coefficient"] / MU - 1.0) < 1e-6
    # The fitted path reproduces the data to far below the noise level.
    assert max(np.max(np.abs(v)) for v in res.residuals.values()) < 1e-3 * SIGMA
    assert res.identifiable and res.noise_known
    assert res.scenario.foundation.friction_coefficient == pytest.approx(res.values[0], rel=1e-15)


def test_progress_reports_every_evaluation_and_nothing_without_a_callback(scenario, clean, capfd):
    """The fit reports on the host between its compiled steps: numbered evaluations, the best cost never
    increases and ends at the result's, the first step is from the start; without a callback (the same
    compiled pieces) nothing is printed. The second fit starts at the first one's estimate, so it takes a few
    evaluations only."""
    reps = []
    kw = dict(noise={"position": SIGMA})
    res = identify(scenario, clean, ["mu"], start={"mu": 0.3}, progress=reps.append, **kw)
    assert res.converged and len(reps) == res.iterations >= 2
    assert [r["iteration"] for r in reps] == list(range(1, len(reps) + 1))
    assert all(r["start"] == 0 and r["n_starts"] == 1 and r["solve_ok"] for r in reps)
    best = [r["best_cost"] for r in reps]
    assert all(b1 <= b0 for b0, b1 in zip(best, best[1:], strict=False))
    assert best[-1] == pytest.approx(res.cost, rel=1e-9)
    assert reps[0]["step"] == 0.0 and reps[0]["improved"] and reps[0]["cost"] > 10 * res.cost
    assert any(r["step"] > 0 for r in reps[1:])
    assert all(r["elapsed"] >= 0 and r["solver_steps"] > 0 for r in reps)
    assert sum(r["improved"] for r in reps) == res.accepted_steps  # LM accepts exactly the improving steps
    capfd.readouterr()
    compiled = _identify_programs()
    quiet = identify(scenario, clean, ["mu"], start={"mu": res.values[0]}, **kw)
    assert _identify_programs() == compiled
    assert quiet.converged and quiet.iterations < res.iterations
    assert quiet.cost == pytest.approx(res.cost, rel=1e-9) and quiet.values[0] == pytest.approx(res.values[0])
    out = capfd.readouterr()
    assert out.out == "" and out.err == ""


def test_host_loop_takes_optimistix_iterates():
    """`identify`'s Levenberg-Marquardt loop on the host over its compiled pieces (`core.Core`) against
    `optimistix.least_squares` with the same solver in one program, on Rosenbrock's residuals from
    (-1.2, 1): the same iterates, steps (rejected ones included) and outcome, converged and out of steps; one
    report per evaluation."""

    def residual_fn(z, a):
        return jnp.stack([10.0 * (z[1] - z[0] ** 2), a - z[0]]), jnp.array([0.0, 3.0])

    @jax.jit
    def reference(z0, a, lm_tol, scale):
        def fn(z, a_):
            r, info = residual_fn(z, a_)
            return r * scale, info

        out = {}
        for max_steps in (100, 5):
            solver = identify_core._LevenbergMarquardt(rtol=lm_tol[0], atol=lm_tol[1])
            sol = optx.least_squares(
                fn, solver, z0, a, has_aux=True, max_steps=max_steps, throw=False, options={"jac": "fwd"}
            )
            codes = [
                sol.result == optx.RESULTS.successful,
                sol.result == optx.RESULTS.nonlinear_max_steps_reached,
            ]
            out[max_steps] = (
                sol.value,
                sol.stats["num_steps"],
                sol.state.num_accepted_steps,
                jnp.stack(codes),
            )
        return out

    z0, a, lm_tol, scale = (
        jnp.array([-1.2, 1.0]),
        jnp.asarray(1.0),
        jnp.array([1e-8, 1e-10]),
        jnp.asarray(0.5),
    )
    init = eqx.filter_jit(identify_core.lm_init).lower(residual_fn, z0, a, lm_tol, scale).compile()
    carry, _ = init(residual_fn, z0, a, lm_tol, scale)
    step = eqx.filter_jit(identify_core.lm_step).lower(residual_fn, carry, a, lm_tol, scale).compile()
    ref = reference(z0, a, lm_tol, scale)
    for max_steps in (100, 5):
        reps = []
        core = identify_core.Core(residual_fn, max_steps, init, step)
        z, r, _, info, n, n_acc, codes = core(z0, a, lm_tol, scale, lambda *e: reps.append(e))
        value, n_ref, n_acc_ref, codes_ref = (np.asarray(x) for x in ref[max_steps])
        np.testing.assert_allclose(z, value, rtol=1e-13, atol=0)
        assert (n, n_acc, list(codes)) == (n_ref, n_acc_ref, list(codes_ref))
        assert len(reps) == n and all(list(e[2]) == [0.0, 3.0] for e in reps)
        assert np.array_equal(info, [0.0, 3.0])
    assert codes_ref.tolist() == [False, True] and ref[100][3].tolist() == [True, False]
    assert int(ref[100][1]) > int(ref[100][2]) > 5  # rejected steps among them, and more than 5 steps
    np.testing.assert_allclose(np.asarray(ref[100][0]), [1.0, 1.0], rtol=1e-6)


def test_covariance_matches_scatter(scenario, clean):
    """The Gauss-Newton standard error of μ̂ against the scatter of μ̂ over independent noise draws."""
    n = 12
    fits = [identify(scenario, _noisy(clean, 0), ["mu"], noise={"position": SIGMA})]
    compiled = _identify_programs()
    fits += [
        identify(scenario, _noisy(clean, seed), ["mu"], noise={"position": SIGMA}) for seed in range(1, n)
    ]
    assert _identify_programs() == compiled  # new data values reuse the compiled core
    # so do a renamed copy and a leaf set to a Python float (neither is part of the problem's structure)
    copy = eqx.tree_at(lambda s: s.rope.stiffness, scenario, float(scenario.rope.stiffness))
    again = identify(
        dataclasses.replace(copy, name="a copy"), _noisy(clean, 0), ["mu"], noise={"position": SIGMA}
    )
    assert _identify_programs() == compiled and again.values[0] == fits[0].values[0]
    assert all(f.compile_time < 0.5 for f in fits[1:])
    est = np.array([f.values[0] for f in fits])
    se = np.array([f.std_errors[0] for f in fits])
    assert all(f.converged and f.identifiable for f in fits)
    # The predicted error is nearly the same for every draw (the Jacobian barely changes over ~1 SE).
    assert np.ptp(se) < 0.1 * se.mean()
    assert 0.002 < se.mean() / MU < 0.2  # a meaningful test: μ is determined to a few per cent
    # Sample standard deviation over n draws: (n-1) s²/σ² ~ χ²(n-1). Two-sided 99.9 % band.
    s = est.std(ddof=1)
    lo, hi = (math.sqrt(scipy.stats.chi2.ppf(q, n - 1) / (n - 1)) for q in (0.0005, 0.9995))
    assert lo < s / se.mean() < hi, (s, se.mean(), lo, hi)
    # No bias beyond the sampling error of the mean (4 standard errors of the mean).
    assert abs(est.mean() - MU) < 4 * se.mean() / math.sqrt(n)
    # With noise levels given, χ²/dof scatters around 1: n_res - p = 62 degrees of freedom.
    chi2 = np.array([f.chi2_reduced for f in fits])
    dof = fits[0].n_residuals - 1
    assert np.all(chi2 > scipy.stats.chi2.ppf(1e-4, dof) / dof)
    assert np.all(chi2 < scipy.stats.chi2.ppf(1 - 1e-4, dof) / dof)
    # The correlation of a single parameter with itself, and the unknown-noise variant: σ² = RSS/(n - p)
    # gives the same standard error up to sqrt(χ²/dof).
    assert fits[0].correlation.shape == (1, 1)
    m = _noisy(clean, 0)
    m_unknown = Measurement(m.t, m.signals, {}, "no noise levels")
    u = identify(scenario, m_unknown, ["mu"], fit=jh.FitOptions(weights={"position": 1.0 / SIGMA}))
    assert not u.noise_known
    assert u.values[0] == pytest.approx(fits[0].values[0], rel=1e-6)
    assert u.std_errors[0] == pytest.approx(fits[0].std_errors[0] * math.sqrt(fits[0].chi2_reduced), rel=1e-4)


def test_default_w_fit_agrees_with_tsit5_and_central_differences(scenario, clean):
    """The default (`SolverOptions()`, RosenbrockW at rtol 5e-4): the state and its sensitivity share W in one
    error-controlled solve. On the same draw as a Tsit5 (rtol 1e-6) fit, μ̂ and
    its standard error agree to a small fraction of the standard error, and the Jacobian at μ̂ agrees with
    central differences. Measured on draws 0-2 with W at rtol 1e-3: |Δμ̂| =
    0.004-0.005 SE, the standard errors 0.1-0.2 % apart, the Jacobian 0.12-0.21 % from central differences
    of a Tsit5 rtol 1e-10 solve."""
    m = _noisy(clean, 0)
    kw = dict(noise={"position": SIGMA})
    w = identify(scenario, m, ["mu"], **kw)
    t5 = identify(scenario, m, ["mu"], options=TSIT5, **kw)
    assert w.converged and w.identifiable and w.solve_status == jh.SolveStatus.OK
    # The fit stops once a rejected step leaves a next trial below the resolution in z
    # (`identify_core._LevenbergMarquardt`): 3 rejected of 9 here; optimistix's own test alone went on
    # through ever smaller rejected steps (12 rejected of 19), at the same μ̂ to 1e-11.
    assert w.iterations - w.accepted_steps <= 4, (w.iterations, w.accepted_steps)
    assert abs(w.values[0] - t5.values[0]) < 0.02 * t5.std_errors[0], (w.values, t5.values, t5.std_errors)
    assert w.std_errors[0] == pytest.approx(t5.std_errors[0], rel=0.01)
    # Central differences of the noise-free path through Tsit5 at rtol 1e-6 (the solve of
    # test_mu_recovered_noise_free); with h = 0.3 % of μ̂ they agree with those of a Tsit5 rtol 1e-10 solve
    # to 3e-5 (those of the default W solve are 0.35 % off them, measured at μ = 0.2512).
    h = 3e-3 * w.values[0]
    mu_path = "foundation.friction_coefficient"
    paths = [_synthetic(jh.set_param(scenario, mu_path, w.values[0] + s), T, tsit5=True) for s in (h, -h)]
    j_cd = np.concatenate([(paths[0].signals[n] - paths[1].signals[n]) / (2 * h * SIGMA) for n in m.names])
    err = np.linalg.norm(w.jacobian[:, 0] - j_cd) / np.linalg.norm(j_cd)
    assert err < 0.01, err


def test_unidentifiable_parameter_reported(scenario, clean):
    """Over the first 20 ms the load has barely moved, so the path cannot tell μ: the result says so."""
    t = np.linspace(0.0, 0.02, T.size)  # same sizes: the compiled core is reused
    m = _synthetic(scenario, t)
    res = identify(scenario, m, ["mu"], noise={"position": SIGMA})
    assert not res.identifiable
    assert res.std_errors[0] > MU  # relative standard error above 100 %
    assert "cannot identify foundation.friction_coefficient" in res.warnings[0]
    assert "relative standard error" in res.warnings[0] and "barely depend" in res.warnings[0]
    assert res.weak_direction == {"foundation.friction_coefficient": 1.0}
    assert "identifiable: NO" in res.summary()


def test_collinear_parameters_give_condition_number_and_direction():
    """Two parameters that enter only through k + 2 h (relative units): the report names the direction."""
    rng = np.random.default_rng(0)
    a = rng.normal(size=200)
    theta = np.array([1.5e7, 2e6])  # k [N/m], h [N s/m]
    Jrel = np.stack([a, 2 * a + 1e-7 * rng.normal(size=200)], axis=1)  # d r / d(Δθ/θ)
    rep = ident.covariance_report(
        Jrel / theta,
        rng.normal(size=200),
        theta,
        ["foundation.stiffness", "foundation.damping"],
        noise_known=True,
    )
    assert not rep["identifiable"]
    assert rep["condition_number"] > 1e12
    w = rep["weak_direction"]
    # The null direction of [a, 2a] is (2, -1)/√5, normalised with its largest component positive.
    assert w["foundation.stiffness"] == pytest.approx(2 / math.sqrt(5), abs=1e-6)
    assert w["foundation.damping"] == pytest.approx(-1 / math.sqrt(5), abs=1e-6)
    msg = rep["warnings"][0]
    assert "near-singular" in msg and "+0.89 Δk/k -0.45 Δh/h" in msg
    assert rep["correlation"][0, 1] == pytest.approx(-1.0, abs=1e-6)
    # Well-conditioned columns: covariance = (JᵀJ)⁻¹ exactly, in the parameters' own units.
    J = rng.normal(size=(200, 2)) / theta
    rep = ident.covariance_report(J, rng.normal(size=200), theta, ["k", "h"], noise_known=True)
    assert rep["identifiable"] and not rep["warnings"]
    np.testing.assert_allclose(rep["covariance"], np.linalg.inv(J.T @ J), rtol=1e-10)


def test_cli_identify_writes_estimates(scenario, clean, tmp_path, capfd):
    from jaxhoist._apps.cli.app import main

    csv = write_measurement(tmp_path / "lift.csv", _noisy(clean, 100), units={"position_z": "mm"})
    out = tmp_path / "fit"
    code = main(
        [
            "identify",
            "paper-4.2",
            str(csv),
            "--fit",
            "mu",
            "--start",
            "mu=0.3",
            "--starts",
            "2",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    err = capfd.readouterr().err  # one progress bar per start on stderr: evaluations, cost, best, step
    assert "fit, start 1/2" in err and "fit, start 2/2" in err and "best" in err and "step" in err
    doc = json.loads((out / "estimates.json").read_text())
    est = doc["estimates"]["foundation.friction_coefficient"]
    assert abs(est["value"] - MU) < 4 * est["std_error"]
    assert doc["noise_known"] is True  # noise levels came from the side JSON written with the CSV
    assert doc["solver"] == {"name": "rosenbrock-w", "rtol": 5e-4, "atol": 1e-5}  # the default solver
    # Two starts (0.3 and a random one within ±30 %) reach the same minimum.
    assert len(doc["starts"]) == 2
    ends = [s["estimate"]["foundation.friction_coefficient"] for s in doc["starts"]]
    assert abs(ends[0] - ends[1]) < 1e-3 * est["std_error"]
    assert (out / "fit.png").stat().st_size > 1000


def test_reparameterisations_round_trip(scenario):
    """log for positive leaves, scaled logit inside bounds (the box for the mass centre), affine otherwise."""
    params, theta0 = ident.build_params(
        scenario, ["k", "load.mass_centre", "rope.attachment[2]", "b_l"], {"b_l": 5e5}, {"k": (1e6, 1e8)}
    )
    assert [p.kind for p in params] == ["logit", "logit", "affine", "log"]
    np.testing.assert_array_equal(params[1].hi, np.asarray(scenario.load.size))  # default bounds: the box
    assert theta0[-1] == 5e5  # the start value
    z = ident.flat_z(params, theta0)
    np.testing.assert_allclose(ident.theta_of(params, z), theta0, rtol=1e-13)
    # dθ/dz against a central difference of the transform.
    h = 1e-6
    num = [
        (ident.theta_of(params, z + h * e) - ident.theta_of(params, z - h * e))[i] / (2 * h)
        for i, e in enumerate(np.eye(z.size))
    ]
    np.testing.assert_allclose(ident.flat_dtheta_dz(params, z), num, rtol=1e-6)
    # Any z maps inside the bounds.
    th = ident.theta_of(params, np.full(z.size, 50.0))
    assert 1e6 < th[0] <= 1e8 and np.all(th[1:4] <= np.asarray(scenario.load.size))


# ---------------------------------------------------------------------------------- input validation


def _write(path, text, side=None):
    path.write_text(text)
    if side is not None:
        path.with_suffix(".json").write_text(json.dumps(side))
    return path


GOOD = "t [s],position_x [m],rope_tension [kN]\n0,1.0,0.0\n0.1,1.01,5.0\n0.2,1.03,7.5\n"


def test_reader_converts_units_and_reads_side_file(tmp_path):
    p = _write(tmp_path / "m.csv", GOOD, {"noise": {"position_x": 0.002, "rope_tension": "1%"}})
    m = read_measurement(p)
    assert m.names == ["position_x", "rope_tension"]
    np.testing.assert_allclose(m.signals["rope_tension"], [0.0, 5e3, 7.5e3])  # kN -> N
    assert m.noise["position_x"] == 0.002
    rms = math.sqrt((5e3**2 + 7.5e3**2) / 3)
    assert m.noise["rope_tension"] == pytest.approx(0.01 * rms)
    # Units only in the side file.
    q = _write(tmp_path / "q.csv", "t,position_x\n0,10\n1,20\n", {"units": {"t": "s", "position_x": "mm"}})
    np.testing.assert_allclose(read_measurement(q).signals["position_x"], [0.01, 0.02])
    # Write -> read round trip keeps values and noise levels (in other units on file).
    w = write_measurement(tmp_path / "w.csv", m, units={"rope_tension": "MN", "t": "ms"})
    back = read_measurement(w)
    np.testing.assert_allclose(back.t, m.t)
    np.testing.assert_allclose(back.signals["rope_tension"], m.signals["rope_tension"])
    assert back.noise["rope_tension"] == pytest.approx(m.noise["rope_tension"])
    # Too few digits to keep the times apart (0, 1, 2 s as 0, 1e+03, 2e+03 ms; 100.1 s and 100.2 s as 1e+02):
    # refused before the file is written, as are digits that are no whole number from 1 to 17.
    dense = Measurement(np.array([0.0, 100.1, 100.2]), {"position_x": np.zeros(3)})
    with pytest.raises(MeasurementError, match="digits = 2 is too few to keep the sample times apart"):
        write_measurement(tmp_path / "few.csv", dense, digits=2)
    assert not (tmp_path / "few.csv").exists()
    write_measurement(tmp_path / "enough.csv", dense, digits=4)
    np.testing.assert_array_equal(read_measurement(tmp_path / "enough.csv").t, dense.t)
    for digits in (0, 18, True):
        with pytest.raises(MeasurementError, match="digits must be a whole number 1 to 17"):
            write_measurement(tmp_path / "bad.csv", dense, digits=digits)


@pytest.mark.parametrize(
    "text, match",
    [
        ("t [s],position_x [m]\n0,1\n0.2,1\n0.1,1\n", r"not sorted: t = 0\.1 s at line 4"),
        ("t [s],position_x [m]\n0,1\n0.1,1\n0.1,1.1\n", r"duplicate time t = 0\.1 s at line 3 and line 4"),
        ("t [s],position_x [m]\n0,1\n0.1,nan\n0.2,1\n", r"column 'position_x' holds NaN at line 3"),
        ("t [s],position_x [m]\n0,1\n0.1,\n0.2,1\n", r"column 'position_x' holds NaN at line 3"),
        ("t [s],positon_x [m]\n0,1\n0.1,1\n", r"unknown signal 'positon_x' \(did you mean 'position_x'\?\)"),
        ("t [s],rope_tenson [N]\n0,1\n0.1,1\n", r"did you mean 'rope_tension'"),
        ("t [s],position_x [kg]\n0,1\n0.1,1\n", r"column 'position_x': unknown unit 'kg'; expected m"),
        (
            "t [s],position_x [N]\n0,1\n0.1,1\n",
            r"column 'position_x': wrong unit 'N' \(a unit of N\); expected m",
        ),
        ("t [s],euler_phi [m]\n0,1\n0.1,1\n", r"column 'euler_phi': wrong unit 'm'.*expected rad"),
        ("t [s],position_x\n0,1\n0.1,1\n", r"column 'position_x' has no unit"),
        ("time [s],position_x [m]\n0,1\n0.1,1\n", r"no time column 't'"),
        ("t [s],position_x [m]\n0,1\n0.1,abc\n", r"line 3, column 'position_x': 'abc' is not a number"),
        ("t [s],position_x [m]\n0,1\n0.1\n", r"line 3 has 1 values, the header has 2 columns"),
    ],
)
def test_bad_measurement_files(tmp_path, text, match):
    p = _write(tmp_path / "bad.csv", text)
    with pytest.raises(MeasurementError, match=match) as e:
        read_measurement(p)
    assert str(p) in str(e.value)  # every message names the file


def test_side_file_errors(tmp_path):
    p = _write(tmp_path / "a.csv", "t [s],position_x [m]\n0,1\n0.1,1\n", {"units": {"position_x": "mm"}})
    with pytest.raises(MeasurementError, match=r"'m' in the header but 'mm'"):
        read_measurement(p)
    p = _write(tmp_path / "b.csv", "t [s],position_x [m]\n0,1\n0.1,1\n", {"noise": {"position_y": 0.1}})
    with pytest.raises(MeasurementError, match=r"noise given for 'position_y'.*did you mean 'position_x'"):
        read_measurement(p)
    p = _write(tmp_path / "c.csv", "t [s],position_x [m]\n0,1\n0.1,1\n", {"unit": {}})
    with pytest.raises(MeasurementError, match=r"unknown key 'unit' \(did you mean 'units'\?\)"):
        read_measurement(p)


@pytest.fixture
def no_compile(monkeypatch):
    """Fail the test if identify reaches the compiled core."""

    def boom(*a, **k):
        raise AssertionError("identify compiled before rejecting invalid input")

    monkeypatch.setattr(ident, "compiled_core", boom)


def test_times_outside_span_rejected_before_compiling(scenario, tmp_path, no_compile):
    p = _write(tmp_path / "long.csv", "t [s],position_x [m]\n0,1\n20,1\n30,1\n")
    with pytest.raises(MeasurementError, match=r"outside the simulated span \[0, 25\] s, first t = 30 s"):
        read_measurement(p, t1=scenario.t1)
    with pytest.raises(MeasurementError, match=r"outside the simulated span \[0, 25\] s"):
        identify(scenario, p, ["mu"])
    with pytest.raises(MeasurementError, match=r"outside the simulated span \[0, 0\.15\] s"):
        identify(scenario, _write(tmp_path / "ok.csv", GOOD), ["mu"], t1=0.15)  # 0.2 s > t1 = 0.15 s
    neg = Measurement(np.array([-0.1, 0.0, 0.1]), {"position_x": np.ones(3)})
    with pytest.raises(MeasurementError, match=r"first t = -0\.1 s"):
        identify(scenario, neg, ["mu"])


@pytest.mark.parametrize("bad", ["unsorted", "duplicate", "nan", "unknown"])
def test_bad_files_rejected_by_identify_before_compiling(scenario, tmp_path, no_compile, bad):
    text = {
        "unsorted": "t [s],position_x [m]\n0,1\n0.2,1\n0.1,1\n",
        "duplicate": "t [s],position_x [m]\n0,1\n0.1,1\n0.1,1\n",
        "nan": "t [s],position_x [m]\n0,1\n0.1,NaN\n0.2,1\n",
        "unknown": "t [s],mass_centre_x [m]\n0,1\n0.1,1\n",
    }[bad]
    with pytest.raises(MeasurementError):
        identify(scenario, _write(tmp_path / f"{bad}.csv", text), ["mu"])


def test_bad_arguments_rejected_before_compiling(scenario, clean, no_compile):
    with pytest.raises(jh.ScenarioError, match=r"'muu'.*\(did you mean 'mu'\?\)"):
        identify(scenario, clean, ["muu"])
    with pytest.raises(jh.ScenarioError, match=r"foundation has no field 'stifness'"):
        identify(scenario, clean, ["foundation.stifness"])
    with pytest.raises(
        jh.ScenarioError, match=r"foundation.damping is fitted on a log scale.*start value > 0"
    ):
        identify(scenario, clean, ["h"], start={"h": 0.0})
    with pytest.raises(jh.ScenarioError, match=r"listed twice"):
        identify(scenario, clean, ["mu", "foundation.friction_coefficient"])
    with pytest.raises(jh.ScenarioError, match=r"must lie strictly inside its bounds"):
        identify(scenario, clean, ["load.mass_centre[0]"], start={"load.mass_centre[0]": 3.0})
    with pytest.raises(MeasurementError, match=r"unknown signal 'postion' \(did you mean 'position'\?\)"):
        identify(scenario, clean, ["mu"], noise={"postion": 0.005})
    with pytest.raises(MeasurementError, match=r"'rope_tension' selects no measured signal"):
        identify(scenario, clean, ["mu"], signals=["rope_tension"])
    with pytest.raises(MeasurementError, match=r"the signal selection is empty; choose from the measured"):
        identify(scenario, clean, ["mu"], signals=[])
    with pytest.raises(jh.ScenarioError, match=r"not both"):
        identify(
            scenario, clean, ["mu"], noise={"position_x": 0.01}, fit=jh.FitOptions(weights={"position": 1.0})
        )


def test_plot_fit_shows_angles_in_degrees():
    """Euler angles and angular velocities are drawn in deg and deg/s, like every other angle plot; lengths
    stay in m. A stand-in result (no fit) carries only the fields `plot_fit` reads."""
    t = np.linspace(0.0, 1.0, 11)
    sig = {"euler_psi": 0.1 * t, "angular_velocity_xi": 0.2 + 0 * t, "position_x": 1.0 + t}
    res = object.__new__(ident.IdentificationResult)
    fields = dict(t=t, measured=sig, fitted={k: v + 1e-3 for k, v in sig.items()}, names=["mu"],
                  values=np.array([0.25]), std_errors=np.array([0.01]))  # fmt: skip
    for k, v in fields.items():
        object.__setattr__(res, k, v)
    fig = ident.plot_fit(res)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_ylabel() for ax in axes] == [
        "euler_psi [deg]",
        "angular_velocity_xi [deg/s]",
        "position_x [m]",
    ]
    np.testing.assert_allclose(axes[0].lines[0].get_ydata(), np.degrees(0.1 * t))
    np.testing.assert_allclose(axes[1].lines[1].get_ydata(), np.degrees(0.2 + 1e-3))
    np.testing.assert_allclose(axes[2].lines[0].get_ydata(), 1.0 + t)


def test_fit_and_solver_options_checked_before_compiling(scenario, clean, no_compile):
    with pytest.raises(jh.ScenarioError, match="n_starts must be >= 1, got 0"):
        jh.FitOptions(n_starts=0)
    with pytest.raises(jh.ScenarioError, match="lm_atol must be a positive number"):
        jh.FitOptions(lm_atol=-1.0)
    # The Rosenbrock-W solver passes every host-side check (identify goes on to compile, which the fixture
    # stops) and is put into forward mode like any other solver.
    with pytest.raises(AssertionError, match="identify compiled before rejecting"):
        identify(scenario, clean, ["mu"], options=jh.SolverOptions())
    w = fit_solver_options(jh.SolverOptions())
    assert isinstance(w.solver, jh.RosenbrockW) and w.forward_mode
    assert fit_solver_options(None) == w  # the default
    assert w.stepsize_controller == jh.SolverOptions().stepsize_controller  # rtol 5e-4, atol 1e-5, PI kept
    with pytest.raises(jh.ScenarioError, match="weights must be a mapping"):
        jh.FitOptions(weights=[1.0])
    with pytest.raises(TypeError, match="unexpected keyword argument.*n_starts"):
        identify(scenario, clean, ["mu"], n_starts=2)  # pyright: ignore[reportCallIssue]  # it is in fit=
