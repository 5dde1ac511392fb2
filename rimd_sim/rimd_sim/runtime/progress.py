"""A lockstep consumer's progress ledger: what it has finished, when a report is due, what a report says.

The one bookkeeping behind both ways a consumer reports (docs/rig.md, "Pacing: lockstep"): over ``/rig/progress``
from another process (:class:`rimd_sim.ros.clients.progress.ProgressReporter`) and straight to the simulator in
the composed rig (:class:`rimd_sim.ros.nodes.feed.DirectProgress`). How a report travels is theirs; what it holds,
and when one is due, is decided here once. Thread-safe: a consumer may finish messages on any thread (the recorder
does on its writer thread).

On the publisher's side, :class:`ReportOrder` decides which of the reports that come over ``/rig/progress`` count:
each once, in the order it was written.
"""

from __future__ import annotations

import threading
import time
from typing import Any

__all__ = ["PACING_STATUS", "PUBLISHED_KEY", "LedgerState", "ProgressLedger", "ReportOrder", "stamp_ns"]

#: The end of the name of a lockstep publisher's status on ``/diagnostics`` (``rimd_simulator: pacing``): what a
#: consumer reads to learn what it publishes and whether it waits for it.
PACING_STATUS = ": pacing"
#: The end of the key of each topic a publisher publishes, in that status (``/rig/impact/force published``).
PUBLISHED_KEY = " published"


def stamp_ns(stamp: Any) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time`` (``sec``, ``nanosec``) or of an integer."""
    if isinstance(stamp, int):
        return stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class ProgressLedger:
    """How far a consumer has finished, per topic (or overall), and whether a report is due.

    Args:
        min_interval: Shortest time between two reports (s) sent from :meth:`done`; the caller's timer sends the
            last one of a burst (:attr:`dirty`).
    """

    def __init__(self, min_interval: float = 0.005) -> None:
        self.lock = threading.Lock()
        self.min_interval = min_interval
        self.done_ns: dict[str, int] = {}
        self.overall: int | None = None
        self.dirty = False
        self.joined = False
        self.joins = 0   # how many times it joined (a lockstep consumer, once it is > 0)
        self.left = False
        self.last_sent = 0.0
        self.reports = 0
        #: Commands the consumer has sent (a controller's, counted by :meth:`command_sent`), and their number as
        #: the last report took it (what that report says: ``ConsumerProgress.commands``).
        self.commands = 0
        self.reported_commands = 0
        self._join_topics: list[str] = []   # what the last join named

    def done(self, ns: int, topic: str | None) -> bool:
        """The consumer finished a message stamped ``ns`` of ``topic`` (None: of everything it takes).

        Returns whether a report is due now (joined, and ``min_interval`` passed since the last one).
        """
        with self.lock:
            if topic is None:
                self.overall = ns if self.overall is None else max(self.overall, ns)
            elif ns > self.done_ns.get(topic, -1):
                self.done_ns[topic] = ns
            self.dirty = True
            return self.joined and time.monotonic() - self.last_sent >= self.min_interval

    def command_sent(self) -> None:
        """The consumer has published one more command (call it after the publish, before :meth:`done`)."""
        with self.lock:
            self.commands += 1

    def join(self) -> bool:
        """Join from scratch (nothing finished yet); False once it has left."""
        with self.lock:
            if self.left:
                return False
            self.joined = True
            self.joins += 1
            self.done_ns.clear()
            self.overall = None
            self._join_topics = []
            return True

    def take_report(self, topics: list[str] | None = None) -> tuple[int, dict[str, int]] | None:
        """What the next report says, marked as sent: ``(overall ns, done ns per topic)``; None before the join.

        ``topics``: the join report, every topic named done through zero (nothing taken yet), so that the publisher
        waits until it has matched the consumer's readers of them. Until the consumer has finished a message, a
        report (a heartbeat) repeats the join's: an empty one would say "done through 0 with everything", and a
        publisher that had run on before the first block came (a paused rig, a rig that dropped this consumer)
        would hold its run at 0 for it.
        Call it with :attr:`lock` *not* held.
        """
        with self.lock:
            if not self.joined:
                return None
            if topics is not None:
                self._join_topics = list(topics)
            nothing_yet = not self.done_ns and self.overall is None
            done = (dict.fromkeys(self._join_topics, 0) if topics is not None or nothing_yet
                    else dict(self.done_ns))
            self.reported_commands = self.commands
            self.dirty = False
            self.last_sent = time.monotonic()
            self.reports += 1
            return self.overall or 0, done

    def leave(self) -> bool:
        """No report after this one (a report would join again); returns whether it had joined."""
        with self.lock:
            joined, self.joined, self.left = self.joined, False, True
            return joined


class LedgerState:
    """What both reporters tell of their ledger (``self._ledger``): whether joined, ever, and the reports sent."""

    _ledger: ProgressLedger

    @property
    def joined(self) -> bool:
        """Whether it has told a lockstep publisher that it is there."""
        return self._ledger.joined

    @property
    def ever_joined(self) -> bool:
        """Whether it has joined a lockstep run at least once (it may have left since)."""
        return self._ledger.joins > 0

    @property
    def reports(self) -> int:
        """Reports sent so far."""
        return self._ledger.reports


class ReportOrder:
    """Which progress reports a lockstep publisher takes: each once, in the order its writer wrote them.

    A lockstep publisher listens on ``/rig/progress`` with two subscriptions: a volatile one, which matches every
    writer, and a transient local one, which matches transient local writers only and receives, at the match, the
    last report such a writer wrote before it (a join published once, before the publisher had matched the
    writer). A transient local writer's reports therefore come twice, once on each, and the executor may hand
    over the copy of an older report after a newer one (a leave, then a copy of the report before it, would make
    the consumer join again). So, per consumer and instance: every report of the transient local subscription is
    taken (its stream has everything from the last report before the match on, in the order written); a report
    of the volatile subscription is taken until the transient local one has brought a report of that consumer and
    instance (a volatile writer never does: all of its reports are taken), and dropped after (a copy). Thread-safe.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._latched: set[tuple[str, str]] = set()

    def take(self, consumer: str, instance: str, *, latched: bool) -> bool:
        """Whether a report of ``consumer`` (its ``instance``) counts.

        ``latched``: it came on the transient local subscription.
        """
        key = (consumer, instance)
        with self._lock:
            if latched:
                self._latched.add(key)
                return True
            return key not in self._latched
