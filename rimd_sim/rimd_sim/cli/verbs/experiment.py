"""``rimd experiment``: a stepped frequency sweep of the running rig, recorded, then analysed.

The steps are scheduled on exact stamps of the rig's own time base, so the same schedule gives the same data
however late the requests travel (:mod:`rimd_sim.ros.clients.experiment`). Unless ``--no-record``, the verb starts
its own recorder process (node ``rimd_experiment_recorder``, topics ``/rig/.*``, into ``OUT/recording``); a rig in
lockstep that names it among its consumers waits for it, however fast the rig runs (what the transport still
loses on a heavily loaded machine is counted and printed on the ``LOSS:`` line, docs/recording.md). Once
the recorder has written everything up to the end of the last step it is stopped with SIGINT and the
recording is analysed into ``OUT`` with the same ``--settle`` (:mod:`rimd_sim.analysis.recordings.report`). The rig
is never stopped: a refused setpoint ends the experiment with an error naming it, and the rig keeps running.
"""

from __future__ import annotations

import argparse
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

from rimd_sim.cli import CommandError, nonnegative_float, number, positive_float
from rimd_sim.cli.verbs._analysis_io import add_frequency_grid

if TYPE_CHECKING:   # rclpy and the ROS layer are imported when the verb runs
    from rimd_sim.ros.clients.experiment import ExperimentPlan

HERTZ = nonnegative_float("--frequencies", "Hz")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd experiment``."""
    parser.add_argument("--frequencies", type=HERTZ, nargs="+", default=None,
                        help="motor frequencies (Hz) in the order they are set (instead of --f-min/--f-max/--f-step)")
    add_frequency_grid(parser, (3.0, 4.5), 0.25, words=("first frequency", "last frequency",
                                                        "frequency step, the paper's grid,"))
    parser.add_argument("--dwell", type=positive_float("--dwell", "s"), default=10.0,
                        help="simulation seconds per step, from the setpoint taking effect (default 10)")
    parser.add_argument("--settle", type=nonnegative_float("--settle", "s"), default=3.0,
                        help="seconds discarded after the motor reached each setpoint (default 3)")
    parser.add_argument("--ramp-rate", type=nonnegative_float("--ramp-rate", "Hz/s"), default=0.0,
                        help="ramp rate to each setpoint (Hz/s; 0 = the rig's motor.ramp_rate)")
    parser.add_argument("--out", type=Path, default=None,
                        help="output directory (default experiment_<UTC time>): recording/ and the analysis")
    parser.add_argument("--no-record", action="store_true",
                        help="do not start a recorder (a recorder already running records the rig)")
    parser.add_argument("--recording", type=Path, default=None,
                        help="with --no-record: the recording to analyse at the end (else no analysis)")
    parser.add_argument("--start", type=positive_float("--start", "s"), default=None,
                        help="stamp of the first step, in seconds of the rig's time base (simulation time when "
                             "real_time_factor is not 1); default: the first motor cycle start 1 s ahead of the rig. "
                             "With --start the rig may be paused until then: the same --start on a rig started the "
                             "same way gives the same data")
    parser.add_argument("--timeout", type=number("--timeout", "s", gt=0, le=86400), default=30.0,
                        help="wall seconds to wait for the rig, the recorder, or the simulation time to advance")
    parser.add_argument("--for-identification", nargs="?", const="", default=None, metavar="CONFIG",
                        help="choose 6 steps that make every parameter identifiable by rimd identify for the rig of "
                             "CONFIG (its parameter file as you believe it is; default config/rimd.yaml): steady "
                             "band-A steps spread across the band (rimd_sim.analysis.identification.design)")


def plan(args: argparse.Namespace) -> ExperimentPlan:
    """The experiment the options describe, checked as a whole (each number's rule is its option's).

    Raises:
        CommandError: A range upside down, a settle as long as the dwell, a ramp too slow for the dwell...
        DesignError: ``--for-identification``: no schedule for the rig, or its parameter file does not load.
    """
    from rimd_sim.ros.clients.experiment import ExperimentPlan, frequency_steps

    if args.for_identification is not None:
        from rimd_sim.analysis.identification.design import steps_for_identification

        freqs = tuple(steps_for_identification(args.for_identification, frequencies=args.frequencies,
                                               dwell=args.dwell, settle=args.settle, ramp_rate=args.ramp_rate))
    elif args.frequencies:
        freqs = tuple(args.frequencies)
    else:
        if args.f_min > args.f_max:
            raise CommandError(f"--f-min {args.f_min:g} > --f-max {args.f_max:g}: need min <= max")
        freqs = frequency_steps(args.f_min, args.f_max, args.f_step)
    if args.recording is not None and not args.no_record:
        raise CommandError("--recording is for --no-record (the experiment records into OUT/recording otherwise)")
    return ExperimentPlan(freqs, dwell=args.dwell, settle=args.settle, ramp_rate=args.ramp_rate, start=args.start,
                          timeout=args.timeout)


def main(args: argparse.Namespace) -> int:
    """Run the experiment, then the analysis of its recording."""
    from rimd_sim.cli.verbs._analysis_io import write_json
    from rimd_sim.ros.clients.experiment import RECORDER_NODE, ExperimentRecorder, ExperimentRun
    from rimd_sim.ros.clients.rig import RigClient

    experiment = plan(args)
    out = args.out or Path(f"experiment_{datetime.now(UTC).strftime('%Y%m%dT%H%M%SZ')}")
    out.mkdir(parents=True, exist_ok=True)
    record_dir = None if args.no_record else out / "recording"
    recorder = None
    with RigClient(timeout=args.timeout, name="rimd_experiment") as client:
        run = ExperimentRun(experiment, client, log=_log, show=_show)
        try:
            if record_dir is not None:   # first: a rig in lockstep with it holds until it joins
                recorder = ExperimentRecorder(client, record_dir, out / "recorder.log", _log)
                recorder.launch()
            client.wait_for_service("set_motor_frequency")
            if recorder is not None:
                recorder.wait_subscribed(args.timeout)
            if experiment.start is None:
                run.wait_for_motor()
            run.run(recorder)
        finally:
            if recorder is not None:
                code = recorder.stop()
                if code not in (0, None):
                    _log(f"the recorder ({RECORDER_NODE}) exited with status {code}: {recorder.tail()}")
            write_json(out / "experiment.json", {
                "frequencies_hz": list(experiment.frequencies), "dwell_s": experiment.dwell,
                "settle_s": experiment.settle, "ramp_rate_hz_s": experiment.ramp_rate,
                "recording": None if record_dir is None else str(record_dir), "steps": run.steps})
    print(file=sys.stderr)
    target = args.recording if args.no_record else record_dir
    if target is None:
        print(f"experiment done ({len(experiment.frequencies)} steps, not recorded here); "
              f"schedule in {out / 'experiment.json'}")
        return 0
    from rimd_sim.analysis.recordings.report import analyze, format_report
    from rimd_sim.errors import RimdError

    try:
        summary = analyze(target, out, settle=args.settle, log=lambda text: _log(f"analyze: {text}"))
    except RimdError as exc:   # not a translation: only the verb knows that the experiment itself ran
        raise CommandError(f"the experiment ran but its recording cannot be analysed: {exc}") from None
    print("\n".join(format_report(summary)))
    print(f"recording in {target}; analysis in {out}")
    return 0


def _log(text: str) -> None:
    print(f"\rrimd experiment: {text}", file=sys.stderr, flush=True)


def _show(text: str) -> None:
    print(f"\rrimd experiment: {text}", end="", file=sys.stderr, flush=True)
