"""Figures of the analyses (matplotlib, no display needed). Apart from the computations they draw."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
# Tick labels say their values whole up to 1e9 (a stiffness of 5.5e6 N/m reads 5500000), with no offset or
# multiplier ("1e6") written at the axis' end, where it ran into a secondary axis' tick labels.
matplotlib.rcParams["axes.formatter.useoffset"] = False
matplotlib.rcParams["axes.formatter.limits"] = (-4, 9)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from rimd_sim.analysis.dynamics.sweep_result import SweepResult
    from rimd_sim.analysis.recordings.reading import Window
    from rimd_sim.analysis.recordings.recorded import Channel, Step


def _save(fig: Figure, path: Path, title: str, ax: Axes | None = None, dpi: int = 120, caption: str = "") -> Path:
    """Title the figure (on ``ax``, else the whole figure), lay it out, write it and close it.

    ``caption``: the configuration the figure shows (:func:`rimd_sim.analysis.captions.describe`), a line under
    the title, both then over the whole figure. The PNG's metadata holds both (tEXt ``Title`` and
    ``Description``), so a figure can be traced to its design without its directory
    (``PIL.Image.open(path).text``).
    """
    if caption:
        # Over the whole figure (a title over an axes narrowed by a legend outside it would overflow the figure),
        # wrapped to its width (about 10 characters per inch at this size) between the caption's items.
        fig.suptitle("\n".join(filter(None, [title, _wrap(caption, max(40, int(10 * fig.get_figwidth())))])),
                     fontsize=10)
    elif title:
        if ax is not None:
            ax.set_title(title)
        else:
            fig.suptitle(title)
    fig.tight_layout()
    metadata = {"Title": title, "Description": caption} if caption else {"Title": title}
    fig.savefig(path, dpi=dpi, metadata=metadata)
    plt.close(fig)
    return path


def warm_up() -> None:
    """Draw a throwaway figure into memory, so that the next figure of this process draws warm.

    A process's first figure pays once for the fonts, the text layout and the PNG writer: about 0.1 s more than
    the next one (docs/benchmarks.md, "Latency"). The figure worker of :mod:`rimd_sim.analysis.figures` calls this
    while its command computes. Nothing is written and matplotlib's settings are left as they were.
    """
    import io

    fig, ax, ax2 = _force_over_impacts()
    ax.plot([0.0, 1.0], [0.0, 1.0], "-o", ms=3, label="warm-up")
    ax2.plot([0.0, 1.0], [1.0, 0.5], "-o", ms=3)
    ax.annotate("A", (0.5, 0.5), textcoords="offset points", xytext=(9, -9), fontsize=9, fontweight="bold")
    _label_force_over_impacts(ax, ax2, force="F_i / mg", frequency="Omega / omega_n",
                              legend={"fontsize": 8, "loc": "best"})
    fig.suptitle("warm-up\na 1, b 2", fontsize=10)   # as _save lays out and writes, into memory
    fig.tight_layout()
    fig.savefig(io.BytesIO(), format="png", dpi=120, metadata={"Title": "warm-up", "Description": "a 1, b 2"})
    plt.close(fig)


def _wrap(text: str, width: int) -> str:
    """``text`` in lines of at most about ``width`` characters, broken only after a comma or a semicolon.

    So that a parameter keeps its value and unit on its line (``damping_ratio 0.02``).
    """
    lines: list[str] = []
    for item in re.split(r"(?<=[,;]) ", text):
        if lines and len(lines[-1]) + 1 + len(item) <= width:
            lines[-1] += " " + item
        else:
            lines.append(item)
    return "\n".join(lines)


def _hz_axis(ax: Axes, natural_frequency_hz: float, label: str = "motor frequency (Hz)") -> None:
    """The motor frequency in Hz on top of an axis of Omega/omega_n (the same ticks' positions, other values)."""
    f = natural_frequency_hz
    top = ax.secondary_xaxis("top", functions=(lambda r: np.multiply(r, f), lambda hz: np.divide(hz, f)))
    top.set_xlabel(label)


def _ratio_axis(ax: Axes, natural_frequency_hz: float) -> None:
    """Omega/omega_n on top of an axis in Hz."""
    f = natural_frequency_hz
    top = ax.secondary_xaxis("top", functions=(lambda hz: np.divide(hz, f), lambda r: np.multiply(r, f)))
    top.set_xlabel(f"Omega / omega_n (f_n = {f:g} Hz)")


def _natural_frequency(points) -> float | None:
    """f_n from points that carry ``frequency_hz`` and ``frequency_ratio`` (None when none has a ratio)."""
    for p in points:
        if p.frequency_ratio > 0 and math.isfinite(p.frequency_hz / p.frequency_ratio):
            return p.frequency_hz / p.frequency_ratio
    return None


def _force_over_impacts() -> tuple[Figure, Axes, Axes]:
    """Two panels sharing the frequency axis: the peak force (3/4 of the height) over impacts per cycle."""
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax2.set_ylabel("impacts / cycle")
    return fig, ax, ax2


def _label_force_over_impacts(ax: Axes, ax2: Axes, *, force: str, frequency: str, legend: dict) -> None:
    """Label a :func:`_force_over_impacts` figure.

    ``force`` and ``frequency`` are the axis labels, ``legend`` the options of the force panel's legend.
    """
    ax.set_ylabel(force)
    if ax.get_legend_handles_labels()[0]:   # a recording without impacts draws no labelled line
        ax.legend(**legend)
    ax2.set_xlabel(frequency)
    for a in (ax, ax2):
        a.grid(alpha=0.3)


def _save_force_over_impacts(fig: Figure, ax: Axes, ax2: Axes, path: Path, title: str, *, force: str, frequency: str,
                             legend: dict, caption: str = "") -> Path:
    """Label (:func:`_label_force_over_impacts`) and save a :func:`_force_over_impacts` figure."""
    _label_force_over_impacts(ax, ax2, force=force, frequency=frequency, legend=legend)
    return _save(fig, path, title, ax, caption=caption)


def mark_invalid(ax: Axes, x, y, rules, *, top: float | None = None, legend: bool = True, marker: str = "o",
                 ms: float = 6) -> None:
    """Draw points outside the model's valid domain as hollow grey markers, the legend naming their rules.

    ``rules``: each point's ``invalid_rule`` field. A value that is not finite (no measure: the chattering guard
    stopped the run) is drawn at 0 with a cross. With ``top`` (the largest valid value), values above 1.2 x
    ``top`` are drawn at the top of the axis as triangles (off-scale), so the valid points keep their scale.
    ``marker`` and ``ms``: the hollow marker of the points on scale and its size.
    """
    y = np.asarray(y, dtype=float)
    names = sorted({name for r in rules for name in r.split(";") if name})
    label = f"outside the model's valid domain: {', '.join(names)}" if legend else None
    finite = np.isfinite(y)
    limit = None if top is None or not top > 0 else 1.2 * top
    on = finite if limit is None else finite & (y <= limit)
    x = np.asarray(x, dtype=float)
    if on.any():
        ax.plot(x[on], y[on], marker, mfc="none", mec="0.5", ms=ms, label=label)
        label = None
    off = finite & ~on
    if off.any() and limit is not None:
        ax.set_ylim(top=limit)
        ax.plot(x[off], np.full(off.sum(), limit * 0.97), "^", mfc="none", mec="0.5", ms=7,
                label=None if label is None else label + " (off scale)")
        label = None
    if (~finite).any():
        ax.plot(x[~finite], np.zeros((~finite).sum()), "x", color="0.5", ms=7, label=label)


#: The paper's bands: the motion of each (impacts per cycle) and the marker of its peak in :func:`plot_sweep`.
BANDS = (("A", "1 impact per cycle", "*"), ("B", "1 impact per 2 cycles", "D"))


def sweep_figure(results: list[SweepResult]) -> tuple[Figure, Axes, Axes]:
    """The figure of :func:`plot_sweep`, labelled, not saved (for a caller that adds to it, or a test)."""
    fig, ax, ax2 = _force_over_impacts()
    f_n = None
    for res in results:
        x = [p.frequency_ratio for p in res.points]
        f_n = f_n or _natural_frequency(res.points)
        # Points outside the model's valid domain break the line and are drawn apart (hollow grey markers).
        line, = ax.plot(x, [p.force_ratio if p.valid else math.nan for p in res.points], "-o", ms=3,
                        label=f"gap {res.gap_mm:g} mm, {res.direction}")
        ax2.plot(x, [p.impacts_per_cycle if p.valid else math.nan for p in res.points], "-o", ms=3)
        invalid = [p for p in res.points if not p.valid]
        if invalid:
            xs = [p.frequency_ratio for p in invalid]
            rules = [p.invalid_rule for p in invalid]
            mark_invalid(ax, xs, [p.force_ratio for p in invalid], rules,
                         top=max((p.force_ratio for p in res.points if p.valid), default=None))
            mark_invalid(ax2, xs, [p.impacts_per_cycle for p in invalid], rules, legend=False,
                         top=max((p.impacts_per_cycle for p in res.points if p.valid), default=None))
        # A band only where the data has it (no motion of its kind: no mark, no words); its peak marked, named
        # in the legend, its letter beside the mark towards the inside of the axes (never on the frame).
        lo, hi = min(x, default=0.0), max(x, default=1.0)
        for (name, motion, marker), band in zip(BANDS, (res.band_a, res.band_b), strict=True):
            if band is None:
                continue
            ax.plot([band.frequency_ratio], [band.force_ratio], marker, ms=11, mfc="none", mec=line.get_color(),
                    mew=1.5, zorder=4, label=f"band {name} ({motion}): {band.frequency_hz:g} Hz, "
                                             f"{band.peak_force_n:.0f} N")
            right = hi > lo and (band.frequency_ratio - lo) / (hi - lo) > 0.8
            ax.annotate(name, (band.frequency_ratio, band.force_ratio), textcoords="offset points",
                        xytext=(-9 if right else 9, -9), ha="right" if right else "left", va="top", fontsize=9,
                        fontweight="bold", color=line.get_color(), clip_on=True)
    _label_force_over_impacts(ax, ax2, force="F_i / mg", frequency="Omega / omega_n",
                              legend={"fontsize": 8, "loc": "best"})
    if f_n:
        _hz_axis(ax, f_n)
    return fig, ax, ax2


def plot_sweep(results: list[SweepResult], path: Path, title: str = "", caption: str = "") -> Path:
    """Non-dimensional peak force F_i/mg versus Omega/omega (the paper's Figs 6 and 8), the motor frequency on top.

    One line per sweep; the lower panel gives impacts per cycle (1: band A, 0.5: band B); each band's peak is
    marked and named where the sweep has one. ``caption``: the configuration (:func:`_save`).
    """
    fig, ax, _ = sweep_figure(results)
    return _save(fig, path, title, ax, caption=caption)


# ---- nonlinear analyses: bifurcation, phase plane + Poincare map, Peterka map, basins ----------

#: Fixed colours of the main classes (the paper's Fig. 12: period 1 red, period 1/2 green).
CLASS_COLOURS = {
    "no impact": "#e8e8e8", "1/1": "#d62728", "1/2": "#2ca02c", "2/2": "#ff7f0e", "1/3": "#1f77b4",
    "2/3": "#9467bd", "2/4": "#8c564b", "2/1": "#e377c2", "chaotic/non-periodic": "#000000",
    "integration failed": "#ffff00", "inside the stop": "#ffffff", "unsettled": "#9ecae1",
}
OTHER_PERIODIC = "other periodic"
_OTHER_COLOUR = "#7570b3"


def class_palette(labels) -> dict[str, str]:
    """Colour per class present: the fixed ones (:data:`CLASS_COLOURS`), every other class one colour.

    The other classes share one colour, named once in the legend as 'other periodic (N classes)': a map has up to
    twenty rare classes, and as many shades of grey and brown could not be told apart (the CSV keeps each class).
    """
    present = set(labels)
    palette = {c: CLASS_COLOURS[c] for c in CLASS_COLOURS if c in present}
    for c in sorted(present - set(palette)):
        palette[c] = _OTHER_COLOUR
    return palette


#: Above this many cells along an axis a map is drawn as an image of one pixel block per cell (not a mesh of
#: cells with edges) and coexisting attractors as a shaded overlay (not one marker per cell).
DENSE_CELLS = 120


def _class_image(ax, x, y, labels, palette):
    from matplotlib.colors import ListedColormap

    names = list(palette)
    index = {c: i for i, c in enumerate(names)}
    grid = np.array([[index[c] for c in row] for row in labels])
    cmap = ListedColormap([palette[c] for c in names])
    if max(grid.shape) > DENSE_CELLS and len(x) > 1 and len(y) > 1:
        dx = (x[-1] - x[0]) / (len(x) - 1) / 2
        dy = (y[-1] - y[0]) / (len(y) - 1) / 2
        ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(names) - 0.5, origin="lower", aspect="auto",
                  interpolation="nearest", extent=(x[0] - dx, x[-1] + dx, y[0] - dy, y[-1] + dy))
        return
    ax.pcolormesh(x, y, grid, cmap=cmap, vmin=-0.5, vmax=len(names) - 0.5, shading="nearest")


def _half_widths(v) -> np.ndarray:
    """Half the spacing around each value of a map axis (half the value's size, or 0.5, for a single one)."""
    v = np.asarray(v, dtype=float)
    if v.size < 2:
        return np.full(v.size, 0.5 * abs(float(v[0])) if v.size and v[0] else 0.5)
    d = np.abs(np.diff(v)) / 2
    return np.concatenate(([d[0]], (d[:-1] + d[1:]) / 2, [d[-1]]))


def _mark_invalid_cells(ax, x, y, rules) -> list:
    """Cover the cells outside the model's valid domain with hatched grey; returns the legend's entry.

    ``rules``: each cell's ``invalid_rule`` field (rows along ``y``, columns along ``x``); empty when valid.
    """
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Patch

    rows, cols = np.nonzero(rules != "")
    if not len(rows):
        return []
    hx, hy = _half_widths(x), _half_widths(y)
    # One box per cell, its corners as whole arrays (no patch object per cell): counter-clockwise from the lower left.
    x0 = np.asarray(x, dtype=float)[cols] - hx[cols]
    y0 = np.asarray(y, dtype=float)[rows] - hy[rows]
    x1, y1 = x0 + 2 * hx[cols], y0 + 2 * hy[rows]
    boxes = np.stack([np.stack([x0, y0], axis=1), np.stack([x1, y0], axis=1), np.stack([x1, y1], axis=1),
                      np.stack([x0, y1], axis=1)], axis=1)
    # Grey at 60 % over the class colour (still guessable beneath), hatched: distinct from every class colour.
    # An (n, 4, 2) array takes matplotlib's fast path (one template path's codes for all); its stubs say a sequence.
    ax.add_collection(PolyCollection(boxes, closed=True, facecolor=(0.6, 0.6, 0.6, 0.6),  # type: ignore[arg-type]
                                     edgecolor=(0.3, 0.3, 0.3, 1.0), hatch="//", lw=0, zorder=3))
    names = sorted({name for r in rules[rows, cols].tolist() for name in r.split(";") if name})
    return [Patch(facecolor=(0.6, 0.6, 0.6, 0.6), edgecolor=(0.3, 0.3, 0.3, 1.0), hatch="//",
                  label="outside the model's valid domain:\n" + ", ".join(names))]


def map_dpi(shape) -> int:
    """Resolution that gives each cell of a map at least about one pixel (120 to 300 dpi).

    ``shape`` is ``(rows, columns)``; the axes of the map figures are about 4.5 in high and 6.5 in wide.
    """
    rows, cols = shape[-2], shape[-1]
    return int(min(300, max(120, 1.1 * max(rows / 4.5, cols / 6.5))))


def _class_legend(ax, palette, extra=()):
    from matplotlib.patches import Patch

    handles, others = [], 0
    for name, col in palette.items():
        if col == _OTHER_COLOUR:
            others += 1
        else:
            handles.append(Patch(facecolor=col, edgecolor="0.5", label=name))
    if others:
        handles.append(Patch(facecolor=_OTHER_COLOUR, edgecolor="0.5", label=f"{OTHER_PERIODIC} ({others} classes)"))
    ax.legend(handles=[*handles, *extra], fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              title="impacts / cycles", title_fontsize=8)


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


def plot_message(path: Path, title: str, message: str, caption: str = "") -> Path:
    """A figure that holds only ``message`` (a point without a result: the chattering guard stopped its run)."""
    fig, ax = plt.subplots(figsize=(8, 3))
    ax.axis("off")
    ax.text(0.5, 0.5, message, ha="center", va="center", fontsize=10, color="0.3", wrap=True)
    return _save(fig, path, title, ax, caption=caption)


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
    if getattr(result, "invalid_rules", None) is not None:
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


# ---- recorded analyses (rimd analyze) ---------------------------------------------------------------------

#: How a left-out window is drawn, by its source: a hole in first_index, a fault seen in the data, /rig/faults.
_WINDOW_STYLE = {"gap": ("#7e57c2", "..", "hole in first_index"), "data": ("#ff9800", None, "fault seen in the data"),
                 "/rig/faults": ("#e53935", "//", "fault on /rig/faults")}


def _draw_windows(ax: Axes, windows: Iterable[Window], topics: Iterable[str] | None = None) -> int:
    """Shade the excluded windows (of ``topics``, or all) on a time axis; returns how many were drawn."""
    drawn, labelled = 0, set()
    for w in windows:
        if topics is not None and w.topic not in topics and w.topic != "motor":
            continue
        key = "gap" if w.kind == "gap" and w.source == "data" else w.source
        colour, hatch, label = _WINDOW_STYLE.get(key, _WINDOW_STYLE["data"])
        ax.axvspan(w.start, max(w.end, w.start + 1e-3), color=colour, alpha=0.25, lw=0, hatch=hatch,
                   label=None if key in labelled else f"left out: {label}")
        labelled.add(key)
        drawn += 1
    return drawn


def plot_recorded_peaks(rows: list[dict], path: Path, title: str = "", caption: str = "",
                        natural_frequency_hz: float | None = None) -> Path:
    """Steady peak force per dwell step versus motor frequency, from the events and from the force channel.

    Per source: the steady window's largest peak (the paper's F_i, filled marker) and the mean of its peaks with
    error bars of one standard deviation (the spread per step); impacts per cycle below. With
    ``natural_frequency_hz`` (the recorded rig's), Omega/omega_n on top.
    """
    fig, ax, ax2 = _force_over_impacts()
    for label, marker, shift in (("events", "o", -0.01), ("channel", "s", 0.01)):
        pts = [r for r in rows if r.get(f"peak_force_{label}_n") is not None]
        if not pts:
            continue
        name = "/rig/impact/events" if label == "events" else "/rig/impact/force"
        f = np.array([r["frequency_hz"] for r in pts])
        ax.plot(f + shift, [r[f"peak_force_{label}_n"] for r in pts], marker, ms=6, label=f"F_i (largest), {name}")
        mean = np.array([np.nan if r[f"peak_force_{label}_mean_n"] is None else r[f"peak_force_{label}_mean_n"]
                         for r in pts])
        std = np.array([0.0 if r[f"peak_force_{label}_std_n"] is None else r[f"peak_force_{label}_std_n"]
                        for r in pts])
        ax.errorbar(f + shift, mean, yerr=std, fmt="_", ms=10, capsize=4, lw=1.2,
                    label=f"mean +- 1 std of the steady peaks, {name}")
        ax2.plot(f + shift, [r[f"impacts_per_cycle_{label}"] for r in pts], marker, ms=6)
    if natural_frequency_hz:
        _ratio_axis(ax, natural_frequency_hz)
    return _save_force_over_impacts(fig, ax, ax2, path, title, force="steady peak force (N)",
                                    frequency="motor frequency setpoint (Hz)", legend={"fontsize": 7, "loc": "best"},
                                    caption=caption)


def plot_recorded_impacts(events_t: np.ndarray, events_peak: np.ndarray, det_t: np.ndarray, det_peak: np.ndarray,
                          steps: Iterable[Step], path: Path, title: str = "", windows: Iterable[Window] = (),
                          caption: str = "") -> int:
    """Peak force of every impact over time (events and force-channel detections), steps and left-out windows.

    Returns the number of windows drawn.
    """
    fig, ax = plt.subplots(figsize=(10, 4))
    for s in steps:
        if s.steady_from is not None:
            ax.axvspan(s.steady_from, s.end, color="#dddddd", alpha=0.5, lw=0)
            # At the foot of the axes whatever the forces' range (at y = 0 in data, a label left the figure
            # when every peak was far above 0, and tight_layout could not make room for it).
            ax.text(s.steady_from, 0.01, f"{s.setpoint:g} Hz", fontsize=7, va="bottom",
                    transform=ax.get_xaxis_transform())
    drawn = _draw_windows(ax, windows)
    ax.plot(events_t, events_peak, "o", ms=4, mfc="none", label="/rig/impact/events peak_force")
    ax.plot(det_t, det_peak, "x", ms=4, label="detected in /rig/impact/force")
    ax.set_xlabel("time (s from the recording's first stamp)")
    ax.set_ylabel("peak force (N)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    _save(fig, path, title, ax, caption=caption)
    return drawn


def plot_recorded_channels(channels: dict[str, Channel], windows: Sequence[Window], path: Path, title: str = "",
                           bins: int = 1500, caption: str = "") -> int:
    """The recorded channels over time (envelope of each time bin: min to max), left-out windows shaded.

    ``channels``: label -> :class:`~rimd_sim.analysis.recordings.recorded.Channel` (its ``topic`` selects its windows).
    Returns the number of windows drawn (over all panels).
    """
    n = max(1, len(channels))
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.9 * n + 0.6), sharex=True, squeeze=False)
    drawn = 0
    for ax, (label, ch) in zip(axes[:, 0], channels.items(), strict=False):
        for seg in ch.segments():
            t, v = ch.time[seg], ch.values[seg]
            k = max(1, v.size // bins)
            m = (v.size // k) * k
            if m >= k:
                tt = t[:m].reshape(-1, k)[:, 0]
                ax.fill_between(tt, v[:m].reshape(-1, k).min(axis=1), v[:m].reshape(-1, k).max(axis=1),
                                color="tab:blue", lw=0.5, step="post")
        drawn += _draw_windows(ax, windows, (ch.topic,))
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        if handles:
            ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time (s from the recording's first stamp)")
    _save(fig, path, title, caption=caption)
    return drawn


def plot_pulse_zoom(zoom: dict, path: Path, title: str = "", caption: str = "") -> Path:
    """One typical impact: the force and acceleration samples around its onset (ms), the capture when recorded.

    ``zoom``: ``onset`` (s), ``force`` and ``acceleration`` as ``(t, values)`` of the 20 kHz channels (either may
    be None), ``capture_force`` / ``model_force`` as ``(t, values)`` or None.
    """
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    t0 = zoom["onset"]
    if zoom.get("capture_force") is not None:
        t, v = zoom["capture_force"]
        ax.plot((t - t0) * 1e3, v, "-", color="0.6", lw=1, label="capture /rig/capture/force")
    if zoom.get("model_force") is not None:
        t, v = zoom["model_force"]
        ax.plot((t - t0) * 1e3, v, "-", color="tab:green", lw=1, label="spring-dashpot pulse fitted")
    if zoom.get("force") is not None:
        t, v = zoom["force"]
        ax.plot((t - t0) * 1e3, v, "o-", ms=4, lw=0.8, label="/rig/impact/force samples")
    ax.set_ylabel("force (N)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    if zoom.get("acceleration") is not None:
        t, v = zoom["acceleration"]
        ax2.plot((t - t0) * 1e3, v, "o-", ms=3, lw=0.8, color="tab:red", label="/rig/rimd/acceleration samples")
        ax2.legend(fontsize=7)
    ax2.set_ylabel("acceleration (m/s^2)")
    ax2.set_xlabel("time from the contact onset (ms)")
    ax2.grid(alpha=0.3)
    return _save(fig, path, title, caption=caption)


def plot_acceleration_spectrum(spectra: list[dict], path: Path, title: str = "", caption: str = "") -> Path:
    """Power spectral density of the hammer's acceleration, one panel per step (Welch), log-log.

    Each entry: ``label``, ``frequency`` (Hz), ``psd`` ((m/s^2)^2/Hz), ``motor_hz`` (its harmonics are marked:
    a steady motion of period one cycle puts its power on them).
    """
    n = max(1, len(spectra))
    cols = 2 if n > 1 else 1
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.5 * cols, 2.8 * rows), squeeze=False, sharex=True, sharey=True)
    for ax, sp in zip(axes.flat, spectra, strict=False):
        f, p = sp["frequency"][1:], sp["psd"][1:]
        ax.loglog(f, p, lw=0.7, color="tab:blue")
        for k in range(1, 6):
            ax.axvline(k * sp["motor_hz"], color="tab:red", ls=":", lw=0.8, label="motor harmonics" if k == 1 else None)
        ax.set_title(sp["label"], fontsize=9)
        ax.grid(alpha=0.3, which="both")
    for ax in list(axes.flat)[len(spectra):]:
        ax.axis("off")
    for ax in axes[-1, :]:
        ax.set_xlabel("frequency (Hz)")
    for ax in axes[:, 0]:
        ax.set_ylabel("PSD ((m/s^2)^2/Hz)", fontsize=8)
    if spectra:
        axes.flat[0].legend(fontsize=7, loc="lower left")
    return _save(fig, path, title, caption=caption)


def plot_recorded_phase_planes(panels: list[dict], path: Path, title: str = "", caption: str = "") -> Path:
    """One panel per step: phase plane (relative displacement vs velocity, mm and mm/s) and Poincare points.

    Each panel dict: ``label``, ``x``, ``v`` (curve, m and m/s), ``px``, ``pv`` (Poincare points).
    """
    n = max(1, len(panels))
    cols = min(4, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3.6 * rows), squeeze=False)
    for ax, panel in zip(axes.flat, panels, strict=False):
        ax.plot(np.asarray(panel["x"]) * 1e3, np.asarray(panel["v"]) * 1e3, "b-", lw=0.5)
        ax.plot(np.asarray(panel["px"]) * 1e3, np.asarray(panel["pv"]) * 1e3, "ro", ms=4, label="motor phase 0")
        ax.set_title(panel["label"], fontsize=9)
        ax.set_xlabel("x_rimd - x_cart (mm)", fontsize=8)
        ax.set_ylabel("velocity (mm/s)", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    if panels:
        axes.flat[0].legend(fontsize=7, loc="upper left")
    return _save(fig, path, title, dpi=110, caption=caption)


# ---- maps over two parameters (rimd map) ------------------------------------------------------------------


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
