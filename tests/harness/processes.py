"""Subprocesses that a test starts and that are always killed at teardown, whole process group included.

Every process starts in its own session (so its own process group) with stdin closed and stdout+stderr
written to a log file. Stopping sends SIGINT to the group (rclpy's clean shutdown), then SIGTERM, then
SIGKILL, each with a bounded wait, and finally makes sure no member of the group is left. The group matters
because the ROS wheels' bootstrapper re-executes Python (same pid, ``os.execve``) and nodes may start
children of their own.

The environment of every process is the test's ROS environment minus ``_ROS_WHEELS_BOOTSTRAP_COMPLETE``,
so a child bootstraps exactly as it does when a user starts it from a shell.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

BOOTSTRAP_GUARD = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"
POLL_INTERVAL_S = 0.05


class ProcessFailure(AssertionError):
    """A managed process did not do what the test waited for; the message ends with its log tail."""


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class ManagedProcess:
    """One subprocess started by :class:`ProcessManager`; a context manager, ``stop()`` is idempotent."""

    def __init__(self, name: str, args: Sequence[str], env: Mapping[str, str], log_path: Path, cwd: Path):
        """Start ``args`` in a new session, output to ``log_path``."""
        self.name = name
        self.args = list(args)
        self.log_path = log_path
        self._log = open(log_path, "wb")  # closed in stop()
        try:
            self._popen = subprocess.Popen(
                self.args,
                env=dict(env),
                cwd=cwd,
                stdin=subprocess.DEVNULL,
                stdout=self._log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        except OSError:
            self._log.close()
            raise
        self.pid = self._popen.pid
        self._stopped = False

    @property
    def returncode(self) -> int | None:
        """Exit status, or None while running (negative: killed by that signal)."""
        return self._popen.poll()

    def is_running(self) -> bool:
        """Whether the process (the group leader) still runs."""
        return self._popen.poll() is None

    def output(self) -> str:
        """Everything the process wrote so far (stdout and stderr)."""
        return self.log_path.read_text(encoding="utf-8", errors="replace")

    def tail(self, lines: int = 40) -> str:
        """The last ``lines`` lines of the output."""
        return "\n".join(self.output().splitlines()[-lines:])

    def _failure(self, what: str) -> ProcessFailure:
        return ProcessFailure(
            f"{self.name} (pid {self.pid}, exit status {self.returncode}): {what}\n"
            f"--- last output of {self.name} ---\n{self.tail()}"
        )

    def wait_for_output(self, pattern: str | re.Pattern[str], timeout: float) -> re.Match[str]:
        """Wait at most ``timeout`` s until the output matches ``pattern`` (a regular expression).

        Raises:
            ProcessFailure: The process exited first, or the time ran out.
        """
        regex = re.compile(pattern) if isinstance(pattern, str) else pattern
        deadline = time.monotonic() + timeout
        while True:
            match = regex.search(self.output())
            if match:
                return match
            if not self.is_running():
                match = regex.search(self.output())
                if match:
                    return match
                raise self._failure(f"exited before printing /{regex.pattern}/")
            if time.monotonic() > deadline:
                raise self._failure(f"printed no /{regex.pattern}/ within {timeout} s")
            time.sleep(POLL_INTERVAL_S)

    def wait(self, timeout: float) -> int:
        """Wait at most ``timeout`` s for the process to exit by itself and return its exit status.

        Raises:
            ProcessFailure: It still runs after ``timeout`` s (it is left running; teardown kills it).
        """
        try:
            return self._popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise self._failure(f"still running after {timeout} s") from None

    def send_signal(self, signum: int) -> None:
        """Send ``signum`` to the whole process group."""
        try:
            os.killpg(self.pid, signum)
        except ProcessLookupError:
            pass

    def stop(self, timeout: float = 5.0) -> int | None:
        """Stop the process group: SIGINT, then SIGTERM, then SIGKILL, waiting up to ``timeout`` s each.

        Returns the exit status of the group leader (negative for a signal). Safe to call twice.
        """
        if not self._stopped:
            self._stopped = True
            for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
                if not self.is_running() and not _group_alive(self.pid):
                    break
                self.send_signal(signum)
                deadline = time.monotonic() + timeout
                while time.monotonic() < deadline:
                    self._popen.poll()
                    if not self.is_running() and not _group_alive(self.pid):
                        break
                    time.sleep(POLL_INTERVAL_S)
            try:
                self._popen.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                pass
            self._log.close()
        return self.returncode

    def __enter__(self) -> ManagedProcess:
        """Return the process."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Stop the process."""
        self.stop()


class ProcessManager:
    """Starts processes with one environment and log directory, and stops them all at the end."""

    def __init__(self, env: Mapping[str, str], log_dir: Path, cwd: Path | None = None) -> None:
        """Use ``env`` for every process (the bootstrap guard removed) and write logs to ``log_dir``."""
        self.env = {key: value for key, value in env.items() if key != BOOTSTRAP_GUARD}
        self.log_dir = log_dir
        self.cwd = cwd or log_dir
        self.processes: list[ManagedProcess] = []
        log_dir.mkdir(parents=True, exist_ok=True)

    def start(self, args: Sequence[str], *, name: str | None = None,
              env: Mapping[str, str] | None = None) -> ManagedProcess:
        """Start the command ``args``; ``env`` adds to (overrides) the common environment."""
        name = name or Path(args[0]).name
        unique = f"{len(self.processes):02d}_{re.sub(r'[^A-Za-z0-9_.-]', '_', name)}"
        process = ManagedProcess(
            name, args, {**self.env, **(env or {})}, self.log_dir / f"{unique}.log", self.cwd
        )
        self.processes.append(process)
        return process

    def start_python(self, *args: str, name: str | None = None,
                     env: Mapping[str, str] | None = None) -> ManagedProcess:
        """Start the venv's Python (unbuffered) with ``args``: a script path, ``-m module`` or ``-c code``."""
        if name is None:
            if args[:1] == ("-m",) and len(args) > 1:
                name = args[1]
            elif args[:1] == ("-c",):
                name = "python-c"
            else:
                name = Path(args[0]).stem if args else "python"
        return self.start([sys.executable, "-u", *args], name=name, env=env)

    def start_node(self, executable: str, *arguments: str, package: str = "rimd_sim",
                   name: str | None = None, env: Mapping[str, str] | None = None) -> ManagedProcess:
        """Start an installed node executable the way ``ros2 run PACKAGE EXECUTABLE ARGS`` does.

        The executable is looked up in ``<prefix>/lib/<package>/`` of the package's install prefix on
        AMENT_PREFIX_PATH.

        Raises:
            FileNotFoundError: The package or the executable is not installed.
        """
        from ament_index_python.packages import get_package_prefix

        path = Path(get_package_prefix(package)) / "lib" / package / executable
        if not os.access(path, os.X_OK):
            raise FileNotFoundError(
                f"no executable {executable!r} in package {package!r} (looked for {path})"
            )
        return self.start([str(path), *arguments], name=name or executable, env=env)

    def stop_all(self, timeout: float = 5.0) -> None:
        """Stop every process started here, newest first."""
        for process in reversed(self.processes):
            process.stop(timeout)

    def __enter__(self) -> ProcessManager:
        """Return the manager."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Stop every process."""
        self.stop_all()
