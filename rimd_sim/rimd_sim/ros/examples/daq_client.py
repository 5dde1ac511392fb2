"""A reference DAQ client of the rig: what a data-acquisition program written against the twin should do.

Walked through in docs/daq-client.md; run it with ``python -m rimd_sim.ros.examples.daq_client --until 10``.

It subscribes to the four channels, the motor state, ``/rig/faults`` (the rig's ground truth of the faults it
injects) and ``/rig/session`` (the run's identity), and keeps, per channel:

* **continuity with a reorder window** (:class:`Continuity`): a block that arrives after a later one (a
  ``delay`` fault's jitter) is *reordered*, not lost; a hole in ``first_index`` is counted as lost only once
  ``reorder_window`` seconds of later data have arrived without it. A new run (``/rig/session``, reason
  ``start``) starts every channel's count again at its first block;
* **fault detection** (:class:`FaultWatch`, and the force baseline's steps of :class:`PeakDetector`): the
  symptoms a DAQ can see by itself (a hole in the indices, samples that repeat exactly, samples on the range's
  rail, ``saturated_count``, a force baseline that jumped), reported with what ``/rig/faults`` says happened;
* **impact peaks per motor step** (:class:`PeakDetector`): an impact is where the force rises more than
  ``threshold`` N *above the running baseline*, not above zero: an ``offset`` fault moves a fixed threshold
  (the trap), not the distance from the baseline. The steady peak of a step is the mean of the peaks after
  ``settle`` seconds, with its spread.

With ``--lockstep NAME`` it reports its progress (:class:`rimd_sim.ros.clients.progress.ProgressReporter`): a rig
in lockstep never runs ahead of it. Once it has ``--until`` seconds of simulation time on every channel, counted
from the first sample it received (sample 0 on a rig that waits for it: lockstep, or started paused), it prints one
JSON report (also to ``--json FILE``) and exits 0; a client that joins a running rig late acquires as long.

Its times are the run's simulation seconds whatever the rig's time base: a block's from its ``first_index /
sample_rate``, a stamped message's (motor state, fault) from its stamp less the stamp of the run's sample 0 (a
block's stamp less its ``first_index / sample_rate``). A rig at real time stamps in wall-clock time: taken for
simulation time, its first block's stamp was already past ``--until`` and the client stopped at once.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Continuity", "FaultWatch", "PeakDetector", "main"]

CHANNELS = {"/rig/cart/displacement": "cart_displacement", "/rig/rimd/displacement": "rimd_displacement",
            "/rig/rimd/acceleration": "rimd_acceleration", "/rig/impact/force": "impact_force"}


@dataclass
class Continuity:
    """The blocks of one channel in index order, with a reorder window (see the module docstring).

    Args:
        reorder_window: Seconds of later data after which a hole is counted as lost.
    """

    reorder_window: float = 0.5
    next_index: int | None = None
    pending: dict[int, int] = field(default_factory=dict)   # first_index -> count, arrived ahead of a hole
    lost_samples: int = 0
    lost_blocks: int = 0
    reordered: int = 0
    duplicates: int = 0
    blocks: int = 0

    def add(self, first_index: int, count: int, rate: float) -> list[tuple[int, int]]:
        """One block; returns the holes now counted as lost, as (first missing index, samples)."""
        self.blocks += 1
        if self.next_index is None:
            self.next_index = first_index + count
            return []
        if first_index < self.next_index:
            if first_index + count <= self.next_index:
                self.duplicates += 1
            return []
        if first_index > self.next_index:
            if first_index in self.pending:
                self.duplicates += 1
            self.pending[first_index] = count
        else:
            if self.pending:          # it fills a hole that later blocks had left: it came late, not lost
                self.reordered += 1
            self.next_index += count
        return self._drain(rate)

    def _drain(self, rate: float) -> list[tuple[int, int]]:
        assert self.next_index is not None   # set by add() before it drains
        lost: list[tuple[int, int]] = []
        while True:
            if self.next_index in self.pending:   # the next block had come ahead of a hole now closed
                self.next_index += self.pending.pop(self.next_index)
                continue
            if not self.pending:
                return lost
            ahead = max(i + n for i, n in self.pending.items())
            if (ahead - self.next_index) / rate < self.reorder_window:
                return lost
            first = min(self.pending)          # waited long enough: the hole is lost
            lost.append((self.next_index, first - self.next_index))
            self.lost_samples += first - self.next_index
            self.lost_blocks += 1
            self.next_index = first

    def restart(self) -> None:
        """A new run: its indices start again."""
        self.next_index = None
        self.pending.clear()


@dataclass
class PeakDetector:
    """Impacts in the force channel: short rises of more than ``threshold`` above the running baseline.

    The baseline is the median of the samples below the threshold over the last ``baseline_s`` seconds. A rise
    that lasts longer than ``max_width_s`` is no impact (a contact lasts about a millisecond): the baseline
    moved (an ``offset`` fault, a drifting sensor); so did it when the force stays more than ``threshold``
    below it that long (the offset ended). Each step is recorded in :attr:`steps` and the baseline starts
    again from the new level, so that the impacts after it are measured from there.
    """

    threshold: float = 10.0
    baseline_s: float = 0.5
    max_width_s: float = 0.005
    peaks: list[tuple[float, float]] = field(default_factory=list)   # (time of the peak, height above baseline)
    steps: list[tuple[float, float]] = field(default_factory=list)   # (time, new baseline - old baseline)
    _recent: deque = field(default_factory=lambda: deque(maxlen=64))
    _in_impact: bool = False
    _width: int = 0
    _best: tuple[float, float] = (0.0, -math.inf)

    @property
    def baseline(self) -> float:
        """The running baseline (0 before any data)."""
        return float(np.median(np.concatenate(self._recent))) if self._recent else 0.0

    def add(self, t0: float, rate: float, samples: np.ndarray) -> None:
        """One block of force samples starting at time ``t0`` (s)."""
        base = self.baseline
        width = self.max_width_s * rate
        for start, end in _runs(samples - base < -self.threshold):
            if end - start > width:   # the baseline went down (an offset ended): measure from the new level
                level = float(np.median(samples[start:end]))
                self.steps.append((t0 + start / rate, level - base))
                self._recent.clear()
                self._recent.append(samples[start:end])
                base = level
                break
        above = samples - base > self.threshold
        runs = _runs(above)
        if self._in_impact and (not runs or runs[0][0] != 0):
            self._close()                     # the impact that went on at the end of the last block ended there
        for start, end in runs:
            self._width = (self._width if start == 0 and self._in_impact else 0) + (end - start)
            if self._width > width:   # too long for an impact: the baseline moved
                level = float(np.median(samples[start:end]))
                self.steps.append((t0 + start / rate, level - base))
                self._recent.clear()
                self._recent.append(samples[start:end])
                self._best, self._in_impact, self._width = (0.0, -math.inf), False, 0
                return
            j = start + int(np.argmax(samples[start:end]))
            height = float(samples[j] - base)
            if height > self._best[1]:
                self._best = (t0 + j / rate, height)
            if end < samples.size:
                self._close()
        self._in_impact = bool(runs) and runs[-1][1] == samples.size
        quiet = samples[~above]
        if quiet.size:
            self._recent.append(quiet)
            keep = max(1, int(self.baseline_s * rate / max(samples.size, 1)))
            while len(self._recent) > keep:
                self._recent.popleft()

    def _close(self) -> None:
        if self._best[1] > -math.inf:
            self.peaks.append(self._best)
        self._best, self._width = (0.0, -math.inf), 0


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs of True in ``mask`` as (start, end) index pairs, end excluded."""
    idx = np.flatnonzero(mask)
    if not idx.size:
        return []
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate(([idx[0]], idx[breaks + 1]))
    ends = np.concatenate((idx[breaks], [idx[-1]])) + 1
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


@dataclass
class FaultWatch:
    """Symptoms of a channel that a DAQ can see by itself, as (kind, start s) detections."""

    stuck_blocks: int = 3          # blocks of identical samples in a row before "stuck"
    detections: list[tuple[str, float]] = field(default_factory=list)
    _same: int = 0
    _last: float | None = None
    _rail: bool = False
    _saturated: bool = False

    def add(self, t0: float, samples: np.ndarray, range_min: float, range_max: float, saturated: int,
            lost: list[tuple[int, int]], rate: float) -> None:
        """One block; records the symptoms that start in it."""
        for first, _ in lost:
            self.detections.append(("dropout", first / rate))
        if samples.size and np.all(samples == samples[0]) and samples[0] == self._last:
            self._same += 1
            if self._same == self.stuck_blocks:
                self.detections.append(("stuck", t0))
        else:
            self._same = 0
        self._last = float(samples[-1]) if samples.size else self._last
        rail = bool(samples.size) and bool(np.all(samples >= range_max))
        if rail and not self._rail:
            self.detections.append(("disconnect", t0))
        self._rail = rail
        saturated_now = saturated > 0 and not rail
        if saturated_now and not self._saturated:
            self.detections.append(("saturate", t0))
        self._saturated = saturated_now


def _ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def main(argv: list[str] | None = None) -> int:
    """Run the client until ``--until`` seconds of simulation time; print the JSON report."""
    parser = argparse.ArgumentParser(prog="python -m rimd_sim.ros.examples.daq_client",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--until", type=float, required=True,
                        help="simulation seconds to acquire, from the first sample received")
    parser.add_argument("--lockstep", default="", metavar="NAME", help="report progress under NAME (a lockstep rig)")
    parser.add_argument("--threshold", type=float, default=10.0, help="N above the baseline that make an impact")
    parser.add_argument("--settle", type=float, default=2.0, help="s after a motor step before its peaks count")
    parser.add_argument("--reorder-window", type=float, default=0.5, help="s of later data before a hole is lost")
    parser.add_argument("--json", default="", help="also write the report to this file")
    parser.add_argument("--timeout", type=float, default=300.0, help="wall seconds before giving up")
    args = parser.parse_args(argv)

    import functools
    import time

    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from rimd_msgs.msg import FaultEvent, MotorState, RigSession, SampleBlock
    from rimd_sim.ros.clients.progress import ProgressReporter

    rclpy.init()
    node = Node("daq_client")
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    continuity = {t: Continuity(args.reorder_window) for t in CHANNELS}
    watch = {t: FaultWatch() for t in CHANNELS}
    peaks = PeakDetector(args.threshold)
    steps: list[dict[str, Any]] = []         # motor steps: setpoint and the stamp it was first seen at
    truth: list[dict[str, Any]] = []         # /rig/faults: the faults that really happened
    reached = dict.fromkeys(CHANNELS, 0.0)
    runs: list[str] = []
    zero_ns: list[int] = []   # the stamp of the run's sample 0 (ns), from the first block
    first_s: list[float] = []  # the run's simulation time of the first sample received

    def run_seconds(ns: int) -> float:
        """A stamp as the run's simulation seconds (as the raw stamp until a block has given sample 0's)."""
        return (ns - zero_ns[0]) / 1e9 if zero_ns else ns / 1e9

    def on_block(msg: SampleBlock, topic: str) -> None:
        rate = msg.sample_rate
        samples = np.asarray(msg.samples)
        t0 = msg.first_index / rate   # the run's simulation seconds, in either time base
        if not zero_ns:
            zero_ns.append(_ns(msg.header.stamp) - round(msg.first_index * 1e9 / rate))
        if not first_s:
            first_s.append(t0)
        lost = continuity[topic].add(msg.first_index, samples.size, rate)
        watch[topic].add(t0, samples, msg.range_min, msg.range_max, msg.saturated_count, lost, rate)
        if topic == "/rig/impact/force":
            before = len(peaks.steps)
            peaks.add(t0, rate, samples)
            watch[topic].detections += [("offset", t) for t, jump in peaks.steps[before:] if jump > 0]
        reached[topic] = max(reached[topic], t0 + samples.size / rate)
        if reporter is not None:
            reporter.done(msg.header.stamp, subs[topic])

    def on_motor(msg: MotorState) -> None:
        if not steps or steps[-1]["setpoint"] != msg.frequency_setpoint:
            steps.append({"setpoint": msg.frequency_setpoint, "from_ns": _ns(msg.header.stamp)})

    def on_session(msg: RigSession) -> None:
        if runs and msg.reason == "start":   # the rig restarted: its indices start again
            for c in continuity.values():
                c.restart()
            zero_ns.clear()
        runs.append(msg.run_id)

    def on_fault(m: FaultEvent) -> None:
        truth.append({"event": m.event, "id": m.id, "channel": m.channel, "kind": m.kind,
                      "at_ns": _ns(m.header.stamp)})

    subs = {t: node.create_subscription(SampleBlock, t, functools.partial(on_block, topic=t), qos)
            for t in CHANNELS}
    node.create_subscription(MotorState, "/rig/motor/state", on_motor, qos)
    node.create_subscription(FaultEvent, "/rig/faults", on_fault, latched)
    node.create_subscription(RigSession, "/rig/session", on_session, latched)
    reporter = ProgressReporter(node, args.lockstep, subscriptions=list(subs.values())) if args.lockstep else None
    deadline = time.monotonic() + args.timeout
    def acquired() -> float:
        return min(reached.values()) - (first_s[0] if first_s else 0.0)

    while acquired() < args.until and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)

    report: dict[str, Any] = {
        "reached_s": min(reached.values()),
        "acquired_s": acquired(),
        "runs": runs,
        "channels": {CHANNELS[t]: {"blocks": c.blocks, "lost_blocks": c.lost_blocks, "lost_samples": c.lost_samples,
                                   "reordered": c.reordered, "duplicates": c.duplicates}
                     for t, c in continuity.items()},
        "faults_detected": [{"channel": CHANNELS[t], "kind": kind, "at": at}
                            for t, w in watch.items() for kind, at in w.detections],
        "faults_truth": [{**{k: v for k, v in f.items() if k != "at_ns"}, "at": run_seconds(f["at_ns"])}
                         for f in truth if f["event"] == "start"],
        "peaks": [{"at": t, "height_n": h} for t, h in peaks.peaks],
        "steps": [],
    }
    for step in steps:
        step["from"] = run_seconds(step["from_ns"])
    for i, step in enumerate(steps):
        end = steps[i + 1]["from"] if i + 1 < len(steps) else report["reached_s"]
        heights = [h for t, h in peaks.peaks if step["from"] + args.settle <= t < end]
        report["steps"].append({"setpoint_hz": step["setpoint"], "from_s": step["from"], "impacts": len(heights),
                                "steady_peak_n": float(np.mean(heights)) if heights else None,
                                "spread_n": float(np.std(heights)) if heights else None})
    text = json.dumps(report, indent=1)
    print(text, flush=True)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text)
    if reporter is not None:
        reporter.leave()   # a rig in lockstep stops waiting for this client
    node.destroy_node()
    rclpy.try_shutdown()
    return 0 if report["acquired_s"] >= args.until else 1


if __name__ == "__main__":
    sys.exit(main())
