"""What a running rig is doing, on one screen: the library behind ``rimd status`` (like ``ros2 topic hz`` + ``echo``).

:class:`RigMonitor` listens to the rig's topics from a node of the caller's and keeps, per channel, the message
rate, the last ``first_index``, the holes in the indices and the lateness *as received* (the DDS reception time
minus the time the block's last sample was due, when the stamps are wall-clock); the motor; the faults in
force (``/rig/faults``); impacts per second; the run (``/rig/session``) and the simulator's pacing status
(``/diagnostics``: lateness it measures, lockstep holds). :meth:`RigMonitor.snapshot` gives it as a plain dict
(the JSON of ``rimd status --json``); :func:`render` as text.
"""

from __future__ import annotations

import statistics
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

__all__ = ["RigMonitor", "render"]

#: Channel topic -> short name shown.
CHANNEL_TOPICS = {"/rig/cart/displacement": "cart_displacement", "/rig/rimd/displacement": "rimd_displacement",
                  "/rig/rimd/acceleration": "rimd_acceleration", "/rig/impact/force": "impact_force"}
#: Seconds over which rates are counted.
RATE_WINDOW_S = 2.0


@dataclass
class _Channel:
    arrivals: deque = field(default_factory=lambda: deque(maxlen=4000))   # monotonic times of arrival
    lateness: deque = field(default_factory=lambda: deque(maxlen=400))    # s, wall-clock stamps only
    last_index: int | None = None
    next_index: int | None = None
    gaps: int = 0
    lost_samples: int = 0
    last_stamp_ns: int | None = None


class RigMonitor:
    """Listens to the rig on ``node`` (subscriptions and a timer of its own). See the module docstring."""

    def __init__(self, node: Any, namespace: str = "/rig") -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        from rimd_msgs.msg import FaultEvent, ImpactEvent, MotorState, RigSession, SampleBlock

        self._node = node
        self._started = time.monotonic()
        self.channels = {topic: _Channel() for topic in CHANNEL_TOPICS}
        self.motor: dict[str, float] = {}
        self.impacts: deque = deque(maxlen=1000)
        self.last_peak: float | None = None
        self.faults: dict[int, dict[str, Any]] = {}
        self.session: dict[str, Any] = {}
        self.pacing: dict[str, str] = {}
        self.pacing_message = ""
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        ns = namespace.rstrip("/")
        for topic in CHANNEL_TOPICS:   # raw, with the message info (two-argument callbacks): the reception time
            node.create_subscription(SampleBlock, topic.replace("/rig", ns, 1), self._block_callback(topic), qos,
                                     raw=True)
        node.create_subscription(MotorState, f"{ns}/motor/state", self._on_motor, qos)
        node.create_subscription(ImpactEvent, f"{ns}/impact/events", self._on_impact, qos)
        node.create_subscription(FaultEvent, f"{ns}/faults", self._on_fault, latched)
        node.create_subscription(RigSession, f"{ns}/session", self._on_session, QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)

    # -- what comes in --------------------------------------------------------------------------------------
    def _block_callback(self, topic: str) -> Callable[[bytes, Any], None]:
        # Two arguments: rclpy passes the message info to a callback that takes it.
        def on_block(data: bytes, info: Any) -> None:
            self._on_block(topic, data, info)
        return on_block

    def _on_block(self, topic: str, data: bytes, info: Any) -> None:
        from rimd_sim.io.cdr import block_span, header_stamp

        c = self.channels[topic]
        c.arrivals.append(time.monotonic())
        first, count = block_span(data)
        if c.next_index is not None and first > c.next_index:
            c.gaps += 1
            c.lost_samples += first - c.next_index
        c.next_index = first + count
        c.last_index = first
        stamp = header_stamp(data)
        c.last_stamp_ns = stamp
        received = info.get("received_timestamp") if isinstance(info, dict) else getattr(info, "received_timestamp", 0)
        if received and stamp is not None and self.session.get("time_base") == "wall_clock":
            from rimd_sim.io.cdr import read_block

            block = read_block(data, arrays=1)
            due = stamp + round((count - 1) * 1e9 / block.sample_rate) if count else stamp
            c.lateness.append((received - due) / 1e9)

    def _on_motor(self, msg: Any) -> None:
        self.motor = {"setpoint_hz": msg.frequency_setpoint, "frequency_hz": msg.frequency, "phase_rad": msg.phase,
                      "cycle": msg.cycle_index, "stamp_s": msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9}

    def _on_impact(self, msg: Any) -> None:
        self.impacts.append(time.monotonic())
        self.last_peak = msg.peak_force

    def _on_fault(self, msg: Any) -> None:
        if msg.event == "start":
            self.faults[msg.id] = {"id": msg.id, "channel": msg.channel, "kind": msg.kind, "start_s": msg.start,
                                   "duration_s": msg.duration, "magnitude": msg.magnitude}
        else:
            self.faults.pop(msg.id, None)

    def _on_session(self, msg: Any) -> None:
        self.session = {"run_id": msg.run_id, "reason": msg.reason, "sequence": msg.sequence,
                        "time_base": msg.time_base, "lockstep": msg.lockstep, "seed": msg.seed,
                        "real_time_factor": msg.real_time_factor}

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name.endswith("rimd_simulator: pacing"):
                self.pacing = {kv.key: kv.value for kv in status.values}
                self.pacing_message = status.message

    # -- what goes out --------------------------------------------------------------------------------------
    @property
    def heard(self) -> bool:
        """Whether anything of the rig was heard."""
        return bool(self.motor or any(c.arrivals for c in self.channels.values()) or self.session)

    def snapshot(self) -> dict[str, Any]:
        """Everything known now, as plain data (JSON)."""
        now = time.monotonic()
        window = min(RATE_WINDOW_S, max(1e-3, now - self._started))
        channels = {}
        for topic, c in self.channels.items():
            recent = [t for t in c.arrivals if now - t <= window]
            lateness = sorted(c.lateness)
            channels[CHANNEL_TOPICS[topic]] = {
                "topic": topic, "blocks_per_s": len(recent) / window, "last_first_index": c.last_index,
                "gaps": c.gaps, "lost_samples": c.lost_samples,
                "lateness_p50_ms": statistics.median(lateness) * 1e3 if lateness else None,
                "lateness_max_ms": lateness[-1] * 1e3 if lateness else None,
                "last_stamp_s": c.last_stamp_ns / 1e9 if c.last_stamp_ns is not None else None}
        return {
            "heard": self.heard, "session": self.session, "motor": self.motor, "channels": channels,
            "impacts_per_s": sum(1 for t in self.impacts if now - t <= window) / window,
            "last_peak_force_n": self.last_peak, "faults_in_force": sorted(self.faults.values(), key=lambda f: f["id"]),
            "pacing": {"message": self.pacing_message, **self.pacing},
        }


def render(snap: dict[str, Any]) -> str:
    """The snapshot as one screen of text."""
    if not snap["heard"]:
        return "no rig heard yet (is it running, on this ROS_DOMAIN_ID?)"
    s, m, p = snap["session"], snap["motor"], snap["pacing"]
    lines = [f"run {s.get('run_id', '?')[:12]} ({s.get('reason', '?')}, {s.get('time_base', '?')} stamps"
             + (", lockstep" if s.get("lockstep") else "") + f"); simulation time {p.get('simulation_time_s', '?')} s",
             f"pacing: {p.get('message', '?')}; lateness p50 {p.get('lateness_p50_ms', '?')} ms (rig's measure)"]
    if m:
        lines.append(f"motor: {m['frequency_hz']:.3f} Hz (setpoint {m['setpoint_hz']:g} Hz), cycle {m['cycle']}")
    lines.append(f"impacts: {snap['impacts_per_s']:.2f}/s" + (f", last peak {snap['last_peak_force_n']:.1f} N"
                                                           if snap["last_peak_force_n"] is not None else ""))
    lines.append(f"{'channel':<18} {'blocks/s':>8} {'first_index':>12} {'gaps':>5} {'lost':>8} {'late p50 ms':>11}")
    for name, c in snap["channels"].items():
        late = "-" if c["lateness_p50_ms"] is None else f"{c['lateness_p50_ms']:.2f}"
        index = "-" if c["last_first_index"] is None else str(c["last_first_index"])
        lines.append(f"{name:<18} {c['blocks_per_s']:>8.1f} {index:>12} {c['gaps']:>5} {c['lost_samples']:>8} "
                     f"{late:>11}")
    faults = snap["faults_in_force"]
    lines.append("faults in force: " + (", ".join(f"{f['kind']} on {f['channel']} (from {f['start_s']:g} s)"
                                                 for f in faults) if faults else "none"))
    return "\n".join(lines)
