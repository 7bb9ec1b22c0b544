"""A 3-D animation of one lift, drawn from saved results (matplotlib only, Agg backend, no display).

    from jaxhoist.plots import animate
    paths = animate("out/paper-4.2")          # animation.gif (or .mp4 with ffmpeg) + keyframes.png

From the command line: `jaxhoist animate out/paper-4.2` or `jaxhoist simulate paper-4.2 --animate`.

Every frame shows the box with its bottom corners D, E, F, H labelled (a filled dot: the corner touches the
ground, N_i > 0), the rope from its attachment point B to the boom tip A, the ground plane Z = 0, the ground
forces N_i as vertical arrows from the corners whose length is N_i divided by the weight m g times a
reference length (the scale is written in the frame), a clock, the rope tension S, and the contact state:
which corners touch (elastic-foundation model) or the phase of the rigid model's phase log. Axis limits come
from the data (every frame the same, equal scale on X, Y, Z), so any scenario fits.

The geometry is rebuilt from the saved arrays: the bottom corners are the saved `corners`, the top corners
are corner + c R e_ζ and B = D + R ρ_B with R from the saved `quaternion` and the box height c and the rope
attachment ρ_B (from D, body axes) from the scenario leaves in `trajectory.json`.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..._errors import ScenarioError
from ..._io.results import corner_detach_times, liftoff_time
from .scene import ARROW_CAP as ARROW_CAP
from .scene import CORNER_COLOURS as CORNER_COLOURS
from .scene import CORNERS as CORNERS
from .scene import FACES
from .scene import Scene as Scene
from .scene import contact_state as contact_state
from .scene import load_scene as load_scene
from .scene import scene_from_result as scene_from_result

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FORMATS = ("gif", "mp4")


# ------------------------------------------------------------------------------------------ drawing


def _setup_axes(ax, limits: np.ndarray, elev: float, azim: float) -> None:
    from matplotlib.ticker import MaxNLocator

    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_zlim(*limits[2])
    ax.set_box_aspect(tuple(limits[:, 1] - limits[:, 0]))  # equal scale on X, Y, Z
    ax.view_init(elev=elev, azim=azim)
    for axis, name in ((ax.xaxis, "X"), (ax.yaxis, "Y"), (ax.zaxis, "Z")):
        axis.set_major_locator(MaxNLocator(4))
        axis.set_label_text(f"{name} [m]", fontsize=8)
        axis.labelpad = -2
    ax.tick_params(labelsize=7, pad=-1)


def frame_text(scene: Scene, k: int) -> str:
    """The text block of saved time `k`: clock, rope tension, contact state or phase, the N_i."""
    forces = " ".join(f"{n} {v / 1e3:5.1f}" for n, v in zip(CORNERS, scene.normal_forces[k], strict=True))
    return (
        f"t = {scene.ts[k]:7.3f} s   S = {scene.rope_tension[k] / 1e3:6.1f} kN\n{scene.state[k]}\n"
        f"N [kN]: {forces}"
    )


def draw_frame(
    ax,
    scene: Scene,
    k: int,
    limits: np.ndarray | None = None,
    *,
    elev: float = 20.0,
    azim: float = -35.0,
    info: bool = True,
) -> dict[str, Any]:
    """Draw saved time `k` of `scene` into the (cleared) 3-D axes `ax`.

    **Arguments**
    - `ax`: a matplotlib `Axes3D`; `scene`: the `Scene`; `k`: index of the saved time.
    - `limits`: axis limits (default `scene.limits()`); `elev`, `azim`: the view [deg].
    - `info`: write the clock, rope tension, contact state and N_i as the axes' title (`frame_text`).

    **Returns** the artists by name: "corners" (one `Line3D` dot per corner D, E, F, H), "labels", "box",
    "rope" (a `Line3D` from B to A), "tip", "arrows" (corner letter -> quiver, or None without contact),
    "ground", "clock" (the title `Text`, or None).
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    limits = scene.limits() if limits is None else limits
    ax.cla()
    _setup_axes(ax, limits, elev, azim)
    out: dict[str, Any] = {}
    (x0, x1), (y0, y1) = limits[0], limits[1]
    ground = Poly3DCollection(
        [[(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)]],
        facecolor="0.75",
        edgecolor="0.5",
        alpha=0.3,
    )
    out["ground"] = ax.add_collection3d(ground)
    c, top = scene.corners[k], scene.top[k]
    verts = np.concatenate([c, top])
    box = Poly3DCollection(
        [[tuple(verts[i]) for i in f] for f in FACES],
        facecolor="tan",
        edgecolor="0.2",
        linewidths=0.9,
        alpha=0.3,
    )
    out["box"] = ax.add_collection3d(box)
    centre = c.mean(axis=0)
    span = float(np.max(limits[:, 1] - limits[:, 0]))
    out["corners"], out["labels"], out["arrows"] = [], [], {}
    arrows = scene.arrows(k)
    for i, name in enumerate(CORNERS):
        touching = scene.normal_forces[k, i] > 0.0
        col = CORNER_COLOURS[i]
        # N_i pushes the corner up: an arrow from below the corner ending at it
        out["arrows"][name] = None
        if arrows[i] > 1e-3 * scene.arrow_length:
            out["arrows"][name] = ax.quiver(
                c[i, 0],
                c[i, 1],
                c[i, 2] - arrows[i],
                0.0,
                0.0,
                arrows[i],
                color=col,
                linewidth=2.5,
                arrow_length_ratio=min(0.4, 0.06 * span / arrows[i]),
            )
        (dot,) = ax.plot(
            [c[i, 0]],
            [c[i, 1]],
            [c[i, 2]],
            "o",
            ms=7,
            color=col,
            markerfacecolor=col if touching else "white",
            markeredgewidth=1.8,
        )
        out["corners"].append(dot)
        d = c[i, :2] - centre[:2]
        d = d / (np.linalg.norm(d) or 1.0) * 0.05 * span
        out["labels"].append(
            ax.text(
                c[i, 0] + d[0],
                c[i, 1] + d[1],
                c[i, 2] + 0.01 * span,
                name,
                color=col,
                fontsize=12,
                fontweight="bold",
                ha="center",
                va="bottom",
            )
        )
    b, a = scene.rope_point[k], scene.tip[k]
    (out["rope"],) = ax.plot([b[0], a[0]], [b[1], a[1]], [b[2], a[2]], color="k", lw=1.5)
    (out["tip"],) = ax.plot([a[0]], [a[1]], [a[2]], "v", ms=9, color="crimson")
    ax.text(a[0], a[1], a[2] + 0.03 * span, "A", fontsize=10, color="crimson", ha="center", va="bottom")
    ax.text(b[0], b[1], b[2] + 0.015 * span, "B", fontsize=10, ha="right", va="bottom")
    out["clock"] = None
    if info:
        out["clock"] = ax.set_title(frame_text(scene, k), loc="left", fontsize=8.5, family="monospace")
    return out


def new_figure(n_cols: int = 1, size: tuple[float, float] = (6.0, 7.0)) -> tuple[Figure, list]:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(size[0] * n_cols, size[1]), layout="constrained")
    axes = [fig.add_subplot(1, n_cols, i + 1, projection="3d") for i in range(n_cols)]
    return fig, axes


def _legend(scene: Scene) -> str:
    return (
        f"dot: corner D, E, F, H (filled: on the ground);  arrow: N_i, {scene.arrow_length:.3g} m = "
        f"weight m g = {scene.weight / 1e3:.4g} kN;  A: boom tip;  B-A: rope"
    )


def keyframe_indices(scene: Scene, n: int = 5) -> list[int]:
    """`n` saved-time indices for the key-frame strip: the start, the end, the first time a corner leaves the
    ground and lift-off (every N_i = 0), then equally spaced times to fill up; sorted."""
    n_t = scene.ts.size
    n = max(1, min(n, n_t))
    events = [0, n_t - 1]
    det = [t for t in corner_detach_times(scene.ts, scene.normal_forces) if t is not None]
    lift = liftoff_time(scene.ts, scene.normal_forces)
    for t in ([min(det)] if det else []) + ([lift] if lift is not None else []):
        events.append(int(np.searchsorted(scene.ts, t)))
    chosen = list(dict.fromkeys(events))[:n]
    for i in [int(round(x)) for x in np.linspace(0, n_t - 1, 2 * n + 1)]:
        if len(chosen) >= n:
            break
        # keep frames apart: skip a time right next to one already chosen
        if all(abs(i - j) > max(1, n_t // (4 * n)) for j in chosen):
            chosen.append(i)
    for i in range(n_t):  # a short result: fill with what is left
        if len(chosen) >= n:
            break
        if i not in chosen:
            chosen.append(i)
    return sorted(chosen)


def plot_keyframes(scene: Scene, n: int = 5, *, indices: Sequence[int] | None = None) -> Figure:
    """A strip of key frames side by side (see `keyframe_indices`), same view and limits in each.

    **Returns** the `Figure` (save with `jaxhoist._apps.plots.trajectory.save_figure`)."""
    idx = list(indices) if indices is not None else keyframe_indices(scene, n)
    fig, axes = new_figure(len(idx), size=(4.4, 6.0))
    limits = scene.limits()
    for ax, k in zip(axes, idx, strict=True):
        draw_frame(ax, scene, k, limits)
    fig.suptitle(f"{scene.name} ({scene.model} model), key frames\n{_legend(scene)}", fontsize=10)
    return fig


def frame_indices(
    n_t: int, t1: float, *, fps: float, duration: float | None = None, stride: int | None = None
) -> np.ndarray:
    """Indices of the saved times to show: every `stride`-th (and the last), or `fps * duration` equally
    spaced ones (at most all of them); default duration min(t1, 10 s).

    **Raises** `ScenarioError` for a non-positive `fps`, `duration` or `stride`, or both of the latter."""
    if not (np.isfinite(fps) and fps > 0):
        raise ScenarioError(f"--fps must be > 0 frames per second, got {fps}")
    if duration is not None and stride is not None:
        raise ScenarioError("give --duration or --stride, not both")
    if stride is not None:
        if stride < 1:
            raise ScenarioError(f"--stride must be >= 1 saved times per frame, got {stride}")
        idx = np.arange(0, n_t, stride)
        return idx if idx[-1] == n_t - 1 else np.append(idx, n_t - 1)
    if duration is None:
        duration = min(float(t1), 10.0) if t1 > 0 else 1.0
    if not (np.isfinite(duration) and duration > 0):
        raise ScenarioError(f"--duration must be > 0 s, got {duration}")
    n = int(min(n_t, max(2, round(fps * duration))))
    return np.unique(np.linspace(0, n_t - 1, n).round().astype(int))


def ffmpeg_available() -> bool:
    """True if an `ffmpeg` executable is on PATH (for MP4)."""
    return shutil.which("ffmpeg") is not None


def save_animation(
    scene: Scene,
    path: str | Path,
    indices: Sequence[int] | np.ndarray,
    *,
    fps: float = 20.0,
    fmt: str | None = None,
    dpi: int = 90,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Render the frames `indices` of `scene` and write them as an animated GIF (Pillow) or MP4 (ffmpeg).

    **Arguments**
    - `path`: output file; its suffix is replaced by the format's.
    - `indices`: saved-time indices, one per frame (`frame_indices`).
    - `fps`: frames per second of the file [1/s].
    - `fmt`: "gif" or "mp4" (default: mp4 if ffmpeg is on PATH, else gif).
    - `dpi`: resolution [dots per inch] of the 6 x 6 inch frames.
    - `progress`: called as `progress(frames_done, frames_total)` after each frame.

    **Returns** the path written.

    **Raises** `ScenarioError` for an unknown format or mp4 without ffmpeg.
    """
    from matplotlib.animation import FFMpegWriter, PillowWriter
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fmt = fmt or ("mp4" if ffmpeg_available() else "gif")
    if fmt not in FORMATS:
        raise ScenarioError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt == "mp4" and not ffmpeg_available():
        raise ScenarioError("--format mp4 needs ffmpeg on PATH; install it or use --format gif")
    path = Path(path).with_suffix("." + fmt)
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = (
        PillowWriter(fps=fps)  # pyright: ignore[reportArgumentType]  # matplotlib's stubs say int; a float fps works
        if fmt == "gif"
        else FFMpegWriter(
            fps=fps,  # pyright: ignore[reportArgumentType]  # as above
            codec="libx264",
            extra_args=["-pix_fmt", "yuv420p"],
        )
    )
    fig, (ax,) = new_figure(1)
    FigureCanvasAgg(fig)
    limits = scene.limits()
    fig.suptitle(f"{scene.name} ({scene.model} model)", fontsize=11)
    fig.text(
        0.5, 0.005, _legend(scene).replace(";  ", "\n", 1), fontsize=7, ha="center", va="bottom", color="0.3"
    )
    tmp = path.with_name(path.stem + ".partial" + path.suffix)
    with writer.saving(fig, str(tmp), dpi):
        for j, k in enumerate(indices):
            draw_frame(ax, scene, int(k), limits)
            writer.grab_frame()
            if progress is not None:
                progress(j + 1, len(indices))
    tmp.replace(path)
    return path


def animate(
    result_dir: str | Path,
    *,
    fps: float = 20.0,
    duration: float | None = None,
    stride: int | None = None,
    fmt: str | None = None,
    keyframes: bool = True,
    n_keyframes: int = 5,
    dpi: int = 90,
    progress: Callable[[int, int], None] | None = None,
) -> list[Path]:
    """Write `RESULT_DIR/animation.gif` (or `.mp4`) and `RESULT_DIR/keyframes.png` from the saved
    `trajectory.npz` + `trajectory.json` of `jaxhoist simulate` (either model, any scenario).

    **Arguments**
    - `result_dir`: the folder holding `trajectory.npz` and `trajectory.json`, or the path of a
      `.npz` result file (its `.json` beside it); the files are written into its folder.
    - `fps`: frames per second [1/s]; `duration`: length of the animation [s] (default min(t1, 10 s));
      `stride`: instead, show every `stride`-th saved time.
    - `fmt`: "gif" or "mp4" (default mp4 when ffmpeg is on PATH, else gif).
    - `keyframes`: also write the key-frame strip `keyframes.png` of `n_keyframes` frames.
    - `dpi`: resolution of the animation's frames; `progress`: `progress(done, total)` after each frame.

    **Returns** the paths written (animation first).

    **Raises** `ScenarioError` for a folder without a result and for bad options, before rendering.
    """
    scene = load_scene(result_dir)
    idx = frame_indices(scene.ts.size, float(scene.ts[-1]), fps=fps, duration=duration, stride=stride)
    if fmt is not None and fmt not in FORMATS:
        raise ScenarioError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt == "mp4" and not ffmpeg_available():
        raise ScenarioError("--format mp4 needs ffmpeg on PATH; install it or use --format gif")
    if keyframes and n_keyframes < 1:
        raise ScenarioError(
            f"n_keyframes (--keyframes) must be >= 1, got {n_keyframes}; to write no key-frame strip, pass "
            f"keyframes=False (--no-keyframes)"
        )
    out = Path(result_dir)
    out = out if out.is_dir() else out.parent  # a result file: its folder
    paths = []
    if keyframes:
        from .trajectory import save_figure

        paths.append(save_figure(plot_keyframes(scene, n_keyframes), out / "keyframes.png", dpi=100))
    anim = save_animation(scene, out / "animation", idx, fps=fps, fmt=fmt, dpi=dpi, progress=progress)
    paths.insert(0, anim)
    return paths
