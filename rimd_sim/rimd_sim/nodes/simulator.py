"""Node ``rimd_simulator``: the rig on DDS, behaving like hardware for DAQ software (SPEC sections 4-5).

A thin adapter over :class:`rimd_sim.core.simulator.RigSimulator`:

* the constructor declares every parameter of :data:`rimd_sim.core.config.PARAMETERS` with a descriptor
  (description, rule, range), builds the validated configuration, creates publishers and services;
* a pacing thread advances the core block by block in simulation time and publishes each block when it
  is due (``real_time_factor`` > 0: at ``t0 + t_sim / factor`` of the wall clock) or at once
  (``real_time_factor`` 0, with ``/clock``). The core advances by its own exact clock: a late thread only
  delays the data, never changes it; lateness and overruns go to ``/diagnostics``;
* services and parameter changes run on the executor; each is validated at once (a refusal answers
  ``success = false`` with the reason and changes nothing) and takes effect at the next block boundary in
  simulation time, which the response and the log state.

Time base: at ``real_time_factor`` 1 the stamps are wall-clock (sample ``n`` at ``t0 + n / rate`` with
``t0`` the wall time of the start, whole milliseconds); otherwise the simulation time itself (``t0 = 0``)
and ``/clock`` is published so that subscribers with ``use_sim_time`` see a consistent world.
"""

from __future__ import annotations

import array
import math
import sys
import threading
import time
import traceback
from collections import deque
from fractions import Fraction
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from rimd_msgs.msg import Capture, FaultEvent, ImpactEvent, MotorState, RigState, SampleBlock
from rimd_msgs.srv import InjectFault, Perturb, SetMotorFrequency
from rimd_sim.core import CHANNEL_NAMES, CommandError, ConfigError, IntegrationError, SimConfig
from rimd_sim.core.capture import CAPTURE_PARAMETERS, CaptureConfig
from rimd_sim.core.config import MAX_RAMP_RATE, PARAMETERS
from rimd_sim.core.faults import parse_fault_entry
from rimd_sim.core.simulator import NODE_ONLY_PARAMETERS, RigSimulator, SimBlock
from rimd_sim.nodes._params import refuse_unnamed
from rimd_sim.nodes._run import run_node, spin_until_stopped
from rimd_sim.recording.cdr import SampleBlockEncoder

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

#: Longest the first resume waits for DDS to match the readers the graph already shows (s).
RESUME_MATCH_TIMEOUT_S = 2.0
#: Longest a command may be scheduled ahead of the simulation (s of simulation time).
MAX_SCHEDULE_AHEAD_S = 86_400

_ROS_TYPES = {"float": 3, "int": 2, "bool": 1, "str": 4}  # rcl_interfaces ParameterType values


def stamp_ns(t0_ns: int, t: Fraction) -> int:
    """ROS time in integer nanoseconds of simulation time ``t`` (exact, rounded to the nearest ns)."""
    return t0_ns + round(t * 1_000_000_000)


def to_time(ns: int) -> Time:
    """``builtin_interfaces/Time`` from integer nanoseconds."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _descriptor(name: str) -> ParameterDescriptor:
    spec = PARAMETERS[name]
    desc = ParameterDescriptor(
        name=name,
        type=_ROS_TYPES[spec.kind],
        description=spec.description,
        additional_constraints=spec.rule,
        # Floats accept integers written in YAML (``gap: 0``); the core checks type and rule itself.
        dynamic_typing=spec.kind == "float",
    )
    if spec.kind == "float" and spec.low is not None and spec.high is not None:
        desc.floating_point_range = [FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high),
                                                        step=0.0)]
    elif spec.kind == "int" and spec.low is not None and spec.high is not None:
        desc.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=0)]
    return desc


class SimulatorNode(Node):
    """The simulator node. See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("namespace", DEFAULT_NAMESPACE)
        super().__init__(NODE_NAME, **kwargs)
        defaults = SimConfig().to_parameters()
        for name in PARAMETERS:
            self.declare_parameter(name, defaults[name], _descriptor(name))
        values = {name: self.get_parameter(name).value for name in PARAMETERS}
        self._config = SimConfig.from_parameters(values)  # ConfigError: caught in main()
        # Node-only, read at start: the triggered capture (rimd_sim.core.capture).
        for name, (default, description) in CAPTURE_PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(
                name=name, type=_ROS_TYPES["bool" if isinstance(default, bool) else "float"], read_only=True,
                description=description, dynamic_typing=not isinstance(default, bool)))
        self._capture = CaptureConfig.from_parameters({n: self.get_parameter(n).value for n in CAPTURE_PARAMETERS})
        self._lock = threading.Lock()
        # Load the compiled kernels now (a throwaway pass), so the first published block is not late.
        RigSimulator(self._config, capture=self._capture).advance_blocks([Fraction(1, 100)])
        self._sim = RigSimulator(self._config, capture=self._capture)
        self._block = 0  # blocks published
        self._rtf = self._config.real_time_factor
        self._block_rate = Fraction(repr(self._config.block_rate))
        self._t0_ns = (time.time_ns() // 1_000_000) * 1_000_000 if self._rtf == 1.0 else 0
        self._wall_ref = time.monotonic()
        self._sim_ref = Fraction(0)
        # Node-only, read at start: wait for /rig/resume (lets recorders and DAQ software connect first, so
        # that they see sample 0). At real time the wall-clock t0 is then taken at the first resume.
        self.declare_parameter("start_paused", False, ParameterDescriptor(
            name="start_paused", type=_ROS_TYPES["bool"], read_only=True,
            description="start paused: publish nothing until /rig/resume (t0 is then the time of that call)"))
        self._paused = bool(self.get_parameter("start_paused").value)
        # Node-only, read at start: the fault scenario (docs/faults.md), one "key=value ..." string per fault.
        self.declare_parameter("faults", [""], ParameterDescriptor(
            name="faults", type=9, read_only=True,  # PARAMETER_STRING_ARRAY
            description="fault scenario loaded at start: one 'channel=NAME kind=KIND start=S duration=S "
                        "magnitude=M' string per fault (\"\" entries are ignored)"))
        self._load_faults(self.get_parameter("faults").value)
        self._started = not self._paused
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._lateness: deque[float] = deque(maxlen=1000)
        self._overruns = 0
        self._published = 0
        self._impacts = 0
        self._last_error = ""

        # History of each publisher: one second of blocks at real time. Faster than real time, 20 s of simulation
        # time (at 20x that is still one second of wall time for a reliable subscriber, such as the recorder,
        # to fall behind without losing a block; memory: about 3 MB per 20 kHz channel).
        seconds = 1 if self._rtf == 1.0 else 20
        depth = max(10, math.ceil(self._config.block_rate * seconds) + 10)
        self._rates = {ch.name: Fraction(repr(ch.sample_rate)) for ch in self._config.channels}
        self._truth_rate = Fraction(repr(self._config.truth_rate))
        # Channel blocks are serialized here, straight from the core's arrays (rimd_sim.recording.cdr), and
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
        self._pub_events = self.create_publisher(ImpactEvent, "impact/events", events_qos)
        self._pub_motor = self.create_publisher(MotorState, "motor/state", reliable)
        self._pub_truth = self.create_publisher(RigState, "truth", reliable)
        # Reliable: compatible with the best-effort subscription of ROS time sources and with reliable ones.
        self._pub_clock = self.create_publisher(Clock, "/clock", QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE))
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._pub_faults = self.create_publisher(FaultEvent, "faults", QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._fault_events = 0
        self._pub_captures = {}
        if self._capture.enabled:
            cap_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=200, reliability=ReliabilityPolicy.RELIABLE)
            self._pub_captures = {"force": self.create_publisher(Capture, "capture/force", cap_qos),
                                  "acceleration": self.create_publisher(Capture, "capture/acceleration", cap_qos)}

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
        self.get_logger().info(
            f"rig ready: gap {self._config.rig.gap * 1e3:g} mm, contact {self._config.rig.contact.model}, "
            f"motor setpoint {self._config.motor.initial_setpoint:g} Hz, real_time_factor {self._rtf:g}, "
            f"{self._config.block_rate:g} blocks/s")

    # ---- life cycle --------------------------------------------------------------------------------

    def start(self) -> None:
        """Start publishing."""
        self._wall_ref = time.monotonic()
        self._thread.start()

    def shutdown(self) -> None:
        """Stop the pacing thread (idempotent)."""
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    # ---- pacing ------------------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                if self._paused:
                    self._wake.wait(0.1)
                    self._wake.clear()
                    continue
                if self._rtf == 0:
                    # As fast as possible: one core pass per 0.1 s of simulation time, published block by
                    # block (advance_blocks gives the same data as block-by-block calls).
                    count = max(1, round(float(self._block_rate) / 10))
                    bounds = [Fraction(self._block + i + 1) / self._block_rate for i in range(count)]
                    with self._lock:
                        if self._paused:   # paused while this thread waited for the lock: nothing more
                            continue
                        blocks = self._sim.advance_blocks(bounds)
                    self._block += count
                    for block in blocks:
                        if not self.context.ok():
                            return
                        self._publish(block)
                    continue
                t_end = Fraction(self._block + 1) / self._block_rate
                if self._rtf > 0:
                    due = self._wall_ref + float(t_end - self._sim_ref) / self._rtf
                    delay = due - time.monotonic()
                    if delay > 0:
                        self._wake.wait(delay)
                        self._wake.clear()
                        continue
                    late = -delay
                    self._lateness.append(late)
                    if late > 1.0 / float(self._block_rate):
                        self._overruns += 1
                with self._lock:
                    if self._paused:   # paused while this thread waited for the lock: nothing more
                        continue
                    block = self._sim.advance(t_end)
                self._block += 1
                if not self.context.ok():
                    return
                self._publish(block)
        except IntegrationError as exc:  # the model cannot continue: say why, keep the services alive
            self._last_error = str(exc)
            self.get_logger().error(f"simulation stopped: {exc}")
        except Exception as exc:  # noqa: BLE001 - at shutdown the context goes away while publishing: not an error
            if self.context.ok():   # a defect: say so where a user looks (log, /diagnostics ERROR), keep services
                self._last_error = f"internal error {type(exc).__name__}: {exc}"
                self.get_logger().error(f"simulation stopped by an internal error (please report it):\n"
                                        f"{traceback.format_exc()}")

    def _refresh_static_fields(self) -> None:
        """Set the fields of the reused channel messages that only change with the configuration."""
        for ch in self._config.channels:
            self._encoders[ch.name] = SampleBlockEncoder(ch.frame_id, ch.sample_rate, ch.unit, ch.range_min,
                                                         ch.range_max)

    def _sample_stamp_ns(self, n: int, rate: Fraction) -> int:
        """Stamp of sample ``n`` of a channel at ``rate``: ``t0 + n / rate`` in exact integer nanoseconds."""
        num = n * 1_000_000_000 * rate.denominator
        return self._t0_ns + (2 * num + rate.numerator) // (2 * rate.numerator)

    def _sample_stamp(self, n: int, rate: Fraction) -> Time:
        """:meth:`_sample_stamp_ns` as a ``builtin_interfaces/Time``."""
        return to_time(self._sample_stamp_ns(n, rate))

    def _publish(self, block: SimBlock) -> None:
        # Messages are reused (publish serialises at once); only the fields that change are set.
        t0 = self._t0_ns
        for name in CHANNEL_NAMES:
            for ch in block.deliveries[name]:   # after dropout, block loss and delay
                sec, nanosec = divmod(self._sample_stamp_ns(ch.first_index, self._rates[name]), 1_000_000_000)
                self._pubs[name].publish(self._encoders[name].encode(sec, nanosec, ch.first_index, ch.samples,
                                                                     ch.saturated))
        for cap in block.captures:
            stamp = to_time(stamp_ns(t0, cap.trigger_time))
            for which, values, channel in (("force", cap.force, "impact_force"),
                                           ("acceleration", cap.acceleration, "rimd_acceleration")):
                cm = Capture()
                cm.header.stamp = stamp
                cm.header.frame_id = self._config.channel(channel).frame_id
                cm.index = cap.number
                cm.sample_rate = cap.sample_rate
                cm.pre_trigger_samples = cap.pre_trigger_samples
                a = array.array("d")
                a.frombytes(values.tobytes())
                cm.samples = a
                cm.unit = self._config.channel(channel).unit
                cm.trigger_level = cap.threshold
                self._pub_captures[which].publish(cm)
        for event in block.fault_events:
            spec = event.fault
            fe = FaultEvent()
            fe.header.stamp = to_time(stamp_ns(t0, event.time))
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
            self._pub_faults.publish(fe)
            self._fault_events += 1
            self.get_logger().info(f"fault {spec.number} {event.event} at t = {float(event.time):.6f} s: "
                                   f"{event.detail}")
        if block.truth is not None:
            self._pub_truth.publish(self._truth_message(block))
        for imp in block.impacts:
            ev = ImpactEvent()
            ev.header.stamp = to_time(t0 + round(imp.t_start * 1e9))
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
            self._pub_events.publish(ev)
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
        self._pub_motor.publish(ms)
        if self._rtf != 1.0:
            self._clock_msg.clock = to_time(end)
            self._pub_clock.publish(self._clock_msg)
        for cmd in block.commands:
            line = f"{cmd.kind} at t = {float(cmd.time):.6f} s: {cmd.detail}"
            self.get_logger().info(line)
        self._published += 1

    def _truth_message(self, block: SimBlock) -> RigState:
        first, rows = block.truth
        msg = self._truth_msg
        msg.header.stamp = self._sample_stamp(first, self._truth_rate)
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
        wall = time.monotonic() - self._wall_ref
        status = DiagnosticStatus()
        status.name = f"{self.get_name()}: pacing"
        status.hardware_id = "rimd_virtual_rig"
        status.level = DiagnosticStatus.OK
        status.message = "running"
        if self._paused:
            status.message = "paused"
        if self._overruns:
            status.level = DiagnosticStatus.WARN
            status.message += f", {self._overruns} overruns (blocks later than one block period)"
        if self._last_error:
            status.level = DiagnosticStatus.ERROR
            status.message = f"stopped: {self._last_error}"
        values = {
            "simulation_time_s": f"{sim_t:.6f}",
            "real_time_factor_target": f"{self._rtf:g}",
            "real_time_factor_achieved": f"{(sim_t - float(self._sim_ref)) / wall:.3f}" if wall > 0 else "0",
            "blocks_published": str(self._published),
            "impacts_published": str(self._impacts),
            "lateness_p50_ms": f"{p50 * 1e3:.3f}",
            "lateness_p99_ms": f"{p99 * 1e3:.3f}",
            "overruns": str(self._overruns),
            "dropped_blocks": "0",
            "paused": str(self._paused).lower(),
        }
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
            f"{f.kind} on {f.channel} from t = {float(f.start):.6f} s, "
            + (f"duration {float(f.duration):g} s" if f.duration else "until cleared")
            + f", magnitude {f.magnitude:g}")) for f in active]
        faults.values.append(KeyValue(key="fault_events_published", value=str(self._fault_events)))
        arr.status = [status, faults]
        self._pub_diag.publish(arr)

    # ---- services ----------------------------------------------------------------------------------

    def _start_time(self, stamp: Time) -> Fraction | None:
        """Simulation time of a request's ``start_stamp`` (None for zero: the next block boundary).

        Raises:
            CommandError: A stamp before the rig's start, already passed, or more than a day ahead.
        """
        if stamp.nanosec >= 1_000_000_000:  # builtin_interfaces/Time: nanosec in [0, 1e9)
            raise CommandError(f"start_stamp.nanosec = {stamp.nanosec} refused: must be < 1000000000 "
                               "(the seconds go in start_stamp.sec)")
        ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
        if ns == 0:
            return None
        t = Fraction(ns - self._t0_ns, 1_000_000_000)
        now = self._sim.time
        rule = "must be zero (next block boundary) or a stamp from now to one day ahead in the rig's time base"
        if t < now:
            raise CommandError(f"start_stamp {stamp.sec}.{stamp.nanosec:09d} refused: already passed "
                               f"(the rig is at {stamp_ns(self._t0_ns, now) / 1e9:.9f}, simulation time "
                               f"{float(now):.6f} s); {rule}")
        if t - now > MAX_SCHEDULE_AHEAD_S:
            raise CommandError(f"start_stamp {stamp.sec}.{stamp.nanosec:09d} refused: {float(t - now):.6g} s "
                               f"ahead of the rig; {rule}")
        return t

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
            response.message = (f"setpoint {request.frequency_hz:g} Hz at {rate:g} Hz/s from t = {float(when):.6f} s "
                                "(simulation time)")
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
            response.message = f"hammer velocity {request.velocity:+g} m/s at t = {float(when):.6f} s"
            response.effective_stamp = to_time(stamp_ns(self._t0_ns, when))
        return response

    def _load_faults(self, entries: list[str]) -> None:
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
                                              request.magnitude)
            except CommandError as exc:
                response.success = False
                response.message = str(exc)
                self.get_logger().warning(f"inject_fault refused: {exc}")
                return response
            response.success = True
            response.message = (f"fault {spec.number}: {spec.kind} on {spec.channel} from t = {float(spec.start):.6f} s"
                                + (f" for {float(spec.duration):g} s" if spec.duration else " until cleared"))
            response.effective_stamp = to_time(stamp_ns(self._t0_ns, spec.start))
        self._wake.set()
        return response

    def _on_clear_faults(self, request, response):
        with self._lock:
            ended, cancelled = self._sim.clear_faults()
            now = self._sim.time
        response.success = True
        response.message = (f"faults cleared at t = {float(now):.6f} s: {ended} ended, {cancelled} scheduled ones "
                            "cancelled")
        self.get_logger().info(response.message)
        return response

    def _on_reset(self, request, response):
        with self._lock:
            when = self._sim.reset()
        response.success = True
        response.message = f"hammer reset to its initial state at t = {float(when):.6f} s (motor unchanged)"
        return response

    def _on_pause(self, request, response):
        with self._lock:   # the pacing thread checks _paused under this lock: no block is computed after it
            if self._paused:
                response.success = False
                response.message = f"already paused at t = {float(self._sim.time):.6f} s"
                return response
            self._paused = True
            frozen = self._sim.time
        response.success = True
        response.message = f"paused at t = {float(frozen):.6f} s (simulation time frozen)"
        self.get_logger().info(response.message)
        return response

    def _unmatched(self) -> list[str]:
        """Topics with a subscription in the ROS graph that its publisher has not matched yet (DDS discovery)."""
        pubs = [*self._pubs.values(), self._pub_events, self._pub_motor, self._pub_truth, *self._pub_captures.values()]
        return [p.topic_name for p in pubs if p.get_subscription_count() < self.count_subscribers(p.topic_name)]

    def _on_resume(self, request, response):
        if not self._started:
            # The first resume starts sample 0, which a volatile topic gives only to readers its publisher has
            # matched. The graph (what a caller such as `rimd rig` sees) can show a subscription some ms
            # before DDS has matched it with this writer: wait for the match (bounded), so that every reader
            # the caller saw gets sample 0.
            deadline = time.monotonic() + RESUME_MATCH_TIMEOUT_S
            while (unmatched := self._unmatched()) and time.monotonic() < deadline:
                time.sleep(0.005)
            if unmatched:
                self.get_logger().warning(f"resuming although readers of {', '.join(unmatched)} are not matched "
                                          f"after {RESUME_MATCH_TIMEOUT_S:g} s: they may miss the first blocks")
        with self._lock:
            if not self._paused:
                response.success = False
                response.message = "not paused"
                return response
            self._sim_ref = self._sim.time
            self._wall_ref = time.monotonic()
            if not self._started and self._rtf == 1.0:
                self._t0_ns = (time.time_ns() // 1_000_000) * 1_000_000
            self._started = True
            self._paused = False
        self._wake.set()
        response.success = True
        response.message = f"resumed at t = {float(self._sim.time):.6f} s"
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
                # Only use_sim_time gets here (start_paused and start_type_description_service are read-only;
                # undeclared names are refused before): the rig's stamps follow its own clock, always.
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
                if config.real_time_factor != self._rtf and 1.0 in (config.real_time_factor, self._rtf):
                    raise ConfigError("real_time_factor", config.real_time_factor,
                                      "cannot switch to or from 1 while running (the time base would change)")
                core = {k: v for k, v in changes.items() if k not in NODE_ONLY_PARAMETERS}
                if core:
                    when = self._sim.set_parameters(core)
                    self.get_logger().info(f"parameters {core} take effect at t = {float(when):.6f} s")
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
        self._sim_ref = t
        self._wall_ref = time.monotonic()


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``rimd_simulator`` executable (also ``rimd node simulator``)."""

    def spin(node: SimulatorNode, executor, stop) -> None:  # noqa: ANN001
        node.start()
        spin_until_stopped(executor, stop)

    return run_node("rimd_simulator", SimulatorNode, (ConfigError,), args=args,
                    refused_prefix="configuration refused: ",
                    spin=spin, close=lambda node: node.shutdown())

if __name__ == "__main__":
    sys.exit(main())
