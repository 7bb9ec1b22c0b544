"""`jaxhoist animate`: animations of a saved result folder."""

from __future__ import annotations

import argparse
from pathlib import Path

from .progress import tqdm_bar

# ---------------------------------------------------------------------------------------- animate


def animate_folder(result_dir, *, quiet: bool = False, **kw) -> list[Path]:
    from ..plots.animation import animate

    bars = []  # the bar opens with the first frame, after every check has passed

    def step(done, total):
        if not bars:
            bars.append(tqdm_bar(total, "animating", "frame", quiet=quiet))
        bars[0].update(done - bars[0].n)

    try:
        return animate(result_dir, progress=step, **kw)
    finally:
        for bar in bars:
            bar.close()


def run_animate(args: argparse.Namespace) -> int:
    """`jaxhoist animate RESULT_DIR`: the 3-D animation and the key-frame strip of a saved lift."""
    paths = animate_folder(
        args.result_dir,
        quiet=args.quiet,
        fps=args.fps,
        duration=args.duration,
        stride=args.stride,
        fmt=args.format,
        keyframes=not args.no_keyframes,
        n_keyframes=args.keyframes,
    )
    print("wrote         " + ", ".join(str(p) for p in paths), flush=True)
    return 0


def configure_animate(subparsers) -> None:
    p = subparsers.add_parser(
        "animate",
        help="draw a saved lift in 3-D: animation (MP4 or GIF) and a key-frame strip (PNG)",
        description="Read RESULT_DIR/trajectory.npz and trajectory.json (written by `jaxhoist simulate`, "
        "either model) and write RESULT_DIR/animation.mp4 (when ffmpeg is on PATH, else animation.gif) and "
        "RESULT_DIR/keyframes.png: the box with its corners D, E, F, H, the rope from B to the boom tip A, "
        "the ground, the corner forces N_i as arrows scaled to the weight, a clock and the contact state "
        "(or the rigid model's phase).",
    )
    p.add_argument("result_dir", metavar="RESULT_DIR", help="a folder written by `jaxhoist simulate --out`")
    p.add_argument("--fps", type=float, default=20.0, metavar="F", help="frames per second of the animation")
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="SECONDS",
        help="length of the animation [s], frames spread evenly over the saved times "
        "(default: min(t1, 10 s), i.e. real time up to 10 s)",
    )
    g.add_argument(
        "--stride", type=int, default=None, metavar="K", help="instead, one frame per K saved times"
    )
    p.add_argument(
        "--format",
        choices=("gif", "mp4"),
        default=None,
        help="file format (default: mp4 if ffmpeg is on PATH, else gif)",
    )
    p.add_argument("--keyframes", type=int, default=5, metavar="N", help="frames in keyframes.png")
    p.add_argument("--no-keyframes", action="store_true", help="do not write keyframes.png")
    p.add_argument("--quiet", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=run_animate)
