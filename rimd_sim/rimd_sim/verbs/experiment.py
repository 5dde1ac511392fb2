"""``rimd experiment``: a stepped frequency sweep of the running rig, recorded, then analysed.

The paper's methodology (section 3): the motor frequency is stepped; at each step the rig dwells, the
transient is discarded and the steady impact force is read. Here the steps are scheduled on exact stamps of
the rig's own time base: step ``k`` starts at ``T0 + k * dwell``, where ``T0`` is the first start of a motor
cycle at least a lead time ahead of the rig when the experiment begins (the lead doubles while the rig
answers that the time has already passed). Each setpoint goes through ``/rig/set_motor_frequency`` with its
``start_stamp`` while the step before it is running, so however late a request travels (a loaded machine,
a fast ``real_time_factor``), the rig changes its setpoint at the same simulation time, and the same
schedule gives the same data. Unless ``--no-record``, the verb starts its own recorder process
(``rimd_sim.nodes._entry recorder`` as node ``rimd_experiment_recorder``, topics ``/rig/.*``, into
``OUT/recording``), waits until it subscribes to every rig topic, and finishes it with SIGINT once the rig has
passed the end of the last step; then it runs ``rimd analyze`` on the recording into ``OUT`` with the same
``--settle`` (its step table says whether each step had settled). The rig is never stopped: a refused setpoint
ends the experiment with an error naming it, and the rig keeps running.
"""

from __future__ import annotations

import argparse
import math
import signal
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

RECORDER_NODE = "rimd_experiment_recorder"
SERVICE = "/rig/set_motor_frequency"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd experiment``."""
    parser.add_argument("--frequencies", type=float, nargs="+", default=None,
                        help="motor frequencies (Hz) in the order they are set (instead of --f-min/--f-max/--f-step)")
    parser.add_argument("--f-min", type=float, default=3.0, help="first frequency (Hz, default 3.0)")
    parser.add_argument("--f-max", type=float, default=4.5, help="last frequency (Hz, default 4.5)")
    parser.add_argument("--f-step", type=float, default=0.25, help="step (Hz, default 0.25, the paper's grid)")
    parser.add_argument("--dwell", type=float, default=10.0,
                        help="simulation seconds per step, from the setpoint taking effect (default 10)")
    parser.add_argument("--settle", type=float, default=3.0,
                        help="seconds discarded after the motor reached each setpoint (default 3)")
    parser.add_argument("--ramp-rate", type=float, default=0.0,
                        help="ramp rate to each setpoint (Hz/s; 0 = the rig's motor.ramp_rate)")
    parser.add_argument("--out", type=Path, default=None,
                        help="output directory (default experiment_<UTC time>): recording/ and the analysis")
    parser.add_argument("--no-record", action="store_true",
                        help="do not start a recorder (a recorder already running records the rig)")
    parser.add_argument("--recording", type=Path, default=None,
                        help="with --no-record: the recording to analyse at the end (else no analysis)")
    parser.add_argument("--start", type=float, default=None,
                        help="stamp of the first step, in seconds of the rig's time base (simulation time when "
                             "real_time_factor is not 1); default: the first motor cycle start 1 s ahead of the rig. "
                             "With --start the rig may be paused until then: the same --start on a rig started the "
                             "same way gives the same data")
    parser.add_argument("--timeout", type=float, default=30.0,
                        help="wall seconds to wait for the rig, the recorder, or the simulation time to advance")
    parser.add_argument("--for-identification", nargs="?", const="", default=None, metavar="CONFIG",
                        help="choose 6 steps that make every parameter identifiable by rimd identify for the rig of "
                             "CONFIG (its parameter file as you believe it is; default config/rimd.yaml): steady "
                             "band-A steps spread across the band (rimd_sim.analysis.design)")


def schedule(args: argparse.Namespace) -> list[float]:
    """The frequencies of the experiment, checked.

    Raises:
        rimd_sim.cli.CommandError: A bad frequency, range, dwell, settle or ramp rate.
    """
    from rimd_sim.cli import CommandError
    from rimd_sim.verbs._analysis_io import check_positive, check_range

    if getattr(args, "for_identification", None) is not None:
        from rimd_sim.analysis.design import steps_for_identification

        try:
            freqs = steps_for_identification(args.for_identification, frequencies=args.frequencies, dwell=args.dwell,
                                             settle=args.settle, ramp_rate=args.ramp_rate)
        except ValueError as exc:
            raise CommandError(str(exc)) from None
    elif args.frequencies:
        freqs = list(args.frequencies)
        for f in freqs:
            if not (math.isfinite(f) and f >= 0):
                raise CommandError(f"--frequencies {f!r} refused: each must be finite and >= 0 Hz")
    else:
        check_range("f", args.f_min, args.f_max)
        check_positive("--f-step", args.f_step)
        n = int(math.floor((args.f_max - args.f_min) / args.f_step + 1e-9)) + 1
        freqs = [round(args.f_min + i * args.f_step, 12) for i in range(n)]
    check_positive("--dwell", args.dwell)
    check_positive("--settle", args.settle, inclusive=True)
    check_positive("--ramp-rate", args.ramp_rate, inclusive=True)
    check_positive("--timeout", args.timeout)
    if args.start is not None:
        check_positive("--start", args.start)
    if args.settle >= args.dwell:
        raise CommandError(f"--settle {args.settle:g} s >= --dwell {args.dwell:g} s: nothing would be measured")
    if args.ramp_rate > 0:
        worst = max((abs(b - a) for a, b in zip(freqs, freqs[1:], strict=False)), default=0.0) / args.ramp_rate
        if worst + args.settle >= args.dwell:
            raise CommandError(f"--dwell {args.dwell:g} s is too short: a ramp takes up to {worst:g} s at "
                               f"{args.ramp_rate:g} Hz/s, plus --settle {args.settle:g} s")
    if args.recording is not None and not args.no_record:
        raise CommandError("--recording is for --no-record (the experiment records into OUT/recording otherwise)")
    return freqs


class _Rig:
    """The experiment's node: the setpoint client and the latest motor state (simulation time)."""

    def __init__(self, timeout: float) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from rimd_msgs.msg import MotorState
        from rimd_msgs.srv import SetMotorFrequency

        self.timeout = timeout
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("rimd_experiment", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.client = self.node.create_client(SetMotorFrequency, SERVICE)
        self.stamp_ns: int | None = None
        self.frequency = math.nan
        self.setpoint = math.nan
        self.phase = math.nan
        self.node.create_subscription(MotorState, "/rig/motor/state", self._on_motor,
                                      QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        from diagnostic_msgs.msg import DiagnosticArray

        self.recorder_stamps: dict[str, int] = {}   # topic -> last stamp (ns) the experiment's recorder received
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        from rimd_msgs.msg import ImpactEvent

        self.event_stamps: list[int] = []   # stamps (ns) of the impact events heard, in order
        self.node.create_subscription(
            ImpactEvent, "/rig/impact/events",
            lambda msg: self.event_stamps.append(int(msg.header.stamp.sec) * 1_000_000_000
                                                 + int(msg.header.stamp.nanosec)),
            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))

    def _on_diagnostics(self, msg) -> None:  # noqa: ANN001
        for status in msg.status:
            if RECORDER_NODE in status.name:
                for kv in status.values:
                    if kv.key.endswith(" last_stamp_ns"):
                        self.recorder_stamps[kv.key[: -len(" last_stamp_ns")]] = int(kv.value)

    def _on_motor(self, msg) -> None:  # noqa: ANN001
        self.stamp_ns = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        self.frequency, self.setpoint = float(msg.frequency), float(msg.frequency_setpoint)
        self.phase = float(msg.phase)

    def spin_until(self, condition, timeout: float) -> bool:  # noqa: ANN001
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() >= deadline:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


def _stop_recorder(proc: subprocess.Popen) -> int | None:
    for sig, wait in ((signal.SIGINT, 20.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        if proc.poll() is not None:
            break
        proc.send_signal(sig)
        try:
            proc.wait(wait)
        except subprocess.TimeoutExpired:
            continue
    return proc.returncode


def _tail(path: Path, lines: int = 5) -> str:
    try:
        return " | ".join(path.read_text(errors="replace").strip().splitlines()[-lines:])
    except OSError:
        return ""


def main(args: argparse.Namespace) -> int:  # noqa: C901 - one linear procedure
    """Run the experiment, then the analysis of its recording."""
    from rimd_sim.cli import CommandError
    from rimd_sim.verbs._analysis_io import write_json

    freqs = schedule(args)
    out = args.out or Path(f"experiment_{datetime.now(UTC).strftime('%Y%m%dT%H%M%SZ')}")
    out.mkdir(parents=True, exist_ok=True)
    log = _progress_log
    rig = _Rig(args.timeout)
    recorder: subprocess.Popen | None = None
    record_dir = out / "recording"
    steps_done: list[dict] = []
    try:
        if not rig.client.wait_for_service(timeout_sec=args.timeout):
            raise CommandError(f"no rig: service {SERVICE} not available after {args.timeout:g} s "
                               "(start it with `rimd rig`, on the same ROS_DOMAIN_ID)")
        if args.start is None and not rig.spin_until(lambda: rig.stamp_ns is not None, args.timeout):
            raise CommandError(f"no /rig/motor/state received in {args.timeout:g} s: is the rig paused? "
                               "(--start schedules a paused rig)")
        if not args.no_record:
            recorder = _start_recorder(rig, record_dir, out / "recorder.log", args.timeout, log)
        dwell_ns = round(args.dwell * 1e9)
        if args.start is None:
            start_ns, first = _first_step(rig, freqs[0], args, len(freqs))
        else:
            start_ns = round(args.start * 1e9)
            first = _request(rig, freqs[0], args, start_ns, 0, len(freqs))
        times = [start_ns + k * dwell_ns for k in range(len(freqs))]
        steps_done.append(_record_step(freqs[0], first, times[0], dwell_ns))
        log(f"{len(freqs)} steps scheduled from t = {start_ns / 1e9:.9f} s, one every {args.dwell:g} s")
        for k, f in enumerate(freqs):
            _wait_for_stamp(rig, times[k], k, len(freqs), f, args, show=False)   # step k in force
            if k + 1 < len(freqs):   # scheduled while step k runs: a whole dwell of lead
                response = _request(rig, freqs[k + 1], args, times[k + 1], k + 1, len(freqs))
                steps_done.append(_record_step(freqs[k + 1], response, times[k + 1], dwell_ns))
            _wait_for_stamp(rig, times[k] + dwell_ns, k, len(freqs), f, args, show=True, origin=times[k])
        if recorder is not None:   # everything up to the end of the last step has reached the recorder
            _wait_for_recorder(rig, times[-1] + dwell_ns, args.timeout, log)
    finally:
        if recorder is not None:
            code = _stop_recorder(recorder)
            if code not in (0, None):
                log(f"the recorder exited with status {code}: {_tail(out / 'recorder.log')}")
        write_json(out / "experiment.json", {
            "frequencies_hz": freqs, "dwell_s": args.dwell, "settle_s": args.settle, "ramp_rate_hz_s": args.ramp_rate,
            "recording": None if args.no_record else str(record_dir), "steps": steps_done})
        rig.close()
    print(file=sys.stderr)
    target = args.recording if args.no_record else record_dir
    if target is None:
        print(f"experiment done ({len(freqs)} steps, not recorded here); schedule in {out / 'experiment.json'}")
        return 0
    from rimd_sim.analysis.report import ReportError, analyze, format_report
    from rimd_sim.recording.reader import RecordingError

    try:
        summary = analyze(target, out, settle=args.settle, log=lambda text: log(f"analyze: {text}"))
    except (RecordingError, ReportError) as exc:
        raise CommandError(f"the experiment ran but its recording cannot be analysed: {exc}") from None
    print("\n".join(format_report(summary)))
    print(f"recording in {target}; analysis in {out}")
    return 0


def _progress_log(text: str) -> None:
    print(f"\rrimd experiment: {text}", file=sys.stderr, flush=True)


def _start_recorder(rig: _Rig, directory: Path, log_path: Path, timeout: float, log) -> subprocess.Popen:  # noqa: ANN001
    from rimd_sim.cli import CommandError

    directory.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "rimd_sim.nodes._entry", "recorder", "--ros-args", "-r", f"__node:={RECORDER_NODE}",
           "-p", f"output_dir:={directory}", "-p", "topics:=['/rig/.*']", "-p", "prefix:=experiment"]
    with open(log_path, "w") as log_file:
        proc = subprocess.Popen(cmd, stdout=log_file, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                start_new_session=True)
    log(f"recorder started (pid {proc.pid}), recording into {directory}")

    def subscribed() -> bool:
        if proc.poll() is not None:
            return True
        topics = [name for name, _ in rig.node.get_topic_names_and_types()
                  if name.startswith("/rig/") and rig.node.count_publishers(name) > 0]
        return bool(topics) and all(
            any(info.node_name == RECORDER_NODE for info in rig.node.get_subscriptions_info_by_topic(t))
            for t in topics)

    ok = rig.spin_until(subscribed, timeout)
    if proc.poll() is not None:
        raise CommandError(f"the recorder exited with status {proc.returncode}: {_tail(log_path)}")
    if not ok:
        _stop_recorder(proc)
        raise CommandError(f"the recorder did not subscribe to the rig topics within {timeout:g} s: {_tail(log_path)}")
    rig.spin_until(lambda: False, 0.5)   # subscriptions matched with the publishers
    return proc


#: First lead of the schedule (s of simulation time); doubled while the rig answers "already passed".
FIRST_LEAD_S = 1.0
#: Longest wait (wall s) for an impact event after the end of the last step, to know that every event
#: before the end has arrived (none comes when the motion does not impact).
EVENTS_GRACE_S = 5.0
MAX_LEAD_DOUBLINGS = 10


def _stamp(t) -> int:  # noqa: ANN001 - builtin_interfaces/Time
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def _cycle_start_after(rig: _Rig, earliest_ns: int) -> int:
    """The first start of a motor cycle at or after ``earliest_ns`` (else ``earliest_ns``, the motor ramping).

    The schedule then starts at the same motor phase whenever the experiment is begun.
    """
    f, phase, stamp = rig.frequency, rig.phase, rig.stamp_ns
    if stamp is None or not (f > 0 and abs(f - rig.setpoint) <= 1e-12 and math.isfinite(phase)):
        return earliest_ns
    period_ns = 1e9 / f
    to_next = ((2 * math.pi - phase) % (2 * math.pi)) / (2 * math.pi) * period_ns
    cycles = max(0, math.ceil((earliest_ns - stamp - to_next) / period_ns))
    return stamp + math.ceil(to_next + cycles * period_ns)


def _request(rig: _Rig, f: float, args: argparse.Namespace, start_ns: int, i: int, n: int,
             refused_ok: bool = False):  # noqa: ANN202
    """Send setpoint ``f`` to start at ``start_ns``; return the response (None: refused and ``refused_ok``)."""
    from builtin_interfaces.msg import Time

    from rimd_msgs.srv import SetMotorFrequency
    from rimd_sim.cli import CommandError

    request = SetMotorFrequency.Request(frequency_hz=float(f), ramp_rate=float(args.ramp_rate),
                                        start_stamp=Time(sec=start_ns // 1_000_000_000,
                                                         nanosec=start_ns % 1_000_000_000))
    future = rig.client.call_async(request)
    if not rig.spin_until(future.done, args.timeout):
        raise CommandError(f"{SERVICE} did not answer the setpoint {f:g} Hz within {args.timeout:g} s")
    response = future.result()
    if not response.success:
        if refused_ok:
            return None
        raise CommandError(f"setpoint {f:g} Hz (step {i + 1}/{n}) refused by the rig: {response.message}; "
                           f"the rig keeps running at its setpoint {response.frequency_hz:g} Hz")
    return response


def _wait_for_recorder(rig: _Rig, end_ns: int, timeout: float, log) -> None:  # noqa: ANN001
    """Wait until the recorder's /diagnostics say every rig stream it records has reached ``end_ns``.

    A recorder lagging behind a fast rig on a loaded machine holds each topic's backlog apart; stopped as soon
    as the rig passes the end, it would cut the topics at different times. The sampled topics and the motor
    states are continuous, so their last stamps tell; the sparse impact events travel with them.
    """
    reached = rig.recorder_stamps
    names = ("/rig/motor/state", "/rig/impact/force", "/rig/rimd/displacement", "/rig/cart/displacement",
             "/rig/rimd/acceleration")
    # The events: each topic arrives in order, so once this node has heard an event stamped at or after the
    # end it has heard every event before it; a motion without impacts at the end gives none (bounded wait).
    rig.spin_until(lambda: bool(rig.event_stamps) and rig.event_stamps[-1] >= end_ns, min(timeout, EVENTS_GRACE_S))
    before = [s for s in rig.event_stamps if s < end_ns]
    last_event = before[-1] if before else None

    def caught_up() -> bool:
        if not reached or any(reached.get(n, 0) < end_ns for n in names if n in reached):
            return False
        return last_event is None or reached.get("/rig/impact/events", 0) >= last_event

    if not rig.spin_until(caught_up, timeout):
        log(f"the recorder had not received everything up to the end of the last step within {timeout:g} s "
            f"({ {n: reached.get(n) for n in (*names, '/rig/impact/events')} }); stopping it anyway: the analysis "
            "ends where every stream ends")


def _first_step(rig: _Rig, f: float, args: argparse.Namespace, n: int):  # noqa: ANN202
    """Schedule the first step at a cycle start a lead ahead; double the lead while the rig was faster."""
    from rimd_sim.cli import CommandError

    lead = FIRST_LEAD_S
    for _ in range(MAX_LEAD_DOUBLINGS):
        start = _cycle_start_after(rig, rig.stamp_ns + round(lead * 1e9))
        response = _request(rig, f, args, start, 0, n, refused_ok=True)
        if response is not None:
            return start, response
        rig.spin_until(lambda: False, 0.05)   # the latest motor state
        if rig.stamp_ns is not None and rig.stamp_ns < start:   # refused for another reason than lateness
            _request(rig, f, args, start, 0, n)                 # raises with the rig's message
        lead *= 2
    raise CommandError(f"the rig ran past every start time proposed (last lead {lead / 2:g} s of simulation time): "
                       "is it running far faster than the requests travel?")


def _record_step(f: float, response, start_ns: int, dwell_ns: int) -> dict:  # noqa: ANN001
    effective = _stamp(response.effective_stamp)
    return {"frequency_hz": f, "scheduled_stamp_ns": start_ns, "effective_stamp_ns": effective,
            "end_stamp_ns": start_ns + dwell_ns, "message": response.message}


def _wait_for_stamp(rig: _Rig, target_ns: int, i: int, n: int, f: float, args: argparse.Namespace, *,
                    show: bool, origin: int = 0) -> None:
    """Spin until the rig's motor state stamp reaches ``target_ns``; fail when the rig stops advancing."""
    from rimd_sim.cli import CommandError

    last_stamp, last_change = rig.stamp_ns, time.monotonic()
    shown = 0.0
    while rig.stamp_ns is None or rig.stamp_ns < target_ns:
        rig.executor.spin_once(timeout_sec=0.05)
        now = time.monotonic()
        if rig.stamp_ns != last_stamp:
            last_stamp, last_change = rig.stamp_ns, now
        elif now - last_change > args.timeout:
            raise CommandError(f"the rig's simulation time stopped advancing during step {i + 1}/{n} ({f:g} Hz) "
                               f"for {args.timeout:g} s: paused or stopped?")
        if show and now - shown >= 0.5:
            shown = now
            elapsed = max(0.0, ((rig.stamp_ns or origin) - origin) * 1e-9)
            print(f"\rrimd experiment: step {i + 1}/{n}: {f:g} Hz, {min(elapsed, args.dwell):5.1f}/{args.dwell:g} s "
                  f"(motor {rig.frequency:.3f} Hz)", end="", file=sys.stderr, flush=True)
    if show:
        print(f"\rrimd experiment: step {i + 1}/{n}: {f:g} Hz, {args.dwell:5.1f}/{args.dwell:g} s "
              f"(motor {rig.frequency:.3f} Hz)", end="", file=sys.stderr, flush=True)
