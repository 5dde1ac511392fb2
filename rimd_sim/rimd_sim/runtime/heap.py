"""A node process gives the C heap's free pages back to the system, once a minute, so its memory stays flat.

A node allocates and frees at the rig's pace for as long as it runs: numpy arrays and message bytes for 100 blocks
a second, the Rerun SDK's Arrow buffers, DDS samples. glibc's ``malloc`` keeps what is freed inside its arenas
mapped, and across hours the pages the process has touched creep up although nothing is kept: the resident size
of the composed rig grew by megabytes an hour that ``malloc_trim(0)`` gives straight back (docs/benchmarks.md,
"Soak"). ``malloc_trim(0)`` returns every whole free page of every arena (``madvise``), holding each arena's lock
only while it walks that arena: once a minute, it is nothing beside the rig's work.

:func:`start` runs it every :data:`PERIOD_S` on a thread of its own (``rimd-heap``) in a node process (the node
executables, ``rimd node``). Where the C library has no ``malloc_trim`` (not glibc), nothing runs. With
``RIMD_PLAIN=heap`` (a benchmarking switch, :mod:`rimd_sim.runtime.plain`) nothing runs either: the allocator's
own behaviour.
"""

from __future__ import annotations

import ctypes
import threading
from collections.abc import Callable
from functools import cache
from typing import Any

from rimd_sim.runtime.plain import plain
from rimd_sim.runtime.threads import libc_function, named_thread

__all__ = ["OS_NAME", "PERIOD_S", "return_free_pages", "start"]

#: Seconds between two returns of the free pages.
PERIOD_S = 60.0
#: The thread's name (:data:`rimd_sim.runtime.threads.OS_NAMES`).
OS_NAME = "rimd-heap"


@cache
def _malloc_trim() -> Callable[[int], int] | None:
    """The C library's ``malloc_trim`` (glibc's), its argument typed, or None without one."""
    trim: Any = libc_function("malloc_trim")   # a ctypes function: its argument and result types are set here
    if trim is None:
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def return_free_pages() -> bool:
    """Give the heap's whole free pages back to the system now; True when some were (False: none, or no glibc)."""
    trim = _malloc_trim()
    return trim is not None and trim(0) == 1


def start(period: float = PERIOD_S) -> threading.Event | None:
    """Return the free pages every ``period`` s from a daemon thread; the event it returns stops it.

    None (nothing started) under ``RIMD_PLAIN=heap`` or without glibc's ``malloc_trim``.
    """
    if plain("heap") or _malloc_trim() is None:
        return None
    stop = threading.Event()

    def run() -> None:
        while not stop.wait(period):
            return_free_pages()

    named_thread(run, OS_NAME).start()
    return stop
