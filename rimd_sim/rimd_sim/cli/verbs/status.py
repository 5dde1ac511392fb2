"""``rimd status``: a live one-screen view of the running rig; ``--once`` for scripts.

The library: rimd_sim.ros.clients.status.
"""

from __future__ import annotations

import argparse
import json
import sys

from rimd_sim.cli import CommandError, number


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd status``."""
    parser.add_argument("--once", action="store_true", help="listen for --window s, print once and exit")
    parser.add_argument("--json", action="store_true", help="print the status as JSON (one object per refresh)")
    parser.add_argument("--window", type=number("--window", "s", gt=0, le=60), default=2.0,
                        help="seconds of listening before the first print (rates are counted over it; default 2)")
    parser.add_argument("--period", type=number("--period", "s", ge=0.1, le=60), default=1.0,
                        help="seconds between refreshes of the live view (default 1)")
    parser.add_argument("--timeout", type=number("--timeout", "s", gt=0, le=600), default=10.0,
                        help="seconds to wait for the rig to be heard at all (default 10)")


def main(args: argparse.Namespace) -> int:
    """Listen, print; exit 1 when no rig was heard (with --once)."""
    import os

    from rimd_sim.ros.clients.rig import RigClient
    from rimd_sim.ros.clients.status import RigMonitor, render

    with RigClient(name="rimd_status") as client:
        monitor = RigMonitor(client.node)
        heard = client.spin_until(lambda: monitor.heard, args.timeout)   # discovery, then the first messages
        if not heard and args.once:
            raise CommandError(f"no rig heard on ROS_DOMAIN_ID {os.environ.get('ROS_DOMAIN_ID', '0')} in "
                               f"{args.timeout:g} s (start it with `rimd rig`)")
        client.spin_until(lambda: False, args.window)
        live = not args.once and sys.stdout.isatty() and not args.json
        while True:
            snap = monitor.snapshot()
            if args.json:
                print(json.dumps(snap), flush=True)
            else:
                print(("\x1b[H\x1b[2J" if live else "") + render(snap), flush=True)
            if args.once:
                return 0
            client.spin_until(lambda: False, args.period)
