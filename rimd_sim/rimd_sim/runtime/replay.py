"""The replay without ROS: which recorded message goes next, and when; the player controls of rosbag2.

:class:`Player` walks a recording's messages in log-time order and answers, each time it is asked
(:meth:`Player.step`), with the messages to publish now, or how long to wait, or who holds the run
(lockstep), or that it is paused or finished. The pacing is :class:`rimd_sim.runtime.pacing.Pacer`: message ``i``
is due at ``anchor + (log_time_i - log_time_anchor) / rate`` (the recorded timing at ``rate``); in lockstep it
also waits until every consumer has finished with its stamp minus the window. The controls are rosbag2's
player's (pause, resume, toggle, rate, seek, play next, burst; a start offset and a duration), and they act at
once: the replay node calls them from its services while its thread calls :meth:`Player.step` (a lock keeps
them apart).

Times: the start offset counts from the recording's first message (all topics), as ``ros2 bag play`` does;
``seek`` takes a recorded log time (the time base of ``metadata.yaml``). With ``restamp`` every header stamp is
shifted by one offset, so that the first message published carries the wall time it leaves: consumers that
check freshness see fresh data, and the data keep their own timing (a shift, not a rescale).
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

from rimd_sim.errors import ConfigError
from rimd_sim.io.cdr import HEADER_FIRST_TYPES, header_stamp, with_header_stamp
from rimd_sim.io.reader import RecordedMessage, Recording
from rimd_sim.runtime.pacing import Go, Hold, Pacer, ProgressVerdict, Wait
from rimd_sim.settings.lockstep import LockstepSettings
from rimd_sim.settings.params import BAD_REGEX_LISTS, group, param, parameters, regex_list_problem

__all__ = ["Finished", "Outgoing", "Paused", "Player", "PlayerState", "ReplaySettings"]


def _remap_entry(entry: str) -> bool:
    source, sep, target = entry.partition(":=")
    return bool(sep) and source.startswith("/") and target.startswith("/")


@dataclass(frozen=True)
class ReplaySettings:
    """The replay node's parameters (``rimd_replay``), read at start; the rate changes through ``~/set_rate``."""

    file: str = param("", "recording to replay: an .mcap file or a recording directory (required)", read_only=True)
    rate: float = param(1.0, "replay speed factor (2.0 = twice as fast as recorded; ~/set_rate changes it)", gt=0,
                        le=1e4, read_only=True)
    loop: bool = param(False, "start again from the start offset when the end is reached", read_only=True)
    start_offset: float = param(0.0, "where the replay starts, from the recording's first message", unit="s", ge=0,
                                le=1e9, read_only=True)
    playback_duration: float = param(0.0, "how much of the recording is played from the start offset (0 = to "
                                          "the end), as rosbag2's --playback-duration", unit="s", ge=0, le=1e9,
                                     read_only=True)
    topics: tuple[str, ...] = param((".*",), "topics to replay: regular expressions (full match)",
                                    rule="a list of regular expressions", check=regex_list_problem,
                                    breaks=BAD_REGEX_LISTS, read_only=True)
    remap: tuple[str, ...] = param((), "topic renames, entries '/from:=/to'",
                                   rule="a list of '/from:=/to' entries with absolute topic names",
                                   check=lambda entries: all(_remap_entry(e) for e in entries),
                                   breaks=(("x:=/y",), ("/a=/b",)), read_only=True)
    clock: bool = param(False, "publish /clock from the recorded log time (a recorded /clock is then not replayed; "
                               "always on in lockstep)", read_only=True)
    clock_frequency: float = param(100.0, "/clock publications per second of recorded time", unit="Hz", gt=0,
                                   le=1e6, read_only=True)
    start_paused: bool = param(False, "wait for ~/resume (or ~/play_next, ~/burst) before publishing",
                               read_only=True)
    wait_for_subscribers: int = param(0, "before the first message, wait (at most 10 s) until this many "
                                         "subscribers have matched: on each topic of wait_topics, or else on each "
                                         "replayed topic that has a subscriber (the node names the topics it "
                                         "waits for)", ge=0, le=1000, read_only=True)
    wait_topics: tuple[str, ...] = param((), "topics wait_for_subscribers waits on: regular expressions (full "
                                             "match) of replayed topics (empty: the topics that have a subscriber)",
                                         rule="a list of regular expressions", check=regex_list_problem,
                                         breaks=BAD_REGEX_LISTS, read_only=True)
    skip_unknown: bool = param(False, "replay the other topics when some message types are not installed",
                               read_only=True)
    restamp: bool = param(False, "shift every header stamp so that the first message carries the wall time it is "
                                 "published (for consumers that check freshness); the data keep their timing",
                          read_only=True)
    keep_alive: bool = param(False, "stay up at the end of the part played (until stopped), where ~/seek plays "
                                    "again: for a client that shows a timeline (`rimd replay --foxglove` sets it); "
                                    "as rosbag's --keep-alive", read_only=True)
    lockstep: LockstepSettings = group(LockstepSettings, "lockstep.")


@dataclass(frozen=True)
class Outgoing:
    """A message to publish: its recorded topic, its bytes (restamped or as recorded), log time and stamp."""

    topic: str
    data: bytes
    log_time: int
    stamp: int | None


@dataclass(frozen=True)
class PlayerState:
    """Where the playback stands, in one snapshot (``~/get_state``).

    Attributes:
        start_ns, end_ns: The part played, as log times (from the start offset to the last message, or to the
            end of ``playback_duration`` when that comes first).
        position_ns: The log time the player stands at (the last message published, or where a seek, a resume or
            a new pass put it).
        paused: Paused (``~/pause``).
        ended: Every message of the part has gone out (and no loop): only a seek plays again.
        rate: The playback rate.
        passes: Passes started (1 at start, one more per loop); seeks: seeks done. A change of either is a jump.
        published: Messages handed out for publishing since the start.
    """

    start_ns: int
    end_ns: int
    position_ns: int
    paused: bool
    ended: bool
    rate: float
    passes: int
    seeks: int
    published: int = 0

    @property
    def status(self) -> str:
        """``ended``, ``paused`` or ``playing`` (the end first: a replay paused at the end has ended)."""
        return "ended" if self.ended else "paused" if self.paused else "playing"


@dataclass(frozen=True)
class Paused:
    """The player is paused."""


@dataclass(frozen=True)
class Finished:
    """Nothing is left to play (and no loop)."""


#: Messages handed out by one step at most (as fast as possible).
MAX_BATCH = 50


class Player:
    """What a replay publishes next, and when. See the module docstring.

    Args:
        recording: The opened recording.
        topics: The recorded topics to play (the others are skipped).
        settings: The replay's settings.
        published_name: The name a recorded topic is published under (remapping), for lockstep's topics.
        clock: Monotonic seconds.
    """

    def __init__(self, recording: Recording, topics: Iterable[str], settings: ReplaySettings, *,
                 published_name: Callable[[str], str] = lambda topic: topic,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._recording = recording
        self._topics = sorted(topics)
        self._name = published_name
        self._clock = clock
        self._lock = threading.RLock()
        self.settings = settings
        self.rate = settings.rate
        first, last = recording.start_ns, recording.end_ns   # both None, or neither
        if first is None or last is None:
            raise ConfigError("file", settings.file, "must be a recording with at least one readable message")
        self.first_ns = first
        self.last_ns = last
        self.start_ns = first + round(settings.start_offset * 1e9)
        self.end_ns = (self.start_ns + round(settings.playback_duration * 1e9) if settings.playback_duration
                       else self.last_ns)
        if self.start_ns > self.last_ns:
            raise ConfigError("start_offset", settings.start_offset,
                              f"must be within the recording (it spans {(self.last_ns - first) / 1e9:.3f} s)")
        self._lockstep = settings.lockstep if settings.lockstep.enabled else None
        self._pacer = self._new_pacer()
        self._types = {name: topic.type_name for name, topic in recording.topics.items()}
        self._paused = settings.start_paused
        self._iter: Iterator[RecordedMessage] | None = None
        self._next: RecordedMessage | None = None
        self._offset: int | None = None      # restamp offset (ns), fixed by the first message published
        self.passes = 0
        self.seeks = 0
        self.published = 0
        self.run_id = ""
        self._new_pass = False
        self._position = self.start_ns        # log time the player stands at (the next message's, or the end)
        self._open_pass(self.start_ns)

    def _new_pacer(self) -> Pacer:
        topics = [self._name(t) for t in self._topics]
        return Pacer(self.rate, self._lockstep, topics=topics, clock=self._clock)

    # -- the stream ------------------------------------------------------------------------------------------
    def _open_pass(self, at_ns: int) -> None:
        """Read from the first message at or after ``at_ns``; a new pass when ``at_ns`` is the start."""
        self._iter = iter(self._recording.messages(self._topics))
        self._next = None
        for msg in self._iter:
            if msg.log_time >= at_ns:
                self._next = msg
                break
        if at_ns == self.start_ns:
            self.passes += 1
            self.run_id = uuid.uuid4().hex
            self._new_pass = True
            if self._lockstep is not None and self.passes > 1:
                self._pacer = self._new_pacer()   # a new run for the consumers: they join again
        self._anchor(at_ns)

    def _anchor(self, at_ns: int) -> None:
        self._position = at_ns
        self._pacer.schedule.anchor(at_ns)

    def _advance(self) -> None:
        self._next = next(self._iter, None) if self._iter is not None else None

    def _due(self) -> RecordedMessage:
        """The next message, while there is one (not :meth:`_ended`)."""
        assert self._next is not None
        return self._next

    def _ended(self) -> bool:
        return self._next is None or (self.end_ns is not None and self._next.log_time > self.end_ns)

    def start(self) -> None:
        """Playback begins now: the recorded timing counts from here (call once the publishers are ready)."""
        with self._lock:
            self._anchor(self._next.log_time if self._next is not None else self._position)

    def take_new_pass(self) -> bool:
        """Whether a pass started since the last call (the node then names the new run)."""
        with self._lock:
            new, self._new_pass = self._new_pass, False
            return new

    def _stamp(self, msg: RecordedMessage) -> int | None:
        return header_stamp(msg.data) if self._types.get(msg.topic) in HEADER_FIRST_TYPES else None

    def _out(self, msg: RecordedMessage) -> Outgoing:
        """The message as it leaves (restamped when asked), counted; the player moves past it."""
        stamp = self._stamp(msg)
        data = msg.data
        if self.settings.restamp and stamp is not None:
            if self._offset is None:
                self._offset = time.time_ns() - stamp
            stamp += self._offset
            data = with_header_stamp(data, stamp)
        if stamp is not None:
            self._pacer.published(stamp, self._name(msg.topic))
        self.published += 1
        self._position = msg.log_time
        self._advance()
        return Outgoing(msg.topic, data, msg.log_time, stamp)

    # -- the pace -------------------------------------------------------------------------------------------
    def step(self) -> list[Outgoing] | Wait | Hold | Paused | Finished:
        """The messages to publish now, or what to wait for."""
        with self._lock:
            if self._ended():
                if not self.settings.loop:
                    return Finished()
                self._open_pass(self.start_ns)
                if self._ended():
                    return Finished()
            if self._paused:
                return Paused()
            decision = self._decide()
            if not isinstance(decision, Go):
                return decision
            # Every message due now goes in one batch (each is decided on its own: the reader is a stream).
            out = [self._out(self._due())]
            while len(out) < MAX_BATCH and not self._ended() and isinstance(self._decide(), Go):
                out.append(self._out(self._due()))
            return out

    def _decide(self) -> Go | Wait | Hold:
        msg = self._due()
        stamp = self._stamp(msg)
        if stamp is not None and self.settings.restamp:   # decided on the stamp it will leave with, as reported
            stamp += self._offset if self._offset is not None else time.time_ns() - stamp
        return self._pacer.next([stamp if stamp is not None else self._last_stamp()], schedule_times=[msg.log_time])

    def _last_stamp(self) -> int:
        """For a message without a stamp: the run's current data time (it holds nobody)."""
        lockstep = self._pacer.lockstep
        return lockstep.published_ns if lockstep is not None else 0

    def pacer_events(self) -> list[tuple[str, str]]:
        """Lockstep's timeout and drop events since the last call."""
        with self._lock:
            lockstep = self._pacer.lockstep
            return lockstep.take_events() if lockstep is not None else []

    def progress(self, consumer: str, done_ns: int, instance: str = "", topics: dict[str, int] | None = None,
                 leaving: bool = False) -> ProgressVerdict:
        """A lockstep consumer's report (see :meth:`rimd_sim.runtime.pacing.Lockstep.progress`).

        Only for a player with lockstep (the node takes reports only then).
        """
        with self._lock:
            lockstep = self._pacer.lockstep
            assert lockstep is not None
            return lockstep.progress(consumer, done_ns, instance, topics, leaving)

    def holders_text(self) -> str:
        """Who holds the run (lockstep), for a person."""
        with self._lock:
            lockstep = self._pacer.lockstep
            if lockstep is None:
                return ""
            return ", ".join(f"{c.name} (" + ("not joined" if c.done_ns is None else
                                               f"done through {c.done_ns / 1e9:.6f} s") + ")"
                             for c in lockstep.holders())

    # -- the controls (rosbag2's player) --------------------------------------------------------------------
    @property
    def paused(self) -> bool:
        """Whether the playback is paused."""
        return self._paused

    @property
    def position_ns(self) -> int:
        """The log time the player stands at."""
        return self._position

    def state(self) -> PlayerState:
        """Where the playback stands (see :class:`PlayerState`), every field from the same moment."""
        with self._lock:
            return PlayerState(self.start_ns, min(self.end_ns, self.last_ns), self._position, self._paused,
                               not self.settings.loop and self._ended(), float(self.rate), self.passes, self.seeks,
                               self.published)

    def pause(self) -> bool:
        """Pause; False when already paused."""
        with self._lock:
            if self._paused:
                return False
            self._paused = True
            return True

    def resume(self) -> bool:
        """Resume from where it stands (the recorded timing from there); False when not paused."""
        with self._lock:
            if not self._paused:
                return False
            self._paused = False
            self._anchor(self._next.log_time if self._next is not None else self._position)
            return True

    def toggle(self) -> bool:
        """Pause when playing, resume when paused; returns whether it is paused now."""
        with self._lock:
            if not self.pause():
                self.resume()
            return self._paused

    def set_rate(self, rate: float) -> None:
        """Play at ``rate`` from the current position on.

        Raises:
            ConfigError: Naming ``rate`` and its rule (finite, > 0, <= 10000).
        """
        with self._lock:
            rate = parameters(ReplaySettings)["rate"].validate(rate)
            here = self._next.log_time if self._next is not None else self._position
            self.rate = rate
            self._pacer.schedule.set_factor(rate, here)
            self._position = here

    def seek(self, t_ns: int) -> str:
        """Go on from the first message recorded at or after ``t_ns``; returns where it landed.

        Raises:
            ConfigError: ``t_ns`` outside the part being played.
        """
        with self._lock:
            end = self.end_ns if self.end_ns is not None else self.last_ns
            if not self.start_ns <= t_ns <= end:
                raise ConfigError("time", f"{t_ns // 10**9}.{t_ns % 10**9:09d}",
                                  f"must be a recorded log time within the part being played, "
                                  f"{self.start_ns // 10**9}.{self.start_ns % 10**9:09d} to "
                                  f"{end // 10**9}.{end % 10**9:09d}")
            if self._next is not None and self._next.log_time <= t_ns:   # forward: read on
                while self._next is not None and self._next.log_time < t_ns:
                    self._advance()
                self._anchor(t_ns)
            else:
                passes, new = self.passes, self._new_pass
                self._open_pass(t_ns)
                self.passes, self._new_pass = passes, new   # a seek is not a new pass
            self.seeks += 1
            landed = self._next.log_time if self._next is not None else None
            return ("at the end (no message at or after it)" if landed is None else
                    f"at the message recorded at {landed // 10**9}.{landed % 10**9:09d}"
                    f" ({(landed - self.first_ns) / 1e9:.6f} s into the recording)")

    def play_next(self) -> Outgoing | None:
        """While paused, the next message now (None: not paused, or nothing left)."""
        with self._lock:
            if not self._paused or self._ended():
                return None
            out = self._out(self._due())
            self._anchor(self._next.log_time if self._next is not None else out.log_time)
            return out

    def burst(self, count: int) -> list[Outgoing]:
        """While paused, the next ``count`` messages now (fewer at the end; none when not paused)."""
        with self._lock:
            out: list[Outgoing] = []
            while self._paused and len(out) < count and not self._ended():
                out.append(self._out(self._due()))
            if out:
                self._anchor(self._next.log_time if self._next is not None else out[-1].log_time)
            return out
