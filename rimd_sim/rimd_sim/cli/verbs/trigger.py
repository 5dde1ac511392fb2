"""``rimd pause``, ``rimd resume``, ``rimd reset``, ``rimd clear-faults``: the rig's Trigger services in one line."""

from __future__ import annotations

import argparse

from rimd_sim.cli.verbs._oneshot import add_timeout, call


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of the trigger verbs."""
    add_timeout(parser)


def main(args: argparse.Namespace) -> int:
    """Call ``/rig/<verb>``; print the rig's answer (a refusal, such as resuming a running rig, exits 1)."""
    service = args.verb.replace("-", "_")
    return call(args, lambda rig: rig.trigger(service), service.replace("_", " "))
