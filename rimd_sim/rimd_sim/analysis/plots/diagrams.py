"""Figures along the frequency, and of one orbit: bifurcation diagram, continued branches, Poincare map."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rimd_sim.analysis.plots.base import _hz_axis, _natural_frequency, _save, mark_invalid, plt
from rimd_sim.analysis.plots.classes import _class_legend, class_palette

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["bifurcation_figure", "plot_bifurcation", "plot_continuation", "plot_poincare"]


#: Colours of the classes too light for a marker on white (drawn darker in :func:`plot_bifurcation`).
_MARKER_COLOURS = {"no impact": "#9e9e9e", "inside the stop": "#bdbdbd"}

#: How each sweep direction is drawn in :func:`plot_bifurcation`: up small filled dots over down larger rings, so
#: that both show where they coincide.
_SWEEP_MARKERS: dict[str, dict[str, Any]] = {"up": {"s": 12, "linewidths": 0, "zorder": 3},
                  "down": {"s": 46, "linewidths": 1.0, "zorder": 2}}


def bifurcation_figure(branches) -> tuple[Figure, Axes]:
    """The figure of :func:`plot_bifurcation`, labelled, not saved (for a caller that adds to it, or a test)."""
    from matplotlib.lines import Line2D

    fig, ax = plt.subplots(figsize=(10, 5.5))
    palette = class_palette([p.label for b in branches for p in b.points if p.valid])
    colours = {c: _MARKER_COLOURS.get(c, col) for c, col in palette.items()}
    marked = False   # the legend names the invalid points once
    f_n = None
    for b in branches:
        f_n = f_n or _natural_frequency(b.points)
        xs = [p.frequency_ratio for p in b.points if p.valid for _ in p.u]
        ys = [float(u) for p in b.points if p.valid for u in p.u]
        cs = [colours[p.label] for p in b.points if p.valid for _ in p.u]
        style = _SWEEP_MARKERS.get(b.direction, _SWEEP_MARKERS["up"])
        if b.direction == "down":
            ax.scatter(xs, ys, facecolors="none", edgecolors=cs, **style)
        elif b.direction == "rest":   # crosses over both sweeps: each frequency started from rest
            ax.scatter(xs, ys, c=cs, marker="x", s=14, linewidths=0.8, zorder=4)
        else:
            ax.scatter(xs, ys, c=cs, **style)
        invalid = [p for p in b.points if not p.valid]
        if invalid:
            # Hollow grey markers: the samples of the points outside the model's valid domain (none where the
            # chattering guard fired: a cross at 0).
            valid_u = [abs(float(u)) for p in b.points if p.valid for u in p.u]
            mark_invalid(ax, [p.frequency_ratio for p in invalid for _ in (p.u if len(p.u) else [0])],
                         [float(u) for p in invalid for u in (p.u if len(p.u) else [math.nan])],
                         [p.invalid_rule for p in invalid for _ in (p.u if len(p.u) else [0])],
                         top=max(valid_u, default=None), legend=not marked, marker="s",
                         ms=7 if b.direction == "down" else 3.5)
            marked = True
    ax.set_xlabel("Omega / omega_n")
    ax.set_ylabel("l sin(theta) / A0 (stroboscopic)")
    ax.grid(alpha=0.3)
    if f_n:
        _hz_axis(ax, f_n)
    sweeps = [Line2D([], [], ls="", marker="o", ms=4.5, mfc="0.3", mec="0.3", label="sweep up (filled dots)"),
              Line2D([], [], ls="", marker="o", ms=8, mfc="none", mec="0.3", label="sweep down (rings)"),
              Line2D([], [], ls="", marker="x", ms=6, color="0.3", label="each frequency from rest (crosses)")]
    sweeps = [h for h, d in zip(sweeps, ("up", "down", "rest"), strict=True) if any(b.direction == d for b in branches)]
    _class_legend(ax, colours, [*sweeps, *ax.get_legend_handles_labels()[0]])
    return fig, ax


def plot_bifurcation(branches, path: Path, title: str = "", caption: str = "") -> Path:
    """Stroboscopic ``l sin(theta) / A0`` versus Omega/omega_n, up and down sweeps (the paper's Fig. 11).

    Each sample is coloured by the class of its point's motion (:func:`class_palette`); the up sweep is drawn as
    small filled dots over the down sweep's larger rings, the from-rest reading as crosses. The motor frequency in
    Hz on top.
    """
    fig, ax = bifurcation_figure(branches)
    return _save(fig, path, title, ax, caption=caption)


#: Marker and colour of each bifurcation kind in :func:`plot_continuation`: black and grey, told apart by shape, so
#: that no mark takes a branch's colour (:data:`_PERIOD_COLOURS`).
_BIFURCATION_STYLE = {"period_doubling": ("v", "k", "period doubling"), "fold": ("s", "k", "fold"),
                      "neimark_sacker": ("D", "k", "Neimark-Sacker"), "grazing": ("X", "0.45", "grazing"),
                      "branch_point": ("P", "k", "branch point")}
#: Colour of a continued branch by its period (1, 2, 4, 8, ... then others), none of them black or grey.
_PERIOD_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive",
                   "tab:cyan")


def plot_continuation(result, path: Path, title: str, *, natural_frequency_hz: float, length_m: float,
                      amplitude_m: float, diagram=None, caption: str = "") -> Path:
    """Branches of periodic orbits (stable solid, unstable dashed) over the brute-force bifurcation diagram.

    Top: the stroboscopic ``l sin(theta) / A0`` of every orbit's ``n`` points against the parameter (for the
    frequency: Omega/omega_n below, Hz above), the bifurcations marked; ``diagram`` (the
    :func:`~rimd_sim.analysis.dynamics.bifurcation.bifurcation` branches) in grey behind. Bottom: the largest
    Floquet multiplier's modulus (log scale) with the stability limit 1. Points outside the model's valid domain
    are drawn hollow grey.
    """
    freq = result.parameter == "frequency"
    scale_x = (1.0 / natural_frequency_hz) if freq else 1.0
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(10, 7.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.2]})
    if diagram:
        for b in diagram:
            xs = [p.frequency_ratio for p in b.points for _ in p.u]
            ys = [float(u) for p in b.points for u in p.u]
            # Large enough to show around a branch drawn over them (where they agree, they are under it).
            ax.scatter(xs, ys, s=14 if b.direction == "up" else 6, c="0.6" if b.direction == "up" else "0.8",
                       linewidths=0, label=f"brute force, sweep {b.direction}", zorder=1)
    seen_periods: set[int] = set()
    for br in result.branches:
        colour = _PERIOD_COLOURS[(br.period.bit_length() - 1) % len(_PERIOD_COLOURS)]
        x = np.array([p.parameter for p in br.points]) * scale_x
        stable = np.array([p.stable for p in br.points])
        valid = np.array([p.valid for p in br.points])
        mu = np.array([p.max_multiplier for p in br.points])
        n = br.period
        u = np.array([[length_m * math.sin(o[0]) / amplitude_m for o in p.orbit[:n]]
                      + [math.nan] * (n - len(p.orbit[:n])) for p in br.points])
        label = f"period {n}" if n not in seen_periods else None
        seen_periods.add(n)
        for i in range(len(x) - 1):
            style = "-" if stable[i] and stable[i + 1] else "--"
            for j in range(n):
                ax.plot(x[i:i + 2], u[i:i + 2, j], style, color=colour, lw=1.6, zorder=3,
                        label=label if (i == 0 and j == 0) else None)
            ax2.plot(x[i:i + 2], mu[i:i + 2], style, color=colour, lw=1.4)
        if len(x) == 1:
            ax.plot(x, u[:, 0], "o", color=colour, label=label)
        bad = ~valid
        if bad.any():
            mark_invalid(ax, np.repeat(x[bad], n), u[bad].ravel(), [p.invalid_rule for p in br.points if not p.valid
                                                                      for _ in range(n)], legend=True)
    marked: set[str] = set()
    for bif in result.bifurcations:
        marker, colour, name = _BIFURCATION_STYLE.get(bif.kind, ("o", "k", bif.kind))
        bx = bif.parameter * scale_x
        by = length_m * math.sin(float(bif.point[0])) / amplitude_m
        ax.plot([bx], [by], marker, color=colour, ms=9, mfc="none" if bif.kind == "grazing" else colour, mew=1.5,
                zorder=5, label=name if bif.kind not in marked else None)
        ax2.axvline(bx, color=colour, lw=0.8, ls=":")
        marked.add(bif.kind)
    ax2.axhline(1.0, color="k", lw=0.8)
    ax2.set_yscale("log")
    ax2.set_ylabel("largest |multiplier|")
    ax.set_ylabel("l sin(theta) / A0 (stroboscopic)")
    ax2.set_xlabel("Omega / omega_n" if freq else result.parameter)
    if freq:
        _hz_axis(ax, natural_frequency_hz)
    for a in (ax, ax2):
        a.grid(alpha=0.3)
    from matplotlib.lines import Line2D

    styles = [Line2D([], [], ls="-", color="k", lw=1.6, label="stable orbit (solid)"),
              Line2D([], [], ls="--", color="k", lw=1.6, label="unstable orbit (dashed)")]
    handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=[*handles, *styles], fontsize=8, markerscale=1.0, loc="best", ncols=2)
    return _save(fig, path, title, None, caption=caption)


def plot_poincare(t, x_rimd, x_cart, u, v, strobe_u, strobe_v, path: Path, title: str = "", invalid: str = "",
                  caption: str = "") -> Path:
    """Displacements over time and the phase plane with the Poincare map (the paper's Figs 9 and 10).

    ``x_rimd``, ``x_cart`` in mm (inertial); ``u = l sin(theta) / A0``, ``v`` its rate over ``A0 Omega``.
    ``invalid``: the point's broken rules of the model's valid domain; its curves are then drawn grey, hatched
    behind, the rules named in the legend.
    """
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.8))
    ax.plot(t, x_rimd, "b-", lw=1, label="RIMD (inertial)")
    ax.plot(t, x_cart, "k--", lw=1, label="cart")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("displacement (mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    ax2.plot(u, v, "-", color="0.6" if invalid else "b", lw=0.6, label="phase plane")
    # Few points (a periodic orbit) as dots, many (a chaotic section) small enough for its structure to show.
    ax2.plot(strobe_u, strobe_v, "o", mfc="none" if invalid else "r", mec="0.5" if invalid else "r",
             ms=5 if len(strobe_u) <= 60 else 1.5, label="Poincare map (motor phase 0)")
    if invalid:
        for a in (ax, ax2):
            a.add_patch(plt.Rectangle((0, 0), 1, 1, transform=a.transAxes, fill=False, hatch="//", ec="0.85",
                                      lw=0, zorder=0, label=f"outside the model's valid domain: {invalid}"))
    ax2.set_xlabel("l sin(theta) / A0")
    ax2.set_ylabel("l theta' cos(theta) / (A0 Omega)")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8, loc="upper left")
    return _save(fig, path, title, caption=caption)
