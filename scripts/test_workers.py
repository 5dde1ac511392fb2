#!/usr/bin/env python3
"""How many pytest-xdist workers ``scripts/run_tests.sh`` starts: one per free core, plus one.

Many tests wait: on a rig running at real time, on a process starting, on DDS discovery. One worker more than
the free cores keeps the cores busy through those waits. Cores another job keeps busy are not free: under a
load of one busy core on a 2-core machine this gives 2 workers, on the idle machine 3. More than one extra worker
starves the rigs the tests start (their real-time runs fall behind until their waits run out).

The busy cores are read from ``/proc/stat`` over a short sample, not from the load average, which lags by a
minute and still counts the set-up that ran just before the tests.

Usage: scripts/test_workers.py [--sample SECONDS]   (prints the number)
"""

from __future__ import annotations

import argparse
import os
import time


def workers(cores: int, busy_cores: float) -> int:
    """One worker per free core (``cores`` less ``busy_cores`` rounded to the nearest core), plus one; at least 2."""
    free = max(0, cores - int(round(busy_cores)))
    return max(2, free + 1)


def _cpu_times() -> tuple[int, int]:
    """(busy, total) jiffies of all cores from ``/proc/stat``; idle and iowait count as not busy."""
    with open("/proc/stat") as fh:
        fields = [int(v) for v in fh.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)
    total = sum(fields[:8])   # user nice system idle iowait irq softirq steal; guest time is inside user
    return total - idle, total


def busy_cores(sample_s: float = 0.5) -> float:
    """Cores kept busy by other processes over ``sample_s`` seconds (0.0 where ``/proc/stat`` is absent)."""
    try:
        busy0, total0 = _cpu_times()
        time.sleep(sample_s)
        busy1, total1 = _cpu_times()
    except OSError:
        return 0.0
    cores = os.cpu_count() or 1
    return cores * (busy1 - busy0) / max(1, total1 - total0)


def main(argv: list[str] | None = None) -> int:
    """Print the worker count for this machine now."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sample", type=float, default=0.5, help="seconds over which busy cores are read")
    args = parser.parse_args(argv)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    print(workers(cores, busy_cores(args.sample)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
