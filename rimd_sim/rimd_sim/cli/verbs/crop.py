"""``rimd crop``: a time window of a recording as a new rosbag2 MCAP recording, as ``ros2 bag convert`` would."""

from __future__ import annotations

import argparse
from pathlib import Path

from rimd_sim.cli import nonnegative_float


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd crop``."""
    parser.add_argument("recording", type=Path,
                        help="ROS 2 MCAP recording: one .mcap file or a recording directory of rimd_recorder")
    parser.add_argument("--start", type=nonnegative_float("--start", "s"), default=0.0, metavar="S",
                        help="s from the recording's first message where the window starts (default 0)")
    parser.add_argument("--end", type=nonnegative_float("--end", "s"), default=None, metavar="E",
                        help="s from the recording's first message where the window ends, included "
                             "(default: the last message)")
    parser.add_argument("--topics", nargs="+", default=None, metavar="TOPIC",
                        help="topics to keep, exact names (default: every topic)")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR",
                        help="new recording directory (must not exist, or be empty)")
    parser.add_argument("--compression", choices=("zstd", "lz4", "none"), default="zstd",
                        help="chunk compression of the new files (default zstd)")


def main(args: argparse.Namespace) -> int:
    """Crop and print what was written."""
    from rimd_sim.io.crop import crop

    result = crop(args.recording, args.out, start=args.start, end=args.end, topics=args.topics,
                  compression=args.compression)
    for note in result.notes:
        print(f"rimd crop: source {note}")
    window = f"{(result.end_ns - result.start_ns) / 1e9:.6g} s"
    print(f"rimd crop: {result.message_count} messages of {len(result.topic_counts)} topics "
          f"({args.start:g} s to {args.end if args.end is not None else result.source_duration:g} s of "
          f"{args.recording}, {window}) into {result.output_dir}: "
          + ", ".join(p.name for p in result.files))
    for topic, count in sorted(result.topic_counts.items()):
        print(f"  {topic}: {count}")
    return 0
