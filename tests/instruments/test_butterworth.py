"""The instruments' Butterworth sections (rimd_sim.instruments.butterworth) are scipy.signal.butter's, bit for bit.

The simulator node does not import scipy.signal (a slow import that delays its start); its readings are
bit-identical to scipy's design only if the coefficients are the same floating-point numbers, signs of zeros
included.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import signal

from rimd_sim.instruments.butterworth import highpass1_sos, lowpass2_sos
from rimd_sim.instruments.sensors import Instrument
from rimd_sim.settings.config import load_config

#: Sample rates of the channels (config/rimd.yaml: 2 kHz, 20 kHz, 100 kHz) and others.
RATES = (1.0, 100.0, 1000.0, 2000.0, 20_000.0, 44_100.0, 100_000.0)


def _cutoffs(fs: float) -> list[float]:
    """Cutoffs over the whole valid range (0, fs / 2): random, the configuration's and round ones, both ends."""
    rng = np.random.default_rng(int(fs))
    fixed = [0.5, 0.05, 1.0, 10.0, 100.0, 0.25 * fs, 0.45 * fs, 1e-9 * fs, 0.4999999 * fs]
    return [c for c in [*rng.uniform(0.0, 0.5, 300) * fs, *fixed] if 0.0 < c < fs / 2]


def _identical(mine: np.ndarray, theirs: np.ndarray) -> bool:
    return (mine.shape == theirs.shape and np.array_equal(mine, theirs)
            and np.array_equal(np.signbit(mine), np.signbit(theirs)))


@pytest.mark.parametrize("fs", RATES)
def test_lowpass2_is_scipy_butter_bit_for_bit(fs: float) -> None:
    for cutoff in _cutoffs(fs):
        theirs = signal.butter(2, cutoff, btype="lowpass", fs=fs, output="sos")
        assert _identical(lowpass2_sos(cutoff, fs), theirs), (fs, cutoff)


@pytest.mark.parametrize("fs", RATES)
def test_highpass1_is_scipy_butter_bit_for_bit(fs: float) -> None:
    for cutoff in _cutoffs(fs):
        theirs = signal.butter(1, cutoff, btype="highpass", fs=fs, output="sos")
        assert _identical(highpass1_sos(cutoff, fs), theirs), (fs, cutoff)


@pytest.mark.parametrize("design", [lowpass2_sos, highpass1_sos])
@pytest.mark.parametrize("cutoff", [0.0, -1.0, 1000.0, 1500.0, float("nan")])
def test_a_cutoff_outside_zero_to_nyquist_is_refused(design, cutoff: float) -> None:
    with pytest.raises(ValueError, match="half the sample rate"):
        design(cutoff, 2000.0)


def test_every_channel_filters_as_with_scipy() -> None:
    """Each channel of the shipped configuration, its high-pass and a low-pass forced in: scipy's sections."""
    for channel in load_config(None).channels:
        highpass = channel.highpass or 2.0
        for bandwidth in (0.0, 0.3 * channel.sample_rate):
            instrument = Instrument(dataclasses.replace(channel, bandwidth=bandwidth, highpass=highpass),
                                    noise=False, seed=0)
            sections = [signal.butter(1, highpass, btype="highpass", fs=channel.sample_rate, output="sos")]
            if bandwidth:
                sections.insert(0, signal.butter(2, bandwidth, btype="lowpass", fs=channel.sample_rate,
                                                 output="sos"))
            assert _identical(instrument._sos, np.vstack(sections)), channel.name
