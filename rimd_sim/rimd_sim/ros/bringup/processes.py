"""Supervising the rig's processes: start them, watch them, stop them in order.

:class:`Rig` starts the processes of a :class:`rimd_sim.ros.bringup.plan.RigPlan` (consumers first, the simulator
last), each in a session of its own, and stops them in reverse order (simulator first, recorder last, so that the
recording gets every block), each with SIGINT, then SIGTERM, then SIGKILL after bounded waits
(:func:`stop_process`). :class:`StopSignals` turns SIGINT and SIGTERM into a request that a verb's loop reads, so
that ``rimd rig`` stops its rig cleanly whichever of the two arrives.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from rimd_sim.ros.bringup.plan import RigPlan
from rimd_sim.ros.bringup.resume import resume_once_subscribed

__all__ = ["Rig", "StopSignals", "stop_process"]


class StopSignals:
    """SIGINT and SIGTERM, within its ``with`` block, set :attr:`requested` instead of stopping this process.

    A verb that runs a rig then stops it cleanly (its recording closed) whichever of the two arrives.
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous: dict[int, Any] = {}

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.requested = True

    def __enter__(self) -> StopSignals:
        """Take SIGINT and SIGTERM."""
        self._previous = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Give the signals back to their previous handlers."""
        for s, handler in self._previous.items():
            signal.signal(s, handler)


@dataclass
class Rig:
    """The processes of a :class:`RigPlan`: start, watch, stop. A context manager; :meth:`stop` is idempotent.

    Args:
        plan: What to start.
        env: The processes' environment (default: this process's).
        log_dir: Write each process's output to ``log_dir/<process>.log`` (default: this process's stdout and
            stderr).
    """

    plan: RigPlan
    env: Mapping[str, str] | None = None
    log_dir: Path | None = None
    processes: dict[str, subprocess.Popen] = field(default_factory=dict)
    _logs: list[TextIO] = field(default_factory=list)

    def __enter__(self) -> Rig:
        """Start the rig."""
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Stop the rig."""
        self.stop()

    def start(self) -> None:
        """Start every process (consumers first, the simulator last; or the composed rig's one)."""
        for node in self.plan.processes:
            out: Any = None
            if self.log_dir is not None:
                self.log_dir.mkdir(parents=True, exist_ok=True)
                out = open(self.log_dir / f"{node.name}.log", "w")   # closed in stop()
                self._logs.append(out)
            self.processes[node.name] = subprocess.Popen(
                node.command(), start_new_session=True, env=dict(self.env) if self.env is not None else None,
                stdout=out, stderr=subprocess.STDOUT if out is not None else None, stdin=subprocess.DEVNULL)

    def resume_when_connected(self, timeout: float = 20.0) -> bool:
        """Open loop: once every consumer subscribes to every rig topic, resume the simulator.

        Returns True when they all connected in time; otherwise the simulator is resumed all the same (the
        consumers may miss the first blocks) and False comes back. Nothing to do in lockstep, or without
        consumers (True).
        """
        consumers = tuple(n.name for n in self.plan.processes if n.consumer)   # none composed: fed in the process
        if self.plan.lockstep_consumers or not consumers:
            return True
        domain = int(self.env["ROS_DOMAIN_ID"]) if self.env and self.env.get("ROS_DOMAIN_ID") else None
        if resume_once_subscribed(consumers, self.processes, timeout, domain):
            return True
        if self.failed() is None:
            resume_once_subscribed((), self.processes, 10.0, domain)
        return False

    def failed(self) -> tuple[str, int] | None:
        """A process that has exited, as (name, status), or None."""
        gone = self.exited()
        return gone[0] if gone else None

    def exited(self) -> list[tuple[str, int]]:
        """Every process that has exited, as (name, status), in start order (a status < 0: killed by that signal)."""
        return [(name, proc.returncode) for name, proc in self.processes.items() if proc.poll() is not None]

    def watch(self, stop: StopSignals, duration: float = 0.0, ends_itself: str | None = None) -> tuple[str, int] | None:
        """Wait until ``stop`` is requested, ``duration`` s have passed (0: no limit) or a process exits.

        Returns the process that exited, as (name, status), unless it is ``ends_itself`` with status 0 (a replay
        that reached its end); None otherwise.
        """
        deadline = time.monotonic() + duration if duration > 0 else None
        while not stop.requested and (deadline is None or time.monotonic() < deadline):
            failed = self.failed()
            if failed is not None:
                return None if failed == (ends_itself, 0) else failed
            time.sleep(0.1)
        return None

    def run(self, verb: str, announce: Callable[[], None], *, duration: float = 0.0,
            ends_itself: str | None = None) -> int:
        """Start, ``announce()``, :meth:`watch` within :class:`StopSignals`, then stop: the status of ``rimd VERB``.

        1 when a process exited by itself (said on stderr as ``rimd VERB: NAME exited with status N``) or
        :meth:`stop` found an error; 0 otherwise. The rig is stopped whatever happens.
        """
        status = 0
        with StopSignals() as stop:
            try:
                self.start()
                announce()
                failed = self.watch(stop, duration=duration, ends_itself=ends_itself)
                if failed is not None:
                    print(f"rimd {verb}: {failed[0]} exited with status {failed[1]}", file=sys.stderr)
                    status = 1
            finally:
                status = self.stop() or status
        return status

    def stop(self) -> int:
        """Stop every process in reverse order; 0, or 1 when a node exited with an error."""
        status = 0
        for name, proc in reversed(list(self.processes.items())):
            code = _stop(proc, name)
            if code not in (0, None) and code != -signal.SIGINT:
                status = 1
        for log in self._logs:
            log.close()
        self._logs.clear()
        if self.plan.overrides_path is not None:
            self.plan.overrides_path.unlink(missing_ok=True)
        return status


def stop_process(proc: subprocess.Popen, waits: Sequence[tuple[int, float]] = (
        (signal.SIGINT, 10.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)), *,
        send: Callable[[int], None] | None = None, on_timeout: Callable[[int], None] | None = None) -> int | None:
    """Send ``proc`` each signal of ``waits`` in turn and wait its bounded time (s), until it has exited.

    Args:
        proc: The child process.
        waits: (signal, seconds) in order; by default SIGINT (a node finishes its work), SIGTERM, SIGKILL.
        send: How a signal is sent (default ``proc.send_signal``; ``os.killpg`` for a process group); the
            process gone meanwhile ends the sequence.
        on_timeout: Called with the signal that did not stop it in its time.

    Returns:
        Its exit status (None if it outlived even the last signal's wait).
    """
    for sig, wait in waits:
        if proc.poll() is not None:
            break
        try:
            (send or proc.send_signal)(sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait)
        except subprocess.TimeoutExpired:
            if on_timeout is not None:
                on_timeout(sig)
    return proc.returncode


def _stop(proc: subprocess.Popen, name: str) -> int | None:
    def say(sig: int) -> None:
        print(f"rimd rig: {name} did not stop on {signal.Signals(sig).name}", file=sys.stderr)

    return stop_process(proc, send=lambda sig: os.killpg(proc.pid, sig), on_timeout=say)
