"""Bringing up the rig from a configuration, like a launch file: behind ``rimd rig``, ``rimd replay``, the plugin.

:func:`plan_rig` reads and checks a configuration and decides what to start: the recorder, the Rerun bridge
(Rerun and/or Foxglove) and the simulator, each a separate process run with ``--ros-args --params-file
CONFIG`` (and an overrides file when parameters are given). Nothing starts when the configuration is refused.
:class:`Rig` starts the plan's processes (consumers first, the simulator last), makes sure the consumers see
sample 0, watches them, and stops them in reverse order (simulator first, recorder last, so the recording gets
everything), each with SIGINT, then SIGTERM, then SIGKILL after bounded waits.

Two ways to make the consumers see sample 0:

* open loop (default): the simulator starts paused and is resumed once every consumer subscribes to every rig
  topic (and the simulator's first resume waits until DDS has matched them);
* lockstep (``lockstep=True``): the simulator waits for its consumers by itself (``lockstep.consumers``: the
  recorder and the bridge under their node names, plus the names given), and never runs ahead of the slowest
  (docs/rig.md, "Pacing: lockstep").

:func:`plan_replay` plans a replay of a recording the same way (``rimd replay``): the replay node and, to drive it
from Foxglove's timeline, the bridge serving Foxglove only, pointed at it (``foxglove.playback_node``).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import yaml

from rimd_sim.errors import CommandError, ConfigError, InputError
from rimd_sim.ros.nodes.registry import by_name, rig_nodes
from rimd_sim.settings.config import (
    SimConfig,
    check_simulator_section,
    find_config_file,
    misapplied_section,
    misapplied_section_message,
    read_ros_parameters,
)
from rimd_sim.settings.yaml_file import read_yaml, resolve_config

__all__ = ["PlannedNode", "Rig", "RigPlan", "StopSignals", "plan_replay", "plan_rig"]

#: Topics every open-loop consumer subscribes to before the simulator is resumed.
RIG_TOPICS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force",
              "/rig/impact/events", "/rig/motor/state", "/rig/truth")


@dataclass(frozen=True)
class PlannedNode:
    """One process of the rig: its node name (= config section), entry (``rimd_sim.ros.nodes._entry``) and arguments.

    ``consumer``: the open-loop bring-up waits for it to subscribe before resuming the simulator.
    """

    name: str
    entry: str
    args: tuple[str, ...]
    consumer: bool = False
    namespace: str = "/"

    @property
    def fqn(self) -> str:
        """The node's fully qualified name, which a section of the parameter file must match (or a wildcard)."""
        return self.namespace.rstrip("/") + "/" + self.name

    def command(self) -> list[str]:
        """The command line of the process."""
        return [sys.executable, "-m", "rimd_sim.ros.nodes._entry", self.entry, *self.args]


@dataclass(frozen=True)
class RigPlan:
    """What :class:`Rig` starts, decided from a configuration (see :func:`plan_rig`; a replay has none)."""

    config_path: Path | None
    config: SimConfig | None
    nodes: tuple[PlannedNode, ...]
    recording_dir: Path | None = None
    foxglove_address: str | None = None
    lockstep_consumers: tuple[str, ...] = ()
    lockstep_window: float = 0.0
    overrides_path: Path | None = None
    separate: bool = True

    @property
    def names(self) -> list[str]:
        """The node names, in start order."""
        return [node.name for node in self.nodes]

    @property
    def processes(self) -> tuple[PlannedNode, ...]:
        """The processes to start: one per node when separate, else the composed rig's one.

        Composed: the simulator with the recorder and the bridge in its process (:mod:`rimd_sim.ros.nodes.composed`).
        A simulator alone (no recorder, no bridge) runs as itself: there is nothing to compose.
        """
        if self.separate or len(self.nodes) < 2 or not any(n.name == "rimd_simulator" for n in self.nodes):
            return self.nodes
        return (composed_process(self.nodes),)

    def process_of(self, node: str) -> str:
        """The name of the process that runs ``node`` (its log is ``<process>.log``)."""
        names = [p.name for p in self.processes]
        return node if node in names or self.separate else names[0]


#: The composed rig's process name (its log: ``rimd_composed.log``).
COMPOSED = "rimd_composed"


def composed_process(nodes: Sequence[PlannedNode]) -> PlannedNode:
    """The composed rig running ``nodes`` (planned as separate processes): one process, the same parameters.

    Each node's ``-p NAME:=VALUE`` becomes ``--param NODE:NAME:=VALUE`` (a ``-p`` would set it on every node of
    the process); the parameter files are the simulator's (the same for every node). The simulator does not start
    paused: its consumers are fed in the process from sample 0.
    """
    from rimd_sim.ros.nodes.registry import by_name

    names = {n.name for n in nodes}
    args = ["--record", str("rimd_recorder" in names).lower(), "--bridge", str("rimd_rerun" in names).lower()]
    ros_args: list[str] = []
    for node in nodes:
        pairs = list(zip(node.args, node.args[1:], strict=False))
        if node.name == "rimd_simulator":
            ros_args = ["--ros-args", *(a for flag, value in pairs if flag == "--params-file"
                                        for a in (flag, value))]
        args += [a for flag, value in pairs if flag == "-p" and not (node.name == "rimd_simulator"
                                                                     and value == "start_paused:=true")
                 for a in ("--param", f"{node.name}:{value}")]
    entry = by_name("composed")
    return PlannedNode(COMPOSED, entry.name, (*args, *ros_args))


#: The rig's nodes in start order (stopped in reverse): (name, entry, consumer, namespace), from the registry.
_NODES = tuple((n.executable, n.name, n.consumer, n.namespace) for n in rig_nodes())


def _section(config_path: Path, doc: Any, name: str) -> dict | None:
    """The flat parameters of node ``name`` in the file (document ``doc``), or None when it has no section for it.

    Only a missing section means "none": a section that is not a mapping with ``ros__parameters`` is refused
    (it used to be taken for a missing one, and the node ran with its defaults).
    """
    if not isinstance(doc, Mapping) or all(doc.get(key) is None for key in ("/**", f"/**/{name}", name, f"/{name}")):
        return None
    try:
        return read_ros_parameters(config_path, node=name)
    except ConfigError as exc:
        raise InputError(f"{config_path}, section {name}: {exc}") from None


def plan_rig(config: str | Path | None = None, *, output_dir: str | Path | None = None, record: bool = True,
             rerun: bool = True, foxglove: bool = False, lockstep: bool = False, consumers: Sequence[str] = (),
             real_time_factor: float | None = None, parameters: Mapping[str, Mapping[str, Any]] | None = None,
             run_dir: str | Path | None = None, separate: bool = False) -> RigPlan:
    """Read and check the configuration; decide the processes and their arguments.

    Args:
        config: The rig's parameter file (default ``config/rimd.yaml``), found as :func:`resolve_config` does.
        output_dir: Where the recorder records (default: its ``output_dir`` in the file).
        record: Start the recorder (when its section has ``enabled: true``).
        rerun: Start the Rerun sink of the bridge (when its section has ``enabled: true``).
        foxglove: Serve Foxglove from the bridge (also when its section has ``foxglove.enabled: true``).
        lockstep: The simulator waits for its consumers: the recorder and the bridge, and ``consumers``.
        consumers: More lockstep consumers (the names your DAQ nodes report under).
        real_time_factor: Overrides the simulator's ``real_time_factor`` (in lockstep: its speed cap).
        parameters: More parameters per node name (``{"rimd_simulator": {"seed": 3}}``), written to an
            overrides file given after the configuration.
        run_dir: Where the overrides file goes (default: the recording directory, else the working directory).
        separate: Each node in a process of its own; by default the recorder and the bridge run in the simulator's
            process, fed without DDS (:attr:`RigPlan.processes`, docs/rig.md "The composed rig").

    Raises:
        ConfigError: The configuration (or an override) is refused; nothing was started. The message names
            the file, the section and the rule.
    """
    config_path = resolve_config(config) if config is not None else find_config_file("rimd.yaml")
    extra = {name: dict(values) for name, values in (parameters or {}).items()}
    sim = extra.setdefault("rimd_simulator", {})
    if real_time_factor is not None:
        sim["real_time_factor"] = float(real_time_factor)
    doc = read_yaml(config_path, what="config file")
    if doc is not None and not isinstance(doc, Mapping):   # an empty file is the defaults; a text or a list is not
        raise ConfigError("config file", str(config_path), "must be a mapping of node names to 'ros__parameters'")
    sections = {name: _section(config_path, doc, name) for name, *_ in _NODES}
    plan: list[PlannedNode] = []
    recording_dir = foxglove_address = None
    started_consumers: list[str] = []
    for name, entry, consumer, namespace in _NODES:
        key = misapplied_section(doc, name, namespace.rstrip("/") + "/" + name)
        if key is not None:
            raise InputError(misapplied_section_message(config_path, key, name, namespace.rstrip("/") + "/" + name))
        section = {**(sections[name] or {}), **extra.get(name, {})}
        args: list[str] = []
        if name == "rimd_recorder":
            if not record or sections[name] is None or not section.get("enabled", True):
                continue
            from rimd_sim.settings.recording import check_recorder_parameters

            if output_dir is not None:
                section["output_dir"] = str(output_dir)
            _checked(config_path, name, check_recorder_parameters, section)
            recording_dir = Path(section.get("output_dir", "recordings")).expanduser().resolve()
            args = ["-p", f"output_dir:={recording_dir}"]
        elif name == "rimd_rerun":
            with_rerun = rerun and sections[name] is not None and bool(section.get("enabled", False))
            with_foxglove = foxglove or bool(section.get("foxglove.enabled", False))
            if not with_rerun and not with_foxglove:
                continue
            foxglove_address = _bridge_checked(config_path, section, with_rerun, with_foxglove)
            if with_foxglove:
                args = ["-p", "foxglove.enabled:=true", *([] if with_rerun else ["-p", "rerun:=false"])]
        else:
            _checked(config_path, name, check_simulator_section, section)
        if lockstep and name != "rimd_simulator":
            started_consumers.append(name)
        plan.append(PlannedNode(name, entry, tuple(args), consumer, namespace))
    lockstep_consumers: tuple[str, ...] = ()
    if lockstep:
        lockstep_consumers = tuple(dict.fromkeys([*started_consumers, *consumers]))
        if not lockstep_consumers:
            raise InputError("lockstep without a consumer: nothing to wait for (record, bridge, or --consumer NAME)")
        sim.update({"lockstep.enabled": True, "lockstep.consumers": list(lockstep_consumers)})
    sim_config, sim_settings = _checked(config_path, "rimd_simulator", check_simulator_section,
                                        {**(sections["rimd_simulator"] or {}), **sim})
    from rimd_sim.instruments.faults import check_scenario

    try:
        check_scenario(sim_settings.faults, {c.name: c for c in sim_config.channels})
    except CommandError as exc:
        raise InputError(f"{config_path}, section rimd_simulator: {exc}") from None
    overrides_path = None
    if any(extra.values()):
        directory = Path(run_dir) if run_dir is not None else (recording_dir or Path.cwd())
        directory.mkdir(parents=True, exist_ok=True)
        overrides_path = directory / f".rimd_rig_overrides_{os.getpid()}.yaml"
        overrides_path.write_text(yaml.safe_dump({f"/**/{name}": {"ros__parameters": values}
                                                  for name, values in extra.items() if values}))
    nodes = []
    for node in plan:
        args = ["--ros-args", "--params-file", str(config_path)]
        if overrides_path is not None:
            args += ["--params-file", str(overrides_path)]
        args += list(node.args)
        if node.name == "rimd_simulator" and not lockstep and any(n.consumer for n in plan):
            args += ["-p", "start_paused:=true"]
        nodes.append(PlannedNode(node.name, node.entry, tuple(args), node.consumer, node.namespace))
    return RigPlan(config_path, sim_config, tuple(nodes), recording_dir, foxglove_address, lockstep_consumers,
                   sim_settings.lockstep.window, overrides_path, separate)


#: The replay's node name, as the bridge must name it (``foxglove.playback_node``).
REPLAY_NODE = "/rimd_replay"


def plan_replay(recording: str | Path, *, parameters: Mapping[str, Any] | None = None, foxglove: bool = False,
                host: str | None = None, port: int | None = None) -> RigPlan:
    """Plan a replay of ``recording``: the replay node, and with ``foxglove`` the bridge driving it from Foxglove.

    With ``foxglove`` the replay starts paused (Foxglove's timeline plays it) and stays up at the end
    (``keep_alive``), the bridge serves Foxglove only (``rerun: false``) on ``host:port`` (default
    ws://127.0.0.1:8765) with the replay's services and parameters.

    Args:
        recording: One .mcap file or a recording directory.
        parameters: More parameters of the replay (``{"rate": 2.0}``), checked against their declarations.
        foxglove: Add the bridge, pointed at the replay.
        host: Where the Foxglove server listens (an IP address; default 127.0.0.1).
        port: Its TCP port (default 8765; 0 = a free port, logged by the bridge).

    Raises:
        InputError: The recording is not there, or a parameter is refused (nothing was started).
    """
    from rimd_sim.io.reader import RecordingError, recording_files
    from rimd_sim.runtime.replay import ReplaySettings
    from rimd_sim.settings.params import build
    from rimd_sim.viz.foxglove_sink import DEFAULT_HOST, DEFAULT_PORT, FoxgloveError, check_address, websocket_url

    try:
        recording_files(recording)
    except RecordingError as exc:
        raise InputError(str(exc)) from None
    values = {"file": str(Path(recording).resolve()), **(parameters or {})}
    if foxglove:
        values = {"start_paused": True, "keep_alive": True, **values}
    build(ReplaySettings, values)   # ConfigError (an InputError's parent) names the parameter and its rule
    args = ["--ros-args", *(a for name, value in values.items() for a in ("-p", f"{name}:={_ros_value(value)}"))]
    replay, bridge = by_name("replay"), by_name("rerun")
    nodes = [PlannedNode(replay.executable, replay.name, tuple(args))]
    address = None
    if foxglove:
        host, port = host or DEFAULT_HOST, DEFAULT_PORT if port is None else port
        try:
            check_address(host, port)
        except FoxgloveError as exc:
            raise InputError(str(exc)) from None
        address = websocket_url(host, port) if port else "the ws:// address the bridge logs (port 0: a free port)"
        nodes.append(PlannedNode(bridge.executable, bridge.name, (
            "--ros-args", "-p", "rerun:=false", "-p", "foxglove.enabled:=true", "-p", f"foxglove.host:={host}",
            "-p", f"foxglove.port:={port}", "-p", f"foxglove.playback_node:={REPLAY_NODE}",
            "-p", f"foxglove.parameter_nodes:=['{REPLAY_NODE}']"), namespace=bridge.namespace))
    return RigPlan(None, None, tuple(nodes), foxglove_address=address)


def _ros_value(value: Any) -> str:
    """A value as ``-p name:=value`` takes it (YAML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(f"'{v}'" for v in value) + "]"
    return str(value)


def _checked(config_path: Path, name: str, check: Any, section: dict) -> Any:
    try:
        return check(section)
    except ConfigError as exc:
        raise InputError(f"{config_path}, section {name}: {exc}") from None


def _bridge_checked(config_path: Path, section: dict, rerun: bool, foxglove: bool) -> str | None:
    """Check the bridge's section; the ws:// address it will serve Foxglove on, or None."""
    from rimd_sim.viz.foxglove_sink import (
        DEFAULT_HOST,
        DEFAULT_PORT,
        FoxgloveError,
        check_address,
        require_sdk,
        websocket_url,
    )
    from rimd_sim.viz.sinks import SinkError, spec_from_parameters

    try:
        if rerun:
            spec_from_parameters(section).validate()
        if not foxglove:
            return None
        require_sdk("or set foxglove.enabled: false")   # asked by the section itself (--foxglove is checked earlier)
        host = section.get("foxglove.host", DEFAULT_HOST)
        port = section.get("foxglove.port", DEFAULT_PORT)
        check_address(host, port)
    except (SinkError, FoxgloveError) as exc:
        raise InputError(f"{config_path}, section rimd_rerun: {exc}") from None
    return websocket_url(host, port) if port else "the ws:// address the bridge logs (foxglove.port 0: a free port)"


class StopSignals:
    """SIGINT and SIGTERM, within its ``with`` block, set :attr:`requested` instead of stopping this process.

    A verb that runs a rig then stops it cleanly (its recording closed) whichever of the two arrives.
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous: dict[int, Any] = {}

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.requested = True

    def __enter__(self) -> StopSignals:
        """Take SIGINT and SIGTERM."""
        self._previous = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Give the signals back to their previous handlers."""
        for s, handler in self._previous.items():
            signal.signal(s, handler)


@dataclass
class Rig:
    """The processes of a :class:`RigPlan`: start, watch, stop. A context manager; :meth:`stop` is idempotent.

    Args:
        plan: What to start.
        env: The processes' environment (default: this process's).
        output: Where the processes write (default: this process's stdout/stderr); a file per node when a
            directory is given (``log_dir``).
        log_dir: Write each node's output to ``log_dir/<node>.log``.
    """

    plan: RigPlan
    env: Mapping[str, str] | None = None
    log_dir: Path | None = None
    processes: dict[str, subprocess.Popen] = field(default_factory=dict)
    _logs: list[TextIO] = field(default_factory=list)

    def __enter__(self) -> Rig:
        """Start the rig."""
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Stop the rig."""
        self.stop()

    def start(self) -> None:
        """Start every process (consumers first, the simulator last; or the composed rig's one)."""
        for node in self.plan.processes:
            out: Any = None
            if self.log_dir is not None:
                self.log_dir.mkdir(parents=True, exist_ok=True)
                out = open(self.log_dir / f"{node.name}.log", "w")   # closed in stop()
                self._logs.append(out)
            self.processes[node.name] = subprocess.Popen(
                node.command(), start_new_session=True, env=dict(self.env) if self.env is not None else None,
                stdout=out, stderr=subprocess.STDOUT if out is not None else None, stdin=subprocess.DEVNULL)

    def resume_when_connected(self, timeout: float = 20.0) -> bool:
        """Open loop: once every consumer subscribes to every rig topic, resume the simulator.

        Returns True when they all connected in time; otherwise the simulator is resumed all the same (the
        consumers may miss the first blocks) and False comes back. Nothing to do in lockstep, or without
        consumers (True).
        """
        consumers = tuple(n.name for n in self.plan.processes if n.consumer)   # none composed: fed in the process
        if self.plan.lockstep_consumers or not consumers:
            return True
        domain = int(self.env["ROS_DOMAIN_ID"]) if self.env and self.env.get("ROS_DOMAIN_ID") else None
        if _resume_when_connected(consumers, self.processes, timeout, domain):
            return True
        if self.failed() is None:
            _resume_when_connected((), self.processes, 10.0, domain)
        return False

    def failed(self) -> tuple[str, int] | None:
        """A process that has exited, as (name, status), or None."""
        gone = self.exited()
        return gone[0] if gone else None

    def exited(self) -> list[tuple[str, int]]:
        """Every process that has exited, as (name, status), in start order (a status < 0: killed by that signal)."""
        return [(name, proc.returncode) for name, proc in self.processes.items() if proc.poll() is not None]

    def watch(self, stop: StopSignals, duration: float = 0.0, ends_itself: str | None = None) -> tuple[str, int] | None:
        """Wait until ``stop`` is requested, ``duration`` s have passed (0: no limit) or a process exits.

        Returns the process that exited, as (name, status), unless it is ``ends_itself`` with status 0 (a replay
        that reached its end); None otherwise.
        """
        deadline = time.monotonic() + duration if duration > 0 else None
        while not stop.requested and (deadline is None or time.monotonic() < deadline):
            failed = self.failed()
            if failed is not None:
                return None if failed == (ends_itself, 0) else failed
            time.sleep(0.1)
        return None

    def run(self, verb: str, announce: Callable[[], None], *, duration: float = 0.0,
            ends_itself: str | None = None) -> int:
        """Start, ``announce()``, :meth:`watch` within :class:`StopSignals`, then stop: the status of ``rimd VERB``.

        1 when a process exited by itself (said on stderr as ``rimd VERB: NAME exited with status N``) or
        :meth:`stop` found an error; 0 otherwise. The rig is stopped whatever happens.
        """
        status = 0
        with StopSignals() as stop:
            try:
                self.start()
                announce()
                failed = self.watch(stop, duration=duration, ends_itself=ends_itself)
                if failed is not None:
                    print(f"rimd {verb}: {failed[0]} exited with status {failed[1]}", file=sys.stderr)
                    status = 1
            finally:
                status = self.stop() or status
        return status

    def stop(self) -> int:
        """Stop every process in reverse order; 0, or 1 when a node exited with an error."""
        status = 0
        for name, proc in reversed(list(self.processes.items())):
            code = _stop(proc, name)
            if code not in (0, None) and code != -signal.SIGINT:
                status = 1
        for log in self._logs:
            log.close()
        self._logs.clear()
        if self.plan.overrides_path is not None:
            self.plan.overrides_path.unlink(missing_ok=True)
        return status


def stop_process(proc: subprocess.Popen, waits: Sequence[tuple[int, float]] = (
        (signal.SIGINT, 10.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)), *,
        send: Callable[[int], None] | None = None, on_timeout: Callable[[int], None] | None = None) -> int | None:
    """Send ``proc`` each signal of ``waits`` in turn and wait its bounded time (s), until it has exited.

    Args:
        proc: The child process.
        waits: (signal, seconds) in order; by default SIGINT (a node finishes its work), SIGTERM, SIGKILL.
        send: How a signal is sent (default ``proc.send_signal``; ``os.killpg`` for a process group); the
            process gone meanwhile ends the sequence.
        on_timeout: Called with the signal that did not stop it in its time.

    Returns:
        Its exit status (None if it outlived even the last signal's wait).
    """
    for sig, wait in waits:
        if proc.poll() is not None:
            break
        try:
            (send or proc.send_signal)(sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait)
        except subprocess.TimeoutExpired:
            if on_timeout is not None:
                on_timeout(sig)
    return proc.returncode


def _stop(proc: subprocess.Popen, name: str) -> int | None:
    def say(sig: int) -> None:
        print(f"rimd rig: {name} did not stop on {signal.Signals(sig).name}", file=sys.stderr)

    return stop_process(proc, send=lambda sig: os.killpg(proc.pid, sig), on_timeout=say)


def _subscribed(node: Any, topic: str, consumers: tuple[str, ...]) -> bool:
    names = {info.node_name for info in node.get_subscriptions_info_by_topic(topic)}
    return all(name in names for name in consumers)


def _resume_when_connected(consumers: tuple[str, ...], procs: Mapping[str, subprocess.Popen],
                           timeout: float = 20.0, domain_id: int | None = None) -> bool:
    """Wait until each consumer node subscribes to every rig topic, then call /rig/resume. True when resumed.

    Subscribed in the graph is not yet matched: a volatile topic reaches only the readers its writer has matched,
    and the simulator's own view of the graph may lag this process's under load (the recorder then missed the
    first blocks). So the resume also waits until the simulator's /diagnostics say that each rig topic's
    publisher has matched as many subscriptions as the graph shows here.

    ``domain_id``: the rig's ROS domain (default: this process's ``ROS_DOMAIN_ID``).
    """
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.signals import SignalHandlerOptions
    from std_srvs.srv import Trigger

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node("rimd_rig", context=context, start_parameter_services=False)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        matched: dict[str, int] = {}   # topic -> subscriptions its publisher has matched (the simulator says)

        def on_diagnostics(msg: DiagnosticArray) -> None:
            for status in msg.status:
                if "rimd_simulator" in status.name:
                    matched.update({kv.key[:-len(" subscribers")]: int(kv.value) for kv in status.values
                                    if kv.key.endswith(" subscribers")})

        node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
        deadline = time.monotonic() + timeout
        client = node.create_client(Trigger, "/rig/resume")
        while time.monotonic() < deadline and all(p.poll() is None for p in procs.values()):
            if (all(_subscribed(node, t, consumers) for t in RIG_TOPICS) and client.service_is_ready()
                    and (not consumers or all(matched.get(t, -1) >= node.count_subscribers(t) for t in RIG_TOPICS))):
                future = client.call_async(Trigger.Request())
                executor.spin_until_future_complete(future, timeout_sec=5.0)
                return bool(future.done() and future.result().success)
            executor.spin_once(timeout_sec=0.05)
        return False
    finally:
        context.try_shutdown()
