"""Figures of ``rimd identify`` (kept apart from the computations)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from rimd_sim.analysis.identification.identify import Identification


def _figure(rows: int, cols: int, size: tuple[float, float]) -> tuple[Any, Figure, Any]:
    """Import pyplot (on the Agg backend); return it, a figure and the figure's ``rows`` x ``cols`` axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt, *plt.subplots(rows, cols, figsize=size)


def plot_validation(result: Identification, path: Path, title: str) -> Path:
    """Recording and twin side by side.

    The displacement, the peak force of every impact (left-out windows shaded), the steady peaks per step and the
    impacts per cycle per step.
    """
    from rimd_sim.analysis.plots import _draw_windows

    plt, fig, axes = _figure(2, 2, (13, 8))
    s = result.series
    ax = axes[0, 0]
    if s:
        steps = [st for st in s["steps"] if st.steady_from is not None]
        if steps:   # the last 3 cycles of the last steady step: the orbit, recorded and re-simulated
            st = steps[-1]
            lo = max(st.end - 3.0 / max(st.setpoint, 0.1), st.steady_from)
            sel = (s["t"] >= lo) & (s["t"] < st.end)
            ax.plot(s["t"][sel], s["y"][sel] * 1e3, ".", ms=2, label="recorded (lasers)")
            ax.plot(s["t"][sel], s["y_twin"][sel] * 1e3, "-", lw=1, label="twin")
            ax.set_title(f"relative displacement, {st.setpoint:g} Hz")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("x_rimd - x_cart (mm)")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        ax = axes[0, 1]
        _draw_windows(ax, s.get("windows", ()))
        ax.plot(s["r_on"], s["r_peak"], ".", ms=3, label="recorded (force channel)")
        ax.plot(s["m_on"], s["m_peak"], "x", ms=3, label="twin")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("peak force (N)")
        ax.set_title("peak force per impact")
        ax.legend(fontsize=7)
    rows = result.validation
    if rows:
        f = np.array([r["frequency_hz"] for r in rows])
        idx = np.arange(len(rows))
        ax = axes[1, 0]
        ax.bar(idx - 0.2, [r["peak_force_recorded_n"] or 0.0 for r in rows], 0.4, label="recorded")
        ax.bar(idx + 0.2, [r["peak_force_twin_n"] or 0.0 for r in rows], 0.4, label="twin")
        ax.set_xticks(idx, [f"{v:g} Hz" for v in f])
        for i, r in enumerate(rows):
            if r["peak_force_difference"] is not None:
                ax.annotate(f"{r['peak_force_difference'] * 100:+.2f} %", (i, r["peak_force_recorded_n"]),
                            ha="center", va="bottom", fontsize=8)
        ax.set_ylabel("steady peak force (N)")
        ax.set_title("steady peak force per step (as rimd analyze reads it)")
        ax.legend(fontsize=8)
        ax = axes[1, 1]
        ax.plot(idx, [np.nan if r["impacts_per_cycle_recorded"] is None else r["impacts_per_cycle_recorded"]
                      for r in rows], "o", label="recorded")
        ax.plot(idx, [np.nan if r["impacts_per_cycle_twin"] is None else r["impacts_per_cycle_twin"]
                      for r in rows], "x", ms=8, label="twin")
        ax.set_xticks(idx, [f"{v:g} Hz" for v in f])
        ax.set_ylabel("impacts per cycle")
        ax.set_title("impacts per cycle per step")
        ax.legend(fontsize=8)
    res = result.residuals
    fig.suptitle(f"{title}: displacement residual {res.get('displacement_rms_um') or 0:.2f} um rms "
                 f"(laser noise {res.get('laser_noise_um') or 0:.2f} um)\n{result.verdict.line()[:160]}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
