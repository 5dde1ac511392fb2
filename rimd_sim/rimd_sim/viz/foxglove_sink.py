"""The rig on the Foxglove WebSocket protocol: a server of the Foxglove SDK (``foxglove-sdk``), no ROS import.

The SDK is an extra (``pip install 'rimd-sim[foxglove]'``): it is imported when a server starts, so that this
module (its settings, :func:`check_address`) imports without it; :func:`require_sdk` refuses up front, naming the
extra.

What a Foxglove client (the Foxglove app, or any client of the protocol) gets from :class:`FoxgloveSink`:

* **Channels.** Each rig topic is advertised as a channel of message encoding ``cdr`` with its ``ros2msg``
  schema: the full ``.msg`` text and every message it depends on (:func:`rimd_sim.io.msgdefs.
  message_definition`, the layout rosbag2 and foxglove_bridge use). :meth:`FoxgloveSink.log` passes the
  serialized bytes through as received: nothing is decoded or re-encoded.
* **Time.** ``Capability.Time``: :meth:`FoxgloveSink.broadcast_time` tells the clients the rig's current time
  (the node sends ``/clock`` when the rig publishes it, else the wall clock: foxglove_bridge's
  ``use_sim_time`` behaviour).
* **Services.** Each :class:`ForwardedService` is advertised with foxglove_bridge's schemas
  (``pkg/srv/Name_Request`` / ``_Response``, ``ros2msg``, encoding ``cdr``); a call hands the CDR request to a
  :class:`ServiceBackend` (the node forwards it to the ROS service) and returns its CDR response. A backend
  error (service absent, no answer in time, request not decodable) goes back as the protocol's service call
  failure with the backend's message.
* **Parameters.** ``Capability.Parameters``: get and set go to a :class:`ParameterBackend` (the node uses the
  target nodes' own parameter services). A set that the node refuses is answered with the value in force and
  a status message of level error naming the parameter and the node's reason, which Foxglove shows.
* **Playback control** (a replay driven from Foxglove's timeline). Given a :class:`PlaybackHandler`
  (:class:`rimd_sim.runtime.playback_control.PlaybackControl`), :meth:`FoxgloveSink.set_playback_range` (re)starts the
  server with the recording's time range, which advertises ``Capability.PlaybackControl`` (the range is fixed
  for the life of an SDK server: a new range restarts it on the same port, and the clients reconnect); each
  client request goes to the handler, whose state goes back (the SDK broadcasts it, with the request id) and
  whose errors become error statuses; :meth:`FoxgloveSink.broadcast_playback` tells the clients of a change.

The server binds ``host:port`` (default ``127.0.0.1:8765``; port 0 takes a free port, :attr:`FoxgloveSink.port`
says which). :meth:`FoxgloveSink.close` stops it and is idempotent; the sink is a context manager.
"""

from __future__ import annotations

import ipaddress
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any, Protocol

from rimd_sim.dependencies import installed, missing_extra
from rimd_sim.errors import UnavailableError
from rimd_sim.io.msgdefs import MessageDefinitionError, message_definition, service_definitions
from rimd_sim.runtime.playback_control import PlaybackReport, PlaybackRequest

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "FoxgloveError", "FoxgloveSink", "ForwardedService", "ParameterBackend",
           "ParameterEntry", "PlaybackHandler", "ServiceBackend", "ServiceCallError", "check_address",
           "require_sdk", "websocket_url"]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
SCHEMA_ENCODING = "ros2msg"
#: How long a restarted server (a new playback range) waits for the stopped one to release the port (s).
RESTART_PATIENCE_S = 2.0
#: How long a call to the server waits for a restart to end before it is dropped (s; a restart takes milliseconds).
SERVER_WAIT_S = 0.5
MESSAGE_ENCODING = "cdr"
#: The kinds of parameter values (ROS 2's parameter types, by name).
PARAMETER_KINDS = ("bool", "integer", "double", "string", "byte_array", "bool_array", "integer_array",
                   "double_array", "string_array")

_log = logging.getLogger(__name__)


class FoxgloveError(UnavailableError):
    """The Foxglove server cannot be set up as asked; the message names the parameter and the value."""


class ServiceCallError(UnavailableError):
    """A forwarded service call failed; the message (one line) goes back to the Foxglove client."""


def require_sdk(alternative: str = "") -> None:
    """Refuse, before anything starts, to serve Foxglove without the Foxglove SDK (the extra ``foxglove``).

    Raises:
        FoxgloveError: foxglove-sdk is not installed; the message names the extra (and ``alternative``).
    """
    if not installed("foxglove"):
        raise FoxgloveError(missing_extra("foxglove", "the Foxglove server", alternative))


def _sdk() -> Any:
    """The Foxglove SDK (``foxglove`` with its ``websocket`` module), imported on first use.

    Raises:
        FoxgloveError: foxglove-sdk is not installed; the message names the extra.
    """
    try:
        import foxglove
        import foxglove.websocket
    except ImportError:
        raise FoxgloveError(missing_extra("foxglove", "the Foxglove server")) from None
    return foxglove


@dataclass(frozen=True)
class ForwardedService:
    """A ROS service offered to Foxglove clients: its full name (``/rig/pause``) and type (``std_srvs/srv/Trigger``)."""

    name: str
    type_name: str


@dataclass(frozen=True)
class ParameterEntry:
    """One parameter as the sink and its backend exchange it.

    Attributes:
        name: The name Foxglove shows, ``<node>.<parameter>`` (``/rig/rimd_simulator.gap``), as foxglove_bridge.
        kind: One of :data:`PARAMETER_KINDS`, or None for a parameter without a value.
        value: bool, int, float, str, bytes or a list of one of them; None when ``kind`` is None.
    """

    name: str
    kind: str | None
    value: Any = None


class ServiceBackend(Protocol):
    """Performs a forwarded call; called from the server's threads."""

    def call(self, service: ForwardedService, request: bytes) -> bytes:
        """Return the CDR response to the CDR ``request``, or raise :class:`ServiceCallError`."""
        ...


class ParameterBackend(Protocol):
    """Reads and sets parameters of the nodes behind the sink; called from the server's threads."""

    def get(self, names: Sequence[str]) -> list[ParameterEntry]:
        """The parameters named (every parameter of every node when ``names`` is empty); unknown ones left out."""
        ...

    def set(self, entries: Sequence[ParameterEntry]) -> list[tuple[str, bool, str]]:
        """Set each entry; return ``(name, accepted, reason)`` per entry, the reason the node's own."""
        ...


class PlaybackHandler(Protocol):
    """Carries out the clients' playback control requests; called from the server's threads."""

    def handle(self, request: PlaybackRequest) -> tuple[PlaybackReport | None, list[str]]:
        """The state to answer with (None: none known) and the error lines to show the clients."""
        ...


def playback_state(report: PlaybackReport, request_id: str | None = None) -> Any:
    """The SDK's PlaybackState of a report."""
    ws = _sdk().websocket
    status = {"playing": ws.PlaybackStatus.Playing, "paused": ws.PlaybackStatus.Paused,
              "ended": ws.PlaybackStatus.Ended}[report.status]
    return ws.PlaybackState(status=status, current_time=int(report.current_ns), playback_speed=float(report.speed),
                            did_seek=report.did_seek, request_id=request_id)


def check_address(host: str, port: int) -> None:
    """Refuse a host that is not an IP address or a port outside 0..65535, naming the parameter and the value.

    Raises:
        FoxgloveError: Either is bad.
    """
    try:
        ipaddress.ip_address(host)
    except ValueError:
        raise FoxgloveError(f"foxglove.host {host!r} refused: must be an IP address to bind, such as 127.0.0.1 "
                            "(loopback) or 0.0.0.0 (every interface)") from None
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise FoxgloveError(f"foxglove.port {port!r} refused: must be an integer in 0..65535 (0 = a free port)")


def websocket_url(host: str, port: int) -> str:
    """The address to give Foxglove: ``ws://127.0.0.1:8765`` (IPv6 hosts in brackets)."""
    return f"ws://[{host}]:{port}" if ":" in host else f"ws://{host}:{port}"


def parameter_kind(value: Any, float_hint: bool = False, bytes_hint: bool = False) -> str | None:
    """The ROS parameter kind of a plain Python value (None for None; a list's kind from its elements).

    ``float_hint``: whole numbers stand for doubles (Foxglove's ``Float64``/``Float64Array`` type hints).
    """
    if value is None:
        return None
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "double" if float_hint else "integer"
    if isinstance(value, float):
        return "double"
    if isinstance(value, (bytes, bytearray)) or bytes_hint:
        return "byte_array"
    if isinstance(value, str):
        return "string"
    if isinstance(value, (list, tuple)):
        kinds = {parameter_kind(v, float_hint) for v in value}
        if not kinds:
            return "double_array" if float_hint else "string_array"
        if kinds <= {"integer", "double"} and len(kinds) == 2:
            return "double_array"
        if len(kinds) == 1 and next(iter(kinds)) in ("bool", "integer", "double", "string"):
            return f"{next(iter(kinds))}_array"
    raise ValueError(f"a value of type {type(value).__name__} is not a ROS parameter value")


class FoxgloveSink:
    """A Foxglove WebSocket server carrying the rig's topics, services and parameters. See the module docstring.

    Args:
        host: Address to bind (an IP address).
        port: TCP port (0 = a free port).
        name: Server name shown by clients.
        services: The services to offer (their definitions must be installed).
        service_backend: Performs the calls (required when ``services`` is not empty).
        parameter_backend: Serves the parameters (None: no Parameters capability).
        playback: Handles playback control (None: none); the capability comes with :meth:`set_playback_range`.

    Raises:
        FoxgloveError: Bad address, the port is taken, or a service's definition is not installed.
    """

    def __init__(self, *, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, name: str = "rimd",
                 services: Sequence[ForwardedService] = (), service_backend: ServiceBackend | None = None,
                 parameter_backend: ParameterBackend | None = None, playback: PlaybackHandler | None = None) -> None:
        check_address(host, port)
        fg = self._fg = _sdk()   # FoxgloveError naming the extra when the SDK is not installed
        Capability = fg.websocket.Capability
        self._context = fg.Context()
        self._channels: dict[str, Any] = {}
        self._lock = threading.Lock()
        # The SDK refuses any call on its server while another thread stops it ("Already mutably borrowed"): the
        # server's calls and its stop (a restart, the close) take turns under this lock.
        self._server_lock = threading.Lock()
        self._services = list(services)
        self._service_backend = service_backend
        self._parameter_backend = parameter_backend
        self._playback = playback
        self.playback_range: tuple[int, int] | None = None
        self.unadvertised: dict[str, str] = {}   # topic -> why it has no channel
        capabilities = [Capability.Time]
        if self._services:
            if service_backend is None:
                raise ValueError("services given without a service backend")
            capabilities.append(Capability.Services)
        if parameter_backend is not None:
            capabilities.append(Capability.Parameters)
        self._options: dict[str, Any] = {"name": name, "host": host, "capabilities": capabilities,
                         "server_listener": _listener_class()(self) if parameter_backend or playback else None,
                         "supported_encodings": [MESSAGE_ENCODING],
                         "services": [self._service(s) for s in self._services] or None, "context": self._context}
        self.host = host
        self._server = self._start(port)
        self.port = int(self._server.port)
        self._closed = False

    def _start(self, port: int, patience: float = 0.0) -> Any:
        """Start the SDK's server; ``patience``: s to keep trying while the port is busy (a restart)."""
        deadline = time.monotonic() + patience
        while True:
            try:
                return self._fg.start_server(port=port, playback_time_range=self.playback_range, **self._options)
            except Exception as exc:  # the SDK raises its own error types (e.g. address in use)
                if time.monotonic() < deadline:
                    time.sleep(0.005)
                    continue
                raise FoxgloveError(f"the Foxglove server could not listen on {websocket_url(self.host, port)}: "
                                    f"{exc}") from None

    # -- channels ----------------------------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """``ws://HOST:PORT`` of the running server, the address to give Foxglove."""
        return websocket_url(self.host, self.port)

    @property
    def topics(self) -> list[str]:
        """The topics advertised, in order."""
        return list(self._channels)

    def advertise(self, topic: str, type_name: str) -> bool:
        """Advertise ``topic`` (idempotent); False, with the reason in :attr:`unadvertised`, if its type is unknown."""
        if topic in self._channels:
            return True
        try:
            definition = message_definition(type_name)
        except MessageDefinitionError as exc:
            self.unadvertised[topic] = str(exc)
            return False
        schema = self._fg.Schema(name=definition.type_name, encoding=SCHEMA_ENCODING, data=definition.text.encode())
        with self._lock:
            if topic not in self._channels and not self._closed:
                self._channels[topic] = self._fg.Channel(topic, schema=schema, message_encoding=MESSAGE_ENCODING,
                                                         context=self._context)
        return topic in self._channels

    def log(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Send the serialized message ``data`` of an advertised topic to the clients subscribed to it."""
        channel = self._channels.get(topic)
        if channel is not None:
            channel.log(data, log_time=log_time_ns)

    def _on_server(self, call: Callable[[Any], Any]) -> None:
        """``call(server)`` unless the sink is closed, never while the server stops.

        Waits at most ``SERVER_WAIT_S`` for a restart to end, then drops the call: a restart drops the connected
        clients, so nobody would receive it (and a listener's callback waiting here must not hold the stop up).
        """
        if not self._server_lock.acquire(timeout=SERVER_WAIT_S):
            return
        try:
            if not self._closed:
                call(self._server)
        finally:
            self._server_lock.release()

    def broadcast_time(self, time_ns: int) -> None:
        """Tell every client the rig's current time (ns)."""
        self._on_server(lambda server: server.broadcast_time(int(time_ns)))

    def publish_parameters(self, entries: Sequence[ParameterEntry]) -> None:
        """Send new values to the clients subscribed to them (the SDK filters by subscription)."""
        if entries:
            values = [self._parameter(e) for e in entries]
            self._on_server(lambda server: server.publish_parameter_values(values))

    def status(self, message: str, *, error: bool = False, status_id: str | None = None) -> None:
        """Show ``message`` in the clients (Foxglove's problems and notifications)."""
        level = self._fg.StatusLevel
        self._on_server(lambda server: server.publish_status(message, level.Error if error else level.Info,
                                                             status_id))

    # -- playback control --------------------------------------------------------------------------------------
    def set_playback_range(self, start_ns: int, end_ns: int) -> bool:
        """Offer playback control over ``[start_ns, end_ns]``; False when that range is already offered.

        The server restarts on its port with the range (connected clients are dropped and reconnect).

        Raises:
            FoxgloveError: The port could not be listened on again.
        """
        if self._playback is None:
            raise ValueError("a playback range without a playback handler")
        with self._lock:
            if self._closed or self.playback_range == (start_ns, end_ns):
                return False
            with self._server_lock:
                self._server.stop()   # it lets the port go a few ms later: the new server waits for it
                self.playback_range = (int(start_ns), int(end_ns))
                self._server = self._start(self.port, patience=RESTART_PATIENCE_S)
            return True

    def broadcast_playback(self, report: PlaybackReport) -> None:
        """Tell every client the playback state (a change not asked by a request)."""
        if self.playback_range is not None:
            state = playback_state(report)
            self._on_server(lambda server: server.broadcast_playback_state(state))

    def handle_playback(self, request: Any) -> Any:
        """The SDK's PlaybackControlRequest carried out: its errors shown as error statuses; the state answered."""
        assert self._playback is not None   # the listener takes playback requests only then
        report, errors = self._playback.handle(PlaybackRequest(
            play=request.playback_command == self._fg.websocket.PlaybackCommand.Play,
            speed=float(request.playback_speed),
            seek_ns=None if request.seek_time is None else int(request.seek_time),
            request_id=str(request.request_id or "")))
        for line in errors:
            self.status(line, error=True, status_id="playback")
        return None if report is None else playback_state(report, request.request_id)

    # -- services ----------------------------------------------------------------------------------------------
    def _service(self, service: ForwardedService) -> Any:
        try:
            request, response = service_definitions(service.type_name)
        except MessageDefinitionError as exc:
            raise FoxgloveError(f"service {service.name}: {exc}") from None
        fg = self._fg
        schema = fg.ServiceSchema(
            name=service.type_name,
            request=fg.MessageSchema(encoding=MESSAGE_ENCODING, schema=fg.Schema(
                name=request.type_name, encoding=SCHEMA_ENCODING, data=request.text.encode())),
            response=fg.MessageSchema(encoding=MESSAGE_ENCODING, schema=fg.Schema(
                name=response.type_name, encoding=SCHEMA_ENCODING, data=response.text.encode())))
        backend = self._service_backend
        assert backend is not None   # checked in __init__: services come with their backend

        def handler(request_msg: Any) -> bytes:
            # Runs in one of the SDK's threads; an exception's text becomes the client's failure message.
            if request_msg.encoding != MESSAGE_ENCODING:
                raise ServiceCallError(f"{service.name}: request encoding {request_msg.encoding!r} refused: "
                                       f"must be {MESSAGE_ENCODING}")
            return bytes(backend.call(service, bytes(request_msg.payload)))

        return fg.Service(name=service.name, schema=schema, handler=handler)

    # -- parameters --------------------------------------------------------------------------------------------
    def _parameter(self, entry: ParameterEntry) -> Any:
        Parameter, ParameterType = self._fg.Parameter, self._fg.ParameterType
        if entry.kind is None:
            return Parameter(entry.name)
        if entry.kind == "double":
            return Parameter(entry.name, value=float(entry.value), type=ParameterType.Float64)
        if entry.kind == "double_array":
            return Parameter(entry.name, value=[float(v) for v in entry.value], type=ParameterType.Float64Array)
        if entry.kind == "byte_array":
            return Parameter(entry.name, value=bytes(entry.value), type=ParameterType.ByteArray)
        if entry.kind.endswith("_array"):
            return Parameter(entry.name, value=list(entry.value))
        return Parameter(entry.name, value=entry.value)

    def _entry(self, parameter: Any) -> ParameterEntry:
        ParameterType = self._fg.ParameterType
        value = parameter.get_value()
        hint = parameter.type
        kind = parameter_kind(value, float_hint=hint in (ParameterType.Float64, ParameterType.Float64Array),
                              bytes_hint=hint == ParameterType.ByteArray)
        if kind == "double":
            value = float(value)
        elif kind == "double_array":
            value = [float(v) for v in value]
        return ParameterEntry(parameter.name, kind, value)

    def _parameters(self) -> ParameterBackend:
        """The parameter backend (parameters are served only with one)."""
        assert self._parameter_backend is not None
        return self._parameter_backend

    def get_parameters(self, names: Sequence[str]) -> list[Any]:
        """The SDK's parameters for a client's get request (the listener's work, also callable directly)."""
        return [self._parameter(e) for e in self._parameters().get(list(names))]

    def set_parameters(self, parameters: Sequence[Any]) -> list[Any]:
        """Set what a client asked; report refusals as error statuses; return the values now in force."""
        entries = []
        for parameter in parameters:
            try:
                entries.append(self._entry(parameter))
            except ValueError as exc:
                self.status(f"{parameter.name}: {exc}", error=True, status_id=f"parameter {parameter.name}")
        results = self._parameters().set(entries) if entries else []
        for name, accepted, reason in results:
            if not accepted:
                self.status(f"parameter {name} refused: {reason}", error=True, status_id=f"parameter {name}")
        return self.get_parameters([p.name for p in parameters])

    # -- life cycle --------------------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop the server and close the channels (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            channels, self._channels = list(self._channels.values()), {}
        for channel in channels:
            channel.close()
        with self._server_lock:
            self._server.stop()

    def __enter__(self) -> FoxgloveSink:
        """The sink itself."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Close the sink."""
        self.close()


@cache
def _listener_class() -> type:
    """The SDK's server listener class for a sink (made once, when the SDK is first needed)."""
    base: type = _sdk().websocket.ServerListener

    class Listener(base):
        """The SDK's server listener: parameter and playback requests go to the sink (never raised into Rust)."""

        def __init__(self, sink: FoxgloveSink) -> None:
            self._sink = sink

        def _shown(self, call: Callable[[], Any], failed: str, status_id: str, fallback: Any) -> Any:
            """``call()``; should it raise, ``failed: <exception>`` is shown to the clients, ``fallback`` returned."""
            try:
                return call()
            except Exception as exc:  # shown to the client, never raised into the SDK's thread
                self._sink.status(f"{failed}: {exc}", error=True, status_id=status_id)
                return fallback

        def on_get_parameters(self, client: Any, param_names: list[str], request_id: str | None = None) -> list[Any]:
            return self._shown(lambda: self._sink.get_parameters(param_names), "parameters could not be read",
                               "parameters", [])

        def on_set_parameters(self, client: Any, parameters: list[Any], request_id: str | None = None) -> list[Any]:
            return self._shown(lambda: self._sink.set_parameters(parameters), "parameters could not be set",
                               "parameters", [])

        def on_playback_control_request(self, playback_control_request: Any) -> Any:
            return self._shown(lambda: self._sink.handle_playback(playback_control_request),
                               "playback: the request could not be carried out", "playback", None)

    return Listener
