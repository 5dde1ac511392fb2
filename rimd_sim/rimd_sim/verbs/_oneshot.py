"""What the one-shot verbs share: the timeout option and the rig's answer printed, refusals as errors."""

from __future__ import annotations

import argparse
from typing import Any

from rimd_sim.cli import CommandError, positive_float


def add_timeout(parser: argparse.ArgumentParser) -> None:
    """The ``--timeout`` option."""
    parser.add_argument("--timeout", type=positive_float("--timeout", "s"), default=10.0,
                        help="seconds to wait for the rig and its answer (default 10)")


def answer(response: Any, what: str) -> int:
    """Print the rig's answer; a refusal raises (exit 1) with the rig's own words."""
    if not response.success:
        raise CommandError(f"{what} refused by the rig: {response.message}")
    print(response.message)
    return 0
