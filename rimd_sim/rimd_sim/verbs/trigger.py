"""``rimd pause``, ``rimd resume``, ``rimd reset``, ``rimd clear-faults``: the rig's Trigger services in one line."""

from __future__ import annotations

import argparse

from rimd_sim.verbs._oneshot import add_timeout, answer


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of the trigger verbs."""
    add_timeout(parser)


def main(args: argparse.Namespace) -> int:
    """Call ``/rig/<verb>``; print the rig's answer (a refusal, such as resuming a running rig, exits 1)."""
    from rimd_sim.rigclient import RigClient

    service = args.verb.replace("-", "_")
    with RigClient(timeout=args.timeout) as rig:
        return answer(rig.trigger(service), service.replace("_", " "))
