"""What the node benchmarks share: a node executable started in a process group of its own, and stopped.

The benchmarks import it from their own folder (``sys.path`` holds a script's folder when it runs).
"""

from __future__ import annotations

import os
import shutil
import signal
import statistics
import subprocess
import time
from collections.abc import Callable, Mapping
from pathlib import Path


def start(exe: str, *ros_args: str, log: Path | None = None, env: Mapping[str, str] | None = None) -> subprocess.Popen:
    """Start the node executable ``exe`` (on PATH after ``source env.sh``) with ``--ros-args ros_args``.

    Its output goes to ``log`` (else nowhere); ``env`` replaces the environment (default: this process's).
    """
    path = shutil.which(exe)
    if path is None:
        raise SystemExit(f"{exe} not on PATH: run `source env.sh` first")
    out = log.open("wb") if log is not None else subprocess.DEVNULL
    return subprocess.Popen([path, "--ros-args", *ros_args], stdout=out, stderr=subprocess.STDOUT,
                            start_new_session=True, env=None if env is None else dict(env))


def stop(proc: subprocess.Popen, timeout: float = 20.0) -> None:
    """SIGINT to its process group (a node finishes cleanly), SIGKILL after ``timeout`` s."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def cpu_median(proc: subprocess.Popen, seconds: float, spin: Callable[[], None] = lambda: time.sleep(0.05)) -> float:
    """Median CPU of ``proc`` (% of one core) over 1 s samples for ``seconds``, calling ``spin`` meanwhile."""
    import psutil

    ps = psutil.Process(proc.pid)
    ps.cpu_percent(None)
    samples = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        t = time.monotonic()
        while time.monotonic() - t < 1.0:
            spin()
        samples.append(ps.cpu_percent(None))
    return statistics.median(samples)
