"""A node process keeps its C heap flat (:mod:`rimd_sim.runtime.heap`): the mmap threshold, the free pages returned,
the thread, the switch."""

from __future__ import annotations

import subprocess
import sys
import threading

import pytest

from rimd_sim.runtime import heap
from rimd_sim.runtime.plain import PLAIN_ENV

FRAGMENTED = """
import numpy as np
from rimd_sim.runtime.heap import return_free_pages

def rss_mb():
    return int(open("/proc/self/statm").read().split()[1]) * 4096 / 1e6

blocks = [np.ones(512) for _ in range(20_000)]   # 80 MB in 4 kB blocks, below malloc's mmap threshold
kept = blocks[::50]                                # a few stay, spread over the heap: its top is not free
del blocks
before = rss_mb()
print(before, rss_mb() if return_free_pages() else before)
"""


LARGE_BUFFER = """
import ctypes, sys
from rimd_sim.runtime.heap import fix_mmap_threshold

class MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                 "keepcost")]

libc = ctypes.CDLL(None)
libc.mallinfo2.restype = MallInfo2
if sys.argv[1] == "fixed":
    assert fix_mmap_threshold()
bytearray(1 << 20)              # a 1 MiB buffer, mapped and freed: glibc raises its threshold past it
mapped = libc.mallinfo2().hblks
chunk = bytearray(512 * 1024)   # a smaller one, as the recorder's next chunk
print(libc.mallinfo2().hblks - mapped)
"""


@pytest.mark.process
@pytest.mark.parametrize(("mode", "mappings"), [("default", 0), ("fixed", 1)])
def test_with_the_threshold_fixed_a_large_buffer_gets_a_mapping_of_its_own(mode, mappings):
    """By default a freed 1 MiB buffer sends the next 512 KiB one into the arena; fixed, it is mapped whole."""
    result = subprocess.run([sys.executable, "-c", LARGE_BUFFER, mode], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert int(result.stdout) == mappings


def test_a_threshold_glibc_refuses_is_refused():
    with pytest.raises(ValueError, match="mmap threshold 0 refused"):
        heap.fix_mmap_threshold(0)


@pytest.mark.process
def test_the_free_pages_of_a_fragmented_heap_go_back_to_the_system():
    """Freed blocks between kept ones stay resident until returned; returning them shrinks the process."""
    result = subprocess.run([sys.executable, "-c", FRAGMENTED], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    before, after = map(float, result.stdout.split())
    assert before - after > 50, (before, after)   # of the 78 MB freed


def test_a_node_process_returns_them_from_a_thread_of_its_own_until_stopped(monkeypatch):
    monkeypatch.delenv(PLAIN_ENV, raising=False)
    returned = threading.Event()
    threads: list[str] = []

    def note() -> bool:
        threads.append(threading.current_thread().name)
        returned.set()
        return True

    monkeypatch.setattr(heap, "return_free_pages", note)
    stop = heap.start(period=0.01)
    assert stop is not None
    try:
        assert returned.wait(60), "the free pages were never returned"
    finally:
        stop.set()
    assert set(threads) == {heap.OS_NAME}


def test_heap_plain_leaves_the_allocator_alone(monkeypatch):
    monkeypatch.setenv(PLAIN_ENV, "heap")
    assert heap.start(period=0.01) is None
    monkeypatch.setenv(PLAIN_ENV, "collector")
    stop = heap.start(period=3600)
    assert stop is not None
    stop.set()
