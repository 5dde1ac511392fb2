"""The fault part of ``rimd analyze``: what the data shows, and the captures' peaks.

What the data alone shows, beside what ``/rig/faults`` says happened, and the peak force of the triggered
captures against the 20 kHz channel's.

Times are simulation time (s): ``first_index / sample_rate`` for the channels, the requested ``start`` for
the fault events, the trigger stamp's offset from the capture's sample 0 for captures. The scan is
:mod:`rimd_sim.analysis.recordings.faultscan` on each channel in the order the recorder wrote its blocks (arrival
times are unknown in a recording, so a delay shows only where it put blocks out of order).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rimd_sim.analysis.recordings.faultscan import Block, drift_fit, drift_window, impact_times, scan_channel
from rimd_sim.io.decode import topic_decoder

__all__ = ["CHANNEL_TOPICS", "fault_report", "format_fault_report"]

CHANNEL_TOPICS = {
    "/rig/cart/displacement": "cart_displacement",
    "/rig/rimd/displacement": "rimd_displacement",
    "/rig/rimd/acceleration": "rimd_acceleration",
    "/rig/impact/force": "impact_force",
}
FAULTS = "/rig/faults"
CAPTURE_FORCE = "/rig/capture/force"


def fault_report(recording, detected_peaks: np.ndarray, detected_times_s: np.ndarray,
                 origin_ns: int) -> dict:
    """The report of a :class:`~rimd_sim.io.reader.Recording` (see the module docstring).

    Args:
        recording: The open recording.
        detected_peaks: Peak force of each impact detected in the 20 kHz channel (N).
        detected_times_s: Their peak times (s from ``origin_ns``).
        origin_ns: The analysis's time origin (ns).
    """
    blocks: dict[str, list[Block]] = {t: [] for t in CHANNEL_TOPICS}
    meta: dict[str, tuple[float, float, float]] = {}
    zero_ns: dict[str, int] = {}   # per channel: the stamp of its sample 0 (ns)
    events, captures = [], []
    types = {**dict.fromkeys(CHANNEL_TOPICS, "rimd_msgs/msg/SampleBlock"), FAULTS: "rimd_msgs/msg/FaultEvent",
             CAPTURE_FORCE: "rimd_msgs/msg/Capture"}
    decoders: dict[str, Any] = {}
    for msg in recording.messages(list(types)):
        if msg.type_name and msg.type_name != types[msg.topic]:
            continue    # another type under a rig topic name: the main analysis reports it
        try:
            decoder = decoders.get(msg.topic)
            if decoder is None:
                decoder = decoders[msg.topic] = topic_decoder(recording.topics.get(msg.topic), types[msg.topic])
            m = decoder(msg.data)
            stamp_ns = int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec)
            if msg.topic in CHANNEL_TOPICS:
                block = Block(int(m.first_index), np.asarray(m.samples, float), int(m.saturated_count))
                channel_meta = (m.sample_rate, m.range_min, m.range_max)
                blocks[msg.topic].append(block)
                meta.setdefault(msg.topic, channel_meta)
                if msg.topic not in zero_ns and m.sample_rate > 0:
                    zero_ns[msg.topic] = stamp_ns - round(int(m.first_index) * 1e9 / m.sample_rate)
            elif msg.topic == FAULTS:
                events.append({"event": m.event, "id": m.id, "channel": m.channel, "kind": m.kind,
                               "start_s": m.start, "duration_s": m.duration, "magnitude": m.magnitude,
                               "detail": m.detail})
            else:
                captures.append((stamp_ns, m.samples, m.sample_rate))
        except Exception:  # noqa: BLE001 - damaged bytes, no definition: the main analysis counts them
            continue
    report: dict = {"channels": {}, "faults": events, "drift": None, "captures": None}
    for topic, bl in blocks.items():
        if not bl:
            continue
        rate, lo, hi = meta[topic]
        # the force channel's impacts in this channel's own time (index / rate)
        impacts = np.sort(np.asarray(detected_times_s, dtype=float) - (zero_ns.get(topic, origin_ns) - origin_ns)
                          * 1e-9) if topic != "/rig/impact/force" else None
        report["channels"][CHANNEL_TOPICS[topic]] = [
            {"kind": f.kind, "start_s": f.start, "end_s": f.end, "detail": f.detail}
            for f in scan_channel(bl, rate, lo, hi, impacts=impacts)]
    force, acc = "/rig/impact/force", "/rig/rimd/acceleration"
    if blocks[force] and blocks[acc]:
        t_acc = impact_times(blocks[acc], meta[acc][0], 200.0, absolute=True)
        t_force = impact_times(blocks[force], meta[force][0], 20.0)
        t, lag = drift_fit(t_acc, t_force)
        window = drift_window(t, lag, meta[force][0])
        if window is not None:
            report["drift"] = {"channel": "impact_force", "against": "rimd_acceleration", "start_s": window[0],
                               "end_s": window[1] if np.isfinite(window[1]) else None, "ppm": window[2] * 1e6,
                               "impacts_paired": int(t.size)}
        elif t.size:
            report["drift"] = {"channel": "impact_force", "against": "rimd_acceleration", "start_s": None,
                               "end_s": None, "ppm": 0.0, "impacts_paired": int(t.size),
                               "lag_s_max": float(np.max(np.abs(lag - np.median(lag))))}
    if captures:
        rows = []
        for stamp_ns, samples, _ in captures:
            trig = (stamp_ns - origin_ns) * 1e-9
            peak = float(np.max(samples)) if len(samples) else float("nan")
            k = int(np.argmin(np.abs(detected_times_s - trig))) if detected_times_s.size else -1
            near = k >= 0 and abs(detected_times_s[k] - trig) < 0.002
            rows.append((trig, peak, float(detected_peaks[k]) if near else float("nan")))
        arr = np.array(rows)
        low = (1.0 - arr[:, 2] / arr[:, 1]) * 100.0
        ok = np.isfinite(low)
        report["captures"] = {"count": len(captures), "sample_rate": captures[0][2],
                              "matched": int(ok.sum()),
                              "channel_low_percent_mean": float(low[ok].mean()) if ok.any() else None,
                              "channel_low_percent_max": float(low[ok].max()) if ok.any() else None,
                              "channel_low_percent_min": float(low[ok].min()) if ok.any() else None,
                              "capture_peak_n_max": float(np.nanmax(arr[:, 1]))}
    return report


def format_fault_report(report: dict) -> list[str]:
    """The report as text lines (nothing when the recording holds no fault, finding or capture).

    Their times are simulation time (a fault's own start, a channel's ``first_index / rate``), which each line
    says: the analysis's other lines count from the recording's first stamp.
    """
    lines = []
    starts = [f for f in report["faults"] if f["event"] == "start"]
    if starts:
        lines.append(f"faults (/rig/faults, simulation time): {len(starts)} started, "
                     f"{sum(1 for f in report['faults'] if f['event'] == 'end')} ended: "
                     + "; ".join(f"{f['kind']} on {f['channel']} from {f['start_s']:.3f} s"
                                 + (f" for {f['duration_s']:g} s" if f["duration_s"] else " until cleared")
                                 for f in starts))
    for channel, findings in report["channels"].items():
        if findings:
            lines.append(f"seen in the data, {channel} (simulation time): " + "; ".join(
                f"{f['kind']} {f['start_s']:.3f}-{f['end_s']:.3f} s ({f['detail']})" for f in findings))
    drift = report.get("drift")
    if drift and drift.get("start_s") is not None:
        end = "still drifting at the end" if drift["end_s"] is None else f"to {drift['end_s']:.3f} s"
        lines.append(f"clock drift seen in the data (simulation time): {drift['channel']} against {drift['against']}: "
                     f"{drift['ppm']:+.1f} ppm from {drift['start_s']:.3f} s {end} "
                     f"({drift['impacts_paired']} impacts)")
    cap = report.get("captures")
    if cap:
        if cap["matched"]:
            lines.append(f"captures: {cap['count']} at {cap['sample_rate'] / 1e6:g} MHz; the 20 kHz channel's peak "
                         f"force is {cap['channel_low_percent_min']:.1f} to {cap['channel_low_percent_max']:.1f} % "
                         f"below the capture's (mean {cap['channel_low_percent_mean']:.1f} %, "
                         f"{cap['matched']} impacts)")
        else:
            lines.append(f"captures: {cap['count']} at {cap['sample_rate'] / 1e6:g} MHz; none matched an impact of "
                         "the 20 kHz channel")
    return lines
