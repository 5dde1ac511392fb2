"""Figures of the analyses (matplotlib on the Agg backend, no display needed), apart from their computations.

One module per family of figures: :mod:`~rimd_sim.analysis.plots.sweep` (frequency sweeps),
:mod:`~rimd_sim.analysis.plots.diagrams` (bifurcation diagram, continuation, Poincare map),
:mod:`~rimd_sim.analysis.plots.maps` (Peterka map, basins, maps over two parameters),
:mod:`~rimd_sim.analysis.plots.recorded` (``rimd analyze``); :mod:`~rimd_sim.analysis.plots.base` and
:mod:`~rimd_sim.analysis.plots.classes` hold what they share. Every plotting function is importable from this
package, by its name, as :class:`rimd_sim.analysis.figures.Figures` calls it.
"""

from __future__ import annotations

from rimd_sim.analysis.plots.base import _hz_axis as _hz_axis
from rimd_sim.analysis.plots.base import _save as _save
from rimd_sim.analysis.plots.base import mark_invalid, plot_message, plt, warm_up
from rimd_sim.analysis.plots.classes import _OTHER_COLOUR as _OTHER_COLOUR
from rimd_sim.analysis.plots.classes import CLASS_COLOURS, DENSE_CELLS, OTHER_PERIODIC, class_palette, map_dpi
from rimd_sim.analysis.plots.classes import _class_image as _class_image
from rimd_sim.analysis.plots.diagrams import bifurcation_figure, plot_bifurcation, plot_continuation, plot_poincare
from rimd_sim.analysis.plots.maps import plot_basins, plot_map, plot_peterka
from rimd_sim.analysis.plots.recorded import _draw_windows as _draw_windows
from rimd_sim.analysis.plots.recorded import (
    plot_acceleration_spectrum,
    plot_pulse_zoom,
    plot_recorded_channels,
    plot_recorded_impacts,
    plot_recorded_peaks,
    plot_recorded_phase_planes,
)
from rimd_sim.analysis.plots.sweep import BANDS, plot_sweep, sweep_figure

__all__ = [
    "BANDS", "CLASS_COLOURS", "DENSE_CELLS", "OTHER_PERIODIC", "bifurcation_figure", "class_palette", "map_dpi",
    "mark_invalid", "plot_acceleration_spectrum", "plot_basins", "plot_bifurcation", "plot_continuation", "plot_map",
    "plot_message", "plot_peterka", "plot_poincare", "plot_pulse_zoom", "plot_recorded_channels",
    "plot_recorded_impacts", "plot_recorded_peaks", "plot_recorded_phase_planes", "plot_sweep", "plt",
    "sweep_figure", "warm_up",
]
