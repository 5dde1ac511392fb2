"""Analyses of a recording alone (never the simulator's internals): impacts, stepped sweeps, phase planes.

Everything here works on what a recording holds (docs/interface.md, Topics):

* **Impact detection from the sampled force channel** (``/rig/impact/force``), the paper's routine (section
  3: "for each excitation frequency the maximum impact force is detected"): every run of consecutive samples
  at or above a threshold (default 2 N, 200 times the sensor's noise) is one impact; its force peak ``F_i``
  is the largest sample of the run (no interpolation: the paper reads the maximum value), its start the
  threshold crossing (linearly interpolated between samples), its impulse the sum of the run's samples times
  the sample period. A run that touches a hole in the data (lost blocks, the start or end of the recording)
  is flagged ``complete = False``.
* **Peak at contact onset (spring-dashpot law).** With the default contact law the force jumps to ``c v0``
  at contact start and then may fall (``dF/dt = v0 (k - c^2/m) < 0`` for the default hammer), by up to 18 %
  within one 50 us sample: the largest sample of a 0.37 ms contact is 0-18 % below the true peak. When the
  recording's metadata (``rimd_rig_parameters``) says ``spring_dashpot`` and gives ``mass``, ``contact.stiffness``
  and ``contact.damping``, each complete run is fitted with the law's pulse
  (:class:`~rimd_sim.analysis.recordings.contact_pulse.SpringDashpotPulse`, the one pulse of the analyses and of
  ``rimd identify``, for any damping of the contact): the onset between the last sample before the contact
  and the first in it, the scale linear, and the peak read off the fitted pulse; a fit that fails falls back
  to the largest sample. A contact so damped that its largest sample can be below 70 % of its peak (the force
  falls from ``c v0`` within one sample: ``c / 2 sqrt(k m)`` above ~1 at 20 kHz) is read by its largest sample
  too: its peak would be an extrapolation the samples barely hold (the 1 MHz captures resolve it).
  ``peak_force`` is that estimate, and ``peak_force_sample`` the largest sample (the paper's raw reading) for
  comparison.
* **Cross-check** with the recorded ``/rig/impact/events``: an event (contact start ``t``, duration ``d``)
  matches the first unmatched detection whose peak lies in ``[t - 2/rate, t + d + 2/rate]``. Events without
  a detection are misses (split into below-threshold ones and others), detections without an event extras;
  events outside the force channel's recorded samples are "not covered", not misses.
* **Stepped sweeps**: ``/rig/motor/state`` is cut into steps of constant ``frequency_setpoint``. Each step's
  ramp ends when the actual ``frequency`` reaches the setpoint; ``settle`` seconds after that are discarded
  and the rest of the step is the steady window, over which the steady peak force (largest peak, as the
  paper and :mod:`rimd_sim.analysis.dynamics.sweep` read it) and the impacts per cycle are taken, both from the
  events and from the force channel.
* **Phase plane**: RIMD displacement relative to the cart (``/rig/rimd/displacement`` minus
  ``/rig/cart/displacement``, both inertial lasers at 2 kHz) versus its velocity, a Savitzky-Golay derivative
  (cubic, 21 samples = 10.5 ms at 2 kHz, which keeps the laser noise's derivative small and still follows
  an impact's velocity reversal within a few samples).
* **Poincare map**: one point per excitation cycle, at motor phase 0: the instants where the unwrapped
  motor phase ``2 pi cycle_index + phase`` crosses a multiple of ``2 pi``, linearly interpolated between
  motor states (exact at constant frequency), the phase-plane coordinates interpolated there.

Times are seconds relative to the recording's earliest stamp (``origin_ns``); stamps are simulation time.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from rimd_sim.analysis.recordings.contact_pulse import PulseSamples, SpringDashpotPulse, pulse_of, pulse_peaks
from rimd_sim.errors import AnalysisError
from rimd_sim.io.decode import topic_decoder
from rimd_sim.io.msgdefs import MessageDefinitionError
from rimd_sim.io.reader import Recording, open_recording
from rimd_sim.settings.recording import LOSS_METADATA, STOP_METADATA

FORCE = "/rig/impact/force"
EVENTS = "/rig/impact/events"
MOTOR = "/rig/motor/state"
RIMD_X = "/rig/rimd/displacement"
CART_X = "/rig/cart/displacement"
ACC = "/rig/rimd/acceleration"
FAULTS = "/rig/faults"
CAPTURE_FORCE = "/rig/capture/force"
SESSION = "/rig/session"
#: ``/rig/session`` reasons that start every channel's ``first_index`` from 0 again (a reset lets them go on).
_COUNT_FROM_ZERO = ("start", "replay")
BLOCK_TOPICS = (FORCE, RIMD_X, CART_X, ACC)
#: The message type of each topic the analyses read.
EXPECTED_TYPES = {**{topic: "rimd_msgs/msg/SampleBlock" for topic in BLOCK_TOPICS},
                  EVENTS: "rimd_msgs/msg/ImpactEvent", MOTOR: "rimd_msgs/msg/MotorState",
                  FAULTS: "rimd_msgs/msg/FaultEvent", CAPTURE_FORCE: "rimd_msgs/msg/Capture"}

#: Default detection threshold of the force channel (N).
DEFAULT_THRESHOLD = 2.0

__all__ = [
    "Channel", "RecordedData", "Step", "load", "pulse_model", "detect_impacts", "match_impacts",
    "common_end", "stop_time", "segment_steps", "settled", "phase_plane", "poincare_times", "poincare_points",
]


@dataclass
class Channel:
    """A sampled channel: sample indices, times (s from the origin) and values, with its holes."""

    topic: str
    rate: float
    index: np.ndarray
    time: np.ndarray
    values: np.ndarray
    lost_samples: int = 0
    lost_blocks: int = 0

    def segments(self) -> list[slice]:
        """Slices of consecutive samples (split at every hole of the index)."""
        if self.index.size == 0:
            return []
        cuts = np.flatnonzero(np.diff(self.index) != 1) + 1
        bounds = [0, *cuts.tolist(), self.index.size]
        return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


@dataclass
class RecordedData:
    """The decoded content of a recording that the analyses use."""

    path: Path
    recording: Recording
    origin_ns: int
    channels: dict[str, Channel] = field(default_factory=dict)
    events: dict[str, np.ndarray] = field(default_factory=dict)
    motor: dict[str, np.ndarray] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    undecodable: dict[str, int] = field(default_factory=dict)
    wrong_type: dict[str, dict] = field(default_factory=dict)
    #: ``/rig/faults``: one dict per event (``event``, ``id``, ``channel``, ``kind``, ``time`` s from the origin,
    #: ``start``, ``duration``, ``magnitude``, ``detail``).
    fault_events: list[dict] = field(default_factory=list)
    #: ``/rig/capture/force``: the triggered 1 MHz captures of the force.
    captures: list[Capture] = field(default_factory=list)

    def loss(self) -> dict:
        """What was lost: unreadable file tails, holes in the sampled channels, undecodable messages.

        ``wrong_type``: the topics recorded with another type than the rig's (recorded and expected type, the
        messages left out). ``recorder``: what the recorder said was lost that the file cannot show (its
        :data:`~rimd_sim.settings.recording.LOSS_METADATA` record: messages the transport declared lost, samples
        missing at the start of a lockstep recording), ``"<topic> <what>": count``.
        """
        reported = self.recording.metadata.get(LOSS_METADATA, {}) if self.recording is not None else {}
        return {
            "complete": self.recording.complete,
            "files": [r.describe() for r in self.recording.reports],
            "lost_samples": {t: c.lost_samples for t, c in self.channels.items() if c.lost_samples},
            "lost_blocks": {t: c.lost_blocks for t, c in self.channels.items() if c.lost_blocks},
            "undecodable_messages": dict(self.undecodable),
            "wrong_type": {t: dict(v) for t, v in self.wrong_type.items()},
            "recorder": {k: int(v) for k, v in reported.items() if str(v).isdigit()},
        }


@dataclass(frozen=True)
class Capture:
    """One triggered capture of the force: times (s from the origin) and values (N) at its own rate."""

    index: int
    rate: float
    trigger: float
    time: np.ndarray
    values: np.ndarray


def loss_text(loss: dict) -> str | None:
    """One line saying what :meth:`RecordedData.loss` found, or None when nothing was lost."""
    if loss["complete"] and not loss["lost_samples"] and not loss["undecodable_messages"] \
            and not loss.get("wrong_type") and not loss.get("recorder"):
        return None
    parts = list(loss["files"])
    if loss["lost_samples"]:
        parts.append(f"lost samples {loss['lost_samples']}")
    if loss.get("recorder"):
        parts.append(f"lost before the file, said by the recorder {loss['recorder']}")
    if loss["undecodable_messages"]:
        parts.append(f"undecodable {loss['undecodable_messages']}")
    parts += [f"{topic} has type {w['recorded_type']}, not {w['expected_type']}: its {w['messages']} messages "
              f"left out" for topic, w in loss.get("wrong_type", {}).items()]
    return "; ".join(parts)


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


_EVENT_FIELDS = ("duration", "peak_force", "impulse", "impact_velocity", "max_penetration", "excitation_frequency",
                 "excitation_phase", "cycle_index", "index")
_MOTOR_FIELDS = ("frequency_setpoint", "frequency", "phase", "cycle_index")
_FAULT_FIELDS = ("event", "id", "channel", "kind", "start", "duration", "magnitude", "detail")


def _block_row(m) -> tuple:  # noqa: ANN001 - a decoded message (rimd_sim.io.decode)
    return _stamp_ns(m.header), int(m.first_index), float(m.sample_rate), np.asarray(m.samples, dtype=float)


def _event_row(m) -> tuple:  # noqa: ANN001
    return _stamp_ns(m.header), *(getattr(m, f) for f in _EVENT_FIELDS)


def _motor_row(m) -> tuple:  # noqa: ANN001
    return _stamp_ns(m.header), *(getattr(m, f) for f in _MOTOR_FIELDS)


def _fault_row(m) -> tuple:  # noqa: ANN001
    return _stamp_ns(m.header), {f: getattr(m, f) for f in _FAULT_FIELDS}


def _capture_row(m) -> tuple:  # noqa: ANN001 - the samples copied out of the message's bytes: few, kept whole
    return (_stamp_ns(m.header), int(m.index), float(m.sample_rate), int(m.pre_trigger_samples),
            np.array(m.samples, dtype=float))


#: What the analyses keep of each topic's messages.
_ROWS = {**{topic: _block_row for topic in BLOCK_TOPICS}, EVENTS: _event_row, MOTOR: _motor_row, FAULTS: _fault_row,
         CAPTURE_FORCE: _capture_row}


def _decoder(recording: Recording, topic: str, expected: str) -> Callable:
    """The decoder of ``topic``'s messages (:mod:`rimd_sim.io.decode`); one that refuses each when there is none."""
    try:
        return topic_decoder(recording.topics.get(topic), expected)
    except MessageDefinitionError as exc:
        reason = str(exc)

        def undecodable(_data: bytes) -> None:
            raise ValueError(reason)
        return undecodable


def load(path: str | Path) -> RecordedData:
    """Open and decode a recording (file or directory); damaged parts are skipped and reported.

    The messages are decoded from the definitions the file carries (:mod:`rimd_sim.io.decode`): no ROS needed.

    Args:
        path: An MCAP file or a rosbag2 directory.

    Returns:
        The channels, events, motor states, faults and captures, with what was lost.

    Raises:
        rimd_sim.io.reader.RecordingError: The path does not exist or is not MCAP at all.
        rimd_sim.errors.AnalysisError: The recording holds several runs of the rig that each count their samples
            from 0 (``/rig/session`` with reason ``start`` or ``replay``: a directory recorded into twice, a
            simulator restarted under one recorder, a looped replay): their samples would be mixed; the
            message lists each run, when it began and its file. A reset within a run is not a new count.
    """
    recording = open_recording(path)
    rows: dict[str, list] = {topic: [] for topic in EXPECTED_TYPES}
    undecodable: dict[str, int] = {}
    wrong_type: dict[str, dict] = {}
    counts: dict[str, int] = {}
    decoders: dict[str, Callable] = {}
    starts: dict[str, tuple[int, str, str]] = {}
    session_decoder = _decoder(recording, SESSION, "rimd_msgs/msg/RigSession")
    for msg in recording.messages([*EXPECTED_TYPES, SESSION]):
        if msg.topic == SESSION:
            try:
                session = session_decoder(msg.data)
            except Exception:  # noqa: BLE001 - a damaged session message says nothing: the data still counts
                continue
            if session.reason in _COUNT_FROM_ZERO:
                starts.setdefault(session.run_id, (msg.log_time, session.reason, msg.path.name if msg.path else ""))
            continue
        expected = EXPECTED_TYPES[msg.topic]
        if msg.type_name and msg.type_name != expected:
            # Another type under a rig topic name: its bytes may well decode as the rig's type (garbage), so
            # the type is checked, not left to the decoder.
            wrong = wrong_type.setdefault(msg.topic, {"recorded_type": msg.type_name, "expected_type": expected,
                                                      "messages": 0})
            wrong["messages"] += 1
            continue
        decoder = decoders.get(msg.topic)
        if decoder is None:
            decoder = decoders[msg.topic] = _decoder(recording, msg.topic, expected)
        try:
            # A definition in the file without a field read here counts as bytes that do not decode.
            row = _ROWS[msg.topic](decoder(msg.data))
        except Exception:  # noqa: BLE001 - damaged bytes inside a readable record: count, do not stop
            undecodable[msg.topic] = undecodable.get(msg.topic, 0) + 1
            continue
        counts[msg.topic] = counts.get(msg.topic, 0) + 1
        rows[msg.topic].append(row)
    if len(starts) > 1:
        raise AnalysisError(_several_runs(Path(path), starts))
    blocks = {topic: rows[topic] for topic in BLOCK_TOPICS}
    events, motor, faults, captures = rows[EVENTS], rows[MOTOR], rows[FAULTS], rows[CAPTURE_FORCE]
    stamps = [b[0][0] for b in blocks.values() if b] + [e[0] for e in events[:1]] + [m[0] for m in motor[:1]]
    origin = min(stamps) if stamps else 0
    data = RecordedData(Path(path), recording, origin, counts=counts, undecodable=undecodable,
                        wrong_type=wrong_type)
    for topic, items in blocks.items():
        if items:
            data.channels[topic] = _channel(topic, items, origin)
    events.sort(key=lambda e: e[0])
    data.events = _columns(events, ("time", *_EVENT_FIELDS), origin)
    motor.sort(key=lambda m: m[0])
    data.motor = _columns(motor, ("time", *_MOTOR_FIELDS), origin)
    data.fault_events = [{**fields, "time": (ns - origin) * 1e-9} for ns, fields in sorted(faults, key=lambda f: f[0])]
    for ns, index, rate, pre, samples in sorted(captures, key=lambda c: c[0]):
        if rate > 0 and samples.size:
            trigger = (ns - origin) * 1e-9
            data.captures.append(Capture(index, rate, trigger, trigger + (np.arange(samples.size) - pre) / rate,
                                         samples))
    return data


def _several_runs(path: Path, starts: dict[str, tuple[int, str, str]]) -> str:
    """Why a recording of several runs of the rig is refused, and what to do instead (one line).

    ``starts``: per run id, the log time (ns) of its first ``/rig/session`` message, its reason and its file.
    """
    runs = []
    for n, (run_id, (log_ns, reason, file)) in enumerate(sorted(starts.items(), key=lambda r: r[1][0]), 1):
        when = (datetime.fromtimestamp(log_ns * 1e-9, UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
                if log_ns > 10**18 else f"log time {log_ns * 1e-9:.3f} s")   # a recorder on simulation time
        runs.append(f"run {n} {run_id[:8]} ({reason}, from {when}{', in ' + file if file else ''})")
    return (f"{path} holds {len(starts)} runs of the rig, each counting its samples from 0: {'; '.join(runs)}. "
            "Their samples would be mixed: analyse one run at a time (give its file, or record each run into "
            "a directory of its own: rimd rig --output-dir DIR)")


def _columns(rows: list[tuple], names: tuple[str, ...], origin: int) -> dict[str, np.ndarray]:
    cols = {name: np.array([r[i] for r in rows], dtype=float) for i, name in enumerate(names)}
    cols["time"] = np.array([(r[0] - origin) * 1e-9 for r in rows], dtype=float)
    return cols


def _channel(topic: str, items: list, origin: int) -> Channel:
    """Samples of a channel in index order; sample n is at ``t_ref + n / rate`` (docs/interface.md, Topics)."""
    items.sort(key=lambda b: b[1])
    stamp0, first0, rate, _ = items[0]
    index_parts, value_parts = [], []
    expected = None
    lost_samples = lost_blocks = 0
    for _, first, _, samples in items:
        if expected is not None and first < expected:   # duplicate or restarted counter: keep the first copy
            continue
        if expected is not None and first > expected:
            lost_samples += first - expected
            lost_blocks += max(1, round((first - expected) / max(samples.size, 1)))
        index_parts.append(np.arange(first, first + samples.size, dtype=np.int64))
        value_parts.append(samples)
        expected = first + samples.size
    index = np.concatenate(index_parts)
    # Integer nanoseconds to the origin first: absolute stamps in float seconds would lose ~0.2 us.
    t_ref = (stamp0 - origin) * 1e-9 - first0 / rate
    return Channel(topic, rate, index, t_ref + index / rate, np.concatenate(value_parts), lost_samples, lost_blocks)


# ---- impacts from the force channel ------------------------------------------------------------------------

def pulse_model(metadata: dict[str, dict[str, str]]) -> SpringDashpotPulse | None:
    """The contact pulse of a recording's rig parameters, or None when the law is not spring-dashpot.

    The pulse of :mod:`rimd_sim.analysis.recordings.contact_pulse` (any damping of the contact), with the hammer's
    ``cos(theta)`` at the gap and the wires' damping ``zeta w_n`` when the parameters give them.
    """
    params = metadata.get("rimd_rig_parameters", {})
    if params.get("contact.model") != "spring_dashpot":
        return None
    try:
        m, k, c = float(params["mass"]), float(params["contact.stiffness"]), float(params["contact.damping"])
    except (KeyError, ValueError):
        return None
    if not (m > 0 and k > 0 and c >= 0):
        return None
    cos_theta, sigma_free = 1.0, 0.0
    try:
        wn = 2 * math.pi * float(params["natural_frequency"])
        length = float(params.get("pendulum_length", 0.0)) or float(params.get("gravity", 9.81)) / wn ** 2
        cos_theta = math.sqrt(max(1.0 - (float(params["gap"]) / length) ** 2, 0.0))
        sigma_free = float(params["damping_ratio"]) * wn
    except (KeyError, ValueError, ZeroDivisionError):
        pass
    return pulse_of(m, k, c, cos_theta=cos_theta, sigma_free=sigma_free)


def force_noise(force: Channel) -> float:
    """Noise of the force channel (N): the robust spread of its samples, which are 0 between impacts."""
    if force.values.size == 0:
        return 0.0
    return float(np.median(np.abs(force.values))) * 1.4826


#: The onset fit reads a peak only where the largest sample is at least this fraction of the pulse's peak at every
#: sampling phase: below it (a strongly overdamped contact, whose force falls from ``c v0`` within a sample) the
#: peak is an extrapolation the samples barely hold.
ONSET_FIT_LIMIT = 0.7


def readable_at(pulse: SpringDashpotPulse, dt: float) -> bool:
    """Whether samples ``dt`` apart determine ``pulse``'s peak (see :data:`ONSET_FIT_LIMIT`)."""
    release = pulse.release()
    peak = pulse.features(1.0)[0]
    worst = min(float(np.max(pulse.shape(np.arange(phase, release, dt)), initial=0.0))
                for phase in np.linspace(0.0, dt, 20, endpoint=False))
    return bool(peak > 0 and worst >= ONSET_FIT_LIMIT * peak)


def detect_impacts(force: Channel, threshold: float = DEFAULT_THRESHOLD,
                   pulse: SpringDashpotPulse | None = None) -> dict[str, np.ndarray]:
    """Impacts of the sampled force signal: one per run of samples ``>= threshold`` (see the module doc).

    Args:
        force: The force channel.
        threshold: Detection threshold (N).
        pulse: The contact pulse, to estimate each peak at contact onset; None: the largest sample.

    Returns:
        Columns ``start`` (s, interpolated threshold crossing), ``peak_time`` (s), ``peak_force`` (N, the
        estimate), ``peak_force_sample`` (N, largest sample), ``fitted`` (1.0 when ``peak_force`` comes from
        the pulse fit), ``duration`` (s above the threshold), ``impulse`` (N s, over the run), ``complete``.
    """
    rows: list[list[float]] = []
    fits: list[tuple[int, PulseSamples]] = []
    dt = 1.0 / force.rate
    quiet = 5.0 * force_noise(force)
    if pulse is not None and not readable_at(pulse, dt):
        pulse = None
    for seg in force.segments():
        v = force.values[seg]
        t = force.time[seg]
        above = v >= threshold
        if not above.any():
            continue
        edges = np.diff(above.astype(np.int8))
        starts = np.flatnonzero(edges == 1) + 1
        ends = np.flatnonzero(edges == -1) + 1
        if above[0]:
            starts = np.r_[0, starts]
        if above[-1]:
            ends = np.r_[ends, v.size]
        for a, b in zip(starts, ends, strict=True):
            k = a + int(np.argmax(v[a:b]))
            if a > 0:   # interpolated crossing between sample a-1 (below) and a (at or above)
                start = t[a - 1] + (threshold - v[a - 1]) / (v[a] - v[a - 1]) * dt
            else:
                start = t[a]
            complete = a > 0 and b < v.size
            if pulse is not None and complete:
                j = a   # the first sample of the contact: back through the samples above the noise
                while j > 1 and a - j < 10 and v[j - 1] > quiet:
                    j -= 1
                if j > 0:
                    lo, hi = j - 1, min(b + 1, v.size)
                    fits.append((len(rows), PulseSamples(t[lo:hi], v[lo:hi], dt, float(t[j - 1]), float(t[j]))))
            rows.append([start, t[k], v[k], v[k], 0.0, (b - a) * dt, float(v[a:b].sum()) * dt, float(complete)])
    if fits and pulse is not None:   # fits are made only with a pulse
        peaks = pulse_peaks(pulse, [p for _, p in fits])
        for (i, _), estimate in zip(fits, peaks, strict=True):
            if np.isfinite(estimate) and estimate >= rows[i][3]:
                rows[i][2], rows[i][4] = float(estimate), 1.0
    names = ("start", "peak_time", "peak_force", "peak_force_sample", "fitted", "duration", "impulse", "complete")
    arr = np.array(rows, dtype=float).reshape(-1, len(names))
    return {name: arr[:, i] for i, name in enumerate(names)}


def _covered(force: Channel | None, times: np.ndarray) -> np.ndarray:
    """True where a time lies inside a stretch of consecutive recorded force samples."""
    covered = np.zeros(times.shape, dtype=bool)
    if force is None:
        return covered
    for seg in force.segments():
        covered |= (times >= force.time[seg][0]) & (times <= force.time[seg][-1])
    return covered


def match_impacts(detected: dict[str, np.ndarray], events: dict[str, np.ndarray], force: Channel | None,
                  threshold: float = DEFAULT_THRESHOLD) -> dict:
    """Cross-check detected impacts with the recorded events (see the module doc).

    Returns:
        ``event_match`` (per event: index of the matching detection or -1), ``detected_match`` (per detection:
        index of the matching event or -1), ``covered`` (per event) and the counts ``matches``, ``misses``,
        ``misses_below_threshold``, ``not_covered``, ``extras``, with the largest and median relative peak
        difference of the matches.
    """
    n_ev = events.get("time", np.empty(0)).size
    n_det = detected["peak_time"].size
    event_match = np.full(n_ev, -1, dtype=int)
    detected_match = np.full(n_det, -1, dtype=int)
    slack = 2.0 / force.rate if force is not None else 0.0
    order = np.argsort(detected["peak_time"])
    peaks = detected["peak_time"][order]
    for i in range(n_ev):
        lo, hi = events["time"][i] - slack, events["time"][i] + events["duration"][i] + slack
        for j in range(np.searchsorted(peaks, lo), np.searchsorted(peaks, hi, side="right")):
            if detected_match[order[j]] < 0:
                detected_match[order[j]] = i
                event_match[i] = order[j]
                break
    covered = _covered(force, events["time"]) if n_ev else np.zeros(0, dtype=bool)
    matched = event_match >= 0
    missed = ~matched & covered
    below = missed & (events["peak_force"] < threshold) if n_ev else missed
    rel = np.abs(detected["peak_force"][event_match[matched]] / events["peak_force"][matched] - 1.0)
    # Detections after the events' stream ended (see events_end) are not extras: no event could match them.
    end = events_end(detected, detected_match, events)
    beyond = (detected_match < 0) & (detected["start"] >= end) if end is not None else np.zeros(n_det, dtype=bool)
    return {
        "event_match": event_match, "detected_match": detected_match, "covered": covered,
        "matches": int(matched.sum()), "misses": int(missed.sum()), "misses_below_threshold": int(below.sum()),
        # An event matched by a detection is matched even where its start lies just outside a stretch of
        # samples: the counts add up, events = matches + misses + not covered.
        "not_covered": int((~covered & ~matched).sum()), "extras": int(((detected_match < 0) & ~beyond).sum()),
        "detected_after_events_end": int(beyond.sum()),
        "peak_difference_max": float(rel.max()) if rel.size else None,
        "peak_difference_median": float(np.median(rel)) if rel.size else None,
    }


# ---- stepped sweeps ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Step:
    """A dwell step of the motor: constant setpoint from ``start`` to ``end``; steady from ``steady_from``."""

    number: int
    setpoint: float
    start: float
    ramp_end: float | None
    steady_from: float | None
    end: float

    @property
    def steady_seconds(self) -> float:
        """Length of the steady window (0 when the step never became steady)."""
        return 0.0 if self.steady_from is None else max(0.0, self.end - self.steady_from)


def common_end(data: RecordedData, detected: dict[str, np.ndarray] | None = None,
               detected_match: np.ndarray | None = None) -> float | None:
    """The time (s from the origin) up to which every recorded stream of the analysis has its data.

    A recorder stops its topics one after the other, and a recorder that lags behind a fast rig holds each
    topic's backlog separately, so the streams of a recording can end at different times. An analysis that
    counts the impact events over a window running to the end of the motor states would count over a tail
    where the events were not recorded (and read a steady 1 impact per cycle as 0.63). The sampled channels
    and the motor states end where they end. The sparse impact events show their end through the force
    channel (``detected`` impacts and their ``detected_match`` with the events, :func:`match_impacts`): an
    impact the force sensor saw after the last recorded event, with no event of its own, is past the end
    of the events' stream.
    """
    ends = [float(c.time[-1]) for c in data.channels.values() if c.time.size]
    t = data.motor.get("time", np.empty(0))
    if t.size:
        ends.append(float(t[-1]))
    if detected is not None and detected_match is not None:
        end = events_end(detected, detected_match, data.events)
        if end is not None:
            ends.append(end)
    return min(ends) if ends else None


def events_end(detected: dict[str, np.ndarray], detected_match: np.ndarray,
               events: dict[str, np.ndarray]) -> float | None:
    """Where the recorded impact events end, when the force channel shows it; else None.

    The start of the first impact that the force sensor saw after the last recorded event with no event of
    its own. A reliable low-rate topic can lag seconds behind the sampled ones in a loaded recorder (a
    sample lost in transit holds the later ones back until the writer's next heartbeat), so a stopped
    recording can hold force samples of impacts whose events it never received.
    """
    times = events.get("time", np.empty(0))
    if not times.size or not detected_match.size:
        return None
    orphans = detected["start"][(detected_match < 0) & (detected["start"] > float(times[-1]))]
    return float(orphans.min()) if orphans.size else None


def stop_time(data: RecordedData, detected: dict[str, np.ndarray] | None = None,
              detected_match: np.ndarray | None = None) -> float | None:
    """The recording's stop (s from the origin) when it names one and every analysed stream reaches it; else None.

    A recording made by ``rimd experiment`` names the end of its last step (the recorder's ``stop_at``, metadata
    record :data:`~rimd_sim.settings.recording.STOP_METADATA`): it holds every message stamped before it and
    nothing after. The streams reach it when each sampled channel's last sample is its last period before it,
    the motor states' last is within one of their periods of it, and the impact events do not end before it
    (:func:`events_end`). A recording whose recorder was stopped before it caught up ends where its streams end
    (:func:`common_end`), as any other.
    """
    record = data.recording.metadata.get(STOP_METADATA, {}) if data.recording is not None else {}
    try:
        stop = (int(record["stop_at_ns"]) - data.origin_ns) * 1e-9
    except (KeyError, ValueError):
        return None
    for c in data.channels.values():
        if c.time.size and c.time[-1] + 1.5 / c.rate < stop:
            return None
    t = data.motor.get("time", np.empty(0))
    if t.size > 1 and t[-1] + 1.5 * float(np.median(np.diff(t))) < stop:
        return None
    if detected is not None and detected_match is not None:
        end = events_end(detected, detected_match, data.events)
        if end is not None and end < stop:
            return None
    return stop


def segment_steps(motor: dict[str, np.ndarray], settle: float, tolerance_hz: float = 1e-6,
                  end: float | None = None, stop: float | None = None) -> list[Step]:
    """Cut the motor states into steps of constant setpoint; discard the ramp plus ``settle`` seconds.

    ``end``: the time where the recording's streams stop together (:func:`common_end`); the last step ends
    there when it is earlier than its last motor state, and steps that start after it are dropped.
    ``stop``: the end of the schedule (:func:`stop_time`), which the recording reaches: the last step ends
    there (the motor states stop one period short of it), and ``end`` is not used.
    """
    t = motor.get("time", np.empty(0))
    if stop is not None:
        end = stop
    if end is not None:
        keep = t <= end
        motor = {k: v[keep] for k, v in motor.items()}
        t = motor["time"]
    if t.size == 0:
        return []
    sp, f = motor["frequency_setpoint"], motor["frequency"]
    cuts = np.flatnonzero(np.diff(sp) != 0) + 1
    bounds = [0, *cuts.tolist(), t.size]
    last = t[-1] if stop is None else stop
    steps = []
    for n, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        end = t[b] if b < t.size else last
        reached = np.flatnonzero(np.abs(f[a:b] - sp[a]) <= tolerance_hz)
        ramp_end = float(t[a + reached[0]]) if reached.size else None
        steady = None if ramp_end is None or ramp_end + settle >= end else ramp_end + settle
        steps.append(Step(n, float(sp[a]), float(t[a]), ramp_end, steady, float(end)))
    return steps


#: A step is settled when the two halves of its steady window agree: impact counts within one impact (a
#: window edge can fall on either side of an impact) plus this much per cycle of a half ...
SETTLED_IMPACTS_PER_CYCLE = 0.1
#: ... and largest peak forces within this fraction of the larger.
SETTLED_PEAK_FRACTION = 0.05


def settled(times: np.ndarray, peaks: np.ndarray, start: float, end: float, frequency: float) -> bool | None:
    """Whether the motion over ``[start, end)`` is steady (None when each half is shorter than two cycles).

    Steady: the two halves hold the same number of impacts, within one (the edges of a window cut the train
    of impacts at any phase) plus :data:`SETTLED_IMPACTS_PER_CYCLE` per cycle, and the same largest peak
    force, within :data:`SETTLED_PEAK_FRACTION`.

    A transient that has not died out (a step that started at an unlucky phase, a chaotic motion) shows as
    halves that differ; a steady periodic motion of period up to a few cycles gives equal halves.
    """
    mid = 0.5 * (start + end)
    cycles = (mid - start) * frequency
    if not cycles >= 2.0:
        return None
    halves = []
    for lo, hi in ((start, mid), (mid, end)):
        sel = (times >= lo) & (times < hi)
        halves.append((int(sel.sum()), float(peaks[sel].max()) if sel.any() else 0.0))
    (n1, f1), (n2, f2) = halves
    return bool(abs(n1 - n2) <= 1 + SETTLED_IMPACTS_PER_CYCLE * cycles
                and abs(f1 - f2) <= SETTLED_PEAK_FRACTION * max(f1, f2))


# ---- phase plane and Poincare map ------------------------------------------------------------------------

def phase_plane(rimd: Channel, cart: Channel, window: int = 21) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Relative displacement ``x_rimd - x_cart`` (m) and its velocity (m/s) at the RIMD laser's samples.

    The cart is interpolated onto the RIMD laser's times (both lasers sample together at the same rate, so
    this is exact where both have data); samples outside the cart's recorded stretches are dropped. The
    velocity is a cubic Savitzky-Golay derivative per stretch of consecutive samples (``np.gradient`` for
    stretches shorter than ``window``); stretches are separated by NaN so plots do not join across holes.
    """
    from scipy.signal import savgol_filter

    ts, xs, vs = [], [], []
    cart_ok = _covered(cart, rimd.time)
    for seg in rimd.segments():
        ok = cart_ok[seg]
        if ok.sum() < 3:
            continue
        t = rimd.time[seg][ok]
        x = rimd.values[seg][ok] - np.interp(t, cart.time, cart.values)
        dt = 1.0 / rimd.rate
        v = savgol_filter(x, window, 3, deriv=1, delta=dt) if x.size >= window else np.gradient(x, dt)
        ts += [t, [np.nan]]
        xs += [x, [np.nan]]
        vs += [v, [np.nan]]
    if not ts:
        return np.empty(0), np.empty(0), np.empty(0)
    return np.concatenate(ts[:-1]), np.concatenate(xs[:-1]), np.concatenate(vs[:-1])


def poincare_times(motor: dict[str, np.ndarray]) -> np.ndarray:
    """Instants (s) at which the motor phase crosses 0, interpolated between consecutive motor states."""
    t = motor.get("time", np.empty(0))
    if t.size < 2:
        return np.empty(0)
    phi = 2.0 * math.pi * motor["cycle_index"] + motor["phase"]
    turns = np.floor(phi / (2.0 * math.pi))
    i = np.flatnonzero((turns[1:] > turns[:-1]) & (phi[1:] > phi[:-1]) & (np.diff(t) > 0))
    target = 2.0 * math.pi * turns[i + 1]
    return t[i] + (target - phi[i]) / (phi[i + 1] - phi[i]) * (t[i + 1] - t[i])


def poincare_points(t: np.ndarray, x: np.ndarray, v: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Phase-plane points at ``times`` (rows ``time, x, v``), only where the phase plane has samples around."""
    if t.size == 0 or times.size == 0:
        return np.empty((0, 3))
    ok = np.isfinite(t)
    tt, xx, vv = t[ok], x[ok], v[ok]
    j = np.searchsorted(tt, times)
    inside = (j > 0) & (j < tt.size)
    jj = np.clip(j, 1, max(tt.size - 1, 1))
    # Neighbours must be consecutive samples (no hole between them).
    inside &= (tt[jj] - tt[jj - 1]) < 1.5 * np.median(np.diff(tt)) if tt.size > 1 else False
    sel = times[inside]
    return np.column_stack([sel, np.interp(sel, tt, xx), np.interp(sel, tt, vv)])
