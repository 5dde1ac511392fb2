"""A client of the Foxglove WebSocket protocol (v1) for the tests, on the ``websockets`` library.

Written from the protocol's specification (github.com/foxglove/ws-protocol, docs/spec.md), independently of
the server under test: JSON text frames for control (``serverInfo``, ``advertise``, ``advertiseServices``,
``status``, ``parameterValues``, ``serviceCallFailure``; ``subscribe``, ``getParameters``, ``setParameters``),
binary frames for data. Server binary opcodes: 1 message data (u32 subscription id, u64 log time, payload),
2 time (u64), 3 service call response (u32 service id, u32 call id, u32 encoding length, encoding, payload),
5 playback state (u8 status 0 Playing / 1 Paused / 2 Buffering / 3 Ended, u64 current time, f32 speed, u8 did
seek, u32 request id length, request id). Client binary opcodes: 2 service call request (same layout as the
response), 3 playback control request (u8 command 0 Play / 1 Pause, f32 speed, u8 had seek, u64 seek time, u32
request id length, request id). All integers little-endian. Playback control (capability ``playbackControl``,
``dataStartTime``/``dataEndTime`` as ``{sec, nsec}`` in serverInfo) is not in the version of ws-protocol's
docs/spec.md read here (011a183); its layouts are those of the SDK's own sources (foxglove/foxglove-sdk,
rust/foxglove/src/protocol/common/client/playback_control_request.rs and server/playback_state.rs), checked
against the installed server (foxglove-sdk 0.30.3).

A reader thread files every frame by kind; the test waits on them with bounded deadlines
(:meth:`FoxgloveClient.wait_for`).
"""

from __future__ import annotations

import json
import re
import struct
import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

#: The subprotocol of the Foxglove SDK's server (foxglove-sdk 0.30): the ws-protocol v1 messages under the SDK's name
#: (its handshake answers 400 to a client that offers only ``foxglove.websocket.v1``).
SUBPROTOCOL = "foxglove.sdk.v1"


@dataclass
class Received:
    """Everything the server sent, by kind."""

    server_info: dict | None = None
    channels: dict[int, dict] = field(default_factory=dict)          # channel id -> advertised channel
    services: dict[str, dict] = field(default_factory=dict)          # service name -> advertised service
    statuses: list[dict] = field(default_factory=list)
    parameter_values: list[dict] = field(default_factory=list)      # whole parameterValues messages
    messages: dict[int, list[tuple[int, bytes]]] = field(default_factory=dict)   # subscription -> (log time, data)
    times: list[int] = field(default_factory=list)
    responses: dict[int, tuple[str, bytes]] = field(default_factory=dict)       # call id -> (encoding, payload)
    failures: dict[int, str] = field(default_factory=dict)                      # call id -> message
    playback: list[PlaybackState] = field(default_factory=list)


#: Playback statuses by their code in the protocol.
PLAYBACK_STATUSES = ("playing", "paused", "buffering", "ended")


@dataclass(frozen=True)
class PlaybackState:
    """A playback state the server sent (binary opcode 5)."""

    status: str
    current_ns: int
    speed: float
    did_seek: bool
    request_id: str


class FoxgloveClient:
    """Connects to ``url`` and records what the server sends; a context manager."""

    def __init__(self, url: str, timeout: float = 10.0) -> None:
        self._stack = ExitStack()
        self._ws = self._stack.enter_context(connect(url, subprotocols=[SUBPROTOCOL], open_timeout=timeout,
                                                     max_size=None, compression=None, proxy=None))
        self.subprotocol = self._ws.subprotocol
        self.received = Received()
        self._cond = threading.Condition()
        self._next_id = 1
        self._subscriptions: dict[int, int] = {}   # subscription id -> channel id
        self.closed_reason: str | None = None
        self._reader = threading.Thread(target=self._read, name="foxglove-client", daemon=True)
        self._reader.start()

    # -- receiving ---------------------------------------------------------------------------------------------
    def _read(self) -> None:
        try:
            for frame in self._ws:
                with self._cond:
                    if isinstance(frame, str):
                        self._on_json(json.loads(frame))
                    else:
                        self._on_binary(frame)
                    self._cond.notify_all()
        except ConnectionClosed as exc:
            self.closed_reason = str(exc)
        with self._cond:
            self._cond.notify_all()

    def _on_json(self, msg: dict) -> None:
        r = self.received
        op = msg.get("op")
        if op == "serverInfo":
            r.server_info = msg
        elif op == "advertise":
            for channel in msg["channels"]:
                r.channels[channel["id"]] = channel
        elif op == "unadvertise":
            for channel_id in msg["channelIds"]:
                r.channels.pop(channel_id, None)
        elif op == "advertiseServices":
            for service in msg["services"]:
                r.services[service["name"]] = service
        elif op == "status":
            r.statuses.append(msg)
            # The SDK can send a channel's advertisement a moment before it takes subscriptions to it: a client
            # that subscribes at once may hear "Unknown channel ID: N" (more likely under load); it asks again.
            unknown = re.fullmatch(r"Unknown channel ID: (\d+)", msg.get("message", ""))
            if unknown and int(unknown.group(1)) in r.channels and len(r.statuses) < 200:
                channel = int(unknown.group(1))
                again = [{"id": s, "channelId": c} for s, c in self._subscriptions.items() if c == channel]
                if again:
                    self._ws.send(json.dumps({"op": "subscribe", "subscriptions": again}))
        elif op == "parameterValues":
            r.parameter_values.append(msg)
        elif op == "serviceCallFailure":
            r.failures[msg["callId"]] = msg["message"]

    def _on_binary(self, frame: bytes) -> None:
        r = self.received
        opcode = frame[0]
        if opcode == 1:
            subscription, log_time = struct.unpack_from("<IQ", frame, 1)
            r.messages.setdefault(subscription, []).append((log_time, bytes(frame[13:])))
        elif opcode == 2:
            r.times.append(struct.unpack_from("<Q", frame, 1)[0])
        elif opcode == 3:
            _service, call, length = struct.unpack_from("<III", frame, 1)
            encoding = frame[13:13 + length].decode()
            r.responses[call] = (encoding, bytes(frame[13 + length:]))
        elif opcode == 5:
            status, current, speed, did_seek, length = struct.unpack_from("<BQfBI", frame, 1)
            r.playback.append(PlaybackState(PLAYBACK_STATUSES[status], current, speed, bool(did_seek),
                                            frame[19:19 + length].decode()))

    def wait_for(self, condition: Callable[[Received], Any], timeout: float, what: str = "") -> Any:
        """Wait until ``condition(received)`` is truthy and return it; AssertionError after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                result = condition(self.received)
                if result:
                    return result
                left = deadline - time.monotonic()
                if left <= 0 or (self.closed_reason is not None and not self._reader.is_alive()):
                    closed = f" (connection closed: {self.closed_reason})" if self.closed_reason else ""
                    raise AssertionError(f"Foxglove client: {what or 'condition'} not met within {timeout} s{closed}")
                self._cond.wait(min(left, 0.5))

    # -- sending -----------------------------------------------------------------------------------------------
    def _new_id(self) -> int:
        with self._cond:
            self._next_id += 1
            return self._next_id

    def channel(self, topic: str) -> dict | None:
        """The advertised channel of ``topic``, or None."""
        with self._cond:
            return next((c for c in self.received.channels.values() if c["topic"] == topic), None)

    def subscribe(self, channel_id: int) -> int:
        """Subscribe to a channel; return the subscription id its messages come with."""
        subscription = self._new_id()
        self._subscriptions[subscription] = channel_id
        self._ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": subscription, "channelId": channel_id}]}))
        return subscription

    def call_service(self, name: str, payload: bytes, encoding: str = "cdr") -> int:
        """Send a service call request to the advertised service ``name``; return its call id."""
        service_id = self.received.services[name]["id"]
        call = self._new_id()
        enc = encoding.encode()
        self._ws.send(b"\x02" + struct.pack("<III", service_id, call, len(enc)) + enc + payload)
        return call

    def get_parameters(self, names: list[str], request_id: str) -> None:
        self._ws.send(json.dumps({"op": "getParameters", "parameterNames": names, "id": request_id}))

    def set_parameters(self, parameters: list[dict], request_id: str) -> None:
        self._ws.send(json.dumps({"op": "setParameters", "parameters": parameters, "id": request_id}))

    def parameters_reply(self, request_id: str) -> Callable[[Received], dict[str, Any] | None]:
        """A condition for :meth:`wait_for`: the reply to ``request_id`` as {name: value}."""
        def condition(r: Received) -> dict[str, Any] | None:
            for msg in r.parameter_values:
                if msg.get("id") == request_id:
                    return {p["name"]: p.get("value") for p in msg["parameters"]} or {"": None}
            return None

        return condition

    def playback_control(self, play: bool, speed: float, seek_ns: int | None, request_id: str) -> None:
        """Send a playback control request: Play (else Pause) at ``speed``, seeking to ``seek_ns`` when given."""
        rid = request_id.encode()
        self._ws.send(b"\x03" + struct.pack("<BfBQI", 0 if play else 1, speed, seek_ns is not None, seek_ns or 0,
                                            len(rid)) + rid)

    def playback_reply(self, request_id: str) -> Callable[[Received], PlaybackState | None]:
        """A condition for :meth:`wait_for`: the playback state answering ``request_id``."""
        return lambda r: next((s for s in r.playback if s.request_id == request_id), None)

    def close(self) -> None:
        self._stack.close()
        self._reader.join(5)

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
