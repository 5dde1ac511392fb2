"""The rig's stamps: simulation time to ROS time in exact integer nanoseconds, and back for a request's stamp.

A stamp is ``t0_ns`` plus the simulation time, rounded to the nearest nanosecond; ``t0_ns`` is the wall time of
the run's start when the stamps are wall-clock, else 0 (:mod:`rimd_sim.runtime.simulator`). The arithmetic is on
integers and Fractions, so a stamp never depends on float rounding.
"""

from __future__ import annotations

from fractions import Fraction

__all__ = ["block_end_stamps", "sample_stamp_ns", "show_stamp", "stamp_ns", "stamp_time"]


def stamp_ns(t0_ns: int, t: Fraction) -> int:
    """ROS time in integer nanoseconds of simulation time ``t`` (exact, rounded to the nearest ns, half to even).

    In integers, as ``round(t * 1_000_000_000)`` rounds a Fraction, without the Fractions it would build.
    """
    num, den = t.as_integer_ratio()
    q, r = divmod(num * 1_000_000_000, den)
    if 2 * r > den or (2 * r == den and q & 1):
        q += 1
    return t0_ns + q


def block_end_stamps(t0_ns: int, first: int, count: int, rate: Fraction) -> list[int]:
    """``stamp_ns(t0_ns, k / rate)`` for the ``count`` block boundaries ``k = first, first + 1, ...``.

    In integers, rounded half to even as ``round`` rounds a Fraction: the pacing asks for them at every pass,
    and a Fraction per boundary costs more than the pass's other pacing work.
    """
    num, den = rate.numerator, rate.denominator
    ends = []
    for k in range(first, first + count):
        q, r = divmod(k * 1_000_000_000 * den, num)
        if 2 * r > num or (2 * r == num and q & 1):
            q += 1
        ends.append(t0_ns + q)
    return ends


def sample_stamp_ns(t0_ns: int, n: int, rate: Fraction) -> int:
    """Stamp of sample ``n`` of a channel at ``rate``: ``t0 + n / rate`` in exact integer nanoseconds."""
    rate_num, rate_den = rate.as_integer_ratio()
    num = n * 1_000_000_000 * rate_den
    return t0_ns + (2 * num + rate_num) // (2 * rate_num)


def stamp_time(t0_ns: int, ns: int) -> Fraction:
    """Simulation time (s, exact) of the stamp ``ns``: the inverse of :func:`stamp_ns`."""
    return Fraction(ns - t0_ns, 1_000_000_000)


def show_stamp(ns: int) -> str:
    """A stamp in seconds, exact to the nanosecond.

    A float64 resolves epoch seconds between 2**30 and 2**31 (the years 2004 to 2038) only to 2**-22 s, 238 ns.
    """
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"
