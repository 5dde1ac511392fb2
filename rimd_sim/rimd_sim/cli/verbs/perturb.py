"""``rimd perturb V``: add a velocity to the hammer of the running rig (``/rig/perturb``) and print its answer."""

from __future__ import annotations

import argparse

from rimd_sim.cli import number
from rimd_sim.cli.verbs._oneshot import add_timeout, call


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd perturb``."""
    parser.add_argument("velocity", type=number("V", "m/s", ge=-10, le=10), metavar="V",
                        help="velocity added to the hammer (m/s, within +-10; the paper's energy inserted)")
    add_timeout(parser, at=True)


def main(args: argparse.Namespace) -> int:
    """Send the kick; print the rig's answer."""
    return call(args, lambda rig: rig.perturb(args.velocity, args.at), f"perturbation {args.velocity:+g} m/s")
