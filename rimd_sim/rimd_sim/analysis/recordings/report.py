"""The analysis of a recording alone (``rimd analyze``): tables, figures, summary and the report's lines.

:func:`analyze` reads the recording once (:func:`rimd_sim.analysis.recordings.reading.read`, the reading
``rimd identify`` validates against) and writes into ``out``:

* ``impacts_detected.csv``, ``impact_events.csv`` (the cross-check, each side with its match), ``steps.csv``
  (per dwell step: steady peak force, its mean, spread and smallest, impacts per cycle, from the events and
  from the force channel), ``poincare.csv``, ``excluded_windows.csv`` (the windows left out: holes in
  ``first_index``, faults seen in the data or named on ``/rig/faults``), ``spectrum.csv``;
* figures ``peak_force_vs_frequency.png`` (error bars: the spread of each step's steady peaks), ``impacts.png``
  and ``channels.png`` (time plots, every left-out window drawn), ``phase_planes.png``, ``pulse_zoom.png`` (a
  typical impact's force and acceleration samples, with its 1 MHz capture when recorded) and
  ``acceleration_spectrum.png`` (Welch's PSD of the acceleration per step);
* ``summary.json``: what was lost, the cross-check counts, warnings, the steps, the fault report.

:func:`format_report` gives the lines the verb prints; the cross-check counts add up (every event is matched,
missed or not covered by the force channel; every detection is matched, an extra or after the events' end),
and a threshold that hides most impacts is said in a ``WARNING`` line.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rimd_sim.analysis.recordings import recorded as rec
from rimd_sim.analysis.recordings.reading import Reading, keep_mask, read
from rimd_sim.errors import AnalysisError

__all__ = ["ReportError", "analyze", "format_report", "format_steps", "threshold_warnings"]

#: Figures written by :func:`analyze`.
FIGURES = ("peak_force_vs_frequency.png", "impacts.png", "channels.png", "phase_planes.png", "pulse_zoom.png",
           "acceleration_spectrum.png")


class ReportError(AnalysisError):
    """The recording holds nothing to analyse (one line naming it and what it holds)."""


def analyze(recording: Path, out: Path, *, settle: float = 2.0, threshold: float = rec.DEFAULT_THRESHOLD,
            peak: str = "onset-fit", log: Callable[[str], None] | None = None, figures: bool = True) -> dict:
    """Analyse ``recording`` into ``out``; return the summary (also written as ``summary.json``).

    ``figures=False`` writes the tables and the summary only (no plotting library is loaded); the figures of an
    earlier run into ``out`` are removed either way.

    Raises:
        rimd_sim.io.reader.RecordingError: Not a recording at all.
        ReportError: The recording holds none of the topics analysed.
    """
    from rimd_sim.analysis.outputs import write_csv, write_summary

    start = time.perf_counter()
    log = log or (lambda text: None)
    data = rec.load(recording)   # a file that is not a recording fails here, before any output
    log(f"read {recording}: {sum(data.counts.values())} messages of the analysed topics")
    for report in data.recording.reports:
        if not report.complete:
            log(f"damaged: {report.describe()}")
    wanted = (rec.FORCE, rec.EVENTS, rec.MOTOR, rec.RIMD_X, rec.CART_X)
    if not any(data.counts.get(t) for t in wanted):
        found = ", ".join(sorted(data.recording.topics)) or "no topics"
        # A damaged recording may have lost them all: the one line says so, not only the log above it.
        damage = "; ".join(r.describe() for r in data.recording.reports if not r.complete)
        raise ReportError(f"{recording} holds none of the rig topics analysed ({', '.join(wanted)}); found: {found}"
                          + (f" (the recording is damaged: {damage})" if damage else ""))
    out.mkdir(parents=True, exist_ok=True)
    for name in FIGURES:   # "figures" in the summary lists this run's only
        (out / name).unlink(missing_ok=True)
    pulse = rec.pulse_model(data.recording.metadata) if peak == "onset-fit" else None
    if peak == "onset-fit":
        log("peaks: fitted spring-dashpot pulse at contact onset" if pulse is not None else
            "peaks: largest sample (the recording's contact law is not spring_dashpot or its parameters are missing)")
    reading = read(data, threshold=threshold, settle=settle, pulse=pulse)
    detected, events, match, steps = reading.detected, data.events, reading.match, reading.steps
    log(f"{len(detected['peak_time'])} impacts detected, {events['time'].size} events, {len(steps)} steps")
    if reading.windows:
        log(f"left out (s from the recording's first stamp): {reading.windows_text()}")

    write_csv(out / "impacts_detected.csv", [
        {"start_s": detected["start"][i], "peak_time_s": detected["peak_time"][i],
         "peak_force_n": detected["peak_force"][i], "peak_force_largest_sample_n": detected["peak_force_sample"][i],
         "peak_fitted": bool(detected["fitted"][i]), "duration_above_threshold_s": detected["duration"][i],
         "impulse_ns": detected["impulse"][i], "complete": bool(detected["complete"][i]),
         "event_index": _event_index(events, match["detected_match"][i]),
         "event_peak_force_n": _at(events, "peak_force", match["detected_match"][i])}
        for i in range(detected["peak_time"].size)])
    write_csv(out / "impact_events.csv", [
        {"time_s": events["time"][i], **{k: events[k][i] for k in (
            "index", "peak_force", "impulse", "duration", "impact_velocity", "max_penetration",
            "excitation_frequency", "excitation_phase", "cycle_index")},
         "detected_peak_force_n": _at(detected, "peak_force", match["event_match"][i]),
         "status": "matched" if match["event_match"][i] >= 0 else (
             "missed" if match["covered"][i] else "not covered")}
        for i in range(events["time"].size)])
    write_csv(out / "steps.csv", reading.rows)
    write_csv(out / "excluded_windows.csv", [w.as_dict() for w in reading.windows])

    caption, f_n = _recorded_design(data.recording.metadata)
    panels, poincare_rows = _phase_planes(data, steps)
    write_csv(out / "poincare.csv", poincare_rows)
    zoom = pulse_zoom(reading)
    spectra = acceleration_spectra(reading)
    drawn = _figures(reading, recording, out, panels, zoom, spectra, caption, f_n) if figures else {}
    if spectra:
        write_csv(out / "spectrum.csv", [{"step": sp["step"], "motor_hz": sp["motor_hz"], "frequency_hz": f,
                                          "psd_m2_s4_hz": p}
                                         for sp in spectra for f, p in zip(sp["frequency"], sp["psd"], strict=True)])
    summary = {
        "recording": str(recording),
        "origin_ns": data.origin_ns,
        "times": "seconds of simulation time since origin_ns (the earliest stamp in the recording)",
        "loss": data.loss(),
        "messages": data.counts,
        "settle_s": settle,
        "threshold_n": threshold,
        "detection": ("runs of force samples >= threshold; peak = "
                      + ("the fitted spring-dashpot pulse's peak (largest sample when the fit fails)"
                         if pulse is not None else "largest sample of the run")
                      + "; matched to an event when the peak lies in [contact start, contact end] +- 2 samples"),
        "peak_estimator": "onset-fit" if pulse is not None else "sample",
        "peaks_fitted": int(detected["fitted"].sum()) if detected["fitted"].size else 0,
        "impacts": {"events": int(events["time"].size), "detected": int(detected["peak_time"].size),
                    **{k: v for k, v in match.items() if k not in ("event_match", "detected_match", "covered")}},
        "warnings": threshold_warnings(reading),
        "steps": reading.rows,
        "excluded_windows": [w.as_dict() for w in reading.windows],
        "poincare_points": len(poincare_rows),
        "figures": sorted(p.name for p in out.glob("*.png")),
        "figure_windows": drawn,
        "pulse_zoom": None if zoom is None else {k: zoom[k] for k in ("onset", "peak", "step", "captured")},
        "spectra": [{"step": sp["step"], "motor_hz": sp["motor_hz"], "seconds": sp["seconds"]} for sp in spectra],
        "faults": reading.faults,
        "wall_seconds": time.perf_counter() - start,
    }
    write_summary(out, summary)
    return summary


def threshold_warnings(reading: Reading) -> list[str]:
    """``WARNING`` lines when the threshold hides the impacts (most recorded events below it, or no detection)."""
    out = []
    match, events, threshold = reading.match, reading.data.events, reading.threshold
    covered = int(np.sum(match["covered"])) if events.get("time", np.empty(0)).size else 0
    below = match["misses_below_threshold"]
    if covered and below >= max(1, covered / 2):
        peaks = events["peak_force"][match["covered"]]
        out.append(f"WARNING: --threshold {threshold:g} N is above the recorded peak of {below} of the {covered} "
                   f"events the force channel covers (median {float(np.median(peaks)):.3g} N, largest "
                   f"{float(peaks.max()):.3g} N): they are missed below; lower --threshold")
    force = reading.data.channels.get(rec.FORCE)
    if not reading.detected["start"].size and force is not None and force.values.size and not out:
        out.append(f"WARNING: no run of force samples reaches --threshold {threshold:g} N (the largest sample is "
                   f"{float(force.values.max()):.3g} N): no impact can be detected; lower --threshold if the "
                   "hammer hits")
    return out


def _recorded_design(metadata: dict[str, dict[str, str]]) -> tuple[str, float | None]:
    """The caption of the recorded rig's design (:mod:`rimd_sim.analysis.captions`) and its f_n (Hz).

    From the recording's ``rimd_rig_parameters`` metadata; ``("", None)`` without it.
    """
    from rimd_sim.analysis.captions import describe_parameters

    params = metadata.get("rimd_rig_parameters") or {}
    if not params:
        return "", None
    try:
        f_n: float | None = float(params["natural_frequency"])
    except (KeyError, ValueError):
        f_n = None
    return "recorded rig: " + describe_parameters(params), f_n if f_n and f_n > 0 else None


def _figures(reading: Reading, recording: Path, out: Path, panels: list[dict] | None, zoom: dict | None,
             spectra: list[dict], caption: str, f_n: float | None) -> dict[str, int]:
    """Write :data:`FIGURES` (those the recording gives); the left-out windows drawn per time plot."""
    from rimd_sim.analysis import plots

    data, detected, events, steps = reading.data, reading.detected, reading.data.events, reading.steps
    if panels is not None:
        plots.plot_recorded_phase_planes(panels, out / "phase_planes.png",
                                         "phase planes (RIMD relative to cart) and Poincare points, steady windows",
                                         caption=caption)
    plots.plot_recorded_peaks(reading.rows, out / "peak_force_vs_frequency.png",
                              f"steady peak force per step ({recording.name})", caption=caption,
                              natural_frequency_hz=f_n)
    drawn = plots.plot_recorded_impacts(events["time"], events["peak_force"], detected["peak_time"],
                                        detected["peak_force"], steps, out / "impacts.png",
                                        "impacts over time (steady windows grey, left-out windows coloured)",
                                        reading.windows, caption=caption)
    channels = {label: data.channels[t] for label, t in (("cart (m)", rec.CART_X), ("RIMD (m)", rec.RIMD_X),
                                                          ("acceleration (m/s^2)", rec.ACC), ("force (N)", rec.FORCE))
                if t in data.channels}
    drawn_channels = plots.plot_recorded_channels(channels, reading.windows, out / "channels.png",
                                                  "recorded channels (envelope), left-out windows shaded",
                                                  caption=caption) \
        if channels else 0
    if zoom is not None:
        plots.plot_pulse_zoom(zoom, out / "pulse_zoom.png",
                              f"a typical impact at {zoom['onset']:.4f} s (peak {zoom['peak']:.1f} N)",
                              caption=caption)
    if spectra:
        plots.plot_acceleration_spectrum(spectra, out / "acceleration_spectrum.png",
                                         "hammer acceleration, steady window of each step (Welch)",
                                         caption=caption)
    return {"impacts.png": drawn, "channels.png": drawn_channels}


def _phase_planes(data: rec.RecordedData, steps: list[rec.Step]) -> tuple[list[dict] | None, list[dict]]:
    """Phase planes and Poincare points over each step's steady window: the figure's panels, the Poincare rows.

    The panels are None when a laser is missing (no phase plane to draw).
    """
    panels: list[dict] = []
    poincare_rows: list[dict] = []
    rimd, cart = data.channels.get(rec.RIMD_X), data.channels.get(rec.CART_X)
    if rimd is None or cart is None:
        return None, poincare_rows
    t, x, v = rec.phase_plane(rimd, cart)
    strobe = rec.poincare_points(t, x, v, rec.poincare_times(data.motor))
    windows: list[tuple[rec.Step | None, float, float]] = [(s, s.steady_from, s.end) for s in steps
                                                            if s.steady_from is not None]
    if not windows:   # no motor states: the whole recording is one window
        finite = t[np.isfinite(t)]
        windows = [(None, finite[0], finite[-1])] if finite.size else []
    for step, lo, hi in windows:
        sel = (t >= lo) & (t < hi)
        psel = (strobe[:, 0] >= lo) & (strobe[:, 0] < hi)
        label = f"step {step.number}: {step.setpoint:g} Hz" if step else "whole recording"
        # The curve: the last 5 cycles of the window (the whole window would hide the orbit).
        f = step.setpoint if step and step.setpoint > 0 else 1.0
        tail = sel & (t >= hi - 5.0 / f)
        panels.append({"label": label, "x": x[tail], "v": v[tail], "px": strobe[psel, 1], "pv": strobe[psel, 2]})
        for tp, xp, vp in strobe[psel]:
            poincare_rows.append({"step": step.number if step else 0, "frequency_hz": step.setpoint if step else None,
                                  "time_s": tp, "x_rel_m": xp, "velocity_m_s": vp})
    return panels, poincare_rows


def pulse_zoom(reading: Reading, before: float = 0.5e-3, after: float = 1.5e-3) -> dict | None:
    """A typical impact: its samples around the onset, its capture, its fitted pulse.

    The complete impact outside every left-out window whose peak is the median of the steady windows' impacts (of
    all impacts when no step is steady).
    """
    from rimd_sim.analysis.recordings.contact_pulse import PulseSamples, fit_onsets

    data, det = reading.data, reading.detected
    force = data.channels.get(rec.FORCE)
    if force is None or not det["start"].size:
        return None
    ok = (det["complete"] > 0) & keep_mask(det["start"], reading.windows, (rec.FORCE, rec.ACC), 2e-3)
    steady = np.zeros(det["start"].size, dtype=bool)
    step_of = np.full(det["start"].size, -1)
    for s in reading.steps:
        if s.steady_from is not None:
            inside = (det["start"] >= s.steady_from) & (det["start"] < s.end)
            steady |= inside
            step_of[inside] = s.number
    pool = np.flatnonzero(ok & steady) if np.any(ok & steady) else np.flatnonzero(ok)
    if not pool.size:
        return None
    median = float(np.median(det["peak_force"][pool]))
    i = int(pool[np.argmin(np.abs(det["peak_force"][pool] - median))])
    onset = float(det["start"][i])
    zoom: dict[str, Any] = {"onset": onset, "peak": float(det["peak_force"][i]), "step": int(step_of[i]),
                            "captured": False, "force": None, "acceleration": None, "capture_force": None,
                            "model_force": None}
    sel = (force.time >= onset - before) & (force.time <= onset + after)
    zoom["force"] = (force.time[sel], force.values[sel])
    acc = data.channels.get(rec.ACC)
    if acc is not None:
        asel = (acc.time >= onset - before) & (acc.time <= onset + after)
        zoom["acceleration"] = (acc.time[asel], acc.values[asel]) if asel.any() else None
    for cap in data.captures:
        if abs(cap.trigger - onset) < 1e-3:
            csel = (cap.time >= onset - before) & (cap.time <= onset + after)
            zoom["capture_force"] = (cap.time[csel], cap.values[csel])
            zoom["captured"] = True
            break
    if reading.pulse is not None:
        t, v = force.time[sel], force.values[sel]
        j = int(np.searchsorted(t, onset))
        if 0 < j < t.size:
            (on,), (scale,) = fit_onsets(reading.pulse, [PulseSamples(t, v, 1.0 / force.rate, float(t[j - 1]),
                                                                      float(t[j]))])
            if scale > 0:
                fine = np.linspace(onset - before, onset + after, 2000)
                zoom["model_force"] = (fine, reading.pulse.force(fine - on, scale))
    return zoom


def acceleration_spectra(reading: Reading, seconds_per_segment: float = 4.0) -> list[dict]:
    """Welch's power spectral density of the acceleration over each step's steady window.

    The longest stretch of consecutive samples of the window outside the accelerometer's left-out windows;
    segments of ``seconds_per_segment`` (0.25 Hz resolution: the harmonics of the motor apart) with a Hann window,
    half overlapping.
    """
    from scipy.signal import welch

    acc = reading.data.channels.get(rec.ACC)
    if acc is None:
        return []
    ok = keep_mask(acc.time, reading.windows, (rec.ACC,))
    spectra = []
    for s in reading.steps:
        if s.steady_from is None:
            continue
        sel = ok & (acc.time >= s.steady_from) & (acc.time < s.end)
        idx = np.flatnonzero(sel)
        if idx.size < 64:
            continue
        runs = np.split(idx, np.flatnonzero((np.diff(idx) != 1) | (np.diff(acc.index[idx]) != 1)) + 1)
        run = max(runs, key=len)
        if run.size < 64:
            continue
        nper = min(run.size, int(round(seconds_per_segment * acc.rate)))
        f, p = welch(acc.values[run], fs=acc.rate, nperseg=nper)
        spectra.append({"step": s.number, "label": f"step {s.number}: {s.setpoint:g} Hz", "frequency": f, "psd": p,
                        "motor_hz": s.setpoint, "seconds": run.size / acc.rate})
    return spectra


def format_steps(rows: list[dict]) -> list[str]:
    """The step table as text lines."""
    def num(value: float | None, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    verdicts = {True: "yes", False: "NO", None: "-"}
    lines = [f"{'step':>4} {'f (Hz)':>7} {'steady (s)':>10} {'F_i events (N)':>15} {'F_i force (N)':>14} "
             f"{'impacts/cycle':>13} {'settled':>7}"]
    for r in rows:
        lines.append(f"{r['step']:>4} {r['frequency_hz']:>7.3f} {r['steady_seconds']:>10.2f} "
                     f"{num(r['peak_force_events_n'], '15.2f')} {num(r['peak_force_channel_n'], '14.2f')} "
                     f"{num(r['impacts_per_cycle_events'], '13.3f')} {verdicts[r.get('settled')]:>7}")
    unsettled = [f"{r['frequency_hz']:g} Hz" for r in rows if r.get("settled") is False]
    if unsettled:
        lines.append(f"NOT SETTLED: {', '.join(unsettled)}: the two halves of the steady window differ (impacts "
                     "per cycle or peak force); the step still held a transient, or the motion is not periodic "
                     "(a longer --dwell or --settle tells which)")
    return lines


def format_counts(imp: dict) -> str:
    """The cross-check counts as one line whose parts add up to the totals."""
    below = f" ({imp['misses_below_threshold']} below the threshold)" if imp.get("misses_below_threshold") else ""
    after = imp.get("detected_after_events_end") or 0
    return (f"impacts: {imp['events']} events = {imp['matches']} matched + {imp['misses']} missed{below} + "
            f"{imp['not_covered']} not covered by the force channel; {imp['detected']} detected in the force channel "
            f"= {imp['matches']} matched + {imp['extras']} extras"
            + (f" + {after} after the recorded events end" if after else ""))


def format_report(summary: dict) -> list[str]:
    """The lines ``rimd analyze`` prints: the step table, the counts, warnings, left-out windows, faults, loss."""
    from rimd_sim.analysis.recordings.faultreport import format_fault_report

    lines = format_steps(summary["steps"])
    lines.append(format_counts(summary["impacts"]))
    lines += summary.get("warnings", [])
    windows = summary.get("excluded_windows") or []
    if windows:
        from rimd_sim.analysis.recordings.reading import CHANNEL_OF_TOPIC

        lines.append(f"left out ({len(windows)} windows, s from the recording's first stamp): " + "; ".join(
            f"{CHANNEL_OF_TOPIC.get(w['topic'], w['topic'])} {w['kind']} {w['start_s']:.3f}-{w['end_s']:.3f} s "
            f"({w['source']})" for w in windows))
    lines += format_fault_report(summary.get("faults") or {"faults": [], "channels": {}})
    text = rec.loss_text(summary["loss"])
    if text:
        lines.append(f"LOSS: {text}")
    return lines


def _event_index(events: dict[str, np.ndarray], i: int) -> int | None:
    return int(events["index"][i]) if i >= 0 else None


def _at(columns: dict[str, np.ndarray], name: str, i: int) -> float | None:
    return float(columns[name][i]) if i >= 0 else None
