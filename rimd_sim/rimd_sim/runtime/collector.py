"""The cycle collector's settings for a process of its own: ``rimd`` and the node executables.

Such a process imports numba, matplotlib, rclpy or Rerun before it does anything: some 70,000 objects that live
as long as it does (160,000 after one ``rimd sweep`` point with its figure). With CPython's defaults the
collector walks them over and over while they are made and once more at exit (a full pass over 160,000 objects
is 0.07 s here): measured on one ``rimd sweep`` point, a quarter of its wall time (docs/benchmarks.md, "Latency").
So a process of the package collects its youngest generation every :data:`YOUNG_THRESHOLD` allocations
instead of 700 (cycles are still collected, later and in fewer passes), and hands what it has built to
:func:`gc.freeze` once it is built (its imports, or its work at the end), which the collector then leaves alone.

Only entry points call these (:func:`rimd_sim.cli.entry`, :mod:`rimd_sim.ros.nodes._entry`): a program that
imports the package (a test session, a notebook) keeps its own collector.
"""

from __future__ import annotations

import gc

__all__ = ["YOUNG_THRESHOLD", "configure", "keep_what_exists"]

#: Net allocations of tracked objects between two collections of the youngest generation (CPython: 700).
#: The older generations keep CPython's thresholds, counted in collections of the younger one.
YOUNG_THRESHOLD = 10_000


def configure() -> None:
    """Collect the youngest generation every :data:`YOUNG_THRESHOLD` allocations (the process's own setting)."""
    _, middle, oldest = gc.get_threshold()
    gc.set_threshold(YOUNG_THRESHOLD, middle, oldest)


def keep_what_exists() -> None:
    """Put every object tracked so far out of the collector's reach (:func:`gc.freeze`).

    For what lives as long as the process (its modules, its node) and at its end (so that the exit does not
    walk the whole heap again). A cycle already garbage at this moment is not collected any more: call this
    after a start-up or at the end, not in a loop.
    """
    gc.freeze()
