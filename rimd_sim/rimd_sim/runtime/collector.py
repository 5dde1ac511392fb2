"""The cycle collector's settings for a process of its own: ``rimd`` and the node executables.

Such a process imports numba, matplotlib, rclpy or Rerun before it does anything: some 70,000 objects that live
as long as it does (160,000 after one ``rimd sweep`` point with its figure). With CPython's defaults the
collector walks them over and over while they are made and once more at exit, a large share of a short
command's wall time (docs/benchmarks.md, "Latency", gives the figures).

* A command (:func:`configure`, then :func:`keep_what_exists` at its end): its youngest generation is collected
  every :data:`YOUNG_THRESHOLD` allocations instead of 700 (cycles are still collected, later and in fewer
  passes), and what it has built is frozen before the exit, which then does not walk it again.
* A node: its imports as a command's (:func:`configure`), then (:func:`for_node`) its imports frozen, so that
  no later full collection walks them, and CPython's young threshold back while it runs (a young collection 14
  times larger would be a longer pause of its paced thread).

Entry points call these (:func:`rimd_sim.cli.entry`, :mod:`rimd_sim.ros.nodes._entry`, ``rimd node``), and the
test suite's session for itself (tests/conftest.py); a program that imports the package (a notebook, a user's
test session) keeps its own collector. With ``RIMD_PLAIN=collector`` (a benchmarking switch,
:mod:`rimd_sim.runtime.plain`) these functions leave the collector alone: CPython's defaults.
"""

from __future__ import annotations

import gc

from rimd_sim.runtime.plain import plain

__all__ = ["CPYTHON_YOUNG_THRESHOLD", "YOUNG_THRESHOLD", "configure", "for_node", "keep_what_exists"]

#: Net allocations of tracked objects between two collections of the youngest generation (CPython: 700).
#: The older generations keep CPython's thresholds, counted in collections of the younger one.
YOUNG_THRESHOLD = 10_000
#: CPython's own young threshold, which a node keeps.
CPYTHON_YOUNG_THRESHOLD = 700


def configure(young: int = YOUNG_THRESHOLD) -> None:
    """Collect the youngest generation every ``young`` allocations (a command's setting); the older unchanged."""
    if plain("collector"):
        return
    _, middle, oldest = gc.get_threshold()
    gc.set_threshold(young, middle, oldest)


def for_node() -> None:
    """A node's setting, once its module is imported: CPython's young threshold, and what exists frozen."""
    configure(CPYTHON_YOUNG_THRESHOLD)
    keep_what_exists()


def keep_what_exists() -> None:
    """Put every object tracked so far out of the collector's reach (:func:`gc.freeze`).

    For what lives as long as the process (its modules, its node) and at its end (so that the exit does not
    walk the whole heap again). A cycle already garbage at this moment is not collected any more: call this
    after a start-up or at the end, not in a loop.
    """
    if not plain("collector"):
        gc.freeze()
