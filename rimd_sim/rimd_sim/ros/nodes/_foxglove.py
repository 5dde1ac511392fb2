"""The ROS side of the bridge's Foxglove sink: topics, service calls and parameters of a running rig.

:class:`FoxgloveRelay` owns a :class:`rimd_sim.viz.foxglove_sink.FoxgloveSink` (the server, no ROS in it) and
feeds it from the node it belongs to (the Rerun bridge ``rimd_rerun``):

* **Topics.** The node hands over the raw (CDR) messages of the subscriptions it already has for Rerun
  (:meth:`FoxgloveRelay.on_message`; no second subscription to a topic), and the relay subscribes to the other
  topics matching ``foxglove.topics`` as they appear in the graph (every ``DISCOVERY_PERIOD_S``), raw, taken by
  the node's :class:`~rimd_sim.ros.nodes.polling.PolledSubscriptions`, with the publishers' reliability and
  durability, like the recorder. Each message goes out with its bytes unchanged, at log time = the node's rig
  clock: the last ``/clock`` received when the rig publishes one (simulation time), else the wall clock; that
  clock is also broadcast to the clients every ``TIME_PERIOD_S`` (foxglove_bridge with ``use_sim_time``).
* **Services.** :data:`RIG_SERVICES` under the node's namespace: a call is deserialized into the service's
  request type, sent to the ROS service, and the ROS response serialized back: the node's own answer
  (a refusal is its ``success: false`` and ``message``). No server, or no answer within ``call_timeout``:
  a failure naming the service and the reason.
* **Parameters.** Those of ``foxglove.parameter_nodes`` (default the simulator), named
  ``<node>.<parameter>`` as foxglove_bridge does, read and set through each node's own parameter services
  (``list_parameters``, ``get_parameters``, ``set_parameters``), so the node validates and refuses with its
  own reason; changes made elsewhere reach the clients from ``/parameter_events``.
* **A replay** (``foxglove.playback_node``, e.g. ``/rimd_replay``). Foxglove's timeline drives it:
  :class:`rimd_sim.runtime.playback_control.PlaybackControl` over the replay's services (``~/get_state``, ``~/seek``,
  ``~/set_rate``, ``~/pause``, ``~/resume``), read every ``PLAYBACK_POLL_S`` in a thread of the relay (a change
  made by anyone is broadcast); the server offers playback control once the replay has answered with its range
  (and again, restarted, when the range changes). The clock is then the playback time, and the services offered
  are the replay's (:data:`REPLAY_SERVICES`), not the rig's.
"""

from __future__ import annotations

import importlib
import re
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from builtin_interfaces.msg import Time
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterEvent, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from std_srvs.srv import Trigger

from rimd_msgs.srv import GetReplayState, Seek, SetRate
from rimd_sim.io.cdr import header_stamp
from rimd_sim.runtime.playback_control import PlaybackControl, ReplayUnavailable
from rimd_sim.runtime.replay import PlayerState
from rimd_sim.runtime.threads import named_thread
from rimd_sim.viz.foxglove_sink import (
    ForwardedService,
    FoxgloveError,
    FoxgloveSink,
    ParameterEntry,
    ServiceCallError,
)

__all__ = ["DISCOVERY_PERIOD_S", "FoxgloveRelay", "PLAYBACK_POLL_S", "REPLAY_SERVICES", "RIG_SERVICES",
           "TIME_PERIOD_S"]

#: The rig's services offered to Foxglove clients: name relative to the node's namespace, type.
RIG_SERVICES: tuple[tuple[str, str], ...] = (
    ("set_motor_frequency", "rimd_msgs/srv/SetMotorFrequency"),
    ("perturb", "rimd_msgs/srv/Perturb"),
    ("inject_fault", "rimd_msgs/srv/InjectFault"),
    ("clear_faults", "std_srvs/srv/Trigger"),
    ("pause", "std_srvs/srv/Trigger"),
    ("resume", "std_srvs/srv/Trigger"),
    ("reset", "std_srvs/srv/Trigger"),
)
#: A replay's services offered to Foxglove clients instead (foxglove.playback_node): name under the node, type.
REPLAY_SERVICES: tuple[tuple[str, str], ...] = (
    ("pause", "std_srvs/srv/Trigger"),
    ("resume", "std_srvs/srv/Trigger"),
    ("toggle_paused", "std_srvs/srv/Trigger"),
    ("is_paused", "rimd_msgs/srv/IsPaused"),
    ("get_rate", "rimd_msgs/srv/GetRate"),
    ("set_rate", "rimd_msgs/srv/SetRate"),
    ("seek", "rimd_msgs/srv/Seek"),
    ("play_next", "rimd_msgs/srv/PlayNext"),
    ("burst", "rimd_msgs/srv/Burst"),
    ("get_state", "rimd_msgs/srv/GetReplayState"),
)
DISCOVERY_PERIOD_S = 1.0
#: Period of the reading of a replay's state (s): a change made by another client shows within it.
PLAYBACK_POLL_S = 0.2
TIME_PERIOD_S = 0.05
CLOCK_TOPIC = "/clock"
#: ROS parameter type constants <-> the sink's kinds, and the ParameterValue field of each.
_KINDS = {ParameterType.PARAMETER_BOOL: "bool", ParameterType.PARAMETER_INTEGER: "integer",
          ParameterType.PARAMETER_DOUBLE: "double", ParameterType.PARAMETER_STRING: "string",
          ParameterType.PARAMETER_BYTE_ARRAY: "byte_array", ParameterType.PARAMETER_BOOL_ARRAY: "bool_array",
          ParameterType.PARAMETER_INTEGER_ARRAY: "integer_array",
          ParameterType.PARAMETER_DOUBLE_ARRAY: "double_array",
          ParameterType.PARAMETER_STRING_ARRAY: "string_array"}
_TYPES = {kind: code for code, kind in _KINDS.items()}


def _interface(type_name: str) -> Any:
    """The class of ``pkg/msg/Name`` or ``pkg/srv/Name`` (ImportError or AttributeError when not installed)."""
    pkg, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def _wait(future: Any, timeout: float, stop: threading.Event | None = None) -> bool:
    """Wait (in a thread that is not the executor's) until ``future`` is done; False after ``timeout`` s or a stop."""
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    if stop is None:
        return done.wait(timeout)
    deadline = time.monotonic() + timeout
    while not done.wait(0.05):
        if stop.is_set() or time.monotonic() > deadline:
            return False
    return True


def _ns(stamp: Any) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def value_to_entry(name: str, value: ParameterValue) -> ParameterEntry:
    """A ROS ParameterValue as the sink's entry."""
    kind = _KINDS.get(value.type)
    if kind is None:
        return ParameterEntry(name, None)
    data = getattr(value, f"{kind}_value")
    if kind == "byte_array":
        data = b"".join(data)
    elif kind.endswith("_array"):
        data = list(data)
    return ParameterEntry(name, kind, data)


def entry_to_value(entry: ParameterEntry, current: int | None = None) -> ParameterValue:
    """The sink's entry as a ROS ParameterValue; a number is given the current type (``1`` for a double is 1.0)."""
    kind = entry.kind
    if current is not None and kind is not None:
        wanted = _KINDS.get(current)
        if (kind, wanted) in (("integer", "double"), ("integer_array", "double_array")):
            kind = wanted
    if kind is None:
        return ParameterValue(type=ParameterType.PARAMETER_NOT_SET)
    value = ParameterValue(type=_TYPES.get(kind, ParameterType.PARAMETER_NOT_SET))
    data = entry.value
    if kind == "double":
        data = float(data)
    elif kind == "double_array":
        data = [float(v) for v in data]
    elif kind == "byte_array":
        data = [bytes([b]) for b in bytes(data)]
    setattr(value, f"{kind}_value", data)
    return value


class _ServiceForwarder:
    """Forwards a Foxglove call to the ROS service (the sink's ServiceBackend)."""

    def __init__(self, node: Node, services: Sequence[ForwardedService], timeout: float, server: str) -> None:
        self._timeout = timeout
        self._server = server
        self._clients = {s.name: (node.create_client(_interface(s.type_name), s.name), _interface(s.type_name))
                         for s in services}

    def call(self, service: ForwardedService, request: bytes) -> bytes:
        client, srv = self._clients[service.name]
        try:
            message = deserialize_message(request, srv.Request)
        except Exception as exc:  # rclpy raises a bare error for undecodable bytes
            raise ServiceCallError(f"{service.name}: the request is not a CDR {service.type_name} request ({exc})") \
                from None
        if not client.wait_for_service(timeout_sec=min(self._timeout, 1.0)):
            raise ServiceCallError(f"{service.name}: no such service is running (is {self._server} up?)")
        future = client.call_async(message)
        if not _wait(future, self._timeout) or future.result() is None:
            raise ServiceCallError(f"{service.name}: no answer within {self._timeout:g} s")
        return serialize_message(future.result())


class _ReplayControls:
    """A replay's services as :class:`rimd_sim.runtime.playback_control.ReplayControls`.

    Blocking: never called from the executor's thread.
    """

    def __init__(self, node: Node, replay: str, timeout: float, stop: threading.Event) -> None:
        self._replay, self._timeout, self._stop = replay, timeout, stop
        self._clients = {name: node.create_client(srv, f"{replay}/{name}") for name, srv in (
            ("get_state", GetReplayState), ("seek", Seek), ("set_rate", SetRate), ("pause", Trigger),
            ("resume", Trigger))}

    def _call(self, name: str, request: Any) -> Any:
        client = self._clients[name]
        if not client.wait_for_service(timeout_sec=min(self._timeout, 1.0)):
            raise ReplayUnavailable(f"{self._replay}/{name}: no such service is running")
        future = client.call_async(request)
        if not _wait(future, self._timeout, self._stop) or future.result() is None:
            raise ReplayUnavailable(f"{self._replay}/{name}: no answer within {self._timeout:g} s")
        return future.result()

    def state(self) -> PlayerState:
        r = self._call("get_state", GetReplayState.Request())
        return PlayerState(_ns(r.start), _ns(r.end), _ns(r.position), r.paused, r.ended, r.rate, r.passes, r.seeks,
                           r.published)

    def seek(self, t_ns: int) -> tuple[bool, str]:
        sec, nanosec = divmod(t_ns, 1_000_000_000)
        if not 0 <= sec < 2**31:
            return False, f"time = {t_ns} ns refused: not a ROS time (0 to 2147483647 s)"
        r = self._call("seek", Seek.Request(time=Time(sec=sec, nanosec=nanosec)))
        return r.success, r.message

    def set_rate(self, rate: float) -> tuple[bool, str]:
        r = self._call("set_rate", SetRate.Request(rate=rate))
        return r.success, r.message

    def pause(self) -> tuple[bool, str]:
        r = self._call("pause", Trigger.Request())
        return r.success, r.message

    def resume(self) -> tuple[bool, str]:
        r = self._call("resume", Trigger.Request())
        return r.success, r.message


class _ParameterForwarder:
    """Reads and sets parameters through the nodes' own parameter services (the sink's ParameterBackend)."""

    def __init__(self, node: Node, node_names: Sequence[str], timeout: float) -> None:
        self._timeout = timeout
        self._nodes = {name: {
            "list": node.create_client(ListParameters, f"{name}/list_parameters"),
            "get": node.create_client(GetParameters, f"{name}/get_parameters"),
            "set": node.create_client(SetParameters, f"{name}/set_parameters"),
        } for name in node_names}

    def _call(self, node: str, which: str, request: Any) -> Any:
        client = self._nodes[node][which]
        if not client.wait_for_service(timeout_sec=min(self._timeout, 1.0)):
            raise ServiceCallError(f"{node}: its parameter services are not running (is the node up?)")
        future = client.call_async(request)
        if not _wait(future, self._timeout) or future.result() is None:
            raise ServiceCallError(f"{node}: no answer to {which}_parameters within {self._timeout:g} s")
        return future.result()

    def _split(self, names: Sequence[str]) -> dict[str, list[str]]:
        """``<node>.<parameter>`` names grouped by node (names of other nodes left out)."""
        out: dict[str, list[str]] = {}
        for full in names:
            node, _, param = full.partition(".")
            if node in self._nodes and param:
                out.setdefault(node, []).append(param)
        return out

    def _values(self, node: str, params: list[str]) -> list[ParameterValue]:
        return list(self._call(node, "get", GetParameters.Request(names=params)).values)

    def get(self, names: Sequence[str]) -> list[ParameterEntry]:
        wanted = self._split(names) if names else {
            node: list(self._call(node, "list", ListParameters.Request()).result.names) for node in self._nodes}
        entries = []
        for node, params in wanted.items():
            for param, value in zip(params, self._values(node, params), strict=False):
                if value.type != ParameterType.PARAMETER_NOT_SET:
                    entries.append(value_to_entry(f"{node}.{param}", value))
        return entries

    def set(self, entries: Sequence[ParameterEntry]) -> list[tuple[str, bool, str]]:
        results = []
        by_name = {e.name: e for e in entries}
        for full in by_name:
            node, _, param = full.partition(".")
            if node not in self._nodes or not param:
                results.append((full, False, f"not a parameter of {', '.join(self._nodes)} (names are "
                                             "<node>.<parameter>)"))
        for node, params in self._split(list(by_name)).items():
            current = [v.type for v in self._values(node, params)]
            request = SetParameters.Request(parameters=[
                ParameterMsg(name=p, value=entry_to_value(by_name[f"{node}.{p}"], t or None))
                for p, t in zip(params, current, strict=True)])
            answer = self._call(node, "set", request)
            results += [(f"{node}.{p}", r.successful, r.reason) for p, r in zip(params, answer.results, strict=False)]
        return results


class FoxgloveRelay:
    """The bridge node's Foxglove side. See the module docstring.

    Args:
        node: The bridge node (its namespace resolves the rig's services).
        polled: The node's PolledSubscriptions (the relay's own subscriptions join them).
        host, port: Where the server listens.
        topics: Regular expressions (full match) of the topics to offer.
        parameter_nodes: Fully qualified names of the nodes whose parameters are offered.
        call_timeout: s to wait for a service or parameter answer.
        shared: The topics (full names, with types) the node already subscribes to and hands over.
        playback_node: A replay to drive from Foxglove's timeline (its fully qualified name), or "".

    Raises:
        FoxgloveError: The server could not start (bad address, port taken, a definition missing).
    """

    def __init__(self, node: Node, polled: Any, *, host: str, port: int, topics: Sequence[str],
                 parameter_nodes: Sequence[str], call_timeout: float, shared: dict[str, str],
                 playback_node: str = "") -> None:
        self._node = node
        self._polled = polled
        self._include = [re.compile(p) for p in topics if p]
        self._stop = threading.Event()
        self.playback = None
        if playback_node:
            self.playback = PlaybackControl(_ReplayControls(node, playback_node, call_timeout, self._stop),
                                            playback_node)
            services = [ForwardedService(f"{playback_node}/{name}", t) for name, t in REPLAY_SERVICES]
        else:
            ns = node.get_namespace().rstrip("/")
            services = [ForwardedService(f"{ns}/{name}", type_name) for name, type_name in RIG_SERVICES]
        params = [n for n in parameter_nodes if n]
        self.sink = FoxgloveSink(
            host=host, port=port, name=f"rimd {node.get_fully_qualified_name()}", services=services,
            service_backend=_ServiceForwarder(node, services, call_timeout,
                                              f"the replay {playback_node}" if playback_node else "the simulator"),
            parameter_backend=_ParameterForwarder(node, params, call_timeout) if params else None,
            playback=self.playback)
        self._parameter_nodes = set(params)
        self._clock_ns: int | None = None
        self.forwarded = 0
        self._known: set[str] = set()
        for topic, type_name in shared.items():
            if self.wanted(topic):
                self._offer(topic, type_name)
            self._known.add(topic)
        self._own: dict[str, Any] = {}
        if params:
            node.create_subscription(ParameterEvent, "/parameter_events", self._on_parameter_event, 100)
        self._timers = [node.create_timer(DISCOVERY_PERIOD_S, self.discover),
                        node.create_timer(TIME_PERIOD_S, self._broadcast_time)]
        self.discover()
        self._watcher = None
        if self.playback is not None:
            self._watcher = named_thread(self._watch_playback, "rimd-foxglove")
            self._watcher.start()

    @property
    def url(self) -> str:
        """``ws://HOST:PORT`` to give Foxglove."""
        return self.sink.url

    def wanted(self, topic: str) -> bool:
        """Whether ``topic`` is offered (``foxglove.topics``)."""
        return any(p.fullmatch(topic) for p in self._include)

    def _offer(self, topic: str, type_name: str) -> None:
        if not self.sink.advertise(topic, type_name):
            self._node.get_logger().error(f"foxglove: {topic} not offered: {self.sink.unadvertised[topic]}")

    # -- messages ----------------------------------------------------------------------------------------------
    def now_ns(self) -> int:
        """The rig clock: a replay's playback time; else the last /clock received, else the wall clock."""
        if self.playback is not None:
            now = self.playback.now_ns()
            if now is not None:
                return now
        return self._clock_ns if self._clock_ns is not None else time.time_ns()

    def on_message(self, topic: str, data: bytes) -> None:
        """Forward one serialized message of ``topic`` (full name) as received."""
        if topic == CLOCK_TOPIC and (stamp := header_stamp(data)) is not None:   # Clock: a Time first
            self._clock_ns = stamp
        self.forwarded += 1
        self.sink.log(topic, data, self.now_ns())

    def _broadcast_time(self) -> None:
        self.sink.broadcast_time(self.now_ns())

    def discover(self) -> None:
        """Subscribe to the offered topics that appeared in the graph since the last look."""
        node = self._node
        for topic, types in node.get_topic_names_and_types():
            if topic in self._known or not self.wanted(topic):
                continue
            publishers = [p for p in node.get_publishers_info_by_topic(topic)
                          if (p.node_namespace.rstrip("/") + "/" + p.node_name) != node.get_fully_qualified_name()]
            if not publishers:
                continue
            self._known.add(topic)
            type_name = types[0]
            try:
                msg_type = _interface(type_name)
            except (ImportError, AttributeError, ValueError):
                node.get_logger().error(f"foxglove: {topic} not offered: its type {type_name} is not installed here")
                continue
            reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
            latched = all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                             reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
            self._offer(topic, type_name)
            self._own[topic] = self._polled.create(msg_type, topic, qos, self._forward(topic))

    def _forward(self, topic: str) -> Callable[[bytes, dict], None]:
        def handler(data: bytes, info: dict) -> None:  # the message info is not used
            self.on_message(topic, data)

        return handler

    def _watch_playback(self) -> None:
        """Read the replay's state every PLAYBACK_POLL_S: offer its range, tell the clients of every change."""
        log = self._node.get_logger()
        playback = self.playback
        assert playback is not None   # the watcher runs only with one
        while not self._stop.is_set():
            report, line = playback.poll()
            span = playback.time_range
            if span is not None and span != self.sink.playback_range:
                try:
                    self.sink.set_playback_range(*span)
                    log.info(f"foxglove: playback control of {playback.name} over its recording's log times "
                             f"{span[0] / 1e9:.9f} to {span[1] / 1e9:.9f} s ({self.url})")
                except FoxgloveError as exc:
                    log.error(f"foxglove: playback control of {playback.name} not offered: {exc}")
            if report is not None:
                self.sink.broadcast_playback(report)
            if line:
                gone = "stopped answering" in line
                (log.warning if gone else log.info)(f"foxglove: {line}")
                self.sink.status(line, error=gone, status_id="playback")
            self._stop.wait(PLAYBACK_POLL_S)

    def _on_parameter_event(self, event: ParameterEvent) -> None:
        if event.node not in self._parameter_nodes:
            return
        changed = [value_to_entry(f"{event.node}.{p.name}", p.value) for p in (*event.new_parameters,
                                                                                 *event.changed_parameters)]
        self.sink.publish_parameters(changed)

    def close(self) -> None:
        """Stop the server (idempotent)."""
        self._stop.set()
        if self._watcher is not None:
            self._watcher.join(timeout=3.0)
        for timer in self._timers:
            timer.cancel()
        self.sink.close()
