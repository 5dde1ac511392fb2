"""The rig's impact resonance as a rest sweep finds it: the reference a controller's result is checked against.

The resonance is the frequency of the largest steady peak impact force from rest (``rimd sweep --direction rest``,
rimd_sim.analysis.dynamics.sweep) in band A (one impact per cycle, the band the controllers of
tests/ros/test_controller_example.py start in): a 0.1 Hz sweep over ``low``..``high`` finds the band's peak, and a
0.01 Hz sweep 0.1 Hz either side of it finds the resonance. One process, a second or two; cached per
configuration.
"""

from __future__ import annotations

import functools

import numpy as np

from rimd_sim.analysis.dynamics.sweep import band_peak, sweep
from rimd_sim.settings.config import load_config


@functools.lru_cache(maxsize=8)
def rest_resonance(gap: float, low: float = 2.5, high: float = 4.5) -> tuple[float, float]:
    """``(frequency_hz, peak_force_n)`` of band A's largest steady peak force from rest at ``gap`` (m), to 0.01 Hz."""
    config = load_config(None, {"gap": gap})
    coarse = band_peak(sweep(config, np.round(np.arange(low, high + 0.05, 0.1), 4), "rest", workers=1).points, 1.0)
    assert coarse is not None, f"no 1/1 motion from rest between {low} and {high} Hz at gap {gap * 1e3:g} mm"
    around = np.round(np.arange(coarse.frequency_hz - 0.1, coarse.frequency_hz + 0.105, 0.01), 4)
    fine = band_peak(sweep(config, around, "rest", workers=1).points, 1.0)
    assert fine is not None
    return fine.frequency_hz, fine.peak_force_n
