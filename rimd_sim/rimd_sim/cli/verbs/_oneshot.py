"""What the one-shot verbs share: the timeout option and the rig's answer printed, refusals as errors."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

from rimd_sim.cli import CommandError, nonnegative_float, positive_float


def add_timeout(parser: argparse.ArgumentParser, *, at: bool = False) -> None:
    """The ``--timeout`` option; with ``at``, the ``--at STAMP`` of a command that takes a stamp."""
    if at:
        parser.add_argument("--at", type=nonnegative_float("--at", "s"), default=None, metavar="STAMP",
                            help="when: a stamp in the rig's time base (s; default: the next block boundary)")
    parser.add_argument("--timeout", type=positive_float("--timeout", "s"), default=10.0,
                        help="seconds to wait for the rig and its answer (default 10)")


def call(args: argparse.Namespace, request: Callable[[Any], Any], what: str) -> int:
    """Send ``request(rig)`` to the rig on this domain and print its answer (see :func:`answer`)."""
    from rimd_sim.ros.clients.rig import RigClient

    with RigClient(timeout=args.timeout) as rig:
        return answer(request(rig), what)


def answer(response: Any, what: str) -> int:
    """Print the rig's answer; a refusal raises (exit 1) with the rig's own words."""
    if not response.success:
        raise CommandError(f"{what} refused by the rig: {response.message}")
    print(response.message)
    return 0
