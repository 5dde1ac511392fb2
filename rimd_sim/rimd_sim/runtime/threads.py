"""The rig's own threads, named for the operating system too, so that ``top -H`` and ``/proc`` tell them apart.

CPython before 3.14 names a thread for itself only: the kernel sees every thread of a node as ``python``, and a
look at a busy rig (``top -H -p PID``, ``ps -L``, ``perf``, the benchmarks' per-thread CPU) cannot say whether
the pacing loop, the recorder's writer or the DDS writes take the time. :func:`named_thread` makes a thread that
sets its kernel name (``/proc/PID/task/TID/comm``, at most 15 bytes) as it starts; :data:`OS_NAMES` lists the
names the rig's threads take, which ``benchmarks/bench_rig.py`` reports the composed rig's CPU by. With
``RIMD_PLAIN=threads`` (a benchmarking switch, :mod:`rimd_sim.runtime.plain`) the threads are named for Python
only.
"""

from __future__ import annotations

import ctypes
import sys
import threading
from collections.abc import Callable
from functools import cache

from rimd_sim.runtime.plain import plain

__all__ = ["OS_NAMES", "libc_function", "named_thread", "set_os_name"]

#: The kernel's longest thread name in bytes (``TASK_COMM_LEN`` 16, with its terminating zero).
MAX_OS_NAME = 15
#: prctl's option that names the calling thread (linux/prctl.h).
_PR_SET_NAME = 15

#: The threads of the rig's nodes, by their kernel name.
OS_NAMES = {
    "rimd-pacing": "the simulator's pacing loop: the model, the instruments, the messages of each pass",
    "rimd-dds": "the composed rig's DDS writes when they leave the pacing loop (lockstep, a fast rig)",
    "rimd-recorder": "the recorder's writer: the MCAP file",
    "rimd-replay": "the replay's pacing loop",
    "rimd-foxglove": "the Foxglove sink's watch of the replay",
    "rimd-heap": "a node process's return of the C heap's free pages, once a minute",
}


@cache
def libc_function(name: str) -> Callable[..., int] | None:
    """The Linux C library's function ``name``, or None where there is no such function (or no Linux).

    Found among the process's own symbols (``dlopen(NULL)``; the C library's are part of them), not through
    ``ctypes.util.find_library``, which runs ``ldconfig -p`` in a child process: a fork from the thread starting.
    """
    if not sys.platform.startswith("linux"):
        return None
    try:
        return getattr(ctypes.CDLL(None, use_errno=True), name)
    except (OSError, AttributeError):
        return None


def set_os_name(name: str) -> bool:
    """Name the calling thread for the kernel (its first 15 bytes, UTF-8); False where the system has no way."""
    prctl = libc_function("prctl")
    if prctl is None:
        return False
    raw = name.encode("utf-8", errors="replace")[:MAX_OS_NAME]
    return prctl(_PR_SET_NAME, ctypes.c_char_p(raw), 0, 0, 0) == 0


def named_thread(target: Callable[[], object], name: str, *, daemon: bool = True) -> threading.Thread:
    """A thread (not started) named ``name`` for Python and, as it starts, for the kernel (:func:`set_os_name`)."""
    if plain("threads"):
        return threading.Thread(target=target, name=name, daemon=daemon)

    def run() -> None:
        set_os_name(name)
        target()

    return threading.Thread(target=run, name=name, daemon=daemon)
