"""The simulator's runtime: everything the ``rimd_simulator`` node does but its ROS calls. ROS-free, on any clock.

:class:`SimulatorRuntime` drives a :class:`~rimd_sim.instruments.rig_simulator.RigSimulator` (the rig's model and
instruments) with a :class:`~rimd_sim.runtime.pacing.Pacer` and turns its blocks into the serialized messages the
node publishes. The node (:mod:`rimd_sim.ros.nodes.simulator`) creates one publisher per
:func:`~rimd_sim.runtime.publishers.outputs` entry, hands the runtime a ``send(key, data)`` that publishes the bytes,
runs :meth:`SimulatorRuntime.run` on a thread of its own, and maps its services, parameter changes and
``/rig/progress`` reports onto the runtime's methods; the runtime answers with plain data
(:mod:`rimd_sim.runtime.sim_answers`). What it decides:

* **Pacing.** :meth:`SimulatorRuntime.step` is one pass of the pacing loop: it asks the pacer how many of the next
  blocks may go (the clock: ``real_time_factor``, 0 = as fast as possible; the consumers: ``lockstep.*``, with
  their holds, timeouts and drops), advances the core by exactly those blocks and sends their messages, or says
  how long to wait. The core advances by its own exact clock: a late caller only delays the data, never changes
  it. At real time one block goes per pass; otherwise up to ``MAX_BATCH`` blocks share one core pass.
* **Time base** (:mod:`rimd_sim.runtime.stamps`). At ``real_time_factor`` 1 without lockstep the stamps are
  wall-clock: sample ``n`` at ``t0 + n / rate``, ``t0`` the wall time of the run's start in whole milliseconds,
  taken at the same instant as the pacing's anchor. Otherwise they are simulation time from 0 and ``/clock`` is
  published.
* **Commands** (:mod:`rimd_sim.runtime.sim_commands`), validated at once (a refusal answers ``success = false``
  with the reason and changes nothing) and applied at the next block boundary in simulation time, or at the exact
  stamp the request names: motor setpoint, perturbation, fault injection and clearing, reset, pause and resume,
  parameter changes (:mod:`rimd_sim.runtime.sim_settings`).
* **Motor commands from the topic** (``/rig/motor/command``, :meth:`SimulatorRuntime.motor_command`): applied
  at their stamp, or at the next block boundary for stamp zero and for a stamp already simulated (late: counted);
  a refused one is counted and said once per sender. No log line per command (debug level only): a summary every
  ``COMMAND_SUMMARY_S`` while they come, and counts in the diagnostics. In lockstep each command of a controller
  is counted against its progress reports (:meth:`rimd_sim.runtime.pacing.Lockstep.command`, docs/control.md).
* **The run's identity** (``/rig/session``, :mod:`rimd_sim.runtime.session`): each start and each reset opens a
  run with a new ``run_id``, its reason, a sequence number, the stamp of its first sample, the seed, the
  configuration's hash and time base.
* **Diagnostics** (``/diagnostics``, :meth:`SimulatorRuntime.diagnostics`, :mod:`rimd_sim.runtime.sim_diagnostics`):
  pacing state, lateness as a subscriber sees it, per-topic counts, the lockstep consumers, the faults in force.
* **Serialization** (:mod:`rimd_sim.runtime.block_messages`): every message is CDR bytes written straight from the
  core's arrays by the encoders of :mod:`rimd_sim.io.cdr` and :mod:`rimd_sim.io.cdr_write`, the bytes rclpy would
  serialize from the same fields (tests/runtime/test_simulator_runtime.py checks them against rclpy).

It is thread-safe the way the node uses it: one pacing thread calls :meth:`~SimulatorRuntime.step`, the executor
calls the rest. The clocks are injected (``clock``: monotonic seconds; ``wall_ns``: wall time in nanoseconds),
so that every decision can be tested on a fake clock without DDS.
"""

from __future__ import annotations

import math
import threading
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from fractions import Fraction
from typing import Any

from rimd_sim.errors import CommandError, ConfigError, IntegrationError
from rimd_sim.instruments.faults import parse_fault_entry
from rimd_sim.instruments.rig_simulator import NODE_ONLY_PARAMETERS, RigSimulator, SimBlock
from rimd_sim.runtime.block_messages import BlockMessages
from rimd_sim.runtime.pacing import Go, Hold, Pacer, ProgressVerdict, Wait
from rimd_sim.runtime.progress import PACING_STATUS, PUBLISHED_KEY
from rimd_sim.runtime.publishers import CHANNEL_TOPICS, Output, Qos, default_topics, outputs
from rimd_sim.runtime.reader_matches import ReaderMatches
from rimd_sim.runtime.session import SESSION_FRAME, Session, config_hash
from rimd_sim.runtime.sim_answers import ERROR, OK, WARN, Answer, Status, Step
from rimd_sim.runtime.sim_commands import CommandBook, command_time, request_time
from rimd_sim.runtime.sim_diagnostics import Lateness, faults_status, holders_text, lockstep_values
from rimd_sim.runtime.sim_settings import check_time_base, load_settings, running_changes, wall_clock_stamps
from rimd_sim.runtime.stamps import block_end_stamps, show_stamp, stamp_ns
from rimd_sim.settings.config import MAX_RAMP_RATE, SimConfig, SimulatorNodeSettings

# The names the node, the tests and docs/api.md import from here, besides the runtime: re-exported from the
# modules that define them.
__all__ = ["CHANNEL_TOPICS", "ERROR", "OK", "WARN", "Answer", "Output", "Qos", "SimulatorRuntime", "Status", "Step",
           "config_hash", "default_topics", "load_settings", "outputs", "show_stamp", "stamp_ns"]

#: Blocks offered to the pacer at once (one core pass): as fast as possible, 0.1 s of simulation time.
MAX_BATCH = 10
#: Longest wait of one pass of the pacing loop (s): paused, held, or waiting for the clock.
IDLE_S = 0.1
#: A lockstep hold is said in the log and in /diagnostics once it has lasted this long (s), then every REPEAT s.
HOLD_REPORT_S = 0.5
HOLD_REPEAT_S = 10.0


def _no_log(level: str, line: str) -> None:
    del level, line


class SimulatorRuntime:
    """The simulator node's logic: pacing, commands, the run's identity, diagnostics, serialization.

    Args:
        config: The validated configuration (:func:`~rimd_sim.runtime.sim_settings.load_settings`).
        settings: The node's own settings.
        send: Publishes ``data`` (serialized) on the output ``key`` (:func:`~rimd_sim.runtime.publishers.outputs`).
        topics: Output key -> topic name as published (lockstep reports and diagnostics name them); default
            :func:`~rimd_sim.runtime.publishers.default_topics` in ``/rig``.
        node: The node's fully qualified name (the run's identity; the diagnostics use its last part).
        log: ``log(level, line)`` with level ``debug`` (each motor command from the topic), ``info``, ``warning``
            or ``error``.
        clock: Monotonic clock (s).
        wall_ns: Wall clock (ns since the epoch): the stamps' ``t0`` at real time.
        alive: False once the caller's publishers are gone (the loop then stops quietly).
        match: ``match(joining)``: wait, bounded (:mod:`~rimd_sim.runtime.reader_matches`), until the transport
            has matched the readers: before the first block with ``joining`` empty (every reader), and when lockstep
            consumers join with ``joining`` mapping each one's node to the topics its report named, or to None when
            it named none (the readers the graph shows for that node).
        warm_up: Load the compiled kernels now (a throwaway pass), so the first block is not late.

    Raises:
        ConfigError: A refused ``faults`` entry.
    """

    def __init__(self, config: SimConfig, settings: SimulatorNodeSettings, *, send: Callable[[str, bytes], None],
                 topics: Mapping[str, str] | None = None, node: str = "/rig/rimd_simulator",
                 log: Callable[[str, str], None] = _no_log, clock: Callable[[], float] = time.monotonic,
                 wall_ns: Callable[[], int] = time.time_ns, alive: Callable[[], bool] = lambda: True,
                 match: Callable[[dict[str, list[str] | None]], None] | None = None, warm_up: bool = True) -> None:
        self._config = config
        self._settings = settings
        self._lockstep = settings.lockstep if settings.lockstep.enabled else None
        self._capture = settings.capture
        self._send_bytes, self._log, self._clock, self._wall_ns = send, log, clock, wall_ns
        self._alive, self._match = alive, match
        self._node = node
        self._outputs = outputs(config, settings)
        self._topics = dict(topics) if topics is not None else default_topics([o.key for o in self._outputs])
        self._lock = threading.Lock()        # the core and the run's state
        self._pace_lock = threading.Lock()   # the pacer (progress reports come from another thread)
        #: Set to end the caller's wait between two passes (a command, a report, a resume).
        self.wake = threading.Event()
        if warm_up:
            RigSimulator(config, capture=self._capture).advance_blocks([Fraction(1, 100)])
        self._sim = RigSimulator(config, capture=self._capture)
        self._block = 0  # blocks published (at the current block rate)
        self._rtf = config.real_time_factor
        self._block_rate = Fraction(repr(config.block_rate))
        self._ends: list[int] = []
        self._ends_for: tuple[int, Fraction, int] | None = None   # (block, block_rate, t0_ns) of _ends
        self._wall_clock = wall_clock_stamps(config, settings)
        self._t0_ns = 0
        self._paused = settings.start_paused
        self._load_faults(settings.faults)
        self._started = False
        self._lateness = Lateness()
        self._published = self._impacts = self._fault_events = self._sessions = 0
        self._last_error = ""
        self._paused_wall = 0.0    # wall-clock seconds spent paused after the start (stamps lag the wall by it)
        self._paused_at: float | None = None
        self._run_id = ""
        self._hold_reported = 0.0  # monotonic time of the last hold report (0: not reported in this hold)
        self._messages = BlockMessages(config, self._wall_clock)
        self._sent: dict[str, int] = {}   # messages published per topic since the start (diagnostics)
        self._pacer = Pacer(self._rtf, self._lockstep, topics=list(self._topics.values()), clock=clock)
        self._warned: set[tuple[str, str]] = set()
        self._commands = CommandBook()   # motor commands from the topic
        self._matches = ReaderMatches(self._topics.values())   # the readers to match before the next block
        #: The last block the run publishes (``until``: the first block end at or after it), None: no end.
        self._last_block: int | None = (math.ceil(Fraction(repr(settings.until)) * self._block_rate)
                                        if settings.until > 0 else None)
        self._held_said = False

    # ---- state -------------------------------------------------------------------------------------------------

    @property
    def config(self) -> SimConfig:
        """The configuration in force (parameter changes included)."""
        return self._config

    @property
    def outputs(self) -> tuple[Output, ...]:
        """The publishers the node creates (:func:`outputs`)."""
        return self._outputs

    @property
    def topics(self) -> dict[str, str]:
        """Output key -> topic name."""
        return dict(self._topics)

    @property
    def paused(self) -> bool:
        """Whether the run is paused (or waits for its first resume)."""
        return self._paused

    @property
    def started(self) -> bool:
        """Whether the run has started (its ``t0`` is taken)."""
        return self._started

    @property
    def run_id(self) -> str:
        """The current run's id ('' before the start)."""
        return self._run_id

    @property
    def t0_ns(self) -> int:
        """The stamp of simulation time 0 (0 unless the stamps are wall-clock)."""
        return self._t0_ns

    @property
    def time_base(self) -> str:
        """``wall_clock`` or ``simulation``."""
        return "wall_clock" if self._wall_clock else "simulation"

    @property
    def simulation_time(self) -> Fraction:
        """Simulation time reached (s)."""
        return self._sim.time

    def describe(self) -> str:
        """The line the node logs when it is ready."""
        c = self._config
        pacing = (f"lockstep with {', '.join(self._lockstep.consumers)} (window {self._lockstep.window:g} s, "
                  f"speed cap {self._rtf:g}x)" if self._lockstep is not None else f"real_time_factor {self._rtf:g}")
        return (f"rig ready: gap {c.rig.gap * 1e3:g} mm, contact {c.rig.contact.model}, motor setpoint "
                f"{c.motor.initial_setpoint:g} Hz, {pacing}, {c.block_rate:g} blocks/s; stamps: "
                + ("wall clock" if self._wall_clock else "simulation time from 0, with /clock"))

    # ---- life cycle --------------------------------------------------------------------------------------------

    def start(self) -> None:
        """Start the run now, unless it starts paused (then at the first :meth:`resume`)."""
        if not self._paused:
            self._wait_for_matches(start=True)
            with self._lock:
                self._begin()

    def _begin(self) -> None:
        """The run starts now (call with ``_lock``): take ``t0`` and the pacing anchor at the same instant.

        A block is then due at the wall time its stamps name. A ``t0`` taken before the anchor would make every
        block late by the time between the two, as its subscribers measure lateness, while the pacing's own
        lateness, measured against the anchor, would not show it.
        """
        wall_ns, mono = self._wall_ns(), self._clock()
        if self._wall_clock:
            self._t0_ns = (wall_ns // 1_000_000) * 1_000_000
        start = stamp_ns(self._t0_ns, self._sim.time)
        with self._pace_lock:
            # The stamp t0 + t is due at the wall time it names: the anchor shifted back by the ms rounding of t0.
            self._pacer.schedule.anchor(start, mono - (wall_ns - start) / 1e9 if self._wall_clock else mono)
        self._started = True
        self._new_session("start")

    def _new_session(self, reason: str, at: Fraction | None = None) -> None:
        """Publish the identity of a new run (``session``): at the start and at each reset (call with ``_lock``)."""
        t = self._sim.time if at is None else at
        self._run_id = uuid.uuid4().hex
        session = Session(self._run_id, reason, self._sessions, stamp_ns(self._t0_ns, t), float(t), self.time_base,
                          float(self._rtf), self._lockstep is not None, int(self._config.seed),
                          config_hash(self._config), self._node)
        self._sessions += 1
        self._send("session", session.encode(), session.start_stamp)
        self._log("info", f"run {self._run_id} ({reason}, session {session.sequence}) from simulation time "
                          f"{float(t):.6f} s, stamp {show_stamp(session.start_stamp)} ({session.time_base} time base)")

    def _load_faults(self, entries: tuple[str, ...]) -> None:
        """Schedule the faults of the ``faults`` parameter (a refusal stops the node with the reason)."""
        for i, entry in enumerate(entries):
            if not entry.strip():
                continue
            try:
                self._sim.inject_fault(**parse_fault_entry(entry, f"faults[{i}]"))
            except CommandError as exc:
                raise ConfigError("faults", entry, f"faults[{i}]: {exc}") from None

    def fail(self, reason: str) -> None:
        """Say in the diagnostics that the run stopped (the caller's loop ended on an unexpected error)."""
        self._last_error = reason

    # ---- pacing ------------------------------------------------------------------------------------------------

    def run(self, stop: threading.Event, *, after_pass: Callable[[], None] | None = None,
            report: Callable[[], None] = lambda: None) -> None:
        """The pacing loop: :meth:`step` until ``stop`` is set or a step ends the loop, waiting as each step says.

        A command, a report or a resume (:attr:`wake`) ends a wait sooner.

        Args:
            stop: Set to end the loop at its next pass.
            after_pass: Called after each pass (the composed rig flushes its DDS writes there); what it raises
                ends the loop and reaches the caller.
            report: Publishes the diagnostics, when a step asks for it (a lockstep hold to report).
        """
        while not stop.is_set():
            step = self.step()
            if after_pass is not None:
                after_pass()
            if step.report:
                report()
            if step.stopped:
                return
            if step.wait:
                self.wake.wait(step.wait)
                self.wake.clear()

    def step(self) -> Step:
        """One pass of the pacing loop: send the blocks that may go now, or say how long to wait."""
        if self._paused:
            return Step(IDLE_S)
        ends = self._candidate_ends()
        with self._pace_lock:
            decision = self._pacer.next(ends)
            events = self._pacer.lockstep.take_events() if self._pacer.lockstep is not None else []
        for level, line in events:
            self._log(level, f"lockstep: {line}")
        if isinstance(decision, Hold):
            return Step(IDLE_S, report=self._hold_report(decision))
        self._hold_reported = 0.0
        if isinstance(decision, Wait):
            return Step(min(decision.seconds, IDLE_S))
        assert isinstance(decision, Go)
        if self._matches.pending:
            self._wait_for_matches()
        count = 1 if self._wall_clock else decision.count
        if self._last_block is not None:
            count = min(count, self._last_block - self._block)
            if count <= 0:
                self._say_held()
                return Step(IDLE_S)
        try:
            with self._lock:
                if self._paused:   # paused while the caller waited for the lock: nothing more
                    return Step()
                blocks = self._sim.advance_blocks([Fraction(self._block + i + 1) / self._block_rate
                                                   for i in range(count)])
                self._block += count
        except IntegrationError as exc:  # the model cannot continue: say why, keep the services alive
            self._last_error = str(exc)
            self._log("error", f"simulation stopped: {exc}")
            return Step(stopped=True)
        for block in blocks:
            if not self._alive():
                return Step(stopped=True)
            self._publish(block)
        return Step()

    def _say_held(self) -> None:
        """Say once that the run reached ``until`` and holds there."""
        if not self._held_said:
            self._held_said = True
            self._log("info", f"until: holding at simulation time {float(self._sim.time):.6f} s "
                              f"(until {self._settings.until:g} s); nothing more is published")

    def _candidate_ends(self) -> list[int]:
        """The stamps (ns) at which the next MAX_BATCH blocks end, kept until a block goes (asked twice a block)."""
        key = (self._block, self._block_rate, self._t0_ns)
        if self._ends_for != key:
            self._ends = block_end_stamps(self._t0_ns, self._block + 1, MAX_BATCH, self._block_rate)
            self._ends_for = key
        return self._ends

    def _hold_report(self, hold: Hold) -> bool:
        """Say which consumers hold the run and since when: once it has lasted HOLD_REPORT_S, then every REPEAT s."""
        now = self._clock()
        held = now - hold.since
        if held < HOLD_REPORT_S or (self._hold_reported and now - self._hold_reported < HOLD_REPEAT_S):
            return False
        self._hold_reported = now
        self._log("warning", f"lockstep: holding at simulation time {float(self._sim.time):.6f} s for {held:.1f} s, "
                             f"waiting for {self._hold_text(now)}")
        return True

    def _hold_text(self, now: float) -> str:
        """The consumers that hold the run, in words (:func:`~rimd_sim.runtime.sim_diagnostics.holders_text`)."""
        with self._pace_lock:
            holders = self._pacer.lockstep.holders() if self._pacer.lockstep is not None else []
            return holders_text(holders, now)

    def _wait_for_matches(self, start: bool = False) -> None:
        """Let the caller wait until the transport matched the readers (:class:`.ReaderMatches`).

        Every one at the ``start`` (the first block) and after a join of a consumer that did not name its node;
        the readers of the consumers that joined since the last wait.
        """
        everyone, joining = self._matches.take(start)
        if self._match is not None:
            if everyone:
                self._match({})
            if joining:
                self._match(joining)
        self._matches.matched(joining)

    def progress(self, consumer: str, done_ns: int, *, instance: str = "", topics: Sequence[str] = (),
                 topics_done_ns: Sequence[int] = (), leaving: bool = False, node: str = "", controls: bool = False,
                 commands: int = 0) -> None:
        """A lockstep consumer's progress report (``rimd_msgs/msg/ConsumerProgress``; see :mod:`.pacing`).

        ``controls`` and ``commands``: a controller's (docs/control.md); a report that counts commands not received
        yet is taken when the last of them comes (:meth:`motor_command`).
        """
        if self._pacer.lockstep is None:
            return
        per_topic = None
        if topics:
            if len(topics) != len(topics_done_ns):
                self._warn_once(consumer, "arrays", f"lockstep: progress from '{consumer}' ignored: {len(topics)} "
                                                    f"topics but {len(topics_done_ns)} topics_done_through")
                return
            per_topic = dict(zip(topics, topics_done_ns, strict=True))
        self._matches.reported(consumer, node, topics)   # what a report taken later (commands pending) named
        with self._pace_lock:
            verdict = self._pacer.lockstep.progress(consumer, done_ns, instance, per_topic, leaving=leaving,
                                                    controls=controls, commands=commands)
        self._take_verdict(consumer, verdict)

    def _take_verdict(self, consumer: str, verdict: ProgressVerdict) -> None:
        """Act on a progress report's verdict: the match wait of a join, the log line, the pacing thread woken."""
        if verdict.joined:   # its subscriptions may be newer than its report: let the transport match them first
            self._matches.joined(consumer)
        if verdict.log and verdict.accepted and verdict.reason != "topics":
            self._log("info", f"lockstep: {verdict.log}")
        elif verdict.log:   # ignored, or topics of other publishers left out: said once per consumer and reason
            self._warn_once(consumer, verdict.reason, f"lockstep: {verdict.log}")
        self.wake.set()

    def _warn_once(self, who: str, kind: str, line: str) -> None:
        """Log a warning about ``who`` once per kind (a misbehaving consumer would flood the log otherwise)."""
        if (who, kind) not in self._warned:
            self._warned.add((who, kind))
            self._log("warning", line + " (said once)")

    # ---- the messages of a block -------------------------------------------------------------------------------

    def _send(self, key: str, data: bytes, stamp: int) -> None:
        """Send ``data`` stamped ``stamp`` on ``key`` (the pacer learns it first: a consumer may answer at once)."""
        topic = self._topics[key]
        if self._lockstep is not None:
            with self._pace_lock:
                self._pacer.published(stamp, topic)
        self._send_bytes(key, data)
        self._sent[topic] = self._sent.get(topic, 0) + 1

    def _publish(self, block: SimBlock) -> None:
        """Send the messages of ``block`` (:class:`.BlockMessages`), then count and log what it brought."""
        t0 = self._t0_ns
        for key, data, stamp in self._messages.of(block, t0):
            self._send(key, data, stamp)
        for event in block.fault_events:
            spec = event.fault
            self._fault_events += 1
            self._log("info", f"fault {spec.number} {event.event} at simulation time {float(event.time):.6f} s "
                              f"(stamp {show_stamp(stamp_ns(t0, event.time))}): {event.detail}")
        self._impacts += len(block.impacts)
        for cmd in block.commands:
            if cmd.kind == "motor_command":   # the topic's: counted, summed up every COMMAND_SUMMARY_S
                self._commands.took(f"{cmd.detail} at {self._when(cmd.time)}")
                continue
            self._log("info", f"{cmd.kind} at simulation time {float(cmd.time):.6f} s "
                              f"(stamp {show_stamp(stamp_ns(t0, cmd.time))}): {cmd.detail}")
        self._summarize_commands()
        self._published += 1
        last_due = self._messages.last_sample_stamp(block, t0)
        if last_due is not None:
            self._measure_lateness(last_due)

    def _measure_lateness(self, due_ns: int) -> None:
        """How late the block left against the time its last sample was due, as a subscriber sees it.

        Wall-clock stamps: the wall clock now against the last sample's stamp (what a subscriber computes).
        Otherwise the pacing schedule's due time of that sample (none as fast as possible).
        """
        if self._wall_clock:
            late = (self._wall_ns() - due_ns) / 1e9 - self._paused_wall
        else:
            with self._pace_lock:
                due = self._pacer.schedule.due(due_ns)
            if not math.isfinite(due):
                return
            late = self._clock() - due
        self._lateness.add(late, 1.0 / float(self._block_rate))

    # ---- diagnostics -------------------------------------------------------------------------------------------

    def diagnostics(self, subscribers: Mapping[str, int] | None = None) -> list[Status]:
        """The node's ``/diagnostics``: the pacing status, then the faults status.

        Args:
            subscribers: Topic -> subscriptions its publisher has matched (0 for a topic not given).
        """
        subscribers = subscribers or {}
        p50, p99 = self._lateness.percentiles()
        overruns = self._lateness.overruns
        level = OK
        message = "paused" if self._paused else "running" if self._started else "waiting to start"
        if overruns:
            level = WARN
            message += f", {overruns} overruns (blocks later than one block period)"
        holding = ""
        lockstep = self._pacer.lockstep
        if self._lockstep is not None and lockstep is not None and self._pacer.held:
            now = self._clock()
            with self._pace_lock:
                holders = lockstep.holders()
                since = min((c.held_since for c in holders if c.held_since is not None), default=now)
                timed_out = any(c.timed_out for c in holders)
            if now - since >= HOLD_REPORT_S:
                holding = self._hold_text(now)
                level = max(level, ERROR if timed_out else WARN)
                message += f", lockstep holding for {now - since:.1f} s: waiting for {holding}"
        if self._last_error:
            level = ERROR
            message = f"stopped: {self._last_error}"
        wall = self._clock() - self._pacer.schedule.wall_ref   # since the last anchor
        anchor_sim = (self._pacer.schedule.data_ref - self._t0_ns) / 1e9
        values = {
            "simulation_time_s": f"{float(self._sim.time):.6f}",
            "run_id": self._run_id,
            "time_base": self.time_base,
            "real_time_factor_target": f"{self._rtf:g}",
            "real_time_factor_achieved": (f"{(self._block / float(self._block_rate) - anchor_sim) / wall:.3f}"
                                          if wall > 0 and self._started else "0"),
            "blocks_published": str(self._published),
            "impacts_published": str(self._impacts),
            "lateness_p50_ms": f"{p50 * 1e3:.3f}",
            "lateness_p99_ms": f"{p99 * 1e3:.3f}",
            "overruns": str(overruns),
            "dropped_blocks": "0",
            "paused": str(self._paused).lower(),
            **self._commands.values(),
        }
        if self._wall_clock:
            values["stamps_behind_wall_clock_s"] = f"{self._paused_wall:.3f}"
        for out in self._outputs:   # per topic: what went out, and to how many matched subscribers
            topic = self._topics[out.key]
            values[f"{topic}{PUBLISHED_KEY}"] = str(self._sent.get(topic, 0))
            values[f"{topic} subscribers"] = str(subscribers.get(topic, 0))
        if self._lockstep is not None and lockstep is not None:
            values["lockstep_waiting_for"] = holding
            with self._pace_lock:
                values.update(lockstep_values(lockstep.consumers.values()))
        name = self._node.rsplit("/", 1)[-1]
        pacing = Status(f"{name}{PACING_STATUS}", level, message, SESSION_FRAME, values)
        with self._lock:
            active = self._sim.active_faults()
        return [pacing, faults_status(name, active, self._fault_events)]

    # ---- commands ----------------------------------------------------------------------------------------------

    def _start_time(self, stamp: tuple[int, int]) -> Fraction | None:
        """Simulation time of a request's ``start_stamp`` (:func:`~rimd_sim.runtime.sim_commands.request_time`)."""
        return request_time(stamp, self._t0_ns, self._sim.time)

    def _when(self, t: Fraction) -> str:
        """A time as users read it: simulation time and stamp, each naming its base."""
        return f"simulation time {float(t):.6f} s (stamp {show_stamp(stamp_ns(self._t0_ns, t))})"

    def stamp_of(self, t: Fraction) -> int:
        """The stamp (ns) of simulation time ``t``."""
        return stamp_ns(self._t0_ns, t)

    def set_motor_frequency(self, frequency_hz: float, ramp_rate: float = 0.0,
                            start_stamp: tuple[int, int] = (0, 0)) -> Answer:
        """Ramp the motor to ``frequency_hz`` at ``ramp_rate`` Hz/s (0: ``motor.ramp_rate``) from ``start_stamp``."""
        with self._lock:
            try:
                at = self._start_time(start_stamp)
                # The core takes any finite ramp rate >= 0; the rig's bound is motor.ramp_rate's (a ramp of
                # 1e300 Hz/s is a jump, which the motor cannot do).
                if ramp_rate > MAX_RAMP_RATE:
                    raise CommandError(f"ramp_rate = {ramp_rate!r} refused: must be <= {MAX_RAMP_RATE:g} "
                                       "Hz/s (0 = motor.ramp_rate)")
                when = self._sim.set_motor_frequency(frequency_hz, ramp_rate, at=at)
            except CommandError as exc:
                setpoint = float(self._sim.model.motor_state().frequency_setpoint)
                self._log("warning", f"set_motor_frequency refused: {exc}")
                return Answer(False, str(exc), frequency_hz=setpoint)
            rate = ramp_rate or self._config.motor.ramp_rate
            answer = Answer(True, f"setpoint {frequency_hz:g} Hz at {rate:g} Hz/s from {self._when(when)}",
                            self.stamp_of(when), float(frequency_hz))
        self.wake.set()
        return answer

    def motor_command(self, frequency_hz: float, ramp_rate: float = 0.0, stamp: tuple[int, int] = (0, 0), *,
                      consumer: str = "", instance: str = "", sequence: int = 0) -> None:
        """A motor command from ``/rig/motor/command`` (``rimd_msgs/msg/MotorCommand``; docs/control.md).

        Applied at ``stamp`` (``(sec, nanosec)`` in the rig's time base), or at the next block boundary when it is
        zero or already simulated (late: counted, the worst lateness kept). A refused one (a value out of its range,
        a stamp more than a day ahead) changes nothing; it is counted and said once per sender. Nothing is logged
        per command but at debug level: :meth:`_summarize_commands` sums them up.

        In lockstep a command of a registered consumer (``consumer``, ``instance``) is counted once scheduled: a
        progress report of that consumer that counts it is taken only then (:meth:`.pacing.Lockstep.command`).
        """
        book = self._commands
        sender = consumer or "an unnamed sender"
        late = False
        with self._lock:
            book.received += 1
            now = self._sim.time
            try:
                t = command_time(stamp, ramp_rate, self._t0_ns, now)
                late = t is not None and t < now
                when = self._sim.set_motor_frequency(frequency_hz, ramp_rate, at=None if late else t,
                                                     kind="motor_command")
            except CommandError as exc:
                book.refused += 1
                book.last_refusal = f"from {sender}: {exc}"
                self._warn_once(sender, "motor command refused", f"motor command {sequence} from {sender} refused: "
                                                                 f"{exc}; the next refusals are counted in "
                                                                 "/diagnostics and the summary")
                when = None
            if late and when is not None:
                assert t is not None
                book.late += 1
                book.worst_late_s = max(book.worst_late_s, float(now - t))
        if when is not None:
            self._log("debug", f"motor command {sequence} from {sender}: setpoint {frequency_hz:g} Hz, ramp "
                               f"{ramp_rate:g} Hz/s at {self._when(when)}" + (" (late)" if late else ""))
        if consumer and self._pacer.lockstep is not None:
            with self._pace_lock:
                verdict = self._pacer.lockstep.command(consumer, instance)
            if verdict is not None:
                self._take_verdict(consumer, verdict)
        self.wake.set()

    def _summarize_commands(self) -> None:
        """One log line for the motor commands applied since the last one, at most every COMMAND_SUMMARY_S."""
        line = self._commands.summary(self._clock)
        if line is not None:
            self._log("info", line)

    def perturb(self, velocity: float, start_stamp: tuple[int, int] = (0, 0)) -> Answer:
        """Add ``velocity`` (m/s) to the hammer at ``start_stamp`` (zero: the next block boundary)."""
        with self._lock:
            try:
                when = self._sim.perturb(velocity, at=self._start_time(start_stamp))
            except CommandError as exc:
                return Answer(False, str(exc))
            return Answer(True, f"hammer velocity {velocity:+g} m/s at {self._when(when)}", self.stamp_of(when))

    def inject_fault(self, channel: str, kind: str, start: float = 0.0, duration: float = 0.0,
                     magnitude: float = 0.0, after: float = 0.0) -> Answer:
        """Schedule a sensor fault (docs/faults.md)."""
        with self._lock:
            try:
                spec = self._sim.inject_fault(channel, kind, start, duration, magnitude, after=after)
            except CommandError as exc:
                self._log("warning", f"inject_fault refused: {exc}")
                return Answer(False, str(exc))
            answer = Answer(True, f"fault {spec.number}: {spec.kind} on {spec.channel} from {self._when(spec.start)}"
                            + (f" for {float(spec.duration):g} s" if spec.duration else " until cleared"),
                            self.stamp_of(spec.start))
        self.wake.set()
        return answer

    def clear_faults(self) -> Answer:
        """End every fault in force now and cancel the scheduled ones."""
        with self._lock:
            ended, cancelled = self._sim.clear_faults()
            now = self._sim.time
        answer = Answer(True, f"faults cleared at {self._when(now)}: {ended} ended, {cancelled} scheduled ones "
                              "cancelled")
        self._log("info", answer.message)
        return answer

    def reset(self) -> Answer:
        """Put the hammer back to its initial state at the next block boundary (the motor keeps running): a new run."""
        with self._lock:
            when = self._sim.reset()
            if self._started:
                self._new_session("reset", when)
        return Answer(True, f"hammer reset to its initial state at {self._when(when)} (motor unchanged); "
                            f"run {self._run_id}")

    def pause(self) -> Answer:
        """Freeze simulation time: no block is computed after this returns."""
        with self._lock:   # step() checks _paused under this lock
            if self._paused:
                return Answer(False, f"already paused at {self._when(self._sim.time)}")
            self._paused = True
            self._paused_at = self._clock()
            frozen = self._sim.time
        answer = Answer(True, f"paused at {self._when(frozen)} (simulation time frozen)")
        self._log("info", answer.message)
        return answer

    def resume(self) -> Answer:
        """Go on from where the run was paused; the first resume of a run started paused starts it."""
        if not self._started and self._paused:
            self._wait_for_matches(start=True)   # sample 0 goes once the transport matched the readers the caller saw
        with self._lock:
            if not self._paused:
                return Answer(False, "not paused")
            self._paused = False
            if not self._started:
                self._begin()
            else:
                if self._paused_at is not None:
                    self._paused_wall += self._clock() - self._paused_at
                with self._pace_lock:
                    self._pacer.schedule.anchor(stamp_ns(self._t0_ns, self._sim.time))
            self._paused_at = None
        self.wake.set()
        answer = Answer(True, f"resumed at {self._when(self._sim.time)}")
        self._log("info", answer.message)
        return answer

    def set_parameters(self, changes: Sequence[tuple[str, Any]]) -> str | None:
        """Apply parameter changes (name, value) at the next block boundary; return why they are refused, or None.

        A refusal changes nothing. The node's own parameters, ``use_sim_time`` and the channels' QoS are read at
        start only; the stamps' time base cannot switch while the rig runs.
        """
        accepted, refusal = running_changes(changes)
        if refusal is not None:
            return refusal
        with self._lock:
            try:
                config = self._config.with_parameters(accepted)
                check_time_base(config, self._wall_clock, self._lockstep is not None)
                core = {k: v for k, v in accepted.items() if k not in NODE_ONLY_PARAMETERS}
                if core:
                    when = self._sim.set_parameters(core)
                    self._log("info", f"parameters {core} take effect at {self._when(when)}")
            except (ConfigError, CommandError) as exc:
                self._log("warning", f"parameter change refused: {exc}")
                return str(exc)
            if "real_time_factor" in accepted or "block_rate" in accepted:
                self._retime(config)
            self._config = config
            self._messages.configure(config)
        self.wake.set()
        return None

    def _retime(self, config: SimConfig) -> None:
        """Apply a new pacing from the current block boundary on (call with ``_lock``)."""
        t = self._sim.time
        # Blocks continue from the current time: the block counter is re-based on the new rate.
        self._block_rate = Fraction(repr(config.block_rate))
        self._block = math.floor(t * self._block_rate)
        if self._last_block is not None:
            self._last_block = math.ceil(Fraction(repr(self._settings.until)) * self._block_rate)
        self._rtf = config.real_time_factor
        with self._pace_lock:
            self._pacer.schedule.set_factor(self._rtf, stamp_ns(self._t0_ns, t))
