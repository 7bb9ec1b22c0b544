"""Inputs that several test modules share, scenarios and command lines (`import _inputs`)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import jaxhoist as jh

DATA = Path(__file__).parent / "data"
#: The box of docs/lift-planning.md's example as a scenario file: boom tip at x = 2 m, hoist speed 0.2 m/s,
#: t1 = 3 s. The command-line tests pass it with `--t1` and `--set` for their variants.
DRAG_BOX = DATA / "drag_box.toml"
#: A 1 m cube of 1000 kg lifted at 0.05 m/s by a vertical rope from the centre of its top face, the mass
#: centre at (0.45, 0.5, 0.5) m; t1 = 0.2 s.
SYMMETRIC_LIFT = DATA / "symmetric_lift.toml"


def drag_box(tip_x: float = 2.0, speed: float = 0.2, t1: float = 3.0) -> jh.Scenario:
    """The box of `DRAG_BOX` with the boom tip at x = `tip_x` [m], hoist speed `speed` [m/s] and end time
    `t1` [s]."""
    data = tomllib.loads(DRAG_BOX.read_text())
    data["t1"] = t1
    data["hoist"]["speed"] = speed
    data["boom"]["tip_position"][0] = tip_x
    return jh.scenario_from_dict(data, str(DRAG_BOX))


def write_knot_box(path: Path) -> Path:
    """`DRAG_BOX` as a scenario file at `path`, with the boom tip 0.6 m aside (x = 1.6 m), t1 = 2 s and a
    hoist speed profile (`law = "knots"`: 0, 0.25, 0.4 and 0.3 m/s at 0, 0.5, 1.5 and 3 s, at most 0.5 m/s)
    instead of the constant speed; returns `path`."""
    text = DRAG_BOX.read_text()
    for old, new in (
        ('name = "drag-box"', 'name = "knot-box"'),
        ("t1 = 3.0", "t1 = 2.0"),
        ('law = "constant-speed"\nspeed = 0.2\n', KNOT_HOIST),
        ("tip_position = [2.0, 1.0, 8.5]", "tip_position = [1.6, 1.0, 8.5]"),
    ):
        assert text.count(old) == 1, f"{DRAG_BOX} no longer holds {old!r} once"
        text = text.replace(old, new)
    path.write_text(text)
    return path


KNOT_HOIST = """law = "knots"
times = [0.0, 0.5, 1.5, 3.0]
speeds = [0.0, 0.25, 0.4, 0.3]
max_speed = 0.5
"""


def symmetric_lift(xi_c: float = 0.45) -> jh.Scenario:
    """The cube of `SYMMETRIC_LIFT` with its mass centre offset along ξ only, to (`xi_c`, 0.5, 0.5) m."""
    data = tomllib.loads(SYMMETRIC_LIFT.read_text())
    data["load"]["mass_centre"][0] = xi_c
    return jh.scenario_from_dict(data, str(SYMMETRIC_LIFT))


#: `jaxhoist bifurcation` on paper-4.2 over the friction coefficient in [0.2, 0.4], without options.
BIFURCATION_MU = (
    "bifurcation",
    "paper-4.2",
    "--param",
    "foundation.friction_coefficient",
    "--bracket",
    "0.2",
    "0.4",
)
