"""Helpers for a Python node that consumes the rig: report progress to a rig in lockstep, in one line.

A rig (or a replay) in lockstep (``lockstep.enabled``, docs/rig.md "Pacing: lockstep") publishes data time
``t`` only once every consumer it names has finished with the data up to ``t - lockstep.window``. A consumer
tells it how far it is with ``rimd_msgs/msg/ConsumerProgress`` on ``/rig/progress``; in Python::

    from rimd_sim.ros.clients.progress import ProgressReporter

    class MyDaq(Node):
        def __init__(self):
            super().__init__("my_daq")
            self.sub = self.create_subscription(SampleBlock, "/rig/impact/force", self.on_block, 100)
            self.progress = ProgressReporter(self, "my_daq", subscriptions=[self.sub])   # the one line

        def on_block(self, msg):
            ...                                              # the work
            self.progress.done(msg.header.stamp, self.sub)   # finished with this message

What :class:`ProgressReporter` does for you:

* it *joins* (reports "nothing taken yet") once every subscription you gave it has matched a publisher and a
  lockstep publisher listens, so the rig waits for you before its first block and you miss none; while a lockstep
  publisher listens but a subscription has matched no publisher (a misspelt topic: the rig waits for you, and
  nothing comes), it logs a warning after ``unmatched_warning`` seconds naming that topic and the published topics
  of its type;
* it reports per topic (the rig does not wait for you on a topic where you have everything published, a
  fault's dropout for instance), at most every ``min_interval`` seconds, and again from a timer so that the
  last report always goes out;
* it publishes on a reliable, transient local writer with a history of one (:data:`PROGRESS_QOS`): a report
  written before a lockstep publisher matched the writer, the join above all, reaches it at the match;
* it joins again when a new run starts (``/rig/session``: the rig restarted, or a replay started a pass), with
  a new ``instance`` for each process, so a restarted consumer resumes where the run stands;
* for a controller (:class:`rimd_sim.ros.clients.motor.MotorCommander` given this reporter: docs/control.md) its
  reports say that it commands the rig and count the commands it has sent, and it reports at once after each
  ``done``: the rig then waits for its decision on each message before it simulates further, and applies a
  command where it waits. Call ``done`` after publishing the commands a message led to.

Clients in other languages publish the message themselves: it is documented field by field in
``rimd_msgs/msg/ConsumerProgress.msg``, and the protocol (QoS, join, reports, leave) in docs/rig.md, "Pacing:
lockstep". :func:`listen_for_progress` is the publishers' side (the simulator, the replay).

This module is what a user's DAQ node imports: it imports rclpy, ``rimd_msgs`` and the standard library only
(and, of the package, only modules that import nothing beyond the standard library: the ``rimd_sim``,
``rimd_sim.ros``, ``rimd_sim.ros.clients``, ``rimd_sim.runtime`` and ``rimd_sim.io`` packages, the books
:mod:`rimd_sim.runtime.progress` and the report's encoder :mod:`rimd_sim.io.cdr_progress`), so a consumer does not
load the twin's numerical stack (numba, numpy, scipy, mcap...) to report its progress
(tests/ros/test_progress_lean.py checks it).
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Sequence
from typing import Any

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from rimd_msgs.msg import ConsumerProgress, RigSession
from rimd_sim.io.cdr_progress import encode_progress
from rimd_sim.runtime.progress import LedgerState, ProgressLedger, ReportOrder, stamp_ns

__all__ = ["PROGRESS_QOS", "PROGRESS_TOPIC", "SESSION_TOPIC", "ProgressReporter", "listen_for_progress"]

#: Where lockstep publishers listen for progress, and where the rig names its runs.
PROGRESS_TOPIC = "/rig/progress"
SESSION_TOPIC = "/rig/session"

#: QoS of a consumer's progress writer: reliable (a lost report would hold the run until the next one), transient
#: local with a history of one (a report written before the lockstep publisher matched the writer, the join above
#: all, reaches it at the match; each report is the consumer's whole progress, so the last one is all it needs).
PROGRESS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: QoS of a lockstep publisher's two subscriptions of the progress topic (:func:`listen_for_progress`): volatile
#: (it matches every writer, a volatile one too) and transient local (it matches transient local writers only, and
#: receives their last report at the match), reliable, deep enough for a burst of reports of many consumers.
PROGRESS_SUBSCRIPTION_QOS = (
    QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE),
    QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
               durability=DurabilityPolicy.TRANSIENT_LOCAL))
#: QoS of the session topic: transient local (the current run reaches a late joiner).
SESSION_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


def listen_for_progress(node: Node, on_report: Callable[[ConsumerProgress], None],
                        topic: str = PROGRESS_TOPIC) -> list[Any]:
    """A lockstep publisher's subscriptions of the progress topic: ``on_report(msg)`` once per report, in order.

    Two subscriptions (:data:`PROGRESS_SUBSCRIPTION_QOS`): the volatile one hears every writer, the transient local
    one also hears the last report a transient local writer wrote before the match (a client that published its
    join once, before it had matched the publisher). A transient local writer's reports come on both: which copy
    counts is :class:`~rimd_sim.runtime.progress.ReportOrder`'s decision.
    """
    order = ReportOrder()

    def taker(latched: bool) -> Callable[[ConsumerProgress], None]:
        def take(msg: ConsumerProgress) -> None:
            if order.take(msg.consumer, msg.instance, latched=latched):
                on_report(msg)
        return take

    from rclpy.event_handler import SubscriptionEventCallbacks

    volatile, latched = PROGRESS_SUBSCRIPTION_QOS
    # A volatile writer cannot match the transient local subscription, by design (the volatile one hears it):
    # without a handler of its own, rclpy would log that as an incompatible QoS warning.
    expected = SubscriptionEventCallbacks(incompatible_qos=lambda event: None)
    return [node.create_subscription(ConsumerProgress, topic, taker(False), volatile),
            node.create_subscription(ConsumerProgress, topic, taker(True), latched, event_callbacks=expected)]


class ProgressReporter(LedgerState):
    """Reports how far a consumer has finished, for rigs and replays in lockstep (see the module docstring).

    Thread-safe: :meth:`done` may be called from any thread (the recorder calls it from its writer thread).

    Args:
        node: The consumer's node (the reporter creates a publisher, a subscription and a timer on it).
        name: The consumer's name, as the rig's ``lockstep.consumers`` lists it (usually the node's name).
        subscriptions: The subscriptions whose messages the consumer takes: it joins once each has matched a
            publisher.
        ready: A further condition to join (for consumers that subscribe over time, such as the recorder).
        min_interval: Shortest time between two reports (s); the timer sends the last one.
        topic: The progress topic.
        unmatched_warning: Seconds a subscription may go without a publisher, while a lockstep publisher listens,
            before the node's logger warns which (once).
    """

    def __init__(self, node: Node, name: str, *, subscriptions: Sequence[Any] = (),
                 ready: Callable[[], bool] | None = None, min_interval: float = 0.005,
                 topic: str = PROGRESS_TOPIC, unmatched_warning: float = 5.0) -> None:
        if not name or name != name.strip():
            raise ValueError(f"ProgressReporter name {name!r} refused: must be a non-empty name without surrounding "
                             "spaces (an entry of the rig's lockstep.consumers)")
        self.name = name
        self.instance = uuid.uuid4().hex
        self._node = node
        self._subscriptions = list(subscriptions)
        self._ready = ready
        self._ledger = ProgressLedger(min_interval)
        self._run_id = ""
        self._unmatched_warning = unmatched_warning
        self._unmatched_since: float | None = None
        self._warned = False
        self._controls = False   # a controller's reporter (take_control)
        self._pub = node.create_publisher(ConsumerProgress, topic, PROGRESS_QOS)
        node.create_subscription(RigSession, SESSION_TOPIC, self._on_session, SESSION_QOS)
        self._timer = node.create_timer(0.02, self._tick)

    @property
    def controls(self) -> bool:
        """Whether this consumer commands the rig (:meth:`take_control`)."""
        return self._controls

    @property
    def commands(self) -> int:
        """The commands counted so far in this instance (:meth:`command_sent`)."""
        return self._ledger.commands

    def take_control(self, ready: Callable[[], bool] | None = None) -> None:
        """Make this consumer a controller: its reports say so and count its commands, and go out at each ``done``.

        :class:`rimd_sim.ros.clients.motor.MotorCommander` calls it; call it before the node spins (the join report
        must say it: a rig that took it for a plain consumer could run a window ahead of its first decision).

        Args:
            ready: A further condition to join: the command writer has matched the rig's command reader (a command
                published before that would be lost, and the rig would wait for it).
        """
        with self._ledger.lock:
            self._controls = True
            self._ledger.min_interval = 0.0
            if ready is not None:
                before = self._ready

                def both() -> bool:
                    return (before is None or bool(before())) and ready()

                self._ready = both

    def command_sent(self) -> None:
        """One more command published (:class:`~rimd_sim.ros.clients.motor.MotorCommander` calls it after each)."""
        self._ledger.command_sent()

    def add_subscription(self, subscription: Any) -> None:
        """Take one more subscription into account (before the join: it must match a publisher first)."""
        with self._ledger.lock:
            self._subscriptions.append(subscription)

    def done(self, stamp: Any, subscription: Any = None, *, topic: str | None = None) -> None:
        """The consumer has finished with a message stamped ``stamp`` (a ``Time`` or integer nanoseconds).

        Args:
            stamp: The message's ``header.stamp``.
            subscription: The subscription it came from (its topic is what the report names); or ``topic``.
            topic: The full topic name, when no subscription is given. With neither, one report for all.
        """
        name = topic if topic is not None else getattr(subscription, "topic_name", None)
        if self._ledger.done(stamp_ns(stamp), name):
            self.flush()

    def flush(self, *, join: bool = False) -> None:
        """Send the current progress now (after the join; no-op before).

        The join report names the topics taken, each done through zero (nothing taken yet), so that the publisher
        waits until its writers have matched this node's readers of them before it goes on.
        """
        report = self._ledger.take_report([sub.topic_name for sub in self._subscriptions] if join else None)
        if report is None:
            return
        overall, done = report
        self._pub.publish(encode_progress(self.name, overall, self.instance, done,
                                          node=self._node.get_fully_qualified_name(), controls=self._controls,
                                          commands=self._ledger.reported_commands))

    def leave(self, timeout: float = 1.0) -> bool:
        """Say that the consumer stops cleanly: its progress so far, then its last report, ``leaving``.

        A lockstep publisher then stops waiting for it (a consumer that just vanishes holds the run until
        ``lockstep.timeout``). Call it once the consumer has finished with everything it will take. Waits (at
        most ``timeout`` s) until the publishers acknowledged the report; returns whether they did.
        """
        if not self._ledger.joined and self._pub.get_subscription_count() == 0:
            return True   # nobody waits for it
        self.flush()
        self._ledger.leave()   # no report after the leave (it would join again)
        self._pub.publish(encode_progress(self.name, 0, self.instance, leaving=True, controls=self._controls,
                                          commands=self._ledger.commands))
        try:
            return bool(self._pub.wait_for_all_acked(Duration(nanoseconds=round(timeout * 1e9))))
        except Exception:  # the context is going down: best effort
            return False

    def _can_join(self) -> bool:
        if self._pub.get_subscription_count() == 0:
            return False   # no lockstep publisher listens (yet)
        if any(sub.get_publisher_count() == 0 for sub in self._subscriptions):
            return False   # a subscription has not matched its publisher: its first messages could be lost
        return self._ready is None or bool(self._ready())

    def _tick(self) -> None:
        ledger = self._ledger
        if ledger.left:
            return
        if not ledger.joined:
            if self._can_join() and ledger.join():
                self.flush(join=True)
            elif not self._warned:
                self._warn_unmatched()
            return
        if ledger.dirty or time.monotonic() - ledger.last_sent > 1.0:
            self.flush()       # the last report of a burst, or a heartbeat (which is no progress for the rig)

    def _warn_unmatched(self) -> None:
        """Once: the subscriptions that have matched no publisher while a lockstep publisher waits for this one."""
        missing = [sub for sub in self._subscriptions if sub.get_publisher_count() == 0]
        if not missing or self._pub.get_subscription_count() == 0:
            self._unmatched_since = None
            return
        now = time.monotonic()
        if self._unmatched_since is None:
            self._unmatched_since = now
        if now - self._unmatched_since < self._unmatched_warning:
            return
        self._warned = True
        published = dict(self._node.get_topic_names_and_types())
        parts = []
        for sub in missing:
            kind = f"{sub.msg_type.__module__.split('.')[0]}/msg/{sub.msg_type.__name__}"
            same = sorted(t for t, types in published.items()
                          if kind in types and t != sub.topic_name and self._node.count_publishers(t) > 0)
            parts.append(f"{sub.topic_name} ({kind}; published topics of that type: "
                         f"{', '.join(same) if same else 'none'})")
        self._node.get_logger().warning(
            f"{self.name}: no publisher after {self._unmatched_warning:g} s on {'; '.join(parts)}. A rig in lockstep "
            "waits for this consumer to join, and it joins once every subscription it was given has matched a "
            "publisher: is the topic name right?")

    def _on_session(self, msg: RigSession) -> None:
        """A new run (the rig restarted, or a replay started a pass): join it from scratch."""
        if msg.run_id == self._run_id:
            return
        first = not self._run_id
        self._run_id = msg.run_id
        if first or msg.reason == "reset":
            return   # a reset goes on with the same stamps: the progress stands
        with self._ledger.lock:
            self._ledger.joined = False
            self._ledger.commands = 0   # counted per instance
            self.instance = uuid.uuid4().hex
