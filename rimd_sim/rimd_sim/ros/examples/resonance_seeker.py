"""A reference controller of the rig: keep it at its impact resonance by perturb and observe (docs/control.md).

Run it against a rig in lockstep with ``python -m rimd_sim.ros.examples.resonance_seeker --lockstep seeker``
(``rimd rig --lockstep --consumer seeker`` in another shell), or against a rig at real time without
``--lockstep``. It prints one JSON report once it has converged (also to ``--json FILE``) and exits 0; 1 when it
has not converged by ``--until`` seconds of simulation time.

The algorithm is :class:`PerturbObserve`, a plain class without ROS (unit-tested alone, and against the rig's core
offline with :func:`seek_offline`): it commands a motor frequency, lets the motion settle, takes the mean of the
true peak impact forces of the next impacts, and steps the frequency towards higher forces, halving the step and
turning back each time a step made them lower, until the step is below ``min_step_hz``. It then commands the best
frequency it measured and holds it.

The node is a thin adapter:

* **the true peak.** It reads each impact's peak from ``/rig/impact/events`` (``peak_force``: the model's own
  peak, the ground truth), or with ``--peaks capture`` from the 1 MHz triggered capture ``/rig/capture/force``
  (the rig's ``capture.enabled``: the largest sample, within 0.5 % of the true peak). Not from the 20 kHz force
  channel: its largest sample is up to ~18 % below the peak depending on where the samples fall in the
  millisecond contact, and that bias changes with the frequency (docs/control.md, "Reading the peak force");
* **the commands** go on ``/rig/motor/command`` through :class:`rimd_sim.ros.clients.motor.MotorCommander`,
  stamp zero; with ``--lockstep NAME`` it reports its progress (``ProgressReporter``) as a controller: the rig
  stops after each block that brought an impact until the controller has taken it, and applies a command at the
  end of that block. Two runs give the same commands and the same data, bit for bit, and :func:`seek_offline`
  gives them too, in process;
* **the applied frequency** is read back from ``/rig/motor/state`` (``frequency_setpoint`` at each block's end)
  for the report; the decisions do not depend on it (it is not a topic the controller holds the rig on).

Its times are the run's simulation seconds whatever the rig's time base (the stamp less the run's start, from
``/rig/session``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

__all__ = ["Observation", "PerturbObserve", "main", "seek_offline"]


@dataclass(frozen=True)
class Observation:
    """One measured point: the frequency (Hz), the mean peak force there (N), and the impacts' times (s)."""

    frequency_hz: float
    peak_n: float
    first_s: float
    last_s: float


@dataclass
class PerturbObserve:
    """Perturb and observe on the steady peak impact force: the motor frequency that makes it largest.

    Feed it every impact (:meth:`impact`, in order); it answers with a new setpoint to command at once, or None.
    Times are seconds of simulation time; a command is taken to apply when the impact that decided it starts
    (the rig applies it at the end of that block, a few milliseconds later).

    Args:
        start_hz: The first setpoint (commanded by :meth:`begin`).
        step_hz: The first step (Hz).
        min_step_hz: Converged once the step is below this (Hz): the best frequency measured is held.
        settle_s: Seconds after a ramp ends before the impacts count (the motion's transient).
        measure: Impacts averaged per observation.
        ramp_hz_s: Ramp rate of the commands (Hz/s); the ramp's length is waited for too.
        low_hz: Lowest setpoint it commands.
        high_hz: Highest setpoint it commands.
    """

    start_hz: float = 3.0
    step_hz: float = 0.2
    min_step_hz: float = 0.01
    settle_s: float = 2.0
    measure: int = 4
    ramp_hz_s: float = 2.0
    low_hz: float = 0.5
    high_hz: float = 12.0
    #: The setpoint in force (Hz).
    frequency_hz: float = field(init=False, default=math.nan)
    #: The best point measured so far (the incumbent), and every observation in order.
    best: Observation | None = field(init=False, default=None)
    observations: list[Observation] = field(init=False, default_factory=list)
    #: Whether it has converged, and the time of the impact that made it so (s).
    converged: bool = field(init=False, default=False)
    converged_at: float = field(init=False, default=math.nan)
    _direction: float = field(init=False, default=1.0)
    _step: float = field(init=False, default=0.0)
    _since: float = field(init=False, default=math.inf)
    _peaks: list[tuple[float, float]] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        """Check the settings (a ValueError names the first one refused)."""
        rules = {"step_hz": self.step_hz > 0, "min_step_hz": 0 < self.min_step_hz <= self.step_hz,
                 "settle_s": self.settle_s >= 0, "measure": self.measure >= 1, "ramp_hz_s": self.ramp_hz_s > 0,
                 "low_hz": 0 <= self.low_hz < self.high_hz,
                 "start_hz": self.low_hz <= self.start_hz <= self.high_hz}
        for name, ok in rules.items():
            if not ok or not math.isfinite(float(getattr(self, name))):
                raise ValueError(f"{name} = {getattr(self, name)!r} refused: must be finite, with step_hz > 0, "
                                 "0 < min_step_hz <= step_hz, settle_s >= 0, measure >= 1, ramp_hz_s > 0, "
                                 "0 <= low_hz < high_hz and start_hz within them")
        self._step = self.step_hz

    @property
    def result_hz(self) -> float:
        """The best frequency measured (NaN before the first observation)."""
        return self.best.frequency_hz if self.best is not None else math.nan

    def begin(self, t: float) -> float:
        """The first setpoint, commanded at ``t`` s: its ramp is taken to start from rest (the worst case)."""
        self.frequency_hz = self.start_hz
        self._since = t + self.start_hz / self.ramp_hz_s + self.settle_s
        return self.start_hz

    def impact(self, t: float, peak_n: float) -> float | None:
        """One impact: its start (s) and true peak force (N). Returns the setpoint to command now, or None."""
        if self.converged or t < self._since:
            return None
        self._peaks.append((t, peak_n))
        if len(self._peaks) < self.measure:
            return None
        seen = Observation(self.frequency_hz, math.fsum(p for _, p in self._peaks) / len(self._peaks),
                           self._peaks[0][0], t)
        self._peaks.clear()
        self.observations.append(seen)
        if self.best is None or seen.peak_n > self.best.peak_n:
            self.best = seen   # better: go on the same way
        else:                  # not better: turn back from the best point, with half the step
            self._direction = -self._direction
            self._step /= 2
        if self._step < self.min_step_hz:
            self.converged, self.converged_at = True, t
            return self._go(t, self.best.frequency_hz) if self.best.frequency_hz != self.frequency_hz else None
        target = self.best.frequency_hz + self._direction * self._step
        if not self.low_hz <= target <= self.high_hz:   # at a bound: the other way
            self._direction = -self._direction
            target = self.best.frequency_hz + self._direction * self._step
        return self._go(t, min(max(target, self.low_hz), self.high_hz))

    def _go(self, t: float, target: float) -> float:
        self._since = t + abs(target - self.frequency_hz) / self.ramp_hz_s + self.settle_s
        self.frequency_hz = target
        return target


def seek_offline(config: Any, seeker: PerturbObserve, until: float, *, peaks: str = "events") -> list[Any]:
    """Run ``seeker`` against the rig's core offline, as the node runs it against a rig in lockstep.

    The same commands at the same times, bit for bit (:mod:`rimd_sim.runtime.closed_loop`): each block's impacts
    (or captures, ``peaks="capture"``) fed in order with their stamps' times, each setpoint applied at the end of
    the block it was decided on. Stops at convergence or at ``until`` s.

    Returns:
        The applied commands (:class:`rimd_sim.runtime.closed_loop.Applied`), the start setpoint first.
    """
    from rimd_sim.runtime.closed_loop import Command, run_closed_loop
    from rimd_sim.settings.capture import CaptureConfig

    def decide(block: Any) -> list[Command]:
        if peaks == "capture":
            seen = [(round(float(c.trigger_time) * 1e9), float(max(c.force))) for c in block.captures]
        else:
            seen = [(round(i.t_start * 1e9), i.peak_force) for i in block.impacts]
        out = []
        for ns, peak in seen:   # times as the stamps carry them (integer ns), as the node reads them
            target = seeker.impact(ns / 1e9, peak)
            if target is not None:
                out.append(Command(target, seeker.ramp_hz_s))
        return out

    start = Command(seeker.begin(0.0), seeker.ramp_hz_s)
    capture = CaptureConfig(enabled=True) if peaks == "capture" else None
    return run_closed_loop(config, decide, until, initial=[start], capture=capture, stop=lambda: seeker.converged)


def _ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the controller until it converges or ``--until`` s of simulation time; print the JSON report."""
    parser = argparse.ArgumentParser(prog="python -m rimd_sim.ros.examples.resonance_seeker",
                                     description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--lockstep", default="", metavar="NAME",
                        help="report progress under NAME, as a controller (a rig in lockstep with --consumer NAME)")
    parser.add_argument("--peaks", choices=("events", "capture"), default="events",
                        help="where the true peak comes from: /rig/impact/events (default) or /rig/capture/force "
                             "(the rig's capture.enabled)")
    defaults = PerturbObserve()
    parser.add_argument("--start", type=float, default=defaults.start_hz, help="first setpoint (Hz)")
    parser.add_argument("--step", type=float, default=defaults.step_hz, help="first step (Hz)")
    parser.add_argument("--min-step", type=float, default=defaults.min_step_hz, help="converged below this step (Hz)")
    parser.add_argument("--settle", type=float, default=defaults.settle_s, help="s after a ramp before impacts count")
    parser.add_argument("--measure", type=int, default=defaults.measure, help="impacts averaged per point")
    parser.add_argument("--ramp", type=float, default=defaults.ramp_hz_s, help="ramp rate of the commands (Hz/s)")
    parser.add_argument("--until", type=float, default=300.0, help="simulation seconds before giving up")
    parser.add_argument("--json", default="", help="also write the report to this file")
    parser.add_argument("--timeout", type=float, default=600.0, help="wall seconds before giving up")
    args = parser.parse_args(argv)
    try:
        seeker = PerturbObserve(args.start, args.step, args.min_step, args.settle, args.measure, args.ramp)
    except ValueError as exc:
        parser.error(str(exc))

    import time

    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from rimd_msgs.msg import Capture, ImpactEvent, MotorState, RigSession
    from rimd_sim.ros.clients.motor import MotorCommander
    from rimd_sim.ros.clients.progress import ProgressReporter

    rclpy.init()
    node = Node("resonance_seeker")
    # rclpy's events executor takes the messages in the order they come, at a fraction of the single-threaded
    # executor's cost per message: the motor state comes at every block, faster than that one keeps up with when
    # the rig runs several times real time.
    executor = EventsExecutor()
    executor.add_node(node)
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    origin_ns: list[int] = []              # the stamp of simulation time 0 (from /rig/session)
    latest_s: list[float] = []             # the last motor state's time (s)
    applied: list[dict[str, float]] = []   # setpoint changes as /rig/motor/state shows them
    commands: list[dict[str, float]] = []

    def seconds(ns: int) -> float:
        return (ns - (origin_ns[0] if origin_ns else 0)) / 1e9

    def on_session(msg: RigSession) -> None:
        origin_ns[:] = [_ns(msg.start_stamp) - round(msg.simulation_time * 1e9)]

    def on_motor(msg: MotorState) -> None:
        latest_s[:] = [seconds(_ns(msg.header.stamp))]
        if not applied or applied[-1]["setpoint_hz"] != msg.frequency_setpoint:
            applied.append({"seen_at_s": latest_s[0], "setpoint_hz": msg.frequency_setpoint})

    def on_peak(msg: Any) -> None:
        # The decision first, then the commands it led to, then done: the rig waits for all three (lockstep).
        peak = msg.peak_force if args.peaks == "events" else max(msg.samples, default=0.0)
        t = seconds(_ns(msg.header.stamp))
        target = seeker.impact(t, peak)
        if target is not None:
            motor.command(target, seeker.ramp_hz_s)
            commands.append({"decided_at_s": t, "frequency_hz": target})
        if reporter is not None:
            reporter.done(msg.header.stamp, peaks)

    node.create_subscription(RigSession, "/rig/session", on_session, latched)
    node.create_subscription(MotorState, "/rig/motor/state", on_motor, qos)
    peaks = (node.create_subscription(ImpactEvent, "/rig/impact/events", on_peak, qos) if args.peaks == "events"
             else node.create_subscription(Capture, "/rig/capture/force", on_peak, qos))
    # Joins once the first setpoint is given (below): the join counts it, so the rig applies it at its start.
    reporter = (ProgressReporter(node, args.lockstep, subscriptions=[peaks], ready=lambda: bool(commands))
                if args.lockstep else None)
    motor = MotorCommander(node, reporter)
    deadline = time.monotonic() + args.timeout
    while not origin_ns and time.monotonic() < deadline:   # the run's time origin, before the first command
        executor.spin_once(timeout_sec=0.05)
    start = seeker.begin(latest_s[0] if latest_s else 0.0)
    motor.command(start, seeker.ramp_hz_s)   # in lockstep: before the join, so at the run's start
    commands.append({"decided_at_s": latest_s[0] if latest_s else 0.0, "frequency_hz": start})
    while not seeker.converged and (not latest_s or latest_s[0] < args.until) and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)

    report = {
        "converged": seeker.converged,
        "frequency_hz": seeker.result_hz,
        "converged_at_s": seeker.converged_at if seeker.converged else None,
        "peaks": args.peaks,
        "commands": commands,
        "observations": [asdict(o) for o in seeker.observations],
        "applied": applied,
    }
    text = json.dumps(report, indent=1)
    print(text, flush=True)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text)
    if reporter is not None:
        reporter.leave()   # a rig in lockstep goes on without it
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0 if seeker.converged else 1


if __name__ == "__main__":
    sys.exit(main())
