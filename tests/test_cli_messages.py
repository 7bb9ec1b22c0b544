"""The command line runs, and runs again: one rule for output folders (a `.jaxhoist` marker names the
command that wrote a folder; a re-run of that command replaces its results, a folder with other files is
refused unless --overwrite), default folders from the scenario FILE's name, result paths with dots and
folders, `animate` on a file; one-line messages naming the expected form (ranges, vectors, corners, the
closest observable); summaries that say what happened (transient detachments of the rigid model, no ETA
while compiling, located values to the digits their bracket supports, why a scan plot is skipped)."""

import jax

jax.config.update("jax_enable_x64", True)

import inspect  # noqa: E402
import io  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from importlib import resources  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from _inputs import BIFURCATION_MU  # noqa: E402

from jaxhoist._apps import cli  # noqa: E402
from jaxhoist._apps.cli import bifurcation as bifurcation_cli  # noqa: E402
from jaxhoist._apps.cli import identify as identify_cli  # noqa: E402
from jaxhoist._apps.cli import scan as scan_cli  # noqa: E402
from jaxhoist._apps.cli import simulate as simulate_cli  # noqa: E402
from jaxhoist._apps.cli.common import (  # noqa: E402
    MARKER,
    claim_out_dir,
    default_out,
    marker_command,
    prepare_out_dir,
)
from jaxhoist._errors import ScenarioError  # noqa: E402
from jaxhoist._io import results  # noqa: E402

SHORT = ["--t1", "0.5", "--n-save", "11"]  # the short solve of tests/test_cli.py (compiled once per process)


def _boom(*a, **k):
    raise AssertionError("the computation ran despite the refusal")


def _error(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err and lines, err
    assert lines[-1].startswith("jaxhoist: error:"), err
    return lines[-1]


_ROOT = str(Path(__file__).resolve().parents[1])

# `entry_point` with `main` replaced by one that writes to stdout without a newline and returns 3, and an exit
# handler that writes to stderr: the exit must run the handler, flush the stdout left in its buffer and
# keep main's code
_ENTRY_POINT_SCRIPT = """
import atexit, sys
from jaxhoist._apps.cli import app
atexit.register(lambda: sys.stderr.write("handler ran"))
app.main = lambda: (sys.stdout.write("buffered, no newline"), 3)[1]
app.entry_point()
"""


def _python(args: list[str]) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # stdout block-buffered
    env.update(PYTHONPATH=_ROOT, JAX_PLATFORMS="cpu")
    return subprocess.run(
        [sys.executable, *args], env=env, capture_output=True, text=True, timeout=300, cwd=_ROOT
    )


def test_the_command_s_exit_runs_the_handlers_flushes_and_keeps_main_s_code():
    """`entry_point` (the `jaxhoist` command, `python -m jaxhoist`) ends with `os._exit`: before it, the exit
    handlers run and the standard streams are flushed, and the exit code is `main()`'s."""
    proc = _python(["-c", _ENTRY_POINT_SCRIPT])
    assert proc.returncode == 3, proc.stderr[-3000:]
    assert proc.stdout == "buffered, no newline"
    assert proc.stderr.endswith("handler ran"), proc.stderr[-3000:]


def test_the_command_exits_with_main_s_code_and_its_message(tmp_path):
    """`python -m jaxhoist` exits 2 on invalid input, with main's one-line message on stderr and nothing
    written (no compiling: a fresh process, no cache)."""
    out = tmp_path / "out"
    proc = _python(
        ["-m", "jaxhoist", "simulate", "paper-4.2", "--no-cache", "--out", str(out)]
        + ["--set", "foundation.friction_coefficient=-0.1"]
    )
    assert proc.returncode == 2, proc.stderr[-3000:]
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert "Traceback" not in proc.stderr and lines[-1].startswith("jaxhoist: error:"), proc.stderr[-3000:]
    assert "friction_coefficient" in lines[-1] and "compiling" not in proc.stderr
    assert not out.exists()


# ------------------------------------------------------------------------------------- output folders


def test_out_folder_rule(tmp_path):
    out = tmp_path / "o"
    assert prepare_out_dir(out, "simulate") == out  # not there yet
    out.mkdir()
    assert prepare_out_dir(out, "simulate") == out  # empty
    (out / "notes.txt").write_text("mine")
    with pytest.raises(ScenarioError, match=r"--out .*did not write.*notes\.txt.*--overwrite"):
        prepare_out_dir(out, "simulate")
    assert prepare_out_dir(out, "simulate", overwrite=True) == out
    # marked by the same command: reused; by another command: refused, naming it
    for name in ("trajectory.npz", "overview.png", "scan_x.png"):
        (out / name).write_text("old")
    claim_out_dir(out, "simulate", ["trajectory.npz", "*.png"])
    assert marker_command(out) == "simulate" and (out / MARKER).is_file()
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "notes.txt"]  # only the listed files went
    assert prepare_out_dir(out, "simulate") == out
    with pytest.raises(ScenarioError, match=r"results of `jaxhoist simulate`.*--overwrite"):
        prepare_out_dir(out, "scan")
    assert prepare_out_dir(out, "scan", overwrite=True) == out
    with pytest.raises(ScenarioError, match="is a file"):
        prepare_out_dir(out / "notes.txt", "simulate")


def test_a_scan_folder_written_from_python_is_the_scan_command_s(tmp_path):
    """`jaxhoist.scan(..., out_dir=)` marks its folder as `jaxhoist scan` does, so the command line can
    resume or recompute there (docs/bifurcation.md runs both into out/mu)."""
    from jaxhoist._io.scan_store import ScanStore

    store = ScanStore(tmp_path / "mu", "fingerprint")
    store.open(
        np.arange(4), 2, {"n_members": 4, "params": ["p"], "mode": "sweep", "t1": 1.0, "lanes": 2}, True
    )
    assert marker_command(tmp_path / "mu") == "scan"
    assert prepare_out_dir(tmp_path / "mu", "scan") == tmp_path / "mu"


def test_default_out_comes_from_the_file_name():
    assert default_out("paper-4.2") == default_out("paper-4.2", "") and str(default_out("paper-4.2")) == (
        os.path.join("out", "paper-4.2")
    )
    assert default_out("lifts/my-lift.toml") == default_out("my-lift.toml")
    assert str(default_out("lifts/my-lift.toml")) == os.path.join("out", "my-lift")
    assert str(default_out("my-lift.toml", "scan-")) == os.path.join("out", "scan-my-lift")


def test_result_paths_with_dots_and_folders(tmp_path):
    npz, js = results.save_arrays(tmp_path / "paper-4.2", {"a": [1.0, 2.0]}, {"a": "m"})
    assert npz.name == "paper-4.2.npz" and js.name == "paper-4.2.json"  # ".2" is no suffix
    np.testing.assert_array_equal(results.load_arrays(tmp_path / "paper-4.2")["a"], [1.0, 2.0])
    run = tmp_path / "run-4.2"
    results.save_arrays(run / "trajectory", {"b": [3.0]}, {"b": "s"})
    np.testing.assert_array_equal(results.load_trajectory(run)["b"], [3.0])  # a result folder
    assert results.load_metadata(run)["arrays"]["b"]["unit"] == "s"


def test_simulate_runs_twice_and_refuses_foreign_folders(tmp_path, capsys, monkeypatch):
    """End to end: the same command twice into one folder (the worked example of docs/cli.md, short),
    a copied preset's default folder named after the file, `animate` on the trajectory file, and the
    refusals (before any solve) of a folder holding the user's files or another command's results."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out" / "mu-0.3"
    argv = ["simulate", "paper-4.2", "--set", "foundation.friction_coefficient=0.3", *SHORT, "--quiet"]
    assert cli.main([*argv, "--out", str(out), "--no-plots"]) == 0
    (out / "notes.txt").write_text("mine")
    assert cli.main([*argv, "--out", str(out)]) == 0  # again, now with plots: replaced, not refused
    assert marker_command(out) == "simulate" and (out / "notes.txt").read_text() == "mine"
    assert list(out.glob("*.png"))
    assert cli.main([*argv, "--out", str(out), "--no-plots"]) == 0  # the third run leaves no stale PNGs
    assert not list(out.glob("*.png"))
    assert results.load_trajectory(out)["ts"].shape == (11,)
    capsys.readouterr()

    # animate on the file works as on its folder
    assert (
        cli.main(["animate", str(out / "trajectory.npz"), "--quiet", "--format", "gif", "--stride", "5"]) == 0
    )
    assert (out / "animation.gif").is_file() and (out / "keyframes.png").is_file()
    capsys.readouterr()

    # a copy of a preset keeps name = "paper-4.2"; its default folder is the file's name
    (tmp_path / "my-lift.toml").write_text(
        resources.files("jaxhoist._io.presets").joinpath("paper-4.2.toml").read_text()
    )
    assert cli.main(["simulate", "my-lift.toml", *SHORT, "--quiet", "--no-plots"]) == 0
    assert (tmp_path / "out" / "my-lift" / "trajectory.npz").is_file()
    assert not (tmp_path / "out" / "paper-4.2").exists()
    capsys.readouterr()

    # refusals, exit 2 before anything is computed
    monkeypatch.setattr(simulate_cli, "_compiled_solve", _boom)
    monkeypatch.setattr(scan_cli, "scan", _boom)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    assert cli.main([*argv, "--out", str(mine)]) == 2
    assert "notes.txt" in _error(capsys) and (mine / "notes.txt").read_text() == "mine"
    scan = ["scan", "paper-4.2", "--param", "foundation.friction_coefficient", "--values", "0.2:0.3:2"]
    assert cli.main([*scan, "--t1", "0.5", "--out", str(out)]) == 2
    assert "`jaxhoist simulate`" in _error(capsys)


def test_identify_and_bifurcation_keep_the_rule(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(identify_cli, "identify", _boom)
    for name in ("locate_bifurcation", "scan", "trace_boundary"):
        monkeypatch.setattr(bifurcation_cli, name, _boom)
    csv = tmp_path / "lift.csv"
    csv.write_text("t [s],position_x [m]\n0.1,1.0\n0.2,1.0\n0.3,1.0\n")
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "estimates.json").write_text("{}")  # not written by jaxhoist: no marker
    assert cli.main(["identify", "paper-4.2", str(csv), "--fit", "mu", "--quiet", "--out", str(mine)]) == 2
    assert "--overwrite" in _error(capsys) and (mine / "estimates.json").read_text() == "{}"
    claim_out_dir(mine, "simulate")
    assert cli.main([*BIFURCATION_MU, "--quiet", "--out", str(mine)]) == 2
    assert "`jaxhoist simulate`" in _error(capsys)


def test_a_refused_scan_leaves_the_earlier_scan_in_its_folder(tmp_path, capsys, monkeypatch):
    """A scan refused by any check (an option, a member's values, a repeated --param) exits 2 before the
    folder is claimed: the results of the scan that wrote the folder before stay there."""
    monkeypatch.setattr(scan_cli, "scan", _boom)
    folder = tmp_path / "S"
    earlier = ["scan.npz", "scan.json", "scan.nc", "scan_final_psi.png", "chunk_00000.npz", "manifest.json"]
    claim_out_dir(folder, "scan")
    for name in earlier:
        (folder / name).write_text("earlier")
    base = ["scan", "paper-4.2", "--param", "foundation.friction_coefficient", "--values", "0.2,0.3",
            "--out", str(folder), "--quiet"]  # fmt: skip
    refusals = {
        "--lanes": [*base, "--lanes", "0"],
        "--chunk-size": [*base, "--chunk-size", "-4"],
        "AccuracyCheck.members": [*base, "--accuracy-members", "0"],
        "--n-save": [*base, "--n-save", "1"],
        "given more than once": [*base, "--param", "foundation.friction_coefficient", "--values", "0.5"],
        "every member of the scan is invalid": [*base[:3], "load.mass", "--values=-1,-2", *base[6:]],
    }
    for words, argv in refusals.items():
        assert cli.main(argv) == 2, words
        assert words in _error(capsys)
        assert sorted(p.name for p in folder.iterdir()) == sorted([*earlier, MARKER]), words
        assert all((folder / name).read_text() == "earlier" for name in earlier), words


def test_a_warning_is_one_line_naming_no_source(tmp_path, capsys, monkeypatch):
    """A warning while a command runs (a damaged chunk recomputed, a stored program compiled again) prints as
    `jaxhoist: warning: <message>`, without Python's source file, line and code line; Python's own display is
    back afterwards."""
    import warnings

    def warns_then_stops(*a, **k):
        warnings.warn("jaxhoist: out/chunk_00000.npz: damaged; recomputed", UserWarning, stacklevel=2)
        raise ScenarioError("stopped here")

    monkeypatch.setattr(scan_cli, "scan", warns_then_stops)
    shown = warnings.showwarning
    argv = ["scan", "paper-4.2", "--param", "foundation.friction_coefficient", "--values", "0.2,0.3",
            "--out", str(tmp_path / "S"), "--quiet"]  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert cli.main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "jaxhoist: warning: out/chunk_00000.npz: damaged; recomputed",
        "jaxhoist: error: stopped here",
    ]
    assert warnings.showwarning is shown


def test_identify_says_the_fit_starts_only_once_its_input_is_checked(tmp_path, capsys, monkeypatch):
    """`jaxhoist identify` with a misspelled --fit name, --starts 0 or a misspelled --noise signal prints the
    one error line only, not first its "fitting ..." line; valid input prints that line, then fits."""
    monkeypatch.setattr(identify_cli, "identify", _boom)
    csv = tmp_path / "lift.csv"
    csv.write_text("t [s],position_x [m]\n0.1,1.0\n0.2,1.0\n0.3,1.0\n")
    base = ["identify", "paper-4.2", str(csv), "--out", str(tmp_path / "fit")]
    for extra, words in (
        (["--fit", "muu"], "did you mean 'mu'"),
        (["--fit", "mu", "--starts", "0"], "n_starts"),
        (["--fit", "mu", "--noise", "positon_x=0.01"], "positon_x"),
    ):
        assert cli.main([*base, *extra]) == 2, extra
        err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
        assert len(err) == 1 and words in err[0], err
    with pytest.raises(AssertionError, match="the computation ran"):
        cli.main([*base, "--fit", "mu"])
    assert capsys.readouterr().err.startswith("fitting mu of paper-4.2")


def test_a_value_list_may_start_with_a_negative_number():
    """`--values -0.2:0.4:4` (and `--along-values`) reach the command as written, not as an unknown option."""
    from jaxhoist._apps.cli.app import _join_negative_specs, build_parser

    argv = ["scan", "paper-4.2", "--param", "boom.tip_position[0]", "--values", "-0.2:0.4:4", "--t1", "-1"]
    joined = _join_negative_specs(argv)
    assert joined[4] == "--values=-0.2:0.4:4" and joined[5:] == ["--t1", "-1"]
    assert build_parser().parse_args(joined).values == ["-0.2:0.4:4"]
    assert _join_negative_specs(["bifurcation", "--along-values", "-1,0,1"])[1] == "--along-values=-1,0,1"


def test_set_load_density_gives_the_mass_of_the_box_as_a_file_does(paper42):
    """`--set load.density` makes m = ρabc of the size after any `--set load.size`, as a scenario file's
    `density` does; `load.size` alone keeps the mass (a leaf replaced); mass and density together are
    refused; `load.inertia` sets an inertia where the preset has none, checked as a file's."""
    from jaxhoist._io.scenario import apply_overrides, load_scenario

    m0 = float(paper42.load.mass)  # 850 kg/m^3 x 2.5 m x 6 m x 2.5 m
    sc, _ = apply_overrides(paper42, ["load.density=900"])
    assert float(sc.load.mass) == pytest.approx(m0 * 900 / 850, rel=1e-15)
    sc, overrides = apply_overrides(paper42, ["load.size=5,12,5", "load.density=850"])
    assert float(sc.load.mass) == pytest.approx(850 * 5 * 12 * 5, rel=1e-15)
    assert overrides == {"load.size": [5.0, 12.0, 5.0], "load.density": 850.0}
    assert float(apply_overrides(paper42, ["load.size=5,12,5"])[0].load.mass) == m0
    # an inertia where the preset has none (the uniform box's is computed) is set as a file's would be
    assert paper42.load.inertia is None
    j = [[2e5, 0.0, 0.0], [0.0, 2e5, 0.0], [0.0, 0.0, 3e5]]
    sc, _ = apply_overrides(paper42, [f"load.inertia={j}"])
    np.testing.assert_array_equal(np.asarray(sc.load.inertia_tensor()), j)
    assert float(sc.load.mass) == m0 and sc.load.mass_centre is not None
    np.testing.assert_array_equal(np.asarray(sc.load.mass_centre), np.asarray(paper42.load.mass_centre))
    with pytest.raises(ScenarioError, match="symmetric"):
        apply_overrides(paper42, ["load.inertia=[[2e5, 1, 0], [0, 2e5, 0], [0, 0, 3e5]]"])
    for items, words in (
        (["load.density=850", "load.mass=3"], "not both"),
        (["load.density=1,2"], "one number"),
        (["load.density=-1"], "load.density"),
        (["load.density=1.2e5"], "outside its plausible range"),  # as in a file (0.1 to 1e5 kg/m^3)
    ):
        with pytest.raises(ScenarioError, match=words):
            apply_overrides(paper42, items)
    opted_in = load_scenario("paper-4.2", allow_implausible=True)
    assert float(apply_overrides(opted_in, ["load.density=1.2e5"])[0].load.mass) == pytest.approx(
        1.2e5 * 37.5
    )


# ------------------------------------------------------------------------------------------- messages


@pytest.mark.parametrize(
    "argv,words",
    [
        (["scan", "paper-4.2", "--param", "foundation.friction_coefficient", "--values", "0.2-0.4"],
         ["start:stop:num", "'0.2-0.4'"]),
        (["simulate", "paper-4.2", "--set", "load.mass_centre=1;2.5;1"], ["x,y,z", "load.mass_centre"]),
        ([*BIFURCATION_MU, "--observable", "contact_margin[G]"], ["D, E, F, H", "--observable"]),
        ([*BIFURCATION_MU, "--observable", "final_pos"], ["did you mean 'final_position'"]),
        (["scan", "paper-4.2", "--param", "foundation.friction_coefficient", "--values", "0.2:0.3:2",
          "--observable", "final_pos"], ["did you mean 'final_position'"]),
    ],
)  # fmt: skip
def test_messages_name_the_expected_form(argv, words, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(simulate_cli, "_compiled_solve", _boom)
    monkeypatch.setattr(scan_cli, "scan", _boom)
    for name in ("locate_bifurcation", "scan", "trace_boundary"):
        monkeypatch.setattr(bifurcation_cli, name, _boom)
    monkeypatch.chdir(tmp_path)
    assert cli.main([*argv, "--quiet"]) == 2
    assert not (tmp_path / "out").exists()  # refused before any folder was made
    line = _error(capsys)
    assert all(w in line for w in words), line
    assert "locate_bifurcation" not in line  # the CLI's words, not a Python function's


def test_vector_override_as_x_y_z():
    from jaxhoist._io.scenario import apply_overrides, load_scenario

    sc, overrides = apply_overrides(load_scenario("paper-4.2"), ["load.mass_centre=1,2.5,1"])
    np.testing.assert_array_equal(np.asarray(sc.load.mass_centre), [1.0, 2.5, 1.0])
    assert overrides == {"load.mass_centre": [1.0, 2.5, 1.0]}


def test_closest_observable_by_meaning_then_spelling():
    from jaxhoist._numerics.observables import BUILTIN, closest_name

    assert closest_name("final_pos", BUILTIN) == "final_position"  # difflib alone says final_psi
    assert closest_name("tilt", BUILTIN) == "max_tilt"
    assert closest_name("liftof_time", BUILTIN) == "liftoff_time"  # spelling, when no name contains it
    assert closest_name("zzz", BUILTIN) is None


# ------------------------------------------------------------------------------------------ summaries


def test_rigid_summary_names_a_start_transient_and_reports_the_sustained_detachment():
    from jaxhoist._errors import SolveStatus

    ts = np.linspace(0.0, 1.0, 11)
    normal = np.full((11, 4), 9e4)
    normal[0, [0, 1, 3]] = 0.0  # only F touches in the first 0.2 ms (the rope's start jerk)
    normal[7:, 0] = 0.0  # D leaves the ground for good at 0.65 s
    free, stick = "free", "stick"
    phases = [
        {"t_start": 0.0, "t_end": 2e-4, "contact": [free, free, "slide", free]},
        {"t_start": 2e-4, "t_end": 0.65, "contact": [stick] * 4},
        {"t_start": 0.65, "t_end": 1.0, "contact": [free, stick, stick, stick]},
    ]
    before = simulate_cli.event_lines(SolveStatus.OK, ts, normal)  # without the phase log: as sampled
    assert "D: 0 s, E: 0 s, F: -, H: 0 s" in before[1]
    lines = simulate_cli.event_lines(SolveStatus.OK, ts, normal, phases)
    assert "D: 0.7 s, E: -, F: -, H: -" in lines[1], lines
    assert lines[2].startswith("transient") and "D, E, H" in lines[2] and "0.2 ms" in lines[2], lines
    # a detachment longer than the save interval is no transient
    assert simulate_cli.transient_detachments(phases, np.linspace(0.0, 1.0, 100_001)) == []


def test_progress_bars_show_no_eta_while_compiling(monkeypatch):
    from tqdm import tqdm

    from jaxhoist._apps.cli import progress as progress_bars

    clock = iter([100.0, 101.0, 102.0])  # the first phase line comes after 100 s of compile
    monkeypatch.setattr(progress_bars.time, "perf_counter", lambda: next(clock))
    stream = io.StringIO()
    bar = tqdm(total=10.0, file=stream, bar_format="{n:.3f} [{elapsed}{postfix}]")
    on_line = progress_bars.phase_to_bar(bar)
    on_line("  0.000000 -   0.000200 s  F slide -> tangential:F [12 steps so far]")
    assert "ETA" not in str(bar) and "F slide" in str(bar)
    on_line("  0.000200 -   1.000000 s  rest -> rest:slip [40 steps so far]")
    assert "ETA 0:09" in str(bar), str(bar)  # 1 s of t per second of wall time since the first line
    # the bars of `simulate` carry no tqdm {remaining} (elapsed over the whole time, compile included)
    assert "{remaining}" not in inspect.getsource(simulate_cli)


def test_located_value_printed_to_the_digits_its_bracket_supports():
    from jaxhoist._apps.bifurcation.result import Bifurcation, fmt_located

    assert fmt_located(0.27952341234, 4.5e-7) == "0.2795234"
    assert fmt_located(0.27952322, 4.5e-7, -1) == "0.2795232"
    assert fmt_located(0.27952367, 4.5e-7, +1) == "0.2795237"
    assert fmt_located(14028942.3, 250.0) == "14028900"
    b = Bifurcation(
        param="foundation.friction_coefficient",
        unit="-",
        observable="contact_margin[E]",
        value=0.279523412345,
        bracket=(0.279523189, 0.279523636),
        width=4.47e-7,
        level=0.0,
        y_lo=1e-3,
        y_hi=-1e-3,
        tol=1e-6,
        n_solves=6,
        n_derivative_solves=3,
        n_uniform=200_001,
        history=[],
        converged=True,
        method="newton",
    )
    text = b.summary()
    assert "* = 0.2795234 (bracket [0.2795231, 0.2795237]" in text, text
    assert "0.279523412" not in text


def test_scan_says_why_a_plot_is_skipped():
    from jaxhoist._apps.plots import scan as scan_plots
    from jaxhoist._apps.scan.result import ScanResult

    mu = np.linspace(0.2, 0.4, 3)
    res = ScanResult(
        params=["foundation.friction_coefficient"],
        mode="sweep",
        coords={"foundation.friction_coefficient": mu},
        shape=(3,),
        data={"liftoff_time": np.full(3, np.inf), "final_x": mu},
        components={},
        status=np.zeros(3, dtype=np.int32),
        reasons={},
        num_accepted_steps=np.full(3, 100),
        num_rejected_steps=np.zeros(3, dtype=int),
        ts=None,
        histories={},
        units={"liftoff_time": "s", "final_x": "m"},
        descriptions={},
        attrs={"t1": 5.0},
    )
    skips = scan_plots.plot_skips(res)
    assert list(skips) == ["liftoff_time"] and "t1 = 5 s" in skips["liftoff_time"]
