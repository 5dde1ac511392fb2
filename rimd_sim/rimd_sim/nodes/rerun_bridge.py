"""Node ``rimd_rerun``: streams the rig topics to Rerun (SPEC section 6) and, if asked, to Foxglove (issue 27).

A thin adapter: subscriptions to the rig topics (relative names, namespace ``/rig`` by default) hand each
message to :class:`rimd_sim.viz.rerun_map.RigMapper`, which logs it to a :class:`rimd_sim.viz.sinks.RerunStream`
(``sink``: ``save`` an ``.rrd``, ``spawn`` a viewer, ``connect`` to a URL, ``serve_web`` on loopback).
With ``foxglove.enabled`` the same raw messages also go, bytes unchanged, to a Foxglove WebSocket server
(:class:`rimd_sim.nodes._foxglove.FoxgloveRelay`, which also subscribes to the other rig topics, forwards the
rig's services and the simulator's parameters); ``rerun: false`` leaves Rerun out (Foxglove only).
Every ``status_period`` seconds it logs one line with what it has logged and its lag behind the data
(wall time now minus the stamp of a block's last sample: meaningful at ``real_time_factor`` 1, where stamps
are wall-clock). SIGINT or SIGTERM: the stream is flushed and closed (an ``.rrd`` gets its footer).
"""

from __future__ import annotations

import sys
import time
from collections import deque
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from rimd_msgs.msg import ImpactEvent, RigState, SampleBlock
from rimd_sim.nodes._params import refuse_unnamed
from rimd_sim.nodes._run import PolledSubscriptions, PollingNode, run_node
from rimd_sim.recording.cdr import read_block
from rimd_sim.viz.foxglove_sink import DEFAULT_HOST, DEFAULT_PORT, FoxgloveError
from rimd_sim.viz.rerun_map import CHANNELS, EVENTS_TOPIC, TRUTH_TOPIC, RigMapper, blueprint, stamp_ns
from rimd_sim.viz.sinks import SINKS, RerunStream, SinkError, spec_from_parameters

__all__ = ["RerunBridgeNode", "main"]

NODE_NAME = "rimd_rerun"
#: Period of the takes from the block subscriptions (s); their history (500 blocks) holds seconds of it.
POLL_PERIOD_S = 0.02
SAMPLE_BLOCK, RIG_STATE = "rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState"
DEFAULT_NAMESPACE = "rig"

#: name -> (default, description, (low, high) or None). Fixed after start (the sink is opened once).
PARAMETERS: dict[str, tuple[Any, str, tuple[float, float] | None]] = {
    "enabled": (True, "read by `rimd rig`: whether the bring-up starts this node (the node ignores it)", None),
    "sink": ("serve_web", f"where the stream goes: one of {', '.join(SINKS)}", None),
    "save_path": ("", "sink save: .rrd file to write ('' = ./rimd_<UTC timestamp>.rrd)", None),
    "url": ("rerun+http://127.0.0.1:9876/proxy", "sink connect: gRPC URL of a running viewer or server", None),
    "grpc_port": (0, "sinks spawn/serve_web: gRPC port of the viewer/server started (0 = a free port)", (0, 65535)),
    "web_port": (0, "sink serve_web: HTTP port of the web viewer on 127.0.0.1 (0 = a free port)", (0, 65535)),
    "memory_limit": ("1GiB", "sinks spawn/serve_web: memory limit of the viewer/server (oldest data dropped)", None),
    "analytics": (False, "let Rerun report usage per the user's Rerun configuration (default: off)", None),
    "natural_frequency": (1.82, "Hz: the phase plane's velocity axis is v_rel / (2 pi f)", (0.01, 1000.0)),
    "window": (2.0, "s of channel data the time-series views show", (0.01, 3600.0)),
    "trail": (1.0, "s of phase-plane trajectory shown (trailing line)", (0.01, 3600.0)),
    "batch_blocks": (10, "blocks of a channel sent per send_columns call (1 = one call per block; more = less CPU, "
                     "up to that many block periods of latency)", (1, 1000)),
    "reliable": (True, "reliable subscriptions (false: best effort, matches best-effort channels)", None),
    "status_period": (10.0, "s between status lines (0 = none)", (0.0, 3600.0)),
    "rerun": (True, "stream to Rerun (false: the Foxglove server only, which foxglove.enabled must then turn on)",
              None),
    "foxglove.enabled": (False, "serve the Foxglove WebSocket protocol: the rig topics (cdr, ros2msg schemas), "
                         "the rig's services, the parameters of foxglove.parameter_nodes, the rig clock", None),
    "foxglove.host": (DEFAULT_HOST, "IP address the Foxglove server binds (127.0.0.1 = this machine only)", None),
    "foxglove.port": (DEFAULT_PORT, "TCP port of the Foxglove server (0 = a free port, logged)", (0, 65535)),
    "foxglove.topics": (["/rig/.*", "/clock", "/diagnostics"], "topics offered to Foxglove: regular expressions "
                        "(full match)", None),
    "foxglove.parameter_nodes": (["/rig/rimd_simulator"], "nodes whose parameters Foxglove reads and sets, "
                                 "through their own parameter services ('' entries ignored)", None),
    "foxglove.call_timeout": (3.0, "s to wait for the answer of a forwarded service call or parameter request",
                              (0.1, 60.0)),
}
_TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING,
          list: ParameterType.PARAMETER_STRING_ARRAY}


def _descriptor(name: str) -> ParameterDescriptor:
    default, description, bounds = PARAMETERS[name]
    desc = ParameterDescriptor(name=name, type=_TYPES[type(default)], description=description, read_only=True,
                               dynamic_typing=isinstance(default, float))
    if bounds is not None and isinstance(default, float):
        desc.floating_point_range = [FloatingPointRange(from_value=bounds[0], to_value=bounds[1], step=0.0)]
    elif bounds is not None:
        desc.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]), step=0)]
    return desc


class RerunBridgeNode(PollingNode):
    """The Rerun bridge node. See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare parameters, open the sink (SinkError: caught in main), subscribe."""
        kwargs.setdefault("namespace", DEFAULT_NAMESPACE)
        super().__init__(NODE_NAME, **kwargs)
        for name, (default, _, _) in PARAMETERS.items():
            self.declare_parameter(name, default, _descriptor(name))
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        if not p["rerun"] and not p["foxglove.enabled"]:
            raise FoxgloveError("rerun and foxglove.enabled are both false: the bridge would serve nothing")
        spec = spec_from_parameters(p)
        self.stream: RerunStream | None = None
        self.mapper: RigMapper | None = None
        self.foxglove: Any = None
        # The block topics arrive serialized and are read in place (rimd_sim.recording.cdr.read_block: the
        # samples as NumPy views, no message objects): a third of the bridge's time went to rclpy's
        # deserialisation. They are taken by a timer, every message waiting at once (nodes._run.
        # PolledSubscriptions): one wake-up per period instead of one dispatch per message.
        # With Foxglove on, the same raw messages go to it too (one subscription per topic); the impact events
        # then arrive raw as well and are deserialised for Rerun only.
        self._polled = PolledSubscriptions(self, POLL_PERIOD_S)
        ns = self.get_namespace().rstrip("/")
        if p["foxglove.enabled"]:   # first: a refused address or a taken port starts no Rerun viewer
            from rimd_sim.nodes._foxglove import FoxgloveRelay

            shared = {f"{ns}/{ch.topic}": SAMPLE_BLOCK for ch in CHANNELS} | {
                f"{ns}/{TRUTH_TOPIC}": RIG_STATE, f"{ns}/{EVENTS_TOPIC}": "rimd_msgs/msg/ImpactEvent"}
            self.foxglove = FoxgloveRelay(
                self, self._polled, host=str(p["foxglove.host"]), port=int(p["foxglove.port"]),
                topics=list(p["foxglove.topics"]), parameter_nodes=list(p["foxglove.parameter_nodes"]),
                call_timeout=float(p["foxglove.call_timeout"]), shared=shared)
        if p["rerun"]:
            try:
                self.stream = RerunStream(spec, blueprint(window=float(p["window"]), trail=float(p["trail"])),
                                          recording_name=f"rimd {self.get_namespace()}")
            except SinkError:
                if self.foxglove is not None:
                    self.foxglove.close()
                raise
            self.mapper = RigMapper(self.stream.rec, natural_frequency=float(p["natural_frequency"]),
                                    batch=int(p["batch_blocks"]))
            self.mapper.log_static()
        self._lags: deque[float] = deque(maxlen=10_000)
        self._received = 0
        self._undecodable = 0
        self._slowest = 0.0  # s, longest message handling since the last status line

        reliability = ReliabilityPolicy.RELIABLE if p["reliable"] else ReliabilityPolicy.BEST_EFFORT
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=500, reliability=reliability)
        events_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=reliability)
        # The impact events (a few per second) are an ordinary subscription.
        for ch in CHANNELS:
            self._polled.create(SampleBlock, ch.topic, qos, self._raw_handler(ch.topic, SAMPLE_BLOCK))
        self._polled.create(RigState, TRUTH_TOPIC, qos, self._raw_handler(TRUTH_TOPIC, RIG_STATE))
        if self.foxglove is not None:
            self.create_subscription(ImpactEvent, EVENTS_TOPIC, self._raw_events_handler(), events_qos, raw=True)
        else:
            self.create_subscription(ImpactEvent, EVENTS_TOPIC, self._handler(EVENTS_TOPIC), events_qos)
        if self.mapper is not None:
            self.create_timer(0.25, self.mapper.flush)  # a paused rig leaves no batch pending for long
        if p["status_period"] > 0:
            self.create_timer(float(p["status_period"]), self._report)
        if self.stream is not None:
            self.get_logger().info(
                f"rerun bridge ready: sink {spec.kind} -> {self.stream.viewer_url}; topics under "
                f"{self.get_namespace()}; analytics {'per user config' if spec.analytics else 'off'}")
        if self.foxglove is not None:
            self.get_logger().info(
                f"foxglove server ready: {self.foxglove.url} (open it in Foxglove: Open connection > Foxglove "
                f"WebSocket); {len(self.foxglove.sink.topics)} topics so far, services and parameters under "
                f"{self.get_namespace()}")


    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        """Set parameters; rclpy's parameter services come here. Every refusal names the parameter."""
        refusal = refuse_unnamed(self, parameter_list)
        return refusal if refusal is not None else super().set_parameters_atomically(parameter_list)

    def _raw_handler(self, topic: str, type_name: str):
        on_message = self._handler(topic)
        relay = self.foxglove
        full = f"{self.get_namespace().rstrip('/')}/{topic}"
        if relay is not None and not relay.wanted(full):
            relay = None

        def on_raw(data: bytes, info: dict) -> None:  # noqa: ARG001 - the message info is not used
            if relay is not None:
                relay.on_message(full, data)
            if self.mapper is None:
                return
            try:
                view = read_block(data, type_name)
            except ValueError as exc:
                self._undecodable += 1
                if self._undecodable <= 5:
                    self.get_logger().error(f"{topic}: a message that is not a {type_name} ({exc}): skipped")
                return
            on_message(view)

        return on_raw

    def _raw_events_handler(self):
        """The impact events as bytes: to Foxglove as they are, deserialised for Rerun."""
        from rclpy.serialization import deserialize_message

        on_message = self._handler(EVENTS_TOPIC)
        relay = self.foxglove
        full = f"{self.get_namespace().rstrip('/')}/{EVENTS_TOPIC}"

        def on_raw(data: bytes) -> None:
            if relay.wanted(full):
                relay.on_message(full, data)
            if self.mapper is not None:
                on_message(deserialize_message(data, ImpactEvent))

        return on_raw

    def _handler(self, topic: str):
        def on_message(msg: Any) -> None:
            self._received += 1
            start = time.perf_counter()
            self.mapper.log_message(topic, msg)
            self._slowest = max(self._slowest, time.perf_counter() - start)
            if topic == "impact/force":
                end_ns = stamp_ns(msg.header.stamp) + round(len(msg.samples) * 1e9 / msg.sample_rate)
                self._lags.append((time.time_ns() - end_ns) / 1e9)

        return on_message

    def _report(self) -> None:
        if self.foxglove is not None:
            self.get_logger().info(f"foxglove status: {self.foxglove.forwarded} messages forwarded on "
                                   f"{len(self.foxglove.sink.topics)} topics; {self.foxglove.url}")
        if self.mapper is None:
            return
        lags = sorted(self._lags)
        self._lags.clear()
        s = self.mapper.stats
        lag = (f"lag p50 {lags[len(lags) // 2] * 1e3:.1f} ms, max {lags[-1] * 1e3:.1f} ms" if lags
               else "lag n/a")
        lag += f", slowest message {self._slowest * 1e3:.1f} ms"
        self._slowest = 0.0
        self.get_logger().info(
            f"status: {self._received} messages, {sum(s.samples.values())} samples, {s.impacts} impacts, "
            f"{s.poincare_points} Poincare points, {sum(s.gaps.values())} gaps; {lag}")

    def close(self) -> str:
        """Close the Rerun stream and the Foxglove server (idempotent); "" or why the last data was not delivered."""
        if self.foxglove is not None:
            self.foxglove.close()
        if self.stream is None:
            return ""
        self.mapper.flush()
        return self.stream.close()


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``rimd_rerun`` executable (also ``rimd node rerun``)."""

    def close(node: RerunBridgeNode) -> int:
        status = 0
        problem = node.close()
        if problem:
            print(f"rimd_rerun: {problem}", file=sys.stderr)
            status = 1
        if node.foxglove is not None:
            print(f"rimd_rerun: closed the Foxglove server {node.foxglove.url}: {node.foxglove.forwarded} messages "
                  "forwarded", flush=True)
        if node.mapper is not None:
            s = node.mapper.stats
            print(f"rimd_rerun: closed {node.stream.viewer_url}: "
                  + ", ".join(f"{k} {v} samples" for k, v in sorted(s.samples.items()))
                  + f", {s.impacts} impacts, {sum(s.gaps.values())} gaps", flush=True)
        return status

    return run_node("rimd_rerun", RerunBridgeNode, (SinkError, FoxgloveError), args=args, refused_status=1,
                    close=close)

if __name__ == "__main__":
    sys.exit(main())
