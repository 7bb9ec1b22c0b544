"""Plots and animations of results (public; matplotlib only, no pyplot state).

    import jaxhoist as jh
    from jaxhoist import plots

    tr = jh.simulate(jh.load_scenario("paper-4.2"), 10.0)
    plots.save_figure(plots.plot_motion(tr), "motion.png")

Every trajectory plot takes a `jaxhoist.Trajectory` (either model) or the dict read back by
`jaxhoist.load_trajectory`, and returns a `matplotlib.figure.Figure` with units on its axes. The scan plots
take a `jaxhoist.ScanResult`; `plot_locator` a `jaxhoist.Bifurcation`, `plot_boundary` what `trace_boundary`
returns.
`animate` draws a folder written by `jaxhoist simulate --out DIR` (as `jaxhoist animate DIR` does).
"""

from ._apps.plots import animate as animate
from ._apps.plots import load_scene as load_scene
from ._apps.plots import plot_boundary as plot_boundary
from ._apps.plots import plot_corner_forces as plot_corner_forces
from ._apps.plots import plot_corner_tracks as plot_corner_tracks
from ._apps.plots import plot_energy as plot_energy
from ._apps.plots import plot_euler as plot_euler
from ._apps.plots import plot_forces as plot_forces
from ._apps.plots import plot_grid as plot_grid
from ._apps.plots import plot_keyframes as plot_keyframes
from ._apps.plots import plot_locator as plot_locator
from ._apps.plots import plot_mass_centre as plot_mass_centre
from ._apps.plots import plot_motion as plot_motion
from ._apps.plots import plot_sweep as plot_sweep
from ._apps.plots import save_all as save_all
from ._apps.plots import save_animation as save_animation
from ._apps.plots import save_figure as save_figure
from ._apps.plots import save_scan_plots as save_scan_plots
from ._apps.plots import scene_from_result as scene_from_result
