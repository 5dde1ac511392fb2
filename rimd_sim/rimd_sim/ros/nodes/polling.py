"""Subscriptions a node takes itself, every waiting message at once (the recorder, the Rerun bridge).

Under the events executor each message costs a dispatch from C++ to Python on top of its take; a timer that
takes everything waiting serves the rig's 600 messages a second in 50 wake-ups (docs/rig.md, "CPU: executor and
message handling").

With ``RIMD_PLAIN=polling`` (a benchmarking switch, :mod:`rimd_sim.runtime.plain`) :class:`PolledSubscriptions`
makes ordinary subscriptions instead, whose callbacks the executor runs one message at a time, and takes the
in-process hand-overs at its fixed shortest period.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from rclpy.event_handler import EventHandler, QoSSubscriptionEventType, SubscriptionEventCallbacks
from rclpy.node import Node

from rimd_sim.ros.nodes.base import RimdNode
from rimd_sim.runtime.plain import plain

__all__ = ["LocalSubscription", "PollPeriod", "PolledSubscriptions", "PollingNode"]


class LocalSubscription:
    """A topic handed over in the same process (the composed rig), polled like a raw subscription.

    The publisher :meth:`put` s the serialized bytes (:class:`rimd_sim.ros.nodes.feed.InProcessFeed`), the
    consumer's :class:`PolledSubscriptions` takes them from its timer.

    Keep-last like the DDS subscription it replaces: ``depth`` messages wait at most, the oldest go first. The
    message info has the ``source_timestamp`` (wall time of the hand-over, ns) that a DDS take gives.
    """

    def __init__(self, topic: str, depth: int) -> None:
        self.topic_name = topic
        self._queue: deque[tuple[bytes, dict]] = deque(maxlen=depth)

    def put(self, data: bytes) -> None:
        """Hand one serialized message over (any thread; a deque's append is atomic)."""
        self._queue.append((data, {"source_timestamp": time.time_ns()}))

    def get_publisher_count(self) -> int:
        """Always matched: the publisher is in this process."""
        return 1

    def take(self, handler: Callable[[bytes, dict], None], limit: int = 100_000) -> int:
        """Hand up to ``limit`` waiting messages to ``handler``; return how many."""
        queue = self._queue
        for n in range(limit):
            try:
                data, info = queue.popleft()
            except IndexError:
                return n
            handler(data, info)
        return limit


class PollPeriod:
    """How long until the next poll: soon when messages come fast, later when they come slowly.

    Each wake-up of a mostly idle thread costs far more than its work suggests (its caches are cold: the
    simulator's pass for one block costs several times as much CPU every 10 ms as back to back, docs/benchmarks.md);
    so a poll should find a worthwhile batch. The next period is the time in which ``aim`` messages come,
    within ``[shortest, longest]``, at the faster of the last period's rate and the rate averaged over about
    ``memory`` s: a rig at real time is taken every ``longest`` s, a fast one (lockstep, a replay at speed) every
    ``shortest`` s even across the short pauses of lockstep's holds, and a burst after a quiet spell brings the
    short period back at the next poll.
    """

    def __init__(self, shortest: float, longest: float | None = None, aim: int = 40, memory: float = 0.25) -> None:
        longest = shortest if longest is None else longest
        if not 0 < shortest <= longest:
            raise ValueError(f"poll periods must satisfy 0 < shortest ({shortest}) <= longest ({longest})")
        if aim < 1:
            raise ValueError(f"aim {aim} must be >= 1")
        self.shortest, self.longest, self.aim, self.memory = shortest, longest, aim, memory
        self.period = shortest
        self.rate = 0.0   # messages per second, averaged over about ``memory`` s

    def after(self, taken: int, elapsed: float) -> float:
        """The next period after a poll that took ``taken`` messages ``elapsed`` s after the one before."""
        now = taken / elapsed if elapsed > 0 else 0.0
        self.rate += (1.0 - math.exp(-max(elapsed, 0.0) / self.memory)) * (now - self.rate)
        rate = max(now, self.rate)
        self.period = self.longest if rate <= 0 else min(self.longest, max(self.shortest, self.aim / rate))
        return self.period

    def worth_setting(self, timer_ns: int) -> bool:
        """Whether a timer running at ``timer_ns`` should take :attr:`period` (changing it is a C call).

        When the period has moved by more than a fifth, or has reached a bound and the timer is not there (a
        period that creeps up in small steps would otherwise stop short of the longest).
        """
        period_ns = round(self.period * 1e9)
        return period_ns != timer_ns and (abs(period_ns - timer_ns) > 0.2 * timer_ns
                                          or self.period in (self.shortest, self.longest))


class _LostStatus:
    """A subscription's sample-lost status (DDS's SAMPLE_LOST), read on demand, never dispatched by an executor.

    rclpy's :class:`~rclpy.event_handler.EventHandler` over the subscription, which this node does not register
    as a waitable: :meth:`take` reads the status (and resets its change) from the caller's thread.
    """

    def __init__(self, node: Node, sub: Any) -> None:
        self._event = EventHandler(callback_group=node.default_callback_group, callback=lambda status: None,
                                   event_type=QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST,
                                   parent_impl=sub.handle)

    def destroy(self) -> None:
        """Release the status (before its subscription and node go)."""
        self._event.destroy()

    def take(self) -> int:
        """Messages newly declared lost since the last take (0 when the subscription is gone)."""
        self._event._ready_to_take_data = True   # rclpy's flag that a wait set saw it ready: asked directly here
        try:
            status = self._event.take_data()
        except Exception:  # noqa: BLE001 - the subscription is being destroyed
            return 0
        return int(status.total_count_change) if status is not None else 0


class PolledSubscriptions:
    """Raw subscriptions that their node takes itself, every ready message at once, every ``period`` s.

    Under the events executor each message costs a dispatch from C++ to Python on top of its take; a
    timer that takes everything waiting (``take_message`` in a loop, one C call per message) serves the
    rig's 600 messages a second in 50 wake-ups. The messages wait at most one period in their DDS history
    (the subscriptions' depth must hold a period of traffic), and the take gives the message info (source
    timestamp) with the bytes. The executor must not take these subscriptions too: the node is a
    :class:`PollingNode`, which hides them from it.
    Should an executor dispatch one all the same, the message still reaches its handler (without info).

    With ``longest`` the period follows the traffic (:class:`PollPeriod`): ``period`` when it is fast, up to
    ``longest`` when it is slow (the subscriptions' depth must then hold ``longest`` s of traffic). ``after``,
    when set, is called after each timer's poll (a lockstep consumer sends its last progress there).

    ``RIMD_PLAIN=polling`` (:attr:`plain`): :meth:`create` makes an ordinary subscription, whose handler the
    executor calls per message without the message info, and the timer, made by the first :meth:`attach`,
    keeps ``period``.
    """

    def __init__(self, node: Node, period: float, *, longest: float | None = None, aim: int = 40) -> None:
        self._node = node
        self.plain = plain("polling")
        self._subs: list[tuple[Any, Callable[[bytes, dict], None]]] = []
        self._lost: list[tuple[_LostStatus, Callable[[int], None]]] = []
        self._hidden: set[int] = set()
        self.pace = PollPeriod(period, None if self.plain else longest, aim)
        self.after: Callable[[], None] | None = None
        self._last = time.monotonic()
        self._period_ns = round(period * 1e9)
        self.timer: Any = None if self.plain else node.create_timer(period, self._on_timer)

    def create(self, msg_type: type, topic: str, qos: Any, handler: Callable[[bytes, dict], None],
               lost: Callable[[int], None] | None = None) -> Any:
        """Create a raw subscription of the node whose messages go to ``handler(data, info)``.

        ``lost(count)``: called with the number of messages the transport newly declared lost (DDS's sample-lost
        status: a reliable reader told that samples are gone), read at each :meth:`poll`.
        """
        events = None
        if self.plain and lost is not None:   # plain: the lost status as an executor event
            count = lost

            def on_lost(status: Any) -> None:
                count(status.total_count_change)

            events = SubscriptionEventCallbacks(message_lost=on_lost)
        sub = self._node.create_subscription(msg_type, topic, lambda data: handler(data, {}),  # type: ignore[arg-type]
                                             qos, raw=True,  # raw=True hands bytes, not the annotated message
                                             event_callbacks=events)
        if self.plain:
            return sub
        self._hidden.add(id(sub))
        self._subs.append((sub, handler))
        if lost is not None:
            self._lost.append((_LostStatus(self._node, sub), lost))
        return sub

    def attach(self, sub: LocalSubscription, handler: Callable[[bytes, dict], None]) -> LocalSubscription:
        """Poll an in-process topic like the raw subscriptions: its messages go to ``handler(data, info)``."""
        self._subs.append((sub, handler))
        if self.timer is None:
            self.timer = self._node.create_timer(self.pace.shortest, self._on_timer)
        return sub

    def visible(self, subscriptions: Iterable[Any]) -> list[Any]:
        """The subscriptions an executor should take: all but the polled ones."""
        return [s for s in subscriptions if id(s) not in self._hidden]

    @staticmethod
    def take(sub: Any, handler: Callable[[bytes, dict], None], limit: int = 100_000) -> int:
        """Hand up to ``limit`` messages waiting in ``sub`` to ``handler``; return how many."""
        if isinstance(sub, LocalSubscription):
            return sub.take(handler, limit)
        handle = sub.handle
        for n in range(limit):
            try:
                with handle:
                    taken = handle.take_message(sub.msg_type, True)
            except Exception:  # noqa: BLE001 - the subscription is being destroyed
                return n
            if taken is None:
                return n
            handler(taken[0], taken[1])
        return limit

    def poll(self) -> int:
        """Take every message waiting in every polled subscription; return how many.

        Then the transport's new sample-lost counts go to the ``lost`` callbacks, read here rather than
        dispatched as events: a reader falling behind gets that status many times a second, and as executor
        events they kept the node from taking its messages, and from stopping on SIGINT.
        """
        taken = sum(self.take(sub, handler) for sub, handler in self._subs)
        for status, lost in self._lost:
            count = status.take()
            if count:
                lost(count)
        return taken

    def close(self) -> None:
        """Release what the subscriptions' lost statuses hold (the node is being destroyed)."""
        for status, _ in self._lost:
            status.destroy()
        self._lost.clear()

    def _on_timer(self) -> None:
        """The timer's poll; then ``after``, and the next period from the traffic."""
        taken = self.poll()
        if self.after is not None:
            self.after()
        now = time.monotonic()
        elapsed, self._last = now - self._last, now
        pace = self.pace
        if pace.longest == pace.shortest:
            return
        pace.after(taken, elapsed)
        if pace.worth_setting(self._period_ns):
            self.timer.timer_period_ns = self._period_ns = round(pace.period * 1e9)


class PollingNode(RimdNode):
    """A node whose executor does not take its :class:`PolledSubscriptions` (``self._polled``).

    rclpy's executors read ``Node.subscriptions``; this property leaves the polled ones out. The subclass
    sets ``self._polled`` in its ``__init__``.
    """

    _polled: PolledSubscriptions | None = None   # None until the subclass creates it

    @property
    def subscriptions(self) -> list:  # type: ignore[override]  # rclpy's is an iterator; executors only iterate
        """The subscriptions the executor takes: all but the polled ones."""
        subs = super().subscriptions
        return list(subs) if self._polled is None else self._polled.visible(subs)

    def destroy_node(self) -> None:
        """Release the polled subscriptions' lost statuses, then destroy the node as rclpy does."""
        if self._polled is not None:
            self._polled.close()
        super().destroy_node()
