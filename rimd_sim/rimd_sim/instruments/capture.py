"""Triggered capture around each impact, as the paper's oscilloscopes took it (section 2).

The model samples the force and the hammer's acceleration at the capture rate (default 1 MHz) as two extra
channels (:class:`~rimd_sim.model.rig_model.RigModel` ``extra_channels``); :class:`TriggeredCapture` watches the
force like a scope in normal trigger mode: a capture starts when the force crosses ``threshold`` upwards
(the signal, not the model's contact event), keeps ``pre_trigger`` seconds before that sample and
``post_trigger`` seconds from it, and re-arms once the window is complete. Each capture gets the force
sensor's and the accelerometer's noise (their ``noise_std``, from a stream of its own seeded by the
simulator's seed) and is clipped to their ranges; the noise is drawn for the captured samples only, so the
cost does not grow with the capture rate between impacts.

Cost: the model evaluates the fast force and acceleration only in contact (the force is 0 and the
acceleration NaN outside, filled cheaply); outside contact the captured acceleration is interpolated
linearly between the acceleration channel's noise-free 20 kHz samples (free flight is smooth: the error is
well under 1 m/s^2 against hundreds in contact). Figures: ``benchmarks/bench_faults.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np

from rimd_sim.settings.capture import CaptureConfig

if TYPE_CHECKING:
    from rimd_sim.settings.config import ChannelConfig

__all__ = ["CaptureRecord", "TriggeredCapture"]

@dataclass(frozen=True)
class CaptureRecord:
    """One capture: its number, the trigger's sample index at the capture rate, the samples."""

    number: int
    trigger_index: int
    sample_rate: float
    pre_trigger_samples: int
    force: np.ndarray
    acceleration: np.ndarray
    threshold: float

    @property
    def trigger_time(self) -> Fraction:
        """Simulation time of the trigger sample (s, exact)."""
        return Fraction(self.trigger_index) / Fraction(repr(self.sample_rate))


class TriggeredCapture:
    """The scope: feed it the fast force and acceleration pass by pass, get the completed captures.

    Args:
        config: The capture settings (enabled).
        force: The force channel (noise and range of the captured force).
        acceleration: The acceleration channel.
        seed: The simulator's seed.
    """

    def __init__(self, config: CaptureConfig, force: ChannelConfig, acceleration: ChannelConfig, seed: int,
                 *, noise: bool = True) -> None:
        self.config = config
        self._pre = round(config.pre_trigger * config.sample_rate)
        self._post = max(1, round(config.post_trigger * config.sample_rate))
        self._force = force
        self._acc = acceleration
        self._noise = noise
        self._rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(2000,))))
        self._hist_first = 0
        self._hist_f = np.zeros(0)
        self._hist_a = np.zeros(0)
        self._slow_first = 0
        self._slow_a = np.zeros(0)
        self._slow_f = np.zeros(0)
        self._rearm = 0
        self._pending: list[tuple[int, int]] = []
        self._count = 0

    def process(self, first: int, force: np.ndarray, acc: np.ndarray, slow_first: int, slow_rate: float,
                slow_acc: np.ndarray, slow_force: np.ndarray) -> list[CaptureRecord]:
        """Take the next stretch (samples ``first ..`` at the capture rate); return the captures completed.

        ``acc`` is the acceleration in contact only (NaN outside, because evaluating it at 1 MHz all the time
        would be the capture's main cost); outside contact, where it is smooth, the captured acceleration is
        interpolated linearly between the noise-free samples of the acceleration channel (``slow_acc`` from index
        ``slow_first`` at ``slow_rate``) that lie outside contact (``slow_force`` zero).
        """
        thr = self.config.threshold
        n_slow = self._slow_a.size
        slow_base = slow_first - n_slow
        a_slow = np.concatenate([self._slow_a, slow_acc]) if n_slow else slow_acc
        f_slow = np.concatenate([self._slow_f, slow_force]) if n_slow else slow_force
        n_hist = self._hist_f.size
        assert self._hist_first + n_hist == first or n_hist == 0
        base = first - n_hist
        f_all = np.concatenate([self._hist_f, force]) if n_hist else force
        a_all = np.concatenate([self._hist_a, acc]) if n_hist else acc
        if force.size:
            above = force >= thr
            before = np.empty_like(above)
            before[0] = n_hist > 0 and self._hist_f[-1] >= thr
            before[1:] = above[:-1]
            for c in np.flatnonzero(above & ~before):
                idx = first + int(c)
                if idx < self._rearm:
                    continue
                self._pending.append((idx, self._count))
                self._count += 1
                self._rearm = idx + self._post
        end = first + force.size
        done = []
        keep = []
        for idx, number in self._pending:
            if idx + self._post > end:
                keep.append((idx, number))
                continue
            lo = max(idx - self._pre, base)
            hi = idx + self._post
            f = f_all[lo - base:hi - base].copy()
            a = a_all[lo - base:hi - base].copy()
            gaps = np.isnan(a)
            if gaps.any():
                free = f_slow == 0.0
                xp = np.arange(slow_base, slow_base + a_slow.size)[free] / slow_rate
                a[gaps] = np.interp(np.arange(lo, hi)[gaps] / self.config.sample_rate, xp, a_slow[free]) \
                    if xp.size else 0.0
            if self._noise:
                f += self._force.noise_std * self._rng.standard_normal(f.size)
                a += self._acc.noise_std * self._rng.standard_normal(a.size)
            np.clip(f, self._force.range_min, self._force.range_max, out=f)
            np.clip(a, self._acc.range_min, self._acc.range_max, out=a)
            done.append(CaptureRecord(number, idx, self.config.sample_rate, idx - lo, f, a, thr))
        self._pending = keep
        # keep what a pending capture or the next one's pre-trigger part still needs
        need_from = min([end - self._pre] + [idx - self._pre for idx, _ in keep])
        need_from = max(need_from, base)
        self._hist_f = f_all[need_from - base:].copy()
        self._hist_a = a_all[need_from - base:].copy()
        self._hist_first = need_from
        slow_from = max(slow_base, int(math.floor(need_from / self.config.sample_rate * slow_rate)) - 2)
        self._slow_a = a_slow[slow_from - slow_base:].copy()
        self._slow_f = f_slow[slow_from - slow_base:].copy()
        return done
