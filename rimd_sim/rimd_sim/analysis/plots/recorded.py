"""Figures of a recording (``rimd analyze``): peaks per step, impacts and channels over time, pulse, spectra."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rimd_sim.analysis.plots.base import _force_over_impacts, _ratio_axis, _save, _save_force_over_impacts, plt

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from rimd_sim.analysis.recordings.reading import Window
    from rimd_sim.analysis.recordings.recorded import Channel, Step

__all__ = ["plot_acceleration_spectrum", "plot_pulse_zoom", "plot_recorded_channels", "plot_recorded_impacts",
           "plot_recorded_peaks", "plot_recorded_phase_planes"]


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
            # At the foot of the axes whatever the forces' range: a label at y = 0 in data would leave the figure
            # when every peak is far above 0, and tight_layout cannot make room for it.
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
