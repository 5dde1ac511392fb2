"""Map figures: the Peterka map, the basins of attraction and the maps over two parameters."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rimd_sim.analysis.plots.base import _hz_axis, _save, plt
from rimd_sim.analysis.plots.classes import (
    DENSE_CELLS,
    _class_image,
    _class_legend,
    _half_widths,
    _mark_invalid_cells,
    class_palette,
    map_dpi,
)

if TYPE_CHECKING:
    from matplotlib.artist import Artist

__all__ = ["plot_basins", "plot_map", "plot_peterka"]


def plot_peterka(result, path: Path, title: str = "", caption: str = "") -> Path:
    """Class of the motion from rest over gap/A0 x Omega/omega_n, coexisting attractors marked (Fig. 12 left).

    The motor frequency in Hz on top.
    """
    from matplotlib.lines import Line2D

    palette = class_palette(result.primary.ravel().tolist())
    fig, ax = plt.subplots(figsize=(10, 6))
    _class_image(ax, result.frequency_ratio, result.gap_ratio, result.primary, palette)
    gi, fj = np.nonzero(result.coexisting)
    # The mark is a lower bound: an attractor none of the starts reaches is not found (docs/analyses.md).
    found = f"at least: found from {getattr(result, 'starts', 3)} starts per cell"
    marks: list[Artist] = []
    dense = max(result.primary.shape) > DENSE_CELLS
    if len(gi) and dense:
        from matplotlib.colors import ListedColormap
        from matplotlib.patches import Patch

        x, y = result.frequency_ratio, result.gap_ratio
        dx = (x[-1] - x[0]) / (len(x) - 1) / 2
        dy = (y[-1] - y[0]) / (len(y) - 1) / 2
        ax.imshow(np.where(result.coexisting, 1.0, np.nan), cmap=ListedColormap(["black"]), alpha=0.3,
                  origin="lower", aspect="auto", interpolation="nearest",
                  extent=(x[0] - dx, x[-1] + dx, y[0] - dy, y[-1] + dy))
        marks = [Patch(facecolor="black", alpha=0.3, label=f"coexisting attractors (shaded; {found})")]
    elif len(gi):
        ms = max(1.0, min(4.0, 400.0 / max(result.primary.shape)))
        ax.plot(result.frequency_ratio[fj], result.gap_ratio[gi], "x", color="0.25", ms=ms, mew=0.6)
        marks = [Line2D([], [], marker="x", ls="", color="0.25", label=f"coexisting attractors ({found})")]
    if getattr(result, "invalid_rule", None) is not None:
        # A cell where any start left the valid domain (its class is still in the CSV, marked).
        marks = [*marks, *_mark_invalid_cells(ax, result.frequency_ratio, result.gap_ratio, result.invalid_rule)]
    ax.set_xlabel("Omega / omega_n")
    ax.set_ylabel("gap / A0")
    ratio, hz = np.asarray(result.frequency_ratio, float), np.asarray(result.frequencies_hz, float)
    if ratio.size and ratio[0] > 0:
        _hz_axis(ax, float(hz[0] / ratio[0]))
    _class_legend(ax, palette, marks)
    return _save(fig, path, title, ax, dpi=map_dpi(result.primary.shape), caption=caption)


def plot_basins(result, path: Path, title: str = "", caption: str = "") -> Path:
    """Class of the steady motion per initial condition (theta0, theta_dot0), in rad and rad/s, attractors drawn."""
    palette = class_palette(result.labels.ravel().tolist())
    fig, ax = plt.subplots(figsize=(9, 6))
    _class_image(ax, result.theta0, result.theta_dot0, result.labels, palette)
    marks = []
    if getattr(result, "invalid_rule", None) is not None:
        marks = _mark_invalid_cells(ax, result.theta0, result.theta_dot0, result.invalid_rule)
    # The grid's extent stays the view: an attractor far outside it (a pendulum that turns over) would shrink the
    # basins to a point; such an attractor is named in the legend as off the grid.
    hx, hy = _half_widths(result.theta0), _half_widths(result.theta_dot0)
    x_lim = (float(result.theta0[0] - hx[0]), float(result.theta0[-1] + hx[-1]))
    y_lim = (float(result.theta_dot0[0] - hy[0]), float(result.theta_dot0[-1] + hy[-1]))
    # Each attractor's stroboscopic points (theta, theta') in the axes' units, its id beside them.
    for a in getattr(result, "attractors", None) or []:
        th = np.asarray(a["theta_rad"])
        om = np.asarray(a["theta_dot_rad_s"])
        inside = (th >= min(x_lim)) & (th <= max(x_lim)) & (om >= min(y_lim)) & (om <= max(y_lim))
        off = "" if inside.all() else " (partly off the grid)" if inside.any() else " (off the grid)"
        line, = ax.plot(th, om, "o" if a["period"] else "s", ms=7, mfc="white", mec="black", mew=1.2, ls="",
                        zorder=5, label=f"attractor {a['id']}: {a['class']}"
                        + ("" if a["period"] else " (not settled)") + off)
        ax.annotate(str(a["id"]), (th[0], om[0]), textcoords="offset points", xytext=(5, 5), fontsize=8, zorder=5)
        marks.append(line)
    ax.set_xlim(*x_lim)
    ax.set_ylim(*y_lim)
    ax.set_xlabel("initial theta (rad)")
    ax.set_ylabel("initial theta' (rad/s)")
    _class_legend(ax, palette, marks)
    return _save(fig, path, title, ax, dpi=map_dpi(result.labels.shape), caption=caption)


def _axis_label(name: str, unit: str) -> str:
    """``natural_frequency (Hz)``; the motor frequency as ``motor frequency (Hz)``."""
    words = "motor frequency" if name == "frequency" else name
    return f"{words} ({unit})" if unit else words


def plot_map(result, path: Path, title: str = "", caption: str = "") -> Path:
    """Two panels over (x, y): the class of the motion from rest (as :func:`plot_peterka` draws it), and the peak force.

    ``result``: a :class:`~rimd_sim.analysis.dynamics.maps.ParameterMap`. Cells outside the model's valid domain
    are hatched on both panels; a failed cell has no force (blank).
    """
    x, y = np.asarray(result.x_values, dtype=float), np.asarray(result.y_values, dtype=float)
    xlabel, ylabel = _axis_label(result.x, result.x_unit), _axis_label(result.y, result.y_unit)
    palette = class_palette(result.labels.ravel().tolist())
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(15, 6))
    _class_image(ax, x, y, result.labels, palette)
    marks = _mark_invalid_cells(ax, x, y, result.invalid_rule)
    _class_legend(ax, palette, marks)
    ax.set_title("class of the motion from rest", fontsize=10)
    force = np.ma.masked_invalid(np.asarray(result.peak_force, dtype=float))
    mesh = ax2.pcolormesh(x, y, force, cmap="viridis", shading="nearest")
    fig.colorbar(mesh, ax=ax2, label="peak impact force (N), steady window")
    _mark_invalid_cells(ax2, x, y, result.invalid_rule)
    ax2.set_title("peak impact force from rest (0: no impact)", fontsize=10)
    for a in (ax, ax2):
        a.set_xlabel(xlabel)
        a.set_ylabel(ylabel)
    return _save(fig, path, title, dpi=map_dpi(result.labels.shape), caption=caption)
