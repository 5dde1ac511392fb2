"""Instrument models: what a DAQ channel reads given the noise-free physical quantity.

Chain, applied to each block of samples in order (filter states carry over between blocks, so the
result does not depend on how the stream is cut into blocks):

1. bandwidth: a 2nd-order Butterworth low-pass at ``bandwidth`` Hz (the instrument's upper frequency
   limit), only when it lies below 0.45 x the sample rate (above that it cannot be represented at the
   channel's rate and has no effect);
2. AC coupling: a 1st-order high-pass at ``highpass`` Hz (piezoelectric sensors' discharge time constant);
3. additive white Gaussian noise of standard deviation ``noise_std`` (when noise is enabled), from a
   per-channel stream seeded by ``(seed, channel index)``;
4. quantisation to ``resolution``;
5. saturation: the reading is clipped to ``[range_min, range_max]`` and the clipped samples are counted.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from rimd_sim.instruments.butterworth import highpass1_sos, lowpass2_sos
from rimd_sim.settings.config import CHANNEL_NAMES, ChannelConfig

__all__ = ["Instrument", "Reading"]


# The compiled functions here keep the GIL: a call takes microseconds on the simulator's pacing thread, and a
# release there would hand the GIL to another thread of the node that the pacing thread must then wait for.
@njit(cache=True)
def _sos_filter(sos, x, zi):  # pragma: no cover - compiled
    """In-place cascade of biquads (direct form II transposed), state ``zi`` carried between calls.

    The same recursion as ``scipy.signal.sosfilt`` without its per-call overhead.
    """
    for s in range(sos.shape[0]):
        b0, b1, b2, a0, a1, a2 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 3], sos[s, 4], sos[s, 5]
        z0 = zi[s, 0]
        z1 = zi[s, 1]
        for i in range(x.shape[0]):
            xi = x[i]
            yi = (b0 * xi + z0) / a0
            z0 = (b1 * xi - a1 * yi) / a0 + z1
            z1 = (b2 * xi - a2 * yi) / a0
            x[i] = yi
        zi[s, 0] = z0
        zi[s, 1] = z1


@njit(cache=True, _nrt=False)  # type: ignore[call-overload]  # _nrt: numba's option (model/jit.py)
def _read(values, x, sos, zi, noise, noise_std, resolution, range_min, range_max, clipped):  # pragma: no cover
    """The chain of the module docstring on one stretch, in one compiled call: the readings of ``values`` in ``x``.

    ``sos`` with no rows: no filter; ``noise`` empty: no noise (else one standard normal per sample, scaled by
    ``noise_std``); ``resolution`` 0: no quantisation. ``clipped`` receives the mask of the samples clipped at a
    range end; returns how many there are. Each step is the numpy expression it replaces, operation for operation
    (no fused multiply-add), so the readings are bit for bit those of the numpy chain.
    """
    n = values.shape[0]
    for i in range(n):
        x[i] = values[i]
    if sos.shape[0]:
        _sos_filter(sos, x, zi)
    if noise.shape[0]:
        for i in range(n):
            x[i] += noise_std * noise[i]
    count = 0
    for i in range(n):
        v = x[i]
        if resolution > 0.0:
            v = np.rint(v / resolution) * resolution
        out = v < range_min or v > range_max
        clipped[i] = out
        if out:
            count += 1
            v = min(max(v, range_min), range_max)
        x[i] = v
    return count


#: The filter of a channel without one: no section (``_read`` skips it).
_NO_SOS = np.zeros((0, 6))
_NO_ZI = np.zeros((0, 2))
_NO_NOISE = np.zeros(0)
#: Standard normals an instrument draws at once (32 kB; 20 blocks of a 20 kHz channel at 100 blocks/s).
NORMALS_AHEAD = 4096


class Reading:
    """One block of readings of a channel.

    Attributes:
        samples: The readings (SI).
        saturated: How many samples were clipped at a range end.
    """

    __slots__ = ("samples", "saturated")

    def __init__(self, samples: np.ndarray, saturated: int) -> None:
        self.samples = samples
        self.saturated = saturated


class Instrument:
    """A sensor on one channel.

    Args:
        channel: The channel's configuration.
        noise: Whether to add noise.
        seed: Seed of the random streams (the channel's own stream is derived from it).
    """

    def __init__(self, channel: ChannelConfig, *, noise: bool, seed: int) -> None:
        stream = CHANNEL_NAMES.index(channel.name)
        self._rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(stream,))))
        self._normals = _NO_NOISE   # drawn ahead from the stream (:meth:`_draw`); the next unused at _next_normal
        self._next_normal = 0
        self._channel = channel
        self._noise = noise
        self._design()

    def _design(self) -> None:
        ch = self._channel
        sections = []
        if 0.0 < ch.bandwidth < 0.45 * ch.sample_rate:
            sections.append(lowpass2_sos(ch.bandwidth, ch.sample_rate))   # = scipy.signal.butter(2, ..., "sos")
        if ch.highpass > 0.0:
            sections.append(highpass1_sos(ch.highpass, ch.sample_rate))   # = scipy.signal.butter(1, ..., "sos")
        self._sos = np.vstack(sections) if sections else None
        self._zi = np.zeros((self._sos.shape[0], 2)) if self._sos is not None else None

    @property
    def channel(self) -> ChannelConfig:
        """The channel's configuration."""
        return self._channel

    def reconfigure(self, channel: ChannelConfig, *, noise: bool) -> None:
        """Change the instrument's parameters; the sample rate must stay the same.

        The filter state restarts only when the filter changes.
        """
        if channel.sample_rate != self._channel.sample_rate:
            raise ValueError("the sample rate of a running channel cannot change")
        filters_changed = (channel.bandwidth, channel.highpass) != (self._channel.bandwidth, self._channel.highpass)
        self._channel = channel
        self._noise = noise
        if filters_changed:
            self._design()

    def measure_each(self, values: np.ndarray, ranges: list[tuple[int, int]]) -> list[tuple[tuple[int, int],
                                                                                              np.ndarray, int]]:
        """Measure a stretch once and cut it into blocks: ``[((lo, hi), readings, saturated), ...]``."""
        x, clipped = self._measure(values)
        return [((lo, hi), x[lo:hi], int(np.count_nonzero(clipped[lo:hi])) if clipped is not None else 0)
                for lo, hi in ranges]

    def measure(self, values: np.ndarray) -> Reading:
        """Turn a block of noise-free values into readings."""
        x, clipped = self._measure(values)
        return Reading(x, int(np.count_nonzero(clipped)) if clipped is not None else 0)

    def measure_mask(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Readings of a stretch and the mask of clipped samples (None: none clipped)."""
        return self._measure(values)

    def _draw(self, n: int) -> np.ndarray:
        """The next ``n`` standard normals of the channel's stream.

        Drawn :data:`NORMALS_AHEAD` at a time: the Generator draws each normal from the bits that follow the last
        one's, so the numbers are those of one draw of ``n`` per stretch, at one call per many blocks.
        """
        at = self._next_normal
        if at + n > self._normals.size:
            rest = self._normals[at:]
            self._normals = np.concatenate([rest, self._rng.standard_normal(max(n - rest.size, NORMALS_AHEAD))])
            at = 0
        self._next_normal = at + n
        return self._normals[at:at + n]

    def _measure(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        ch = self._channel
        values = np.ascontiguousarray(values, dtype=np.float64)
        n = values.size
        x = np.empty(n)
        clipped = np.empty(n, dtype=np.bool_)
        if not n:
            return x, None
        noise = self._draw(n) if self._noise and ch.noise_std > 0.0 else _NO_NOISE
        sos, zi = (self._sos, self._zi) if self._sos is not None else (_NO_SOS, _NO_ZI)
        if _read(values, x, sos, zi, noise, ch.noise_std, ch.resolution, ch.range_min, ch.range_max, clipped):
            return x, clipped
        return x, None
