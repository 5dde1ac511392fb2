"""A stepped frequency sweep of the running rig on exact stamps, recorded: the library behind ``rimd experiment``.

The paper's methodology (section 3): the motor frequency is stepped; at each step the rig dwells, the transient
is discarded and the steady impact force is read. Here the steps are scheduled on exact stamps of the rig's own
time base: step ``k`` starts at ``T0 + k * dwell``, where ``T0`` is the first start of a motor cycle at least a
lead time ahead of the rig when the experiment begins (the lead doubles while the rig answers that the time has
already passed), or the stamp the plan names. Each setpoint goes through ``/rig/set_motor_frequency`` with its
``start_stamp``, all of them once the first is accepted (the rig queues them), so however late a request travels
(a loaded machine, a fast rig) the rig changes its setpoint at the same simulation time, and the same plan gives
the same data.

:class:`ExperimentRecorder` is the experiment's own recorder process (node ``rimd_experiment_recorder``, topics
``/rig/.*``): started before the first step (it joins a rig in lockstep by itself: name it among the rig's
consumers). Once the first step is scheduled, its ``stop_at`` is set to the end of the last step,
``T0 + n * dwell``: every message stamped at or after it is left out and the sample blocks that straddle it are
cut there, so the recording holds every sample strictly before the end and nothing after, on every topic, however
late the recorder is stopped (docs/recording.md). It is stopped once it has handled every topic up to that end.
How far it has handled each topic is read from its ``/diagnostics``, the declared key
:data:`rimd_sim.settings.recording.PROGRESS_STAMP_KEY` (not a string convention shared by copy).
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimd_sim.errors import CommandError
from rimd_sim.runtime.progress import PACING_STATUS, PUBLISHED_KEY
from rimd_sim.settings.recording import PROGRESS_STAMP_KEY, RecorderSettings, compile_patterns

__all__ = ["RECORDER_NODE", "ExperimentPlan", "ExperimentRecorder", "ExperimentRun", "frequency_steps"]

RECORDER_NODE = "rimd_experiment_recorder"
SERVICE = "/rig/set_motor_frequency"
#: First lead of the schedule (s of simulation time); doubled while the rig answers "already passed".
FIRST_LEAD_S = 1.0
MAX_LEAD_DOUBLINGS = 10
#: Longest wait (wall s) for an impact event after the end of the last step, to know that every event before
#: the end has arrived (none comes when the motion does not impact).
EVENTS_GRACE_S = 5.0
#: What the simulator's refusal of a ``start_stamp`` that the rig has already passed says (ros/nodes/simulator.py).
PASSED = "refused: already passed"


def frequency_steps(f_min: float, f_max: float, f_step: float) -> tuple[float, ...]:
    """The frequencies ``f_min, f_min + f_step, ...`` up to ``f_max`` (within 1e-9 of a step)."""
    n = int(math.floor((f_max - f_min) / f_step + 1e-9)) + 1
    return tuple(round(f_min + i * f_step, 12) for i in range(n))


@dataclass(frozen=True)
class ExperimentPlan:
    """What to run: the setpoints in order, the dwell and settle times, the ramp rate, the first stamp.

    Raises:
        CommandError: On construction, naming the option and its rule (a negative frequency, a settle time
            as long as the dwell, a ramp too slow for the dwell...).
    """

    frequencies: tuple[float, ...]
    dwell: float = 10.0
    settle: float = 3.0
    ramp_rate: float = 0.0
    start: float | None = None
    timeout: float = 30.0

    def __post_init__(self) -> None:
        """Check the plan as a whole (each number's own rule is its option's)."""
        if not self.frequencies:
            raise CommandError("--frequencies: no frequency given")
        for f in self.frequencies:
            if not (math.isfinite(f) and f >= 0):
                raise CommandError(f"--frequencies {f!r} refused: each must be finite and >= 0 Hz")
        if self.settle >= self.dwell:
            raise CommandError(f"--settle {self.settle:g} s >= --dwell {self.dwell:g} s: nothing would be measured")
        if self.ramp_rate > 0:
            worst = max((abs(b - a) for a, b in zip(self.frequencies, self.frequencies[1:], strict=False)),
                        default=0.0) / self.ramp_rate
            if worst + self.settle >= self.dwell:
                raise CommandError(f"--dwell {self.dwell:g} s is too short: a ramp takes up to {worst:g} s at "
                                   f"{self.ramp_rate:g} Hz/s, plus --settle {self.settle:g} s")


class ExperimentRecorder:
    """The experiment's recorder process, from its start to its file's end. See the module docstring.

    Args:
        client: The experiment's connection to the rig (its node hears the recorder's /diagnostics).
        directory: Where it records.
        log_path: Its output.
        log: Progress lines for a person.
    """

    def __init__(self, client: Any, directory: Path, log_path: Path, log: Callable[[str], None]) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        self._client, self.directory, self._log_path, self._log = client, directory, log_path, log
        self.written: dict[str, int] = {}   # topic -> header stamp (ns) of the last message it wrote
        self.rig_topics: set[str] = set()   # what the rig says it publishes (its pacing status)
        self.proc: subprocess.Popen | None = None
        client.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if RECORDER_NODE in status.name:
                for kv in status.values:
                    if kv.key.endswith(PROGRESS_STAMP_KEY):
                        self.written[kv.key[: -len(PROGRESS_STAMP_KEY)]] = int(kv.value)
            elif status.name.endswith(PACING_STATUS):
                self.rig_topics.update(kv.key[: -len(PUBLISHED_KEY)] for kv in status.values
                                       if kv.key.endswith(PUBLISHED_KEY) and kv.key.startswith("/rig/"))

    def tail(self, lines: int = 5) -> str:
        """The end of its output, for an error message."""
        try:
            return " | ".join(self._log_path.read_text(errors="replace").strip().splitlines()[-lines:])
        except OSError:
            return ""

    def start(self, timeout: float) -> None:
        """Start it and wait until it subscribes to every rig topic that has a publisher.

        Raises:
            CommandError: It exited, or did not subscribe in time (stopped then).
        """
        self.launch()
        self.wait_subscribed(timeout)

    def launch(self) -> None:
        """Start the process (it discovers the rig by itself: start it early, it takes seconds to come up)."""
        self.directory.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "rimd_sim.ros.nodes._entry", "recorder", "--ros-args", "-r",
               f"__node:={RECORDER_NODE}", "-p", f"output_dir:={self.directory}", "-p", "topics:=['/rig/.*']",
               "-p", "prefix:=experiment"]
        with open(self._log_path, "w") as out:
            self.proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                         start_new_session=True)
        self._log(f"recorder started (pid {self.proc.pid}), recording into {self.directory}")

    def wait_subscribed(self, timeout: float) -> None:
        """Wait until it subscribes to every rig topic (those it never records aside).

        The rig's topics are those its pacing status on ``/diagnostics`` lists, and any other ``/rig/`` topic with
        a publisher: the graph alone is not enough, since under load it can show some of the rig's publishers
        before the others, and a topic the recorder subscribed to only after the run began misses its start.

        Raises:
            CommandError: It exited, or did not subscribe in time (stopped then).
        """
        node = self._client.node
        excluded = compile_patterns("exclude", RecorderSettings().exclude)   # it never records those
        proc = self.proc
        assert proc is not None, "launch() first"

        def subscribed() -> bool:
            if proc.poll() is not None:
                return True
            if not self.rig_topics:
                return False   # the rig's own list not heard yet
            topics = {name for name, _ in node.get_topic_names_and_types()
                      if name.startswith("/rig/") and node.count_publishers(name) > 0} | self.rig_topics
            topics = {name for name in topics if not any(p.fullmatch(name) for p in excluded)}
            return bool(topics) and all(
                any(info.node_name == RECORDER_NODE for info in node.get_subscriptions_info_by_topic(t))
                for t in topics)

        ok = self._client.spin_until(subscribed, timeout)
        if proc.poll() is not None:
            raise CommandError(f"the recorder exited with status {proc.returncode}: {self.tail()}")
        if not ok:
            self.stop()
            raise CommandError(f"the recorder did not subscribe to the rig topics within {timeout:g} s: "
                               f"{self.tail()}")
        self._client.spin_until(lambda: False, 0.5)   # subscriptions matched with the publishers

    def set_stop_at(self, end_ns: int, timeout: float) -> str | None:
        """Set its ``stop_at`` to ``end_ns`` (the end of the last step); None when done, else why not."""
        from rclpy.parameter import Parameter
        from rclpy.parameter_client import AsyncParameterClient

        params = AsyncParameterClient(self._client.node, RECORDER_NODE)
        if not params.wait_for_services(timeout):
            return f"its parameter services did not answer within {timeout:g} s"
        future = params.set_parameters([Parameter("stop_at", Parameter.Type.INTEGER, end_ns)])
        self._client.spin_until(future.done, timeout)
        if not future.done() or future.result() is None:
            return f"no answer to setting stop_at within {timeout:g} s"
        result = future.result().results[0]
        return None if result.successful else result.reason

    def wait_until_written(self, end_ns: int, last_event_ns: int | None, timeout: float) -> bool:
        """Wait until it has handled every continuous topic up to ``end_ns`` (and written the last event before it).

        Handled: a message at or after ``end_ns`` has reached its writer (left out by its ``stop_at``), so every
        message before it is written. A recorder lagging behind a fast rig on a loaded machine holds each topic's
        backlog apart; stopped as soon as the rig passes the end, it would miss the end of some topics.
        """
        names = ("/rig/motor/state", "/rig/impact/force", "/rig/rimd/displacement", "/rig/cart/displacement",
                 "/rig/rimd/acceleration")
        reached = self.written

        def caught_up() -> bool:
            if not reached or any(reached.get(n, 0) < end_ns for n in names if n in reached):
                return False
            return last_event_ns is None or reached.get("/rig/impact/events", 0) >= last_event_ns

        return self._client.spin_until(caught_up, timeout)

    def stop(self) -> int | None:
        """SIGINT (it finishes its file), then SIGTERM, then SIGKILL, each after a bounded wait; its status."""
        proc = self.proc
        if proc is None:
            return None
        from rimd_sim.ros.bringup.processes import stop_process

        return stop_process(proc, ((signal.SIGINT, 20.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)))


@dataclass
class ExperimentRun:
    """One run of a plan on the rig the client reaches; :meth:`run` returns the schedule as applied.

    Args:
        plan: What to run.
        client: A :class:`rimd_sim.ros.clients.rig.RigClient`.
        log: Progress lines for a person.
        show: Progress within a step (a line rewritten in place), or None.
    """

    plan: ExperimentPlan
    client: Any
    log: Callable[[str], None] = print
    show: Callable[[str], None] | None = None
    steps: list[dict] = field(default_factory=list)
    stamp_ns: int | None = None
    frequency: float = math.nan
    setpoint: float = math.nan
    phase: float = math.nan
    event_stamps: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        """Listen to the motor state and the impact events."""
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from rimd_msgs.msg import ImpactEvent, MotorState

        node = self.client.node
        node.create_subscription(MotorState, "/rig/motor/state", self._on_motor,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        node.create_subscription(ImpactEvent, "/rig/impact/events", lambda msg: self.event_stamps.append(
            _ns(msg.header.stamp)), QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))

    def _on_motor(self, msg: Any) -> None:
        self.stamp_ns = _ns(msg.header.stamp)
        self.frequency, self.setpoint, self.phase = float(msg.frequency), float(msg.frequency_setpoint), msg.phase

    def wait_for_motor(self) -> None:
        """The rig's time (its motor state), needed to schedule without a stated start.

        Raises:
            CommandError: No motor state in the plan's timeout (a paused rig).
        """
        if not self.client.spin_until(lambda: self.stamp_ns is not None, self.plan.timeout):
            raise CommandError(f"no /rig/motor/state received in {self.plan.timeout:g} s: is the rig paused? "
                               "(--start schedules a paused rig)")

    def run(self, recorder: ExperimentRecorder | None = None) -> list[dict]:
        """Schedule and run every step; the schedule as applied (the rig's answer to each setpoint).

        Raises:
            CommandError: A setpoint refused by the rig (naming it; the rig keeps running), no answer, or the
                rig's time stopping.
        """
        plan = self.plan
        freqs, n = plan.frequencies, len(plan.frequencies)
        dwell_ns = round(plan.dwell * 1e9)
        if plan.start is None:
            start_ns, first = self._first_step(freqs[0], n)
        else:
            start_ns = round(plan.start * 1e9)
            first = self._request(freqs[0], start_ns, 0, n)
        times = [start_ns + k * dwell_ns for k in range(n)]
        self.steps.append(_record_step(freqs[0], first, times[0], dwell_ns))
        end_ns = times[-1] + dwell_ns
        if recorder is not None:   # the recording ends at the end of the last step, on every topic
            refused = recorder.set_stop_at(end_ns, plan.timeout)
            if refused is None:
                self.log(f"the recording ends at t = {end_ns / 1e9:.9f} s (the end of the last step)")
            else:
                self.log(f"the recorder's stop_at could not be set to {end_ns} ns ({refused}): the recording goes "
                         "on until the recorder stops; the analysis ends where every stream ends")
        # Every later step is scheduled now, while the first is still ahead of the rig: the rig queues them and
        # applies each at its stamp. Scheduled one dwell ahead instead, a starved experiment process (a loaded
        # machine) could see the rig's time too late and find its next stamp already passed while the rig, held
        # only by its recorders in lockstep, ran on.
        for k in range(1, n):
            response = self._request(freqs[k], times[k], k, n)
            self.steps.append(_record_step(freqs[k], response, times[k], dwell_ns))
        self.log(f"{n} steps scheduled from t = {start_ns / 1e9:.9f} s, one every {plan.dwell:g} s")
        for k, f in enumerate(freqs):
            self._wait_for_stamp(times[k], k, n, f, show=False)   # step k in force
            self._wait_for_stamp(times[k] + dwell_ns, k, n, f, show=True, origin=times[k])
        if recorder is not None:   # everything up to the end of the last step has reached the recorder
            # The events: each topic arrives in order, so once an event at or after the end is heard, every
            # event before it was; a motion without impacts at the end gives none (bounded wait).
            self.client.spin_until(lambda: bool(self.event_stamps) and self.event_stamps[-1] >= end_ns,
                                   min(plan.timeout, EVENTS_GRACE_S))
            before = [s for s in self.event_stamps if s < end_ns]
            if not recorder.wait_until_written(end_ns, before[-1] if before else None, plan.timeout):
                self.log(f"the recorder had not written everything up to the end of the last step within "
                         f"{plan.timeout:g} s ({recorder.written}); stopping it anyway: the analysis ends where "
                         "every stream ends")
        return self.steps

    def _request(self, f: float, start_ns: int, i: int, n: int, late_ok: bool = False) -> Any:
        """The rig's answer to setpoint ``f`` at ``start_ns``; None when refused as already passed and ``late_ok``."""
        response = self.client.motor(f, self.plan.ramp_rate, start_ns / 1e9)
        if not response.success:
            if late_ok and PASSED in response.message:
                return None
            raise CommandError(f"setpoint {f:g} Hz (step {i + 1}/{n}) refused by the rig: {response.message}; "
                               f"the rig keeps running at its setpoint {response.frequency_hz:g} Hz")
        return response

    def _cycle_start_after(self, earliest_ns: int) -> int:
        """The first start of a motor cycle at or after ``earliest_ns`` (else ``earliest_ns``: the motor ramps).

        The schedule then starts at the same motor phase whenever the experiment is begun.
        """
        f, phase, stamp = self.frequency, self.phase, self.stamp_ns
        if stamp is None or not (f > 0 and abs(f - self.setpoint) <= 1e-12 and math.isfinite(phase)):
            return earliest_ns
        period_ns = 1e9 / f
        to_next = ((2 * math.pi - phase) % (2 * math.pi)) / (2 * math.pi) * period_ns
        cycles = max(0, math.ceil((earliest_ns - stamp - to_next) / period_ns))
        return stamp + math.ceil(to_next + cycles * period_ns)

    def _first_step(self, f: float, n: int) -> tuple[int, Any]:
        """Schedule the first step at a cycle start a lead ahead; double the lead while the rig was faster."""
        lead = FIRST_LEAD_S
        assert self.stamp_ns is not None   # wait_for_motor() first
        for _ in range(MAX_LEAD_DOUBLINGS):
            start = self._cycle_start_after(self.stamp_ns + round(lead * 1e9))
            response = self._request(f, start, 0, n, late_ok=True)
            if response is not None:
                return start, response
            self.client.spin_until(lambda: False, 0.05)   # the latest motor state
            lead *= 2
        raise CommandError(f"the rig ran past every start time proposed (last lead {lead / 2:g} s of simulation "
                           "time): is it running far faster than the requests travel?")

    def _wait_for_stamp(self, target_ns: int, i: int, n: int, f: float, *, show: bool, origin: int = 0) -> None:
        """Spin until the rig's motor state reaches ``target_ns``; fail when the rig stops advancing."""
        last_stamp, last_change, shown = self.stamp_ns, time.monotonic(), 0.0
        while self.stamp_ns is None or self.stamp_ns < target_ns:
            self.client.executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            if self.stamp_ns != last_stamp:
                last_stamp, last_change = self.stamp_ns, now
            elif now - last_change > self.plan.timeout:
                raise CommandError(f"the rig's simulation time stopped advancing during step {i + 1}/{n} ({f:g} Hz) "
                                   f"for {self.plan.timeout:g} s: paused or stopped?")
            if show and self.show is not None and now - shown >= 0.5:
                shown = now
                elapsed = max(0.0, ((self.stamp_ns or origin) - origin) * 1e-9)
                self.show(f"step {i + 1}/{n}: {f:g} Hz, {min(elapsed, self.plan.dwell):5.1f}/{self.plan.dwell:g} s "
                          f"(motor {self.frequency:.3f} Hz)")
        if show and self.show is not None:
            self.show(f"step {i + 1}/{n}: {f:g} Hz, {self.plan.dwell:5.1f}/{self.plan.dwell:g} s "
                      f"(motor {self.frequency:.3f} Hz)")


def _ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _record_step(f: float, response: Any, start_ns: int, dwell_ns: int) -> dict:
    return {"frequency_hz": f, "scheduled_stamp_ns": start_ns, "effective_stamp_ns": _ns(response.effective_stamp),
            "end_stamp_ns": start_ns + dwell_ns, "message": response.message}
