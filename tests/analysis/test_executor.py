"""The analyses' executor seam: how many local processes it runs, and when the tasks run in this process."""

from __future__ import annotations

import os

from rimd_sim.analysis.executor import ENV_SCHEDULER, local_workers, open_executor


def test_local_workers_are_the_cores_at_most_one_per_task():
    cores = os.cpu_count() or 1
    assert local_workers() == local_workers(None, None) == cores
    assert local_workers(4) == 4 and local_workers(4, 2) == 2 and local_workers(4, 1) == 1
    assert local_workers(1, 10) == 1 and local_workers(0, 0) == 1
    assert local_workers(None, 3) == min(cores, 3)


def test_one_local_worker_runs_the_tasks_here(monkeypatch):
    monkeypatch.delenv(ENV_SCHEDULER, raising=False)
    for workers, tasks in ((1, 5), (4, 1)):
        assert local_workers(workers, tasks) == 1
        with open_executor(workers, None, tasks=tasks) as runner:
            assert (runner.workers, runner.where) == (1, "local")
            assert runner.executor.submit(os.getpid).result() == os.getpid()   # no process of its own
