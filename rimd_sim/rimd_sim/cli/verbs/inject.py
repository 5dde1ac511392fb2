"""``rimd inject CHANNEL KIND``: inject a fault into the running rig (``/rig/inject_fault``); print its answer."""

from __future__ import annotations

import argparse

from rimd_sim.cli import nonnegative_float, number
from rimd_sim.cli.verbs._oneshot import add_timeout, call


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd inject``."""
    from rimd_sim.instruments.faults import FAULT_KINDS
    from rimd_sim.settings.config import CHANNEL_NAMES

    parser.add_argument("channel", choices=[*CHANNEL_NAMES, "motor"], help="the channel (motor: motor_slip)")
    parser.add_argument("kind", choices=list(FAULT_KINDS), help="the fault (docs/faults.md)")
    when = parser.add_mutually_exclusive_group()
    when.add_argument("--after", type=nonnegative_float("--after", "s"), default=0.0,
                      help="start this many seconds of simulation time after the rig takes the request "
                           "(default 0: the next block boundary)")
    when.add_argument("--start", type=nonnegative_float("--start", "s"), default=0.0,
                      help="start at this simulation time (s)")
    parser.add_argument("--duration", type=nonnegative_float("--duration", "s"), default=0.0,
                        help="length (s; default 0: until `rimd clear-faults`)")
    parser.add_argument("--magnitude", type=number("--magnitude"), default=0.0,
                        help="magnitude where the kind has one (docs/faults.md)")
    add_timeout(parser)


def main(args: argparse.Namespace) -> int:
    """Send the fault; print the rig's answer."""
    return call(args, lambda rig: rig.inject(args.channel, args.kind, start=args.start, after=args.after,
                                             duration=args.duration, magnitude=args.magnitude),
                f"{args.kind} on {args.channel}")
