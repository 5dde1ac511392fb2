"""``rimd perturb V``: add a velocity to the hammer of the running rig (``/rig/perturb``) and print its answer."""

from __future__ import annotations

import argparse

from rimd_sim.cli import nonnegative_float, number
from rimd_sim.verbs._oneshot import add_timeout, answer


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd perturb``."""
    parser.add_argument("velocity", type=number("V", "m/s", ge=-10, le=10), metavar="V",
                        help="velocity added to the hammer (m/s, within +-10; the paper's energy inserted)")
    parser.add_argument("--at", type=nonnegative_float("--at", "s"), default=None, metavar="STAMP",
                        help="when: a stamp in the rig's time base (s; default: the next block boundary)")
    add_timeout(parser)


def main(args: argparse.Namespace) -> int:
    """Send the kick; print the rig's answer."""
    from rimd_sim.rigclient import RigClient

    with RigClient(timeout=args.timeout) as rig:
        return answer(rig.perturb(args.velocity, args.at), f"perturbation {args.velocity:+g} m/s")
