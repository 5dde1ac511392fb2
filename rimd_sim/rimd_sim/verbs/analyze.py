"""``rimd analyze REC --out DIR``: analyse a recording alone (see :mod:`rimd_sim.analysis.recorded`).

Writes into DIR: ``impacts_detected.csv`` (impacts found in ``/rig/impact/force``, with the matching event),
``impact_events.csv`` (the recorded events, with the matching detection), ``steps.csv`` (per dwell step of the
motor: steady peak force and impacts per cycle, from the events and from the force channel),
``poincare.csv``; figures ``peak_force_vs_frequency.png``, ``impacts.png``, ``phase_planes.png``; and
``summary.json`` (what was lost, the cross-check counts, the steps). A damaged recording is analysed as far as
it is readable and the loss is reported; a file that is not a recording is refused in one line (exit 1).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rimd_sim.cli import nonnegative_float, positive_float


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd analyze``."""
    parser.add_argument("recording", type=Path, help="a recording directory or one .mcap file")
    parser.add_argument("--out", type=Path, default=Path("analysis"), help="output directory (default: analysis)")
    parser.add_argument("--settle", type=nonnegative_float("--settle", "s"), default=2.0,
                        help="seconds discarded at the start of each dwell step, after the motor reached its "
                             "setpoint (default 2.0)")
    parser.add_argument("--threshold", type=positive_float("--threshold", "N"), default=2.0,
                        help="force threshold (N) above which a run of force samples is one impact (default 2.0)")
    parser.add_argument("--peak", choices=("onset-fit", "sample"), default="onset-fit",
                        help="peak of each sampled impact: 'onset-fit' fits the spring-dashpot contact pulse "
                             "(when the recording's rig parameters give that law) and reads its peak; 'sample' "
                             "takes the largest sample (the paper's raw reading). Default onset-fit")


def main(args: argparse.Namespace) -> int:
    """Run the analysis; print the step table and where the results are."""
    from rimd_sim.cli import CommandError
    from rimd_sim.verbs._analysis_io import check_positive

    check_positive("--settle", args.settle, inclusive=True)
    check_positive("--threshold", args.threshold)
    from rimd_sim.recording.reader import RecordingError

    try:
        summary = analyze(args.recording, args.out, settle=args.settle, threshold=args.threshold,
                          peak=args.peak, log=_log)
    except RecordingError as exc:
        raise CommandError(str(exc)) from None
    print_report(summary)
    print(f"results in {args.out}")
    return 0


def print_report(summary: dict) -> None:
    """Print the step table, the cross-check counts and, when anything was lost, a LOSS line."""
    for line in format_steps(summary["steps"]):
        print(line)
    imp = summary["impacts"]
    print(f"impacts: {imp['events']} events, {imp['detected']} detected in the force channel; "
          f"{imp['matches']} matches, {imp['misses']} misses, {imp['extras']} extras"
          + (f"; {imp['detected_after_events_end']} detected after the recorded events end"
             if imp.get("detected_after_events_end") else ""))
    from rimd_sim.analysis.faultreport import format_fault_report

    for line in format_fault_report(summary.get("faults") or {"faults": [], "channels": {}}):
        print(line)
    from rimd_sim.analysis.recorded import loss_text

    text = loss_text(summary["loss"])
    if text:
        print(f"LOSS: {text}")


def _log(text: str) -> None:
    print(f"rimd analyze: {text}", file=sys.stderr, flush=True)


def format_steps(rows: list[dict]) -> list[str]:
    """The step table as text lines."""
    def num(value, fmt):  # noqa: ANN001
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


def analyze(recording: Path, out: Path, *, settle: float = 2.0, threshold: float = 2.0,  # noqa: ANN001
            peak: str = "onset-fit", log=None) -> dict:
    """Analyse ``recording`` into ``out``; return the summary (also written as ``summary.json``).

    Raises:
        rimd_sim.recording.reader.RecordingError: Not a recording at all.
        rimd_sim.cli.CommandError: The recording holds none of the topics analysed.
    """
    import numpy as np

    from rimd_sim.analysis import plots
    from rimd_sim.analysis import recorded as rec
    from rimd_sim.cli import CommandError
    from rimd_sim.verbs._analysis_io import write_csv, write_summary

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
        raise CommandError(f"{recording} holds none of the rig topics analysed ({', '.join(wanted)}); found: {found}"
                           + (f" (the recording is damaged: {damage})" if damage else ""))
    out.mkdir(parents=True, exist_ok=True)

    force = data.channels.get(rec.FORCE)
    empty = np.empty(0)
    pulse = rec.pulse_model(data.recording.metadata) if peak == "onset-fit" else None
    if peak == "onset-fit":
        log("peaks: fitted spring-dashpot pulse at contact onset" if pulse is not None else
            "peaks: largest sample (the recording's contact law is not spring_dashpot or its parameters are missing)")
    detected = rec.detect_impacts(force, threshold, pulse) if force is not None else {
        k: empty for k in ("start", "peak_time", "peak_force", "peak_force_sample", "fitted", "duration", "impulse",
                           "complete")}
    events = data.events
    match = rec.match_impacts(detected, events, force, threshold)
    steps = rec.segment_steps(data.motor, settle, end=rec.common_end(data, detected, match["detected_match"]))
    rows = rec.step_table(steps, events, detected, force)
    log(f"{len(detected['peak_time'])} impacts detected, {events['time'].size} events, {len(steps)} steps")

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
    write_csv(out / "steps.csv", rows)

    # Phase planes and Poincare maps over each step's steady window.
    panels, poincare_rows = [], []
    rimd, cart = data.channels.get(rec.RIMD_X), data.channels.get(rec.CART_X)
    if rimd is not None and cart is not None:
        t, x, v = rec.phase_plane(rimd, cart)
        strobe = rec.poincare_points(t, x, v, rec.poincare_times(data.motor))
        windows = [(s, s.steady_from, s.end) for s in steps if s.steady_from is not None]
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
                poincare_rows.append({"step": step.number if step else 0,
                                      "frequency_hz": step.setpoint if step else None,
                                      "time_s": tp, "x_rel_m": xp, "velocity_m_s": vp})
        plots.plot_recorded_phase_planes(panels, out / "phase_planes.png",
                                         "phase planes (RIMD relative to cart) and Poincare points, steady windows")
    write_csv(out / "poincare.csv", poincare_rows)
    plots.plot_recorded_peaks(rows, out / "peak_force_vs_frequency.png",
                              f"steady peak force per step ({recording.name})")
    plots.plot_recorded_impacts(events["time"], events["peak_force"], detected["peak_time"], detected["peak_force"],
                                steps, out / "impacts.png", "impacts over time (steady windows shaded)")

    from rimd_sim.analysis.faultreport import fault_report

    # Faults (issue 12): what the data alone shows beside /rig/faults; captures against the channel's raw peak.
    faults = fault_report(data.recording, detected["peak_force_sample"], detected["peak_time"], data.origin_ns)
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
        "steps": rows,
        "poincare_points": len(poincare_rows),
        "figures": sorted(p.name for p in out.glob("*.png")),
        "faults": faults,
        "wall_seconds": time.perf_counter() - start,
    }
    write_summary(out, summary)
    return summary


def _event_index(events, i):  # noqa: ANN001
    return int(events["index"][i]) if i >= 0 else None


def _at(columns, name, i):  # noqa: ANN001
    return float(columns[name][i]) if i >= 0 else None


