"""``rimd motor FREQ``: set the running rig's motor frequency (``/rig/set_motor_frequency``) and print its answer."""

from __future__ import annotations

import argparse

from rimd_sim.cli import nonnegative_float, number
from rimd_sim.cli.verbs._oneshot import add_timeout, call


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd motor``."""
    parser.add_argument("frequency", type=nonnegative_float("FREQ", "Hz"), metavar="FREQ",
                        help="the new setpoint (Hz, at most the rig's motor.max_frequency)")
    parser.add_argument("--ramp", type=number("--ramp", "Hz/s", ge=0, le=1e4), default=0.0,
                        help="ramp rate to it (Hz/s; 0 = the rig's motor.ramp_rate)")
    add_timeout(parser, at=True)


def main(args: argparse.Namespace) -> int:
    """Send the setpoint; print the rig's answer."""
    return call(args, lambda rig: rig.motor(args.frequency, args.ramp, args.at), f"setpoint {args.frequency:g} Hz")
