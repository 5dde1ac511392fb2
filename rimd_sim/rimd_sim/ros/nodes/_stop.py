"""Stop requests of the node executables: SIGINT and SIGTERM set a flag that the spin loop reads.

No ROS import here: the executables' entry module installs these handlers before it loads rclpy, numba or
rerun, so a signal that arrives while a node is still loading is a stop request too (see ``_run``).
"""

from __future__ import annotations

import os
import signal
import threading

__all__ = ["STOP_SIGNALS", "StopRequest", "install_stop_handlers"]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    """A stop asked for by SIGINT or SIGTERM: a flag, set from the signal handler, read by the spin loop."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.signal: int | None = None
        self.count = 0

    def __call__(self, signum: int, frame: object) -> None:  # signal handler signature
        """The signal handler: record the request (no exception, no ROS call).

        The first signal asks for a clean stop; a second one says so on stderr; the third ends the process at
        once (exit status 128 + signal), for a stop that hangs.
        """
        self.count += 1
        if self.signal is None:
            self.signal = signum
        self._event.set()
        if self.count == 2:
            os.write(2, b"stopping cleanly (one more signal ends the process at once)\n")
        elif self.count >= 3:
            os._exit(128 + signum)

    def is_set(self) -> bool:
        """Whether a stop was requested."""
        return self._event.is_set()

    def set(self) -> None:
        """Request a stop from the program itself."""
        self._event.set()


_STOP: StopRequest | None = None


def install_stop_handlers() -> StopRequest:
    """Route SIGINT and SIGTERM to the process's :class:`StopRequest` (idempotent; main thread only)."""
    global _STOP
    if _STOP is None:
        _STOP = StopRequest()
    if threading.current_thread() is threading.main_thread():
        for signum in STOP_SIGNALS:
            signal.signal(signum, _STOP)
    return _STOP
