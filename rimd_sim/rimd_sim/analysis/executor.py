"""Where the analyses run their tasks: one ``concurrent.futures.Executor``-shaped seam.

Every map and sweep (``peterka``, ``basins``, ``sweep``, ``bifurcation``) cuts its work into independent tasks
(picklable functions of picklable arguments) and hands them to :func:`run_tasks`, which submits them to an
executor and collects the results as they finish (the progress bar moves per finished task), returning them
in submission order, so the result does not depend on where or in which order the tasks ran.

* Default: a local process pool (:class:`concurrent.futures.ProcessPoolExecutor`) on ``workers`` processes
  (all cores); with one worker the tasks run in this process. Nothing to start.
* ``scheduler="tcp://HOST:PORT"`` (or the environment variable ``RIMD_DASK_SCHEDULER``): the tasks go to a
  Dask distributed cluster through ``distributed.Client(address).get_executor()``, a
  ``concurrent.futures.Executor`` whose futures are the cluster's. Dask resubmits the tasks of a worker that
  dies. Each worker needs this package importable (``pip install`` of the repository, or its ``env.sh``) and
  the same dependency versions (see docs/analyses.md, "Maps at scale").

An unreachable scheduler is refused within ``CONNECT_TIMEOUT_S`` (+ the wait for a first worker) with the
address and the reason (:class:`SchedulerError`).
"""

from __future__ import annotations

import concurrent.futures as cf
import os
import re
import socket
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

from rimd_sim.dependencies import installed, missing_extra
from rimd_sim.errors import UnavailableError

__all__ = ["CONNECT_TIMEOUT_S", "ENV_SCHEDULER", "SchedulerError", "TaskRunner", "local_workers", "open_executor",
           "run_tasks"]

ENV_SCHEDULER = "RIMD_DASK_SCHEDULER"
#: Seconds to connect to the scheduler, then again at most to wait for a first worker (refused within 10 s).
CONNECT_TIMEOUT_S = 3.0
WORKER_TIMEOUT_S = 3.0
_ADDRESS = re.compile(r"^(tcp|tls|ws|wss|inproc|ucx)://[^\s/]+(:\d+)?/?$")


class SchedulerError(UnavailableError):
    """The Dask scheduler named cannot be used (address, reason)."""


class _InlineExecutor(cf.Executor):
    """Runs each task at submission, in this process (one worker: no pool to start, errors unchanged)."""

    def submit(self, fn, /, *args, **kwargs):
        future: cf.Future = cf.Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # handed to the caller through the future
            future.set_exception(exc)
        return future


@dataclass
class TaskRunner:
    """An open executor and what to tell the user about it.

    Attributes:
        executor: A ``concurrent.futures.Executor``.
        workers: Worker processes (local) or worker threads of the cluster.
        where: ``"local"`` or the scheduler's address.
    """

    executor: cf.Executor
    workers: int
    where: str

    def run(self, fn: Callable, jobs: Sequence, progress=None) -> list:
        """``[fn(job) for job in jobs]``, computed by the executor; ``progress(done, total)`` per finished task."""
        futures = {self.executor.submit(fn, job): i for i, job in enumerate(jobs)}
        results: list = [None] * len(jobs)
        done = 0
        try:
            for future in cf.as_completed(futures):
                results[futures[future]] = future.result()
                done += 1
                if progress:
                    progress(done, len(jobs))
        except BaseException:
            for future in futures:
                future.cancel()
            raise
        return results


def scheduler_address(scheduler: str | None) -> str | None:
    """The scheduler to use: ``scheduler``, else ``$RIMD_DASK_SCHEDULER``, else None (local)."""
    address = scheduler if scheduler is not None else os.environ.get(ENV_SCHEDULER) or None
    if address is None:
        return None
    address = address.strip()
    if not _ADDRESS.match(address):
        raise SchedulerError(f"scheduler {address!r} refused: must look like tcp://HOST:PORT")
    return address


def _probe(address: str) -> None:
    """Refuse at once a TCP scheduler that nothing listens on (before the seconds of importing Dask)."""
    if not address.startswith("tcp://"):
        return
    host, _, port = address[len("tcp://"):].rstrip("/").rpartition(":")
    if not port.isdigit():
        raise SchedulerError(f"scheduler {address!r} refused: must look like tcp://HOST:PORT")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise SchedulerError(f"cannot reach the Dask scheduler at {address}: {reason}") from None


@contextmanager
def _dask(address: str) -> Iterator[TaskRunner]:
    if not installed("distributed"):   # the extra dask: named before the address is probed
        raise SchedulerError(missing_extra("distributed", f"the Dask scheduler {address}",
                                           "or run without --scheduler and RIMD_DASK_SCHEDULER"))
    _probe(address)
    try:
        from distributed import Client
    except ImportError as exc:  # installed but broken
        raise SchedulerError(f"cannot use the Dask scheduler at {address}: {exc}") from None
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SchedulerError(f"cannot reach the Dask scheduler at {address}: {reason}") from None
    try:
        try:
            client.wait_for_workers(1, timeout=WORKER_TIMEOUT_S)
        except (OSError, TimeoutError):
            raise SchedulerError(f"the Dask scheduler at {address} has no worker "
                                 f"(waited {WORKER_TIMEOUT_S:g} s): start one with `dask worker {address}`") from None
        threads = sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values())
        # pure=False: every submission is its own task (two equal cells still get their own result).
        yield TaskRunner(client.get_executor(pure=False), max(1, threads), address)
    finally:
        client.close(timeout=CONNECT_TIMEOUT_S)


def local_workers(workers: int | None = None, tasks: int | None = None) -> int:
    """The local processes :func:`open_executor` runs (without a scheduler); 1: the tasks run in this process.

    ``workers`` (default: all cores), at most one per task of ``tasks``.
    """
    n = max(1, workers or os.cpu_count() or 1)
    return n if tasks is None else max(1, min(n, tasks))


@contextmanager
def open_executor(workers: int | None = None, scheduler: str | None = None, tasks: int | None = None
                  ) -> Iterator[TaskRunner]:
    """Open the executor of the seam (module docstring).

    Args:
        workers: Local processes (default: all cores); ignored with a scheduler.
        scheduler: Dask scheduler address (default: ``$RIMD_DASK_SCHEDULER``, else local).
        tasks: Number of tasks to come, to start no more local processes than tasks.

    Yields:
        The runner: its executor, its workers and where it runs.

    Raises:
        SchedulerError: Bad address, scheduler unreachable or without workers.
    """
    address = scheduler_address(scheduler)
    if address is not None:
        with _dask(address) as runner:
            yield runner
        return
    n = local_workers(workers, tasks)
    if n == 1:
        yield TaskRunner(_InlineExecutor(), 1, "local")
        return
    with cf.ProcessPoolExecutor(n) as pool:
        yield TaskRunner(pool, n, "local")


def run_tasks(fn: Callable, jobs: Sequence, *, workers: int | None = None, scheduler: str | None = None,
              progress=None) -> tuple[list, int, str]:
    """Run ``fn`` over ``jobs`` through the seam (:func:`open_executor`).

    Args:
        fn: A picklable callable of one job (a top-level function).
        jobs: The jobs.
        workers: Local processes (default: all cores, at most one per job; 1 runs inline).
        scheduler: Dask scheduler address (default: ``$RIMD_DASK_SCHEDULER``, else local).
        progress: Optional callable ``progress(done, total)``, per finished task.

    Returns:
        ``(results in job order, workers, where)``: ``where`` is ``local`` or the scheduler's address.

    Raises:
        SchedulerError: Bad address, scheduler unreachable or without workers.
    """
    with open_executor(workers, scheduler, tasks=len(jobs)) as runner:
        return runner.run(fn, jobs, progress), runner.workers, runner.where
