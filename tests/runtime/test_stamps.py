"""The rig's stamps (rimd_sim.runtime.stamps), computed in integers, are Python's exact rounding of Fractions."""

from __future__ import annotations

from fractions import Fraction

from hypothesis import given
from hypothesis import strategies as st

from rimd_sim.runtime.stamps import block_end_stamps, stamp_ns, stamp_time

T0 = st.integers(0, 2_000_000_000 * 1_000_000_000)


@given(t0=T0, num=st.integers(-10**15, 10**15), den=st.integers(1, 10**9))
def test_a_stamp_is_the_time_in_nanoseconds_rounded_half_to_even(t0: int, num: int, den: int) -> None:
    t = Fraction(num, den)
    assert stamp_ns(t0, t) == t0 + round(t * 1_000_000_000)


@given(t0=T0, ns=st.integers(-10**12, 10**12))
def test_half_a_nanosecond_rounds_to_the_even_one(t0: int, ns: int) -> None:
    t = Fraction(2 * ns + 1, 2_000_000_000)   # exactly between two nanoseconds
    assert stamp_ns(t0, t) == t0 + ns + (ns & 1)


@given(t0=T0, first=st.integers(0, 10**7), count=st.integers(1, 20), rate=st.fractions(Fraction(1), Fraction(10**4)))
def test_block_ends_are_the_stamps_of_the_block_boundaries(t0: int, first: int, count: int, rate: Fraction) -> None:
    assert block_end_stamps(t0, first, count, rate) == [stamp_ns(t0, k / rate) for k in range(first, first + count)]


@given(t0=T0, ns=st.integers(0, 10**15))
def test_a_stamp_time_stamps_back_to_itself(t0: int, ns: int) -> None:
    assert stamp_ns(t0, stamp_time(t0, t0 + ns)) == t0 + ns
