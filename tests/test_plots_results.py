"""Result files (npz + JSON sidecar) and plots: round trip of every array and unit, scenario metadata,
lift-off detection, and every plot function returning a Figure with unit-labelled axes."""

import jax

jax.config.update("jax_enable_x64", True)

import json  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._apps.plots import trajectory as plots  # noqa: E402
from jaxhoist._io import results  # noqa: E402

try:  # share the compiled core with the physics tests (same saved-time count and solver options)
    from conftest import N_SAVE, SOLVE_OPTIONS
except ImportError:  # pragma: no cover - running this file alone without the shared conftest
    N_SAVE, SOLVE_OPTIONS = 201, jh.SolverOptions(rtol=1e-8, atol=1e-9)

T1 = 1.0  # [s]: corners D and H of paper-4.2 leave the ground within 0.3 s, so every plot has content


@pytest.fixture(scope="module")
def traj42():
    scenario = jh.load_scenario("paper-4.2")
    ts = jnp.linspace(0.0, T1, N_SAVE)
    return scenario, jh.simulate(scenario, jh.Times(ts=ts), options=SOLVE_OPTIONS)


def test_npz_round_trip_preserves_arrays_units_and_scenario(traj42, tmp_path):
    scenario, traj = traj42
    arrays = results.trajectory_arrays(traj)
    npz, meta = results.save_trajectory(
        tmp_path / "run" / "trajectory",
        traj,
        scenario,
        command=["jaxhoist", "simulate", "paper-4.2"],
        options={"rtol": 1e-8},
    )
    assert npz.suffix == ".npz" and meta.suffix == ".json" and npz.parent == meta.parent

    loaded = results.load_trajectory(npz)
    assert set(loaded) == set(results.TRAJECTORY_ARRAYS) == set(arrays)
    for name, a in arrays.items():
        assert loaded[name].shape == a.shape and loaded[name].dtype == a.dtype, name
        np.testing.assert_array_equal(loaded[name], a, err_msg=name)
    # the same file by stem or by sidecar path
    np.testing.assert_array_equal(
        results.load_trajectory(tmp_path / "run" / "trajectory.json")["position"], arrays["position"]
    )

    units = results.units(npz)
    assert units == {k: u for k, (u, _) in results.TRAJECTORY_ARRAYS.items()}
    assert (units["position"], units["normal_forces"], units["euler"], units["ts"]) == ("m", "N", "rad", "s")

    md = json.loads(meta.read_text())
    assert md["versions"]["jaxhoist"] == jh.__version__
    assert md["command"] == ["jaxhoist", "simulate", "paper-4.2"]
    assert md["status"] == "ok"
    assert md["scenario"]["name"] == "paper-4.2"
    leaves = md["scenario"]["leaves"]
    assert leaves["foundation.friction_coefficient"] == float(scenario.foundation.friction_coefficient)
    assert leaves["load.mass"] == pytest.approx(850.0 * 2.5 * 6.0 * 2.5)  # ρ a b c [kg], paper §4.2
    assert leaves["load.mass_centre"] == [1.0, 2.5, 1.0]
    assert md["scenario"]["types"]["foundation.friction"] == type(scenario.foundation.friction).__name__
    assert md["arrays"]["friction_forces"]["shape"] == [N_SAVE, 4, 3]

    # derived arrays stay consistent through the file: R = ΣN_i, E_mech = Σ terms
    np.testing.assert_allclose(loaded["ground_reaction"], loaded["normal_forces"].sum(axis=1), rtol=1e-12)
    terms = sum(
        loaded[f"energy_{k}"] for k in ("kinetic", "potential", "ground_spring", "rope_spring", "boom_spring")
    )
    np.testing.assert_allclose(loaded["energy_mechanical"], terms, rtol=1e-12)
    np.testing.assert_allclose(
        loaded["energy_residual"], np.asarray(traj.energy_residual()), rtol=0, atol=1e-9
    )


def test_liftoff_and_detach_times():
    ts = np.linspace(0.0, 4.0, 5)
    n = np.array(
        [
            [1.0, 1.0, 1.0, 1.0],
            [0.0, 2.0, 1.0, 1.0],
            [0.0, 0.0, 3.0, 0.0],
            [0.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ]
    )  # F touches down again at t = 4 s
    assert results.liftoff_time(ts, n) == 3.0
    assert results.corner_detach_times(ts, n) == [1.0, 2.0, 3.0, 2.0]
    assert results.liftoff_time(ts, np.ones((5, 4))) is None


def test_liftoff_on_the_paper_run(traj42):
    _, traj = traj42
    a = results.trajectory_arrays(traj)
    detach = results.corner_detach_times(a["ts"], a["normal_forces"])
    # the rope pulls at the top corner above D: D lifts first, and the load is not yet off the ground at 1 s
    assert detach[0] is not None and detach[0] < 0.5
    assert results.liftoff_time(a["ts"], a["normal_forces"]) is None
    assert a["rope_tension"].max() > 0.0


def _labels_ok(fig):
    from matplotlib.figure import Figure

    assert isinstance(fig, Figure)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert axes
    for ax in axes:
        y = ax.get_ylabel()
        assert "[" in y and "]" in y, f"y label without a unit: {y!r}"
        assert ax.has_data()
    xlabels = [ax.get_xlabel() for ax in axes if ax.get_xlabel()]
    assert xlabels and all("[" in x and "]" in x for x in xlabels), xlabels
    assert fig.get_suptitle()


@pytest.mark.parametrize("name", [*plots.PLOTS, "motion"])
def test_plot_functions_return_labelled_figures(traj42, name):
    _, traj = traj42
    fn = plots.PLOTS.get(name) or getattr(plots, f"plot_{name}")
    _labels_ok(fn(traj))  # from a Trajectory


def test_plots_from_loaded_file_and_save_all(traj42, tmp_path):
    scenario, traj = traj42
    npz, _ = results.save_trajectory(tmp_path / "t", traj, scenario)
    d = results.load_trajectory(npz)
    fig = plots.plot_corner_tracks(d)
    _labels_ok(fig)
    assert fig.axes[0].get_xlabel() == "X [m]" and fig.axes[0].get_ylabel() == "Y [m]"
    fig = plots.plot_euler(d)
    # the angles are plotted in degrees
    np.testing.assert_allclose(fig.axes[0].lines[0].get_ydata(), np.degrees(d["euler"][:, 0]))
    paths = plots.save_all(d, tmp_path / "png")
    assert len(paths) == len(plots.PLOTS)
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert 5_000 < p.stat().st_size < 300_000


def _fake_sweep(mu, data, units, components):
    from jaxhoist._apps.scan.result import ScanResult

    n = mu.size
    return ScanResult(
        params=["foundation.friction_coefficient"],
        mode="sweep",
        coords={"foundation.friction_coefficient": mu},
        shape=(n,),
        data=data,
        components=components,
        status=np.zeros(n, dtype=np.int32),
        reasons={},
        num_accepted_steps=np.full(n, 100),
        num_rejected_steps=np.zeros(n, dtype=int),
        ts=None,
        histories={},
        units={"foundation.friction_coefficient": "-", **units},
        descriptions={},
        attrs={},
    )


def test_scan_plots_use_degrees_and_draw_no_empty_panels(tmp_path):
    from jaxhoist._apps.plots import scan as scan_plots

    mu = np.linspace(0.2, 0.4, 5)
    psi = np.stack([np.zeros(5), 0.1 * mu, np.zeros(5)], axis=1)  # final (φ, ψ, ϑ) [rad]
    detach = np.stack([mu, np.full(5, np.inf), 2 * mu, np.full(5, np.inf)], axis=1)  # E and H never leave
    data = {"final_euler": psi, "liftoff_time": np.full(5, np.inf), "detachment_times": detach}
    res = _fake_sweep(
        mu,
        data,
        {"final_euler": "rad", "liftoff_time": "s", "detachment_times": "s"},
        {"final_euler": ("phi", "psi", "theta"), "detachment_times": ("D", "E", "F", "H")},
    )
    fig = scan_plots.plot_sweep(res, "final_euler")
    assert "[deg]" in fig.get_suptitle() and "rad" not in fig.get_suptitle()
    np.testing.assert_allclose(fig.axes[1].lines[0].get_ydata(), np.degrees(0.1 * mu))
    assert fig.axes[1].get_ylabel() == "final_euler[psi]"
    # corners that never leave the ground get no panel; the title says which were left out
    fig = scan_plots.plot_sweep(res, "detachment_times")
    assert [ax.get_ylabel() for ax in fig.axes] == ["detachment_times[D]", "detachment_times[F]"]
    assert "detachment_times[E], detachment_times[H]" in fig.get_suptitle()
    assert all(ax.has_data() for ax in fig.axes)
    # nothing lifts off: no scan_liftoff_time.png at all
    paths = scan_plots.save_scan_plots(res, tmp_path)
    assert sorted(p.name for p in paths) == ["scan_detachment_times.png", "scan_final_euler.png"]
    assert scan_plots.display_unit("rad/s") == (pytest.approx(180 / np.pi), "deg/s")
    assert scan_plots.display_unit("m") == (1.0, "m")


def test_component_observables_keep_the_name_as_written():
    from jaxhoist._numerics import observables

    assert observables.get("contact_margin[E]").name == "contact_margin[E]"  # not contact_margin[1]
    assert observables.get("final_euler[1]").name == "final_euler[1]"


def test_rigid_results_keep_the_phase_log(traj42, tmp_path):
    """A rigid-model trajectory saves `impact_loss`, `phase_index` and the phase log (names per phase)."""
    import types

    from jaxhoist._numerics.rigid.solve import PhaseRecord

    scenario, traj = traj42
    n = N_SAVE
    names = (
        "ts",
        "position",
        "velocity",
        "euler",
        "angular_velocity",
        "corners",
        "normal_forces",
        "friction_forces",
        "ground_reaction",
        "rope_tension",
        "tip_position",
        "energy",
        "hoist_work",
        "damping_loss",
        "friction_work",
        "states",
        "status",
        "num_accepted_steps",
        "num_rejected_steps",
    )
    fields = {k: getattr(traj, k) for k in names}
    phases = (
        PhaseRecord(0.0, 0.4, ("stick",) * 4, True, "rest:slip"),
        PhaseRecord(0.4, T1, ("free", "slide", "slide", "free"), False, "t1"),
    )
    index = jnp.asarray(np.arange(n) > n // 2, dtype=int)
    rigid_like = types.SimpleNamespace(**fields, impact_loss=jnp.zeros(n), phase_index=index, phases=phases)
    npz, meta = results.save_trajectory(tmp_path / "r", rigid_like, scenario)
    loaded = results.load_trajectory(npz)
    assert set(loaded) == set(results.TRAJECTORY_ARRAYS) | {"impact_loss", "phase_index"}
    md = json.loads(meta.read_text())
    assert [p["name"] for p in md["phases"]] == ["rest", "E slide, F slide"]
    assert md["arrays"]["phase_index"]["unit"] == "-" and md["arrays"]["impact_loss"]["unit"] == "J"
    nc = results.save_trajectory_netcdf(tmp_path / "r.nc", loaded)
    assert nc.read_bytes()[:4] == b"CDF\x02"
