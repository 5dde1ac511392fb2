"""The figure of a frequency sweep: the peak force over the impacts per cycle (the paper's Figs 6 and 8)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from rimd_sim.analysis.plots.base import (
    _force_over_impacts,
    _hz_axis,
    _label_force_over_impacts,
    _natural_frequency,
    _save,
    mark_invalid,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from rimd_sim.analysis.dynamics.sweep_result import SweepResult

__all__ = ["BANDS", "plot_sweep", "sweep_figure"]


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
