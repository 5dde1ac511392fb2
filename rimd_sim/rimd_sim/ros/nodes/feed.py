"""The composed rig's hand-over: the simulator's messages to consumers in the same process, without DDS.

In the composed rig (:mod:`rimd_sim.ros.nodes.composed`, docs/rig.md "The composed rig") the recorder and the Rerun
bridge run in the simulator's process. :class:`InProcessFeed` sits between them:

* the simulator node :meth:`~InProcessFeed.offer` s each of its topics (type, the QoS its publisher offers) and
  hands every serialized message to :meth:`~InProcessFeed.send` before it publishes it on DDS for the other
  processes;
* a consumer :meth:`~InProcessFeed.subscribe` s to a topic: a
  :class:`~rimd_sim.ros.nodes.polling.LocalSubscription` that its polling timer takes like a raw DDS subscription
  (same handler, same thread, same keep-last depth), so the node's logic is the one of the separate process;
* lockstep: a consumer's progress (:class:`DirectProgress`, the :class:`~rimd_sim.ros.clients.progress.
  ProgressReporter` interface the nodes use) goes straight to the simulator's runtime
  (:meth:`rimd_sim.runtime.simulator.SimulatorRuntime.progress`), not over ``/rig/progress``: the rig holds data
  time ``t`` until the recorder has *written* up to ``t - window`` and the bridge has *logged* it, exactly as with
  separate processes, only without the messages.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rimd_sim.ros.nodes.polling import LocalSubscription
from rimd_sim.runtime.progress import LedgerState, ProgressLedger, stamp_ns

__all__ = ["DirectProgress", "FedTopic", "InProcessFeed"]


@dataclass(frozen=True)
class FedTopic:
    """One topic the simulator hands over: its type and the QoS profiles its publisher offers (as the graph says)."""

    topic: str
    type_name: str
    offered: tuple[Any, ...]


class InProcessFeed:
    """The simulator's topics, handed to consumers of the same process (see the module docstring)."""

    def __init__(self) -> None:
        self.topics: dict[str, FedTopic] = {}
        self._subs: dict[str, tuple[LocalSubscription, ...]] = {}
        self._reporters: list[DirectProgress] = []
        self._report: Callable[..., None] | None = None

    # -- the publisher's side -----------------------------------------------------------------------------------
    def offer(self, topic: str, type_name: str, offered: list[Any]) -> None:
        """The simulator publishes ``topic`` (before any consumer subscribes)."""
        self.topics[topic] = FedTopic(topic, type_name, tuple(offered))

    def bind(self, report: Callable[..., None]) -> None:
        """Where lockstep progress goes: ``report(consumer, done_ns, *, instance, topics, topics_done_ns, leaving)``."""
        self._report = report

    def send(self, topic: str, data: bytes) -> None:
        """Hand one serialized message to every in-process subscriber of ``topic`` (the pacing thread).

        The bytes are those a DDS reader receives: the middleware pads a serialized message to a multiple of 4
        bytes with zeros (a RigState, ending with its 10 ``in_contact`` flags, arrives 2 bytes longer than it was
        written), and so does the hand-over, so that a recording holds the same bytes either way.
        """
        subs = self._subs.get(topic)
        if not subs:
            return
        pad = -len(data) % 4
        if pad:
            data += b"\0" * pad
        for sub in subs:
            sub.put(data)

    # -- the consumers' side ------------------------------------------------------------------------------------
    def subscribe(self, topic: str, depth: int) -> LocalSubscription:
        """A keep-last subscription of ``depth`` messages to an offered topic."""
        if topic not in self.topics:
            raise KeyError(f"{topic} is not published in this process")
        sub = LocalSubscription(topic, depth)
        self._subs[topic] = (*self._subs.get(topic, ()), sub)
        return sub

    def progress(self, name: str) -> DirectProgress:
        """A consumer's lockstep progress, reported to the simulator in this process."""
        reporter = DirectProgress(self, name)
        self._reporters.append(reporter)
        return reporter

    def join(self) -> None:
        """Every consumer joins the lockstep (before the simulator starts: it then waits for them from sample 0)."""
        for reporter in self._reporters:
            reporter.join()

    def flush(self) -> None:
        """Report what is left of each consumer's progress (a timer: the last report of a burst always goes)."""
        for reporter in self._reporters:
            reporter.flush()

    def report(self, name: str, done_ns: int, instance: str, topics: dict[str, int], leaving: bool = False) -> None:
        """One progress report to the simulator (no-op until it is bound)."""
        if self._report is None:
            return
        names = sorted(topics)
        self._report(name, min(topics.values()) if topics else done_ns, instance=instance, topics=names,
                     topics_done_ns=[topics[n] for n in names], leaving=leaving)


class DirectProgress(LedgerState):
    """A consumer's lockstep progress, reported in the process: what the nodes use of ``ProgressReporter``.

    Thread-safe (the recorder reports from its writer thread). Reports at most every ``min_interval`` seconds
    from :meth:`done`; the consumer's :meth:`flush` after each of its batches (the bridge's poll, the recorder's
    write) sends the last one, and :meth:`InProcessFeed.flush` (a slow timer) whatever is left.
    """

    def __init__(self, feed: InProcessFeed, name: str, min_interval: float = 0.005) -> None:
        self.name = name
        self.instance = uuid.uuid4().hex
        self._feed = feed
        self._ledger = ProgressLedger(min_interval)
        self._topics: list[str] = []

    def add_subscription(self, subscription: Any) -> None:
        """A topic it takes: named, done through 0, in its join."""
        with self._ledger.lock:
            self._topics.append(subscription.topic_name)

    def done(self, stamp: Any, subscription: Any = None, *, topic: str | None = None) -> None:
        """Finished with a message stamped ``stamp`` (integer ns or a ``Time``) of ``topic`` (or ``subscription``)."""
        name = topic if topic is not None else getattr(subscription, "topic_name", None)
        if self._ledger.done(stamp_ns(stamp), name):
            self._send()

    def join(self) -> None:
        """Join: every topic taken, done through 0 (nothing taken yet)."""
        if self._ledger.join():
            self._send(join=True)

    def flush(self) -> None:
        """Send the progress not reported yet."""
        if self._ledger.dirty:
            self._send()

    def _send(self, *, join: bool = False) -> None:
        report = self._ledger.take_report(list(self._topics) if join else None)
        if report is not None:
            self._feed.report(self.name, report[0], self.instance, report[1])

    def leave(self, timeout: float = 1.0) -> bool:
        """Finished with everything it will take: the last progress, then ``leaving`` (the rig stops waiting)."""
        del timeout   # in the process: nothing to wait for
        self._send()
        if self._ledger.leave():
            self._feed.report(self.name, 0, self.instance, {}, leaving=True)
        return True
