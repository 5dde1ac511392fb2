"""Node ``rimd_replay``: republishes a recording with its original timing (SPEC section 6).

The recording (an MCAP file or a recording directory) is opened with :mod:`rimd_sim.recording.reader`: a
truncated or damaged file replays what is readable, and the node says first what was lost. Each message is
published as the recorded bytes (a raw publish: what a subscriber gets is byte for byte what was recorded)
when it is due: message ``i`` leaves at ``start + (log_time_i - log_time_first - start_offset) / rate`` of
the monotonic clock, shifted by the time spent paused. Publishers use the QoS the original publishers
offered (reliability, durability), with a deep history.

Parameters: ``file`` (required), ``rate`` (> 0), ``loop``, ``start_offset`` (s into the recording),
``topics`` (regular expressions, full match; default all), ``remap`` (``"/from:=/to"`` entries), ``clock``
(publish ``/clock`` from the recorded log time at ``clock_frequency`` Hz; a recorded ``/clock`` is then not
replayed), ``start_paused``, ``wait_for_subscribers`` (wait, up to 10 s, until every publisher has this many
subscribers), ``skip_unknown`` (replay the other topics when some types are not installed; otherwise the
node refuses to start and names them). Services ``~/pause`` and ``~/resume`` (``std_srvs/srv/Trigger``).
"""

from __future__ import annotations

import importlib
import math
import re
import sys
import threading
import time
from typing import Any

import yaml
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from rimd_sim.nodes._params import refuse_unnamed
from rimd_sim.nodes._run import run_node, spin_until_stopped
from rimd_sim.recording.reader import Recording, RecordingError, open_recording

__all__ = ["ReplayNode", "main"]

NODE_NAME = "rimd_replay"

PARAMETERS: dict[str, tuple[Any, str]] = {
    "file": ("", "recording to replay: an .mcap file or a recording directory"),
    "rate": (1.0, "replay speed factor (2.0 = twice as fast)"),
    "loop": (False, "start again from the beginning when the end is reached"),
    "start_offset": (0.0, "s into the recording where the replay starts"),
    "topics": ([".*"], "topics to replay: regular expressions (full match)"),
    "remap": ([""], "topic renames, entries '/from:=/to'"),
    "clock": (False, "publish /clock from the recorded time (a recorded /clock is then not replayed)"),
    "clock_frequency": (100.0, "Hz, /clock publications per second of recorded time"),
    "start_paused": (False, "wait for ~/resume before publishing"),
    "wait_for_subscribers": (0, "wait (at most 10 s) until every publisher has this many subscribers"),
    "skip_unknown": (False, "replay the other topics when some message types are not installed"),
}


class ReplayError(Exception):
    """The replay cannot start; the message says why (bad parameter, unreadable file, unknown types)."""


def _message_class(type_name: str):  # noqa: ANN202
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


def parse_remap(entries: list[str]) -> dict[str, str]:
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


#: name -> (rule, predicate) of the numbers, checked at start (every parameter is read-only afterwards). Each
#: must be finite with an upper bound: rate = inf published a looping recording in a busy loop, and an
#: infinite start_offset killed the replay thread (OverflowError) with a traceback.
NUMBER_RULES: dict[str, tuple[str, Any]] = {
    "rate": ("must be > 0 and <= 10000", lambda v: 0 < v <= 1e4),
    "start_offset": ("must be >= 0 and <= 1e9 s", lambda v: 0 <= v <= 1e9),
    "clock_frequency": ("must be > 0 and <= 1e6 Hz", lambda v: 0 < v <= 1e6),
    "wait_for_subscribers": ("must be >= 0 and <= 1000", lambda v: 0 <= v <= 1000),
}


def check_parameters(p: dict[str, Any]) -> None:
    """Check the replay's parameters at start; ReplayError names the first refused one and its rule."""
    if not p["file"]:
        raise ReplayError("file: no recording given (set -p file:=REC.mcap or a recording directory)")
    for name, (rule, ok) in NUMBER_RULES.items():
        value = p[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not ok(value):
            raise ReplayError(f"{name}: {value!r} refused: {rule}")


class ReplayNode(Node):
    """The replay node. See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        for name, (default, description) in PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=description, read_only=True))
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        check_parameters(p)
        try:
            patterns = [re.compile(x) for x in p["topics"] if x]
        except re.error as exc:
            raise ReplayError(f"topics: not a regular expression ({exc})") from None
        remap = parse_remap(p["remap"])
        self._p = p
        try:
            self._recording: Recording = open_recording(p["file"])
        except RecordingError as exc:
            raise ReplayError(str(exc)) from None
        log = self.get_logger()
        for report in self._recording.reports:
            (log.info if report.complete else log.warning)(report.describe())
        selected = {name: topic for name, topic in self._recording.topics.items()
                    if any(x.fullmatch(name) for x in patterns) and not (p["clock"] and name == "/clock")}
        unknown = {}
        self._pubs: dict[str, Any] = {}
        for name, topic in sorted(selected.items()):
            try:
                msg_type = _message_class(topic.type_name)
            except (ImportError, AttributeError):
                unknown[name] = topic.type_name or "(no schema)"
                continue
            qos = _qos(topic.offered_qos_profiles)
            self._pubs[name] = self.create_publisher(msg_type, remap.get(name, name), qos)
        if unknown:
            listing = ", ".join(f"{t} ({name})" for name, t in unknown.items())
            if not p["skip_unknown"]:
                raise ReplayError(f"the recording has message types not installed here: {listing}; install their "
                                  "packages, leave the topics out with -p topics:=..., or set skip_unknown:=true")
            log.warning(f"not replaying topics of unknown types: {listing}")
        if not self._pubs:
            # A damaged recording may have lost every topic with its first chunk: say so in the one line.
            damage = "; ".join(r.describe() for r in self._recording.reports if not r.complete)
            raise ReplayError(f"nothing to replay: no topic of {p['file']} matches {p['topics']}"
                              + (f" (the recording is damaged: {damage})" if damage else ""))
        self._clock_pub = self.create_publisher(Clock, "/clock", 10) if p["clock"] else None
        self._paused = threading.Event()
        if p["start_paused"]:
            self._paused.set()
        self._stop = threading.Event()
        self.finished = threading.Event()
        self.published = 0
        self.create_service(Trigger, "~/pause", self._on_pause)
        self.create_service(Trigger, "~/resume", self._on_resume)
        self._thread = threading.Thread(target=self._run, name="rimd_replay", daemon=True)
        log.info(f"replaying {len(self._pubs)} topics of {p['file']} ({self._recording.message_count} "
                 f"messages) at {p['rate']:g}x" + (", looping" if p["loop"] else ""))

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        """Set parameters; rclpy's parameter services come here. Every refusal names the parameter."""
        refusal = refuse_unnamed(self, parameter_list)
        return refusal if refusal is not None else super().set_parameters_atomically(parameter_list)

    def start(self) -> None:
        """Start publishing (in a thread)."""
        self._thread.start()

    def stop(self) -> None:
        """Stop publishing and wait for the thread."""
        self._stop.set()
        self._paused.clear()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    def wait_for_acknowledgements(self, timeout: float = 2.0) -> None:
        """Give reliable subscribers the time to acknowledge the last messages before the node goes away."""
        for pub in self._pubs.values():
            pub.wait_for_all_acked(Duration(seconds=timeout))

    def _wait_for_subscribers(self) -> None:
        wanted = self._p["wait_for_subscribers"]
        deadline = time.monotonic() + 10.0
        while wanted > 0 and time.monotonic() < deadline and not self._stop.is_set():
            if all(pub.get_subscription_count() >= wanted for pub in self._pubs.values()):
                # The publisher side has matched; give the subscribers' side the moment it needs to match
                # too, or a reliable volatile subscriber can still miss the first messages.
                time.sleep(0.3)
                return
            time.sleep(0.02)

    def _sleep_until(self, due: float) -> bool:
        """Sleep until the monotonic time ``due``; False when stopping."""
        while not self._stop.is_set():
            remaining = due - time.monotonic()
            if remaining <= 0:
                return True
            time.sleep(min(remaining, 0.05))
        return False

    def _run(self) -> None:
        try:
            self._wait_for_subscribers()
            rate, offset_ns = self._p["rate"], round(self._p["start_offset"] * 1e9)
            clock_period_ns = 1e9 / self._p["clock_frequency"]
            # Times count from the recording's first message (all topics), as rosbag2 play does.
            first = next(iter(self._recording.messages()), None)
            first_ns = first.log_time if first is not None else 0
            while not self._stop.is_set():
                start = time.monotonic()
                last_clock = None
                for msg in self._recording.messages(self._pubs):
                    if msg.log_time - first_ns < offset_ns:
                        continue
                    if self._paused.is_set():
                        paused_at = time.monotonic()
                        while self._paused.is_set() and not self._stop.is_set():
                            time.sleep(0.01)
                        start += time.monotonic() - paused_at
                    due = start + (msg.log_time - first_ns - offset_ns) / 1e9 / rate
                    if not self._sleep_until(due):
                        return
                    if self._clock_pub is not None and (last_clock is None
                                                        or msg.log_time - last_clock >= clock_period_ns):
                        clock = Clock()
                        clock.clock.sec, clock.clock.nanosec = divmod(msg.log_time, 1_000_000_000)
                        self._clock_pub.publish(clock)
                        last_clock = msg.log_time
                    self._pubs[msg.topic].publish(msg.data)
                    self.published += 1
                if not self._p["loop"]:
                    break
            self.get_logger().info(f"replay finished: {self.published} messages published")
        finally:
            self.finished.set()

    def _on_pause(self, request, response):  # noqa: ARG002
        response.success = not self._paused.is_set()
        response.message = "paused" if response.success else "already paused"
        self._paused.set()
        return response

    def _on_resume(self, request, response):  # noqa: ARG002
        response.success = self._paused.is_set()
        response.message = "resumed" if response.success else "not paused"
        self._paused.clear()
        return response


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``rimd_replay`` executable (also ``rimd node replay``)."""

    def spin(node: ReplayNode, executor, stop) -> None:  # noqa: ANN001
        node.start()
        spin_until_stopped(executor, stop, done=node.finished.is_set)
        node.wait_for_acknowledgements()

    return run_node("rimd_replay", ReplayNode, (ReplayError,), args=args, refused_status=1, spin=spin,
                    close=lambda node: node.stop())

if __name__ == "__main__":
    sys.exit(main())
