"""A fake monotonic clock for the cores that take a ``clock`` (pacing, player, recording session): no waiting."""

from __future__ import annotations


class FakeClock:
    """A monotonic clock (s) that moves only when told: ``clock.now += s`` or ``clock.advance(s)``.

    It starts at ``start``, not 0, so that a core mistaking the clock's origin for zero shows.
    """

    def __init__(self, start: float = 100.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds
