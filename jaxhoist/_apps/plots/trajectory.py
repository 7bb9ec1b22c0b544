"""Plots of one lift (matplotlib only). Every function takes a `Trajectory` or the dict of arrays read back by
`jaxhoist._io.results.load_trajectory`, and returns a `matplotlib.figure.Figure`; axis labels carry units.

Figures are built without pyplot (no global state, no GUI backend needed); `save_figure` renders with the Agg
backend. In a notebook, display a returned figure with `display(fig)`.

- `plot_mass_centre`: x, y, z of the mass centre vs t (paper Fig. 5 / 7 kind).
- `plot_euler`: φ, ψ, ϑ [deg] vs t (Fig. 7, 11, 12 kind).
- `plot_forces`: rope tension S and ground reaction R = ΣN_i vs t (Fig. 6 kind).
- `plot_corner_forces`: per corner D, E, F, H, normal force and friction-force magnitude vs t (Fig. 8 kind).
- `plot_corner_tracks`: corner paths seen from above with friction-force directions (Fig. 9 kind).
- `plot_energy`: mechanical-energy change vs hoist work - dissipation, and the residual.
- `plot_motion`: mass centre and Euler angles side by side (Fig. 7 kind).
- `save_all`: all of the above as PNGs in a folder.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..._io.results import as_arrays, liftoff_time

if TYPE_CHECKING:
    from matplotlib.figure import Figure

CORNERS = ("D", "E", "F", "H")
CORNER_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red")


# Fixed margins [inch] of the plots of one lift: room for a suptitle, tick labels of up to six characters and
# an axis label on the left and below, and (`top_titles`) a title above each column's first axes.
_LEFT, _RIGHT, _BOTTOM, _TOP, _TOP_TITLES, _GAP_V, _GAP_H = 0.8, 0.2, 0.5, 0.45, 0.7, 0.15, 0.95


def new_figure(nrows=1, ncols=1, *, figsize=(7.0, 5.0), sharex=True, fixed=False, top_titles=False, **kw):
    """A figure and its `nrows` x `ncols` axes (a 2-D array). By default matplotlib's constrained layout
    places them; with `fixed`, fixed margins do (`_LEFT` etc., in inches), which skips the layout engine's
    measuring of every label (about a third of the drawing time): for figures whose labels are known to
    fit, such as the plots of one lift. `top_titles` leaves room for a title above each column."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout=None if fixed else "constrained")
    axes = fig.subplots(nrows, ncols, sharex=sharex, squeeze=False, **kw)
    if fixed:
        w, h = figsize
        top = _TOP_TITLES if top_titles else _TOP
        cell_h = (h - _BOTTOM - top - _GAP_V * (nrows - 1)) / nrows
        cell_w = (w - _LEFT - _RIGHT - _GAP_H * (ncols - 1)) / ncols
        fig.subplots_adjust(
            left=_LEFT / w,
            right=1.0 - _RIGHT / w,
            bottom=_BOTTOM / h,
            top=1.0 - top / h,
            hspace=_GAP_V / cell_h,
            wspace=_GAP_H / cell_w,
        )
    return fig, axes


def _title(fig, what: str, title: str | None):
    fig.suptitle(what if title is None else title)


def _mark_liftoff(ax, data: dict, label: bool = False):
    t = liftoff_time(data["ts"], data["normal_forces"]) if "normal_forces" in data else None
    if t is not None:
        ax.axvline(t, color="0.5", lw=0.8, ls="--", label=f"lift-off {t:.2f} s" if label else None)


def plot_mass_centre(data, *, title: str | None = None) -> Figure:
    """Coordinates x, y, z [m] of the mass centre C in world axes vs time [s]; a dashed line marks lift-off
    (the first saved time with every N_i = 0)."""
    d = as_arrays(data)
    fig, axes = new_figure(3, 1, figsize=(7.0, 6.0), fixed=True)
    for i, (ax, name) in enumerate(zip(axes[:, 0], ("x", "y", "z"), strict=True)):
        ax.plot(d["ts"], d["position"][:, i], color="k", lw=1.2)
        ax.set_ylabel(f"{name}_C [m]")
        ax.grid(alpha=0.3)
        _mark_liftoff(ax, d, label=i == 0)
    if axes[0, 0].get_legend_handles_labels()[0]:
        axes[0, 0].legend(loc="best", fontsize="small")
    axes[-1, 0].set_xlabel("t [s]")
    _title(fig, "Mass centre", title)
    return fig


def plot_euler(data, *, title: str | None = None) -> Figure:
    """Euler angles φ (roll about ξ), ψ (yaw about Z), ϑ (pitch) [deg] vs time [s];
    R = R_Z(ψ) R_Y(ϑ) R_X(φ)."""
    d = as_arrays(data)
    fig, axes = new_figure(3, 1, figsize=(7.0, 6.0), fixed=True)
    deg = np.degrees(d["euler"])
    for i, (ax, name) in enumerate(zip(axes[:, 0], ("φ", "ψ", "ϑ"), strict=True)):
        ax.plot(d["ts"], deg[:, i], color="k", lw=1.2)
        ax.set_ylabel(f"{name} [deg]")
        ax.grid(alpha=0.3)
        _mark_liftoff(ax, d)
    axes[-1, 0].set_xlabel("t [s]")
    _title(fig, "Euler angles (R = R_Z(ψ) R_Y(ϑ) R_X(φ))", title)
    return fig


def plot_motion(data, *, title: str | None = None) -> Figure:
    """Mass-centre coordinates x, y, z [m] (left) and Euler angles φ, ψ, ϑ [deg] (right) vs time [s]
    (the paper's Fig. 7 kind)."""
    d = as_arrays(data)
    fig, axes = new_figure(3, 2, figsize=(10.0, 6.5), fixed=True, top_titles=True)
    deg = np.degrees(d["euler"])
    for i in range(3):
        ax = axes[i, 0]
        ax.plot(d["ts"], d["position"][:, i], color="k", lw=1.2)
        ax.set_ylabel(f"{'xyz'[i]}_C [m]")
        ax = axes[i, 1]
        ax.plot(d["ts"], deg[:, i], color="k", lw=1.2)
        ax.set_ylabel(f"{('φ', 'ψ', 'ϑ')[i]} [deg]")
        for ax in axes[i]:
            ax.grid(alpha=0.3)
            _mark_liftoff(ax, d, label=i == 0)
    if axes[0, 0].get_legend_handles_labels()[0]:
        axes[0, 0].legend(loc="best", fontsize="small")
    axes[0, 0].set_title("mass centre C (world axes)")
    axes[0, 1].set_title("Euler angles")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    _title(fig, "Motion of the load", title)
    return fig


def plot_forces(data, *, title: str | None = None) -> Figure:
    """Rope tension S [kN] and ground reaction R = ΣN_i [kN] vs time [s] (the paper's Fig. 6 kind)."""
    d = as_arrays(data)
    fig, axes = new_figure(2, 1, figsize=(7.0, 5.0), fixed=True)
    axes[0, 0].plot(d["ts"], d["rope_tension"] / 1e3, color="k", lw=1.2)
    axes[0, 0].set_ylabel("rope tension S [kN]")
    axes[1, 0].plot(d["ts"], d["ground_reaction"] / 1e3, color="k", lw=1.2)
    axes[1, 0].set_ylabel("ground reaction R = ΣN [kN]")
    for ax in axes[:, 0]:
        ax.grid(alpha=0.3)
        _mark_liftoff(ax, d)
    axes[-1, 0].set_xlabel("t [s]")
    _title(fig, "Rope tension and ground reaction", title)
    return fig


def plot_corner_forces(data, *, title: str | None = None) -> Figure:
    """For each corner D, E, F, H: normal force N_i [kN] and friction-force magnitude |T_i| [kN] vs time [s]
    (the paper's Fig. 8 kind; a corner off the ground shows N_i = |T_i| = 0)."""
    d = as_arrays(data)
    fig, axes = new_figure(4, 1, figsize=(7.0, 7.5), sharey=True, fixed=True)
    t = d["ts"]
    n = d["normal_forces"] / 1e3
    f = np.linalg.norm(d["friction_forces"], axis=-1) / 1e3
    for i, ax in enumerate(axes[:, 0]):
        ax.plot(t, n[:, i], color="0.55", lw=1.0, label="normal N")
        ax.plot(t, f[:, i], color=CORNER_COLOURS[i], lw=1.3, label="friction |T|")
        ax.set_ylabel(f"{CORNERS[i]} [kN]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize="small", ncols=2)
    axes[-1, 0].set_xlabel("t [s]")
    _title(fig, "Corner forces: normal N_i and friction |T_i|", title)
    return fig


def plot_corner_tracks(data, *, n_arrows: int = 40, n_outlines: int = 6, title: str | None = None) -> Figure:
    """The bottom corners D, E, F, H seen from above (world X-Y [m]) (the paper's Fig. 9 kind).

    Tracks are thick while the corner touches the ground (N_i > 0) and thin where it is in the air. Arrows
    point along the friction force T_i at up to `n_arrows` equally spaced saved times at which the corner
    touches the ground; they have a fixed length (direction, not magnitude). Grey outlines show the footprint
    D-E-F-H at `n_outlines` equally spaced times from t = 0 to lift-off (or the end), labelled with the time
    at corner D; dots mark the start."""
    d = as_arrays(data)
    fig, axes = new_figure(1, 1, figsize=(7.0, 7.0), sharex=False, fixed=True)
    ax = axes[0, 0]
    c, t, n = d["corners"], d["ts"], d["normal_forces"]
    span = float(np.ptp(c[..., :2].reshape(-1, 2), axis=0).max()) or 1.0
    arrow_len = 0.04 * span
    lift = liftoff_time(t, n)
    last = len(t) - 1 if lift is None else int(np.searchsorted(t, lift))
    for k, idx in enumerate(np.linspace(0, last, max(n_outlines, 2)).round().astype(int)):
        poly = np.vstack([c[idx, :, :2], c[idx, :1, :2]])
        ax.plot(
            poly[:, 0],
            poly[:, 1],
            color="0.55",
            lw=0.9 if k == 0 else 0.7,
            ls="-" if k == 0 else "--",
            zorder=1,
        )
        ax.annotate(
            f"{t[idx]:.1f} s",
            poly[0],
            fontsize="x-small",
            color="0.35",
            xytext=(3, -9),
            textcoords="offset points",
        )
    sample = np.linspace(0, len(t) - 1, max(n_arrows, 1)).round().astype(int)
    for i in range(4):
        col = CORNER_COLOURS[i]
        x, y = c[:, i, 0], c[:, i, 1]
        touch = n[:, i] > 0.0
        # contact segments: keep a point if it or a neighbour touches, so short contacts still show as lines
        near = touch | np.r_[touch[1:], False] | np.r_[False, touch[:-1]]
        ax.plot(x, y, color=col, lw=0.7, alpha=0.45, zorder=2)
        ax.plot(
            np.where(near, x, np.nan),
            np.where(near, y, np.nan),
            color=col,
            lw=2.0,
            zorder=3,
            label=f"{CORNERS[i]}",
        )
        ax.plot(x[0], y[0], "o", color=col, ms=5, zorder=4)
        T = d["friction_forces"][sample, i, :2]
        mag = np.linalg.norm(T, axis=-1)
        on = touch[sample] & (mag > 0.0)
        if np.any(on):
            u = T[on] / mag[on, None]
            ax.quiver(
                x[sample[on]],
                y[sample[on]],
                u[:, 0] * arrow_len,
                u[:, 1] * arrow_len,
                angles="xy",
                scale_units="xy",
                scale=1.0,
                color=col,
                width=0.0045,
                zorder=5,
            )
    ax.plot([], [], color="0.3", lw=2.0, label="on the ground")
    ax.plot([], [], color="0.3", lw=0.7, alpha=0.45, label="in the air")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.grid(alpha=0.3)
    ax.legend(title="corner", loc="best", fontsize="small")
    _title(fig, "Corner tracks from above; arrows: friction-force direction", title)
    return fig


def plot_energy(data, *, title: str | None = None) -> Figure:
    """Energy balance [kJ] (residual [J]) vs time [s]: the change of mechanical energy E(t) - E(0) against the
    hoist work minus the damping and friction losses (top), and their difference, the residual (bottom), which
    measures the solver error."""
    d = as_arrays(data)
    fig, axes = new_figure(2, 1, figsize=(7.0, 5.5), fixed=True)
    t = d["ts"]
    mech = d["energy_mechanical"] - d["energy_mechanical"][0]
    supplied = d["hoist_work"] - d["damping_loss"] - d["friction_work"]
    supplied = supplied - supplied[0]
    ax = axes[0, 0]
    ax.plot(t, mech / 1e3, color="k", lw=1.6, label="ΔE mechanical")
    ax.plot(t, supplied / 1e3, color="tab:orange", lw=1.0, ls="--", label="W_hoist - D_damping - W_friction")
    ax.plot(t, d["hoist_work"] / 1e3, color="tab:blue", lw=0.8, alpha=0.7, label="W_hoist")
    ax.set_ylabel("energy [kJ]")
    ax.legend(loc="best", fontsize="small")
    ax = axes[1, 0]
    ax.plot(t, d["energy_residual"], color="tab:red", lw=1.0)
    ax.set_ylabel("residual [J]")
    ax.set_xlabel("t [s]")
    for ax in axes[:, 0]:
        ax.grid(alpha=0.3)
    _title(fig, "Energy balance", title)
    return fig


PLOTS = {
    "mass_centre": plot_mass_centre,
    "euler": plot_euler,
    "forces": plot_forces,
    "corner_forces": plot_corner_forces,
    "corner_tracks": plot_corner_tracks,
    "energy": plot_energy,
}


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 110) -> Path:
    """Render `fig` with the Agg backend to `path` (PNG unless the suffix says otherwise)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=dpi)
    return path


def save_all(
    data, out_dir: str | Path, *, prefix: str = "", dpi: int = 110, title_prefix: str = ""
) -> list[Path]:
    """Write every plot of `PLOTS` as `<out_dir>/<prefix><name>.png`; returns the paths."""
    d = as_arrays(data)
    paths = []
    for name, fn in PLOTS.items():
        fig = fn(d)
        if title_prefix:
            fig.suptitle(f"{title_prefix}: {fig.get_suptitle()}")
        paths.append(save_figure(fig, Path(out_dir) / f"{prefix}{name}.png", dpi=dpi))
    return paths
