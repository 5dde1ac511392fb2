"""Node ``rimd_replay``: republishes a recording with its original timing, driven like rosbag2's player.

A thin adapter over :class:`rimd_sim.runtime.replay.Player` (what goes next and when, the controls) and
:func:`rimd_sim.io.reader.open_recording` (a truncated or damaged file replays what is readable; the
node first says what was lost). Each message is published as the recorded bytes (a raw publish: what a
subscriber gets is byte for byte what was recorded, or restamped with ``restamp``) on a publisher with the QoS
the original publishers offered (reliability, durability) and a deep history.

Services, with rosbag2's player names (types: ``std_srvs/srv/Trigger`` for pause, resume and toggle_paused,
which answer a message where rosbag2's answer nothing; ``rimd_msgs/srv`` IsPaused, GetRate, SetRate, Seek,
PlayNext, Burst for the others, with rosbag2_interfaces' fields, since that package is not installable here):
``~/pause``, ``~/resume``, ``~/toggle_paused``, ``~/is_paused``, ``~/get_rate``, ``~/set_rate``, ``~/seek``,
``~/play_next``, ``~/burst``; and ``~/get_state`` (``rimd_msgs/srv/GetReplayState``: the part played, the
position, paused, ended, rate, passes, seeks and messages published in one snapshot, for a client that shows a
timeline). With ``keep_alive`` the node stays up at the end, where ``~/seek`` plays again. Parameters:
:class:`rimd_sim.runtime.replay.ReplaySettings` (one declaration each); in lockstep (``lockstep.*``) the
replay waits for its consumers like the simulator, publishes ``/clock`` and names each pass on ``/rig/session``
(reason ``replay``).
"""

from __future__ import annotations

import importlib
import re
import sys
import threading
import time
from typing import Any

import yaml
from rclpy.duration import Duration
from rclpy.executors import Executor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from rimd_msgs.msg import ConsumerProgress, RigSession
from rimd_msgs.srv import Burst, GetRate, GetReplayState, IsPaused, PlayNext, Seek, SetRate
from rimd_sim.errors import ConfigError, InputError
from rimd_sim.io.reader import Recording, RecordingError, open_recording
from rimd_sim.ros.clients.progress import PROGRESS_TOPIC, SESSION_QOS, SESSION_TOPIC, listen_for_progress
from rimd_sim.ros.nodes._stop import StopRequest
from rimd_sim.ros.nodes.base import RimdNode, spin_until_stopped
from rimd_sim.runtime.pacing import Hold, Wait
from rimd_sim.runtime.replay import Finished, Paused, Player, ReplaySettings
from rimd_sim.runtime.threads import named_thread
from rimd_sim.settings.params import build, parameters

__all__ = ["PARAMETERS", "ReplayError", "ReplayNode", "main"]

NODE_NAME = "rimd_replay"
#: The replay's parameters by name (one declaration each: ReplaySettings).
PARAMETERS = parameters(ReplaySettings)
#: Longest wait for subscribers (wait_for_subscribers), s.
SUBSCRIBER_WAIT_S = 10.0
#: After the publishers have matched the subscriptions waited for, the time left to the subscriptions to match
#: the publishers: discovery is two-sided, and a volatile subscription of Fast DDS drops what arrives from a
#: publisher it has not matched yet (its first messages, never sent again).
DISCOVERY_SETTLE_S = 0.5
#: At the end, how long reliable subscribers get to acknowledge the last messages before the node goes away.
ACKNOWLEDGE_WAIT_S = 5.0
#: A lockstep hold is logged once it has lasted this long (s), then every 10 s.
HOLD_REPORT_S = 0.5


class ReplayError(InputError):
    """The replay cannot start; the message says why (bad parameter, unreadable file, unknown types)."""


def _message_class(type_name: str):
    pkg, _, name = type_name.partition("/msg/")
    if not pkg or not name:
        raise ImportError(type_name)
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _qos(offered: str) -> QoSProfile:
    reliable, latched = True, False
    try:
        profiles = yaml.safe_load(offered) if offered else []
        if profiles:
            reliable = all(str(p.get("reliability", "reliable")).lower() in ("reliable", "1") for p in profiles)
            latched = all(str(p.get("durability", "volatile")).lower() in ("transient_local", "1")
                          for p in profiles)
    except (yaml.YAMLError, AttributeError):
        pass
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def parse_remap(entries: tuple[str, ...] | list[str]) -> dict[str, str]:
    """Parse ``"/from:=/to"`` entries (empty entries ignored)."""
    remap = {}
    for entry in entries:
        if not entry:
            continue
        source, sep, target = entry.partition(":=")
        if not sep or not source.startswith("/") or not target.startswith("/"):
            raise ReplayError(f"remap: '{entry}' refused: expected '/from:=/to' with absolute topic names")
        remap[source] = target
    return remap


def _patterns(key: str, values: tuple[str, ...]) -> list[re.Pattern[str]]:
    try:
        return [re.compile(x) for x in values if x]
    except re.error as exc:
        raise ReplayError(f"{key}: not a regular expression ({exc})") from None


def check_parameters(values: dict[str, Any]) -> ReplaySettings:
    """The replay's settings from its parameters; ReplayError names the first refused one and its rule."""
    try:
        settings = build(ReplaySettings, values)
    except ConfigError as exc:
        raise ReplayError(str(exc)) from None
    if not settings.file:
        raise ReplayError("file: no recording given (set -p file:=REC.mcap or a recording directory)")
    return settings


class ReplayNode(RimdNode):
    """The replay node. See the module docstring."""

    NODE_NAME = NODE_NAME
    REFUSED = (ReplayError,)
    REFUSED_STATUS = 1

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        p = self._p = check_parameters(self.declare(PARAMETERS))
        patterns = _patterns("topics", p.topics)
        self._wait_patterns = _patterns("wait_topics", p.wait_topics)
        remap = parse_remap(p.remap)
        try:
            self._recording: Recording = open_recording(p.file)
        except RecordingError as exc:
            raise ReplayError(str(exc)) from None
        log = self.get_logger()
        for report in self._recording.reports:
            (log.info if report.complete else log.warning)(report.describe())
        self._lockstep = p.lockstep.enabled
        self._with_clock = p.clock or self._lockstep
        # The replay names its own runs on /rig/session: a recorded session is not replayed.
        skip = {SESSION_TOPIC} | ({"/clock"} if self._with_clock else set())
        selected = {name: topic for name, topic in self._recording.topics.items()
                    if any(x.fullmatch(name) for x in patterns) and name not in skip}
        unknown = {}
        self._pubs: dict[str, Any] = {}
        for name, topic in sorted(selected.items()):
            try:
                msg_type = _message_class(topic.type_name)
            except (ImportError, AttributeError):
                unknown[name] = topic.type_name or "(no schema)"
                continue
            self._pubs[name] = self.create_publisher(msg_type, remap.get(name, name), _qos(topic.offered_qos_profiles))
        if unknown:
            listing = ", ".join(f"{t} ({name})" for name, t in unknown.items())
            if not p.skip_unknown:
                raise ReplayError(f"the recording has message types not installed here: {listing}; install their "
                                  "packages, leave the topics out with -p topics:=..., or set skip_unknown:=true")
            log.warning(f"not replaying topics of unknown types: {listing}")
        if not self._pubs:
            # A damaged recording may have lost every topic with its first chunk: say so in the one line.
            damage = "; ".join(r.describe() for r in self._recording.reports if not r.complete)
            raise ReplayError(f"nothing to replay: no topic of {p.file} matches {list(p.topics)}"
                              + (f" (the recording is damaged: {damage})" if damage else ""))
        try:
            self.player = Player(self._recording, self._pubs, p,
                                 published_name=lambda t: self._pubs[t].topic_name)
        except ConfigError as exc:
            raise ReplayError(str(exc)) from None
        self._clock_pub = self.create_publisher(Clock, "/clock", 1000) if self._with_clock else None
        self._session_pub = self.create_publisher(RigSession, remap.get(SESSION_TOPIC, SESSION_TOPIC), SESSION_QOS)
        if self._lockstep:   # a transient local writer's join reaches it at the match, too
            listen_for_progress(self, self._on_progress, remap.get(PROGRESS_TOPIC, PROGRESS_TOPIC))
        self._stop = threading.Event()
        self._wake = threading.Event()
        self.finished = threading.Event()
        self._last_clock: int | None = None
        self._hold_logged = 0.0
        self._warned: set[tuple[str, str]] = set()
        for name, srv, handler in (("pause", Trigger, self._on_pause), ("resume", Trigger, self._on_resume),
                                   ("toggle_paused", Trigger, self._on_toggle), ("is_paused", IsPaused,
                                   self._on_is_paused), ("get_rate", GetRate, self._on_get_rate),
                                   ("set_rate", SetRate, self._on_set_rate), ("seek", Seek, self._on_seek),
                                   ("play_next", PlayNext, self._on_play_next), ("burst", Burst, self._on_burst),
                                   ("get_state", GetReplayState, self._on_get_state)):
            self.create_service(srv, f"~/{name}", handler)
        self._thread = named_thread(self._run, "rimd-replay")
        window = (f" from {p.start_offset:g} s" if p.start_offset else "") + (
            f" for {p.playback_duration:g} s" if p.playback_duration else "")
        # The count is the recording's: name what of it is not replayed, so that the end's count adds up.
        left = sorted(set(self._recording.topics) - set(self._pubs))
        more = f" and {len(left) - 5} more" if len(left) > 5 else ""
        not_replayed = f"; not replayed: {', '.join(left[:5])}{more}" if left else ""
        log.info(f"replaying {len(self._pubs)} topics of {p.file} ({self._recording.message_count} messages in the "
                 f"recording{not_replayed}){window} "
                 f"at {p.rate:g}x" + (", looping" if p.loop else "") + (", restamped" if p.restamp else "")
                 + (f", in lockstep with {', '.join(p.lockstep.consumers)}" if self._lockstep else "")
                 + (", kept alive at the end" if p.keep_alive else "")
                 + (" (paused: ~/resume, ~/play_next or ~/burst)" if p.start_paused else ""))

    def start(self) -> None:
        """Start publishing (in a thread)."""
        self._thread.start()

    def spin_node(self, executor: Executor, stop: StopRequest) -> None:
        """Publish until the stop, or the end of the recording (then wait for the subscribers' acknowledgements)."""
        self.start()
        spin_until_stopped(executor, stop, done=self.finished.is_set)
        self.wait_for_acknowledgements()

    def finish(self) -> None:
        """At the stop: :meth:`stop`."""
        self.stop()

    def stop(self) -> None:
        """Stop publishing and wait for the thread."""
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    def wait_for_acknowledgements(self, timeout: float = ACKNOWLEDGE_WAIT_S) -> list[str]:
        """Give reliable subscribers the time to acknowledge the last messages before the node goes away.

        Returns (and names in a warning) the topics whose subscribers did not acknowledge everything in time.
        """
        deadline = time.monotonic() + timeout
        short = [pub.topic_name for pub in self._pubs.values()
                 if not pub.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))]
        if short:
            self.get_logger().warning(f"not acknowledged within {timeout:g} s by every subscriber: "
                                      f"{', '.join(sorted(short))}: they may miss the last messages")
        return short

    # -- the thread -------------------------------------------------------------------------------------------
    def _wait_for_subscribers(self) -> None:
        """Wait (bounded) for ``wait_for_subscribers`` matched subscribers, on the topics it names in the log."""
        wanted = self._p.wait_for_subscribers
        if wanted <= 0:
            return
        named = self._wait_patterns
        pubs = {name: pub for name, pub in self._pubs.items()
                if not named or any(x.fullmatch(pub.topic_name) for x in named)}
        if not pubs:
            self.get_logger().warning("wait_for_subscribers: no replayed topic matches wait_topics "
                                      f"{list(self._p.wait_topics)}: not waiting")
            return

        def waited() -> dict[str, Any]:
            if named:
                return pubs
            # Without wait_topics: the topics that have a subscriber in the graph (at least one must).
            return {n: p for n, p in pubs.items() if self.count_subscribers(p.topic_name) > 0}

        self.get_logger().info(f"waiting (at most {SUBSCRIBER_WAIT_S:g} s) for {wanted} matched subscriber(s) on "
                               + (", ".join(sorted(p.topic_name for p in pubs.values())) if named
                                  else "each replayed topic that has a subscriber"))
        deadline = time.monotonic() + SUBSCRIBER_WAIT_S
        while time.monotonic() < deadline and not self._stop.is_set():
            current = waited()
            if current and all(p.get_subscription_count() >= max(wanted, self.count_subscribers(p.topic_name))
                               for p in current.values()):
                self.get_logger().info("subscribers matched on " + ", ".join(sorted(p.topic_name
                                                                                    for p in current.values())))
                self._stop.wait(DISCOVERY_SETTLE_S)   # their side of the match
                return
            time.sleep(0.02)
        short = sorted(p.topic_name for p in (waited() or pubs).values() if p.get_subscription_count() < wanted)
        self.get_logger().warning(f"wait_for_subscribers: after {SUBSCRIBER_WAIT_S:g} s, fewer than {wanted} "
                                  f"subscriber(s) on {', '.join(short) or 'every replayed topic'}: replaying anyway")

    def _run(self) -> None:
        try:
            self._wait_for_subscribers()
            player = self.player
            player.start()
            at_end = False
            while not self._stop.is_set():
                if player.take_new_pass():
                    self._name_pass()
                outcome = player.step()
                for level, line in player.pacer_events():
                    (self.get_logger().error if level == "error" else self.get_logger().warning)(f"lockstep: {line}")
                if isinstance(outcome, list):
                    self._hold_logged = 0.0
                    at_end = False
                    for out in outcome:
                        self._publish(out)
                elif isinstance(outcome, Finished):
                    if not self._p.keep_alive:
                        break
                    if not at_end:
                        self.get_logger().info(f"replay at the end: {player.published} messages published; kept "
                                               "alive (keep_alive): ~/seek plays again")
                    at_end = True
                    self._wait(0.05)
                    continue
                elif isinstance(outcome, Hold):
                    self._on_hold(outcome)
                    self._wait(0.1)
                elif isinstance(outcome, Wait):
                    self._wait(min(outcome.seconds, 0.05))
                elif isinstance(outcome, Paused):
                    self._wait(0.05)
            self.get_logger().info(f"replay finished: {player.published} messages published")
        finally:
            self.finished.set()

    def _wait(self, seconds: float) -> None:
        self._wake.wait(seconds)
        self._wake.clear()

    def _publish(self, out: Any) -> None:
        if self._clock_pub is not None:
            period = 1e9 / self._p.clock_frequency
            if self._last_clock is None or out.log_time - self._last_clock >= period:
                clock = Clock()
                clock.clock.sec, clock.clock.nanosec = divmod(out.log_time, 1_000_000_000)
                self._clock_pub.publish(clock)
                self._last_clock = out.log_time
        self._pubs[out.topic].publish(out.data)

    def _name_pass(self) -> None:
        player = self.player
        msg = RigSession(run_id=player.run_id, reason="replay", sequence=player.passes - 1,
                         real_time_factor=float(player.rate), lockstep=self._lockstep,
                         node=self.get_fully_qualified_name(), time_base="recording")
        msg.header.frame_id = "rimd_replay"
        self._session_pub.publish(msg)

    def _on_hold(self, hold: Hold) -> None:
        now = time.monotonic()
        if now - hold.since < HOLD_REPORT_S or (self._hold_logged and now - self._hold_logged < 10.0):
            return
        self._hold_logged = now
        self.get_logger().warning(f"lockstep: holding for {now - hold.since:.1f} s, waiting for "
                                  f"{self.player.holders_text()}")

    def _on_progress(self, msg: ConsumerProgress) -> None:
        topics = None
        if msg.topics and len(msg.topics) == len(msg.topics_done_through):
            topics = {t: d.sec * 1_000_000_000 + d.nanosec for t, d in zip(msg.topics, msg.topics_done_through,
                                                                             strict=True)}
        done = msg.done_through.sec * 1_000_000_000 + msg.done_through.nanosec
        verdict = self.player.progress(msg.consumer, done, msg.instance, topics, leaving=msg.leaving)
        if verdict.log and verdict.accepted and verdict.reason != "topics":
            self.get_logger().info(f"lockstep: {verdict.log}")
        elif verdict.log and (msg.consumer, verdict.reason) not in self._warned:
            self._warned.add((msg.consumer, verdict.reason))
            self.get_logger().warning(f"lockstep: {verdict.log} (said once)")
        self._wake.set()

    # -- services ---------------------------------------------------------------------------------------------
    def _on_pause(self, request, response):
        response.success = self.player.pause()
        count = f"{self.player.published} messages published"   # taken: each reaches its subscribers
        response.message = f"paused after {count}" if response.success else f"already paused ({count})"
        return response

    def _on_resume(self, request, response):
        response.success = self.player.resume()
        response.message = "resumed" if response.success else "not paused"
        self._wake.set()
        return response

    def _on_toggle(self, request, response):
        paused = self.player.toggle()
        response.success, response.message = True, "paused" if paused else "resumed"
        self._wake.set()
        return response

    def _on_is_paused(self, request, response):
        response.paused = self.player.paused
        return response

    def _on_get_rate(self, request, response):
        response.rate = float(self.player.rate)
        return response

    def _on_set_rate(self, request, response):
        def set_rate() -> str:
            self.player.set_rate(request.rate)
            return f"rate {self.player.rate:g}"

        return self._answer(response, set_rate, "rate")

    def _on_seek(self, request, response):
        if request.time.nanosec >= 1_000_000_000:
            response.success = False
            response.message = f"time.nanosec = {request.time.nanosec} refused: must be < 1000000000"
            return response
        stamp = request.time.sec * 1_000_000_000 + request.time.nanosec
        return self._answer(response, lambda: f"sought: {self.player.seek(stamp)}", "time")

    def _answer(self, response, call, field: str):
        """Answer a player request: ``call()``'s message, or the refusal naming the request's ``field``."""
        try:
            message = call()
        except ConfigError as exc:
            response.success, response.message = False, str(exc).replace(f"parameter '{field}'", field, 1)
            return response
        response.success, response.message = True, message
        self._wake.set()
        return response

    def _on_get_state(self, request, response):
        state = self.player.state()
        for stamp, value in ((response.start, state.start_ns), (response.end, state.end_ns),
                             (response.position, state.position_ns)):
            stamp.sec, stamp.nanosec = divmod(value, 1_000_000_000)
        response.paused, response.ended, response.rate = state.paused, state.ended, state.rate
        response.passes, response.seeks, response.published = state.passes, state.seeks, state.published
        return response

    def _on_play_next(self, request, response):
        out = self.player.play_next()
        if out is not None:
            self._publish(out)
        response.success = out is not None
        return response

    def _on_burst(self, request, response):
        for out in (outs := self.player.burst(int(request.num_messages))):
            self._publish(out)
        response.actually_burst = len(outs)
        return response


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``rimd_replay`` executable (also ``rimd node replay``)."""
    return ReplayNode.main(args)


if __name__ == "__main__":
    sys.exit(main())
