"""``rimd rerun REC [--save OUT.rrd | --connect URL]``: the live bridge's view of a recording, without ROS.

``REC`` is an ``.mcap`` file or a recording directory (all its ``.mcap`` files, in order).

Reads the rig topics of a ROS 2 MCAP recording and logs them through the same mapping as the ``rimd_rerun``
node (:mod:`rimd_sim.viz.rerun_map`), to a spawned viewer (default), a viewer at a URL, or an ``.rrd`` file.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rimd_sim.cli import CommandError, positive_float


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``rimd rerun``."""
    parser.add_argument("recording", type=Path,
                        help="ROS 2 MCAP recording: one .mcap file or a recording directory of rimd_recorder")
    target = parser.add_mutually_exclusive_group()
    target.add_argument("--save", type=Path, default=None, metavar="OUT.rrd",
                        help="write an .rrd file instead of opening a viewer")
    target.add_argument("--connect", default=None, metavar="URL",
                        help="send to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy")
    parser.add_argument("--namespace", default="/rig", help="namespace of the rig topics (default /rig)")
    parser.add_argument("--natural-frequency", type=positive_float("--natural-frequency", "Hz"), default=1.82,
                        help="Hz, scales the phase plane's velocity axis (default 1.82)")
    parser.add_argument("--analytics", action="store_true",
                        help="let Rerun report usage per your Rerun configuration (default: off)")


def convert(recording: Path, spec, *, namespace: str = "/rig", natural_frequency: float = 1.82):
    """Log ``recording`` to the sink ``spec``; return (mapper stats, recording info, wall seconds).

    Raises:
        McapError: Unreadable recording.
        SinkError: The sink cannot be opened.
        CommandError: The sink reported a problem when closed.
    """
    from rimd_sim.viz.mcap_source import RecordingInfo, read_rig_messages
    from rimd_sim.viz.rerun_map import RigMapper, blueprint
    from rimd_sim.viz.sinks import RerunStream

    info = RecordingInfo({}, {})
    messages = read_rig_messages(recording, namespace=namespace, info=info)
    start = time.perf_counter()
    first = next(messages, None)  # opens and checks the file before any sink is opened
    with RerunStream(spec, blueprint(), recording_name=recording.name) as stream:
        mapper = RigMapper(stream.rec, natural_frequency=natural_frequency, batch=50)
        mapper.log_static()
        if first is not None:
            mapper.log_message(*first)
        for topic, msg in messages:
            mapper.log_message(topic, msg)
        mapper.flush()
        problem = stream.close()
    if problem:
        raise CommandError(problem)
    return mapper.stats, info, time.perf_counter() - start


def main(args: argparse.Namespace) -> int:
    """Convert or show the recording; print a one-line summary."""
    from rimd_sim.viz.sinks import SinkSpec, require_rerun

    require_rerun("the Rerun view of a recording", "")

    if args.save is not None:
        spec = SinkSpec("save", path=str(args.save), analytics=args.analytics)
    elif args.connect is not None:
        spec = SinkSpec("connect", url=args.connect, analytics=args.analytics)
    else:
        spec = SinkSpec("spawn", analytics=args.analytics)
    stats, info, wall = convert(args.recording, spec, namespace=args.namespace,
                                natural_frequency=args.natural_frequency)
    samples = sum(stats.samples.values())
    per_channel = ", ".join(f"{name} {count}" for name, count in sorted(stats.samples.items()))
    gaps = sum(stats.gaps.values())
    print(f"rimd rerun: {args.recording} -> {spec.path or spec.url if spec.kind != 'spawn' else 'viewer'}: "
          f"{samples} samples ({per_channel}), {stats.impacts} impacts, {stats.poincare_points} Poincare points, "
          f"{gaps} gaps, in {wall:.2f} s ({samples / wall if wall > 0 else 0:.0f} samples/s)")
    # A damaged recording is converted as far as it is readable: say what was lost and what was left out.
    for line in info.damaged:
        print(f"rimd rerun: damaged: {line}", file=sys.stderr)
    for line in info.problems:
        print(f"rimd rerun: warning: {line}", file=sys.stderr)
    if not stats.samples:
        print("rimd rerun: warning: the recording has no sample block on the rig channels", file=sys.stderr)
    return 0
