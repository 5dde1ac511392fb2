"""Where a command draws its figures: in a process of its own, started before the computation, or here.

A command that computes and then plots waits, after its computation, for matplotlib's import and the plotting
module before it draws: a large part of one sweep point's time (docs/benchmarks.md, "Latency"). With the figure
process on, :class:`Figures` starts one worker process at once, which imports :mod:`rimd_sim.analysis.plots`
(matplotlib, not the model: the results it draws unpickle from data-only modules) on the other core while this
process computes, then draws a throwaway figure (:func:`~rimd_sim.analysis.plots.warm_up`: a process's first
figure is slower than the next). Each :meth:`Figures.draw` hands it a plotting function's name and
arguments (pickled), and leaving the ``with`` block waits for every figure, raising the first failure as it was
raised in the worker. With it off (the default), the figures are drawn here, at the call, exactly the same way.
``rimd sweep``, the command a study scripts point by point, draws through :class:`Figures` when its sweep runs in
its own process (one point, one worker, or up/down); the maps and diagrams, which compute for seconds to minutes,
draw in the calling process. The worker ends with the command, also when the command is killed (it asks the
kernel for SIGTERM at its parent's death).

The ``rimd`` executable turns it on (:func:`rimd_sim.cli.entry`, :func:`use_own_process`): its process is its
own and ends with the command. A program that calls the analyses or ``rimd_sim.cli.main`` keeps it off: no
process appears under it (a test session's quick target refuses them).
"""

from __future__ import annotations

import ctypes
import importlib
import os
import signal
import sys
import threading
from types import TracebackType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import concurrent.futures as cf

__all__ = ["PLOTS_MODULE", "Figures", "own_process", "use_own_process"]

#: The module whose functions :meth:`Figures.draw` names.
PLOTS_MODULE = "rimd_sim.analysis.plots"

_own_process = [False]


def use_own_process(on: bool = True) -> None:
    """Draw the figures of every later :class:`Figures` in a process of their own (``on``) or here."""
    _own_process[0] = bool(on)


def own_process() -> bool:
    """Whether a new :class:`Figures` draws in a process of its own."""
    return _own_process[0]


#: prctl's option that sends the caller a signal when its parent thread dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1


def _start_worker(parent: int) -> None:
    # Ctrl-C is the command's: it stops the worker through the pool; the worker says nothing of it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # A command killed outright (SIGKILL: a script's timeout) never closes the pool: the worker, which holds
    # the pool's queues itself, would wait forever. On Linux it asks for SIGTERM at its parent's death.
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:   # the parent died before the request
        os._exit(0)


def _start_method(methods: list[str]) -> str:
    """``fork`` when this process runs no other Python thread, else ``spawn``.

    A forked worker inherits what this process has imported (no interpreter start-up: the command's case, which
    makes its block before it starts any thread of its own); forking while another thread of this program runs
    could leave the child a lock that no thread will release. (The idle pool threads of numpy's BLAS, there from
    numpy's import, are fork-aware: they are not counted.)
    """
    return "fork" if "fork" in methods and threading.active_count() == 1 else "spawn"


def _load_plots() -> None:
    importlib.import_module(PLOTS_MODULE).warm_up()


def _draw(name: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
    return getattr(importlib.import_module(PLOTS_MODULE), name)(*args, **kwargs)


class Figures:
    """A command's figures: ``with Figures() as figures: ...; figures.draw("plot_sweep", result, path)``.

    Make it before the computation, so that the worker's imports overlap it. :meth:`draw` returns at once in the
    worker's case; leaving the block waits for every figure drawn (:attr:`results` then holds what each plotting
    function returned, in the order of the calls). An exception leaving the block cancels what was not drawn.
    """

    def __init__(self, own: bool | None = None) -> None:
        """``own``: draw in a process of its own (default: :func:`own_process`)."""
        self._pool: cf.ProcessPoolExecutor | None = None
        self._loaded: cf.Future | None = None
        self._futures: list[cf.Future] = []
        self.results: list[Any] = []
        self._own = own_process() if own is None else bool(own)
        if self._own:
            import concurrent.futures
            import multiprocessing

            context = multiprocessing.get_context(_start_method(multiprocessing.get_all_start_methods()))
            self._pool = concurrent.futures.ProcessPoolExecutor(max_workers=1, mp_context=context,
                                                                initializer=_start_worker, initargs=(os.getpid(),))
            self._loaded = self._pool.submit(_load_plots)   # starts the worker: its imports begin now

    @property
    def in_own_process(self) -> bool:
        """Whether the figures are drawn in a worker process."""
        return self._own

    def draw(self, name: str, /, *args: Any, **kwargs: Any) -> None:
        """Draw with ``rimd_sim.analysis.plots.<name>(*args, **kwargs)``: in the worker, or here at once."""
        if self._pool is None:
            self.results.append(_draw(name, args, kwargs))
        else:
            self._futures.append(self._pool.submit(_draw, name, args, kwargs))

    def __enter__(self) -> Figures:  # noqa: D105
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        """Wait for every figure (the first failure raised); after an error in the block, cancel instead."""
        if self._pool is None:
            return
        pool, self._pool = self._pool, None
        if kind is not None:
            pool.shutdown(wait=False, cancel_futures=True)
            return
        try:
            if self._loaded is not None:
                self._loaded.result()
            self.results.extend(future.result() for future in self._futures)
        finally:
            pool.shutdown(wait=True)
