"""What every figure of the analyses shares: matplotlib on the Agg backend, saving, axes and markers.

Importing this module selects matplotlib's Agg backend (no display needed) and its tick format: tick labels say
their values whole up to 1e9 (a stiffness of 5.5e6 N/m reads 5500000), with no offset or multiplier ("1e6") at the
axis' end, where it would run into a secondary axis' tick labels.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
matplotlib.rcParams["axes.formatter.useoffset"] = False
matplotlib.rcParams["axes.formatter.limits"] = (-4, 9)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["mark_invalid", "plot_message", "plt", "warm_up"]


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

    A process's first figure pays once for the fonts, the text layout and the PNG writer (docs/benchmarks.md,
    "Latency", measures it). The figure worker of :mod:`rimd_sim.analysis.figures` calls this while its command
    computes. Nothing is written and matplotlib's settings are left as they were.
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


def plot_message(path: Path, title: str, message: str, caption: str = "") -> Path:
    """A figure that holds only ``message`` (a point without a result: the chattering guard stopped its run)."""
    fig, ax = plt.subplots(figsize=(8, 3))
    ax.axis("off")
    ax.text(0.5, 0.5, message, ha="center", va="center", fontsize=10, color="0.3", wrap=True)
    return _save(fig, path, title, ax, caption=caption)
