"""An instrument's readings (rimd_sim.instruments.sensors) are its documented chain's, bit for bit.

The chain runs in one compiled call per stretch; the reference here is the chain written as numpy expressions, one
operation each (the filter, the noise scaled and added, the quantisation, the range), with its own noise stream
seeded as the instrument seeds its own and drawn per stretch. Equal arrays, equal clip masks and equal counts,
whatever the channel's settings and however the stream is cut into stretches (across the instrument's draws
ahead too: up to 18,000 samples against 4,096 a draw).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from rimd_sim.instruments.sensors import Instrument, _sos_filter
from rimd_sim.settings.config import CHANNEL_NAMES, load_config


class NumpyChain:
    """The chain of the sensors module's docstring in numpy, with the instrument's filter sections and noise stream."""

    def __init__(self, instrument: Instrument, noise: bool, seed: int) -> None:
        self.ch = instrument.channel
        self.noise = noise
        stream = CHANNEL_NAMES.index(self.ch.name)
        self.rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(stream,))))
        self.sos = None if instrument._sos is None else instrument._sos.copy()
        self.zi = None if self.sos is None else np.zeros((self.sos.shape[0], 2))

    def read(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ch = self.ch
        x = np.array(values, dtype=np.float64)
        if self.sos is not None and x.size:
            _sos_filter(self.sos, x, self.zi)   # the cascade itself is checked against scipy in test_streaming
        if self.noise and ch.noise_std > 0.0 and x.size:
            x += ch.noise_std * self.rng.standard_normal(x.size)
        if ch.resolution > 0.0:
            x = np.round(x / ch.resolution) * ch.resolution
        clipped = (x < ch.range_min) | (x > ch.range_max)
        return np.clip(x, ch.range_min, ch.range_max), clipped


@settings(max_examples=60, deadline=None)
@given(channel=st.sampled_from(CHANNEL_NAMES), noise=st.booleans(), seed=st.integers(0, 2**32 - 1),
       filtered=st.booleans(), resolution=st.sampled_from([0.0, 1e-6, 1.5e-6, 0.01, 0.5]),
       half_range=st.floats(0.05, 5.0), cuts=st.lists(st.integers(0, 3000), min_size=1, max_size=6))
def test_readings_are_the_numpy_chain_bit_for_bit(channel: str, noise: bool, seed: int, filtered: bool,
                                                  resolution: float, half_range: float, cuts: list[int]) -> None:
    base = next(c for c in load_config(None).channels if c.name == channel)
    config = dataclasses.replace(base, noise_std=0.3, resolution=resolution, range_min=-half_range,
                                 range_max=half_range, bandwidth=0.2 * base.sample_rate if filtered else 0.0,
                                 highpass=2.0 if filtered else 0.0)
    instrument = Instrument(config, noise=noise, seed=seed)
    reference = NumpyChain(instrument, noise, seed)
    signal = 2.0 * np.sin(np.linspace(0.0, 40.0, sum(cuts)))   # crosses a range end for most half ranges
    start = 0
    for size in cuts:
        stretch = signal[start:start + size]
        start += size
        mine, mask = instrument.measure_mask(stretch)
        theirs, clipped = reference.read(stretch)
        assert mine.tobytes() == theirs.tobytes()
        if mask is None:
            assert not clipped.any()
        else:
            assert np.array_equal(mask, clipped) and mask.any()
        count = instrument.measure(np.zeros(0)).saturated   # an empty stretch: nothing read, nothing drawn
        assert count == 0


def test_a_reading_counts_the_samples_clipped_at_either_end() -> None:
    base = next(c for c in load_config(None).channels if c.name == "rimd_displacement")
    instrument = Instrument(dataclasses.replace(base, range_min=-1.0, range_max=2.0, resolution=0.0, bandwidth=0.0,
                                                highpass=0.0), noise=False, seed=0)
    reading = instrument.measure(np.array([-3.0, -1.0, 0.5, 2.0, 2.5, 7.0]))
    assert reading.samples.tolist() == [-1.0, -1.0, 0.5, 2.0, 2.0, 2.0]
    assert reading.saturated == 3
