"""The live view's display stream: each channel's smallest and largest sample per display interval.

Hypotheses (in-process, no ROS):
* every impact's peak force sample reaches the view exactly, value and time, whatever the split of the force
  channel into blocks: on the simulator core's own output (``RigSimulator``, the paper's rig at gap 0 and
  3.75 Hz, ten impacts of about 78 N lasting 0.37 ms);
* on any signal and any split into blocks (with or without the time of the next sample): the points are samples
  of the input, value and time; they are, interval by interval, its first smallest and first largest sample in
  time order, one point when those are the same sample: what a per-interval scan of the whole signal gives, so a
  carried interval is neither lost nor doubled;
* the view's rate is bounded whatever the channel's rate: 2, 20 and 200 kHz in, at most 2 points per interval
  out, and at least one per interval that has a sample;
* through the mapper into a real ``.rrd``: with a display interval, each channel holds its envelope and every
  impact's peak sample; with display interval 0 (full rate: ``rimd rig --rerun-full-rate``, and ``rimd rerun``'s
  default) every sample; the impact markers are the same either way.
"""

from __future__ import annotations

from fractions import Fraction
from functools import cache
from types import SimpleNamespace

import numpy as np
import pytest
import rerun as rr
from hypothesis import given, settings
from hypothesis import strategies as st

from rimd_sim.viz.display import EnvelopeDecimator
from rimd_sim.viz.rerun_map import CHANNELS, IMPACT_MARKERS, RigMapper, sample_times_ns
from rimd_sim.viz.rrd_data import load_rrd

#: The bridge's default display interval (bridge_settings.display_interval), ns.
INTERVAL_NS = 5_000_000
SECONDS = 3.0


@cache
def simulated() -> tuple:
    """``SECONDS`` of the core's output at gap 0 and 3.75 Hz from t = 0, in the simulator node's 100 blocks/s."""
    from rimd_sim.instruments.rig_simulator import RigSimulator
    from rimd_sim.settings.config import SimConfig

    config = SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
    blocks = RigSimulator(config).advance_blocks([Fraction(i + 1, 100) for i in range(round(SECONDS * 100))])
    return config, tuple(blocks)


def channel(name: str) -> tuple[np.ndarray, np.ndarray, float]:
    """One channel of :func:`simulated`, whole: sample times (ns), samples and rate."""
    config, blocks = simulated()
    rate = next(c.sample_rate for c in config.channels if c.name == name)
    values = np.concatenate([b.channels[name].samples for b in blocks])
    return sample_times_ns(blocks[0].channels[name].first_index, values.size, rate), values, rate


def decimate(times, values, cuts, *, rate: float | None, first: int = 0, interval_ns: int = INTERVAL_NS):
    """Feed ``times, values`` cut at ``cuts`` (indices), then flush; with ``rate`` (and the index of the first
    sample, ``first``) each block says the time of the sample after it, as the mapper does."""
    dec = EnvelopeDecimator(interval_ns)
    edges = [0, *sorted({c for c in cuts if 0 < c < times.size}), times.size]
    out_t, out_v = [], []
    for a, b in zip(edges, edges[1:], strict=False):
        end = int(sample_times_ns(first + b, 1, rate)[0]) if rate else None
        t, v = dec.feed(times[a:b], values[a:b], end_ns=end)
        out_t.append(t)
        out_v.append(v)
    t, v = dec.flush()
    assert not dec.carrying
    return np.concatenate([*out_t, t]), np.concatenate([*out_v, v])


def scan(times: np.ndarray, values: np.ndarray, interval_ns: int = INTERVAL_NS) -> tuple[np.ndarray, np.ndarray]:
    """The envelope by a plain scan, interval by interval: first min and first max sample, in time order."""
    ids = times // interval_ns
    index: list[int] = []
    for k in np.unique(ids):
        where = np.flatnonzero(ids == k)
        lo = int(where[np.argmin(values[where])])
        hi = int(where[np.argmax(values[where])])
        index += sorted({lo, hi}, key=lambda i: times[i])
    return times[index], values[index]


def impact_peaks() -> list[tuple[int, float]]:
    """(time ns, value) of the force channel's largest sample during each impact of :func:`simulated`."""
    config, blocks = simulated()
    times, values, _ = channel("impact_force")
    peaks = []
    for impact in (i for b in blocks for i in b.impacts):
        inside = np.flatnonzero((times >= impact.t_start * 1e9) & (times <= impact.t_end * 1e9))
        assert inside.size >= 3, impact   # 0.37 ms at 20 kHz: the impact is sampled
        top = inside[np.argmax(values[inside])]
        peaks.append((int(times[top]), float(values[top])))
    return peaks


def test_the_simulated_force_channel_has_its_impacts():
    config, blocks = simulated()
    impacts = [i for b in blocks for i in b.impacts]
    peaks = impact_peaks()
    assert len(impacts) == len(peaks) >= 10
    # Each impact's largest sample stands far above the noise (0.01 N RMS): a peak, not a noise sample.
    assert min(v for _, v in peaks) > 30.0
    assert max(v for _, v in peaks) == channel("impact_force")[1].max()


@settings(max_examples=60, deadline=None)
@given(cuts=st.lists(st.integers(1, round(20000 * SECONDS) - 1), max_size=40), with_end=st.booleans())
def test_every_impact_peak_reaches_the_view_exactly(cuts, with_end):
    times, values, rate = channel("impact_force")
    shown_t, shown_v = decimate(times, values, cuts, rate=rate if with_end else None)
    shown = dict(zip(shown_t.tolist(), shown_v.tolist(), strict=True))
    for t, v in impact_peaks():
        assert shown.get(t) == v, (t, v, shown.get(t))   # the very sample: its time, its value
    assert shown_v.max() == values.max()
    # Blocks of the simulator node (10 ms) give the same stream as any other split.
    blocks = list(range(200, times.size, 200))
    assert all(np.array_equal(a, b) for a, b in zip(decimate(times, values, blocks, rate=rate),
                                                     (shown_t, shown_v), strict=True))


@settings(max_examples=300, deadline=None)
@given(data=st.data(), rate=st.sampled_from([2000.0, 20000.0, 200000.0, 3000.0]),
       interval_ns=st.sampled_from([INTERVAL_NS, 100_000, 1_000_000, 7_000_003]),
       first=st.integers(0, 10**6), with_end=st.booleans())
def test_the_stream_is_each_intervals_min_and_max_sample_whatever_the_split(data, rate, interval_ns, first,
                                                                             with_end):
    # Small integers: many ties (a quantised laser, a stuck channel), where the earliest sample must win.
    values = np.array(data.draw(st.lists(st.integers(-3, 3), min_size=1, max_size=400)), dtype=np.float64)
    times = sample_times_ns(first, values.size, rate)
    cuts = data.draw(st.lists(st.integers(1, max(1, values.size - 1)), max_size=30))
    got_t, got_v = decimate(times, values, cuts, rate=rate if with_end else None, first=first,
                            interval_ns=interval_ns)
    want_t, want_v = scan(times, values, interval_ns)
    assert np.array_equal(got_t, want_t) and np.array_equal(got_v, want_v)
    # Each point is a sample of the input, at its own time; time order.
    position = np.searchsorted(times, got_t)
    assert np.array_equal(times[position], got_t) and np.array_equal(values[position], got_v)
    assert np.all(np.diff(got_t) > 0)


@pytest.mark.parametrize("rate", [2000.0, 20000.0, 200000.0])
def test_the_views_rate_is_bounded_whatever_the_channels_rate(rate):
    # One second of a noisy channel with a 0.4 ms spike every 0.25 s, in 10 ms blocks.
    rng = np.random.default_rng(3)
    n = round(rate)
    times = sample_times_ns(0, n, rate)
    values = rng.normal(0.0, 0.01, n)
    for start in np.arange(0.1, 1.0, 0.25):
        spike = (times >= start * 1e9) & (times < (start + 4e-4) * 1e9)
        values[spike] += 78.0 * np.hanning(spike.sum() + 2)[1:-1]
    shown_t, shown_v = decimate(times, values, list(range(n // 100, n, n // 100)), rate=rate)
    intervals = 1_000_000_000 // INTERVAL_NS
    per_interval = np.bincount(shown_t // INTERVAL_NS, minlength=intervals)
    assert per_interval.size == intervals and per_interval.max() <= 2 and per_interval.min() >= 1
    assert shown_v.max() == values.max()   # the spikes are there at any rate
    assert shown_t.size <= 2 * intervals   # 400 points/s per channel, whether 2 kHz or 200 kHz come in


def _block(name: str, block) -> SimpleNamespace:
    config, _ = simulated()
    ch = block.channels[name]
    rate = next(c.sample_rate for c in config.channels if c.name == name)
    sec, nanosec = divmod(int(sample_times_ns(ch.first_index, 1, rate)[0]), 1_000_000_000)
    return SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec)),
                           first_index=ch.first_index, sample_rate=rate, samples=ch.samples)


def _event(impact) -> SimpleNamespace:
    sec, nanosec = divmod(round(impact.t_start * 1e9), 1_000_000_000)
    return SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec)),
                           index=impact.index, cycle_index=impact.cycle_index, peak_force=impact.peak_force,
                           impulse=impact.impulse, impact_velocity=impact.impact_velocity, duration=impact.duration,
                           max_penetration=impact.max_penetration,
                           excitation_frequency=impact.excitation_frequency,
                           excitation_phase=impact.excitation_phase)


def mapped(path, display_interval: float) -> dict:
    """The core's blocks and impacts through the bridge's mapping (batches of 10 blocks) into an .rrd; its data."""
    _, blocks = simulated()
    rec = rr.RecordingStream("test_display")
    rec.save(str(path))
    mapper = RigMapper(rec, batch=10, display_interval=display_interval)
    mapper.log_static()
    for block in blocks:   # in the simulator node's order: the channels, then the impacts of the block
        for ch in CHANNELS:
            mapper.log_message(ch.topic, _block(ch.name, block))
        for impact in block.impacts:
            mapper.log_message("impact/events", _event(impact))
    mapper.flush()
    rec.flush()
    rec.disconnect()
    data = load_rrd(path)
    for ch in CHANNELS:   # what the mapper says it sent is what the file holds
        assert mapper.stats.points[ch.name] == data[ch.entity].times.size, ch.name
        assert mapper.stats.samples[ch.name] == channel(ch.name)[1].size, ch.name
    return data


def test_the_mapper_sends_the_display_stream_or_every_sample(tmp_path):
    display = mapped(tmp_path / "display.rrd", INTERVAL_NS / 1e9)
    full = mapped(tmp_path / "full.rrd", 0.0)
    for ch in CHANNELS:
        times, values, rate = channel(ch.name)
        # Full rate: every sample at its time.
        assert np.array_equal(full[ch.entity].times, times) and np.array_equal(full[ch.entity].scalars(), values)
        # Display stream: the envelope of the whole channel, at most 2 points per 5 ms.
        want_t, want_v = scan(times, values)
        assert np.array_equal(display[ch.entity].times, want_t), ch.name
        assert np.array_equal(display[ch.entity].scalars(), want_v), ch.name
        assert display[ch.entity].times.size <= 2 * SECONDS * 1e9 / INTERVAL_NS
    shown = dict(zip(display["channels/impact_force"].times.tolist(),
                     display["channels/impact_force"].scalars().tolist(), strict=True))
    assert all(shown.get(t) == v for t, v in impact_peaks())
    # The impacts are events, the same in both: one marker per impact at its contact start, at its peak force.
    assert np.array_equal(display[IMPACT_MARKERS].times, full[IMPACT_MARKERS].times)
    assert np.array_equal(display[IMPACT_MARKERS].scalars(), full[IMPACT_MARKERS].scalars())
    assert display[IMPACT_MARKERS].times.size == len(impact_peaks())


def test_a_decimator_refuses_an_empty_interval_and_mismatched_arrays():
    with pytest.raises(ValueError, match="must be > 0"):
        EnvelopeDecimator(0)
    with pytest.raises(ValueError, match="same length"):
        EnvelopeDecimator(INTERVAL_NS).feed(np.arange(3, dtype=np.int64), np.zeros(2))


def test_an_interval_of_nan_breaks_the_line_and_nan_does_not_hide_a_peak():
    times = sample_times_ns(0, 200, 20000.0)   # two 5 ms intervals
    values = np.full(200, np.nan)
    values[150] = 5.0
    values[160] = -1.0
    t, v = decimate(times, values, [], rate=20000.0)
    assert t.tolist() == [times[0], times[150], times[160]]
    assert np.isnan(v[0]) and v[1:].tolist() == [5.0, -1.0]
