"""The 3-D animation of a saved lift (`jaxhoist._apps.plots.animation`, `jaxhoist animate`): the files are
valid images with the expected frame count, the drawn geometry is the saved geometry (corners, rope, boom tip,
box edges, force arrows scaled to the weight), the state text follows the contacts or the rigid model's phase
log, and bad input is refused with one line before anything is rendered."""

import jax

jax.config.update("jax_enable_x64", True)

import json  # noqa: E402
import shutil  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PIL import Image  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist import ScenarioError  # noqa: E402
from jaxhoist._apps.cli import app as cli  # noqa: E402
from jaxhoist._apps.plots import animation as an  # noqa: E402
from jaxhoist._io import results  # noqa: E402

try:  # share the compiled core with the physics tests (same saved-time count and solver options)
    from conftest import N_SAVE, SOLVE_OPTIONS
except ImportError:  # pragma: no cover - running this file alone without the shared conftest
    N_SAVE, SOLVE_OPTIONS = 201, jh.SolverOptions(rtol=1e-8, atol=1e-9)

T1 = 1.0  # [s]: corners D and H of paper-4.2 leave the ground within 0.3 s


@pytest.fixture(scope="module")
def result_dir(tmp_path_factory):
    """A saved paper-4.2 result over T1 (N_SAVE saved times), as `jaxhoist simulate` writes it."""
    scenario = jh.load_scenario("paper-4.2")
    traj = jh.simulate(scenario, jh.Times(ts=jnp.linspace(0.0, T1, N_SAVE)), options=SOLVE_OPTIONS)
    out = tmp_path_factory.mktemp("anim") / "paper-4.2"
    results.save_trajectory(out / "trajectory", traj, scenario, options={"model": "elastic"})
    return out


@pytest.fixture(scope="module")
def scene(result_dir):
    return an.load_scene(result_dir)


def _fresh_copy(src, dst):
    dst.mkdir(parents=True, exist_ok=True)
    for name in ("trajectory.npz", "trajectory.json"):
        shutil.copy(src / name, dst / name)
    return dst


def test_gif_and_keyframes_are_valid_images_with_the_expected_frames(result_dir, tmp_path):
    d = _fresh_copy(result_dir, tmp_path / "r")
    calls = []
    paths = an.animate(
        d, fps=4.0, duration=1.0, fmt="gif", n_keyframes=3, dpi=40, progress=lambda i, n: calls.append((i, n))
    )
    gif, png = d / "animation.gif", d / "keyframes.png"
    assert paths == [gif, png]
    with Image.open(gif) as im:
        assert im.format == "GIF" and im.n_frames == 4  # fps * duration frames
        assert im.info["duration"] == pytest.approx(250, abs=10)  # 1/fps [ms]
    assert calls == [(i, 4) for i in range(1, 5)]
    with Image.open(png) as im:
        assert im.format == "PNG"
        w, h = im.size
        assert w / h == pytest.approx(3 * 4.4 / 6.0, rel=0.01)  # a strip of three 4.4 x 6 inch frames
    assert not list(d.glob("*.partial*"))

    # --stride: every k-th saved time plus the last; --no-keyframes writes no PNG
    d2 = _fresh_copy(result_dir, tmp_path / "s")
    an.animate(d2, stride=100, fmt="gif", keyframes=False, dpi=40)
    with Image.open(d2 / "animation.gif") as im:
        assert im.n_frames == len(range(0, N_SAVE, 100))  # 0, 100, 200 (= the last)
    assert not (d2 / "keyframes.png").exists()


def test_drawn_geometry_is_the_saved_geometry(result_dir, scene):
    from jaxhoist._apps.plots.animation import new_figure

    arrays = results.load_trajectory(result_dir / "trajectory.npz")
    size = np.array([2.5, 6.0, 2.5])  # a, b, c of paper-4.2 [m]
    weight = 850.0 * 2.5 * 6.0 * 2.5 * 9.81  # m g [N]
    assert scene.weight == pytest.approx(weight, rel=1e-12)
    fig, (ax,) = new_figure(1)
    limits = scene.limits()
    for k in (0, N_SAVE // 4, N_SAVE - 1):
        art = an.draw_frame(ax, scene, k, limits)
        drawn = np.array([np.ravel(np.asarray(dot.get_data_3d())) for dot in art["corners"]])
        np.testing.assert_allclose(drawn, arrays["corners"][k], rtol=0, atol=1e-12)
        assert [t.get_text() for t in art["labels"]] == ["D", "E", "F", "H"]
        rope = np.asarray(art["rope"].get_data_3d()).T  # (B, A)
        np.testing.assert_allclose(rope[1], arrays["tip_position"][k], atol=1e-12)
        np.testing.assert_allclose(
            np.ravel(np.asarray(art["tip"].get_data_3d())), arrays["tip_position"][k], atol=1e-12
        )
        # B is the rope attachment, the top corner above D: D + c * (the body's ζ axis)
        np.testing.assert_allclose(rope[0], scene.top[k, 0], atol=1e-12)
        # the box is rigid: bottom edges a and b, vertical edges c
        c, top = scene.corners[k], scene.top[k]
        np.testing.assert_allclose(np.linalg.norm(c[1] - c[0]), size[0], rtol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(c[3] - c[0]), size[1], rtol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(top - c, axis=1), size[2], rtol=1e-9)
        # a force arrow exactly for the corners that touch; the clock shows the saved time
        n = arrays["normal_forces"][k]
        assert [art["arrows"][x] is not None for x in "DEFH"] == list(n > 0.0)
        assert f"t = {arrays['ts'][k]:7.3f} s" in art["clock"].get_text()
        # every drawn point lies inside the axis limits, which are equal in scale
        for p in (*drawn, *rope, *top):
            assert np.all(p >= limits[:, 0]) and np.all(p <= limits[:, 1])
    np.testing.assert_allclose(
        ax.get_box_aspect() / ax.get_box_aspect()[0], np.ptp(limits, axis=1) / np.ptp(limits[0]), rtol=1e-9
    )
    # at rest (t = 0, slack-free rope with S = 0) the ground carries the weight: the four arrows add up to
    # the length that stands for m g
    assert arrays["rope_tension"][0] == 0.0
    np.testing.assert_allclose(scene.arrows(0).sum(), scene.arrow_length, rtol=1e-6)
    # the rope of paper-4.2 pulls at the top corner above D: D leaves the ground first (open dot, no arrow)
    k_off = int(np.argmax(arrays["normal_forces"][:, 0] <= 0.0))
    assert k_off > 0 and scene.state[k_off].startswith("contact") and "D" not in scene.state[k_off]
    assert scene.state[0] == "contact D, E, F, H"


def test_keyframes_hold_start_end_and_first_detachment(scene):
    idx = an.keyframe_indices(scene, 5)
    first_off = min(t for t in results.corner_detach_times(scene.ts, scene.normal_forces) if t is not None)
    assert len(idx) == 5 and idx == sorted(set(idx))
    assert idx[0] == 0 and idx[-1] == N_SAVE - 1
    assert int(np.searchsorted(scene.ts, first_off)) in idx


def test_rigid_phase_log_names_the_state(result_dir, tmp_path):
    """A rigid-model result carries `phase_index` and the phase log; each frame names its phase."""
    arrays = results.load_trajectory(result_dir / "trajectory.npz")
    meta = results.load_metadata(result_dir / "trajectory.npz")
    n_t = arrays["ts"].size
    arrays["phase_index"] = (np.arange(n_t) >= n_t // 2).astype(np.int64)
    meta["phases"] = [
        {
            "t_start": 0.0,
            "t_end": 0.5,
            "contact": ["stick"] * 4,
            "rest": True,
            "end": "rest:slip",
            "rope": "elastic",
            "name": results.phase_name(["stick"] * 4, True),
        },
        {
            "t_start": 0.5,
            "t_end": 1.0,
            "contact": ["free", "slide", "stick", "free"],
            "rest": False,
            "end": "t1",
            "rope": "elastic",
            "name": results.phase_name(["free", "slide", "stick", "free"], False),
        },
    ]
    meta["solver"] = {"model": "rigid"}
    sc = an.scene_from_result(arrays, meta)
    assert sc.model == "rigid"
    assert sc.state[0] == "phase 1/2: rest" and sc.state[-1] == "phase 2/2: E slide, F stick"
    assert results.phase_name(["free"] * 4, False) == "flight"
    slack = results.phase_name(["slide"] * 4, False, "slack")
    assert slack == "D slide, E slide, F slide, H slide (rope slack)"


def test_bad_input_refused_before_rendering(result_dir, tmp_path, capsys):
    with pytest.raises(ScenarioError, match="no trajectory.npz"):
        an.animate(tmp_path)
    with pytest.raises(ScenarioError, match="--fps"):
        an.animate(result_dir, fps=0.0)
    with pytest.raises(ScenarioError, match="--stride"):
        an.animate(result_dir, stride=0)
    with pytest.raises(ScenarioError, match="--format"):
        an.animate(result_dir, fmt="avi")
    with pytest.raises(ScenarioError, match="--keyframes"):
        an.animate(result_dir, n_keyframes=0)
    meta = json.loads((result_dir / "trajectory.json").read_text())
    del meta["scenario"]
    with pytest.raises(ScenarioError, match="load.size"):
        an.scene_from_result(results.load_trajectory(result_dir / "trajectory.npz"), meta)
    assert not (result_dir / "animation.gif").exists()

    assert cli.main(["animate", str(tmp_path / "nothing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("jaxhoist: error:") and "trajectory.npz" in err[0]
    assert cli.main(["animate", str(result_dir), "--fps", "-1"]) == 2
    assert "--fps" in capsys.readouterr().err
    if not an.ffmpeg_available():
        assert cli.main(["animate", str(result_dir), "--format", "mp4"]) == 2
        assert "ffmpeg" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse: --duration and --stride exclude each other
        cli.main(["animate", str(result_dir), "--duration", "1", "--stride", "2"])
    assert not (result_dir / "animation.gif").exists()


def test_damaged_or_mismatched_result_files_are_refused(result_dir, tmp_path, capsys):
    """A result whose npz is truncated, or is another run's npz beside this sidecar (the sidecar's
    checksum differs), or whose sidecar is not JSON: one line naming the file, exit code 2, nothing drawn."""
    other = tmp_path / "other"
    results.save_arrays(other / "trajectory", {"ts": np.linspace(0.0, 2.0, 5)}, {"ts": "s"})
    cases = {
        "mismatched": lambda d: shutil.copy(other / "trajectory.npz", d / "trajectory.npz"),
        "truncated": lambda d: (d / "trajectory.npz").write_bytes((d / "trajectory.npz").read_bytes()[:500]),
        "sidecar": lambda d: (d / "trajectory.json").write_text("{"),
        "not an object": lambda d: (d / "trajectory.json").write_text("null"),
    }
    for name, damage in cases.items():
        d = _fresh_copy(result_dir, tmp_path / name)
        damage(d)
        with pytest.raises(results.ResultFileError, match="trajectory"):
            results.load_trajectory(d) if name in ("mismatched", "truncated") else results.load_metadata(d)
        assert cli.main(["animate", str(d)]) == 2, name
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("jaxhoist: error:") and str(d) in err[0], (name, err)
        assert not (d / "animation.gif").exists()
    # without a sidecar there is no checksum to compare: a truncated npz is still refused as damaged
    d = _fresh_copy(result_dir, tmp_path / "alone")
    (d / "trajectory.json").unlink()
    (d / "trajectory.npz").write_bytes((d / "trajectory.npz").read_bytes()[:500])
    with pytest.raises(results.ResultFileError, match="damaged"):
        results.load_trajectory(d)
    # the intact file reads back as written
    np.testing.assert_array_equal(results.load_trajectory(other)["ts"], np.linspace(0.0, 2.0, 5))


def test_cli_animate_writes_both_files(result_dir, tmp_path, capsys):
    d = _fresh_copy(result_dir, tmp_path / "c")
    assert cli.main(["animate", str(d), "--fps", "3", "--duration", "1", "--format", "gif", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "animation.gif" in out and "keyframes.png" in out
    with Image.open(d / "animation.gif") as im:
        assert im.n_frames == 3
    assert (d / "keyframes.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.skipif(not an.ffmpeg_available(), reason="ffmpeg not on PATH")
def test_mp4_with_ffmpeg(result_dir, tmp_path):  # pragma: no cover - needs ffmpeg
    d = _fresh_copy(result_dir, tmp_path / "m")
    paths = an.animate(d, fps=4.0, duration=1.0, keyframes=False, dpi=40)
    assert paths == [d / "animation.mp4"] and paths[0].stat().st_size > 1000
