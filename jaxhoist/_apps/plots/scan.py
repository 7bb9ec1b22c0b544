"""Plots of parameter scans and located changes of character (matplotlib only, no pyplot state).

- `plot_sweep`: an observable (each component in its own panel) against one swept parameter, failed
  members marked, candidate jumps shaded and located critical values drawn as vertical lines.
- `plot_grid`: an observable over a grid of two parameters, as a colour map per component.
- `plot_locator`: the evaluations of `locate_bifurcation`: the indicator against the parameter, and the
  bracket width against the solve count.
- `plot_boundary`: a boundary p*(q) traced by `trace_boundary`.
- `save_scan_plots`: every observable of a scan as PNGs, as `jaxhoist scan` writes them.

Every function returns a `matplotlib.figure.Figure`; `jaxhoist._apps.plots.trajectory.save_figure` writes it.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .trajectory import new_figure, save_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..scan.result import ScanResult

_MAX_PANELS = 6


def _with_unit(text: str, unit: str) -> str:
    return text if unit in ("-", "") else f"{text} [{unit}]"


def display_unit(unit: str) -> tuple[float, str]:
    """(factor, unit) in which a quantity of SI `unit` is drawn: angles in degrees ("rad" -> 180/π, "deg";
    "rad/s" -> "deg/s"), everything else as it is."""
    if unit == "rad" or unit.startswith("rad/"):
        return 180.0 / np.pi, "deg" + unit[3:]
    return 1.0, unit


def _label(result: ScanResult, name: str) -> str:
    return _with_unit(name, display_unit(result.units.get(name, "?"))[1])


def _values(result: ScanResult, name: str, y: np.ndarray) -> np.ndarray:
    return y * display_unit(result.units.get(name, "?"))[0]


def _has_values(result: ScanResult, name: str) -> bool:
    """True if some successful member has a finite value of `name` (else a plot of it would be empty, e.g.
    liftoff_time when nothing lifts off)."""
    y = np.asarray(result.data[name], dtype=float).reshape(*np.shape(result.ok), -1)
    return bool(np.any(np.isfinite(y[np.asarray(result.ok)])))


def _shown(n: int, total: int) -> str:
    return "" if n == total else f" (the first {n} of {total} components)"


def _components(result: ScanResult, name: str):
    """(labels, values of shape (members..., k)) for every component of `name`, all its trailing axes
    flattened (a sensitivity of a vector observable: component x parameter)."""
    y = np.asarray(result.data[name], dtype=float)
    axes = result.axes(name)
    if not axes:
        return [name], y[..., None]
    lists = [labels if labels is not None else [str(i) for i in range(n)] for _, n, labels in axes]
    return [f"{name}[{', '.join(c)}]" for c in itertools.product(*lists)], y.reshape(*result.shape, -1)


def plot_sweep(
    result: ScanResult,
    name: str,
    *,
    param: str | None = None,
    jumps: Sequence = (),
    located: Sequence = (),
    title: str | None = None,
) -> Figure:
    """Observable `name` against the swept parameter (the first one unless `param` is given).

    `jumps`: candidate `Jump`s from `find_jumps` (shaded); `located`: `Bifurcation`s or plain values of the
    parameter (vertical lines). Failed members are marked by red ticks on the parameter axis; values of
    +-inf (an event that never happened) are left out and counted in the panel title.
    """
    param = param or result.params[0]
    if result.mode == "grid" and len(result.params) > 1:
        raise ValueError("plot_sweep needs a 1-D scan (a sweep or points); use plot_grid for a grid")
    xf, x_unit = display_unit(result.units.get(param, "?"))
    x = xf * np.asarray(result.coords[param], dtype=float).reshape(-1)
    labels, y = _components(result, name)
    y = _values(result, name, y.reshape(x.size, -1))
    unit = display_unit(result.units.get(name, "?"))[1]
    ok = np.asarray(result.ok).reshape(-1)
    order = np.argsort(x, kind="stable")
    x, y, ok = x[order], y[order], ok[order]
    # components never finite (an event that happens for no member) get no panel
    empty = [k for k in range(len(labels)) if not np.any(np.isfinite(y[ok, k]))]
    keep = [k for k in range(len(labels)) if k not in empty] or [0]
    n_all = len(labels)
    labels, y = [labels[k] for k in keep], y[:, keep]
    n = min(len(labels), _MAX_PANELS)
    fig, axes = new_figure(n, 1, figsize=(7.0, 1.2 + 1.8 * n))
    for k in range(n):
        ax = axes[k, 0]
        yk = np.where(ok, y[:, k], np.nan)
        fin = np.isfinite(yk)
        ax.plot(x[fin], yk[fin], ".-", ms=2.5, lw=0.8, color="C0")
        n_inf = int(np.sum(np.isinf(yk)))
        ax.set_ylabel(labels[k] + ("" if n > 1 else f" [{unit}]"), fontsize=8)
        if n_inf:
            ax.set_title(f"{n_inf} members: ±inf (event not reached), not drawn", fontsize=8, loc="right")
        for j in jumps:
            ax.axvspan(j.lo, j.hi, color="orange", alpha=0.3, lw=0)
        for b in located:
            v = float(getattr(b, "value", b))
            ax.axvline(v, color="C3", lw=0.9, ls="--", label=f"{param}* = {v:.7g}" if k == 0 else None)
        if np.any(~ok):
            ax.plot(
                x[~ok],
                np.full(np.sum(~ok), 0.0),
                "|",
                color="red",
                ms=12,
                mew=1.5,
                transform=ax.get_xaxis_transform(),
                label="failed" if k == 0 else None,
            )
    if located or np.any(~ok):
        axes[0, 0].legend(fontsize=7, loc="best")
    axes[-1, 0].set_xlabel(_with_unit(param, x_unit))
    what = f"{name} [{unit}] against {param}" + _shown(n, n_all)
    if empty and len(keep) < n_all:
        what += f"\nnot drawn, no finite value: {', '.join(_components(result, name)[0][k] for k in empty)}"
    fig.suptitle(what if title is None else title, fontsize=10)
    return fig


def plot_grid(result: ScanResult, name: str, *, title: str | None = None) -> Figure:
    """Observable `name` over a grid scan of two parameters, one colour map per component (up to six)."""
    if result.mode != "grid" or len(result.params) != 2:
        raise ValueError(f"plot_grid needs a grid of two parameters, got {result.mode} of {result.params}")
    p0, p1 = result.params
    (f0, u0), (f1, u1) = (display_unit(result.units.get(p, "?")) for p in (p0, p1))
    x0, x1 = f0 * np.asarray(result.coords[p0], dtype=float), f1 * np.asarray(result.coords[p1], dtype=float)
    labels, y = _components(result, name)
    y = _values(result, name, y)
    ok = np.asarray(result.ok)
    n = min(len(labels), _MAX_PANELS)
    ncols = 1 if n == 1 else 2
    nrows = -(-n // ncols)
    fig, axes = new_figure(nrows, ncols, figsize=(6.0 * ncols, 4.0 * nrows), sharex=False)
    for k in range(nrows * ncols):
        ax = axes.flat[k]
        if k >= n:
            ax.set_visible(False)
            continue
        z = np.where(ok, y[..., k], np.nan)
        n_inf = int(np.sum(np.isinf(z)))
        z = np.where(np.isfinite(z), z, np.nan)
        pc = ax.pcolormesh(x0, x1, z.T, shading="nearest", cmap="viridis")
        fig.colorbar(pc, ax=ax, label=_label(result, name) if n == 1 else labels[k])
        if np.any(~ok):
            i0, i1 = np.nonzero(~ok)
            ax.plot(x0[i0], x1[i1], "x", color="red", ms=5, label="failed")
            ax.legend(fontsize=7)
        ax.set_xlabel(_with_unit(p0, u0))
        ax.set_ylabel(_with_unit(p1, u1))
        blank = f"{n_inf} cells ±inf (event not reached): blank" if n_inf else ""
        if n > 1 or blank:
            ax.set_title(", ".join(x for x in (labels[k] if n > 1 else "", blank) if x), fontsize=9)
    what = f"{_label(result, name)} over ({p0}, {p1})" + _shown(n, len(labels))
    fig.suptitle(what if title is None else title, fontsize=10)
    return fig


def plot_locator(b, *, title: str | None = None) -> Figure:
    """How `locate_bifurcation` got there: the indicator g = observable - level at every evaluation against
    the parameter (numbered in order; Newton steps, bisections and bracket ends in different markers), and,
    after each evaluation, the width of the smallest bracket with opposite signs of g at its ends and the
    distance of the evaluated point from the final estimate."""
    fig, axes = new_figure(1, 2, figsize=(10.0, 4.0), sharex=False)
    ax, aw = axes[0, 0], axes[0, 1]
    hist = [h for h in b.history if np.isfinite(h[1])]
    markers = {"end": ("s", "k"), "newton": ("o", "C0"), "bisect": ("v", "C1"), "multisection": ("d", "C2")}
    for tag, (m, c) in markers.items():
        pts = [(h[0], h[1]) for h in hist if h[3] == tag]
        if pts:
            px, py = zip(*pts, strict=True)
            ax.plot(px, py, m, color=c, ms=5, ls="none", label=tag)
    for i, h in enumerate(hist):
        ax.annotate(str(i + 1), (h[0], h[1]), fontsize=6, xytext=(3, 3), textcoords="offset points")
    ax.axhline(0.0, color="0.5", lw=0.7)
    ax.axvline(b.value, color="C3", ls="--", lw=0.9, label=f"{b.param}* = {b.value:.9g}")
    ax.set_xlabel(_with_unit(b.param, b.unit))
    ax.set_ylabel(f"g = {b.observable} - level")
    ax.legend(fontsize=7)
    # Bracket width after each evaluation: the smallest interval between evaluations of opposite sign.
    widths = []
    for i in range(1, len(hist) + 1):
        xs = np.array([h[0] for h in hist[:i]])
        gs = np.array([h[1] for h in hist[:i]])
        pos, neg = xs[gs > 0], xs[gs <= 0]
        if pos.size and neg.size:
            widths.append(float(np.min(np.abs(pos[:, None] - neg[None, :]))))
        else:
            widths.append(np.nan)
    k = np.arange(1, len(widths) + 1)
    aw.semilogy(k, widths, "o-", ms=4, label="bracket width")
    dist = np.array([abs(h[0] - b.value) for h in hist])
    aw.semilogy(k[dist > 0], dist[dist > 0], "x:", ms=5, label=f"|{b.param.split('.')[-1]} - estimate|")
    aw.axhline(b.tol, color="0.5", ls=":", label=f"tol = {b.tol:g}")
    aw.set_xlabel("solve")
    aw.set_ylabel(_with_unit("distance", b.unit))
    aw.legend(fontsize=7)
    what = (
        f"{_with_unit(f'{b.param}* = {b.value:.9g}', b.unit)}: {b.n_solves} solves against {b.n_uniform} "
        "for a uniform grid"
    )
    fig.suptitle(what if title is None else title, fontsize=10)
    return fig


def plot_boundary(boundary, *, title: str | None = None) -> Figure:
    """A boundary p*(q) traced by `trace_boundary`: located points with their final brackets as error bars
    (usually far below the marker size), lost or failed points marked on the q axis."""
    fig, axes = new_figure(1, 1, figsize=(6.5, 4.5))
    ax = axes[0, 0]
    q, p = np.asarray(boundary.along_values), np.asarray(boundary.values)
    ok = np.isfinite(p)
    ax.errorbar(p[ok], q[ok], xerr=0.5 * np.asarray(boundary.widths)[ok], fmt="o-", ms=4, capsize=2)
    if np.any(~ok):
        ax.plot(
            np.full(np.sum(~ok), np.nanmin(p) if ok.any() else 0.0),
            q[~ok],
            "x",
            color="red",
            label="lost or not found",
        )
        ax.legend(fontsize=7)
    unit = next((b.unit for b in boundary.points if b is not None and b.unit != "?"), "")
    ax.set_xlabel(_with_unit(f"{boundary.param}*", unit))
    ax.set_ylabel(boundary.along)
    what = (
        f"{boundary.param}*({boundary.along}) by continuation\n{boundary.n_solves} solves "
        f"(a dense grid at {boundary.tol:g}: {boundary.n_dense})"
    )
    fig.suptitle(what if title is None else title, fontsize=10)
    return fig


def plot_skips(result: ScanResult) -> dict[str, str]:
    """Observable name -> why `save_scan_plots` draws no `scan_<name>.png` for it (no entry: it draws one)."""
    if not (len(result.params) == 1 or (result.mode == "grid" and len(result.params) == 2)):
        n = len(result.params)
        why = f"scan plots are drawn for one parameter or a grid of two, not a {result.mode} of {n}"
        return dict.fromkeys(result.data, why)
    t1 = result.attrs.get("t1")
    within = "" if t1 is None else f" within t1 = {float(t1):g} s"
    return {
        name: f"{name} is inf or NaN in every successful member (an event that no member reaches{within}; "
        "a longer --t1 may reach it)"
        for name in result.data
        if not _has_values(result, name)
    }


def save_scan_plots(result: ScanResult, out_dir: str | Path, *, located=(), dpi: int = 110) -> list[Path]:
    """Write `<out_dir>/scan_<observable>.png` for every observable: against the parameter for a sweep of
    one parameter (with `located` critical values drawn), a colour map for a grid of two; angles in degrees.
    Other layouts (points, three or more parameters) and observables without a single finite value (an
    event no member reaches, e.g. liftoff_time when nothing lifts off) get no plots. Returns the paths."""
    paths = []
    for name in result.data:
        if not _has_values(result, name):
            continue  # e.g. liftoff_time when nothing lifts off: no empty plot
        if result.mode == "grid" and len(result.params) == 2:
            fig = plot_grid(result, name)
        elif len(result.params) == 1:
            fig = plot_sweep(result, name, located=located)
        else:
            continue
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
        paths.append(save_figure(fig, Path(out_dir) / f"scan_{safe}.png", dpi=dpi))
    return paths
