"""What a DAQ can tell about a channel's health from its stream alone (no knowledge of the faults injected).

:func:`scan_channel` takes the blocks of one channel in the order they arrived and returns
:class:`Finding` windows (simulation time from the channel's sample 0, ``first_index / rate``):

* ``gap``: samples never received (a hole in ``first_index``: dropout, lost blocks);
* ``late``: blocks that arrived after a block with a later ``first_index`` (out of order), or more than
  ``late_blocks`` block periods after their last sample (when the arrival time is known: delay);
* ``stuck``: runs of at least ``stuck_min`` identical consecutive readings (a live sensor's noise never
  repeats a value that often);
* ``rail``: blocks whose every sample sits on ``range_max`` and is counted saturated (no sensor);
* ``saturated``: blocks with some samples counted saturated (clipping);
* ``outliers``: isolated samples further than ``outlier_fraction`` of the range span from the median of
  their 5 neighbours;
* ``level``: blocks whose median is off the median of all block medians by more than ``level_sigmas``
  noise standard deviations and 6 robust spreads of the block medians (offsets; sensitive on channels with
  a steady baseline, such as the force sensor between impacts; on a moving signal only large offsets show);
* ``noise``: blocks whose noise (robust, from the second differences) exceeds ``noise_ratio`` times the
  reference (noise bursts, gain errors).

The reference is the channel's own first ``reference_s`` seconds (assumed healthy). Flagged blocks closer
than ``merge`` blocks are merged into one window. :func:`impact_times` and :func:`drift_ppm` estimate a
clock drift from the impacts seen on two channels.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Block", "Finding", "drift_fit", "drift_window", "impact_times", "scan_channel", "stream"]


@dataclass(frozen=True)
class Block:
    """One received block.

    ``first_index``, readings, ``saturated_count`` and, when the DAQ knows it, the simulation time it arrived
    at (``arrival``, s; NaN = unknown).
    """

    first_index: int
    samples: np.ndarray
    saturated: int = 0
    arrival: float = float("nan")


@dataclass(frozen=True)
class Finding:
    """A window of the stream where something is wrong: ``kind``, start and end (s), a short detail."""

    kind: str
    start: float
    end: float
    detail: str = ""


def stream(blocks: Sequence[Block]) -> tuple[np.ndarray, np.ndarray]:
    """The received samples in index order (duplicates dropped): ``(indices, values)``."""
    ordered = sorted({b.first_index: b for b in blocks}.values(), key=lambda b: b.first_index)
    if not ordered:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    idx = np.concatenate([np.arange(b.first_index, b.first_index + len(b.samples)) for b in ordered])
    val = np.concatenate([np.asarray(b.samples, dtype=float) for b in ordered])
    return idx, val


def _windows(flags: list[tuple[int, int]], rate: float, merge_samples: int, kind: str, what: str) -> list[Finding]:
    """Merge flagged sample ranges ``[a, b)`` closer than ``merge_samples`` into findings."""
    out: list[list[int]] = []
    for a, b in sorted(flags):
        if out and a - out[-1][1] <= merge_samples:
            out[-1][1] = max(out[-1][1], b)
            out[-1][2] += 1
        else:
            out.append([a, b, 1])
    return [Finding(kind, a / rate, b / rate, f"{n} {what}") for a, b, n in out]


def _noise(x: np.ndarray) -> float:
    """Robust noise standard deviation from the second differences (insensitive to slow signals)."""
    if x.size < 4:
        return 0.0
    d2 = np.diff(x, 2)
    return float(np.median(np.abs(d2 - np.median(d2))) * 1.4826 / np.sqrt(6.0))


def scan_channel(blocks: Sequence[Block], rate: float, range_min: float, range_max: float, *,
                 reference_s: float = 0.4, stuck_min: int = 10, outlier_fraction: float = 0.1,
                 level_sigmas: float = 20.0, noise_ratio: float = 1.6, merge: int = 3,
                 late_blocks: float = 3.0, chunk_min: int = 200, impacts: np.ndarray | None = None) -> list[Finding]:
    """Findings of one channel, blocks in arrival order (see the module docstring).

    ``impacts``: times (s, the channel's ``first_index / rate``) of impacts seen on another channel: an isolated
    sample within 2 ms of one is the impact itself (a short contact spans one or two accelerometer samples at
    20 kHz), not an outlier.
    """
    if not blocks:
        return []
    n_block = max(len(b.samples) for b in blocks) or 1
    merge_samples = merge * n_block
    findings: list[Finding] = []
    # gaps and late blocks
    ordered = sorted(blocks, key=lambda b: b.first_index)
    gaps = []
    for prev, cur in zip(ordered, ordered[1:], strict=False):
        end = prev.first_index + len(prev.samples)
        if cur.first_index > end:
            gaps.append((end, cur.first_index))
    findings += _windows(gaps, rate, merge_samples, "gap", "hole(s) in first_index")
    late = []
    seen = -1
    for b in blocks:
        lag = b.arrival - (b.first_index + len(b.samples)) / rate
        if b.first_index < seen or lag > late_blocks * n_block / rate:
            late.append((b.first_index, b.first_index + len(b.samples)))
        seen = max(seen, b.first_index)
    findings += _windows(late, rate, merge_samples, "late", "block(s) late or out of order")
    # per-block reading checks
    ref_blocks = [b for b in ordered if b.first_index < reference_s * rate and len(b.samples) and b.saturated == 0]
    ref = np.concatenate([np.asarray(b.samples, float) for b in ref_blocks]) if ref_blocks else np.zeros(0)
    ref_median = float(np.median(ref)) if ref.size else 0.0
    ref_noise = _noise(ref) if ref.size else 0.0
    rail, sat, level, noisy = [], [], [], []
    span = range_max - range_min
    for b in ordered:
        x = np.asarray(b.samples, dtype=float)
        if not x.size:
            continue
        r = (b.first_index, b.first_index + x.size)
        if b.saturated == x.size and np.all(x == range_max):
            rail.append(r)
        elif b.saturated:
            sat.append(r)
    # Level and noise over chunks of at least chunk_min samples (whole blocks; a 2 kHz channel's 20-sample
    # blocks are too short for a robust noise estimate), rail blocks left out.
    chunks: list[tuple[int, int, np.ndarray]] = []
    acc: list[Block] = []
    for b in ordered:
        if not len(b.samples) or (b.saturated == len(b.samples) and np.all(np.asarray(b.samples) == range_max)):
            continue
        acc.append(b)
        if sum(len(a.samples) for a in acc) >= chunk_min:
            chunks.append((acc[0].first_index, acc[-1].first_index + len(acc[-1].samples),
                           np.concatenate([np.asarray(a.samples, float) for a in acc])))
            acc = []
    # Level: against the median of all chunk medians, beyond the larger of level_sigmas noise deviations and
    # 6 robust spreads of the chunk medians (a moving signal, such as a displacement, spreads them).
    medians = np.array([float(np.median(x)) for _, _, x in chunks])
    center = float(np.median(medians)) if medians.size else ref_median
    spread = float(np.median(np.abs(medians - center))) * 1.4826 if medians.size else 0.0
    level_limit = max(level_sigmas * ref_noise, 6.0 * spread)
    if ref_noise > 0:
        for (start, end, x), med in zip(chunks, medians, strict=True):
            if abs(med - center) > level_limit:
                level.append((start, end))
            if _noise(x) > noise_ratio * ref_noise:
                noisy.append((start, end))
    findings += _windows(rail, rate, merge_samples, "rail", "block(s) on the rail")
    findings += _windows(sat, rate, merge_samples, "saturated", "block(s) with clipped samples")
    findings += _windows(level, rate, merge_samples, "level", "block(s) off the reference level")
    findings += _windows(noisy, rate, merge_samples, "noise", "block(s) noisier than the reference")
    # sample checks over contiguous stretches
    idx, val = stream(ordered)
    if val.size:
        cuts = np.flatnonzero(np.diff(idx) != 1) + 1
        stuck, outliers = [], []
        for seg_i, seg_v in zip(np.split(idx, cuts), np.split(val, cuts), strict=True):
            if seg_v.size < 2:
                continue
            same = np.r_[False, seg_v[1:] == seg_v[:-1]]
            # runs of equal values: starts where same goes False->True
            edges = np.diff(same.astype(np.int8))
            starts = np.flatnonzero(edges == 1)            # index of the run's first value
            ends = np.flatnonzero(edges == -1) + 1
            if same[-1]:
                ends = np.r_[ends, seg_v.size]
            for run_start, run_end in zip(starts, ends, strict=False):
                if run_end - run_start >= stuck_min and seg_v[run_start] != range_max:
                    stuck.append((int(seg_i[run_start]), int(seg_i[run_end - 1]) + 1))
            if seg_v.size >= 5:
                padded = np.pad(seg_v, 2, mode="edge")
                windows = np.lib.stride_tricks.sliding_window_view(padded, 5)
                med = np.median(windows, axis=1)
                dev = np.abs(seg_v - med) > outlier_fraction * span
                if impacts is not None and len(impacts):
                    tk = seg_i / rate
                    j = np.clip(np.searchsorted(impacts, tk), 1, max(len(impacts) - 1, 1))
                    near = np.minimum(np.abs(impacts[j - 1] - tk), np.abs(impacts[np.minimum(j, len(impacts) - 1)]
                                                                          - tk)) < 2e-3
                    dev &= ~near
                for k in np.flatnonzero(dev):
                    outliers.append((int(seg_i[k]), int(seg_i[k]) + 1))
        findings += _windows(stuck, rate, merge_samples, "stuck", "run(s) of a repeated value")
        findings += _windows(outliers, rate, merge_samples, "outliers", "isolated outlier(s)")
    return sorted(findings, key=lambda f: (f.start, f.kind))


def impact_times(blocks: Sequence[Block], rate: float, threshold: float, *, absolute: bool = False) -> np.ndarray:
    """Times (s, ``index / rate``) of the upward crossings of ``threshold``.

    ``|x|`` when ``absolute``; a crossing counts after at least 2 ms below the threshold, contiguous samples.
    """
    idx, val = stream(blocks)
    if not val.size:
        return np.zeros(0)
    x = np.abs(val) if absolute else val
    above = x >= threshold
    rising = np.flatnonzero(above[1:] & ~above[:-1]) + 1
    quiet = max(1, int(0.002 * rate))
    keep = [idx[k] for k in rising
            if k >= quiet and not above[k - quiet:k].any() and idx[k] - idx[k - quiet] == quiet]
    return np.asarray(keep, dtype=float) / rate


def drift_window(t: np.ndarray, lag: np.ndarray, rate: float) -> tuple[float, float, float] | None:
    """Start (s), end (s) and rate (s/s) of a clock drift from the lags of :func:`drift_fit`.

    The lags before the drift are the two channels' constant offset (their median); a line is fitted to the
    lags that grow beyond it by more than a sample and have not reached the final plateau; the drift starts
    where the line leaves the offset and ends where it reaches the plateau (in the drifting channel's stamps).
    None when no drift is seen.
    """
    if t.size < 4:
        return None
    base = float(np.median(lag[: max(2, t.size // 8)]))
    grow = lag - base
    moving = np.flatnonzero(grow > 1.5 / rate)
    if moving.size < 2:
        return None
    plateau = float(grow[-1])
    rising = moving[grow[moving] < plateau - 1.5 / rate]
    if rising.size < 2:
        return None
    slope, intercept = np.polyfit(t[rising], grow[rising], 1)
    start = -intercept / slope
    # the end in the drifting channel's own stamps (true time + its lag), as the fault was stated
    end = (plateau - intercept) / slope + plateau if abs(grow[-1] - grow[-2]) < 1.5 / rate else float("inf")
    return float(start), float(end), float(slope)


def drift_fit(t_ref: np.ndarray, t_other: np.ndarray, tolerance: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Pair each impact of ``t_ref`` with the nearest of ``t_other`` within ``tolerance`` s.

    Returns ``(t_ref_paired, t_other - t_ref)``: how far the other channel's clock has drifted at each impact.
    """
    if not t_ref.size or not t_other.size:
        return np.zeros(0), np.zeros(0)
    j = np.clip(np.searchsorted(t_other, t_ref), 1, t_other.size - 1) if t_other.size > 1 else np.zeros(
        t_ref.size, dtype=int)
    cand = np.stack([t_other[np.maximum(j - 1, 0)], t_other[j]])
    best = cand[np.argmin(np.abs(cand - t_ref), axis=0), np.arange(t_ref.size)]
    ok = np.abs(best - t_ref) <= tolerance
    return t_ref[ok], (best - t_ref)[ok]
