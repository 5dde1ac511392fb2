"""A node process returns the C heap's free pages (:mod:`rimd_sim.runtime.heap`): the effect, the thread, the switch."""

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
