"""The simulator's runtime: everything the ``rimd_simulator`` node does but its ROS calls. ROS-free, on any clock.

:class:`SimulatorRuntime` drives a :class:`~rimd_sim.instruments.rig_simulator.RigSimulator` (the rig's model and
instruments) with a :class:`~rimd_sim.runtime.pacing.Pacer` and turns its blocks into the serialized messages the
node publishes. The node (:mod:`rimd_sim.ros.nodes.simulator`) creates one publisher per :func:`outputs` entry,
hands the runtime a ``send(key, data)`` that publishes the bytes, and maps its services, parameter changes and
``/rig/progress`` reports onto the runtime's methods; the runtime answers with plain data (:class:`Answer`,
:class:`Status`, :class:`Step`). What it decides:

* **Pacing.** :meth:`SimulatorRuntime.step` is one pass of the pacing loop: it asks the pacer how many of the next
  blocks may go (the clock: ``real_time_factor``, 0 = as fast as possible; the consumers: ``lockstep.*``, with
  their holds, timeouts and drops), advances the core by exactly those blocks and sends their messages, or says
  how long to wait. The core advances by its own exact clock: a late caller only delays the data, never changes
  it. At real time one block goes per pass; otherwise up to ``MAX_BATCH`` blocks share one core pass.
* **Time base.** At ``real_time_factor`` 1 without lockstep the stamps are wall-clock: sample ``n`` at
  ``t0 + n / rate``, ``t0`` the wall time of the run's start in whole milliseconds, taken at the same instant as
  the pacing's anchor. Otherwise they are simulation time from 0 and ``/clock`` is published.
* **Commands**, validated at once (a refusal answers ``success = false`` with the reason and changes nothing)
  and applied at the next block boundary in simulation time, or at the exact stamp the request names: motor
  setpoint, perturbation, fault injection and clearing, reset, pause and resume, parameter changes.
* **Motor commands from the topic** (``/rig/motor/command``, :meth:`SimulatorRuntime.motor_command`): applied
  at their stamp, or at the next block boundary for stamp zero and for a stamp already simulated (late: counted);
  a refused one is counted and said once per sender. No log line per command (debug level only): a summary every
  ``COMMAND_SUMMARY_S`` while they come, and counts in the diagnostics. In lockstep each command of a controller
  is counted against its progress reports (:meth:`rimd_sim.runtime.pacing.Lockstep.command`, docs/control.md).
* **The run's identity** (``/rig/session``): each start and each reset opens a run with a new ``run_id``, its
  reason, a sequence number, the stamp of its first sample, the seed, the configuration's hash and time base.
* **Diagnostics** (``/diagnostics``, :meth:`SimulatorRuntime.diagnostics`): pacing state, lateness as a subscriber
  sees it, per-topic counts, the lockstep consumers, the faults in force.
* **Serialization**: every message is CDR bytes written straight from the core's arrays
  (:class:`rimd_sim.io.cdr.CdrWriter`, :class:`~rimd_sim.io.cdr.SampleBlockEncoder`), the bytes rclpy would
  serialize from the same fields (tests/runtime/test_simulator_runtime.py checks them against rclpy).

It is thread-safe the way the node uses it: one pacing thread calls :meth:`~SimulatorRuntime.step`, the executor
calls the rest. The clocks are injected (``clock``: monotonic seconds; ``wall_ns``: wall time in nanoseconds),
so that every decision can be tested on a fake clock without DDS.
"""

from __future__ import annotations

import hashlib
import json
import math
import struct
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from rimd_sim.errors import CommandError, ConfigError, IntegrationError
from rimd_sim.instruments.faults import parse_fault_entry
from rimd_sim.instruments.rig_simulator import NODE_ONLY_PARAMETERS, RigSimulator, SimBlock
from rimd_sim.io.cdr import BLOCK_ARRAYS, ENCAPSULATION, CdrWriter, SampleBlockEncoder
from rimd_sim.runtime.pacing import Go, Hold, Pacer, ProgressVerdict, Wait
from rimd_sim.runtime.progress import PACING_STATUS, PUBLISHED_KEY
from rimd_sim.settings.config import (
    CHANNEL_NAMES,
    MAX_RAMP_RATE,
    NODE_PARAMETERS,
    PARAMETERS,
    SimConfig,
    SimulatorNodeSettings,
)
from rimd_sim.settings.params import build

__all__ = ["CHANNEL_TOPICS", "Answer", "Output", "Qos", "SimulatorRuntime", "Status", "Step", "config_hash",
           "load_settings", "outputs", "show_stamp", "stamp_ns"]

#: Channel -> topic (the output's key), relative to the node's namespace (``/rig`` by default).
CHANNEL_TOPICS = {
    "cart_displacement": "cart/displacement",
    "rimd_displacement": "rimd/displacement",
    "rimd_acceleration": "rimd/acceleration",
    "impact_force": "impact/force",
}
#: RigState's ``float64[]`` fields, in the order of the core's truth rows (the 11th row, in_contact, is bool[]).
TRUTH_ARRAY_FIELDS = BLOCK_ARRAYS["rimd_msgs/msg/RigState"]
#: Longest a command may be scheduled ahead of the simulation (s of simulation time).
MAX_SCHEDULE_AHEAD_S = 86_400
#: Blocks offered to the pacer at once (one core pass): as fast as possible, 0.1 s of simulation time.
MAX_BATCH = 10
#: Longest wait of one pass of the pacing loop (s): paused, held, or waiting for the clock.
IDLE_S = 0.1
#: A lockstep hold is said in the log and in /diagnostics once it has lasted this long (s), then every REPEAT s.
HOLD_REPORT_S = 0.5
HOLD_REPEAT_S = 10.0
#: Motor commands from the topic are summed up in one log line at most this often (s of wall time), while they come.
COMMAND_SUMMARY_S = 10.0
#: Stamp frame of the run's identity, and the hardware id of the diagnostics.
SESSION_FRAME = "rimd_virtual_rig"
#: Diagnostic levels (diagnostic_msgs/DiagnosticStatus).
OK, WARN, ERROR = 0, 1, 2


# ---- time ----------------------------------------------------------------------------------------------------------

def stamp_ns(t0_ns: int, t: Fraction) -> int:
    """ROS time in integer nanoseconds of simulation time ``t`` (exact, rounded to the nearest ns)."""
    return t0_ns + round(t * 1_000_000_000)


def block_end_stamps(t0_ns: int, first: int, count: int, rate: Fraction) -> list[int]:
    """``stamp_ns(t0_ns, k / rate)`` for the ``count`` block boundaries ``k = first, first + 1, ...``.

    In integers, rounded half to even as ``round`` rounds a Fraction: the pacing asks for them at every pass,
    and a Fraction per boundary cost more than the pass's other pacing work.
    """
    num, den = rate.numerator, rate.denominator
    ends = []
    for k in range(first, first + count):
        q, r = divmod(k * 1_000_000_000 * den, num)
        if 2 * r > num or (2 * r == num and q & 1):
            q += 1
        ends.append(t0_ns + q)
    return ends


def sample_stamp_ns(t0_ns: int, n: int, rate: Fraction) -> int:
    """Stamp of sample ``n`` of a channel at ``rate``: ``t0 + n / rate`` in exact integer nanoseconds."""
    rate_num, rate_den = rate.as_integer_ratio()
    num = n * 1_000_000_000 * rate_den
    return t0_ns + (2 * num + rate_num) // (2 * rate_num)


def show_stamp(ns: int) -> str:
    """A stamp in seconds, exact to the nanosecond (a float would round a 2026 epoch stamp to ~100 ns)."""
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def config_hash(config: SimConfig) -> str:
    """SHA-256 of the configuration's parameters in canonical JSON (sorted keys): the run's configuration id."""
    text = json.dumps(config.to_parameters(), sort_keys=True, default=list, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


# ---- settings and outputs ------------------------------------------------------------------------------------------

def load_settings(values: Mapping[str, Any]) -> tuple[SimConfig, SimulatorNodeSettings]:
    """The configuration and the node's settings from the node's parameter values (as ROS holds them).

    Raises:
        ConfigError: Naming the first refused parameter and its rule.
    """
    config = SimConfig.from_parameters({k: values[k] for k in PARAMETERS if k in values})
    settings = build(SimulatorNodeSettings, {k: values[k] for k in NODE_PARAMETERS if k in values})
    lockstep = settings.lockstep
    if lockstep.enabled and lockstep.window < 2.0 / config.block_rate:
        raise ConfigError("lockstep.window", lockstep.window,
                          f"must be >= two block periods (2 / block_rate = {2.0 / config.block_rate:g} s): "
                          "a consumer reports the stamp of the last block it took, which is a block behind")
    return config, settings


def wall_clock_stamps(config: SimConfig, settings: SimulatorNodeSettings) -> bool:
    """Whether the stamps are wall-clock: only at real time without lockstep."""
    return config.real_time_factor == 1.0 and not settings.lockstep.enabled


@dataclass(frozen=True)
class Qos:
    """A publisher's QoS: keep-last ``depth``, reliable or best effort, volatile or transient local (``latched``)."""

    depth: int
    reliable: bool = True
    latched: bool = False


@dataclass(frozen=True)
class Output:
    """One publisher of the node: its key (the topic, relative to the namespace unless absolute), type and QoS."""

    key: str
    type_name: str
    qos: Qos


#: Seconds of blocks each data publisher keeps at real time for a reliable subscriber that stalls.
REAL_TIME_HISTORY_S = 3.0


def history_depth(config: SimConfig, settings: SimulatorNodeSettings) -> int:
    """The history of each data publisher, in messages.

    Three seconds of blocks at real time (a reliable subscriber, such as the recorder, may stall that long
    without losing a block: a stall of 1.1 s on a loaded machine lost five blocks with one second; memory: about
    0.5 MB per 20 kHz channel); faster than real time, 20 s of simulation time (at 20x that is still one second
    of wall time; about 3 MB per 20 kHz channel). In lockstep no consumer falls further behind than the window:
    twice the window and a second.
    """
    seconds = REAL_TIME_HISTORY_S if wall_clock_stamps(config, settings) else 20.0
    if settings.lockstep.enabled:
        seconds = max(1.0, 2 * settings.lockstep.window + 1.0)
    return max(10, math.ceil(config.block_rate * seconds) + 10)


def outputs(config: SimConfig, settings: SimulatorNodeSettings) -> tuple[Output, ...]:
    """The node's publishers, in the order of their per-topic diagnostics.

    ``/clock`` is reliable (compatible with the best-effort subscription of ROS time sources and with reliable
    ones), one per block, so it has the blocks' depth (a recorder that lags must not lose ticks either);
    ``faults`` and ``session`` are transient local (a late subscriber gets them).
    """
    depth = history_depth(config, settings)
    out = [Output(CHANNEL_TOPICS[ch.name], "rimd_msgs/msg/SampleBlock", Qos(depth, ch.reliable))
           for ch in config.channels]
    out += [Output("impact/events", "rimd_msgs/msg/ImpactEvent", Qos(1000)),
            Output("motor/state", "rimd_msgs/msg/MotorState", Qos(depth)),
            Output("truth", "rimd_msgs/msg/RigState", Qos(depth)),
            Output("faults", "rimd_msgs/msg/FaultEvent", Qos(1000, latched=True)),
            Output("/clock", "rosgraph_msgs/msg/Clock", Qos(depth)),
            Output("session", "rimd_msgs/msg/RigSession", Qos(1, latched=True))]
    if settings.capture.enabled:
        out += [Output("capture/force", "rimd_msgs/msg/Capture", Qos(200)),
                Output("capture/acceleration", "rimd_msgs/msg/Capture", Qos(200))]
    return tuple(out)


def default_topics(keys: Sequence[str], namespace: str = "/rig") -> dict[str, str]:
    """Key -> topic as ROS resolves it in ``namespace`` (absolute keys stay), without remapping."""
    return {k: k if k.startswith("/") else f"{namespace.rstrip('/')}/{k}" for k in keys}


# ---- the messages --------------------------------------------------------------------------------------------------

def _header(w: CdrWriter, stamp: int, frame_id: str) -> CdrWriter:
    """``std_msgs/Header``."""
    sec, nanosec = divmod(stamp, 1_000_000_000)
    return w.time(sec, nanosec).string(frame_id)


def _bools(w: CdrWriter, values: np.ndarray) -> CdrWriter:
    """``bool[]`` (one byte each)."""
    w.u32(int(values.size))
    w.parts.append(values.astype(np.uint8).tobytes())
    w.pos += int(values.size)
    return w


def _frame(frame_id: str) -> bytes:
    """A header's ``frame_id`` as it follows the 8-byte stamp, padded so that an 8-byte field comes next."""
    w = CdrWriter(at=8).string(frame_id)
    w.f64(0.0)
    return w.body()[:-8]


# Each block sends a motor state and a truth block: their layouts are fixed, so they are packed at once rather
# than field by field (the bytes rosbags serializes from the same fields: tests/io/test_cdr_blocks.py).
_STAMP, _U32 = struct.Struct("<iI"), struct.Struct("<I")
_MOTOR_FRAME, _MOTOR = _frame("motor"), struct.Struct("<dddQdd")
_TRUTH_FRAME, _TRUTH_HEAD = _frame("truth"), struct.Struct("<Qd")
_ENCAPSULATION = ENCAPSULATION["<"]


def encode_motor(stamp: int, m: Any) -> bytes:
    """``rimd_msgs/msg/MotorState`` of the core's motor state ``m``."""
    return b"".join((_ENCAPSULATION, _STAMP.pack(*divmod(stamp, 1_000_000_000)), _MOTOR_FRAME,
                     _MOTOR.pack(m.frequency_setpoint, m.frequency, m.phase, max(m.cycle_index, 0), m.ramp_rate,
                                 m.cart_position)))


def encode_truth(stamp: int, first_index: int, sample_rate: float, rows: np.ndarray) -> bytes:
    """``rimd_msgs/msg/RigState`` of the core's truth rows (10 float rows, then in_contact)."""
    k, n = len(TRUTH_ARRAY_FIELDS), rows.shape[1]
    if n == 0:
        w = _header(CdrWriter(), stamp, "truth").u64(first_index).f64(sample_rate)
        for i in range(k):
            w.f64_array(rows[i])
        return _bools(w, rows[k] != 0.0).message()
    # From the 8-aligned first array on, each float64[] is its count, 4 bytes of padding and its values: one
    # row of n + 1 float64 slots whose first slot holds the count and the padding.
    arrays = np.empty((k, n + 1), dtype="<f8")
    arrays[:, 1:] = rows[:k]
    head = arrays.view(np.uint32)
    head[:, 0], head[:, 1] = n, 0
    return b"".join((_ENCAPSULATION, _STAMP.pack(*divmod(stamp, 1_000_000_000)), _TRUTH_FRAME,
                     _TRUTH_HEAD.pack(first_index, sample_rate), arrays.tobytes(), _U32.pack(n),
                     (rows[k] != 0.0).astype(np.uint8).tobytes()))


def encode_impact(stamp: int, imp: Any) -> bytes:
    """``rimd_msgs/msg/ImpactEvent`` of one impact."""
    w = _header(CdrWriter(), stamp, "impact_force_sensor")
    for value in (imp.duration, imp.peak_force, imp.impulse, imp.impact_velocity, imp.max_penetration,
                  imp.excitation_frequency, imp.excitation_phase):
        w.f64(value)
    return w.u64(imp.cycle_index).u64(imp.index).message()


def encode_fault(stamp: int, frame_id: str, event: Any) -> bytes:
    """``rimd_msgs/msg/FaultEvent`` of a fault's start or end."""
    spec = event.fault
    w = _header(CdrWriter(), stamp, frame_id).string(event.event).u32(spec.number).string(spec.channel)
    w.string(spec.kind).f64(float(spec.start)).f64(float(spec.duration)).f64(spec.magnitude)
    return w.string(event.detail).message()


def encode_capture(stamp: int, frame_id: str, unit: str, cap: Any, values: np.ndarray) -> bytes:
    """``rimd_msgs/msg/Capture`` of one triggered capture's channel."""
    w = _header(CdrWriter(), stamp, frame_id).u32(cap.number).f64(cap.sample_rate).u32(cap.pre_trigger_samples)
    return w.f64_array(values).string(unit).f64(cap.threshold).message()


def encode_clock(stamp: int) -> bytes:
    """``rosgraph_msgs/msg/Clock``."""
    return CdrWriter().time(*divmod(stamp, 1_000_000_000)).message()


@dataclass(frozen=True)
class Session:
    """One run's identity, as ``rimd_msgs/msg/RigSession`` carries it."""

    run_id: str
    reason: str
    sequence: int
    start_stamp: int
    simulation_time: float
    time_base: str
    real_time_factor: float
    lockstep: bool
    seed: int
    config_hash: str
    node: str

    def encode(self) -> bytes:
        """The serialized ``rimd_msgs/msg/RigSession`` (header stamped at the start stamp)."""
        w = _header(CdrWriter(), self.start_stamp, SESSION_FRAME).string(self.run_id).string(self.reason)
        w.u32(self.sequence).time(*divmod(self.start_stamp, 1_000_000_000)).f64(self.simulation_time)
        w.string(self.time_base).f64(self.real_time_factor).boolean(self.lockstep).u64(self.seed)
        return w.string(self.config_hash).string(self.node).message()


# ---- answers -------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Answer:
    """A service's answer: ``stamp_ns`` when it takes effect (None: no stamp), ``frequency_hz`` the setpoint."""

    success: bool
    message: str
    stamp_ns: int | None = None
    frequency_hz: float | None = None


@dataclass(frozen=True)
class Status:
    """One ``diagnostic_msgs/DiagnosticStatus``: level (:data:`OK`, :data:`WARN`, :data:`ERROR`), texts, values."""

    name: str
    level: int
    message: str
    hardware_id: str
    values: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Step:
    """What one pass of the pacing loop asks of its caller.

    Attributes:
        wait: Seconds to wait before the next pass (0: go on at once); :attr:`SimulatorRuntime.wake` ends it sooner.
        report: Publish the diagnostics now (a lockstep hold to report).
        stopped: The loop is over (the model cannot continue, or the caller is no longer alive).
    """

    wait: float = 0.0
    report: bool = False
    stopped: bool = False


def _no_log(level: str, line: str) -> None:
    del level, line


@dataclass
class CommandBook:
    """The counts of the motor commands taken from the topic, for the diagnostics and the periodic summary.

    Attributes:
        received: Commands taken (valid or not).
        applied: Commands the core applied (at their stamp, or at the next block boundary).
        late: Commands whose stamp was already simulated when they came (applied at the next block boundary).
        refused: Commands refused (a value out of its range, a stamp more than a day ahead).
        worst_late_s: The largest lateness (s of simulation time from the stamp to where the rig stood).
        last: The last applied command, in words.
        last_refusal: Why the last refused one was refused.
        since_summary: Commands applied since the last summary line.
        summary_at: Monotonic time of the last summary line (0: none yet).
    """

    received: int = 0
    applied: int = 0
    late: int = 0
    refused: int = 0
    worst_late_s: float = 0.0
    last: str = ""
    last_refusal: str = ""
    since_summary: int = 0
    summary_at: float = 0.0


# ---- the runtime ---------------------------------------------------------------------------------------------------

class SimulatorRuntime:
    """The simulator node's logic: pacing, commands, the run's identity, diagnostics, serialization.

    Args:
        config: The validated configuration (:func:`load_settings`).
        settings: The node's own settings.
        send: Publishes ``data`` (serialized) on the output ``key`` (:func:`outputs`).
        topics: Output key -> topic name as published (lockstep reports and diagnostics name them); default
            :func:`default_topics` in ``/rig``.
        node: The node's fully qualified name (the run's identity; the diagnostics use its last part).
        log: ``log(level, line)`` with level ``debug`` (each motor command from the topic), ``info``, ``warning``
            or ``error``.
        clock: Monotonic clock (s).
        wall_ns: Wall clock (ns since the epoch): the stamps' ``t0`` at real time.
        alive: False once the caller's publishers are gone (the loop then stops quietly).
        match: ``match(joining)``: wait (bounded) until the transport has matched the readers: before the first
            block with ``joining`` empty (every reader), and when lockstep consumers join with ``joining`` mapping
            each one's node to the topics its report named, or to None when it named none (the readers the
            graph shows for that node).
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
        self._lateness: deque[float] = deque(maxlen=1000)
        self._overruns = self._published = self._impacts = self._fault_events = self._sessions = 0
        self._last_error = ""
        self._paused_wall = 0.0    # wall-clock seconds spent paused after the start (stamps lag the wall by it)
        self._paused_at: float | None = None
        self._run_id = ""
        self._hold_reported = 0.0  # monotonic time of the last hold report (0: not reported in this hold)
        self._match_pending = False  # a lockstep consumer joined: wait for the transport to match it
        self._joining: dict[str, list[str] | None] = {}   # node -> its topics (None: unnamed), of new joins
        self._match_all = False      # a consumer that did not name its node joined: wait for every reader
        self._rates = {ch.name: Fraction(repr(ch.sample_rate)) for ch in config.channels}
        self._truth_rate = Fraction(repr(config.truth_rate))
        self._truth_sample_rate = config.truth_rate
        self._encoders: dict[str, SampleBlockEncoder] = {}
        self._refresh_encoders()
        self._sent: dict[str, int] = {}   # messages published per topic since the start (diagnostics)
        self._pacer = Pacer(self._rtf, self._lockstep, topics=list(self._topics.values()), clock=clock)
        self._warned: set[tuple[str, str]] = set()
        self._commands = CommandBook()   # motor commands from the topic
        self._reporting: dict[str, tuple[str, tuple[str, ...]]] = {}   # consumer -> (node, topics) of its last report
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

        Taken apart (t0 when the node was built, the anchor when it started), every block reached its subscribers
        some 100 ms after its stamps said it was due, while the node's own lateness said 0.2 ms.
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
        if self._match_pending:
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
        with self._pace_lock:
            holders = self._pacer.lockstep.holders() if self._pacer.lockstep is not None else []
            parts = []
            for c in holders:
                heard = "never heard" if c.last_heard is None else f"last heard {now - c.last_heard:.1f} s ago"
                done = "not joined" if c.done_ns is None else f"done through {c.done_ns / 1e9:.6f} s"
                if c.awaiting is not None:   # a controller's report counts commands that have not come
                    done += f", its report counts {c.awaiting[0]} commands, {c.awaiting[1]} received"
                parts.append(f"{c.name} ({done}, {heard}" + (", timed out" if c.timed_out else "") + ")")
        return ", ".join(parts) or "nobody"

    def _wait_for_matches(self, start: bool = False) -> None:
        """Let the caller wait until the transport matched the readers.

        Every one at the ``start`` (the first block) and after a join of a consumer that did not name its node;
        the readers of the consumers that joined since the last wait.
        """
        joining = dict(self._joining)   # a join that comes meanwhile sets _match_pending again
        everyone, self._match_all = start or self._match_all, False
        self._match_pending = False
        if self._match is not None:
            if everyone:
                self._match({})
            if joining:
                self._match(joining)
        for node in joining:
            self._joining.pop(node, None)

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
        self._reporting[consumer] = (node, tuple(topics))   # what a report taken later (commands pending) named
        with self._pace_lock:
            verdict = self._pacer.lockstep.progress(consumer, done_ns, instance, per_topic, leaving=leaving,
                                                    controls=controls, commands=commands)
        self._take_verdict(consumer, verdict)

    def _take_verdict(self, consumer: str, verdict: ProgressVerdict) -> None:
        """Act on a progress report's verdict: the match wait of a join, the log line, the pacing thread woken."""
        node, topics = self._reporting.get(consumer, ("", ()))
        if verdict.joined:   # its subscriptions may be newer than its report: let the transport match them first
            if node:   # the topics it names, or (None) those the graph shows it reading
                published = set(self._topics.values())
                self._joining[node] = [t for t in topics if t in published] if topics else None
            else:      # its readers are unknown: every reader the graph shows
                self._match_all = True
            self._match_pending = True
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

    def _refresh_encoders(self) -> None:
        """The channel encoders' fields that only change with the configuration."""
        for ch in self._config.channels:
            self._encoders[ch.name] = SampleBlockEncoder(ch.frame_id, ch.sample_rate, ch.unit, ch.range_min,
                                                         ch.range_max)

    def _send(self, key: str, data: bytes, stamp: int) -> None:
        """Send ``data`` stamped ``stamp`` on ``key`` (the pacer learns it first: a consumer may answer at once)."""
        topic = self._topics[key]
        if self._lockstep is not None:
            with self._pace_lock:
                self._pacer.published(stamp, topic)
        self._send_bytes(key, data)
        self._sent[topic] = self._sent.get(topic, 0) + 1

    def _publish(self, block: SimBlock) -> None:
        t0 = self._t0_ns
        last_due = None
        for name in CHANNEL_NAMES:
            rate = self._rates[name]
            for ch in block.deliveries[name]:   # after dropout, block loss and delay
                stamp = sample_stamp_ns(t0, ch.first_index, rate)
                sec, nanosec = divmod(stamp, 1_000_000_000)
                self._send(CHANNEL_TOPICS[name], self._encoders[name].encode(sec, nanosec, ch.first_index,
                                                                             ch.samples, ch.saturated), stamp)
                if len(ch.samples):
                    last = sample_stamp_ns(t0, ch.first_index + len(ch.samples) - 1, rate)
                    last_due = last if last_due is None else max(last_due, last)
        for cap in block.captures:
            stamp = stamp_ns(t0, cap.trigger_time)
            for which, values, channel in (("force", cap.force, "impact_force"),
                                           ("acceleration", cap.acceleration, "rimd_acceleration")):
                sensor = self._config.channel(channel)
                self._send(f"capture/{which}", encode_capture(stamp, sensor.frame_id, sensor.unit, cap, values), stamp)
        for event in block.fault_events:
            spec = event.fault
            stamp = stamp_ns(t0, event.time)
            frame = self._config.channel(spec.channel).frame_id if spec.channel in self._rates else spec.channel
            self._send("faults", encode_fault(stamp, frame, event), stamp)
            self._fault_events += 1
            self._log("info", f"fault {spec.number} {event.event} at simulation time {float(event.time):.6f} s "
                              f"(stamp {show_stamp(stamp)}): {event.detail}")
        if block.truth is not None:
            first, rows = block.truth
            stamp = sample_stamp_ns(t0, first, self._truth_rate)
            self._send("truth", encode_truth(stamp, first, self._truth_sample_rate, rows), stamp)
        for imp in block.impacts:
            stamp = t0 + round(imp.t_start * 1e9)
            self._send("impact/events", encode_impact(stamp, imp), stamp)
            self._impacts += 1
        end = stamp_ns(t0, block.t_stop)
        self._send("motor/state", encode_motor(end, block.motor), end)
        if not self._wall_clock:
            self._send("/clock", encode_clock(end), end)
        for cmd in block.commands:
            if cmd.kind == "motor_command":   # the topic's: counted, summed up every COMMAND_SUMMARY_S
                self._commands.applied += 1
                self._commands.since_summary += 1
                self._commands.last = f"{cmd.detail} at {self._when(cmd.time)}"
                continue
            self._log("info", f"{cmd.kind} at simulation time {float(cmd.time):.6f} s "
                              f"(stamp {show_stamp(stamp_ns(t0, cmd.time))}): {cmd.detail}")
        self._summarize_commands()
        self._published += 1
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
        self._lateness.append(late)
        if late > 1.0 / float(self._block_rate):
            self._overruns += 1

    # ---- diagnostics -------------------------------------------------------------------------------------------

    def diagnostics(self, subscribers: Mapping[str, int] | None = None) -> list[Status]:
        """The node's ``/diagnostics``: the pacing status, then the faults status.

        Args:
            subscribers: Topic -> subscriptions its publisher has matched (0 for a topic not given).
        """
        subscribers = subscribers or {}
        lat = sorted(self._lateness)
        p50 = lat[len(lat) // 2] if lat else 0.0
        p99 = lat[min(len(lat) - 1, int(0.99 * len(lat)))] if lat else 0.0
        level = OK
        message = "paused" if self._paused else "running" if self._started else "waiting to start"
        if self._overruns:
            level = WARN
            message += f", {self._overruns} overruns (blocks later than one block period)"
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
            "overruns": str(self._overruns),
            "dropped_blocks": "0",
            "paused": str(self._paused).lower(),
            "motor_commands_received": str(self._commands.received),
            "motor_commands_applied": str(self._commands.applied),
            "motor_commands_late": str(self._commands.late),
            "motor_commands_worst_late_ms": f"{self._commands.worst_late_s * 1e3:.3f}",
            "motor_commands_refused": str(self._commands.refused),
            "motor_command_last": self._commands.last,
            "motor_command_last_refusal": self._commands.last_refusal,
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
                for c in lockstep.consumers.values():
                    values[f"lockstep {c.name} done_through_s"] = "" if c.done_ns is None else f"{c.done_ns / 1e9:.6f}"
                    values[f"lockstep {c.name} state"] = (
                        "left" if c.left else "dropped" if c.dropped else "timed out" if c.timed_out
                        else "not joined" if c.done_ns is None else "joined")
        name = self._node.rsplit("/", 1)[-1]
        pacing = Status(f"{name}{PACING_STATUS}", level, message, SESSION_FRAME, values)
        with self._lock:
            active = self._sim.active_faults()
        faults = {f"fault_{f.number}": (
            f"{f.kind} on {f.channel} from simulation time {float(f.start):.6f} s, "
            + (f"duration {float(f.duration):g} s" if f.duration else "until cleared")
            + f", magnitude {f.magnitude:g}") for f in active}
        faults["fault_events_published"] = str(self._fault_events)
        return [pacing, Status(f"{name}: faults", WARN if active else OK,
                               (f"{len(active)} fault(s) active: " + ", ".join(f"{f.kind} on {f.channel}"
                                                                               for f in active))
                               if active else "no fault active", SESSION_FRAME, faults)]

    # ---- commands ----------------------------------------------------------------------------------------------

    def _start_time(self, stamp: tuple[int, int]) -> Fraction | None:
        """Simulation time of a request's ``start_stamp`` ``(sec, nanosec)`` (None for zero: the next boundary).

        Raises:
            CommandError: A stamp before the rig's start, already passed, or more than a day ahead.
        """
        sec, nanosec = stamp
        if nanosec >= 1_000_000_000:  # builtin_interfaces/Time: nanosec in [0, 1e9)
            raise CommandError(f"start_stamp.nanosec = {nanosec} refused: must be < 1000000000 "
                               "(the seconds go in start_stamp.sec)")
        ns = int(sec) * 1_000_000_000 + int(nanosec)
        if ns == 0:
            return None
        t = Fraction(ns - self._t0_ns, 1_000_000_000)
        now = self._sim.time
        rule = "must be zero (next block boundary) or a stamp from now to one day ahead in the rig's time base"
        if t < now:
            raise CommandError(f"start_stamp {sec}.{nanosec:09d} refused: already passed "
                               f"(the rig is at stamp {show_stamp(stamp_ns(self._t0_ns, now))}, simulation time "
                               f"{float(now):.6f} s); {rule}")
        if t - now > MAX_SCHEDULE_AHEAD_S:
            raise CommandError(f"start_stamp {sec}.{nanosec:09d} refused: {float(t - now):.6g} s "
                               f"ahead of the rig; {rule}")
        return t

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
        with self._lock:
            book.received += 1
            now = self._sim.time
            sec, nanosec = stamp
            ns = int(sec) * 1_000_000_000 + int(nanosec)
            t = None if ns == 0 else Fraction(ns - self._t0_ns, 1_000_000_000)
            late = t is not None and t < now
            try:
                if not 0 <= int(nanosec) < 1_000_000_000:
                    raise CommandError(f"header.stamp.nanosec = {nanosec} refused: must be in [0, 1000000000)")
                if t is not None and t - now > MAX_SCHEDULE_AHEAD_S:
                    raise CommandError(f"stamp {show_stamp(ns)} refused: {float(t - now):.6g} s ahead of the rig "
                                       "(at most one day)")
                if not ramp_rate <= MAX_RAMP_RATE:
                    raise CommandError(f"ramp_rate = {ramp_rate!r} refused: must be <= {MAX_RAMP_RATE:g} Hz/s "
                                       "(0 = motor.ramp_rate)")
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
        book = self._commands
        if not book.since_summary:
            return
        now = self._clock()
        if book.summary_at and now - book.summary_at < COMMAND_SUMMARY_S:
            return
        span = f"in the last {now - book.summary_at:.1f} s" if book.summary_at else "since the start"
        book.summary_at = now
        self._log("info", f"motor commands: {book.since_summary} applied {span} ({book.applied} in all; "
                          f"{book.late} late, worst {book.worst_late_s * 1e3:.3f} ms; {book.refused} refused); "
                          f"last: {book.last}")
        book.since_summary = 0

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
        accepted = {}
        for name, value in changes:
            if name not in PARAMETERS:
                # Only use_sim_time gets here (the node's own parameters are read-only; undeclared names are
                # refused before): the rig's stamps follow its own clock, always.
                return (f"parameter '{name}' = {value!r} refused: read at start only, it cannot change while the "
                        "rig runs")
            if name.endswith(".reliable"):
                # The publishers' QoS is set when they are created: a change was accepted and had no effect.
                return (f"parameter '{name}' = {value!r} refused: read at start only, the channel's QoS cannot "
                        "change while the rig runs")
            accepted[name] = value
        with self._lock:
            try:
                config = self._config.with_parameters(accepted)
                if self._wall_clock and config.real_time_factor != 1.0:
                    raise ConfigError("real_time_factor", config.real_time_factor,
                                      "cannot switch from 1 while running: the stamps are wall-clock at real time "
                                      "(restart the rig with another factor)")
                if not self._wall_clock and config.real_time_factor == 1.0 and self._lockstep is None:
                    raise ConfigError("real_time_factor", config.real_time_factor,
                                      "cannot switch to 1 while running: the stamps are simulation time (restart "
                                      "the rig at real time for wall-clock stamps)")
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
            self._refresh_encoders()
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
