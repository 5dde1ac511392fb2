"""Node ``rimd_simulator``: the rig on DDS, behaving like hardware for DAQ software (SPEC sections 4-5, 10).

A thin adapter over :class:`rimd_sim.instruments.rig_simulator.RigSimulator` and :class:`rimd_sim.runtime.pacing.Pacer`:

* the constructor declares every parameter (:class:`~rimd_sim.settings.config.SimConfig` and the node's own
  :class:`~rimd_sim.settings.config.SimulatorNodeSettings`, one declaration each, :mod:`rimd_sim.settings.params`),
  builds the validated settings, creates publishers, services and the ``/rig/progress`` subscription;
* a pacing thread asks the pacer how many of the next blocks may go (the clock: ``real_time_factor``; the
  consumers: ``lockstep.*``), advances the core and publishes them. The core advances by its own exact
  clock: a late thread only delays the data, never changes it;
* services and parameter changes run on the executor; each is validated at once (a refusal answers
  ``success = false`` with the reason and changes nothing) and takes effect at the next block boundary in
  simulation time, or at the stamp the request names.

Time base: at ``real_time_factor`` 1 without lockstep the stamps are wall-clock (sample ``n`` at
``t0 + n / rate``, ``t0`` the wall time of the start in whole milliseconds, taken at the same instant as the
pacing's anchor); otherwise simulation time from 0, and ``/clock`` is published. Each start and reset opens a
new run on ``/rig/session`` (transient local).
"""

from __future__ import annotations

import array
import hashlib
import json
import math
import sys
import threading
import time
import traceback
import uuid
from collections import deque
from fractions import Fraction
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from rimd_msgs.msg import (
    Capture,
    ConsumerProgress,
    FaultEvent,
    ImpactEvent,
    MotorState,
    RigSession,
    RigState,
    SampleBlock,
)
from rimd_msgs.srv import InjectFault, Perturb, SetMotorFrequency
from rimd_sim.errors import CommandError, ConfigError, IntegrationError
from rimd_sim.instruments.faults import parse_fault_entry
from rimd_sim.instruments.rig_simulator import NODE_ONLY_PARAMETERS, RigSimulator, SimBlock
from rimd_sim.io.cdr import SampleBlockEncoder
from rimd_sim.ros.nodes._params import declare, refuse_unnamed
from rimd_sim.ros.nodes._run import log_at, run_node, spin_until_stopped
from rimd_sim.runtime.pacing import Go, Hold, Pacer, Wait
from rimd_sim.settings.config import (
    CHANNEL_NAMES,
    MAX_RAMP_RATE,
    NODE_PARAMETERS,
    PARAMETERS,
    SimConfig,
    SimulatorNodeSettings,
)
from rimd_sim.settings.params import build

__all__ = ["SimulatorNode", "main"]

NODE_NAME = "rimd_simulator"
DEFAULT_NAMESPACE = "rig"

#: Channel -> topic, relative to the node's namespace (``/rig`` by default).
CHANNEL_TOPICS = {
    "cart_displacement": "cart/displacement",
    "rimd_displacement": "rimd/displacement",
    "rimd_acceleration": "rimd/acceleration",
    "impact_force": "impact/force",
}

#: RigState array fields, in the order of the core's truth rows (the 11th row, in_contact, is bool[]).
TRUTH_ARRAY_FIELDS = ("theta", "theta_dot", "cart_position", "rimd_position", "rimd_velocity", "rimd_acceleration",
                      "penetration", "contact_force", "motor_phase", "motor_frequency")

#: Longest the rig waits for DDS to match the readers the graph already shows (s): before its first block, and
#: in lockstep whenever a consumer joins.
MATCH_TIMEOUT_S = 2.0
#: Longest a command may be scheduled ahead of the simulation (s of simulation time).
MAX_SCHEDULE_AHEAD_S = 86_400
#: Blocks offered to the pacer at once (one core pass): as fast as possible, 0.1 s of simulation time.
MAX_BATCH = 10
#: A lockstep hold is said in the log and in /diagnostics once it has lasted this long (s), then every REPEAT s.
HOLD_REPORT_S = 0.5
HOLD_REPEAT_S = 10.0
#: Stamp frame of the run's identity.
SESSION_FRAME = "rimd_virtual_rig"


def stamp_ns(t0_ns: int, t: Fraction) -> int:
    """ROS time in integer nanoseconds of simulation time ``t`` (exact, rounded to the nearest ns)."""
    return t0_ns + round(t * 1_000_000_000)


def to_time(ns: int) -> Time:
    """``builtin_interfaces/Time`` from integer nanoseconds."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def show_stamp(ns: int) -> str:
    """A stamp in seconds, exact to the nanosecond (a float would round a 2026 epoch stamp to ~100 ns)."""
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def from_time(t: Time) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``."""
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def config_hash(config: SimConfig) -> str:
    """SHA-256 of the configuration's parameters in canonical JSON (sorted keys): the run's configuration id."""
    text = json.dumps(config.to_parameters(), sort_keys=True, default=list, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


class SimulatorNode(Node):
    """The simulator node. See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("namespace", DEFAULT_NAMESPACE)
        super().__init__(NODE_NAME, **kwargs)
        values = declare(self, {**PARAMETERS, **NODE_PARAMETERS})
        self._config = SimConfig.from_parameters({k: values[k] for k in PARAMETERS})  # ConfigError: caught in main()
        self._settings = build(SimulatorNodeSettings, {k: values[k] for k in NODE_PARAMETERS})
        lockstep = self._settings.lockstep
        self._lockstep = lockstep if lockstep.enabled else None
        if self._lockstep is not None and self._lockstep.window < 2.0 / self._config.block_rate:
            raise ConfigError("lockstep.window", self._lockstep.window,
                              f"must be >= two block periods (2 / block_rate = {2.0 / self._config.block_rate:g} s): "
                              "a consumer reports the stamp of the last block it took, which is a block behind")
        self._capture = self._settings.capture
        self._lock = threading.Lock()
        # Load the compiled kernels now (a throwaway pass), so the first published block is not late.
        RigSimulator(self._config, capture=self._capture).advance_blocks([Fraction(1, 100)])
        self._sim = RigSimulator(self._config, capture=self._capture)
        self._block = 0  # blocks published
        self._rtf = self._config.real_time_factor
        self._block_rate = Fraction(repr(self._config.block_rate))
        #: Stamps are wall-clock only at real time without lockstep; t0 is taken when the run starts.
        self._wall_clock = self._rtf == 1.0 and self._lockstep is None
        self._t0_ns = 0
        self._paused = self._settings.start_paused
        self._load_faults(self._settings.faults)
        self._started = False
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._lateness: deque[float] = deque(maxlen=1000)
        self._overruns = 0
        self._published = 0
        self._impacts = 0
        self._last_error = ""
        self._paused_wall = 0.0    # wall-clock seconds spent paused after the start (stamps lag the wall by it)
        self._paused_at: float | None = None
        self._sessions = 0
        self._run_id = ""
        self._hold_reported = 0.0  # wall time of the last hold report (0: not reported in this hold)
        self._match_pending = False  # a lockstep consumer joined: wait for DDS to match its subscriptions
        self._joining: dict[str, list[str]] = {}   # node -> its topics, of consumers that just joined

        # History of each publisher: one second of blocks at real time; faster than real time, 20 s of simulation
        # time (at 20x that is still one second of wall time for a reliable subscriber, such as the recorder, to
        # fall behind without losing a block; memory: about 3 MB per 20 kHz channel). In lockstep no consumer
        # falls further behind than the window: twice the window and a second.
        seconds = 1.0 if self._wall_clock else 20.0
        if self._lockstep is not None:
            seconds = max(1.0, 2 * self._lockstep.window + 1.0)
        depth = max(10, math.ceil(self._config.block_rate * seconds) + 10)
        self._rates = {ch.name: Fraction(repr(ch.sample_rate)) for ch in self._config.channels}
        self._truth_rate = Fraction(repr(self._config.truth_rate))
        # Channel blocks are serialized here, straight from the core's arrays (rimd_sim.io.cdr), and
        # published as bytes: rclpy's message objects and their conversion were a third of this node's time.
        self._encoders: dict[str, SampleBlockEncoder] = {}
        self._refresh_static_fields()
        self._truth_msg = RigState()
        self._truth_msg.header.frame_id = "truth"
        self._truth_msg.sample_rate = self._config.truth_rate
        self._motor_msg = MotorState()
        self._motor_msg.header.frame_id = "motor"
        self._clock_msg = Clock()
        self._pubs = {}
        for ch in self._config.channels:
            qos = QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=depth,
                reliability=ReliabilityPolicy.RELIABLE if ch.reliable else ReliabilityPolicy.BEST_EFFORT,
            )
            self._pubs[ch.name] = self.create_publisher(SampleBlock, CHANNEL_TOPICS[ch.name], qos)
        reliable = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE)
        events_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._pub_events = self.create_publisher(ImpactEvent, "impact/events", events_qos)
        self._pub_motor = self.create_publisher(MotorState, "motor/state", reliable)
        self._pub_truth = self.create_publisher(RigState, "truth", reliable)
        # Reliable: compatible with the best-effort subscription of ROS time sources and with reliable ones. One
        # per block, so the same depth as the blocks' (a recorder that lags must not lose ticks either).
        self._pub_clock = self.create_publisher(Clock, "/clock", QoSProfile(
            depth=depth, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE))
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._pub_faults = self.create_publisher(FaultEvent, "faults", latched)
        self._pub_session = self.create_publisher(RigSession, "session", QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._fault_events = 0
        self._pub_captures = {}
        if self._capture.enabled:
            cap_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=200, reliability=ReliabilityPolicy.RELIABLE)
            self._pub_captures = {"force": self.create_publisher(Capture, "capture/force", cap_qos),
                                  "acceleration": self.create_publisher(Capture, "capture/acceleration", cap_qos)}
        self._topic = {id(pub): pub.topic_name for pub in self._all_publishers()}
        self._sent: dict[str, int] = {}   # messages published per topic since the start (diagnostics)
        self._pace_lock = threading.Lock()
        self._pacer = Pacer(self._rtf, self._lockstep, topics=list(self._topic.values()))
        self._warned: set[tuple[str, str]] = set()
        if self._lockstep is not None:
            self.create_subscription(ConsumerProgress, "progress", self._on_progress, QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE))

        self.create_service(SetMotorFrequency, "set_motor_frequency", self._on_set_motor_frequency)
        self.create_service(Perturb, "perturb", self._on_perturb)
        self.create_service(Trigger, "reset", self._on_reset)
        self.create_service(Trigger, "pause", self._on_pause)
        self.create_service(Trigger, "resume", self._on_resume)
        self.create_service(InjectFault, "inject_fault", self._on_inject_fault)
        self.create_service(Trigger, "clear_faults", self._on_clear_faults)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.create_timer(1.0, self._publish_diagnostics)

        self._thread = threading.Thread(target=self._run, name="rimd-pacing", daemon=True)
        pacing = (f"lockstep with {', '.join(self._lockstep.consumers)} (window {self._lockstep.window:g} s, "
                  f"speed cap {self._rtf:g}x)" if self._lockstep is not None else f"real_time_factor {self._rtf:g}")
        self.get_logger().info(
            f"rig ready: gap {self._config.rig.gap * 1e3:g} mm, contact {self._config.rig.contact.model}, "
            f"motor setpoint {self._config.motor.initial_setpoint:g} Hz, {pacing}, "
            f"{self._config.block_rate:g} blocks/s; stamps: "
            + ("wall clock" if self._wall_clock else "simulation time from 0, with /clock"))

    def _all_publishers(self) -> list[Any]:
        return [*self._pubs.values(), self._pub_events, self._pub_motor, self._pub_truth, self._pub_faults,
                self._pub_clock, self._pub_session, *self._pub_captures.values()]

    # ---- life cycle --------------------------------------------------------------------------------

    def start(self) -> None:
        """Start the pacing thread (publishing begins now, or at the first resume when started paused)."""
        if not self._paused:
            self._wait_for_matches()
            with self._lock:
                self._begin()
        self._thread.start()

    def shutdown(self) -> None:
        """Stop the pacing thread (idempotent)."""
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    def _begin(self) -> None:
        """The run starts now (call with ``_lock``): take ``t0`` and the pacing anchor at the same instant.

        Taken apart (t0 in the constructor, the anchor in ``start``), every block reached its subscribers some
        100 ms after its stamps said it was due, while the node's own lateness said 0.2 ms (issue 22).
        """
        wall_ns, mono = time.time_ns(), time.monotonic()
        if self._wall_clock:
            self._t0_ns = (wall_ns // 1_000_000) * 1_000_000
        start = stamp_ns(self._t0_ns, self._sim.time)
        with self._pace_lock:
            # The stamp t0 + t is due at the wall time it names: the anchor shifted back by the ms rounding of t0.
            self._pacer.schedule.anchor(start, mono - (wall_ns - start) / 1e9 if self._wall_clock else mono)
        self._started = True
        self._new_session("start")

    def _new_session(self, reason: str, at: Fraction | None = None) -> None:
        """Publish the identity of a new run (/rig/session): at the start and at each reset."""
        t = self._sim.time if at is None else at
        self._run_id = uuid.uuid4().hex
        msg = RigSession(run_id=self._run_id, reason=reason, sequence=self._sessions,
                         start_stamp=to_time(stamp_ns(self._t0_ns, t)), simulation_time=float(t),
                         time_base="wall_clock" if self._wall_clock else "simulation",
                         real_time_factor=float(self._rtf), lockstep=self._lockstep is not None,
                         seed=int(self._config.seed), config_hash=config_hash(self._config),
                         node=self.get_fully_qualified_name())
        msg.header.stamp = msg.start_stamp
        msg.header.frame_id = SESSION_FRAME
        self._sessions += 1
        self._send(self._pub_session, msg, from_time(msg.start_stamp))
        self.get_logger().info(f"run {self._run_id} ({reason}, session {msg.sequence}) from simulation time "
                               f"{float(t):.6f} s, stamp {show_stamp(from_time(msg.start_stamp))} "
                               f"({msg.time_base} time base)")

    # ---- pacing ------------------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                if self._paused:
                    self._wake.wait(0.1)
                    self._wake.clear()
                    continue
                bounds = [Fraction(self._block + i + 1) / self._block_rate for i in range(MAX_BATCH)]
                ends = [stamp_ns(self._t0_ns, b) for b in bounds]
                with self._pace_lock:
                    decision = self._pacer.next(ends)
                    events = self._pacer.lockstep.take_events() if self._pacer.lockstep is not None else []
                for level, line in events:
                    self._log(level, f"lockstep: {line}")
                if isinstance(decision, Hold):
                    self._on_hold(decision)
                    self._wake.wait(0.1)
                    self._wake.clear()
                    continue
                self._hold_reported = 0.0
                if isinstance(decision, Wait):
                    self._wake.wait(min(decision.seconds, 0.1))
                    self._wake.clear()
                    continue
                assert isinstance(decision, Go)
                if self._match_pending:
                    self._wait_for_matches()
                count = 1 if self._wall_clock else decision.count
                with self._lock:
                    if self._paused:   # paused while this thread waited for the lock: nothing more
                        continue
                    blocks = self._sim.advance_blocks(bounds[:count])
                self._block += count
                for block in blocks:
                    if not self.context.ok():
                        return
                    self._publish(block)
        except IntegrationError as exc:  # the model cannot continue: say why, keep the services alive
            self._last_error = str(exc)
            self.get_logger().error(f"simulation stopped: {exc}")
        except Exception as exc:  # at shutdown the context goes away while publishing: not an error
            if self.context.ok():   # a defect: say so where a user looks (log, /diagnostics ERROR), keep services
                self._last_error = f"internal error {type(exc).__name__}: {exc}"
                self.get_logger().error(f"simulation stopped by an internal error (please report it):\n"
                                        f"{traceback.format_exc()}")

    def _log(self, level: str, line: str) -> None:
        log_at(self, level, line)

    def _on_hold(self, hold: Hold) -> None:
        """Say which consumers hold the run and since when: once it has lasted HOLD_REPORT_S, then every REPEAT s."""
        now = time.monotonic()
        held = now - hold.since
        if held < HOLD_REPORT_S or (self._hold_reported and now - self._hold_reported < HOLD_REPEAT_S):
            return
        self._hold_reported = now
        self.get_logger().warning(f"lockstep: holding at simulation time {float(self._sim.time):.6f} s for "
                                  f"{held:.1f} s, waiting for {self._hold_text(now)}")
        self._publish_diagnostics()

    def _hold_text(self, now: float) -> str:
        with self._pace_lock:
            holders = self._pacer.lockstep.holders() if self._pacer.lockstep is not None else []
            parts = []
            for c in holders:
                heard = "never heard" if c.last_heard is None else f"last heard {now - c.last_heard:.1f} s ago"
                done = "not joined" if c.done_ns is None else f"done through {c.done_ns / 1e9:.6f} s"
                parts.append(f"{c.name} ({done}, {heard}" + (", timed out" if c.timed_out else "") + ")")
        return ", ".join(parts) or "nobody"

    def _wait_for_matches(self) -> None:
        """Wait (bounded) until DDS has matched every subscription the graph shows to its publisher.

        A volatile topic reaches only the readers its writer has matched, and the graph can show a new
        subscriber some milliseconds before the match: without this wait a reader the caller saw (`rimd rig`, a
        lockstep consumer that just joined) could miss the first blocks. This node's own view of the graph can
        lag the consumer's too (under load, by more than the match): a joining consumer names its node and
        topics, and the wait lasts until the graph here shows that node's readers of them, and they are matched.
        """
        deadline = time.monotonic() + MATCH_TIMEOUT_S
        joining = dict(self._joining)   # a join that comes meanwhile sets _match_pending again
        self._match_pending = False
        while (unmatched := self._unmatched(joining)) and time.monotonic() < deadline and not self._stop.is_set():
            time.sleep(0.005)
        if unmatched:
            self.get_logger().warning(f"publishing although readers of {', '.join(unmatched)} are not matched after "
                                      f"{MATCH_TIMEOUT_S:g} s: they may miss blocks")
        for node in joining:
            self._joining.pop(node, None)

    def _unmatched(self, joining: dict[str, list[str]] | None = None) -> list[str]:
        """Topics whose publisher has not matched every subscription the graph shows yet (DDS discovery).

        Also the topics of a joining consumer whose reader this node's graph does not show yet.
        """
        out = [p.topic_name for p in self._all_publishers()
               if p.get_subscription_count() < self.count_subscribers(p.topic_name)]
        for node, topics in (joining or {}).items():
            for topic in topics:
                readers = {(i.node_namespace.rstrip("/") + "/" + i.node_name)
                           for i in self.get_subscriptions_info_by_topic(topic)}
                if node not in readers:
                    out.append(f"{topic} (by {node})")
        return out

    def _on_progress(self, msg: ConsumerProgress) -> None:
        topics = None
        if msg.topics:
            if len(msg.topics) != len(msg.topics_done_through):
                self._warn_once(msg.consumer, "arrays", f"lockstep: progress from '{msg.consumer}' ignored: "
                                f"{len(msg.topics)} topics but {len(msg.topics_done_through)} topics_done_through")
                return
            topics = {t: from_time(d) for t, d in zip(msg.topics, msg.topics_done_through, strict=True)}
        with self._pace_lock:
            assert self._pacer.lockstep is not None   # progress is taken only in lockstep
            verdict = self._pacer.lockstep.progress(msg.consumer, from_time(msg.done_through), msg.instance, topics,
                                                    leaving=msg.leaving)
        if verdict.joined:   # its subscriptions may be newer than its report: let DDS match them first
            if msg.node:
                published = set(self._topic.values())
                self._joining[msg.node] = [t for t in (msg.topics or published) if t in published]
            self._match_pending = True
        if verdict.log and verdict.accepted and verdict.reason != "topics":
            self.get_logger().info(f"lockstep: {verdict.log}")
        elif verdict.log:   # ignored, or topics of other publishers left out: said once per consumer and reason
            self._warn_once(msg.consumer, verdict.reason, f"lockstep: {verdict.log}")
        self._wake.set()

    def _warn_once(self, who: str, kind: str, line: str) -> None:
        """Log a warning about ``who`` once per kind (a misbehaving consumer would flood the log otherwise)."""
        if (who, kind) not in self._warned:
            self._warned.add((who, kind))
            self.get_logger().warning(line + " (said once)")

    def _refresh_static_fields(self) -> None:
        """Set the fields of the reused channel messages that only change with the configuration."""
        for ch in self._config.channels:
            self._encoders[ch.name] = SampleBlockEncoder(ch.frame_id, ch.sample_rate, ch.unit, ch.range_min,
                                                         ch.range_max)

    def _sample_stamp_ns(self, n: int, rate: Fraction) -> int:
        """Stamp of sample ``n`` of a channel at ``rate``: ``t0 + n / rate`` in exact integer nanoseconds."""
        num = n * 1_000_000_000 * rate.denominator
        return self._t0_ns + (2 * num + rate.numerator) // (2 * rate.numerator)

    def _send(self, pub: Any, msg: Any, stamp: int) -> None:
        """Publish ``msg`` stamped ``stamp`` (the pacer learns it first: a consumer may answer at once)."""
        topic = self._topic[id(pub)]
        if self._lockstep is not None:
            with self._pace_lock:
                self._pacer.published(stamp, topic)
        pub.publish(msg)
        self._sent[topic] = self._sent.get(topic, 0) + 1

    def _publish(self, block: SimBlock) -> None:
        # Messages are reused (publish serialises at once); only the fields that change are set.
        t0 = self._t0_ns
        last_due = None
        for name in CHANNEL_NAMES:
            rate = self._rates[name]
            for ch in block.deliveries[name]:   # after dropout, block loss and delay
                stamp = self._sample_stamp_ns(ch.first_index, rate)
                sec, nanosec = divmod(stamp, 1_000_000_000)
                self._send(self._pubs[name], self._encoders[name].encode(sec, nanosec, ch.first_index, ch.samples,
                                                                        ch.saturated), stamp)
                if len(ch.samples):
                    last = self._sample_stamp_ns(ch.first_index + len(ch.samples) - 1, rate)
                    last_due = last if last_due is None else max(last_due, last)
        for cap in block.captures:
            stamp = stamp_ns(t0, cap.trigger_time)
            for which, values, channel in (("force", cap.force, "impact_force"),
                                           ("acceleration", cap.acceleration, "rimd_acceleration")):
                cm = Capture()
                cm.header.stamp = to_time(stamp)
                cm.header.frame_id = self._config.channel(channel).frame_id
                cm.index = cap.number
                cm.sample_rate = cap.sample_rate
                cm.pre_trigger_samples = cap.pre_trigger_samples
                a = array.array("d")
                a.frombytes(values.tobytes())
                cm.samples = a
                cm.unit = self._config.channel(channel).unit
                cm.trigger_level = cap.threshold
                self._send(self._pub_captures[which], cm, stamp)
        for event in block.fault_events:
            spec = event.fault
            fe = FaultEvent()
            stamp = stamp_ns(t0, event.time)
            fe.header.stamp = to_time(stamp)
            fe.header.frame_id = (self._config.channel(spec.channel).frame_id if spec.channel in self._rates
                                  else spec.channel)
            fe.event = event.event
            fe.id = spec.number
            fe.channel = spec.channel
            fe.kind = spec.kind
            fe.start = float(spec.start)
            fe.duration = float(spec.duration)
            fe.magnitude = spec.magnitude
            fe.detail = event.detail
            self._send(self._pub_faults, fe, stamp)
            self._fault_events += 1
            self.get_logger().info(f"fault {spec.number} {event.event} at simulation time {float(event.time):.6f} s "
                                   f"(stamp {show_stamp(stamp)}): {event.detail}")
        if block.truth is not None:
            msg = self._truth_message(block)
            self._send(self._pub_truth, msg, from_time(msg.header.stamp))
        for imp in block.impacts:
            ev = ImpactEvent()
            stamp = t0 + round(imp.t_start * 1e9)
            ev.header.stamp = to_time(stamp)
            ev.header.frame_id = "impact_force_sensor"
            ev.duration = imp.duration
            ev.peak_force = imp.peak_force
            ev.impulse = imp.impulse
            ev.impact_velocity = imp.impact_velocity
            ev.max_penetration = imp.max_penetration
            ev.excitation_frequency = imp.excitation_frequency
            ev.excitation_phase = imp.excitation_phase
            ev.cycle_index = imp.cycle_index
            ev.index = imp.index
            self._send(self._pub_events, ev, stamp)
            self._impacts += 1
        m = block.motor
        ms = self._motor_msg
        end = stamp_ns(t0, block.t_stop)
        ms.header.stamp = to_time(end)
        ms.frequency_setpoint = m.frequency_setpoint
        ms.frequency = m.frequency
        ms.phase = m.phase
        ms.cycle_index = max(m.cycle_index, 0)
        ms.ramp_rate = m.ramp_rate
        ms.cart_position = m.cart_position
        self._send(self._pub_motor, ms, end)
        if not self._wall_clock:
            self._clock_msg.clock = to_time(end)
            self._send(self._pub_clock, self._clock_msg, end)
        for cmd in block.commands:
            self.get_logger().info(f"{cmd.kind} at simulation time {float(cmd.time):.6f} s "
                                   f"(stamp {show_stamp(stamp_ns(t0, cmd.time))}): {cmd.detail}")
        self._published += 1
        if last_due is not None:
            self._measure_lateness(last_due)

    def _measure_lateness(self, due_ns: int) -> None:
        """How late the block left against the time its last sample was due, as a subscriber sees it.

        Wall-clock stamps: the wall clock now against the last sample's stamp (what a subscriber computes).
        Otherwise the pacing schedule's due time of that sample (none as fast as possible).
        """
        if self._wall_clock:
            late = (time.time_ns() - due_ns) / 1e9 - self._paused_wall
        else:
            with self._pace_lock:
                due = self._pacer.schedule.due(due_ns)
            if not math.isfinite(due):
                return
            late = time.monotonic() - due
        self._lateness.append(late)
        if late > 1.0 / float(self._block_rate):
            self._overruns += 1

    def _truth_message(self, block: SimBlock) -> RigState:
        assert block.truth is not None   # the truth is published only when simulated
        first, rows = block.truth
        msg = self._truth_msg
        msg.header.stamp = to_time(self._sample_stamp_ns(first, self._truth_rate))
        msg.first_index = first
        for i, field in enumerate(TRUTH_ARRAY_FIELDS):
            a = array.array("d")
            a.frombytes(rows[i].tobytes())
            setattr(msg, field, a)
        msg.in_contact = (rows[10] != 0.0).tolist()
        return msg

    def _publish_diagnostics(self) -> None:
        lat = sorted(self._lateness)
        p50 = lat[len(lat) // 2] if lat else 0.0
        p99 = lat[min(len(lat) - 1, int(0.99 * len(lat)))] if lat else 0.0
        sim_t = float(self._sim.time)
        status = DiagnosticStatus()
        status.name = f"{self.get_name()}: pacing"
        status.hardware_id = "rimd_virtual_rig"
        status.level = DiagnosticStatus.OK
        status.message = "paused" if self._paused else "running" if self._started else "waiting to start"
        if self._overruns:
            status.level = DiagnosticStatus.WARN
            status.message += f", {self._overruns} overruns (blocks later than one block period)"
        holding = ""
        if self._lockstep is not None and self._pacer.held:
            now = time.monotonic()
            with self._pace_lock:
                assert self._pacer.lockstep is not None   # self._lockstep
                holders = self._pacer.lockstep.holders()
                since = min((c.held_since for c in holders if c.held_since is not None), default=now)
                timed_out = any(c.timed_out for c in holders)
            if now - since >= HOLD_REPORT_S:
                holding = self._hold_text(now)
                status.level = max(status.level, DiagnosticStatus.ERROR if timed_out else DiagnosticStatus.WARN)
                status.message += f", lockstep holding for {now - since:.1f} s: waiting for {holding}"
        if self._last_error:
            status.level = DiagnosticStatus.ERROR
            status.message = f"stopped: {self._last_error}"
        wall = time.monotonic() - self._pacer.schedule.wall_ref   # since the last anchor
        values = {
            "simulation_time_s": f"{sim_t:.6f}",
            "run_id": self._run_id,
            "time_base": "wall_clock" if self._wall_clock else "simulation",
            "real_time_factor_target": f"{self._rtf:g}",
            "real_time_factor_achieved": (f"{(self._block / float(self._block_rate) - self._anchor_sim()) / wall:.3f}"
                                          if wall > 0 and self._started else "0"),
            "blocks_published": str(self._published),
            "impacts_published": str(self._impacts),
            "lateness_p50_ms": f"{p50 * 1e3:.3f}",
            "lateness_p99_ms": f"{p99 * 1e3:.3f}",
            "overruns": str(self._overruns),
            "dropped_blocks": "0",
            "paused": str(self._paused).lower(),
        }
        if self._wall_clock:
            values["stamps_behind_wall_clock_s"] = f"{self._paused_wall:.3f}"
        for pub in self._all_publishers():   # per topic: what went out, and to how many matched subscribers
            values[f"{pub.topic_name} published"] = str(self._sent.get(pub.topic_name, 0))
            values[f"{pub.topic_name} subscribers"] = str(pub.get_subscription_count())
        if self._lockstep is not None:
            values["lockstep_waiting_for"] = holding
            with self._pace_lock:
                assert self._pacer.lockstep is not None   # self._lockstep
                for c in self._pacer.lockstep.consumers.values():
                    values[f"lockstep {c.name} done_through_s"] = "" if c.done_ns is None else f"{c.done_ns / 1e9:.6f}"
                    values[f"lockstep {c.name} state"] = (
                        "left" if c.left else "dropped" if c.dropped else "timed out" if c.timed_out
                        else "not joined" if c.done_ns is None else "joined")
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        faults = DiagnosticStatus()
        faults.name = f"{self.get_name()}: faults"
        faults.hardware_id = "rimd_virtual_rig"
        with self._lock:
            active = self._sim.active_faults()
        faults.level = DiagnosticStatus.WARN if active else DiagnosticStatus.OK
        faults.message = (f"{len(active)} fault(s) active: " + ", ".join(f"{f.kind} on {f.channel}" for f in active)
                          if active else "no fault active")
        faults.values = [KeyValue(key=f"fault_{f.number}", value=(
            f"{f.kind} on {f.channel} from simulation time {float(f.start):.6f} s, "
            + (f"duration {float(f.duration):g} s" if f.duration else "until cleared")
            + f", magnitude {f.magnitude:g}")) for f in active]
        faults.values.append(KeyValue(key="fault_events_published", value=str(self._fault_events)))
        arr.status = [status, faults]
        self._pub_diag.publish(arr)

    def _anchor_sim(self) -> float:
        """Simulation time of the pacing's last anchor (s)."""
        return (self._pacer.schedule.data_ref - self._t0_ns) / 1e9

    # ---- services ----------------------------------------------------------------------------------

    def _start_time(self, stamp: Time) -> Fraction | None:
        """Simulation time of a request's ``start_stamp`` (None for zero: the next block boundary).

        Raises:
            CommandError: A stamp before the rig's start, already passed, or more than a day ahead.
        """
        if stamp.nanosec >= 1_000_000_000:  # builtin_interfaces/Time: nanosec in [0, 1e9)
            raise CommandError(f"start_stamp.nanosec = {stamp.nanosec} refused: must be < 1000000000 "
                               "(the seconds go in start_stamp.sec)")
        ns = from_time(stamp)
        if ns == 0:
            return None
        t = Fraction(ns - self._t0_ns, 1_000_000_000)
        now = self._sim.time
        rule = "must be zero (next block boundary) or a stamp from now to one day ahead in the rig's time base"
        if t < now:
            raise CommandError(f"start_stamp {stamp.sec}.{stamp.nanosec:09d} refused: already passed "
                               f"(the rig is at stamp {show_stamp(stamp_ns(self._t0_ns, now))}, simulation time "
                               f"{float(now):.6f} s); {rule}")
        if t - now > MAX_SCHEDULE_AHEAD_S:
            raise CommandError(f"start_stamp {stamp.sec}.{stamp.nanosec:09d} refused: {float(t - now):.6g} s "
                               f"ahead of the rig; {rule}")
        return t

    def _when(self, t: Fraction) -> str:
        """A time as users read it: simulation time and stamp, each naming its base."""
        return f"simulation time {float(t):.6f} s (stamp {show_stamp(stamp_ns(self._t0_ns, t))})"

    def _on_set_motor_frequency(self, request, response):
        with self._lock:
            try:
                at = self._start_time(request.start_stamp)
                # The core takes any finite ramp rate >= 0; the rig's bound is motor.ramp_rate's (a ramp of
                # 1e300 Hz/s is a jump, which the motor cannot do).
                if request.ramp_rate > MAX_RAMP_RATE:
                    raise CommandError(f"ramp_rate = {request.ramp_rate!r} refused: must be <= {MAX_RAMP_RATE:g} "
                                       "Hz/s (0 = motor.ramp_rate)")
                when = self._sim.set_motor_frequency(request.frequency_hz, request.ramp_rate, at=at)
            except CommandError as exc:
                response.success = False
                response.message = str(exc)
                response.frequency_hz = self._current_setpoint()
                self.get_logger().warning(f"set_motor_frequency refused: {exc}")
                return response
            rate = request.ramp_rate or self._config.motor.ramp_rate
            response.success = True
            response.message = f"setpoint {request.frequency_hz:g} Hz at {rate:g} Hz/s from {self._when(when)}"
            response.frequency_hz = float(request.frequency_hz)
            response.effective_stamp = to_time(stamp_ns(self._t0_ns, when))
        self._wake.set()
        return response

    def _current_setpoint(self) -> float:
        return float(self._sim.model.motor_state().frequency_setpoint)

    def _on_perturb(self, request, response):
        with self._lock:
            try:
                when = self._sim.perturb(request.velocity, at=self._start_time(request.start_stamp))
            except CommandError as exc:
                response.success = False
                response.message = str(exc)
                return response
            response.success = True
            response.message = f"hammer velocity {request.velocity:+g} m/s at {self._when(when)}"
            response.effective_stamp = to_time(stamp_ns(self._t0_ns, when))
        return response

    def _load_faults(self, entries: tuple[str, ...]) -> None:
        """Schedule the faults of the ``faults`` parameter (a refusal stops the node with the reason)."""
        for i, entry in enumerate(entries):
            if not entry.strip():
                continue
            try:
                fault = parse_fault_entry(entry, f"faults[{i}]")
                self._sim.inject_fault(**fault)
            except CommandError as exc:
                raise ConfigError("faults", entry, f"faults[{i}]: {exc}") from None

    def _on_inject_fault(self, request, response):
        with self._lock:
            try:
                spec = self._sim.inject_fault(request.channel, request.kind, request.start, request.duration,
                                              request.magnitude, after=request.after)
            except CommandError as exc:
                response.success = False
                response.message = str(exc)
                self.get_logger().warning(f"inject_fault refused: {exc}")
                return response
            response.success = True
            response.message = (f"fault {spec.number}: {spec.kind} on {spec.channel} from {self._when(spec.start)}"
                                + (f" for {float(spec.duration):g} s" if spec.duration else " until cleared"))
            response.effective_stamp = to_time(stamp_ns(self._t0_ns, spec.start))
        self._wake.set()
        return response

    def _on_clear_faults(self, request, response):
        with self._lock:
            ended, cancelled = self._sim.clear_faults()
            now = self._sim.time
        response.success = True
        response.message = (f"faults cleared at {self._when(now)}: {ended} ended, {cancelled} scheduled ones "
                            "cancelled")
        self.get_logger().info(response.message)
        return response

    def _on_reset(self, request, response):
        with self._lock:
            when = self._sim.reset()
            if self._started:
                self._new_session("reset", when)
        response.success = True
        response.message = (f"hammer reset to its initial state at {self._when(when)} (motor unchanged); "
                            f"run {self._run_id}")
        return response

    def _on_pause(self, request, response):
        with self._lock:   # the pacing thread checks _paused under this lock: no block is computed after it
            if self._paused:
                response.success = False
                response.message = f"already paused at {self._when(self._sim.time)}"
                return response
            self._paused = True
            self._paused_at = time.monotonic()
            frozen = self._sim.time
        response.success = True
        response.message = f"paused at {self._when(frozen)} (simulation time frozen)"
        self.get_logger().info(response.message)
        return response

    def _on_resume(self, request, response):
        if not self._started and self._paused:
            self._wait_for_matches()   # sample 0 goes once DDS has matched the readers the caller saw
        with self._lock:
            if not self._paused:
                response.success = False
                response.message = "not paused"
                return response
            self._paused = False
            if not self._started:
                self._begin()
            else:
                if self._paused_at is not None:
                    self._paused_wall += time.monotonic() - self._paused_at
                with self._pace_lock:
                    self._pacer.schedule.anchor(stamp_ns(self._t0_ns, self._sim.time))
            self._paused_at = None
        self._wake.set()
        response.success = True
        response.message = f"resumed at {self._when(self._sim.time)}"
        self.get_logger().info(response.message)
        return response

    # ---- parameters --------------------------------------------------------------------------------

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        """Set parameters; rclpy's parameter services (set_parameters, set_parameters_atomically) come here.

        Every refusal names the parameter and its rule (:func:`refuse_unnamed`), and a refusal leaves the
        descriptors as they were: rclpy sets a dynamically typed parameter's descriptor type (every float
        here) to the type of the value before the value is checked, so ``describe_parameters`` reported
        ``gap`` as a string after ``gap := 'abc'`` was refused.
        """
        refusal = refuse_unnamed(self, parameter_list)
        if refusal is not None:
            return refusal
        types = {p.name: self.describe_parameter(p.name).type for p in parameter_list}
        result = super().set_parameters_atomically(parameter_list)
        if not result.successful:
            for name, kind in types.items():
                self.describe_parameter(name).type = kind  # rclpy's own descriptor object
        return result

    def _on_set_parameters(self, params) -> SetParametersResult:
        changes = {}
        for p in params:
            if p.name not in PARAMETERS:
                # Only use_sim_time gets here (the node's own parameters are read-only; undeclared names are
                # refused before): the rig's stamps follow its own clock, always.
                return SetParametersResult(successful=False, reason=(
                    f"parameter '{p.name}' = {p.value!r} refused: read at start only, it cannot change while "
                    "the rig runs"))
            if p.name.endswith(".reliable"):
                # The publishers' QoS is set when they are created: a change was accepted and had no effect.
                return SetParametersResult(successful=False, reason=(
                    f"parameter '{p.name}' = {p.value!r} refused: read at start only, the channel's QoS cannot "
                    "change while the rig runs"))
            changes[p.name] = p.value
        with self._lock:
            try:
                config = self._config.with_parameters(changes)
                if self._wall_clock and config.real_time_factor != 1.0:
                    raise ConfigError("real_time_factor", config.real_time_factor,
                                      "cannot switch from 1 while running: the stamps are wall-clock at real time "
                                      "(restart the rig with another factor)")
                if not self._wall_clock and config.real_time_factor == 1.0 and self._lockstep is None:
                    raise ConfigError("real_time_factor", config.real_time_factor,
                                      "cannot switch to 1 while running: the stamps are simulation time (restart "
                                      "the rig at real time for wall-clock stamps)")
                core = {k: v for k, v in changes.items() if k not in NODE_ONLY_PARAMETERS}
                if core:
                    when = self._sim.set_parameters(core)
                    self.get_logger().info(f"parameters {core} take effect at {self._when(when)}")
            except (ConfigError, CommandError) as exc:
                self.get_logger().warning(f"parameter change refused: {exc}")
                return SetParametersResult(successful=False, reason=str(exc))
            if "real_time_factor" in changes or "block_rate" in changes:
                self._retime(config)
            self._config = config
            self._refresh_static_fields()
        self._wake.set()
        return SetParametersResult(successful=True)

    def _retime(self, config: SimConfig) -> None:
        """Apply a new pacing from the current block boundary on."""
        t = self._sim.time
        new_rate = Fraction(repr(config.block_rate))
        # Blocks continue from the current time: the block counter is re-based on the new rate.
        self._block_rate = new_rate
        self._block = math.floor(t * new_rate)
        self._rtf = config.real_time_factor
        with self._pace_lock:
            self._pacer.schedule.set_factor(self._rtf, stamp_ns(self._t0_ns, t))


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``rimd_simulator`` executable (also ``rimd node simulator``)."""

    def spin(node: SimulatorNode, executor, stop) -> None:
        node.start()
        spin_until_stopped(executor, stop)

    return run_node("rimd_simulator", SimulatorNode, (ConfigError,), args=args,
                    refused_prefix="configuration refused: ",
                    spin=spin, close=lambda node: node.shutdown())

if __name__ == "__main__":
    sys.exit(main())
