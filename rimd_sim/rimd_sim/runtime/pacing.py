"""Pacing of a publisher of timed data: when may the next block go? Pure, ROS-free, tested with a fake clock.

The simulator node and the replay node publish data that carries its own time axis (simulation time, or a
recording's stamps) and decide, block by block, when a block may leave. Two independent limits decide it:

* :class:`Schedule`, the clock: at ``factor`` F > 0 a block whose data ends at time ``t`` is due at
  ``wall_ref + (t - data_ref) / F`` of the monotonic clock (F = 1: real time); F = 0 puts no limit (as fast as
  possible). A late publisher catches up (the data keeps its exact times; only its delivery is late), unless
  the schedule is re-anchored (:meth:`Schedule.anchor`).
* :class:`Lockstep`, the consumers: a block ending at ``t`` may leave only once every registered consumer has
  reported that it has finished with the data up to ``t - window`` (``ConsumerProgress.done_through``). The
  run then goes exactly as fast as its slowest consumer and a consumer never falls further behind than
  ``window``, so a publisher history that holds ``window`` of data loses nothing in transport.

:class:`Pacer` combines them: :meth:`Pacer.next` takes the data times of the next candidate blocks and answers
how many of them may go now (:class:`Go`), how long to wait for the clock (:class:`Wait`), or which consumers
hold the run and since when (:class:`Hold`). In lockstep the schedule is a cap: after a hold the schedule is
re-anchored, so the run is never faster than ``factor`` over any stretch (it does not burst to catch up).

Consumer protocol (``rimd_msgs/msg/ConsumerProgress`` on ``/rig/progress``; :meth:`Lockstep.progress`):

* ``done_through``: the consumer has finished with every message stamped at or before it. A consumer that
  has taken nothing yet reports zero: it has *joined*.
* A consumer joins (first report, a report with a new ``instance``, or a report after it was dropped) at the
  point the publisher has reached: data published before it joined can never reach it, so it is counted as
  done with it. A consumer restarted after a crash therefore resumes where the run stands.
* Within one instance, progress never goes back: a report below the last one is ignored (and said). A report
  beyond what the publisher has published is ignored too (it is from the future: another run, a clock bug).
* A consumer that stops cleanly says so (``leaving``): the publisher stops waiting for it until it reports
  again (it joins again then). A stale instance's leave does not count against a newer instance.
* A registered consumer that has not joined holds the run from its first block, however long it takes to start.
  When the run has been held by a consumer that had joined for ``timeout`` seconds without progress from it,
  ``on_timeout`` applies: ``wait`` keeps holding (the debugger case; it is reported as timed out), ``drop``
  stops waiting for it until it reports again.
* A consumer that commands the publisher (``controls``: a controller on ``/rig/motor/command``, docs/control.md)
  is held tight: its lead is one block instead of the window, so the publisher stops after each block that
  brought it a message on a topic its report names, until it has finished with it. Its reports count the
  commands it has sent (``commands``); a report that counts more commands than the publisher has received
  (:meth:`Lockstep.command`) waits until they are there, since DDS orders no two topics. A command it decided
  on the data it had then applies where the publisher is held: the same run, whatever the load.

Every time here is an integer number of nanoseconds on the data's axis, except wall times (float seconds of
the injected monotonic clock).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from rimd_sim.settings.lockstep import LockstepSettings

__all__ = [
    "ALL_TOPICS",
    "ConsumerStatus",
    "Go",
    "Hold",
    "Lockstep",
    "Pacer",
    "ProgressVerdict",
    "Schedule",
    "Wait",
]

# ---- decisions -------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Go:
    """The first ``count`` candidate blocks may go now."""

    count: int


@dataclass(frozen=True)
class Wait:
    """No block is due yet: wait ``seconds`` for the clock (a progress report may end the wait sooner)."""

    seconds: float


@dataclass(frozen=True)
class Hold:
    """Consumers hold the run: ``waiting_for`` are their names (the slowest first), held since wall ``since``."""

    waiting_for: tuple[str, ...]
    since: float


# ---- the clock ---------------------------------------------------------------------------------------------


class Schedule:
    """When a block is due by the clock: ``factor`` times real time (0 = no limit).

    Args:
        factor: Speed over real time (> 0), or 0 for none.
        clock: The monotonic clock (s).
    """

    def __init__(self, factor: float, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self.factor = float(factor)
        self._data_ref = 0
        self._wall_ref = clock()

    @property
    def data_ref(self) -> int:
        """Data time of the last anchor."""
        return self._data_ref

    @property
    def wall_ref(self) -> float:
        """Wall time of the last anchor."""
        return self._wall_ref

    def anchor(self, data_ns: int, wall: float | None = None) -> None:
        """Make data time ``data_ns`` due at wall time ``wall`` (default now); later times follow at ``factor``."""
        self._data_ref = int(data_ns)
        self._wall_ref = self._clock() if wall is None else float(wall)

    def set_factor(self, factor: float, data_ns: int) -> None:
        """Change the factor from data time ``data_ns`` on (re-anchored there, now)."""
        self.factor = float(factor)
        self.anchor(data_ns)

    def due(self, data_ns: int) -> float:
        """Wall time at which data time ``data_ns`` is due (``-inf`` without a limit)."""
        if self.factor <= 0:
            return -math.inf
        return self._wall_ref + (data_ns - self._data_ref) / 1e9 / self.factor

    def ready(self, ends: Sequence[int]) -> tuple[int, float]:
        """How many of the blocks ending at ``ends`` are due now, and the wait for the next one (0 if any is due)."""
        now = self._clock()
        count = 0
        for end in ends:
            if self.due(end) > now:
                break
            count += 1
        if count:
            return count, 0.0
        return 0, self.due(ends[0]) - now


# ---- the consumers -----------------------------------------------------------------------------------------

#: The topic key of a report that covers every topic the consumer takes.
ALL_TOPICS = ""


@dataclass
class ConsumerStatus:
    """What the publisher knows of one registered consumer.

    Attributes:
        name: Its registered name.
        done: Data time it has finished with, per topic (``ALL_TOPICS``: every topic it takes); empty until
            it joins.
        instance: The ``instance`` of its last report ('' when it gives none).
        last_heard: Wall time of its last accepted report (None: never).
        dropped: Not waited for until it reports again: dropped by the ``drop`` policy, or it left.
        left: It left cleanly (its last report said ``leaving``).
        timed_out: Held the run ``timeout`` s without progress under the ``wait`` policy.
        held_since: Wall time since which it holds the run (None: it does not).
        joins: How many times it joined (a restart joins again).
        joined_at: Data time the run had reached when it last joined (where its slow start counts from).
        controls: It commands the publisher: its lead is one block (see the module docstring).
        awaiting: A report of it waits for commands: (commands it counts, commands received), else None.
        join_report: The report its instance joined with (a second copy of it is no news: see ``progress``).
    """

    name: str
    done: dict[str, int] = field(default_factory=dict)
    instance: str = ""
    last_heard: float | None = None
    dropped: bool = False
    left: bool = False
    timed_out: bool = False
    held_since: float | None = None
    joins: int = 0
    joined_at: int = 0
    controls: bool = False
    awaiting: tuple[int, int] | None = None
    join_report: dict[str, int] = field(default_factory=dict)

    @property
    def joined(self) -> bool:
        """Whether it has reported since it was registered."""
        return bool(self.done)

    @property
    def done_ns(self) -> int | None:
        """The lowest data time it has finished with over its topics (None: not joined)."""
        return min(self.done.values()) if self.done else None

    @property
    def done_s(self) -> float:
        """``done_ns`` in seconds, for the log lines about a consumer that has joined."""
        done_ns = self.done_ns
        assert done_ns is not None, f"consumer '{self.name}' has not joined"
        return done_ns / 1e9


@dataclass(frozen=True)
class ProgressVerdict:
    """The outcome of one progress report.

    Attributes:
        accepted: Whether it counted.
        log: A line to log when there is something to say ('' otherwise).
        reason: Why it was ignored: ``unknown`` consumer, ``topics`` not published here, from the ``future``,
            going ``back``; ``pending``: kept until the commands it counts are received; '' when accepted.
        joined: The consumer (re)joined with this report (a first report, a restart, a return after a drop).
    """

    accepted: bool
    log: str = ""
    reason: str = ""
    joined: bool = False


class Lockstep:
    """The registered consumers of a publisher and the data times they have finished with, per topic.

    A consumer reports either one ``done_through`` for everything it takes, or one per topic. On each topic
    it lets the publisher go up to its ``done_through`` plus the window; a consumer that has finished with
    everything published on a topic is *caught up* there and counts as being at the front of the run
    (everything published so far, plus the window). Per-topic reports are what keep a consumer of a topic with
    a hole (a dropout, a gap in a recording) from holding the run forever: it has everything published there.

    Args:
        settings: The lockstep settings.
        topics: The topics the publisher publishes (a per-topic report of another topic is ignored); None
            accepts any.
        clock: The monotonic clock (s).
    """

    def __init__(self, settings: LockstepSettings, topics: Sequence[str] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.settings = settings
        self.clock = clock
        self.topics = None if topics is None else frozenset(topics)
        self.consumers = {name: ConsumerStatus(name) for name in settings.consumers}
        #: Data time up to which the publisher has published, in all and per topic.
        self.published_ns = 0
        self.published_on: dict[str, int] = {}
        self.any_published = False
        self._origin = 0
        self._step = 1   # how far the next candidate ends beyond the front: the least lead (one block)
        self._events: list[tuple[str, str]] = []
        #: Commands received per (consumer, instance), and the report of a consumer that waits for its commands.
        self._received: dict[tuple[str, str], int] = {}
        self._pending: dict[str, tuple[int, str, dict[str, int] | None, bool, bool, int]] = {}

    def published(self, data_ns: int, topic: str = ALL_TOPICS) -> None:
        """The publisher publishes (before the publish call) a message stamped ``data_ns`` on ``topic``."""
        data_ns = int(data_ns)
        self.any_published = True
        if data_ns > self.published_ns:
            self.published_ns = data_ns
        if topic and data_ns > self.published_on.get(topic, -1):
            self.published_on[topic] = data_ns

    def _published(self, topic: str) -> int:
        return self.published_ns if topic == ALL_TOPICS else self.published_on.get(topic, 0)

    def command(self, consumer: str, instance: str) -> ProgressVerdict | None:
        """The publisher has received (and scheduled) one command of ``consumer``'s ``instance``.

        Returns the verdict of the report that waited for it, when it is now taken, else None.
        """
        key = (consumer, instance)
        received = self._received[key] = self._received.get(key, 0) + 1
        pending = self._pending.get(consumer)
        c = self.consumers.get(consumer)
        if pending is None or c is None or pending[1] != instance:
            return None
        done_ns, _, topics, leaving, controls, commands = pending
        if commands > received:
            c.awaiting = (commands, received)
            return None
        del self._pending[consumer]
        return self.progress(consumer, done_ns, instance, topics, leaving, controls=controls, commands=commands)

    def progress(self, consumer: str, done_ns: int, instance: str = "",
                 topics: dict[str, int] | None = None, leaving: bool = False, *, controls: bool = False,
                 commands: int = 0) -> ProgressVerdict:
        """Take one progress report; the verdict says whether it counted and what to log.

        Args:
            consumer: The consumer's registered name.
            done_ns: Data time it has finished with, everything it takes.
            instance: Identifies the consumer's process: a new value is a restart.
            topics: Per topic, the data time it has finished with there (replaces ``done_ns``).
            leaving: Its last report: it stops cleanly (see the module docstring).
            controls: It commands the publisher: held with a lead of one block (see the module docstring).
            commands: How many commands this instance has sent: the report waits until they are received.
        """
        c = self.consumers.get(consumer)
        if c is None:
            return ProgressVerdict(False, f"progress from '{consumer}' ignored: not a registered consumer "
                                          f"(lockstep.consumers: {', '.join(self.settings.consumers)})", "unknown")
        self._pending.pop(consumer, None)   # a report is the consumer's whole state: it replaces one that waited
        c.awaiting = None
        received = self._received.get((consumer, instance), 0)
        if commands > received:
            self._pending[consumer] = (int(done_ns), instance, topics, leaving, controls, int(commands))
            c.awaiting = (int(commands), received)
            return ProgressVerdict(False, "", "pending")
        if leaving:
            if c.joins and instance != c.instance:
                return ProgressVerdict(False, f"leave of '{consumer}' ignored: from an earlier instance (the "
                                              "consumer restarted since)", "stale")
            if c.left:
                return ProgressVerdict(True)
            c.dropped, c.left, c.timed_out, c.held_since = True, True, False, None
            # Where it stood (a topic it has everything of, one that never had a message included): not its
            # lowest done, which is zero on a topic nothing was published on.
            where = f" at {min(self._at(c).values()) / 1e9:.9f} s" if c.joined else " before joining"
            return ProgressVerdict(True, f"consumer '{consumer}' left{where} (it stopped cleanly): the run goes on "
                                         "without it until it reports again", "left")
        report = {ALL_TOPICS: int(done_ns)} if not topics else {t: int(v) for t, v in topics.items()}
        note = ""
        if self.topics is not None and topics:
            # A consumer may take topics of other publishers too (the recorder records /diagnostics): those
            # entries are left out, the others count.
            unknown = sorted(t for t in report if t not in self.topics)
            report = {t: v for t, v in report.items() if t in self.topics}
            if unknown:
                note = f"{', '.join(unknown)} left out of the progress of '{consumer}': not published here"
            if not report:
                return ProgressVerdict(False, f"progress from '{consumer}' ignored: {', '.join(unknown)} not "
                                              "published here (topics: " + ", ".join(sorted(self.topics)) + ")",
                                       "topics")
        future = sorted(t or "all topics" for t, v in report.items() if v > self._published(t))
        if future:
            worst = max(report.values())
            return ProgressVerdict(False, f"progress from '{consumer}' ignored: done_through {worst / 1e9:.9f} s on "
                                          f"{', '.join(future)} is beyond what was published there (the run is at "
                                          f"{self.published_ns / 1e9:.9f} s): from another run, or a clock error",
                                   "future")
        now = self.clock()
        if not c.joined or c.dropped or instance != c.instance:
            was = ("returned after leaving" if c.left else "returned after being dropped" if c.dropped else
                   "restarted (new instance)" if c.joined else "joined")
            # Data published before it joined can never reach it (volatile topics): counted as done.
            c.done = {t: max(v, self._published(t)) for t, v in report.items()}
            c.join_report = report
            c.joined_at = min(c.done.values())
            c.instance, c.last_heard, c.dropped, c.left, c.timed_out = instance, now, False, False, False
            c.controls = controls
            c.joins += 1
            return ProgressVerdict(True, f"consumer '{consumer}' {was} at {c.done_s:.9f} s"
                                   + (f"; {note}" if note else ""), joined=True)
        if report == c.join_report:
            # The same join again: a transient local writer's join comes on both of the publisher's subscriptions
            # (rimd_sim.runtime.progress.ReportOrder takes both when the volatile copy comes first). It says
            # nothing new; read as a report it would go back from where the run stood at the join.
            return ProgressVerdict(True)
        back = sorted(t or "all topics" for t, v in report.items() if v < c.done.get(t, v))
        if back:
            return ProgressVerdict(False, f"progress from '{consumer}' ignored: done_through goes back on "
                                          f"{', '.join(back)} (from {c.done_s:.9f} s; a restart must report a "
                                          "new instance)", "back")
        advanced = any(v > c.done.get(t, -1) for t, v in report.items())
        c.done = dict(report)   # a report is the consumer's whole state: a topic it no longer names does not hold
        c.controls = controls
        returned = c.timed_out and advanced
        if advanced:   # a report that repeats itself (a heartbeat) is no progress: the timeout runs on
            c.last_heard, c.timed_out = now, False
        if returned:
            return ProgressVerdict(True, f"consumer '{consumer}' answers again at {c.done_s:.9f} s")
        return ProgressVerdict(True, note, "topics" if note else "")

    @property
    def _front(self) -> int:
        """The front of the run: what was published; before anything, just short of the first candidate.

        A replay's stamps may start anywhere, at a wall-clock epoch: the window counts from its first message.
        """
        return self.published_ns if self.any_published else self._origin

    def _at(self, c: ConsumerStatus) -> dict[str, int]:
        """Per topic, where consumer ``c`` stands: its ``done``, or the front of the run where it is caught up."""
        front = self._front
        # Caught up on a topic (it has everything published there, a hole or not): it is at the front.
        return {topic: done if done < self._published(topic) else front for topic, done in c.done.items()}

    def limit(self, c: ConsumerStatus) -> float:
        """The data time up to which consumer ``c`` lets the publisher go (``inf``: no limit; ``-inf``: none)."""
        if c.dropped:
            return math.inf
        if not c.joined:
            return -math.inf
        at = self._at(c)
        if c.controls:
            # A controller: the next block only once it has finished with every message so far (one where it is
            # caught up is at the front), so that its command lands where the run is held (module docstring).
            lead = self._step
        else:
            # Slow start: the lead grows with what the consumer has confirmed since it joined (the next block, then
            # two, four...) up to the window, so that its readers get the first blocks one by one instead of a
            # window's burst at once (docs/rig.md, "Pacing: lockstep").
            lead = min(self.settings.window_ns, max(self._step, min(at.values(), default=self._front) - c.joined_at))
        return min((v + lead for v in at.values()), default=math.inf)

    def allowed(self, ends: Sequence[int]) -> tuple[int, tuple[str, ...]]:
        """How many of the blocks ending at ``ends`` the consumers allow now, and who holds the next one.

        Also applies the timeout policy to the consumers that hold the run.
        """
        now = self.clock()
        if not self.any_published:
            self._origin = max(0, ends[0] - 1)
        self._step = max(1, ends[0] - self._front)
        limits = {name: self.limit(c) for name, c in self.consumers.items()}
        bound = min(limits.values(), default=math.inf)
        count = 0
        for end in ends:
            if end > bound:
                break
            count += 1
        holders: list[ConsumerStatus] = []
        if count == 0:
            holders = sorted((c for c in self.consumers.values() if limits[c.name] < ends[0]),
                             key=lambda c: limits[c.name])
        holding = {c.name for c in holders}
        dropped_now = False
        for c in self.consumers.values():
            if c.name not in holding:
                c.held_since = None
                continue
            if c.held_since is None:
                c.held_since = now
            if not c.joins:
                continue   # not there yet (still starting): waited for, never dropped (the first block waits)
            quiet_since = c.held_since if c.last_heard is None else max(c.held_since, c.last_heard)
            silent = now - quiet_since
            if silent < self.settings.timeout:
                continue
            if self.settings.on_timeout == "drop":
                c.dropped, c.held_since, dropped_now = True, None, True
                self._events.append(("warning", f"consumer '{c.name}' dropped: no progress for {silent:.1f} s "
                                                f"(lockstep.timeout {self.settings.timeout:g} s, on_timeout drop); "
                                                "the run goes on without it until it reports again"))
            elif not c.timed_out:
                c.timed_out = True
                self._events.append(("error", f"consumer '{c.name}' has not answered for {silent:.1f} s "
                                              f"(lockstep.timeout {self.settings.timeout:g} s, on_timeout wait): "
                                              "still waiting for it"))
        if dropped_now:   # a drop may free the run
            return self.allowed(ends)
        return count, tuple(c.name for c in holders)

    def holders(self) -> list[ConsumerStatus]:
        """The consumers holding the run now (the slowest first)."""
        return sorted((c for c in self.consumers.values() if c.held_since is not None),
                      key=lambda c: self.limit(c))

    def take_events(self) -> list[tuple[str, str]]:
        """The (level, line) events since the last call (timeouts, drops)."""
        events, self._events = self._events, []
        return events


# ---- both ------------------------------------------------------------------------------------------------------


class Pacer:
    """The clock and, in lockstep, the consumers: how many of the next blocks may go now.

    Args:
        factor: Speed over real time (> 0), 0 for no clock limit.
        lockstep: The lockstep settings, or None for an open-loop publisher.
        topics: The topics the publisher publishes (see :class:`Lockstep`).
        clock: The monotonic clock (s).
    """

    def __init__(self, factor: float, lockstep: LockstepSettings | None = None, *,
                 topics: Sequence[str] | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.schedule = Schedule(factor, clock)
        self.lockstep = Lockstep(lockstep, topics, clock) if lockstep is not None else None
        self._held = False

    @property
    def held(self) -> bool:
        """Whether the last decision was a hold."""
        return self._held

    def next(self, ends: Sequence[int], schedule_times: Sequence[int] | None = None) -> Go | Wait | Hold:
        """Decide for the candidate blocks ending at data times ``ends`` (increasing, at least one).

        Args:
            ends: Data times at which the candidate blocks end (what consumers report against).
            schedule_times: Times the clock schedules the blocks by, when not ``ends`` (the replay paces by
                the recording's log times and locksteps by its stamps).
        """
        if not ends:
            raise ValueError("no candidate block")
        times = ends if schedule_times is None else schedule_times
        count = len(ends)
        if self.lockstep is not None:
            count, holders = self.lockstep.allowed(ends)
            if count == 0:
                self._held = True
                since = min((c.held_since for c in self.lockstep.holders() if c.held_since is not None),
                            default=self.clock())
                return Hold(holders, since)
        ready, wait = self.schedule.ready(times[:count])
        if self._held:
            # The end of a hold: as a cap, the clock starts again from here (no burst to catch up).
            self._held = False
            if self.schedule.factor > 0:
                self.schedule.anchor(times[0], self.clock())
                ready, wait = self.schedule.ready(times[:count])
        if ready:
            return Go(ready)
        return Wait(wait)

    def published(self, data_ns: int, topic: str = ALL_TOPICS) -> None:
        """The publisher publishes a message stamped ``data_ns`` on ``topic`` (call before publishing)."""
        if self.lockstep is not None:
            self.lockstep.published(data_ns, topic)
