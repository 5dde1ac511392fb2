"""The handle on a running rig that the ``rimd_rig`` fixture returns: :class:`RigHandle`.

The handle gives the domain's environment (``env``, for the processes a test starts), the run and recording
directories, the rig's services as one-liners (``motor``, ``perturb``, ``inject``, ``pause``, ``resume``, ``reset``,
``clear_faults``; each with a ``timeout``, default :data:`SERVICE_TIMEOUT_S`), waits on simulation time, a program
run against the rig (:meth:`RigHandle.run`), the run's ground truth read from its recording
(:meth:`RigHandle.events`...), each node's log, and ``stop``.

Ready (:meth:`RigHandle.wait_ready`) means every node in the ROS graph, the simulator's services served, and its
lockstep wait armed. The simulator says the last in its ``/diagnostics`` (status ``rimd_simulator: pacing``, a
``lockstep NAME state`` value per consumer), which it publishes once its executor spins, after its pacing thread
has started (or, started paused, is ready to), every second and at once to a reader that has just matched. This
process makes its own node (its DDS participant) only once each process of the rig has said that its participant
is up (a ready file in ``RIMD_READY_DIR``), and on the rig's discovery range, so that its first announcements reach
the rig's participants: a participant made before them would be found only at its next periodic announcement,
seconds later. The wait is bounded, says what it waits for every :data:`READY_REPORT_S` s on stderr, and fails
naming what was missing and the nodes' last log lines.

A node that exits, while the rig comes up or later while the test waits on the rig (a service call,
:meth:`RigHandle.wait_until_simulated`, :meth:`RigHandle.session`, :meth:`RigHandle.run`), fails the test at once
with :class:`rimd_sim.errors.UnavailableError`, naming the node, its exit status and its last log lines.
"""

from __future__ import annotations

import itertools
import math
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rimd_sim.errors import InputError, UnavailableError
from rimd_sim.ros.domains import DomainLease
from rimd_sim.ros.fixture_settings import READY_TIMEOUT_ENV, READY_TIMEOUT_INI
from rimd_sim.runtime.progress import PACING_STATUS as PACING_SUFFIX

__all__ = ["LOG_TAIL_LINES", "PACING_STATUS", "READY_REPORT_S", "RIG_SERVICES", "RUN_TIMEOUT_S", "SERVICE_TIMEOUT_S",
           "TRUTH_TIMEOUT_S", "RigHandle"]

#: How often the ready wait says what it still waits for (s).
READY_REPORT_S = 5.0
#: Default timeout of each service helper (s): the service found and its answer received.
SERVICE_TIMEOUT_S = 30.0
#: Lines of a node's log that an error message shows.
LOG_TAIL_LINES = 20
#: Callbacks :meth:`RigHandle.simulated` lets the client run (none waits) before it reads the latest /clock.
SPINS_PER_READ = 20
#: Default wall time (s) :meth:`RigHandle.run` gives the program.
RUN_TIMEOUT_S = 180.0
#: Default wall time (s) the ground truth waits for the recording to hold the window asked for.
TRUTH_TIMEOUT_S = 60.0
#: The simulator's services the helpers call (in the rig's namespace): served means the rig takes commands.
RIG_SERVICES = ("set_motor_frequency", "perturb", "inject_fault", "pause", "resume", "reset", "clear_faults")
#: The simulator's diagnostic status that names its lockstep consumers (``rimd_simulator: pacing``).
PACING_STATUS = f"rimd_simulator{PACING_SUFFIX}"
_client_counter = itertools.count()
_run_counter = itertools.count()


def _say(line: str) -> None:
    """A progress line of the ready wait, on stderr (pytest shows it with ``-s``, and in a failed test's report)."""
    print(line, file=sys.stderr, flush=True)


def _read(f: Any) -> str:
    f.flush()
    f.seek(0)
    return f.read().decode(errors="replace")


def _tail(f: Any, lines: int = LOG_TAIL_LINES) -> str:
    """The last lines a program wrote on stderr, for an error message ('' when none)."""
    text = _read(f).rstrip().splitlines()[-lines:]
    return ("\n--- the program's last " f"{len(text)} lines on stderr:\n" + "\n".join(f"    {t}" for t in text)
            if text else "")


def _how(status: int) -> str:
    """An exit status in words (a negative one: killed by that signal)."""
    if status < 0:
        try:
            return f"was killed by {signal.Signals(-status).name}"
        except ValueError:
            pass
    return f"exited with status {status}"


@dataclass
class RigHandle:
    """A running rig of the ``rimd_rig`` fixture (see the module docstring), made by its factory.

    Args:
        domain_id: The rig's leased ROS domain id.
        env: The environment for the test's own processes on that domain.
        run_dir: The rig's run directory: its logs (``logs/``), its ready files, ``rig.rrd`` of the bridge.
        recording: The recording directory; None when the rig records nothing.
        consumers: The simulator's lockstep consumers.
        rig: The rig's processes (:class:`rimd_sim.ros.bringup.processes.Rig`).
        until: The simulation time (s) at which the rig holds; None: it runs until stopped.
    """

    domain_id: int
    env: dict[str, str]
    run_dir: Path
    recording: Path | None
    consumers: tuple[str, ...]
    rig: Any
    _lease: DomainLease
    _client: Any = None
    _clock_ns: int = -1
    #: Seconds from the start of the wait (right after the processes started) until the rig was ready.
    ready_after: float = math.nan
    _stopped: bool = False
    #: Where the rig's processes write their ready files (``RIMD_READY_DIR``); None: not waited for.
    _ready_dir: Path | None = None
    #: The simulation time at which the rig holds (``until``; None: no end).
    until: float | None = None
    _truth: Any = None   # the recording's ground truth, read once the rig is stopped
    _status: int = 0     # the rig's exit status, once stopped

    @property
    def config(self) -> Any:
        """The simulator's configuration as started (a :class:`rimd_sim.settings.config.SimConfig`).

        The core reproduces the run offline from it: ``RigSimulator(rig.config)`` with the same commands at the
        same stamps.
        """
        return self.rig.plan.config

    @property
    def node_names(self) -> list[str]:
        """The rig's node names."""
        return self.rig.plan.names

    def log(self, node: str = "rimd_simulator") -> str:
        """What a node has written so far (in the composed rig: the process's log, every node's lines)."""
        path = self.run_dir / "logs" / f"{self.rig.plan.process_of(node)}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def log_tail(self, node: str, lines: int = LOG_TAIL_LINES) -> str:
        """The last ``lines`` lines of a node's log, headed by its name and path (for an error message)."""
        path = self.run_dir / "logs" / f"{self.rig.plan.process_of(node)}.log"
        tail = self.log(node).rstrip().splitlines()[-lines:]
        if not tail:
            return f"--- {node}: its log is empty ({path})"
        return f"--- {node}: last {len(tail)} lines of its log ({path}):\n" + "\n".join(f"    {t}" for t in tail)

    # -- the rig's processes -----------------------------------------------------------------------------------
    def check_alive(self, when: str = "while the test waited on it") -> None:
        """Fail at once when a process of the rig has exited (nothing to check once the rig is stopped).

        Raises:
            UnavailableError: Naming each node that exited, its exit status and its last log lines.
        """
        if self._stopped:
            return
        gone = self.rig.exited()
        if gone:
            what = "; ".join(f"node {self._described(name)} {_how(status)}" for name, status in gone)
            tails = "\n".join(self.log_tail(name) for name, _ in gone)
            raise UnavailableError(f"rimd_rig: {what} {when} (ROS_DOMAIN_ID {self.domain_id}, run directory "
                                   f"{self.run_dir})\n{tails}")

    def _described(self, process: str) -> str:
        """A process as an error names it: the node, or the composed rig and the nodes it runs."""
        plan = self.rig.plan
        return process if process in plan.names else f"{process} (the rig in one process: {', '.join(plan.names)})"

    # -- rclpy in this process, on the rig's domain ------------------------------------------------------------
    def client(self) -> Any:
        """The rig's services and a node on its domain (:class:`rimd_sim.ros.clients.rig.RigClient`, made once).

        Its waits check that the rig's processes are alive (:meth:`check_alive`).
        """
        if self._client is None:
            from rclpy.qos import QoSProfile, ReliabilityPolicy
            from rosgraph_msgs.msg import Clock

            from rimd_sim.ros.clients.rig import RigClient

            self._client = RigClient(domain_id=self.domain_id, timeout=SERVICE_TIMEOUT_S,
                                     name=f"rimd_test_rig_{self.domain_id}_{next(_client_counter)}",
                                     check=self.check_alive,
                                     discovery_range=self.env.get("ROS_AUTOMATIC_DISCOVERY_RANGE"))

            def on_clock(msg: Clock) -> None:
                self._clock_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec

            # Depth 1: only the latest time matters, so a test that reads it after a while gets where the rig is,
            # not the oldest of a backlog.
            self._client.node.create_subscription(Clock, "/clock", on_clock,
                                                  QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
        return self._client

    def _ros(self) -> Any:
        """A node of this process on the rig's domain (for subscriptions of the test's own)."""
        return self.client().node

    def _spin_until(self, condition: Any, timeout: float) -> bool:
        return self.client().spin_until(condition, timeout)

    def wait_ready(self, timeout: float, say: Callable[[str], None] = _say) -> float:
        """Wait until the rig is ready (see the module docstring); the seconds it took.

        First each process of the rig says that its DDS participant is up (a ready file, written once its first
        node is made); only then does this process make its own participant, on the rig's discovery range, so
        that its first announcements reach the rig's participants (a participant made before theirs would be
        found only at its next periodic announcement, seconds later). Then ready: every node of the rig in the
        ROS graph, the simulator's services (:data:`RIG_SERVICES`) served, and its ``/diagnostics`` naming the
        state of each lockstep consumer (its lockstep wait armed).

        Args:
            timeout: Seconds.
            say: Told what the wait still waits for, every :data:`READY_REPORT_S` s.

        Raises:
            UnavailableError: A node exited (named, with its status and last log lines), or the rig was not ready
                within ``timeout`` s (what was missing, and each node's last log lines).
        """
        started = time.monotonic()
        from diagnostic_msgs.msg import DiagnosticArray  # rclpy and the messages load while the rig starts

        from rimd_sim.ros.clients.rig import RigClient  # noqa: F401 - loaded now, used by client()

        next_report = [started + READY_REPORT_S]
        while missing := self._not_built():
            self._still_waiting(missing, started, timeout, next_report, say)
            time.sleep(0.01)
        client = self.client()
        node = client.node
        armed: list[str] = []   # the simulator's pacing message, once it names every consumer's lockstep state
        keys = {f"lockstep {name} state" for name in self.consumers}

        def on_diagnostics(msg: DiagnosticArray) -> None:
            for status in msg.status:
                if status.name.endswith(PACING_STATUS) and keys <= {kv.key for kv in status.values}:
                    armed.append(status.message)

        sub = node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
        try:
            while missing := self._not_ready(client, bool(armed)):
                self._still_waiting(missing, started, timeout, next_report, say)
                client.executor.spin_once(timeout_sec=0.05)
            return time.monotonic() - started
        finally:
            node.destroy_subscription(sub)

    def _still_waiting(self, missing: str, started: float, timeout: float, next_report: list[float],
                       say: Callable[[str], None]) -> None:
        """One turn of the ready wait: fail when a node exited or the time is up; say what is missing now and then."""
        self.check_alive("while the rig came up")
        now = time.monotonic()
        if now - started >= timeout:
            tails = "\n".join(self.log_tail(p.name) for p in self.rig.plan.processes)
            raise UnavailableError(
                f"rimd_rig: the rig was not ready within {timeout:g} s (ROS_DOMAIN_ID {self.domain_id}, run "
                f"directory {self.run_dir}); still waiting for {missing}. A first run on an empty numba "
                f"cache compiles for a while: a longer wait is rimd_rig(ready_timeout=...), the ini key "
                f"{READY_TIMEOUT_INI} or {READY_TIMEOUT_ENV} (docs/testing.md)\n{tails}")
        if now >= next_report[0]:
            say(f"rimd_rig: waiting for {missing} ({now - started:.0f} s of {timeout:g} s)")
            next_report[0] += READY_REPORT_S

    def _not_built(self) -> str:
        """The rig's processes whose DDS participant is not up yet (no ready file), in words ('' when all are)."""
        if self._ready_dir is None:
            return ""
        names = [name for name, proc in self.rig.processes.items() if not (self._ready_dir / str(proc.pid)).exists()]
        return "; ".join(f"{name} (starting: its node not made yet)" for name in names)

    def _not_ready(self, client: Any, armed: bool) -> str:
        """What the rig still lacks to be ready, in words ('' when ready)."""
        graph = {ns.rstrip("/") + "/" + name for name, ns in client.node.get_node_names_and_namespaces()}
        parts = [f"{n.name} (not in the ROS graph yet)" for n in self.rig.plan.nodes if n.fqn not in graph]
        services = [f"{client.namespace}/{s}" for s in RIG_SERVICES if not client.service_ready(s)]
        if services:   # the simulator serves them all at once, then arms its lockstep wait
            parts.append(f"simulator: services {services[0]}"
                         + (f" and {len(services) - 1} more" if len(services) > 2 else
                            "".join(f", {s}" for s in services[1:])))
        elif not armed:
            parts.append(f"simulator: its lockstep wait for {', '.join(self.consumers)} (not in its /diagnostics "
                         "yet)")
        return "; ".join(parts)

    # -- the rig's services --------------------------------------------------------------------------------------
    def motor(self, frequency_hz: float, ramp_rate: float = 0.0, at: float | None = None, *,
              timeout: float = SERVICE_TIMEOUT_S) -> Any:
        """Set the motor frequency (at simulation time ``at`` s, else the next block); the response.

        Each helper raises :class:`rimd_sim.errors.CommandError` naming the service and the domain when it gets
        no answer within ``timeout`` s, and :class:`rimd_sim.errors.UnavailableError` at once when a node of the
        rig has exited.
        """
        return self.client().motor(frequency_hz, ramp_rate, at, timeout=timeout)

    def perturb(self, velocity: float, at: float | None = None, *, timeout: float = SERVICE_TIMEOUT_S) -> Any:
        """Add ``velocity`` (m/s) to the hammer (at simulation time ``at`` s); the response."""
        return self.client().perturb(velocity, at, timeout=timeout)

    def inject(self, channel: str, kind: str, *, start: float = 0.0, after: float = 0.0, duration: float = 0.0,
               magnitude: float = 0.0, timeout: float = SERVICE_TIMEOUT_S) -> Any:
        """Inject a fault (docs/faults.md); the response."""
        return self.client().inject(channel, kind, start=start, after=after, duration=duration, magnitude=magnitude,
                                    timeout=timeout)

    def pause(self, *, timeout: float = SERVICE_TIMEOUT_S) -> Any:
        """``/rig/pause``."""
        return self.client().trigger("pause", timeout=timeout)

    def resume(self, *, timeout: float = SERVICE_TIMEOUT_S) -> Any:
        """``/rig/resume``."""
        return self.client().trigger("resume", timeout=timeout)

    def reset(self, *, timeout: float = SERVICE_TIMEOUT_S) -> Any:
        """``/rig/reset``."""
        return self.client().trigger("reset", timeout=timeout)

    def clear_faults(self, *, timeout: float = SERVICE_TIMEOUT_S) -> Any:
        """``/rig/clear_faults``."""
        return self.client().trigger("clear_faults", timeout=timeout)

    def session(self, timeout: float = 30.0) -> Any:
        """The rig's current run (``rimd_msgs/msg/RigSession`` from /rig/session: run id, seed, configuration hash)."""
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        from rimd_msgs.msg import RigSession

        node = self._ros()
        got: list[Any] = []
        sub = node.create_subscription(RigSession, "/rig/session", got.append, QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        try:
            assert self._spin_until(lambda: got, timeout), f"no /rig/session in {timeout:g} s"
            return got[-1]
        finally:
            node.destroy_subscription(sub)

    def simulated(self) -> float:
        """The rig's simulation time as last heard on its /clock (s; -1e-9 before any).

        Takes what has arrived (a few callbacks of this process's client, without waiting), so that the latest
        /clock is read even when other subscriptions of the test have messages waiting. After ``pause`` the rig's
        own answer is exact: its message gives the simulation time it froze at.
        """
        executor = self.client().executor
        for _ in range(SPINS_PER_READ):
            executor.spin_once(timeout_sec=0.0)
        return self._clock_ns / 1e9

    def wait_until_simulated(self, seconds: float, timeout: float = 120.0) -> None:
        """Wait until the rig's simulation time (its /clock) reaches ``seconds``.

        Raises:
            AssertionError: Not in ``timeout`` s of wall time; the message says where the rig stands and what
                it waits for (its log's last lockstep line).
            UnavailableError: A node of the rig exited meanwhile (at once).
        """
        if self.until is not None and seconds > self.until:
            raise InputError(f"wait_until_simulated({seconds:g}) refused: the rig holds at until = {self.until:g} s")
        target = round(seconds * 1e9)
        if not self._spin_until(lambda: self._clock_ns >= target, timeout):
            raise AssertionError(f"the rig did not reach {seconds:g} s within {timeout:g} s: {self.where()}")

    def where(self) -> str:
        """Where the rig stands, in words: its simulation time and what it waits for (its last lockstep report)."""
        self.client().executor.spin_once(timeout_sec=0.0)
        at = ("the rig has not simulated anything yet (no /clock)" if self._clock_ns < 0
              else f"the rig is at {self._clock_ns / 1e9:.3f} s")
        waiting = [line for line in self.log().splitlines() if "lockstep: holding" in line]
        # Its last report (repeated every 10 s): the time it states is the hold's length then, not now.
        said = f"; its last lockstep report: {waiting[-1].strip()}" if waiting else ""
        if "not joined" in said:
            said += (" (a consumer joins once every subscription it gave its ProgressReporter has matched a "
                     "publisher: one on a misspelt topic never does, and its node warns after 5 s)")
        return at + said

    # -- your program, run against the rig ---------------------------------------------------------------------
    def run(self, args: Sequence[str], *, timeout: float = RUN_TIMEOUT_S, check: bool = True,
            cwd: str | Path | None = None) -> subprocess.CompletedProcess:
        """Run a program in the rig's domain (``env``) until it exits, watching the rig meanwhile.

        Its output is captured (``stdout``, ``stderr`` of the result, as text).

        Args:
            args: The command line.
            timeout: Seconds of wall time the program may take.
            check: Raise when it exits with a status other than 0.
            cwd: Its working directory.

        Raises:
            UnavailableError: A node of the rig exited meanwhile (at once; the program is stopped).
            AssertionError: The program did not exit within ``timeout`` (it is stopped; the message says where the
                rig stands and what it waits for), or, with ``check``, exited with another status than 0 (its
                last output lines).
        """
        out_path = self.run_dir / f"program{next(_run_counter)}.out"
        with open(out_path, "w+b") as out, open(out_path.with_suffix(".err"), "w+b") as err:
            proc = subprocess.Popen(list(args), env=self.env, stdout=out, stderr=err, cwd=cwd)
            try:
                deadline = time.monotonic() + timeout
                while proc.poll() is None:
                    self.check_alive("while the program ran")
                    if time.monotonic() >= deadline:
                        raise AssertionError(f"{' '.join(map(str, args))} did not exit within {timeout:g} s; "
                                             f"{self.where()}{_tail(err)}")
                    self.client().executor.spin_once(timeout_sec=0.05)
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
            result = subprocess.CompletedProcess(list(args), proc.returncode, _read(out), _read(err))
            if check and proc.returncode != 0:
                raise AssertionError(f"{' '.join(map(str, args))} {_how(proc.returncode)}; {self.where()}{_tail(err)}")
        return result

    # -- the ground truth of the run -----------------------------------------------------------------------------
    def events(self, start: float = 0.0, end: float | None = None, *, timeout: float = TRUTH_TIMEOUT_S) -> Any:
        """The rig's impact events whose contact starts in ``[start, end)`` s of simulation time.

        A :class:`rimd_sim.analysis.recordings.truth.Table`: ``time`` (contact start), ``peak_force`` (N, the
        model's true peak), ``impact_velocity`` (m/s), ``duration``, ``impulse``, ``index``... (docs/testing.md).
        Read from the recording; while the rig runs, this waits (up to ``timeout`` s) until the recording holds
        ``end`` (``end`` None: what it holds now; after :meth:`stop`: everything).
        """
        return self._ground_truth(end, timeout).events(start, math.inf if end is None else end)

    def faults(self, start: float = 0.0, end: float | None = None, *, timeout: float = TRUTH_TIMEOUT_S) -> Any:
        """The faults acting in ``[start, end)``, one row each.

        Columns ``id``, ``channel``, ``kind``, ``start``, ``end`` (``inf`` while it lasts), ``magnitude``,
        ``detail``; ``.active(times, channel, kind)`` masks the times a fault acts at. Waits as :meth:`events` does.
        """
        return self._ground_truth(end, timeout).faults(start, math.inf if end is None else end)

    def motor_states(self, start: float = 0.0, end: float | None = None, *,
                     timeout: float = TRUTH_TIMEOUT_S) -> Any:
        """The motor states stamped in ``[start, end)``.

        Columns ``time``, ``frequency_setpoint``, ``frequency`` (Hz), ``phase`` (rad), ``cycle_index``. Waits as
        :meth:`events` does.
        """
        return self._ground_truth(end, timeout).motor_states(start, math.inf if end is None else end)

    def channel(self, name: str, start: float = 0.0, end: float | None = None, *,
                timeout: float = TRUTH_TIMEOUT_S) -> Any:
        """A channel's samples as recorded (``impact_force``, ...) in ``[start, end)``.

        Columns ``time``, ``index``, ``value``. Waits as :meth:`events` does.

        Raises:
            InputError: An unknown channel (with the closest names).
        """
        return self._ground_truth(end, timeout).channel(name, start, math.inf if end is None else end)

    def _ground_truth(self, end: float | None, timeout: float) -> Any:
        """The recording read now; while the rig runs, once it holds every channel up to ``end``."""
        from rimd_sim.analysis.recordings.truth import RunTruth
        from rimd_sim.io.reader import RecordingError

        if self.recording is None:
            raise InputError("this rig keeps no recording (rimd_rig(record=False)): it has no ground truth to give")
        if self._truth is not None:
            return self._truth
        if self.until is not None and end is not None:
            end = min(end, self.until)
        deadline = time.monotonic() + timeout
        while True:
            stopped = self._stopped
            try:
                truth = RunTruth(self.recording)
            except RecordingError:
                truth = None   # no file yet
            if stopped:
                if truth is None:
                    raise InputError(f"the rig recorded nothing (no recording in {self.recording})")
                self._truth = truth
                return truth
            if truth is not None and (end is None or truth.covered_until >= end - 1e-9):
                return truth
            self.check_alive("while the test waited for its recording")
            if time.monotonic() >= deadline:
                held = -math.inf if truth is None else truth.covered_until
                raise AssertionError(f"the recording holds every channel up to {held:.3f} s, not {end:g} s, after "
                                     f"{timeout:g} s; {self.where()}")
            self.client().executor.spin_once(timeout_sec=0.2)

    def stop(self) -> int:
        """Stop the rig (the recorder finishes its file) and give the domain back; the rig's exit status.

        The ground truth (:meth:`events`...) stays readable: from the finished recording.
        """
        if self._stopped:
            return self._status
        self._stopped = True
        status = self._status = self.rig.stop()
        if self._client is not None:
            self._client.close()
            self._client = None
        self._lease.release()
        return status
