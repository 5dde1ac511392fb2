"""Figures of the analyses (matplotlib, no display needed). Apart from the computations they draw."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .sweep import SweepResult  # noqa: E402


def plot_sweep(results: list[SweepResult], path: Path, title: str = "") -> Path:
    """Non-dimensional peak force F_i/mg versus Omega/omega (the paper's Figs 6 and 8).

    One line per sweep; the lower panel gives impacts per cycle (1: band A, 0.5: band B).
    """
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    for res in results:
        x = [p.frequency_ratio for p in res.points]
        ax.plot(x, [p.force_ratio for p in res.points], "-o", ms=3, label=f"gap {res.gap_mm:g} mm, {res.direction}")
        ax2.plot(x, [p.impacts_per_cycle for p in res.points], "-o", ms=3)
        for band, name in ((res.band_a, "A"), (res.band_b, "B")):
            if band is not None:
                ax.annotate(f"{name}: {band.frequency_hz:g} Hz, {band.peak_force_n:.0f} N",
                            (band.frequency_ratio, band.force_ratio), textcoords="offset points", xytext=(5, 5),
                            fontsize=8)
    ax.set_ylabel("F_i / mg")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax2.set_ylabel("impacts / cycle")
    ax2.set_xlabel("Omega / omega_n")
    ax2.grid(alpha=0.3)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
