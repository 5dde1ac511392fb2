"""A node process keeps its C heap flat: large buffers in mappings of their own, free pages given back each minute.

A node allocates and frees at the rig's pace for as long as it runs: numpy arrays and message bytes for 100 blocks
a second, the Rerun SDK's Arrow buffers, DDS samples. glibc's ``malloc`` keeps what is freed inside its arenas
mapped, and across hours the pages the process has touched creep up although nothing is kept: the resident size
of the composed rig grew by megabytes an hour that ``malloc_trim(0)`` gives straight back (docs/benchmarks.md,
"Soak"). ``malloc_trim(0)`` returns every whole free page of every arena (``madvise``), holding each arena's lock
only while it walks that arena: once a minute, it is nothing beside the rig's work.

:func:`start` runs it every :data:`PERIOD_S` on a thread of its own (``rimd-heap``) in a node process (the node
executables, ``rimd node``).

What the trim cannot give back is an arena that fragments. glibc serves a buffer of at least its mmap threshold
from a mapping of its own, unmapped when freed, but by default raises the threshold to the size of each such
buffer freed (up to 32 MiB). After the recorder's first chunk (hundreds of KiB, compressed and freed every
second or so) its chunk buffers come from its writer thread's arena instead: between the long-lived small
allocations there, the arena grew for as long as the rig ran, its resident size by megabytes an hour
(docs/benchmarks.md, "Soak").
:func:`start` therefore also fixes the threshold at :data:`MMAP_THRESHOLD` (``mallopt``, which ends glibc's
adjustment): every buffer that large is mapped and unmapped whole; one mapping per chunk is nothing beside the
rig's work.

Where the C library has neither function (not glibc), nothing is done. With ``RIMD_PLAIN=heap`` (a benchmarking
switch, :mod:`rimd_sim.runtime.plain`) nothing is done either: the allocator's own behaviour.
"""

from __future__ import annotations

import ctypes
import threading
from collections.abc import Callable
from functools import cache
from typing import Any

from rimd_sim.runtime.plain import plain
from rimd_sim.runtime.threads import libc_function, named_thread

__all__ = ["MMAP_THRESHOLD", "OS_NAME", "PERIOD_S", "fix_mmap_threshold", "return_free_pages", "start"]

#: Seconds between two returns of the free pages.
PERIOD_S = 60.0
#: Bytes from which a buffer gets a mapping of its own: glibc's initial threshold, kept fixed.
MMAP_THRESHOLD = 128 * 1024
#: ``mallopt``'s parameter number for the threshold (glibc's ``M_MMAP_THRESHOLD``).
_M_MMAP_THRESHOLD = -3
#: The thread's name (:data:`rimd_sim.runtime.threads.OS_NAMES`).
OS_NAME = "rimd-heap"


@cache
def _glibc(name: str, *argtypes: Any) -> Callable[..., int] | None:
    """The C library's function ``name`` (glibc's), its arguments typed and its result an int; None without one."""
    function: Any = libc_function(name)   # a ctypes function: its argument and result types are set here
    if function is None:
        return None
    function.argtypes = list(argtypes)
    function.restype = ctypes.c_int
    return function


def _malloc_trim() -> Callable[[int], int] | None:
    """The C library's ``malloc_trim(size_t pad)``, or None without one."""
    return _glibc("malloc_trim", ctypes.c_size_t)


def return_free_pages() -> bool:
    """Give the heap's whole free pages back to the system now; True when some were (False: none, or no glibc)."""
    trim = _malloc_trim()
    return trim is not None and trim(0) == 1


def _mallopt() -> Callable[[int, int], int] | None:
    """The C library's ``mallopt(int param, int value)``, or None without one."""
    return _glibc("mallopt", ctypes.c_int, ctypes.c_int)


def fix_mmap_threshold(size: int = MMAP_THRESHOLD) -> bool:
    """Serve every buffer of at least ``size`` bytes from a mapping of its own, for good; False without glibc.

    Raises:
        ValueError: ``size`` is not a positive number of bytes glibc accepts (at most 32 MiB).
    """
    if not 0 < size <= 32 * 1024 * 1024:
        raise ValueError(f"mmap threshold {size} refused: must be 1 to 33554432 bytes")
    mallopt = _mallopt()
    return mallopt is not None and mallopt(_M_MMAP_THRESHOLD, size) == 1


def start(period: float = PERIOD_S) -> threading.Event | None:
    """Fix the mmap threshold, then return the free pages every ``period`` s from a daemon thread.

    The event it returns stops the thread. None (nothing done) under ``RIMD_PLAIN=heap``; without glibc's
    ``malloc_trim``, the threshold only.
    """
    if plain("heap"):
        return None
    fix_mmap_threshold()
    if _malloc_trim() is None:
        return None
    stop = threading.Event()

    def run() -> None:
        while not stop.wait(period):
            return_free_pages()

    named_thread(run, OS_NAME).start()
    return stop
