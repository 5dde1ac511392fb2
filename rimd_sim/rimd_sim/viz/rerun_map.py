"""From rig messages to Rerun: entities, the simulation-time timeline and the blueprint (docs/rerun.md).

Pure of ROS: a message is any object with the attributes of its ``rimd_msgs`` type, so rclpy messages and
messages decoded from an MCAP file by :mod:`rimd_sim.io.decode` go through the same functions. Arrays may be
``array.array``, lists or numpy arrays.

Timeline ``sim_time`` (a duration): the simulation time of each sample, from the channel's sample 0. Sample
``n`` of a channel at ``rate`` Hz is at ``n / rate``, computed exactly in integer nanoseconds and rounded
like the simulator rounds its stamps, so ``stamp - origin`` and ``first_index / rate`` agree to the
nanosecond. The origin (the stamp of sample 0: 0 when the simulator runs in simulation time, the wall-clock
start at real time) is learnt from the blocks; impact events are placed at ``stamp - origin``.

Entities:

* ``channels/<name>``: the four instrument channels (Scalars, SI units, sent as columns): every sample, or with
  ``display_interval`` (the live bridge's default) the display stream, each interval's min and max sample
  (:mod:`rimd_sim.viz.display`);
* ``channels/impact_force/impacts``: one marker per impact at its contact start, at the peak force;
* ``impacts/log`` (TextLog) and ``impacts/table`` (AnyValues: peak, impulse, velocity, ...): one row per impact;
* ``phase_plane/trajectory``: relative displacement of the RIMD (``x - x_c``, mm) versus its relative
  velocity scaled by ``1/omega_n`` (mm), one line segment per truth block; the blueprint shows the last
  ``trail`` seconds, so it is a trailing line;
* ``poincare/points``: the same state at motor phase 0, one point per excitation cycle (interpolated
  between truth samples), all shown, so the section builds up;
* ``motor/frequency``: the actual motor frequency (Hz), from the truth, one value per truth block.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rimd_sim.viz.display import EnvelopeDecimator
from rimd_sim.viz.sinks import require_rerun

__all__ = [
    "CHANNELS",
    "TIMELINE",
    "Channel",
    "RigMapper",
    "blueprint",
    "sample_times_ns",
    "stamp_ns",
]

TIMELINE = "sim_time"
NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class Channel:
    """One instrument channel: topic relative to the rig namespace, entity path and label."""

    name: str
    topic: str
    label: str
    unit: str
    color: tuple[int, int, int]

    @property
    def entity(self) -> str:
        """Entity path of the channel's time series."""
        return f"channels/{self.name}"


CHANNELS: tuple[Channel, ...] = (
    Channel("cart_displacement", "cart/displacement", "cart displacement", "m", (31, 119, 180)),
    Channel("rimd_displacement", "rimd/displacement", "RIMD displacement", "m", (44, 160, 44)),
    Channel("rimd_acceleration", "rimd/acceleration", "RIMD acceleration", "m/s^2", (148, 103, 189)),
    Channel("impact_force", "impact/force", "impact force", "N", (214, 39, 40)),
)
_BY_TOPIC = {ch.topic: ch for ch in CHANNELS}
EVENTS_TOPIC = "impact/events"
TRUTH_TOPIC = "truth"
#: Topics (relative to the rig namespace) the mapping uses. The motor's frequency and phase come from the truth
#: (same values as /rig/motor/state, at the truth rate), which spares the bridge 100 messages/s.
TOPICS = (*(ch.topic for ch in CHANNELS), EVENTS_TOPIC, TRUTH_TOPIC)

IMPACT_MARKERS = "channels/impact_force/impacts"
IMPACT_LOG = "impacts/log"
IMPACT_TABLE = "impacts/table"
PHASE_PLANE = "phase_plane/trajectory"
POINCARE = "poincare/points"
MOTOR_FREQUENCY = "motor/frequency"


def stamp_ns(stamp: Any) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``-like object (``sec``, ``nanosec``)."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def sample_times_ns(first_index: int, count: int, rate: float) -> np.ndarray:
    """Times (int64 ns) of samples ``first_index .. first_index + count - 1`` at ``rate`` Hz: ``n / rate``.

    For an integer rate the arithmetic is exact (``n = q R + r``: ``q s + round(r / R s)``, half up, as the
    simulator stamps its blocks) and never overflows; other rates fall back to float64.
    """
    if float(rate).is_integer() and rate > 0:
        # q0 whole seconds to the first sample, then r = r0 + k samples (k < count) past them: the same rounding
        # of r / R s as of each sample's own remainder, one division per sample, in place (called per send).
        r_hz = int(rate)
        q0, r0 = divmod(int(first_index), r_hz)
        times = _arange(count) + np.int64(r0)
        times *= 2 * NS_PER_S
        times += r_hz
        times //= 2 * r_hz
        times += q0 * NS_PER_S
        return times
    index = np.int64(first_index) + _arange(count)
    return np.rint(index.astype(np.float64) * (NS_PER_S / float(rate))).astype(np.int64)


_ARANGE = np.arange(0, dtype=np.int64)


def _arange(count: int) -> np.ndarray:
    """``np.arange(count)`` as int64, from one cached array (a block's sample offsets: called per block)."""
    global _ARANGE
    if count > _ARANGE.size:
        _ARANGE = np.arange(max(count, 2 * _ARANGE.size), dtype=np.int64)
        _ARANGE.flags.writeable = False
    return _ARANGE[:count]


def _block_times(blocks: list[tuple[int, float, int]]) -> np.ndarray:
    """The sample times (int64 ns) of consecutive blocks ``(first_index, rate, count)``, concatenated.

    Blocks that follow each other at one rate (the usual case) take one :func:`sample_times_ns` call together.
    """
    first, rate, total = blocks[0]
    for f, r, n in blocks[1:]:
        if f != first + total or r != rate:
            return np.concatenate([sample_times_ns(f, n, r) for f, r, n in blocks])
        total += n
    return sample_times_ns(first, total, rate)


def _second_order_rate(f: np.ndarray, dx: float) -> np.ndarray:
    """``np.gradient(f, dx, edge_order=2)`` of a 1-D float64 array of at least 3 samples, the same arithmetic.

    Central differences inside, the one-sided second-order formulas at both ends, as NumPy writes them (the
    result is bit for bit NumPy's, checked in the tests); without its general path's cost (a truth block per
    10 ms in the bridge).
    """
    out = np.empty(f.size)
    out[1:-1] = (f[2:] - f[:-2]) / (2. * dx)
    out[0] = (-1.5 / dx) * f[0] + (2. / dx) * f[1] + (-0.5 / dx) * f[2]
    out[-1] = (0.5 / dx) * f[-3] + (-2. / dx) * f[-2] + (1.5 / dx) * f[-1]
    return out


def line_strips(xs: np.ndarray, ys: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> Any:
    """The strips ``(xs[a..b], ys[a..b])`` for each ``a, b`` of ``starts, ends`` (inclusive) as Rerun's Arrow array.

    What ``rr.LineStrips2D.columns(strips=[np.column_stack((xs[a:b + 1], ys[a:b + 1])), ...])`` builds (float32
    points, the same array: checked in the tests), in a few array operations instead of Rerun's conversion of
    each strip in Python (the phase plane sends one strip per block).
    """
    import pyarrow as pa
    import rerun as rr

    datatype = rr.components.LineStrip2DBatch._ARROW_DATATYPE
    lengths = np.asarray(ends) - np.asarray(starts) + 1
    offsets = np.zeros(lengths.size + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    index = np.arange(offsets[-1]) - np.repeat(offsets[:-1] - starts, lengths)
    points = np.empty((index.size, 2), dtype=np.float32)
    points[:, 0] = xs[index]
    points[:, 1] = ys[index]
    inner = pa.FixedSizeListArray.from_arrays(pa.array(points.ravel()), type=datatype.value_type)
    return pa.ListArray.from_arrays(pa.array(offsets), inner, type=datatype)


def impact_text(ev: Any) -> str:
    """The log line of an ImpactEvent (what ``impacts/log`` shows)."""
    return (f"impact {int(ev.index)} (cycle {int(ev.cycle_index)}): peak {ev.peak_force:.2f} N, "
            f"impulse {ev.impulse * 1e3:.3f} mN s, velocity {ev.impact_velocity * 1e3:.1f} mm/s, "
            f"duration {ev.duration * 1e3:.3f} ms, penetration {ev.max_penetration * 1e6:.1f} um, "
            f"{ev.excitation_frequency:.3f} Hz, phase {ev.excitation_phase:.3f} rad")


def _array(values: Any) -> np.ndarray:
    return np.asarray(values, dtype=np.float64)


@dataclass
class _PhaseState:
    """Last truth sample seen (continuity of the phase-plane line and phase-0 detection across blocks)."""

    t_ns: int | None = None
    x: float = 0.0
    v: float = 0.0
    phase: float = 0.0


@dataclass
class MapperStats:
    """What a :class:`RigMapper` has logged, per entity: samples, blocks, gaps (dropped blocks).

    ``samples`` counts the samples received per channel, ``points`` those sent to Rerun (the same at full rate;
    the envelope's points with a display interval).
    """

    samples: dict[str, int] = field(default_factory=dict)
    points: dict[str, int] = field(default_factory=dict)
    blocks: dict[str, int] = field(default_factory=dict)
    gaps: dict[str, int] = field(default_factory=dict)
    impacts: int = 0
    poincare_points: int = 0
    truth_blocks: int = 0


#: Impacts waiting from which they are sent as columns (one ``send_columns`` per entity) rather than logged one
#: by one: from three impacts on, the ``send_columns`` calls cost no more than logging the impacts one by one
#: (docs/benchmarks.md).
COLUMNS_FROM = 3


class RigMapper:
    """Maps rig messages to Rerun calls on one recording stream.

    State kept between messages (nothing else): the time origin, the last truth sample (for a continuous
    phase-plane line and to catch phase 0 across block boundaries) and the expected next ``first_index`` of
    each channel (to count dropped blocks).

    Blocks are expanded to per-sample times at once and sent columnar: with ``batch`` 1 one ``send_columns``
    per block; with ``batch`` k, one per k consecutive blocks of a channel (fewer calls: the live node uses it
    to stay within its CPU budget, at most k block periods of extra latency). Impact events wait for the next
    send of a channel and go with it (:meth:`log_impact`). :meth:`flush` sends a partial batch and the impacts
    waiting; call it before closing the stream.

    With ``display_interval`` > 0 (s) the channels are sent as their display stream: per channel and per
    interval of that length, its smallest and its largest sample, each at its own time
    (:class:`rimd_sim.viz.display.EnvelopeDecimator`: at most 2 points per interval, every impact's peak sample
    exact); 0 (the default, the offline conversion's) sends every sample. The truth's views and the impacts are
    the same either way.

    Args:
        recording: A ``rerun.RecordingStream``.
        natural_frequency: Hz; the phase plane's velocity axis is ``v_rel / (2 pi natural_frequency)`` so
            that both axes are lengths (mm) and a free oscillation is a circle.
    """

    def __init__(self, recording: Any, *, natural_frequency: float = 1.82, batch: int = 1,
                 min_interval: float = 0.0, display_interval: float = 0.0) -> None:
        """Bind to ``recording``; nothing is logged until :meth:`log_static` or a message.

        A channel's pending blocks are sent once there are ``batch`` of them and ``min_interval`` s of wall time
        have passed since its last send: faster than real time (lockstep, a fast replay), one send carries more
        blocks instead of sending more often.
        """
        require_rerun("the Rerun mapping of the rig", "")
        import rerun as rr

        if batch < 1:
            raise ValueError(f"batch {batch} must be >= 1")
        if not display_interval >= 0:
            raise ValueError(f"display_interval {display_interval} must be >= 0")
        self._rr = rr
        self.rec = recording
        self.batch = batch
        self.min_interval = min_interval
        self._last_send: dict[str, float] = {}
        self._blocks: dict[str, list[tuple[int, float, np.ndarray]]] = {}   # first index, rate, samples
        # (first index, rate, count), x, v, motor phase, motor frequency of each truth block not sent yet
        self._truth: list[tuple[tuple[int, float, int], np.ndarray, np.ndarray, np.ndarray, float]] = []
        self.omega_n = 2.0 * math.pi * natural_frequency
        self.origin_ns: int | None = None
        self._next_index: dict[str, int] = {}
        self._phase = _PhaseState()
        self._pending: list[tuple[str, Any]] = []
        self._impacts: list[tuple] = []   # impacts waiting for the next send: time, text, the table's columns
        self.stats = MapperStats()
        #: The display interval in ns (0: every sample) and each channel's decimator.
        self.display_interval_ns = round(display_interval * NS_PER_S)
        self._display = ({ch.name: EnvelopeDecimator(self.display_interval_ns) for ch in CHANNELS}
                         if self.display_interval_ns > 0 else {})

    # ---- static ------------------------------------------------------------------------------------

    def log_static(self) -> None:
        """Log the series styles (names with units, colours, markers) once, as static data."""
        rr = self._rr
        for ch in CHANNELS:
            # MinMax: when a pixel holds many samples (20 kHz over seconds), draw their range, so that a 0.4 ms
            # impact keeps its peak instead of being averaged away.
            rr.log(ch.entity, rr.SeriesLines(names=f"{ch.label} [{ch.unit}]", colors=[ch.color], widths=1.0,
                                             aggregation_policy="MinMax"), static=True, recording=self.rec)
        rr.log(IMPACT_MARKERS, rr.SeriesPoints(names="impact (peak force at contact start)", colors=[(255, 170, 0)],
                                               markers="diamond", marker_sizes=5.0), static=True, recording=self.rec)
        rr.log(MOTOR_FREQUENCY, rr.SeriesLines(names="motor frequency [Hz]"), static=True, recording=self.rec)
        rr.log(PHASE_PLANE, rr.LineStrips2D.from_fields(colors=[(44, 160, 44)], radii=[-1.5]), static=True,
               recording=self.rec)
        rr.log(POINCARE, rr.Points2D.from_fields(colors=[(214, 39, 40)], radii=[-4.0]), static=True,
               recording=self.rec)

    # ---- dispatch ----------------------------------------------------------------------------------

    def log_message(self, topic: str, msg: Any) -> None:
        """Log one message of ``topic`` (relative to the rig namespace, e.g. ``impact/force``)."""
        channel = _BY_TOPIC.get(topic)
        if channel is not None:
            self.log_block(channel, msg)
        elif topic == TRUTH_TOPIC:
            self.log_truth(msg)
        elif self.origin_ns is None:
            # Events and motor states are placed relative to the origin learnt from the blocks; keep the
            # few that come before the first block (bounded: at most 1000).
            if len(self._pending) < 1000:
                self._pending.append((topic, msg))
        elif topic == EVENTS_TOPIC:
            self.log_impact(msg)

    def _learn_origin(self, stamp: Any, first_index: int, rate: float) -> None:
        origin = stamp_ns(stamp) - int(sample_times_ns(first_index, 1, rate)[0])
        if self.origin_ns != origin:
            self.origin_ns = origin
            pending, self._pending = self._pending, []
            for topic, msg in pending:
                self.log_message(topic, msg)

    def sim_time_ns(self, stamp: Any) -> int:
        """Simulation time (ns) of a stamp, relative to the learnt origin (0 while none is known)."""
        return stamp_ns(stamp) - (self.origin_ns or 0)

    # ---- channels ----------------------------------------------------------------------------------

    def log_block(self, channel: Channel, msg: Any) -> None:
        """One SampleBlock: all its samples at their exact times; sent when ``batch`` blocks are pending."""
        samples = _array(msg.samples)
        first = int(msg.first_index)
        rate = float(msg.sample_rate)
        if self.origin_ns is None:
            self._learn_origin(msg.header.stamp, first, rate)
        expected = self._next_index.get(channel.name)
        if expected is not None and first != expected:
            self.stats.gaps[channel.name] = self.stats.gaps.get(channel.name, 0) + 1
        self._next_index[channel.name] = first + samples.size
        if samples.size == 0:
            return
        pending = self._blocks.setdefault(channel.name, [])
        pending.append((first, rate, samples))
        self.stats.samples[channel.name] = self.stats.samples.get(channel.name, 0) + samples.size
        self.stats.blocks[channel.name] = self.stats.blocks.get(channel.name, 0) + 1
        if len(pending) >= self.batch and self._due(channel.name):
            self._send_channel(channel)

    def _due(self, name: str) -> bool:
        """Whether ``min_interval`` has passed since ``name`` was last sent (then it counts as sent now)."""
        if self.min_interval <= 0:
            return True
        now = time.monotonic()
        if now - self._last_send.get(name, -math.inf) < self.min_interval:
            return False
        self._last_send[name] = now
        return True

    def _send_channel(self, channel: Channel) -> None:
        pending = self._blocks.pop(channel.name, None)
        if not pending:
            return
        times = _block_times([(first, rate, values.size) for first, rate, values in pending])
        values = pending[0][2] if len(pending) == 1 else np.concatenate([v for _, _, v in pending])
        display = self._display.get(channel.name)
        if display is not None:   # the envelope; the next sample's time says whether the last interval is whole
            first, rate, last = pending[-1]
            times, values = display.feed(times, values, end_ns=int(sample_times_ns(first + last.size, 1, rate)[0]))
        self._send_scalars(channel, times, values)
        self._send_impacts()   # the impacts waiting go with the blocks

    def _send_scalars(self, channel: Channel, times: np.ndarray, values: np.ndarray) -> None:
        if times.size == 0:
            return
        rr = self._rr
        rr.send_columns(channel.entity, indexes=[rr.TimeColumn(TIMELINE, duration=times.view("timedelta64[ns]"))],
                        columns=rr.Scalars.columns(scalars=values), recording=self.rec)
        self.stats.points[channel.name] = self.stats.points.get(channel.name, 0) + int(times.size)

    def flush_due(self) -> None:
        """Send the pending blocks of each channel, and the truth, last sent at least ``min_interval`` ago.

        What a timer calls every ``min_interval``: a paused or slow stream leaves nothing pending for longer, and a
        stream at speed still gets one send per channel and interval (the viewer ingests each send as a message
        of its own, so their number, not their size, is what a browser's viewer keeps up with). A display interval
        still open stays carried (:meth:`flush` sends it).
        """
        for channel in CHANNELS:
            if channel.name in self._blocks and self._due(channel.name):
                self._send_channel(channel)
        if self._truth and self._due(TRUTH_TOPIC):
            self._send_truth()
        self._send_impacts()

    def flush(self) -> None:
        """Send everything pending (blocks, truth and impacts of an unfinished batch, a display interval carried)."""
        for channel in CHANNELS:
            self._send_channel(channel)
            display = self._display.get(channel.name)
            if display is not None and display.carrying:
                self._send_scalars(channel, *display.flush())
        self._send_truth()
        self._send_impacts()

    # ---- events ------------------------------------------------------------------------------------

    def log_impact(self, ev: Any) -> None:
        """One ImpactEvent: a marker on the force plot, a text line and a table row, at contact start.

        Sent with the next batch of blocks (or at :meth:`flush`): from :data:`COLUMNS_FROM` impacts waiting, in
        one ``send_columns`` per entity (at speed, lockstep or a fast replay, dozens of impacts a second would
        cost three ``log`` calls each); fewer (real time: one now and then) in three ``log`` calls each, cheaper
        for one impact than the columns.
        """
        self._impacts.append((self.sim_time_ns(ev.header.stamp), impact_text(ev), int(ev.index), int(ev.cycle_index),
                              float(ev.peak_force), float(ev.impulse), float(ev.impact_velocity),
                              float(ev.duration)))
        self.stats.impacts += 1

    def _send_impacts(self) -> None:
        if not self._impacts:
            return
        rr = self._rr
        batch, self._impacts = self._impacts, []
        if len(batch) < COLUMNS_FROM:
            for t_ns, text, *row in batch:
                self._log_impact(t_ns, text, *row)
            return
        times, texts, index, cycle, peak, impulse, velocity, duration = zip(*batch, strict=True)
        time_index = [rr.TimeColumn(TIMELINE, duration=np.array(times, dtype=np.int64).view("timedelta64[ns]"))]
        rr.send_columns(IMPACT_MARKERS, indexes=time_index, columns=rr.Scalars.columns(scalars=np.array(peak)),
                        recording=self.rec)
        rr.send_columns(IMPACT_LOG, indexes=time_index,
                        columns=rr.TextLog.columns(text=list(texts), level=["INFO"] * len(texts)), recording=self.rec)
        # The table keeps the six columns that fit a view; the log line has the rest.
        rr.send_columns(IMPACT_TABLE, indexes=time_index, columns=rr.AnyValues.columns(
            index=np.array(index, dtype=np.int64), cycle=np.array(cycle, dtype=np.int64),
            peak_force_N=np.array(peak), impulse_Ns=np.array(impulse), impact_velocity_mps=np.array(velocity),
            duration_s=np.array(duration),
        ), recording=self.rec)

    def _log_impact(self, t_ns: int, text: str, index: int, cycle: int, peak: float, impulse: float,
                    velocity: float, duration: float) -> None:
        """One impact in three ``log`` calls (the table's values typed already: Rerun then does not infer them)."""
        import pyarrow as pa

        rr = self._rr
        rr.set_time(TIMELINE, duration=np.timedelta64(t_ns, "ns"), recording=self.rec)
        rr.log(IMPACT_MARKERS, rr.Scalars(peak), recording=self.rec)
        rr.log(IMPACT_LOG, rr.TextLog(text, level="INFO"), recording=self.rec)
        i64, f64 = pa.int64(), pa.float64()
        rr.log(IMPACT_TABLE, rr.AnyValues(
            index=pa.array([index], i64), cycle=pa.array([cycle], i64), peak_force_N=pa.array([peak], f64),
            impulse_Ns=pa.array([impulse], f64), impact_velocity_mps=pa.array([velocity], f64),
            duration_s=pa.array([duration], f64),
        ), recording=self.rec)

    # ---- truth: phase plane, Poincare section, motor frequency ---------------------------------------

    def log_truth(self, msg: Any) -> None:
        """One RigState block; phase plane, Poincare points and motor frequency are sent per ``batch`` blocks."""
        first = int(msg.first_index)
        rate = float(msg.sample_rate)
        if self.origin_ns is None:
            self._learn_origin(msg.header.stamp, first, rate)
        cart = _array(msg.cart_position)
        n = cart.size
        if n == 0:
            return
        # Cart velocity: the cart moves smoothly (no impact), so a second-order difference at the truth rate
        # is accurate to O((Omega dt)^2); the RIMD's own velocity is exact in the truth.
        cart_v = _second_order_rate(cart, 1.0 / rate) if n >= 3 else np.zeros(n)
        x_mm = (_array(msg.rimd_position) - cart) * 1e3
        y_mm = (_array(msg.rimd_velocity) - cart_v) / self.omega_n * 1e3
        self._truth.append(((first, rate, n), x_mm, y_mm, _array(msg.motor_phase), float(msg.motor_frequency[-1])))
        self.stats.truth_blocks += 1
        if len(self._truth) >= self.batch and self._due(TRUTH_TOPIC):
            self._send_truth()

    def _send_truth(self) -> None:
        if not self._truth:
            return
        rr = self._rr
        batch, self._truth = self._truth, []
        times = _block_times([b[0] for b in batch])
        xs = np.concatenate([b[1] for b in batch])
        ys = np.concatenate([b[2] for b in batch])
        ph = np.concatenate([b[3] for b in batch])
        prev = self._phase
        step = int(times[1] - times[0]) if times.size > 1 else NS_PER_S
        if prev.t_ns is not None and 0 < times[0] - prev.t_ns <= 2 * step:  # continue the line across batches
            xs, ys, ph = np.r_[prev.x, xs], np.r_[prev.v, ys], np.r_[prev.phase, ph]
            times = np.r_[np.int64(prev.t_ns), times]
        # One line segment per block (from the last sample of the previous one), at the block's last sample.
        ends = np.cumsum([b[0][2] for b in batch]) + (xs.size - sum(b[0][2] for b in batch)) - 1
        starts = np.r_[0, ends[:-1]]
        index = [rr.TimeColumn(TIMELINE, duration=times[ends].view("timedelta64[ns]"))]
        rr.send_columns(PHASE_PLANE, indexes=index,
                        columns=rr.LineStrips2D.columns(strips=line_strips(xs, ys, starts, ends)).partition(
                            [1] * len(ends)),
                        recording=self.rec)
        rr.send_columns(MOTOR_FREQUENCY, indexes=index,
                        columns=rr.Scalars.columns(scalars=[b[4] for b in batch]), recording=self.rec)
        # Motor phase 0: the phase wraps from near 2 pi to near 0 between two samples.
        wraps = np.nonzero(np.diff(ph) < -math.pi)[0]
        if wraps.size:
            a, b = wraps, wraps + 1
            frac = (2 * math.pi - ph[a]) / (ph[b] + 2 * math.pi - ph[a])
            px = xs[a] + frac * (xs[b] - xs[a])
            py = ys[a] + frac * (ys[b] - ys[a])
            pt = times[a] + np.rint(frac * (times[b] - times[a])).astype(np.int64)
            rr.send_columns(POINCARE, indexes=[rr.TimeColumn(TIMELINE, duration=pt.view("timedelta64[ns]"))],
                            columns=rr.Points2D.columns(positions=np.column_stack((px, py))),
                            recording=self.rec)
            self.stats.poincare_points += int(wraps.size)
        self._phase = _PhaseState(int(times[-1]), float(xs[-1]), float(ys[-1]), float(ph[-1]))


#: Impact-table columns, most useful first (the viewer would otherwise sort them by name).
TABLE_COLUMNS = ("index", "cycle", "peak_force_N", "impulse_Ns", "impact_velocity_mps", "duration_s")
#: Phase plane and Poincare section share these bounds (mm), so that the section reads against the orbit;
#: they hold the orbits of the paper's gaps (0 to 2.4 mm) and bands; the viewer zooms freely.
PLANE_BOUNDS = {"x_range": (-10.0, 4.0), "y_range": (-8.0, 8.0)}


def blueprint(*, window: float = 2.0, trail: float = 1.0) -> Any:
    """The default layout.

    The four channels stacked (last ``window`` s) on the left; on the right the phase plane (last ``trail`` s)
    and the Poincare section (all cycles) side by side, the impact table (and log) below.
    """
    require_rerun("the Rerun layout of the rig", "")
    import rerun.blueprint as rrb

    def recent(seconds: float) -> Any:
        return [rrb.VisibleTimeRange(TIMELINE, start=rrb.TimeRangeBoundary.cursor_relative(seconds=-seconds),
                                     end=rrb.TimeRangeBoundary.cursor_relative())]

    everything = [rrb.VisibleTimeRange(TIMELINE, start=rrb.TimeRangeBoundary.infinite(),
                                       end=rrb.TimeRangeBoundary.cursor_relative())]
    series = [rrb.TimeSeriesView(origin=ch.entity, name=f"{ch.label} [{ch.unit}]", time_ranges=recent(window))
              for ch in CHANNELS]
    import rerun.blueprint.archetypes as rrba

    bounds = rrb.VisualBounds2D(**PLANE_BOUNDS)
    table = rrb.DataframeView(origin=IMPACT_TABLE, name="impact table", query=rrba.DataframeQuery(
        timeline=TIMELINE, select=[TIMELINE, *(f"/{IMPACT_TABLE}:{c}" for c in TABLE_COLUMNS)], auto_scroll=True))
    right = rrb.Vertical(
        rrb.Horizontal(
            rrb.Spatial2DView(origin="phase_plane", name="phase plane: x - x_c vs v_rel / omega_n [mm]",
                              time_ranges=recent(trail), visual_bounds=bounds),
            rrb.Spatial2DView(origin="poincare", name="Poincare section, motor phase 0 [mm]",
                              time_ranges=everything, visual_bounds=bounds),
        ),
        rrb.Tabs(table, rrb.TextLogView(origin=IMPACT_LOG, name="impact log")),
        row_shares=[3, 2],
    )
    return rrb.Blueprint(rrb.Horizontal(rrb.Vertical(*series), right, column_shares=[3, 2]),
                         rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(state="collapsed", timeline=TIMELINE))
