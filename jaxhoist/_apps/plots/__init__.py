"""Plots and the animation (matplotlib, no pyplot state): trajectory plots (`trajectory`), scan, locator and
boundary plots (`scan`), the 3-D animation (`animation`) and the scene it draws (`scene`). The public module
`jaxhoist.plots` re-exports these names."""

from .animation import animate as animate
from .animation import load_scene as load_scene
from .animation import plot_keyframes as plot_keyframes
from .animation import save_animation as save_animation
from .animation import scene_from_result as scene_from_result
from .scan import plot_boundary as plot_boundary
from .scan import plot_grid as plot_grid
from .scan import plot_locator as plot_locator
from .scan import plot_sweep as plot_sweep
from .scan import save_scan_plots as save_scan_plots
from .trajectory import plot_corner_forces as plot_corner_forces
from .trajectory import plot_corner_tracks as plot_corner_tracks
from .trajectory import plot_energy as plot_energy
from .trajectory import plot_euler as plot_euler
from .trajectory import plot_forces as plot_forces
from .trajectory import plot_mass_centre as plot_mass_centre
from .trajectory import plot_motion as plot_motion
from .trajectory import save_all as save_all
from .trajectory import save_figure as save_figure
