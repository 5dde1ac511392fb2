"""Planning the rig: what ``rimd rig`` and ``rimd replay`` start, read and checked from a configuration.

:func:`plan_rig` reads a parameter file, checks every node's section and decides the processes: the recorder, the
Rerun bridge (Rerun and/or Foxglove) and the simulator, each run with ``--ros-args --params-file CONFIG`` (and an
overrides file when parameters are given). :func:`plan_replay` plans a replay of a recording: the replay node and,
to drive it from Foxglove's timeline, the bridge serving Foxglove only, pointed at it (``foxglove.playback_node``).

Planning starts no process and imports no rclpy: a configuration that is refused starts nothing. The one file it
writes is the overrides file, when parameters are given. :class:`rimd_sim.ros.bringup.processes.Rig` starts a plan.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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

__all__ = ["COMPOSED", "REPLAY_NODE", "PlannedNode", "RigPlan", "composed_process", "plan_replay", "plan_rig"]


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
    """What :class:`~rimd_sim.ros.bringup.processes.Rig` starts, decided by :func:`plan_rig` or :func:`plan_replay`.

    ``config_path`` and ``config`` are None for a replay, which reads no parameter file.
    """

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

    Only a missing section means "none". A section that is not a mapping with ``ros__parameters`` is refused,
    so that a mistyped section stops the bring-up instead of leaving the node on its defaults.
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
