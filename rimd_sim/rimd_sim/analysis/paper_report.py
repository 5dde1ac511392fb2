"""The paper's figures in its layout, with its published values drawn on them, and the validation table.

``rimd paper`` writes them (docs/validation.md shows them). Every frequency axis is the paper's ``Omega / omega``
with the paper's ``omega`` (1.82 Hz, Table 1), so the twin's points and the experiment's values share one axis
whatever the twin's own natural frequency; the motor frequency in Hz is on top.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rimd_sim.analysis.dynamics.paper_targets import (
    FORCES_GAP0_N,
    PAPER_NATURAL_FREQUENCY_HZ,
    TABLE1_HZ,
    Check,
)
from rimd_sim.analysis.plots import _OTHER_COLOUR, CLASS_COLOURS, _class_image, _hz_axis, _save, plt

if TYPE_CHECKING:
    from matplotlib.artist import Artist

    from rimd_sim.analysis.dynamics.bifurcation import BifurcationBranch
    from rimd_sim.analysis.dynamics.paper_fit import Evaluation
    from rimd_sim.analysis.dynamics.peterka import PeterkaResult
    from rimd_sim.analysis.dynamics.sweep import SweepResult

__all__ = ["grouped_palette", "plot_paper_bifurcation", "plot_paper_forces", "plot_paper_peterka", "plot_pareto",
           "validation_markdown"]

W = PAPER_NATURAL_FREQUENCY_HZ
#: The classes the paper's figures name, in its colours (Fig. 12: period 1 red, period 1/2 green); every other
#: periodic impacting motion is one grey, so that a map's legend stays readable.
GROUPS = {c: "#ececec" if c == "no impact" else CLASS_COLOURS[c]
          for c in ("1/1", "1/2", "2/2", "no impact", "chaotic/non-periodic", "unsettled")}
OTHER = "other periodic impacting motion"
OTHER_COLOUR = _OTHER_COLOUR


def grouped(label: str) -> str:
    """The figure's group of a class (:data:`GROUPS`, else :data:`OTHER`)."""
    return label if label in GROUPS else OTHER


def grouped_palette(labels) -> dict[str, str]:
    """Colour per group present, in :data:`GROUPS`' order, :data:`OTHER` last."""
    present = {grouped(lab) for lab in labels}
    palette = {g: c for g, c in GROUPS.items() if g in present}
    if OTHER in present:
        palette[OTHER] = OTHER_COLOUR
    return palette


def _paper_axis(ax) -> None:
    ax.set_xlabel(f"Omega / omega  (omega: the paper's {W:g} Hz)")
    _hz_axis(ax, W)


def plot_paper_forces(sweeps: dict[float, SweepResult], gap_ratios: dict[float, float], mass_kg: float,
                      gravity: float, path: Path, caption: str = "") -> Path:
    """Figs. 6 and 8: ``F_i / mg`` against ``Omega / omega`` for the three gaps side by side, from rest.

    Each point is coloured by its motion's class; Table 1's resonances are vertical lines (band A solid, band B
    dashed), and at gap 0 the published forces are stars (divided by the twin's ``mg``: the paper gives no mass).
    """
    mg = mass_kg * gravity
    fig, axes = plt.subplots(1, 3, figsize=(17, 5), sharey=True)
    labels = [p.motion_class for r in sweeps.values() for p in r.points]
    palette = grouped_palette(labels)
    for ax, (gap, result) in zip(axes, sorted(sweeps.items()), strict=True):
        pts = [p for p in result.points if p.valid and math.isfinite(p.force_ratio)]
        x = np.array([p.frequency_hz / W for p in pts])
        y = np.array([p.force_ratio for p in pts])
        ax.plot(x, y, "-", color="0.75", lw=1, zorder=1)
        for group, colour in palette.items():
            sel = [i for i, p in enumerate(pts) if grouped(p.motion_class) == group]
            if sel:
                ax.scatter(x[sel], y[sel], s=28, color=colour, edgecolors="0.3", linewidths=0.5, zorder=3)
        fa, fb = TABLE1_HZ[gap]
        ax.axvline(fa / W, color="#d62728", lw=1.2)
        ax.axvline(fb / W, color="#2ca02c", lw=1.2, ls="--")
        if gap == 0.0:
            for band, f in zip("AB", (fa, fb), strict=True):
                ax.plot([f / W], [FORCES_GAP0_N[band] / mg], "*", ms=15, color="gold", mec="k", zorder=5)
        ax.set_title(f"gap {gap:g} mm (gap / A0 = {gap_ratios[gap]:.2f})", fontsize=10)
        _paper_axis(ax)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("F_i / mg (twin's mg)")
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles: list[Artist] = [Patch(facecolor=c, edgecolor="0.3", label=g) for g, c in palette.items()]
    handles += [Line2D([], [], color="#d62728", lw=1.2, label="Table 1: band A's resonance"),
                Line2D([], [], color="#2ca02c", lw=1.2, ls="--", label="Table 1: band B's resonance"),
                Line2D([], [], ls="", marker="*", ms=13, color="gold", mec="k",
                       label=f"paper, gap 0: {FORCES_GAP0_N['A']:g} N and {FORCES_GAP0_N['B']:g} N")]
    axes[-1].legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return _save(fig, path, "Peak impact force against frequency, from rest (paper Figs. 6 and 8)",
                 caption=caption)


def plot_paper_bifurcation(branches: Mapping[float, Sequence[BifurcationBranch]], gap_ratios: dict[float, float],
                           path: Path, caption: str = "") -> Path:
    """Fig. 11: stroboscopic ``l sin(theta) / A0`` against ``Omega / omega`` for the three gaps side by side.

    The up sweep as small dots, the down sweep as rings, the from-rest reading as crosses, each sample coloured by
    its point's class; a chaotic window shows as a vertical spread of small black dots (drawn small so that its
    structure shows).
    """
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2), sharey=True)
    labels = [p.label for bs in branches.values() for b in bs for p in b.points if p.valid]
    palette = grouped_palette(labels)
    palette = {g: ("#b0b0b0" if g == "no impact" else c) for g, c in palette.items()}
    style = {"up": {"marker": "o", "s": 6}, "down": {"marker": "o", "s": 26, "facecolors": "none"},
             "rest": {"marker": "x", "s": 14}}
    for ax, (gap, bs) in zip(axes, sorted(branches.items()), strict=True):
        for b in bs:
            for group, colour in palette.items():
                pts = [p for p in b.points if p.valid and grouped(p.label) == group]
                xs = [p.frequency_hz / W for p in pts for _ in p.u]
                ys = [float(u) for p in pts for u in p.u]
                if not xs:
                    continue
                kw = dict(style[b.direction])
                if group == "chaotic/non-periodic":
                    kw["s"] = 2 if b.direction != "down" else 6
                if kw.get("facecolors") == "none":
                    ax.scatter(xs, ys, edgecolors=colour, linewidths=0.6, zorder=2, **kw)
                elif kw["marker"] == "x":
                    ax.scatter(xs, ys, c=colour, linewidths=0.8, zorder=4, **kw)
                else:
                    ax.scatter(xs, ys, c=colour, linewidths=0, zorder=3, **kw)
        fa, fb = TABLE1_HZ[gap]
        for f, ls in ((fa, "-"), (fb, "--")):
            ax.axvline(f / W, color="0.6", lw=0.8, ls=ls)
        ax.set_title(f"gap {gap:g} mm (gap / A0 = {gap_ratios[gap]:.2f})", fontsize=10)
        _paper_axis(ax)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("l sin(theta) / A0 (stroboscopic)")
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles: list[Artist] = [Patch(facecolor=c, edgecolor="0.5", label=g) for g, c in palette.items()]
    handles += [Line2D([], [], ls="", marker="o", ms=3, color="0.3", label="sweep up (dots)"),
                Line2D([], [], ls="", marker="o", ms=6, mfc="none", mec="0.3", label="sweep down (rings)"),
                Line2D([], [], ls="", marker="x", ms=5, color="0.3", label="each frequency from rest (crosses)"),
                Line2D([], [], ls="-", color="0.6", label="Table 1 band A (solid), band B (dashed)")]
    axes[-1].legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return _save(fig, path, "Bifurcation diagrams (paper Fig. 11)", caption=caption)


def plot_paper_peterka(result: PeterkaResult, path: Path, caption: str = "") -> Path:
    """Fig. 12 (left): the class of the motion from rest over gap/A0 and ``Omega / omega``, coexistence crossed.

    The classes are grouped as the paper names them (:data:`GROUPS`): period 1 red, period 1/2 green, every other
    periodic impacting motion one grey; the line gap/A0 = 1.5 is the paper's limit of the coexisting motions.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    labels = np.vectorize(grouped, otypes=[object])(result.primary)
    palette = grouped_palette(labels.ravel().tolist())
    x = np.asarray(result.frequencies_hz, float) / W
    y = np.asarray(result.gap_ratio, float)
    fig, ax = plt.subplots(figsize=(11, 6))
    _class_image(ax, x, y, labels, palette)
    gi, fj = np.nonzero(result.coexisting)
    ax.plot(x[fj], y[gi], "x", color="k", ms=5, mew=0.9)
    ax.axhline(1.5, color="k", lw=1.0, ls=":")
    ax.set_ylabel("gap / A0")
    _paper_axis(ax)
    handles: list[Artist] = [Patch(facecolor=c, edgecolor="0.5", label=g) for g, c in palette.items()]
    handles += [Line2D([], [], ls="", marker="x", color="k", label=f"coexisting motions (from {result.starts} "
                                                                      "starts: at least)"),
                Line2D([], [], ls=":", color="k", label="gap / A0 = 1.5 (the paper's coexistence limit)")]
    ax.legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), title="motion from rest",
              title_fontsize=8)
    return _save(fig, path, "Peterka map (paper Fig. 12)", ax, caption=caption)


def plot_pareto(evaluations: Sequence[Evaluation], front: Sequence[Evaluation], path: Path, caption: str = "") -> Path:
    """The fit's trade-off: each evaluated set's force error against its doubling error, coloured by resonance fit.

    The Pareto front over the three objectives is ringed; the tolerances (5 %, 0.1 Hz) are the dashed box.
    """
    fig, ax = plt.subplots(figsize=(9, 6))
    objs = np.array([e.objectives() for e in evaluations])
    sc = ax.scatter(objs[:, 2], 100 * objs[:, 1], c=objs[:, 0], cmap="viridis", s=22, vmin=0,
                    vmax=max(0.25, float(objs[:, 0].max())))
    fobj = np.array([e.objectives() for e in front])
    if len(fobj):
        ax.scatter(fobj[:, 2], 100 * fobj[:, 1], s=90, facecolors="none", edgecolors="r", linewidths=1.2,
                   label="Pareto front (resonance, force, doubling)")
    passing = [e for e in evaluations if e.passed]
    if passing:
        p = np.array([e.objectives() for e in passing])
        ax.scatter(p[:, 2], 100 * p[:, 1], marker="*", s=70, c="k", label="every check passes")
    ax.axhline(5.0, color="k", ls="--", lw=0.8)
    ax.axvline(0.1, color="k", ls="--", lw=0.8)
    ax.set_xlabel("|period doubling - 4.75 Hz| (Hz)")
    ax.set_ylabel("largest gap-0 force error (%)")
    ax.set_xlim(left=0.0)
    ax.set_ylim(bottom=0.0)
    fig.colorbar(sc, ax=ax, label="largest Table 1 resonance residual (Hz, parabola-refined)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    return _save(fig, path, "The fit's trade-off between the paper's findings", ax, caption=caption)


def validation_markdown(checks: Sequence[Check], figures: Sequence[tuple[str, str]], *, config_line: str,
                        seconds: float, command: str) -> str:
    """validation.md: the table of every finding (paper, twin, tolerance, pass) and the figures."""
    passed = sum(c.passed for c in checks)
    lines = [
        "# Validation: the twin against the paper's published results",
        "",
        f"Made by `{command}` in {seconds:.0f} s. {config_line}",
        "",
        f"**{passed} of {len(checks)} findings reproduced.**",
        "",
        "| finding | source | paper | twin | tolerance | result | how |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for c in checks:
        unit = f" {c.unit}" if c.unit and not isinstance(c.paper, str) else ""
        twin = "-" if c.twin is None else (f"{c.twin:g}" if isinstance(c.twin, float) else str(c.twin))
        twin_unit = f" {c.unit}" if c.unit and c.twin is not None and not isinstance(c.twin, str) else ""
        paper = f"{c.paper:g}" if isinstance(c.paper, float) else str(c.paper)
        lines.append(f"| {c.finding} | {c.source} | {paper}{unit} | {twin}{twin_unit} | {c.tolerance} | "
                     f"{'pass' if c.passed else '**FAIL**'} | {c.detail} |")
    lines += ["", "## Figures", ""]
    for name, text in figures:
        lines += [f"![{text}]({name})", "", f"*{text}*", ""]
    return "\n".join(lines)
