"""The Rerun mapping's shortcuts give what the general paths give, bit for bit.

Hypotheses (in-process, no ROS):
* :func:`line_strips` builds the Arrow array Rerun's own conversion builds from the list of strips (one per
  block, each starting at the previous one's last point), so the phase plane in the .rrd is unchanged;
* ``_second_order_rate`` is ``np.gradient(f, dx, edge_order=2)`` to the last bit (the cart velocity of the
  phase plane);
* :func:`sample_times_ns` for an integer rate is ``n / rate`` s in integer ns rounded half up (1024 Hz has
  halves), for every ``n`` of a block, across whole seconds (the grid the simulator stamps);
* impacts sent with the blocks, as columns (one ``send_columns`` per entity) or logged one by one with typed
  table values, leave in the .rrd what one plain ``rr.log`` per impact leaves: markers, log lines and table
  rows at the same times.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import rerun as rr
from hypothesis import given, settings
from hypothesis import strategies as st

from rimd_sim.viz.rerun_map import (
    COLUMNS_FROM,
    IMPACT_LOG,
    IMPACT_MARKERS,
    IMPACT_TABLE,
    TIMELINE,
    RigMapper,
    _second_order_rate,
    impact_text,
    line_strips,
    sample_times_ns,
    stamp_ns,
)
from rimd_sim.viz.rrd_data import load_rrd

FINITE = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


@settings(max_examples=150, deadline=None)
@given(lengths=st.lists(st.integers(1, 12), min_size=1, max_size=12), lead=st.integers(0, 3), seed=st.integers(0, 99))
def test_line_strips_is_the_array_rerun_builds_from_the_strips(lengths, lead, seed):
    # lead: points before the first strip's start (the batch continued from the previous batch's last point)
    rng = np.random.default_rng(seed)
    ends = lead + np.cumsum(lengths)
    starts = np.r_[lead, ends[:-1]]
    xs, ys = rng.normal(size=ends[-1] + 1) * 1e3, rng.normal(size=ends[-1] + 1)
    strips = [np.column_stack((xs[a:b + 1], ys[a:b + 1])) for a, b in zip(starts, ends, strict=True)]
    want = rr.LineStrips2D.columns(strips=strips).partition([1] * len(strips))
    got = rr.LineStrips2D.columns(strips=line_strips(xs, ys, starts, ends)).partition([1] * len(strips))
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert g.component_descriptor() == w.component_descriptor()
        assert g.as_arrow_array().equals(w.as_arrow_array())


@settings(max_examples=300, deadline=None)
@given(values=st.lists(FINITE, min_size=3, max_size=40),
       rate=st.sampled_from([1000.0, 2000.0, 20000.0, 3.0, 7.5, 44100.0]))
def test_the_cart_velocity_is_numpys_gradient_bit_for_bit(values, rate):
    f = np.array(values)
    assert np.array_equal(_second_order_rate(f, 1.0 / rate), np.gradient(f, 1.0 / rate, edge_order=2))


@settings(max_examples=300, deadline=None)
@given(rate=st.sampled_from([1, 3, 7, 1000, 1024, 2000, 20000, 44100, 999_983]), seconds=st.integers(0, 10**7),
       offset=st.integers(-5, 5), count=st.integers(0, 300))
def test_sample_times_are_the_exact_grid_across_whole_seconds(rate, seconds, offset, count):
    first = max(0, seconds * rate + offset)   # blocks that start just before, on or after a whole second
    got = sample_times_ns(first, count, float(rate))
    want = [(2 * n * 1_000_000_000 + rate) // (2 * rate) for n in range(first, first + count)]
    assert got.dtype == np.int64 and got.tolist() == want


def _event(index: int, stamp_ns: int, seed: int) -> SimpleNamespace:
    rng = np.random.default_rng(seed)
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec)), index=index,
                           cycle_index=index // 2, peak_force=float(rng.uniform(1, 300)),
                           impulse=float(rng.uniform(0, 1e-2)), impact_velocity=float(rng.uniform(0, 0.5)),
                           duration=float(rng.uniform(1e-4, 1e-3)), max_penetration=float(rng.uniform(0, 1e-4)),
                           excitation_frequency=4.25, excitation_phase=float(rng.uniform(0, 6.28)))


def _logged_one_by_one(rec, events) -> None:
    """The impacts as three ``rr.log`` calls each at their time (how the mapping logged them before batching)."""
    for ev in events:
        rr.set_time(TIMELINE, duration=np.timedelta64(stamp_ns(ev.header.stamp), "ns"), recording=rec)
        rr.log(IMPACT_MARKERS, rr.Scalars(float(ev.peak_force)), recording=rec)
        rr.log(IMPACT_LOG, rr.TextLog(impact_text(ev), level="INFO"), recording=rec)
        rr.log(IMPACT_TABLE, rr.AnyValues(
            index=int(ev.index), cycle=int(ev.cycle_index), peak_force_N=float(ev.peak_force),
            impulse_Ns=float(ev.impulse), impact_velocity_mps=float(ev.impact_velocity), duration_s=float(ev.duration),
        ), recording=rec)


def test_impacts_sent_in_batches_are_what_logging_each_gives(tmp_path):
    # Impacts wait for the next send of a channel and go in one send_columns per entity: the .rrd holds the same
    # markers, log lines (text and level) and table rows at the same times as one rr.log per impact would.
    events = [_event(i, 1_000_000_000 + 137_000_000 * i + i % 3, i) for i in range(9)]
    oracle = rr.RecordingStream("oracle")
    oracle.save(str(tmp_path / "oracle.rrd"))
    _logged_one_by_one(oracle, events)
    oracle.flush()
    oracle.disconnect()

    rec = rr.RecordingStream("batched")
    rec.save(str(tmp_path / "batched.rrd"))
    mapper = RigMapper(rec, batch=5)
    mapper.origin_ns = 0
    sent = 0
    for size in (1, 2, COLUMNS_FROM, 9 - 3 - COLUMNS_FROM):   # logged one by one below COLUMNS_FROM, as columns from it
        for ev in events[sent:sent + size]:
            mapper.log_impact(ev)
        mapper.flush()   # a send: the impacts waiting go
        sent += size
    assert sent == 9 and mapper.stats.impacts == 9 and COLUMNS_FROM <= 9 - 3 - COLUMNS_FROM
    rec.flush()
    rec.disconnect()

    want, got = load_rrd(tmp_path / "oracle.rrd"), load_rrd(tmp_path / "batched.rrd")
    for entity in (IMPACT_MARKERS, IMPACT_LOG, IMPACT_TABLE):
        assert np.array_equal(got[entity].times, want[entity].times), entity
        assert set(got[entity].columns) == set(want[entity].columns), entity
        for name, column in want[entity].columns.items():
            assert got[entity].columns[name].to_pylist() == column.to_pylist(), (entity, name)
    assert got[IMPACT_LOG].texts() == [impact_text(ev) for ev in events]


def _block(first: int, count: int, rate: float = 1000.0) -> SimpleNamespace:
    sec, nanosec = divmod((2 * first * 1_000_000_000 + int(rate)) // (2 * int(rate)), 1_000_000_000)
    return SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec)),
                           first_index=first, sample_rate=rate, samples=np.arange(count, dtype=float) + first)


def test_the_timed_flush_sends_each_channel_at_most_once_per_interval(tmp_path):
    # flush_due (the bridge's timer, every batch_interval) sends a channel's pending blocks only when its last
    # send is at least min_interval old: with an interval of an hour, one send; with 0, every call sends. The
    # full flush sends whatever is pending.
    from rimd_sim.viz.rerun_map import CHANNELS

    channel = CHANNELS[0]
    for interval, sends in ((3600.0, [10, 10, 10, 30]), (0.0, [10, 20, 30, 30])):
        rec = rr.RecordingStream("due")
        rec.save(str(tmp_path / f"due{interval}.rrd"))
        mapper = RigMapper(rec, batch=1000, min_interval=interval)
        seen = []
        for k in range(3):
            mapper.log_block(channel, _block(10 * k, 10))
            mapper.flush_due()
            seen.append(mapper.stats.points.get(channel.name, 0))
        mapper.flush()
        seen.append(mapper.stats.points.get(channel.name, 0))
        assert seen == sends, interval
        rec.disconnect()
