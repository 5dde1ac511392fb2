"""``rimd faults SCENARIO.yaml``: run a fault scenario against a running rig (docs/faults.md).

The scenario file holds a ``faults:`` list; each entry has ``channel``, ``kind``, ``start`` (simulation
time in s; 0 = the next block boundary), ``duration`` (s; 0 = until cleared) and ``magnitude``::

    faults:
      - {channel: impact_force, kind: dropout, start: 12.0, duration: 0.5}
      - {channel: rimd_acceleration, kind: clock_drift, start: 0, magnitude: 80}

Every entry is checked before the first request is sent; then each is sent to ``/rig/inject_fault`` in
order and the rig's answer printed. A refusal stops the verb (exit status 1) naming the entry; the faults
scheduled before it stay scheduled (``--clear`` first clears every fault of the rig).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rimd_sim.cli import CommandError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``rimd faults``."""
    parser.add_argument("scenario", type=Path, help="YAML file with a 'faults:' list")
    parser.add_argument("--namespace", default="/rig", help="namespace of the rig's services (default /rig)")
    parser.add_argument("--clear", action="store_true", help="call clear_faults before sending the scenario")
    parser.add_argument("--timeout", type=float, default=30.0, help="s to wait for the rig's services")


def load_scenario(path: Path) -> list[dict]:
    """The checked entries of a scenario file.

    Raises:
        CommandError: A missing or malformed file, or an entry that names no channel/kind/start or has an
            unknown field (one line, naming the entry and the field).
    """
    import yaml

    from rimd_sim.core.errors import CommandError as CoreCommandError
    from rimd_sim.core.faults import parse_fault_entry

    try:
        doc = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise CommandError(f"cannot read {path}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise CommandError(f"{path} is not valid YAML: {str(exc).splitlines()[0]}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("faults"), list):
        raise CommandError(f"{path}: 'faults' refused: the file must hold a 'faults:' list")
    try:
        entries = [parse_fault_entry(e, f"faults[{i}]") for i, e in enumerate(doc["faults"])]
    except CoreCommandError as exc:
        raise CommandError(f"{path}: {exc}") from None
    for i, e in enumerate(entries):
        for key in ("start", "duration", "magnitude"):
            if isinstance(e[key], bool) or not isinstance(e[key], (int, float)):
                raise CommandError(f"{path}: faults[{i}].{key} = {e[key]!r} refused: must be a number")
        for key in ("channel", "kind"):
            if not isinstance(e[key], str):
                raise CommandError(f"{path}: faults[{i}].{key} = {e[key]!r} refused: must be a string")
    return entries


def main(args: argparse.Namespace) -> int:
    """Send the scenario to the rig."""
    entries = load_scenario(args.scenario)
    import time

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger

    from rimd_msgs.srv import InjectFault

    ns = args.namespace.rstrip("/")
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("rimd_faults", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        inject = node.create_client(InjectFault, f"{ns}/inject_fault")
        if not inject.wait_for_service(timeout_sec=args.timeout):
            raise CommandError(f"no rig: service {ns}/inject_fault not available after {args.timeout:g} s")

        def call(client, request):  # noqa: ANN001, ANN202
            future = client.call_async(request)
            deadline = time.monotonic() + args.timeout
            while not future.done() and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            if not future.done():
                raise CommandError(f"{client.srv_name} did not answer within {args.timeout:g} s")
            return future.result()

        if args.clear:
            clear = node.create_client(Trigger, f"{ns}/clear_faults")
            if not clear.wait_for_service(timeout_sec=args.timeout):
                raise CommandError(f"no rig: service {ns}/clear_faults not available after {args.timeout:g} s")
            print(call(clear, Trigger.Request()).message, flush=True)
        for i, e in enumerate(entries):
            response = call(inject, InjectFault.Request(
                channel=e["channel"], kind=e["kind"], start=float(e["start"]), duration=float(e["duration"]),
                magnitude=float(e["magnitude"])))
            if not response.success:
                raise CommandError(f"faults[{i}] refused by the rig ({i} scheduled before it): {response.message}")
            print(f"faults[{i}]: {response.message}", flush=True)
        print(f"{len(entries)} fault(s) scheduled; their starts and ends are published on {ns}/faults", flush=True)
        return 0
    finally:
        context.try_shutdown()
