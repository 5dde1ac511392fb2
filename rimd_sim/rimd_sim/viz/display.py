"""The display stream of a channel: a min/max envelope per display interval, as an oscilloscope's peak detect.

A screen shows a few hundred to a few thousand points across a plot; a 20 kHz channel over the live view's
window holds tens of thousands of samples, and a viewer that receives them all spends its time ingesting
points it cannot draw. The display stream keeps, per channel and per display interval, the interval's smallest
and its largest sample: at most 2 points per interval, whatever the sample rate.

Contract (:class:`EnvelopeDecimator`):

* Intervals are ``[k D, (k + 1) D)`` on the channel's time axis (``D`` = ``interval_ns``, ``k`` an integer): the
  same boundaries for every channel, whatever its rate, so the channels' envelopes line up.
* Each point emitted is an actual sample: its value and its time are the sample's, unchanged. The largest
  sample of an interval is emitted, so every peak that is the largest sample of its interval (an impact's peak
  force sample: impacts are far shorter than an interval and a motor cycle apart) is in the display stream
  exactly, value and time; likewise every trough.
* Within an interval the two points are in time order; an interval whose min and max are one sample (a single
  sample, a flat stretch) gives one point. Ties: the earliest sample of the extreme value.
* Blocks are fed in time order, each sorted in time (as the rig publishes them). The last interval a block
  touches is carried to the next block (as its min and max samples so far, not its samples) unless ``end_ns``
  (the time of the next sample) says that no more of it can come. A block that does not continue the carried
  interval (a later interval, a hole, an earlier time: a block delivered late) closes the carried interval
  first: every sample is still counted, and an interval fed out of order may show as more than one pair.
* NaN samples are skipped by the min and the max; an interval of NaN only gives its first sample (a NaN, which
  breaks the line as it would at full rate).

NumPy only (no ROS, no Rerun): :class:`rimd_sim.viz.rerun_map.RigMapper` uses it for the live bridge's channels.
The work per block is a fixed number of array operations (no loop over samples or intervals in Python).
"""

from __future__ import annotations

import numpy as np

__all__ = ["EnvelopeDecimator", "envelope_indices"]

_EMPTY_T = np.empty(0, dtype=np.int64)
_EMPTY_T.flags.writeable = False
_EMPTY_V = np.empty(0, dtype=np.float64)
_EMPTY_V.flags.writeable = False


def envelope_indices(values: np.ndarray, starts: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices of each segment's min and max sample, in time order within the segment, and the segment of each.

    Args:
        values: float64 samples.
        starts: Start index of each segment (increasing, ``starts[0] == 0``); a segment runs to the next start.
        times: int64 sample times (ns), to order the two points of a segment.

    Returns:
        ``(index, counts)``: the indices into ``values`` (one or two per segment, segments in order, each
        segment's points in time order) and the number of points of each segment (1 when min and max are the
        same sample).
    """
    n, count = values.size, starts.size
    m = n // count
    imax = imin = None
    if m * count == n and (count == 1 or (starts[1] == m and np.array_equal(starts, np.arange(0, n, m)))):
        # Segments of one length (a channel whose blocks hold whole intervals: the rig's): one row each.
        grid = values.reshape(count, m)
        imax = grid.argmax(axis=1) + starts
        imin = grid.argmin(axis=1) + starts
        if np.isnan(values[imax]).any():   # argmax and argmin stop at a NaN: the general path skips them
            imax = imin = None
    if imax is None or imin is None:
        lengths = np.diff(starts, append=n)
        # fmax/fmin: a NaN does not hide the finite samples of its segment
        imax = _first_equal(values, np.fmax.reduceat(values, starts), starts, lengths)
        imin = _first_equal(values, np.fmin.reduceat(values, starts), starts, lengths)
    in_order = times[imin] <= times[imax]
    first = np.where(in_order, imin, imax)
    second = np.where(in_order, imax, imin)
    both = np.empty(2 * starts.size, dtype=np.intp)
    both[0::2] = first
    both[1::2] = second
    keep = np.ones(both.size, dtype=bool)
    keep[1::2] = imin != imax
    return both[keep], np.where(imin != imax, 2, 1)


def _first_equal(values: np.ndarray, extreme: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Per segment, the index of its first sample equal to the segment's ``extreme`` (its first sample if NaN)."""
    hit = values == np.repeat(extreme, lengths)
    nan = np.isnan(extreme)
    if nan.any():   # a segment of NaN only: its extreme is NaN, equal to nothing; take its first sample
        hit[starts[nan]] = True
    candidates = np.flatnonzero(hit)
    # The segment of each candidate; the first candidate of each segment (every segment has one).
    segment = np.searchsorted(starts, candidates, side="right") - 1
    first = np.ones(candidates.size, dtype=bool)
    first[1:] = segment[1:] != segment[:-1]
    return candidates[first]


class EnvelopeDecimator:
    """The min/max envelope of one channel per display interval, fed blocks of samples (see the module docstring).

    Args:
        interval_ns: The display interval ``D`` in ns (> 0).
    """

    def __init__(self, interval_ns: int) -> None:
        """A decimator with nothing carried."""
        if int(interval_ns) <= 0:
            raise ValueError(f"interval_ns {interval_ns} must be > 0")
        self.interval_ns = int(interval_ns)
        self._carried_id: int | None = None   # the interval carried over, k
        self._carried_t = _EMPTY_T            # its min and max samples so far (1 or 2, in time order)
        self._carried_v = _EMPTY_V

    @property
    def carrying(self) -> bool:
        """Whether an interval is carried over, waiting for more of its samples (:meth:`flush` emits it)."""
        return self._carried_id is not None

    def feed(self, times: np.ndarray, values: np.ndarray, end_ns: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One block: the envelope points of the intervals it completes, as ``(times int64 ns, values float64)``.

        Args:
            times: Sample times (int64 ns), increasing.
            values: The samples (same length).
            end_ns: The time of the sample after the block, when known (the mapper knows it from the rate): the
                block's last interval is then emitted at once if that sample is past it. None: the last interval
                is carried until a block continues past it or :meth:`flush`.
        """
        times = np.asarray(times, dtype=np.int64)
        values = np.asarray(values, dtype=np.float64)
        if times.shape != values.shape or times.ndim != 1:
            raise ValueError(f"times {times.shape} and values {values.shape} must be 1-D of the same length")
        d = self.interval_ns
        out_t: list[np.ndarray] = []
        out_v: list[np.ndarray] = []
        if times.size:
            first_id = int(times[0]) // d
            if self._carried_id == first_id:   # the block continues the carried interval: its min and max join
                times = np.concatenate((self._carried_t, times))
                values = np.concatenate((self._carried_v, values))
                self._drop_carried()
            elif self._carried_id is not None:
                out_t.append(self._carried_t)
                out_v.append(self._carried_v)
                self._drop_carried()
            ids = times // d
            starts = np.flatnonzero(ids[1:] != ids[:-1]) + 1
            starts = np.concatenate((np.zeros(1, dtype=starts.dtype), starts))
            index, counts = envelope_indices(values, starts, times)
            last_id = int(ids[-1])
            if end_ns is None or int(end_ns) // d <= last_id:   # more of the last interval may come: carry it
                last = int(counts[-1])
                self._carried_id = last_id
                self._carried_t, self._carried_v = times[index[-last:]], values[index[-last:]]
                index = index[:-last]
            out_t.append(times[index])
            out_v.append(values[index])
        elif self._carried_id is not None and end_ns is not None and int(end_ns) // d > self._carried_id:
            out_t.append(self._carried_t)
            out_v.append(self._carried_v)
            self._drop_carried()
        if not out_t:
            return _EMPTY_T, _EMPTY_V
        if len(out_t) == 1:
            return out_t[0], out_v[0]
        return np.concatenate(out_t), np.concatenate(out_v)

    def flush(self) -> tuple[np.ndarray, np.ndarray]:
        """Emit the carried interval's points as they are (none: empty arrays).

        Samples of that interval fed afterwards make a pair of their own (the peaks are still all shown).
        """
        if self._carried_id is None:
            return _EMPTY_T, _EMPTY_V
        t, v = self._carried_t, self._carried_v
        self._drop_carried()
        return t, v

    def _drop_carried(self) -> None:
        self._carried_id = None
        self._carried_t = _EMPTY_T
        self._carried_v = _EMPTY_V
