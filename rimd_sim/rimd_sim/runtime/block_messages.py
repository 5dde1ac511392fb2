"""The serialized messages of one block of the core, in the order the simulator publishes them.

:class:`BlockMessages` turns a :class:`~rimd_sim.instruments.rig_simulator.SimBlock` into ``(key, data, stamp)``
triples: ``key`` an output of :func:`rimd_sim.runtime.publishers.outputs`, ``data`` the CDR bytes (the encoders of
:mod:`rimd_sim.io.cdr` and :mod:`rimd_sim.io.cdr_write`), ``stamp`` the message's stamp in integer nanoseconds
(:mod:`rimd_sim.runtime.stamps`). The order within a block: the channels' sample blocks (after dropout, block loss
and delay), the captures, the fault events, the truth block, the impacts, the motor state, then ``/clock`` when
the stamps are simulation time.
"""

from __future__ import annotations

from collections.abc import Iterator
from fractions import Fraction

from rimd_sim.instruments.rig_simulator import SimBlock
from rimd_sim.io.cdr import SampleBlockEncoder
from rimd_sim.io.cdr_write import encode_capture, encode_clock, encode_fault, encode_impact, encode_motor, encode_truth
from rimd_sim.runtime.publishers import CHANNEL_TOPICS
from rimd_sim.runtime.stamps import sample_stamp_ns, stamp_ns
from rimd_sim.settings.config import CHANNEL_NAMES, SimConfig

__all__ = ["BlockMessages"]


class BlockMessages:
    """The messages of each block, for a configuration.

    Args:
        config: The configuration: the channels' rates, and (:meth:`configure`) their frame ids, units and ranges.
        wall_clock: The stamps are wall-clock, so no ``/clock`` is published.
    """

    def __init__(self, config: SimConfig, wall_clock: bool) -> None:
        self._wall_clock = wall_clock
        # The rates a run publishes at are fixed at its start (the core's sampling grid).
        self._rates = {ch.name: Fraction(repr(ch.sample_rate)) for ch in config.channels}
        self._truth_rate = Fraction(repr(config.truth_rate))
        self._truth_sample_rate = config.truth_rate
        self._encoders: dict[str, SampleBlockEncoder] = {}
        self.configure(config)

    def configure(self, config: SimConfig) -> None:
        """Take the fields a parameter change may change: the channels' frame ids, units and ranges."""
        self._config = config
        for ch in config.channels:
            self._encoders[ch.name] = SampleBlockEncoder(ch.frame_id, ch.sample_rate, ch.unit, ch.range_min,
                                                         ch.range_max)

    def of(self, block: SimBlock, t0_ns: int) -> Iterator[tuple[str, bytes, int]]:
        """The ``(key, data, stamp)`` of each message of ``block``, encoded as it is asked for.

        ``t0_ns``: the stamp of simulation time 0.
        """
        for name in CHANNEL_NAMES:
            rate = self._rates[name]
            encoder = self._encoders[name]
            for ch in block.deliveries[name]:
                stamp = sample_stamp_ns(t0_ns, ch.first_index, rate)
                sec, nanosec = divmod(stamp, 1_000_000_000)
                data = encoder.encode(sec, nanosec, ch.first_index, ch.samples, ch.saturated)
                yield CHANNEL_TOPICS[name], data, stamp
        config = self._config
        for cap in block.captures:
            stamp = stamp_ns(t0_ns, cap.trigger_time)
            for which, values, channel in (("force", cap.force, "impact_force"),
                                           ("acceleration", cap.acceleration, "rimd_acceleration")):
                sensor = config.channel(channel)
                yield f"capture/{which}", encode_capture(stamp, sensor.frame_id, sensor.unit, cap, values), stamp
        for event in block.fault_events:
            spec = event.fault
            stamp = stamp_ns(t0_ns, event.time)
            frame = config.channel(spec.channel).frame_id if spec.channel in self._rates else spec.channel
            yield "faults", encode_fault(stamp, frame, event), stamp
        if block.truth is not None:
            first, rows = block.truth
            stamp = sample_stamp_ns(t0_ns, first, self._truth_rate)
            yield "truth", encode_truth(stamp, first, self._truth_sample_rate, rows), stamp
        for imp in block.impacts:
            stamp = t0_ns + round(imp.t_start * 1e9)
            yield "impact/events", encode_impact(stamp, imp), stamp
        end = stamp_ns(t0_ns, block.t_stop)
        yield "motor/state", encode_motor(end, block.motor), end
        if not self._wall_clock:
            yield "/clock", encode_clock(end), end

    def last_sample_stamp(self, block: SimBlock, t0_ns: int) -> int | None:
        """The latest stamp of a sample the block delivers on any channel (None: it delivers none)."""
        last_due = None
        for name in CHANNEL_NAMES:
            rate = self._rates[name]
            for ch in block.deliveries[name]:
                if len(ch.samples):
                    last = sample_stamp_ns(t0_ns, ch.first_index + len(ch.samples) - 1, rate)
                    last_due = last if last_due is None else max(last_due, last)
        return last_due
