"""``rimd faults SCENARIO.yaml``: run a fault scenario against a running rig (docs/faults.md).

The scenario file holds a ``faults:`` list; each entry has ``channel``, ``kind``, and either ``start``
(simulation time in s; 0 = the next block boundary) or ``after`` (seconds from when the rig takes the request:
for a rig that has been up a while), ``duration`` (s; 0 = until cleared) and ``magnitude``::

    faults:
      - {channel: impact_force, kind: dropout, after: 2.0, duration: 0.5}
      - {channel: rimd_acceleration, kind: clock_drift, start: 0, magnitude: 80}

Every entry is checked before the first request is sent (a YAML error names the line and the column); then
each is sent to ``/rig/inject_fault`` in order and the rig's answer printed. A refusal stops the verb (exit
status 1) naming the entry; the faults scheduled before it stay scheduled (``--clear`` first clears every
fault of the rig).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rimd_sim.cli import CommandError, positive_float


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``rimd faults``."""
    parser.add_argument("scenario", type=Path, help="YAML file with a 'faults:' list")
    parser.add_argument("--namespace", default="/rig", help="namespace of the rig's services (default /rig)")
    parser.add_argument("--clear", action="store_true", help="call clear_faults before sending the scenario")
    parser.add_argument("--timeout", type=positive_float("--timeout", "s"), default=30.0,
                        help="s to wait for the rig's services")


def load_scenario(path: Path) -> list[dict]:
    """The checked entries of a scenario file.

    Raises:
        CommandError: A malformed entry (naming the file, the entry and the field).
        InputError: A missing file or bad YAML (file, line and column).
    """
    from rimd_sim.instruments.faults import parse_fault_entry
    from rimd_sim.settings.yaml_file import read_yaml

    doc = read_yaml(path, what="fault scenario")
    if not isinstance(doc, dict) or not isinstance(doc.get("faults"), list):
        raise CommandError(f"{path}: 'faults' refused: the file must hold a 'faults:' list")
    entries = [parse_fault_entry(e, f"{path}: faults[{i}]") for i, e in enumerate(doc["faults"])]
    for i, e in enumerate(entries):
        for key in ("start", "after", "duration", "magnitude"):
            if isinstance(e[key], bool) or not isinstance(e[key], (int, float)):
                raise CommandError(f"{path}: faults[{i}].{key} = {e[key]!r} refused: must be a number")
        for key in ("channel", "kind"):
            if not isinstance(e[key], str):
                raise CommandError(f"{path}: faults[{i}].{key} = {e[key]!r} refused: must be a string")
    return entries


def main(args: argparse.Namespace) -> int:
    """Send the scenario to the rig."""
    from rimd_sim.ros.clients.rig import RigClient

    entries = load_scenario(args.scenario)
    with RigClient(namespace=args.namespace, timeout=args.timeout, name="rimd_faults") as rig:
        if args.clear:
            print(rig.trigger("clear_faults").message, flush=True)
        for i, e in enumerate(entries):
            response = rig.inject(e["channel"], e["kind"], start=e["start"], after=e["after"],
                                  duration=e["duration"], magnitude=e["magnitude"])
            if not response.success:
                raise CommandError(f"faults[{i}] refused by the rig ({i} scheduled before it): {response.message}")
            print(f"faults[{i}]: {response.message}", flush=True)
    print(f"{len(entries)} fault(s) scheduled; their starts and ends are published on "
          f"{args.namespace.rstrip('/')}/faults", flush=True)
    return 0
