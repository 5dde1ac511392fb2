"""One reading of a recording, shared by ``rimd analyze`` and ``rimd identify``'s validation.

:func:`read` turns a :class:`~rimd_sim.analysis.recordings.recorded.RecordedData` into a :class:`Reading`: the
impacts detected in the force channel (:func:`~rimd_sim.analysis.recordings.recorded.detect_impacts`), their
cross-check with the recorded events, the motor's dwell steps, the step table (steady peak force and impacts per
cycle, from the events and from the force channel) and the windows of the recording that no analysis should trust
(:func:`excluded_windows`): holes in ``first_index`` (dropouts, lost blocks), what the data alone shows
(:func:`rimd_sim.analysis.recordings.faultscan.scan_channel`: stuck, rail, saturated, outliers, level, noise, late
blocks), and the faults named on ``/rig/faults``.

``rimd analyze`` prints that step table; ``rimd identify`` compares the twin with the same table of the same
recording (and reads the twin's simulated channels with the same function), so the two commands cannot give
two answers for one recording.

The force channel's columns of the step table leave the force channel's excluded windows out: an impact
inside one is not counted, and neither are the cycles the window covers (impacts per cycle over the part of
the steady window the sensor saw).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rimd_sim.analysis.recordings import recorded as rec
from rimd_sim.analysis.recordings.contact_pulse import SpringDashpotPulse

__all__ = ["Reading", "Window", "excluded_windows", "keep_mask", "read", "step_rows"]

#: Channel names of ``/rig/faults`` and of the fault scan, per topic.
CHANNEL_OF_TOPIC = {rec.CART_X: "cart_displacement", rec.RIMD_X: "rimd_displacement",
                    rec.ACC: "rimd_acceleration", rec.FORCE: "impact_force"}
TOPIC_OF_CHANNEL = {v: k for k, v in CHANNEL_OF_TOPIC.items()}
#: Fault kinds whose effect outlasts the fault: the channel's clock keeps its offset (docs/faults.md).
LASTING = ("clock_drift",)


@dataclass(frozen=True)
class Window:
    """A stretch of one channel (or of the motor) not to be trusted: where, what, and who said so.

    ``topic`` is the channel's topic or ``"motor"``; ``start`` and ``end`` are s from the recording's origin;
    ``source`` is ``"data"`` (seen in the data) or ``"/rig/faults"`` (named by the rig).
    """

    topic: str
    kind: str
    start: float
    end: float
    source: str
    detail: str = ""

    def as_dict(self) -> dict:
        """JSON-ready."""
        return {"topic": self.topic, "kind": self.kind, "start_s": self.start, "end_s": self.end,
                "source": self.source, "detail": self.detail}

    def describe(self) -> str:
        """One phrase: ``impact_force dropout 18.900-19.200 s (/rig/faults)``."""
        name = CHANNEL_OF_TOPIC.get(self.topic, self.topic)
        return f"{name} {self.kind} {self.start:.3f}-{self.end:.3f} s ({self.source})"


def excluded_windows(data: rec.RecordedData, scan: dict | None) -> list[Window]:
    """The windows of ``data`` to leave out (see the module doc), in recording time.

    ``scan``: the fault report of :func:`rimd_sim.analysis.recordings.faultreport.fault_report` (its channel findings
    are in each channel's own time ``first_index / rate``); None: holes and ``/rig/faults`` only.
    """
    windows: list[Window] = []
    end_all = max([float(c.time[-1]) for c in data.channels.values() if c.time.size] + [0.0])
    for topic, channel in data.channels.items():
        if channel.index.size == 0:
            continue
        dt = 1.0 / channel.rate
        # holes in first_index: from the last sample received to the next one
        for a, b in zip(channel.segments()[:-1], channel.segments()[1:], strict=True):
            windows.append(Window(topic, "gap", float(channel.time[a.stop - 1]) + dt, float(channel.time[b.start]),
                                  "data", f"{int(channel.index[b.start] - channel.index[a.stop - 1] - 1)} samples "
                                  "missing in first_index"))
        if scan:
            offset = float(channel.time[0]) - float(channel.index[0]) / channel.rate
            for finding in scan.get("channels", {}).get(CHANNEL_OF_TOPIC.get(topic, ""), []):
                if finding["kind"] == "gap":
                    continue   # from first_index above, with the samples' own times
                windows.append(Window(topic, finding["kind"], finding["start_s"] + offset, finding["end_s"] + offset,
                                      "data", finding.get("detail", "")))
    # The rig's own word: start and end events of /rig/faults (an unended fault runs to the end).
    starts = {}
    for event in data.fault_events:
        if event["event"] == "start":
            starts[event["id"]] = event
        elif event["event"] == "end" and event["id"] in starts:
            s = starts.pop(event["id"])
            end = end_all if s["kind"] in LASTING else event["time"]
            windows.append(_named(s, end))
    for s in starts.values():
        windows.append(_named(s, end_all))
    return sorted(windows, key=lambda w: (w.start, w.topic, w.kind))


def _named(start: dict, end: float) -> Window:
    channel = start["channel"]
    topic = TOPIC_OF_CHANNEL.get(channel, channel)
    return Window(topic, start["kind"], float(start["time"]), float(max(end, start["time"])), "/rig/faults",
                  start.get("detail", ""))


def keep_mask(times: np.ndarray, windows: list[Window], topics: tuple[str, ...], margin: float = 0.0) -> np.ndarray:
    """True where ``times`` lie outside every window of ``topics`` (and of the motor), widened by ``margin``."""
    keep = np.ones(times.shape, dtype=bool)
    for w in windows:
        if w.topic in topics or w.topic == "motor":
            keep &= ~((times >= w.start - margin) & (times <= w.end + margin))
    return keep


def _cycles(lo: float, hi: float, frequency: float, windows: list[Window]) -> float:
    """Excitation cycles in ``[lo, hi)`` outside the force channel's windows."""
    covered = hi - lo
    spans = sorted((max(w.start, lo), min(w.end, hi)) for w in windows if w.end > lo and w.start < hi)
    last = lo
    for a, b in spans:
        a = max(a, last)
        if b > a:
            covered -= b - a
            last = b
    return max(covered, 0.0) * frequency


def step_rows(steps: list[rec.Step], events: dict[str, np.ndarray], detected: dict[str, np.ndarray],
              force: rec.Channel | None, windows: list[Window]) -> list[dict]:
    """Per step: steady peak force, its spread, and impacts per cycle from the events and the force channel.

    The force channel's impacts inside its excluded windows (a hole hides impacts, a spike fault makes false
    ones) are left out, and so are the cycles those windows cover. ``settled``: whether the step had settled
    (:func:`~rimd_sim.analysis.recordings.recorded.settled`, from the events, else the force channel). Per source the
    largest peak (``peak_force_{source}_n``, the paper's reading) and the mean, standard deviation and smallest
    of the steady window's peaks.
    """
    force_windows = [w for w in windows if w.topic in (rec.FORCE, "motor")]
    ok = keep_mask(detected["start"], force_windows, (rec.FORCE,), 1e-3) if detected["start"].size else \
        np.zeros(0, dtype=bool)
    rows = []
    for s in steps:
        row = {"step": s.number, "frequency_hz": s.setpoint, "start_s": s.start, "ramp_end_s": s.ramp_end,
               "steady_from_s": s.steady_from, "end_s": s.end, "steady_seconds": s.steady_seconds}
        verdict = None
        if s.steady_from is not None:
            times, peaks = events.get("time"), events.get("peak_force")
            if (times is None or times.size == 0) and detected["start"].size:   # no events recorded
                times, peaks = detected["start"][ok], detected["peak_force"][ok]
            if times is not None and peaks is not None:   # the event columns come together
                verdict = rec.settled(times, peaks, s.steady_from, s.end, s.setpoint)
        row["settled"] = verdict
        for label, times, peaks in (("events", events.get("time"), events.get("peak_force")),
                                    ("channel", detected["start"][ok], detected["peak_force"][ok])):
            keys = (f"peak_force_{label}_n", f"impacts_{label}", f"impacts_per_cycle_{label}",
                    f"peak_force_{label}_mean_n", f"peak_force_{label}_std_n", f"peak_force_{label}_min_n")
            if s.steady_from is None or times is None or peaks is None or (label == "channel" and force is None):
                row.update(dict.fromkeys(keys))
                if label == "channel":
                    row["peak_force_channel_largest_sample_n"] = None
                continue
            sel = (times >= s.steady_from) & (times < s.end)
            cycles = (s.steady_seconds * s.setpoint if label == "events"
                      else _cycles(s.steady_from, s.end, s.setpoint, force_windows))
            chosen = peaks[sel]
            row[keys[0]] = float(chosen.max()) if chosen.size else 0.0
            if label == "channel":
                raw = detected["peak_force_sample"][ok]
                row["peak_force_channel_largest_sample_n"] = float(raw[sel].max()) if sel.any() else 0.0
            row[keys[1]] = int(sel.sum())
            row[keys[2]] = float(sel.sum() / cycles) if cycles > 0 else None
            row[keys[3]] = float(chosen.mean()) if chosen.size else None
            row[keys[4]] = float(chosen.std(ddof=1)) if chosen.size > 1 else None
            row[keys[5]] = float(chosen.min()) if chosen.size else None
        rows.append(row)
    return rows


@dataclass
class Reading:
    """What :func:`read` found in a recording (times in s from its origin)."""

    data: rec.RecordedData
    threshold: float
    settle: float
    pulse: SpringDashpotPulse | None
    detected: dict[str, np.ndarray]
    match: dict
    steps: list[rec.Step]
    rows: list[dict]
    windows: list[Window] = field(default_factory=list)
    faults: dict = field(default_factory=dict)
    stop: float | None = None   # the schedule's end, when the recording names it and reaches it (rec.stop_time)

    def windows_text(self) -> str | None:
        """One line naming every window left out, or None."""
        if not self.windows:
            return None
        return "; ".join(w.describe() for w in self.windows)


EMPTY_DETECTION = ("start", "peak_time", "peak_force", "peak_force_sample", "fitted", "duration", "impulse",
                   "complete")


def read(data: rec.RecordedData, *, threshold: float = rec.DEFAULT_THRESHOLD, settle: float = 2.0,
         pulse: SpringDashpotPulse | None = None, scan: bool = True) -> Reading:
    """Read ``data``: impacts, cross-check, steps, step table, excluded windows (see the module doc).

    Args:
        data: A loaded recording (:func:`rimd_sim.analysis.recordings.recorded.load`).
        threshold: Impact detection threshold on the force (N).
        settle: Seconds after each motor step before its steady state is read.
        pulse: The contact pulse the peaks are read with at the contact onset (None: the largest sample).
        scan: Scan the channels for faults in the data (a second pass over the recording).

    Returns:
        The impacts detected and matched, the steps and their table, the windows left out.
    """
    from rimd_sim.analysis.recordings.faultreport import fault_report

    force = data.channels.get(rec.FORCE)
    empty = np.empty(0)
    detected = rec.detect_impacts(force, threshold, pulse) if force is not None else dict.fromkeys(
        EMPTY_DETECTION, empty)
    events = data.events
    match = rec.match_impacts(detected, events, force, threshold)
    faults = fault_report(data.recording, detected["peak_force_sample"], detected["peak_time"], data.origin_ns) \
        if scan and data.recording is not None else {}
    windows = excluded_windows(data, faults or None)
    stop = rec.stop_time(data, detected, match["detected_match"])
    steps = rec.segment_steps(data.motor, settle, end=rec.common_end(data, detected, match["detected_match"]),
                              stop=stop)
    rows = step_rows(steps, events, detected, force, windows)
    return Reading(data, threshold, settle, pulse, detected, match, steps, rows, windows, faults, stop)
