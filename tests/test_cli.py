"""The `jaxhoist` command line, called in-process through `main([...])` so that compiled code is shared:
a short simulate writes npz/json/csv/nc/PNGs and a summary (with progress bars on stderr); its CSV goes into
`identify` unchanged; invalid input exits 2 with a one-line message naming the field (in the CLI's flag
names), before anything is compiled; every --help shows the defaults; subcommand modules plug in through
`configure_parser`."""

import jax

jax.config.update("jax_enable_x64", True)

import json  # noqa: E402
import sys  # noqa: E402
import types  # noqa: E402
from importlib import resources  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxhoist._apps.cli import app as cli  # noqa: E402
from jaxhoist._apps.cli import simulate as simulate_cli  # noqa: E402
from jaxhoist._io import results  # noqa: E402
from jaxhoist._io.scenario import SCHEMA  # noqa: E402

SHORT = ["--t1", "0.5", "--n-save", "11"]


def _no_compile(monkeypatch):
    """Make any attempt to compile fail the test (invalid input must be refused before compiling)."""

    def boom(*a, **k):
        raise AssertionError("compiled despite invalid input")

    monkeypatch.setattr(simulate_cli, "_compiled_solve", boom)


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    # not --quiet: the progress meter is compiled into the solve; test_summary_and_progress_lines reuses it
    out = tmp_path_factory.mktemp("cli") / "paper-4.2"
    code = cli.main(["simulate", "paper-4.2", *SHORT, "--out", str(out)])
    return code, out


def test_simulate_writes_results_and_plots(short_run, capsys):
    code, out = short_run
    assert code == 0
    npz, meta = out / "trajectory.npz", out / "trajectory.json"
    assert npz.is_file() and meta.is_file()
    d = results.load_trajectory(npz)
    assert d["ts"].shape == (11,) and d["ts"][-1] == pytest.approx(0.5)
    assert d["normal_forces"].shape == (11, 4) and d["corners"].shape == (11, 4, 3)
    # at t = 0 the load rests: corner loads carry the weight minus the rope's vertical pull (here S(0) = 0)
    m, g = 850.0 * 2.5 * 6.0 * 2.5, 9.81
    assert d["ground_reaction"][0] == pytest.approx(m * g, rel=1e-6)
    assert int(d["status"]) == 0
    md = json.loads(meta.read_text())
    assert md["command"][:3] == ["jaxhoist", "simulate", "paper-4.2"] and "--t1" in md["command"]
    assert md["solver"]["t1"] == 0.5 and md["solver"]["n_save"] == 11
    assert md["scenario"]["name"] == "paper-4.2"
    assert md["arrays"]["rope_tension"]["unit"] == "N"
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == sorted(f"{n}.png" for n in cli_plots())
    assert all((out / p).stat().st_size > 5_000 for p in pngs)
    assert (out / "trajectory.csv").is_file() and (out / "trajectory.nc").is_file()
    assert not (out / "animation.gif").exists()  # only with --animate


def test_trajectory_csv_and_netcdf_hold_the_npz_values(short_run):
    import scipy.io

    from jaxhoist._io.measurement import SIGNALS, read_measurement

    _, out = short_run
    d = results.load_trajectory(out / "trajectory.npz")
    # the CSV reads as a measurement (trajectory.json next to it is the npz's sidecar, not a side file)
    m = read_measurement(out / "trajectory.csv")
    assert set(m.signals) == set(SIGNALS)
    np.testing.assert_allclose(m.t, d["ts"], rtol=1e-11)
    np.testing.assert_allclose(m.signals["position_z"], d["position"][:, 2], rtol=1e-11)
    np.testing.assert_allclose(m.signals["euler_psi"], d["euler"][:, 1], rtol=1e-11, atol=1e-15)
    np.testing.assert_allclose(m.signals["corners_F_y"], d["corners"][:, 2, 1], rtol=1e-11)
    np.testing.assert_allclose(m.signals["normal_forces_E"], d["normal_forces"][:, 1], rtol=1e-11)
    header = (out / "trajectory.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "t [s]" and "rope_tension [N]" in header and "euler_phi [rad]" in header
    # netCDF: every npz array under its name, with the units table's unit
    with scipy.io.netcdf_file(str(out / "trajectory.nc"), "r", mmap=False) as f:
        v = f.variables
        np.testing.assert_array_equal(v["corners"][:], d["corners"])
        np.testing.assert_array_equal(v["ts"][:], d["ts"])
        assert v["normal_forces"].dimensions == ("time", "corner")
        assert v["normal_forces"].units == b"N" and v["euler"].units == b"rad" and v["ts"].units == b"s"
        assert b"".join(v["corner_name"][:].ravel()) == b"DEFH"
        assert int(v["status"].getValue()) == 0
        assert json.loads(f.metadata_json)["scenario"]["name"] == "paper-4.2"


def test_simulate_csv_goes_into_identify_unchanged(tmp_path):
    """simulate (μ = 0.3) -> trajectory.csv -> identify recovers μ from the mass-centre path (0.4 s: before a
    corner touches down again, see docs/identification.md); `identify --set` applies overrides first."""
    sim = tmp_path / "sim"
    # rtol 1e-8: the data are then exact to well below the fit's tolerance (at rtol 1e-3 with the
    # Rosenbrock-W solver the path is off by ~1e-4 relative and a fit lands 4e-4 away from 0.3)
    assert (
        cli.main(
            [
                "simulate",
                "paper-4.2",
                "--t1",
                "0.4",
                "--n-save",
                "21",
                "--out",
                str(sim),
                "--quiet",
                "--no-plots",
                "--set",
                "foundation.friction_coefficient=0.3",
                "--rtol",
                "1e-8",
                "--atol",
                "1e-10",
            ]
        )
        == 0
    )
    fit = tmp_path / "fit"
    code = cli.main(
        [
            "identify",
            "paper-4.2",
            str(sim / "trajectory.csv"),
            "--fit",
            "mu",
            "--signals",
            "position",
            "--start",
            "mu=0.25",
            "--t1",
            "0.4",
            "--out",
            str(fit),
            "--no-plots",
            "--quiet",
            "--set",
            "hoist.speed=0.3",
            # Tsit5 at rtol 1e-6: its model error is far below the 1e-4 asked here; the default (the W solver
            # at rtol 5e-4) is off by ~1e-4 relative on this path and is run by test_identify's CLI test
            "--solver",
            "tsit5",
        ]
    )
    doc = json.loads((fit / "estimates.json").read_text())
    assert code == 0, doc
    assert doc["estimates"]["foundation.friction_coefficient"]["value"] == pytest.approx(0.3, rel=1e-4)
    assert doc["overrides"] == {"hoist.speed": 0.3}


def cli_plots():
    from jaxhoist._apps.plots import trajectory as plots

    return plots.PLOTS


def test_summary_and_progress_lines(short_run, tmp_path, capsys):
    # same shapes and options as short_run: the compiled core is reused, so this is quick
    code = cli.main(
        [
            "simulate",
            "paper-4.2",
            *SHORT,
            "--out",
            str(tmp_path),
            "--no-plots",
            "--set",
            "foundation.friction_coefficient=0.3",
        ]
    )
    assert code == 0
    cap = capsys.readouterr()
    assert "compiling (cached in this process)" in cap.err and "solving ..." in cap.err
    # diffrax's progress meter, drawn as a bar on stderr; stdout holds only the summary
    assert "solving: 100%" in cap.err and "%" not in cap.out
    assert "loading scenario paper-4.2 ..." in cap.err
    for key in ("status        ok", "final C", "lift-off      none within the horizon", "steps", "wall time"):
        assert key in cap.out, key
    assert not list(tmp_path.glob("*.png"))
    md = results.load_metadata(tmp_path / "trajectory.npz")
    assert md["scenario"]["leaves"]["foundation.friction_coefficient"] == 0.3
    assert md["overrides"] == {"foundation.friction_coefficient": 0.3}


def test_misspelled_field_exits_2_naming_the_field(tmp_path, capsys, monkeypatch):
    _no_compile(monkeypatch)
    text = resources.files("jaxhoist._io.presets").joinpath("paper-4.2.toml").read_text()
    assert "friction_coefficient = 0.25" in text
    bad = tmp_path / "typo.toml"
    bad.write_text(text.replace("friction_coefficient = 0.25", "friction_coeficient = 0.25"))
    code = cli.main(["simulate", str(bad), *SHORT, "--out", str(tmp_path / "o"), "--quiet"])
    assert code == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("jaxhoist: error:")
    assert "foundation.friction_coeficient" in err and "did you mean 'friction_coefficient'" in err
    assert "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_invalid_value_and_bad_override_exit_2(tmp_path, capsys, monkeypatch):
    _no_compile(monkeypatch)
    text = resources.files("jaxhoist._io.presets").joinpath("paper-4.2.toml").read_text()
    assert text.count("stiffness = 1.4e7") == 1  # c_l of paper §4.2, only in [rope]
    neg = tmp_path / "neg.toml"
    neg.write_text(text.replace("stiffness = 1.4e7", "stiffness = -1.4e7"))
    assert cli.main(["simulate", str(neg), "--quiet"]) == 2
    assert "rope.stiffness" in capsys.readouterr().err

    assert cli.main(["simulate", "paper-4.2", "--quiet", "--set", "rope.stifness=1e7"]) == 2
    assert "stifness" in capsys.readouterr().err
    assert cli.main(["simulate", "paper-4.2", "--quiet", "--set", "rope.stiffness=-5"]) == 2
    assert "rope.stiffness" in capsys.readouterr().err
    assert cli.main(["simulate", "paper-4.2", "--quiet", "--t1", "-1"]) == 2
    assert "t1" in capsys.readouterr().err
    assert cli.main(["simulate", "paper-4.2", "--quiet", "--rtol", "0"]) == 2
    assert "rtol" in capsys.readouterr().err


def test_unknown_preset_gives_a_hint(capsys, monkeypatch):
    _no_compile(monkeypatch)
    assert cli.main(["simulate", "paper-2.4", "--quiet"]) == 2  # a near miss of paper-2.3
    err = capsys.readouterr().err
    assert "paper-2.4" in err and "did you mean 'paper-2.3'" in err and "Traceback" not in err


def test_no_command_prints_help_and_version(capsys):
    assert cli.main([]) == 2
    assert "simulate" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        cli.main(["--version"])
    assert e.value.code == 0
    assert "jaxhoist" in capsys.readouterr().out


def test_extension_subcommands_plug_in(monkeypatch, capsys):
    calls = []

    def configure_parser(subparsers):
        p = subparsers.add_parser("scan", help="fake scan")
        p.add_argument("--n", type=int, default=3)
        p.set_defaults(func=lambda args: calls.append(args.n) or 0)

    fake = types.ModuleType("fake_scan_module")
    fake.configure_parser = configure_parser
    broken = types.ModuleType("fake_broken_module")  # exists, but has no configure_parser: skipped
    monkeypatch.setitem(sys.modules, "fake_scan_module", fake)
    monkeypatch.setitem(sys.modules, "fake_broken_module", broken)
    monkeypatch.setattr(
        cli,
        "EXTENSIONS",
        {
            "scan": "fake_scan_module",
            "other": "fake_broken_module",
            "missing": "jaxhoist._apps.no_such_module",
        },
    )
    assert cli.main(["scan", "--n", "7"]) == 0
    assert calls == [7]
    help_text = cli.build_parser().format_help()
    assert "scan" in help_text and "missing" not in help_text and "other" not in help_text


def test_readme_scenario_reference_lists_every_field():
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    section = readme.split("## Scenario files", 1)[1].split("\n## ", 1)[0]
    for table, fields in SCHEMA.items():
        tbl = table.split(":")[0]
        for field in fields:
            assert f"`{field}`" in section, f"README scenario reference lacks {tbl}.{field}"
    for cmd in (
        "python3.11 -m venv .venv && .venv/bin/pip install -e . && .venv/bin/jaxhoist simulate "
        "paper-4.2 --out out/paper-4.2",
        'python3.11 -m venv .venv && .venv/bin/pip install -e ".[test]" && .venv/bin/python -m pytest -q',
    ):
        assert cmd in readme


def test_numpy_only_reader(short_run):
    # the npz is readable with numpy alone, without jaxhoist
    _, out = short_run
    with np.load(out / "trajectory.npz") as f:
        assert "position" in f.files and f["position"].shape == (11, 3)


def test_every_help_shows_the_defaults():
    import argparse

    parser = cli.build_parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert {"simulate", "animate"} <= set(subs)
    for name, sub in subs.items():
        text = " ".join(sub.format_help().split())
        for action in sub._actions:
            d = action.default
            if not action.option_strings or d in (None, False, [], argparse.SUPPRESS):
                continue
            helptext = sub._get_formatter()._get_help_string(action)
            assert "default" in helptext, f"{name} {action.option_strings[0]}: {helptext!r}"
        assert text.count("default") >= 2
    sim = " ".join(subs["simulate"].format_help().split())
    assert "out/<preset name or scenario file name>" in sim
    assert "(default 501)" in sim and "atol + rtol |y|" in sim
    if "scan" in subs:
        scan = " ".join(subs["scan"].format_help().split())
        assert "out/scan-<preset name or scenario file name>" in scan
        assert "atol + rtol |y|" in scan and "(default: 201)" in scan


def test_library_hints_use_the_flag_names(monkeypatch, capsys):
    import inspect

    from jaxhoist._errors import ScenarioError
    from jaxhoist._io import scan_store

    src = inspect.getsource(scan_store)
    assert "use another out_dir, or resume=False to " in src and '"overwrite it"' in src  # the text reworded

    def configure_parser(subparsers):
        p = subparsers.add_parser("scan")

        def run(args):
            raise ScenarioError(
                "out/x holds chunks of a different scan (other scenario, values, times, "
                "observables or solver options): use another out_dir, or resume=False to "
                "overwrite it"
            )

        p.set_defaults(func=run)

    fake = types.ModuleType("fake_scan_module")
    fake.configure_parser = configure_parser
    monkeypatch.setitem(sys.modules, "fake_scan_module", fake)
    monkeypatch.setattr(cli, "EXTENSIONS", {"scan": "fake_scan_module"})
    assert cli.main(["scan"]) == 2
    err = capsys.readouterr().err
    assert "use another --out, or --no-resume" in err and "resume=False" not in err and "out_dir" not in err


def test_scan_progress_bar_shows_members_rate_eta_failures(monkeypatch):
    import io

    from jaxhoist._apps.scan import progress as scan_mod

    stream = io.StringIO()
    bar = cli.ScanProgressBar(stream=stream)
    kw = dict(n_chunks=4, total=64, compile_time=3.0, loaded=False)
    bar(scan_mod.Progress(chunk=0, done=16, elapsed=5.0, eta=None, rate=None, failed=0, **kw))
    bar(scan_mod.Progress(chunk=1, done=32, elapsed=6.0, eta=2.0, rate=16.0, failed=1, **kw))
    text = stream.getvalue().replace("\r", "\n")
    last = [ln for ln in text.splitlines() if ln.strip()][-1]
    assert "32/64 members" in last and "16 members/s" in last and "ETA 0:02" in last and "failed 1" in last
    assert " 50%" in last
    bar(scan_mod.Progress(chunk=3, done=64, elapsed=8.0, eta=0.0, rate=16.0, failed=1, **kw))
    assert bar.bar is None  # closed when every member is done

    # while a subcommand runs, the scan's default per-chunk line is this bar; afterwards it is restored
    saved = scan_mod.default_reporter()
    with cli.scan_bars():
        assert isinstance(scan_mod.default_reporter(), cli.ScanProgressBar)
    assert scan_mod.default_reporter() is saved


def test_printed_progress_lines_drive_the_bars():
    import io

    from tqdm import tqdm

    stream = io.StringIO()
    bar = tqdm(total=100.0, file=stream)
    sink = cli.LineSink(cli.percent_to_bar(bar))
    sink.write("0.00%\n12.")  # diffrax's TextProgressMeter lines, possibly split
    sink.write("50%\n")
    assert bar.n == 12.5
    sink.write("100.00%\n")
    assert bar.n == 100.0
    bar = tqdm(total=4.0, file=stream)
    sink = cli.LineSink(cli.phase_to_bar(bar))
    sink.write("  0.000000 -   0.300000 s  rest                     -> rest:slip [12 steps so far]\n")
    assert bar.n == pytest.approx(0.3)
