"""`jaxhoist._apps.bifurcation`: candidate jumps on a scan, refinement to |Δp| <= 1e-6 against critical values
derived by hand, and continuation of a boundary."""

import math

import jax

jax.config.update("jax_enable_x64", True)  # tests/conftest.py also does this

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from _inputs import SYMMETRIC_LIFT, symmetric_lift  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._apps.bifurcation import (  # noqa: E402
    BifurcationError,
    Bisection,
    Multisection,
    SearchOptions,
    find_crossings,
    find_jumps,
    locate_bifurcation,
    trace_boundary,
)
from jaxhoist._apps.scan.result import ScanResult  # noqa: E402
from jaxhoist._numerics import observables as O  # noqa: E402
from jaxhoist._physics import kinematics  # noqa: E402

XI = "load.mass_centre[0]"
E_MINUS_D = O.detachment_time_difference("E", "D")
SYM_KW = dict(times=jh.Times(0.2, n=101))


def locate_symmetric(search: SearchOptions):
    """The locator with `search` on the symmetric lift, with every progress report it made."""
    reports = []
    b = locate_bifurcation(
        symmetric_lift(),
        XI,
        E_MINUS_D,
        (0.46, 0.57),
        level=0.0,
        search=search,
        progress=reports.append,
        **SYM_KW,
    )
    return b, reports


@pytest.fixture(scope="module")
def newton_run():
    """The Newton locator on the symmetric lift, with every progress report it made."""
    return locate_symmetric(SearchOptions(tol=1e-6))


@pytest.fixture(scope="module")
def newton_result(newton_run):
    return newton_run[0]


def test_locator_progress_reports(newton_run):
    """One report per solve, numbered 1, 2, ...; the bracket only shrinks and ends as the result's."""
    b, reps = newton_run
    assert [r["iteration"] for r in reps] == list(range(1, b.n_solves + 1))
    assert [r["n_solves"] for r in reps] == list(range(1, b.n_solves + 1))
    assert [r["kind"] for r in reps[:2]] == ["end", "end"] and reps[0]["bracket"] == (0.46, 0.57)
    widths = [r["width"] for r in reps]
    assert all(w1 <= w0 for w0, w1 in zip(widths, widths[1:], strict=False)) and widths[-1] <= 1e-6
    assert reps[-1]["bracket"] == b.bracket
    assert all(r["bracket"][0] <= r["param"] <= r["bracket"][1] for r in reps[2:])
    assert [(r["param"], r["indicator"]) for r in reps] == [(h[0], h[1]) for h in b.history]
    times = [r["elapsed"] for r in reps]
    assert times == sorted(times) and all(r["tol"] == 1e-6 for r in reps)


def test_corner_order_swaps_at_the_symmetric_mass_centre(newton_result):
    """Which corner leaves the ground first swaps at ξ_C* = a/2 = 0.5 m.

    Derivation. The box (a = b = 1 m) stands with D, E, F, H at (0,0), (a,0), (a,b), (0,b); the rope runs
    vertically from the top-face centre B = (a/2, b/2, c) to the boom tip straight above it, and only ξ_C
    varies. The mirror X -> a - X maps the problem with ξ_C onto the one with a - ξ_C and swaps D <-> E and
    H <-> F, so the indicator g(ξ_C) = t_E - t_D (first detachment times) is odd about a/2: g(a - ξ_C) =
    -g(ξ_C), hence g(a/2) = 0, whatever the dynamics. Its sign: with a vertical pull S through x = a/2 the
    ground reaction G - S acts at x_R = (G ξ_C - S a/2)/(G - S) (moments about the D-H edge, as in (2.8)),
    which moves towards x = 0 as S grows when ξ_C < a/2, so the E-F edge unloads first: g < 0 below a/2
    and g > 0 above. The bracket (0.46, 0.57) is not centred on 0.5, so bisection alone would not land
    on it by accident.
    """
    b = newton_result
    assert b.converged and b.width <= 1e-6
    assert abs(b.value - 0.5) <= 1e-6
    assert b.y_lo < 0.0 < b.y_hi  # E leaves first below ξ_C*, D above it
    assert b.kind == "crossing" and b.jump_fraction < 1e-5  # t_E - t_D passes continuously through zero
    g_ends = [h[1] for h in b.history[:2]]
    assert g_ends[0] < 0.0 < g_ends[1]
    # Newton on the event-time difference converges in a handful of solves, against 110 001 for a uniform
    # grid of the same resolution over the bracket.
    assert b.n_uniform == 110_001
    assert b.n_solves <= 12 and b.n_derivative_solves == b.n_solves
    assert any(tag == "newton" for *_, tag in b.history)


def test_bisection_finds_the_same_point_with_more_solves(newton_result):
    b, reps = locate_symmetric(SearchOptions(Bisection(), tol=1e-6))
    # every bisection report halves the bracket
    assert [r["kind"] for r in reps] == ["end", "end"] + ["bisect"] * (b.n_solves - 2)
    for r0, r1 in zip(reps[1:], reps[2:], strict=False):
        assert r1["width"] == pytest.approx(0.5 * r0["width"], rel=1e-9)
    assert b.converged and abs(b.value - 0.5) <= 1e-6
    assert b.n_derivative_solves == 0
    # log2(0.11 / 1e-6) = 16.7 halvings, plus the two ends
    assert b.n_solves == 2 + math.ceil(math.log2(0.11 / 1e-6))
    assert newton_result.n_solves < b.n_solves


def test_multisection_and_continuation_along_the_hoist_speed():
    """Multisection (8 points per vmapped round) finds ξ_C* = 0.5 m too; and the boundary ξ_C*(v_l) traced
    by continuation over three hoist speeds stays at a/2 (the symmetry argument holds for every v_l).
    The progress reports come one per round (the bracket shrinking by k + 1 each time); the continuation's
    reports name the point."""
    mreps = []
    m = locate_bifurcation(
        symmetric_lift(),
        XI,
        E_MINUS_D,
        (0.46, 0.57),
        level=0.0,
        search=SearchOptions(Multisection(points_per_round=8, lanes=8), tol=1e-6),
        progress=mreps.append,
        **SYM_KW,
    )
    assert m.converged and abs(m.value - 0.5) <= 1e-6
    assert m.n_solves % 8 == 0
    assert [r["iteration"] for r in mreps] == list(range(1, m.n_solves // 8 + 1))
    assert [r["n_solves"] for r in mreps] == [8 * r["iteration"] for r in mreps]
    assert all(len(r["param"]) == 8 and r["kind"] == "multisection" for r in mreps)
    for r0, r1 in zip(mreps, mreps[1:], strict=False):
        assert r1["width"] == pytest.approx(r0["width"] / 9, rel=1e-6)
    assert mreps[-1]["bracket"] == m.bracket

    reps = []
    tr = trace_boundary(
        symmetric_lift(),
        XI,
        (0.46, 0.57),
        "hoist.speed",
        [0.05, 0.06, 0.07],
        E_MINUS_D,
        level=0.0,
        search=SearchOptions(tol=1e-6),
        progress=reps.append,
        **SYM_KW,
    )
    np.testing.assert_allclose(tr.values, 0.5, atol=1e-6)
    assert [r["point"] for r in reps] == sorted(r["point"] for r in reps)
    assert {r["point"] for r in reps} == {0, 1, 2} and all(r["n_points"] == 3 for r in reps)
    assert {r["along_value"] for r in reps} == {0.05, 0.06, 0.07}
    assert len(reps) <= tr.n_solves
    assert np.all(tr.widths <= 1e-6)
    assert tr.n_solves < 40 and tr.n_dense > 3e5
    rows = tr.rows()  # the table form: one plain dict per point
    assert [r["along_value"] for r in rows] == [0.05, 0.06, 0.07]
    np.testing.assert_array_equal([r["value"] for r in rows], tr.values)
    assert all(r["kind"] == "crossing" and "history" not in r and r["param"] == XI for r in rows)


def test_slide_or_tip_first_flips_at_the_static_friction_coefficient():
    """A horizontal pull at the top front edge: the box slides first for μ < μ*, tips first for μ > μ*.

    Set-up: a 1 m cube, m = 1000 kg, mass centre at its centre (ξ_C = ζ_C = 0.5 m), on a soft elastic
    foundation (k = 3e5 N/m per corner, so that the foundation's tilt matters) with little damping
    (h = 100 N s/m), regularised Coulomb friction (ε = 1 mm/s). The rope is attached at B = (a, b/2, c) =
    (1, 0.5, 1) m and runs horizontally in +X to a boom tip 50 m away, at the height of B at the critical
    state; the hoist ramps up smoothly, so the pull S grows slowly (~2.5 s) and the load stays in
    quasi-static equilibrium until one of two things happens:

    - sliding: with a horizontal rope Σ N_i = m g; every bottom corner has the same horizontal velocity v
      (translation, and a pitch about Y moves them all alike), so Σ T_i = μ m g r with the utilisation
      r = v/sqrt(v² + ε²). We call "sliding" the first time r reaches r_s = 0.95, i.e. a corner's slip speed
      reaches ε r_s/sqrt(1 - r_s²): then S = r_s μ m g.
    - tipping: the back corners D, H (x = 0) unload. At that instant they touch the ground with N = 0 and
      the front corners carry m g, so they sink p_f = m g/(2k) and the box is pitched by sin θ = p_f/a.
      Moments about the front contact line (the friction and the front normal forces pass through it):
          S (Z_B + p_f) = m g (X_front - X_C),
      with Z_B + p_f = c cos θ + (a - ξ_B) sin θ = c cos θ and X_front - X_C = (a - ξ_C) cos θ - ζ_C sin θ.

    Both at once: μ* = [(a - ξ_C) - ζ_C tan θ] / (c r_s) = 0.51771; on rigid ground (θ = 0) 0.52632.
    The event-time difference t_tip - t_slide changes sign there (-inf above μ*, where the box tips and the
    slip speed never reaches the threshold within 3 s).

    Tolerance: the derivation is quasi-static. The creep speed ε r/sqrt(1 - r²) grows fast near r_s, and
    accelerating the load takes m dv/dt ~ m ε ṙ (1 - r_s²)^(-3/2) ~ 5 N, ~1e-3 of S (measured: S = 4795 N
    at the sliding event against r_s μ m g = 4790 N); the ground dampers and the inertia of the pitch add
    ~1e-4. So we allow 1.5e-3 in μ, a sixth of the elastic-foundation correction (8.6e-3), which the
    located value must resolve.
    """
    r_s, eps_v, m, g, k = 0.95, 1e-3, 1000.0, 9.81, 3e5
    a = c = 1.0
    xi_c = zeta_c = 0.5
    sin_t = m * g / (2 * k * a)
    cos_t = math.sqrt(1 - sin_t**2)
    mu_star = ((a - xi_c) - zeta_c * sin_t / cos_t) / (c * r_s)
    sc = jh.Scenario(
        load=jh.Load([a, 1.0, c], m),
        foundation=jh.Foundation(k, 100.0, 0.5, jh.RegularisedCoulomb(eps_v)),
        rope=jh.Rope(1.5e7, 1.3e4, [a, 0.5, c]),
        hoist=jh.RampedHoist(8e-3, 0.5),
        boom=jh.Boom([a + 50.0, 0.5, c * cos_t - a * sin_t], 500.0, 5.0e6, 5.0e3),
        gravity=g,
        name="slide-or-tip",
        t1=3.0,
    )
    v_slide = eps_v * r_s / math.sqrt(1 - r_s**2)

    def tip_minus_slide(traj, scenario):
        rel = kinematics.bottom_corners(scenario.load.size) - scenario.load.mass_centre

        def slip_speed(v, q, w):  # horizontal speed of corner E [m/s]
            vh = kinematics.points_velocity(v, kinematics.quat_to_matrix(q), w, rel)[1, :2]
            return jnp.sqrt(jnp.sum(vh**2) + 1e-30)

        st = traj.states
        v_e = jax.vmap(slip_speed)(st.velocity, st.quaternion, st.angular_velocity)
        t_slide = O.first_down_crossing(traj.ts, v_slide - v_e)
        t_tip = O.first_down_crossing(traj.ts, O.contact_function(traj, scenario)[:, 0])  # corner D
        return t_tip - t_slide

    obs = O.Observable("tip_minus_slide", tip_minus_slide, "s", "t_tip - t_slide")
    b = locate_bifurcation(
        sc,
        "foundation.friction_coefficient",
        obs,
        (0.514, 0.521),
        level=0.0,
        search=SearchOptions(Bisection(), tol=1e-6),
        times=jh.Times(3.0, n=301),
    )
    assert b.converged and b.width <= 1e-6
    assert b.y_lo > 0.0 > b.y_hi  # slides first below μ*, tips first above
    assert abs(b.value - mu_star) < 1.5e-3
    assert abs(b.value - 0.5 / r_s) > 6e-3  # the rigid-ground value is excluded


def _sweep(x, name, y, status=None, reasons=None) -> ScanResult:
    """A synthetic one-parameter scan result: parameter "p" at `x`, observable `name` with values `y`."""
    n = x.size
    return ScanResult(
        params=["p"],
        mode="sweep",
        coords={"p": x},
        shape=(n,),
        data={name: y},
        components={name: None},
        status=np.zeros(n, dtype=np.int32) if status is None else status,
        reasons={} if reasons is None else reasons,
        num_accepted_steps=np.zeros(n, dtype=np.int32),
        num_rejected_steps=np.zeros(n, dtype=np.int32),
        ts=None,
        histories={},
        units={"p": "-", name: "-"},
        descriptions={},
        attrs={},
    )


def test_find_jumps_on_a_synthetic_scan():
    """A smooth background with a jump, a steep ramp over a few cells, an event that stops happening, and
    a failed member: three candidates, each bracketing its feature."""
    x = np.linspace(0.0, 1.0, 201)
    y = np.sin(3 * x) + 2.0 * (x > 0.3037) + 5.0 * np.clip((x - 0.7) / 0.012, 0.0, 1.0)
    y[x > 0.9025] = np.inf
    status = np.zeros(x.size, dtype=np.int32)
    status[50] = 1
    y[50] = np.nan
    res = _sweep(x, "y", y, status=status, reasons={50: "max_steps"})
    jumps = find_jumps(res, "y")
    assert len(jumps) == 3
    j0, j1, j2 = jumps
    assert j0.lo < 0.3037 < j0.hi and j0.hi - j0.lo == pytest.approx(0.005)
    assert j0.size == pytest.approx(2.0, abs=0.02)
    assert j1.lo <= 0.7 + 1e-12 and j1.hi >= 0.712 and j1.hi - j1.lo <= 0.02  # the ramp, merged into one
    assert j2.lo < 0.9025 < j2.hi and np.isinf(j2.y_hi)


def test_find_jumps_splits_a_one_cell_excursion():
    """A count that steps 8 -> 7 -> 8 over two neighbouring cells is two jumps with different ends (merged,
    they would have equal ends and no sign change to locate); a monotone ramp stays one candidate."""
    x = np.linspace(0.0, 1.0, 101)
    y = np.full(x.size, 8.0)
    y[40] = 7.0
    y[70:74] = [9.0, 10.0, 11.0, 12.0]
    y[74:] = 12.0
    res = _sweep(x, "n", y)
    jumps = find_jumps(res, "n")
    assert [(j.y_lo, j.y_hi) for j in jumps] == [(8.0, 7.0), (7.0, 8.0), (8.0, 12.0)]
    assert jumps[0].hi == jumps[1].lo == x[40]


def test_find_crossings_brackets_every_zero_of_a_continuous_indicator():
    """A smooth indicator crossing 0.2 twice, with a failed member next to the first crossing: two brackets
    of neighbouring valid members, which find_jumps (no jump anywhere) does not report."""
    x = np.linspace(0.0, 1.0, 101)
    y = 0.2 + (x - 0.3037) * (x - 0.8012)  # = 0.2 at x = 0.3037 and 0.8012
    status = np.zeros(x.size, dtype=np.int32)
    status[31] = 1  # the member at x = 0.31, just above the first crossing, failed
    y[31] = np.nan
    res = _sweep(x, "g", y, status=status, reasons={31: "max_steps"})
    assert find_jumps(res, "g") == []
    c0, c1 = find_crossings(res, "g", 0.2)
    assert (c0.lo, c0.hi) == (x[30], x[32]) and c0.y_lo > 0.2 >= c0.y_hi
    assert c1.lo < 0.8012 < c1.hi and c1.hi - c1.lo == pytest.approx(0.01)


def test_scan_plots_show_the_data_failures_and_located_values(newton_result, tmp_path):
    """The plots of a sweep (one panel per component, failed members ticked, located values as lines), of a
    2-D grid (a colour map per component) and of the locator's convergence, built without solving."""
    from jaxhoist._apps.plots import scan as scan_plots

    x = np.linspace(0.0, 1.0, 21)
    y = np.stack([x, x**2], axis=-1)
    status = np.zeros(x.size, dtype=np.int32)
    status[3] = 1
    res = _sweep(x, "v", y, status=status)
    res.components["v"] = ("a", "b")
    fig = scan_plots.plot_sweep(res, "v", located=[0.5])
    ax0, ax1 = fig.axes
    assert ax1.get_xlabel() == "p" and ax0.get_ylabel() == "v[a]" and ax1.get_ylabel() == "v[b]"
    labels = [t.get_text() for t in ax0.get_legend().get_texts()]
    assert labels == ["p* = 0.5", "failed"]
    drawn = ax0.lines[0].get_xydata()
    assert drawn.shape == (20, 2) and 0.15 not in drawn[:, 0]  # the failed member is not drawn

    grid = ScanResult(
        params=["p", "q"],
        mode="grid",
        coords={"p": x[:4], "q": x[:3]},
        shape=(4, 3),
        data={"w": np.arange(12.0).reshape(4, 3)},
        components={"w": None},
        status=np.zeros((4, 3), dtype=np.int32),
        reasons={},
        num_accepted_steps=np.zeros((4, 3), dtype=np.int32),
        num_rejected_steps=np.zeros((4, 3), dtype=np.int32),
        ts=None,
        histories={},
        units={"p": "-", "q": "m/s", "w": "s"},
        descriptions={},
        attrs={},
    )
    fig = scan_plots.plot_grid(grid, "w")
    assert fig.axes[0].get_ylabel() == "q [m/s]" and fig.axes[1].get_ylabel() == "w [s]"  # the colour bar
    with pytest.raises(ValueError, match="grid of two"):
        scan_plots.plot_grid(res, "v")

    fig = scan_plots.plot_locator(newton_result)
    assert "solves against" in fig.get_suptitle()
    paths = scan_plots.save_scan_plots(grid, tmp_path) + scan_plots.save_scan_plots(res, tmp_path)
    assert [p.name for p in paths] == ["scan_w.png", "scan_v.png"] and all(p.stat().st_size for p in paths)


def test_locator_refuses_a_bracket_without_a_sign_change(capfd):
    """... and, with no progress callback, prints nothing while it solves."""
    with pytest.raises(jh.ScenarioError, match="lo < hi"):
        locate_bifurcation(symmetric_lift(), XI, E_MINUS_D, (0.6, 0.4), **SYM_KW)
    with pytest.raises(jh.ScenarioError, match="mass_centre"):
        locate_bifurcation(symmetric_lift(), XI, E_MINUS_D, (0.4, 1.2), **SYM_KW)  # outside the box
    with pytest.raises(BifurcationError, match="same sign"):
        locate_bifurcation(symmetric_lift(), XI, E_MINUS_D, (0.46, 0.48), level=0.0, **SYM_KW)
    out = capfd.readouterr()
    assert out.out == "" and out.err == ""


def test_scan_and_bifurcation_commands(tmp_path, capfd):
    """The `scan` and `bifurcation` subcommands on `symmetric_lift` written as a scenario file, with a
    `--set` override: the scan sees E leave first below ξ_C = a/2 and D above it (the sign argument of
    the test above), and the command-line locator, asked for the sign change of t_E - t_D (`--level 0`;
    the default level is the midpoint of the values at the bracket ends), lands on a/2."""
    import json

    from jaxhoist._apps.cli.app import main

    path = SYMMETRIC_LIFT
    out = tmp_path / "scan"
    common = ["--t1", "0.2", "--n-save", "101", "--set", "hoist.speed=0.05"]  # both commands
    rc = main(["scan", str(path), "--param", XI, "--values", "0.45,0.55", "--observable", "first_corner",
               *common, "--out", str(out), "--quiet"])  # fmt: skip
    assert rc == 0
    res = ScanResult.load(out / "scan")
    assert (out / "scan.nc").read_bytes()[:4] == b"CDF\x02"  # the same dataset as netCDF
    np.testing.assert_array_equal(res.coords[XI], [0.45, 0.55])
    assert np.all(np.asarray(res.status) == 0)
    # Corner indices D, E, F, H = 0..3; η_C = b/2 makes E and F (and D and H) leave together, so either may
    # come first by round-off: the E-F edge below a/2, the D-H edge above it.
    first = [int(x) for x in res["first_corner"]]
    assert first[0] in (1, 2) and first[1] in (0, 3)

    args = ["bifurcation", str(path), "--param", XI, "--bracket", "0.46", "0.57", "--observable",
            "detach:E-D", "--level", "0", "--method", "bisection", "--tol", "1e-4", *common,
            "--out", str(tmp_path / "bif")]  # fmt: skip
    capfd.readouterr()
    rc = main(args)
    assert rc == 0
    err = capfd.readouterr().err  # the locator's bar: the bracket closing in on a log scale, on stderr
    assert "locating: 100%" in err and "bisect" in err and "solves" in err
    found = json.loads((tmp_path / "bif" / "bifurcation.json").read_text())
    assert found["overrides"] == {"hoist.speed": 0.05}
    (b,) = found["bifurcations"]
    assert abs(b["value"] - 0.5) <= 1e-4
    # and the plots: the scanned observable against ξ_C, how the locator converged
    for png in (out / "scan_first_corner.png", tmp_path / "bif" / "locator_0.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", png

    # The same boundary traced along the hoist speed from the command line: ξ_C* = a/2 at every speed.
    argv = [a for a in args if a not in ("--out", str(tmp_path / "bif"))]
    rc = main([*argv, "--along", "hoist.speed", "--along-values", "0.05,0.06", "--out", str(tmp_path / "tr")])
    assert rc == 0
    rows = json.loads((tmp_path / "tr" / "bifurcation.json").read_text())["boundary"]["rows"]
    assert [r["along_value"] for r in rows] == [0.05, 0.06]
    assert all(abs(r["value"] - 0.5) <= 1e-4 for r in rows)
    assert (tmp_path / "tr" / "boundary.png").exists()


def test_trace_reports_a_vanished_jump_as_lost(monkeypatch):
    """With the level re-estimated per bracket the corrector always finds some crossing; where the change
    across the final bracket is a small fraction of the first point's jump, the boundary is reported lost
    (NaN, with a note), not followed onto a level crossing of a flat observable. The locator is replaced by
    a stand-in (no solves): a jump of size 1 at q = 0 and 0.9, of size 1e-4 at q = 0.5."""
    import types

    from jaxhoist._apps.bifurcation import trace as bifurcation_trace

    def fake_locate(sc, param, obs, br, level=None, search=SearchOptions(), **kw):
        q = float(sc.hoist.speed)
        size = 1e-4 if abs(q - 0.5) < 1e-9 else 1.0
        return types.SimpleNamespace(
            value=0.5 * sum(br), y_lo=0.0, y_hi=size, n_solves=3, width=search.tol, notes=[]
        )

    monkeypatch.setattr(bifurcation_trace, "locate_bifurcation", fake_locate)
    tr = trace_boundary(
        symmetric_lift(), "load.mass_centre[0]", (0.4, 0.6), "hoist.speed", [0.1, 0.5, 0.9], "final_psi"
    )
    assert np.isfinite(tr.values[0]) and np.isnan(tr.values[1]) and np.isfinite(tr.values[2])
    assert "lost" in tr.points[1].notes[0]


def test_trace_boundary_passes_its_settings_to_every_point(monkeypatch):
    """`trace_boundary`'s `search`, `options` and `times` reach every `locate_bifurcation` call as the same
    objects (the locator replaced by a recorder: no solves)."""
    import types

    import diffrax

    from jaxhoist._apps.bifurcation import trace as bifurcation_trace

    seen = []

    def record(sc, param, obs, br, *, search, options, **kw):
        seen.append((search, options, kw))
        return types.SimpleNamespace(value=0.5, y_lo=0.0, y_hi=1.0, n_solves=1, width=search.tol, notes=[])

    monkeypatch.setattr(bifurcation_trace, "locate_bifurcation", record)
    args = (symmetric_lift(), XI, (0.46, 0.57), "hoist.speed", [0.05, 0.06], E_MINUS_D)
    search = SearchOptions(
        Multisection(points_per_round=4, lanes=4), 1e-5, initial_half_width=0.01, max_expansions=3
    )
    options = jh.SolverOptions(diffrax.Tsit5(), atol=1e-9)
    trace_boundary(*args, search=search, options=options, times=0.2)
    assert len(seen) == 2
    for s, o, kw in seen:
        assert s == search and o is options and kw["times"] == jh.Times(0.2)
    assert (options.solver, options.rtol, options.atol) == (diffrax.Tsit5(), 1e-6, 1e-9)


def _no_solve(*a, **k):
    raise AssertionError("a solve ran despite the refusal")


def test_trace_boundary_refuses_invalid_input_before_solving(monkeypatch):
    """A bracket, level, continuation parameter or continuation value that is invalid is refused with the
    argument's name before any point is solved (it was a NaN point, or a Boundary of NaNs with n_dense < 0);
    the values may be text as `scan`'s `--values`, increasing or decreasing."""
    import types

    from jaxhoist._apps.bifurcation import trace as bifurcation_trace

    monkeypatch.setattr(bifurcation_trace, "locate_bifurcation", _no_solve)
    sc = symmetric_lift()
    refusals = [
        (((0.57, 0.46), "hoist.speed", [0.05, 0.06]), {}, r"bracket must be two finite values lo < hi"),
        (((0.46, 0.46), "hoist.speed", [0.05, 0.06]), {}, r"bracket must be two finite values lo < hi"),
        (((0.46, np.nan), "hoist.speed", [0.05, 0.06]), {}, r"bracket must be two finite values lo < hi"),
        (((0.46, 0.57), "hoist.speed", [0.05, -0.05]), {}, r"along_values: hoist.speed = -0.05 is invalid"),
        (((0.46, 0.57), "hoist.speed", [0.05, np.nan]), {}, r"along_values must be finite"),
        (((0.46, 0.57), "hoist.speed", [0.05, 0.05, 0.06]), {}, r"along_values must be distinct values"),
        (((0.46, 0.57), "hoist.speed", [0.05, 0.07, 0.05]), {}, r"along_values must be distinct values"),
        (((0.46, 0.57), "hoist.speed", []), {}, r"along_values: expected a non-empty"),
        (((0.46, 0.57), "hoist.speed", "0.05:0.06"), {}, r"along_values: expected 'start:stop:num'"),
        (((0.46, 0.57), XI, [0.47, 0.48]), {}, r"along 'load.mass_centre\[0\]' is the located parameter"),
        (((0.46, 0.57), "hoist.sped", [0.05, 0.06]), {}, r"along"),
        (((0.46, 0.57), "hoist.speed", [0.05, 0.06]), {"level": np.nan}, r"level must be a finite number"),
    ]
    for args, kw, words in refusals:
        with pytest.raises(jh.ScenarioError, match=words):
            trace_boundary(sc, XI, *args, E_MINUS_D, **kw, **SYM_KW)
    with pytest.raises(jh.ScenarioError, match=r"'final_position\[z\]'"):
        trace_boundary(sc, XI, (0.46, 0.57), "hoist.speed", [0.05], "final_position", **SYM_KW)

    def record(sc, param, obs, br, **kw):
        return types.SimpleNamespace(value=0.5, y_lo=0.0, y_hi=1.0, n_solves=1, width=1e-6, notes=[])

    monkeypatch.setattr(bifurcation_trace, "locate_bifurcation", record)
    for spec, qs in (("0.05:0.06:3", [0.05, 0.055, 0.06]), ("0.07,0.05", [0.07, 0.05]), ([0.06], [0.06])):
        tr = trace_boundary(sc, XI, (0.46, 0.57), "hoist.speed", spec, E_MINUS_D, **SYM_KW)
        np.testing.assert_allclose(tr.along_values, qs, rtol=0, atol=1e-15)
        assert tr.n_dense > 0


def test_locator_refuses_a_vector_observable_and_a_bad_bracket_or_level_before_solving(monkeypatch):
    """A vector observable gets the command line's message (pick a component) before any solve (it solved,
    then failed converting an array to a float); a bracket that is not two numbers, and a level that is
    not finite, are refused naming the argument; a `Jump` is a bracket."""
    from jaxhoist._apps.bifurcation import jumps as bifurcation_jumps
    from jaxhoist._apps.bifurcation import locate as bifurcation_locate

    monkeypatch.setattr(bifurcation_locate, "_refine", _no_solve)
    monkeypatch.setattr(bifurcation_locate, "multisection", _no_solve)
    sc = symmetric_lift()
    refusals = [
        (("final_position", (0.46, 0.57)), {}, r"observable 'final_position' is a vector observable .* "
         r"pick one, e.g. 'final_position\[z\]'"),
        ((E_MINUS_D, (0.46, 0.57)), {"level": np.nan}, r"level must be a finite number"),
        ((E_MINUS_D, (0.46, 0.57)), {"level": -np.inf}, r"level must be a finite number"),
        ((None, (0.46, 0.57)), {}, r"observable: one observable is needed, got 4"),
        ((3.5, (0.46, 0.57)), {}, r"observable: expected a built-in name"),
    ]  # fmt: skip
    for args, kw, words in refusals:
        with pytest.raises(jh.ScenarioError, match=words):
            locate_bifurcation(sc, XI, *args, **kw, **SYM_KW)
    # what the annotations refuse under the tests' run-time type checking, but a user's call reaches (it
    # was "too many values to unpack" and "'float' object is not iterable"): the check the locator makes
    cases = (((0.46, 0.5, 0.57), r"\(0.46, 0.5, 0.57\)"), (0.5, "0.5"), ("ab", "'ab'"), ("12", "'12'"))
    for bracket, shown in cases:
        with pytest.raises(jh.ScenarioError, match=rf"^bracket must be two numbers lo < hi, got {shown}$"):
            bifurcation_locate.check_bracket(bracket)
    with pytest.raises(jh.ScenarioError, match=r"^level must be a finite number"):
        bifurcation_locate.check_level("0")

    def stop(p):  # the checked problem, shown instead of solved
        raise RuntimeError(f"{p.lo}, {p.hi}, {p.level}")

    monkeypatch.setattr(bifurcation_locate, "_refine", stop)
    j = bifurcation_jumps.Jump(XI, "e-d", 0.46, 0.57, -1.0, 1.0, 2.0, np.inf, 0)
    with pytest.raises(RuntimeError, match=r"^0.46, 0.57, 0.0$"):
        locate_bifurcation(sc, XI, E_MINUS_D, j, level=0.0, **SYM_KW)


def test_search_options_refuse_a_budget_the_locator_cannot_start_with():
    """`max_solves` is a whole number no smaller than the first evaluations (the two ends; a multisection's
    first round); the continuation's settings are checked alike."""
    refusals = [
        ({"max_solves": 0}, r"max_solves must be a whole number >= 2 .*got 0"),
        ({"max_solves": -3}, r"max_solves must be a whole number >= 2 .*got -3"),
        ({"max_solves": True}, r"max_solves"),
        ({"method": Multisection(points_per_round=8), "max_solves": 7}, r"max_solves .* >= 8"),
        ({"max_expansions": 0}, r"max_expansions must be a whole number >= 1"),
        ({"initial_half_width": 0.0}, r"initial_half_width must be > 0"),
        ({"min_jump_fraction": np.nan}, r"min_jump_fraction must be a finite number >= 0"),
    ]
    for kw, words in refusals:
        with pytest.raises(jh.ScenarioError, match=words):
            SearchOptions(**kw)
    from jaxhoist._io.validate import whole_number  # SearchOptions' test of max_solves, max_expansions

    # 2.5 reaches the check in a user's call (the tests' run-time type checking refuses it before)
    assert not whole_number(2.5) and whole_number(np.int64(2)) and not whole_number(True)
    assert SearchOptions(max_solves=2).max_solves == 2
    assert SearchOptions(Multisection(points_per_round=8), max_solves=8).max_solves == 8


def test_find_jumps_refuses_settings_that_would_hide_the_jumps():
    """A NaN factor found no jump at all; a negative one, an empty window or a negative min_size, an unknown
    parameter or observable, and a saved scan's path are refused naming the argument."""
    x = np.linspace(0.0, 1.0, 21)
    res = _sweep(x, "impacts", np.where(x > 0.5, 3.0, 2.0))
    assert len(find_jumps(res, "impacts")) == 1
    refusals = [
        ({"factor": np.nan}, r"find_jumps: factor must be a finite number > 0, got nan"),
        ({"factor": -1.0}, r"factor must be a finite number > 0"),
        ({"window": 0}, r"find_jumps: window must be a whole number >= 1, got 0"),
        ({"min_size": -1.0}, r"find_jumps: min_size must be a finite number >= 0"),
        ({"param": "foo"}, r"find_jumps: param 'foo' is not a parameter of the scan: \['p'\]"),
    ]
    for kw, words in refusals:
        with pytest.raises(jh.ScenarioError, match=words):
            find_jumps(res, "impacts", **kw)
    with pytest.raises(jh.ScenarioError, match=r"observable 'impact' is not an observable of the scan"):
        find_jumps(res, "impact")
    with pytest.raises(jh.ScenarioError, match=r"find_crossings: level must be a finite number"):
        find_crossings(res, "impacts", np.nan)
    # what the annotations refuse under the tests' run-time type checking, but a user's call reaches (it was
    # an AttributeError): the checks find_jumps makes
    from jaxhoist._apps.bifurcation import jumps as bifurcation_jumps

    with pytest.raises(TypeError, match=r"ScanResult.load\(path\) first"):
        bifurcation_jumps._series("scan.npz", "impacts", None, "find_jumps")
    with pytest.raises(jh.ScenarioError, match=r"window must be a whole number >= 1, got 2.5"):
        bifurcation_jumps._check_jump_settings(8.0, 2.5, None)


def test_bifurcation_command_refuses_in_one_line(tmp_path, capsys, monkeypatch):
    """`jaxhoist bifurcation` refuses an invalid bracket, level, --along or --along-values in one line and
    exit code 2 before anything is solved; a search that ran and could not proceed (no sign change) ends in
    one line and exit code 1, not a traceback."""
    from jaxhoist._apps.cli import bifurcation as bifurcation_cli
    from jaxhoist._apps.cli.app import main

    for name in ("locate_bifurcation", "scan", "trace_boundary"):
        monkeypatch.setattr(bifurcation_cli, name, _no_solve)
    monkeypatch.chdir(tmp_path)
    base = ["bifurcation", "paper-4.2", "--param", "foundation.friction_coefficient", "--observable",
            "contact_margin[E]", "--t1", "0.6", "--n-save", "601", "--quiet", "--out", "out"]  # fmt: skip
    along = ["--along", "hoist.speed", "--along-values"]

    def error_line(argv, code):
        assert main(argv) == code
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert "Traceback" not in err and len(lines) == 1 and lines[0].startswith("jaxhoist: error: "), err
        return lines[0]

    refusals = [
        (["--bracket", "0.3", "0.25", *along, "0.3:0.32:2"], "--bracket must be two finite values lo < hi"),
        (["--bracket", "0.1", "0.2", "--level", "nan"], "--level must be a finite number"),
        (["--bracket", "0.1", "0.2", *along, "0.3,0.3,0.32"], "--along-values must be distinct values"),
        (["--bracket", "0.1", "0.2", *along, "0.3,nan"], "--along-values must be finite"),
        (["--bracket", "0.1", "0.2", *along, "0.3,-0.3"], "--along-values: hoist.speed = -0.3 is invalid"),
        (["--bracket", "0.1", "0.2", "--along", "foundation.friction_coefficient", "--along-values",
          "0.3,0.4"], "--along 'foundation.friction_coefficient' is the located parameter"),
        (["--bracket", "0.1", "0.2", "--along", "hoist.speed"], "--along and --along-values go together"),
    ]  # fmt: skip
    for extra, words in refusals:
        assert words in error_line([*base, *extra], 2)
    assert not (tmp_path / "out").exists()

    def no_sign_change(*a, **k):
        raise BifurcationError("contact_margin[E] - level has the same sign at both ends of the bracket")

    monkeypatch.setattr(bifurcation_cli, "locate_bifurcation", no_sign_change)
    line = error_line([*base, "--bracket", "0.1", "0.2", "--level", "0"], 1)
    assert line == "jaxhoist: error: contact_margin[E] - level has the same sign at both ends of the bracket"
