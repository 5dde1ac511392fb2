"""``rimd rig``: bring up the rig from a configuration file, like a launch file.

The rig is the simulator, the recorder and the Rerun bridge (each when its config section has
``enabled: true``), each a separate process started with ``--ros-args --params-file CONFIG``. Consumers start
first; the simulator starts paused and is resumed once every rig topic has all its consumers, so the
recording holds every sample from sample 0. Ctrl-C (or ``--duration``) stops the nodes in reverse order
(simulator first, recorder last, so the recording gets everything), each with SIGINT, then SIGTERM, then
SIGKILL after bounded waits.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from rimd_sim.cli import CommandError
from rimd_sim.core import ConfigError, load_config
from rimd_sim.core.config import find_config_file, misapplied_section, misapplied_section_message, read_ros_parameters


@dataclass(frozen=True)
class RigNode:
    """A node of the rig: its name (= config section), entry (``rimd_sim.nodes._entry``), whether it consumes."""

    name: str
    entry: str
    consumer: bool
    namespace: str = "/"

    @property
    def fqn(self) -> str:
        """The node's fully qualified name, which a section of the parameter file must match (or a wildcard)."""
        return self.namespace.rstrip("/") + "/" + self.name


#: The nodes in start order (stopped in reverse). Consumers start before the simulator.
#: The Rerun bridge is not waited for: it reads motor phase and frequency from /rig/truth and does not
#: subscribe to every rig topic; it may miss the first blocks (it reports gaps).
RIG_NODES = (
    RigNode("rimd_recorder", "recorder", consumer=True),
    RigNode("rimd_rerun", "rerun", consumer=False, namespace="/rig"),
    RigNode("rimd_simulator", "simulator", consumer=False, namespace="/rig"),
)

#: Topics every consumer subscribes to before the simulator is resumed.
RIG_TOPICS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force",
              "/rig/impact/events", "/rig/motor/state", "/rig/truth")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd rig``."""
    parser.add_argument("--config", type=Path, default=None,
                        help="ROS parameter YAML of the rig (default: config/rimd.yaml)")
    parser.add_argument("--duration", type=float, default=0.0,
                        help="stop after this many seconds of wall time (default: run until Ctrl-C)")
    parser.add_argument("--output-dir", type=Path, default=None,
                        help="record into this directory (default: the recorder's output_dir in the config)")
    parser.add_argument("--no-record", action="store_true", help="do not start the recorder")
    parser.add_argument("--no-rerun", action="store_true", help="do not start the Rerun bridge")
    parser.add_argument("--foxglove", action="store_true",
                        help="serve the rig to Foxglove (ws://127.0.0.1:8765 by default; the bridge's foxglove.* "
                             "parameters); with --no-rerun the bridge serves Foxglove only")


def _stop(proc: subprocess.Popen, name: str) -> int | None:
    for sig, wait in ((signal.SIGINT, 10.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait)
        except subprocess.TimeoutExpired:
            print(f"rimd rig: {name} did not stop on {signal.Signals(sig).name}", file=sys.stderr)
    return proc.returncode


def _section(config_path: Path, name: str) -> dict | None:
    try:
        return read_ros_parameters(config_path, node=name)
    except ConfigError:
        return None


def _plan(args: argparse.Namespace, config_path: Path) -> list[tuple[RigNode, list[str]]]:
    """The nodes to start with their extra ROS arguments; raises ConfigError for a bad recorder section."""
    plan = []
    import yaml

    doc = yaml.safe_load(config_path.read_text())
    for node in RIG_NODES:
        extra: list[str] = []
        key = misapplied_section(doc, node.name, node.fqn)
        if key is not None:
            raise CommandError(misapplied_section_message(config_path, key, node.name, node.fqn))
        if node.name == "rimd_recorder":
            section = _section(config_path, node.name)
            if args.no_record or section is None or not section.get("enabled", True):
                continue
            from rimd_sim.recording.settings import RecorderConfigError, check_recorder_parameters

            if args.output_dir is not None:
                section["output_dir"] = str(args.output_dir)
            try:
                check_recorder_parameters(section)
            except RecorderConfigError as exc:
                raise CommandError(f"{config_path}, section rimd_recorder: {exc}") from None
            output_dir = Path(section.get("output_dir", "recordings")).expanduser().resolve()
            extra = ["-p", f"output_dir:={output_dir}"]
        elif node.name == "rimd_rerun":
            section = _section(config_path, node.name) or {}
            rerun = not args.no_rerun and bool(section.get("enabled", False))
            foxglove = _foxglove_address(args, section, config_path)
            if not rerun and foxglove is None:
                continue
            if rerun:
                from rimd_sim.viz.sinks import SinkError, spec_from_parameters

                try:
                    spec_from_parameters(section).validate()
                except SinkError as exc:
                    raise CommandError(f"{config_path}, section rimd_rerun: {exc}") from None
            if foxglove is not None:
                extra = ["-p", "foxglove.enabled:=true", *([] if rerun else ["-p", "rerun:=false"])]
        plan.append((node, extra))
    return plan


def _foxglove_address(args: argparse.Namespace, section: dict, config_path: Path) -> str | None:
    """The ws:// address the bridge will serve Foxglove on (``--foxglove`` or ``foxglove.enabled``), or None."""
    if not (args.foxglove or bool(section.get("foxglove.enabled", False))):
        return None
    from rimd_sim.viz.foxglove_sink import DEFAULT_HOST, DEFAULT_PORT, FoxgloveError, check_address, websocket_url

    host = section.get("foxglove.host", DEFAULT_HOST)
    port = section.get("foxglove.port", DEFAULT_PORT)
    try:
        check_address(host, port)
    except FoxgloveError as exc:
        raise ConfigError("rimd_rerun", str(config_path), str(exc)) from None
    return websocket_url(host, port) if port else "the ws:// address the bridge logs (foxglove.port 0: a free port)"


def _subscribed(node, topic: str, consumers: tuple[str, ...]) -> bool:  # noqa: ANN001
    names = {info.node_name for info in node.get_subscriptions_info_by_topic(topic)}
    return all(name in names for name in consumers)


def _resume_when_connected(consumers: tuple[str, ...], procs, timeout: float = 20.0) -> bool:  # noqa: ANN001
    """Wait until each consumer node subscribes to every rig topic, then call /rig/resume. True when resumed."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    from std_srvs.srv import Trigger

    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node("rimd_rig", context=context, start_parameter_services=False)
        deadline = time.monotonic() + timeout
        client = node.create_client(Trigger, "/rig/resume")
        while time.monotonic() < deadline and all(p.poll() is None for _, p in procs):
            if all(_subscribed(node, t, consumers) for t in RIG_TOPICS) and client.service_is_ready():
                future = client.call_async(Trigger.Request())
                executor = rclpy.executors.SingleThreadedExecutor(context=context)
                executor.add_node(node)
                executor.spin_until_future_complete(future, timeout_sec=5.0)
                return bool(future.done() and future.result().success)
            time.sleep(0.05)
        return False
    finally:
        context.try_shutdown()


def main(args: argparse.Namespace) -> int:
    """Start the rig's nodes and wait; return non-zero if a node failed."""
    try:
        config_path = args.config if args.config is not None else find_config_file("rimd.yaml")
        config = load_config(config_path)  # refuse a bad file before starting anything
        plan = _plan(args, Path(config_path))
    except ConfigError as exc:
        print(f"rimd rig: {exc}", file=sys.stderr)
        return 1
    consumers = tuple(node.name for node, _ in plan if node.consumer)
    procs: list[tuple[str, subprocess.Popen]] = []
    stopping = False

    def on_signal(signum, frame):  # noqa: ARG001
        nonlocal stopping
        stopping = True

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    status = 0
    recording_dir = None
    try:
        for node, extra in plan:
            cmd = [sys.executable, "-m", "rimd_sim.nodes._entry", node.entry,
                   "--ros-args", "--params-file", str(config_path), *extra]
            if node.name == "rimd_simulator" and consumers:
                cmd += ["-p", "start_paused:=true"]
            if node.name == "rimd_recorder":
                recording_dir = extra[-1].split(":=", 1)[1]
            procs.append((node.name, subprocess.Popen(cmd, start_new_session=True)))
        for node, extra in plan:
            if "foxglove.enabled:=true" in extra:
                address = _foxglove_address(argparse.Namespace(foxglove=True), _section(Path(config_path), node.name)
                                            or {}, Path(config_path))
                print(f"rimd rig: Foxglove: open {address} in Foxglove (Open connection > Foxglove WebSocket; "
                      "layout: config/foxglove/rig_layout.json)", flush=True)
        print(f"rimd rig: running {', '.join(n for n, _ in procs)} with {config_path} "
              f"(gap {config.rig.gap * 1e3:g} mm, motor setpoint {config.motor.initial_setpoint:g} Hz, "
              f"ROS_DOMAIN_ID {os.environ.get('ROS_DOMAIN_ID', '0')}); topics under /rig. "
              + (f"Recording into {recording_dir}. " if recording_dir else "Not recording. ")
              + "Ctrl-C stops.", flush=True)
        if consumers:
            if _resume_when_connected(consumers, procs):
                print("rimd rig: every consumer is connected; the rig runs from sample 0", flush=True)
            elif all(p.poll() is None for _, p in procs):
                print("rimd rig: the consumers did not all connect within 20 s; resuming the rig anyway",
                      file=sys.stderr, flush=True)
                _resume_when_connected((), procs, timeout=10.0)
        deadline = time.monotonic() + args.duration if args.duration > 0 else None
        while not stopping and (deadline is None or time.monotonic() < deadline):
            for name, proc in procs:
                if proc.poll() is not None:
                    print(f"rimd rig: {name} exited with status {proc.returncode}", file=sys.stderr)
                    stopping = True
                    status = 1
            time.sleep(0.1)
    finally:
        for name, proc in reversed(procs):
            code = _stop(proc, name)
            if code not in (0, None) and status == 0 and code != -signal.SIGINT:
                status = 1
        for s, handler in previous.items():
            signal.signal(s, handler)
    if recording_dir:
        print(f"rimd rig: stopped; the recording is in {recording_dir} "
              f"(replay: rimd node replay --ros-args -p file:={recording_dir})", flush=True)
    else:
        print("rimd rig: stopped", flush=True)
    return status
