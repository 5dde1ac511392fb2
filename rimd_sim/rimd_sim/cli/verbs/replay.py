"""``rimd replay REC``: replay a recording on the rig topics, alone or driven from Foxglove's timeline.

A thin verb over :func:`rimd_sim.ros.bringup.plan.plan_replay` (the replay node ``rimd_replay``; with
``--foxglove`` the bridge serving Foxglove, pointed at the replay) and :class:`rimd_sim.ros.bringup.processes.Rig`
(start, watch, stop).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rimd_sim.cli import count, nonnegative_float, number


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd replay``."""
    parser.add_argument("recording", type=Path,
                        help="ROS 2 MCAP recording: one .mcap file or a recording directory of rimd_recorder")
    parser.add_argument("--rate", type=number("--rate", gt=0, le=1e4), default=1.0, metavar="R",
                        help="speed factor (2 = twice as fast as recorded; default 1)")
    parser.add_argument("--start", type=number("--start", "s", ge=0, le=1e9), default=0.0, metavar="S",
                        help="start S s after the recording's first message (default 0)")
    parser.add_argument("--duration", type=nonnegative_float("--duration", "s"), default=0.0, metavar="D",
                        help="play D s from the start (default 0: to the end)")
    parser.add_argument("--topics", nargs="+", default=None, metavar="REGEX",
                        help="topics to replay: regular expressions, full match (default: every topic)")
    parser.add_argument("--loop", action="store_true", help="start again at the end")
    parser.add_argument("--paused", action="store_true", help="start paused (resume: rimd_replay's ~/resume)")
    parser.add_argument("--clock", action="store_true", help="publish /clock from the recorded log time")
    parser.add_argument("--foxglove", action="store_true",
                        help="drive the replay from Foxglove's timeline (play, pause, speed, seek): the bridge serves "
                             "it on ws://127.0.0.1:8765; the replay starts paused and stays up at the end")
    parser.add_argument("--port", type=count("--port", 0, 65535), default=None, metavar="P",
                        help="with --foxglove: the server's TCP port (default 8765; 0 = a free port, logged)")


def main(args: argparse.Namespace) -> int:
    """Start the replay (and the bridge), wait until it ends or Ctrl-C; return non-zero if a node failed."""
    from rimd_sim.cli import CommandError
    from rimd_sim.errors import ConfigError
    from rimd_sim.ros.bringup.plan import plan_replay
    from rimd_sim.ros.bringup.processes import Rig

    if args.port is not None and not args.foxglove:
        raise CommandError("--port is for --foxglove (the Foxglove server's port)")
    if args.foxglove:   # the extra foxglove: refused before anything starts, naming it
        from rimd_sim.viz.foxglove_sink import require_sdk

        require_sdk("or replay without --foxglove")
    values = {"rate": args.rate, "start_offset": args.start, "playback_duration": args.duration, "loop": args.loop,
              "clock": args.clock}
    if args.topics:
        values["topics"] = args.topics
    if args.paused:
        values["start_paused"] = True
    try:
        plan = plan_replay(args.recording, parameters=values, foxglove=args.foxglove,
                           port=None if args.port is None else int(args.port))
    except ConfigError as exc:   # --topics (the numbers are checked by now): the rule said of the option as typed
        if exc.key != "topics":
            raise
        raise CommandError(f"--topics {' '.join(args.topics)} refused: {exc.rule}") from None

    def announce() -> None:
        if plan.foxglove_address:
            print(f"rimd replay: Foxglove: open {plan.foxglove_address} in Foxglove (Open connection > Foxglove "
                  "WebSocket); the replay is paused: press play on the timeline. Ctrl-C stops.", flush=True)
        else:
            print(f"rimd replay: replaying {args.recording} on its recorded topics"
                  + ("" if args.loop else " until its end") + "; Ctrl-C stops.", flush=True)

    # the replay ending by itself is the normal end
    status = Rig(plan).run("replay", announce, ends_itself="rimd_replay")
    print("rimd replay: stopped", flush=True)
    return status
