"""Node ``rimd_rerun``: streams the rig topics to Rerun (docs/rerun.md) and, if asked, to Foxglove (docs/foxglove.md).

A thin adapter: subscriptions to the rig topics (relative names, namespace ``/rig`` by default) hand each
message to :class:`rimd_sim.viz.rerun_map.RigMapper`, which logs it to a :class:`rimd_sim.viz.sinks.RerunStream`
(``sink``: ``save`` an ``.rrd``, ``spawn`` a viewer, ``connect`` to a URL, ``serve_web`` on loopback).
The channels go as their display stream by default: per ``display_interval`` (5 ms) each channel's smallest and
largest sample at their own times (:mod:`rimd_sim.viz.display`; every peak exact, a bounded rate a browser keeps
up with); ``display_interval`` 0 sends every sample (full rate).
With ``foxglove.enabled`` the same raw messages also go, bytes unchanged, to a Foxglove WebSocket server
(:class:`rimd_sim.ros.nodes._foxglove.FoxgloveRelay`, which also subscribes to the other rig topics, forwards the
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

from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from rimd_msgs.msg import ImpactEvent, RigState, SampleBlock
from rimd_sim.errors import ConfigError
from rimd_sim.io.cdr import header_stamp, read_block
from rimd_sim.ros.clients.progress import ProgressReporter
from rimd_sim.ros.nodes.feed import DirectProgress, InProcessFeed
from rimd_sim.ros.nodes.polling import PolledSubscriptions, PollingNode
from rimd_sim.settings.params import build, to_flat
from rimd_sim.viz.bridge_settings import PARAMETERS, BridgeSettings
from rimd_sim.viz.foxglove_sink import FoxgloveError
from rimd_sim.viz.rerun_map import CHANNELS, EVENTS_TOPIC, TRUTH_TOPIC, RigMapper, blueprint, stamp_ns
from rimd_sim.viz.sinks import RerunStream, SinkError, spec_from_parameters

__all__ = ["RerunBridgeNode", "main"]

NODE_NAME = "rimd_rerun"
#: Period of the takes from the block subscriptions (s); their history (500 blocks) holds seconds of it. It follows
#: the traffic (:class:`~rimd_sim.ros.nodes.polling.PollPeriod`), from POLL_PERIOD_S (fast) to POLL_LONGEST_S (slow).
POLL_PERIOD_S = 0.01
POLL_LONGEST_S = 0.05
#: Period of the full flush (s) when ``batch_interval`` is 0; otherwise the flush follows ``batch_interval``.
FLUSH_PERIOD_S = 0.25
SAMPLE_BLOCK, RIG_STATE = "rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState"
DEFAULT_NAMESPACE = "rig"

class RerunBridgeNode(PollingNode):
    """The Rerun bridge node. See the module docstring."""

    NODE_NAME = NODE_NAME
    NAMESPACE = DEFAULT_NAMESPACE
    REFUSED = (SinkError, FoxgloveError, ConfigError)
    REFUSED_STATUS = 1

    def __init__(self, feed: InProcessFeed | None = None, **kwargs: Any) -> None:
        """Declare parameters, open the sink (SinkError: refused, see REFUSED), subscribe.

        Args:
            feed: In the composed rig (:mod:`rimd_sim.ros.nodes.composed`): the rig topics come from it, in this
                process, and the lockstep progress goes to it.
            kwargs: As rclpy's ``Node`` takes them.
        """
        super().__init__(**kwargs)
        settings = build(BridgeSettings, self.declare(PARAMETERS))   # ConfigError: refused
        p = to_flat(settings)
        if not p["rerun"] and not p["foxglove.enabled"]:
            raise FoxgloveError("rerun and foxglove.enabled are both false: the bridge would serve nothing")
        spec = spec_from_parameters(p)
        self.stream: RerunStream | None = None
        self.mapper: RigMapper | None = None
        self.foxglove: Any = None
        # The block topics arrive serialized and are read in place (rimd_sim.io.cdr.read_block: the
        # samples as NumPy views, no message objects), because rclpy's deserialisation would take a large share
        # of the bridge's time. They are taken by a timer, every message waiting at once (nodes.polling.
        # PolledSubscriptions): one wake-up per period instead of one dispatch per message.
        # With Foxglove on, the same raw messages go to it too (one subscription per topic); the impact events
        # then arrive raw as well and are deserialised for Rerun only.
        self._polled = PolledSubscriptions(self, POLL_PERIOD_S, longest=POLL_LONGEST_S)
        ns = self.get_namespace().rstrip("/")
        if p["foxglove.enabled"]:   # first: a refused address or a taken port starts no Rerun viewer
            from rimd_sim.ros.nodes._foxglove import FoxgloveRelay

            shared = {f"{ns}/{ch.topic}": SAMPLE_BLOCK for ch in CHANNELS} | {
                f"{ns}/{TRUTH_TOPIC}": RIG_STATE, f"{ns}/{EVENTS_TOPIC}": "rimd_msgs/msg/ImpactEvent"}
            self.foxglove = FoxgloveRelay(
                self, self._polled, host=str(p["foxglove.host"]), port=int(p["foxglove.port"]),
                topics=list(p["foxglove.topics"]), parameter_nodes=list(p["foxglove.parameter_nodes"]),
                call_timeout=float(p["foxglove.call_timeout"]), shared=shared,
                playback_node=str(p["foxglove.playback_node"]))
        if p["rerun"]:
            try:
                self.stream = RerunStream(spec, blueprint(window=float(p["window"]), trail=float(p["trail"])),
                                          recording_name=f"rimd {self.get_namespace()}")
            except SinkError:
                if self.foxglove is not None:
                    self.foxglove.close()
                raise
            self.mapper = RigMapper(self.stream.rec, natural_frequency=float(p["natural_frequency"]),
                                    batch=int(p["batch_blocks"]), min_interval=float(p["batch_interval"]),
                                    display_interval=float(p["display_interval"]))
            self.mapper.log_static()
        self._lags: deque[float] = deque(maxlen=10_000)
        self._received = 0
        self._undecodable = 0
        self._slowest = 0.0  # s, longest message handling since the last status line

        reliability = ReliabilityPolicy.RELIABLE if p["reliable"] else ReliabilityPolicy.BEST_EFFORT
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=500, reliability=reliability)
        events_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=reliability)
        # The impact events (a few per second) are an ordinary subscription.
        # Lockstep (docs/rig.md): once these subscriptions have matched, the bridge joins a rig or replay in
        # lockstep under its node name and reports how far it has taken each topic.
        self._progress: ProgressReporter | DirectProgress = (
            ProgressReporter(self, self.get_name()) if feed is None else feed.progress(self.get_name()))
        if feed is not None:   # the composed rig: the same handlers, fed in this process
            subs: list[Any] = [self._polled.attach(feed.subscribe(f"{ns}/{ch.topic}", qos.depth),
                                                   self._raw_handler(ch.topic, SAMPLE_BLOCK)) for ch in CHANNELS]
            subs.append(self._polled.attach(feed.subscribe(f"{ns}/{TRUTH_TOPIC}", qos.depth),
                                            self._raw_handler(TRUTH_TOPIC, RIG_STATE)))
            events = self._raw_events_handler()
            subs.append(self._polled.attach(feed.subscribe(f"{ns}/{EVENTS_TOPIC}", events_qos.depth),
                                            lambda data, info: events(data)))
        else:
            subs = [self._polled.create(SampleBlock, ch.topic, qos, self._raw_handler(ch.topic, SAMPLE_BLOCK))
                    for ch in CHANNELS]
            subs.append(self._polled.create(RigState, TRUTH_TOPIC, qos, self._raw_handler(TRUTH_TOPIC, RIG_STATE)))
            if self.foxglove is not None:
                subs.append(self.create_subscription(ImpactEvent, EVENTS_TOPIC, self._raw_events_handler(),
                                                     events_qos, raw=True))
            else:
                subs.append(self.create_subscription(ImpactEvent, EVENTS_TOPIC, self._handler(EVENTS_TOPIC),
                                                     events_qos))
        for sub in subs:
            self._progress.add_subscription(sub)
        if feed is not None:   # in the composed rig the poll's last progress goes at its end, not on a timer
            self._polled.after = self._progress.flush
        if self.mapper is not None:   # a paused rig leaves no batch pending for long
            period = float(p["batch_interval"])
            if period > 0:
                self.create_timer(period, self.mapper.flush_due)
            else:
                self.create_timer(FLUSH_PERIOD_S, self.mapper.flush)
        if p["status_period"] > 0:
            self.create_timer(float(p["status_period"]), self._report)
        if self.stream is not None:
            assert self.mapper is not None   # made with the stream
            self.get_logger().info(
                f"rerun bridge ready: sink {spec.kind} -> {self.stream.viewer_url}; topics under "
                f"{self.get_namespace()}; channels {self._channels_shown()}; "
                f"analytics {'per user config' if spec.analytics else 'off'}")
        if self.foxglove is not None:
            replay = p["foxglove.playback_node"]
            self.get_logger().info(
                f"foxglove server ready: {self.foxglove.url} (open it in Foxglove: Open connection > Foxglove "
                f"WebSocket); {len(self.foxglove.sink.topics)} topics so far, "
                + (f"the timeline drives the replay {replay} (playback control once it answers)" if replay else
                   f"services and parameters under {self.get_namespace()}"))


    def _channels_shown(self) -> str:
        """How the channels are sent: the display stream's interval, or full rate."""
        assert self.mapper is not None
        interval = self.mapper.display_interval_ns / 1e9
        if interval:
            return f"as a display stream (min and max per {interval * 1e3:g} ms; display_interval 0 = full rate)"
        return "at full rate (every sample)"

    def _raw_handler(self, topic: str, type_name: str):
        on_message = self._handler(topic)
        relay = self.foxglove
        full = f"{self.get_namespace().rstrip('/')}/{topic}"
        if relay is not None and not relay.wanted(full):
            relay = None

        progress = self._progress

        def on_raw(data: bytes, info: dict) -> None:  # the message info is not used
            if relay is not None:
                relay.on_message(full, data)
            if self.mapper is not None:
                try:
                    view = read_block(data, type_name)
                except ValueError as exc:
                    self._undecodable += 1
                    if self._undecodable <= 5:
                        self.get_logger().error(f"{topic}: a message that is not a {type_name} ({exc}): skipped")
                    return
                on_message(view)
            stamp = header_stamp(data)
            if stamp is not None:
                progress.done(stamp, topic=full)

        return on_raw

    def _raw_events_handler(self):
        """The impact events as bytes: to Foxglove as they are, deserialised for Rerun (also in the composed rig)."""
        from rclpy.serialization import deserialize_message

        on_message = self._handler(EVENTS_TOPIC)
        relay = self.foxglove
        full = f"{self.get_namespace().rstrip('/')}/{EVENTS_TOPIC}"

        def on_raw(data: bytes) -> None:
            if relay is not None and relay.wanted(full):
                relay.on_message(full, data)
            if self.mapper is not None:
                on_message(deserialize_message(data, ImpactEvent))
            else:
                stamp = header_stamp(data)
                if stamp is not None:
                    self._progress.done(stamp, topic=full)

        return on_raw

    def _handler(self, topic: str):
        full = f"{self.get_namespace().rstrip('/')}/{topic}"

        def on_message(msg: Any) -> None:
            self._received += 1
            assert self.mapper is not None   # called only with Rerun on
            start = time.perf_counter()
            self.mapper.log_message(topic, msg)
            self._slowest = max(self._slowest, time.perf_counter() - start)
            if topic == EVENTS_TOPIC:   # the blocks are reported by their raw handler
                self._progress.done(msg.header.stamp, topic=full)
            if topic == "impact/force":
                end_ns = stamp_ns(msg.header.stamp) + round(len(msg.samples) * 1e9 / msg.sample_rate)
                lag = (time.time_ns() - end_ns) / 1e9
                if abs(lag) < 86_400:   # wall-clock stamps (real time); simulation-time stamps give no lag
                    self._lags.append(lag)

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
        shown = f"; {sum(s.points.values())} display points" if self.mapper.display_interval_ns else ""
        self.get_logger().info(
            f"status: {self._received} messages, {sum(s.samples.values())} samples, {s.impacts} impacts, "
            f"{s.poincare_points} Poincare points, {sum(s.gaps.values())} gaps; {lag}{shown}")

    def finish(self) -> int:
        """At the stop: close (:meth:`close`) and say what was delivered; 1 when the last data was not."""
        status = 0
        problem = self.close()
        if problem:
            print(f"rimd_rerun: {problem}", file=sys.stderr)
            status = 1
        if self.foxglove is not None:
            print(f"rimd_rerun: closed the Foxglove server {self.foxglove.url}: {self.foxglove.forwarded} messages "
                  "forwarded", flush=True)
        if self.mapper is not None and self.stream is not None:
            s = self.mapper.stats
            shown = " ({} display points)" if self.mapper.display_interval_ns else ""
            print(f"rimd_rerun: closed {self.stream.viewer_url}: "
                  + ", ".join(f"{k} {v} samples" + shown.format(s.points.get(k, 0))
                              for k, v in sorted(s.samples.items()))
                  + f", {s.impacts} impacts, {sum(s.gaps.values())} gaps", flush=True)
        return status

    def close(self) -> str:
        """Close the Rerun stream and the Foxglove server (idempotent); "" or why the last data was not delivered.

        Leaves the lockstep first (a rig in lockstep stops waiting for the bridge).
        """
        if self.context.ok():
            self._progress.leave()
        if self.foxglove is not None:
            self.foxglove.close()
        if self.stream is None:
            return ""
        assert self.mapper is not None   # made with the stream
        self.mapper.flush()
        return self.stream.close()


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``rimd_rerun`` executable (also ``rimd node rerun``)."""
    return RerunBridgeNode.main(args)


if __name__ == "__main__":
    sys.exit(main())
