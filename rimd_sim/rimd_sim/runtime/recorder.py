"""A recording session without ROS: a bag written on a thread of its own, loss counted, write errors reported.

Messages are queued to a :class:`~rimd_sim.io.bag.BagWriter` on a writer thread, and the session tells
how far each topic is written. The recorder node feeds it and reports it.

* :meth:`RecordingSession.put` queues one serialized message (from any thread). A full queue (``queue_size``
  messages) drops the newest message and counts it: nothing is ever dropped silently.
* The writer thread wakes once per batch (it sleeps ``batch_delay`` after the first message of a batch, then
  takes everything waiting; at once when a batch is waiting already), writes, counts the samples missing between
  consecutive blocks of a topic (``first_index`` gaps, :class:`LossCounter`), closes a chunk at least every
  ``flush_interval`` seconds, and tells ``on_written`` how far each topic has been written (the recorder's
  lockstep progress).
* Write errors (disk full, file size limit, quota, I/O error) are the bag's to handle: the first one stops the
  writing, never the session. It is logged once at ERROR naming the path and the system's reason, again every
  ``reminder`` seconds while it lasts, and when the writing resumes after :meth:`split` (the retry). What a
  full disk costs is counted per topic as *not written*.
* A stop stamp (:meth:`set_stop_at`, the recorder's ``stop_at``): every message whose header stamp is at or after
  it is left out (counted per topic as *after the stop*, not as loss), and a block (SampleBlock, RigState) that
  straddles it is cut to its samples strictly before it (:func:`rimd_sim.io.cdr.cut_block`). The messages left
  out still count as handled in ``on_written``: a rig in lockstep goes on, and a client waiting for a topic to
  reach the stop sees it. A message without a stamp is written. ``rimd experiment`` sets it to the end of its
  last step, so its recording ends there on every topic however late the recorder is stopped.
* Loss the file cannot show is counted too: messages the transport declares lost (:meth:`RecordingSession.
  transport_lost`, DDS's sample-lost status: a reliable reader told that samples are gone), and, for a lockstep
  consumer (``in_lockstep``), samples *missing at the start* of a sampled topic: the rig waits for a lockstep
  consumer from its join on, so every sampled topic must start at the same time; one that starts later than the
  earliest lost its first blocks on the way (:meth:`LossCounter.missing_at_start`). When it finishes, the session
  writes both into the recording (:data:`~rimd_sim.settings.recording.LOSS_METADATA`), and its summary counts them.
* Everything the writer does happens in order: :meth:`run_on_writer` runs a function after the messages queued
  before it (``~/split``, ``~/stop``); :meth:`close` writes everything queued, finishes the file and returns.

Time is read from ``clock`` (monotonic seconds) and the session's steps can be driven without the thread
(:meth:`process`), so the tests need neither DDS, nor root, nor a real full disk
(``tests/runtime/test_recording_session.py``).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from queue import Empty, SimpleQueue
from typing import Any

from rimd_sim.errors import CommandError
from rimd_sim.io.bag import BagWriter, FileInfo, WriteFailure
from rimd_sim.io.cdr import BLOCK_TYPES, block_span, cut_block, read_block, samples_before
from rimd_sim.io.msgdefs import MessageDefinitionError
from rimd_sim.runtime.threads import named_thread
from rimd_sim.settings.recording import LOSS_METADATA, STOP_METADATA

__all__ = ["LOSS_METADATA", "STOP_METADATA", "LossCounter", "RecordingSession", "StopRefused", "TopicLoss"]


class StopRefused(CommandError):
    """A stop stamp that a topic has already been written past (the recording could not end there)."""


#: Log levels of the session's lines.
INFO, WARNING, ERROR = "info", "warning", "error"
#: The transport's declared losses of one topic are said at most this often (s); every one is counted.
LOSS_LOG_INTERVAL_S = 5.0


class LossCounter:
    """Counts, per topic, samples missing between consecutive blocks (gaps in ``first_index``).

    The first block seen on a topic sets the start (a recorder started after the rig loses nothing). A block
    that starts before the expected index (the rig was restarted, or replayed) restarts the count and is
    counted in ``restarts``, not as loss.
    """

    def __init__(self) -> None:
        self.expected: dict[str, int] = {}
        self.first: dict[str, int] = {}
        self.lost_samples: dict[str, int] = {}
        self.lost_blocks: dict[str, int] = {}
        self.restarts: dict[str, int] = {}

    def observe(self, topic: str, first_index: int, count: int) -> int:
        """Record one block; return the number of samples missing just before it."""
        expected = self.expected.get(topic)
        missing = 0
        if expected is None:
            self.first[topic] = first_index
        elif first_index > expected:
            missing = first_index - expected
            self.lost_samples[topic] = self.lost_samples.get(topic, 0) + missing
            self.lost_blocks[topic] = self.lost_blocks.get(topic, 0) + max(1, round(missing / max(count, 1)))
        elif first_index < expected:
            self.restarts[topic] = self.restarts.get(topic, 0) + 1
        self.expected[topic] = first_index + count
        return missing

    def missing_at_start(self) -> dict[str, int]:
        """Per sampled topic: the samples before its first block, when another topic starts at the run's start.

        Sample indices count from the run's start on every channel, so a topic whose first block starts at index
        ``n`` lacks ``n`` samples. Only when some topic starts at index 0: then every topic should, for a
        lockstep consumer (the rig waits for it before its first block). A consumer that joins a run under way
        may have subscribed to its topics a block apart: nothing is said then. Meaningful in lockstep only.
        """
        if 0 not in self.first.values():
            return {}
        return {topic: first for topic, first in self.first.items() if first > 0}

@dataclass(frozen=True)
class TopicLoss:
    """What one topic received, wrote and lost."""

    received: int
    written: int
    lost_samples: int
    lost_blocks: int
    queue_dropped: int
    not_written: int
    transport_lost: int = 0
    missing_at_start: int = 0

    @property
    def lost(self) -> int:
        """Messages or samples missing from the recording, whatever the cause."""
        return (self.lost_samples + self.queue_dropped + self.not_written + self.transport_lost
                + self.missing_at_start)


class RecordingSession:
    """A bag written on a thread of its own, fed from any thread. See the module docstring.

    Args:
        bag: Where the messages go.
        queue_size: Messages waiting for the writer before new ones are dropped (and counted).
        flush_interval: The chunk in progress is closed at least this often (s).
        batch_delay: The writer waits this long after the first message of a batch (s), unless ``batch_now``
            messages are waiting already.
        batch_now: A batch this large is written at once (a rig faster than real time: at real time the rig's 600
            messages a second bring a handful per ``batch_delay``).
        reminder: While writing is stopped by an error, the log reminds of it this often (s).
        log: ``log(level, line)``, level ``info``, ``warning`` or ``error``.
        on_written: Called on the writer thread after each batch with the header stamp (ns) of the last
            message written per topic, for the messages that have one.
        in_lockstep: Whether the consumer has joined a lockstep run (then a sampled topic that starts late
            counts as loss); None: never.
        clock: Monotonic seconds.
        sleep: The writer's wait for the rest of a batch (``time.sleep``).
    """

    def __init__(self, bag: BagWriter, *, queue_size: int = 200_000, flush_interval: float = 1.0,
                 batch_delay: float = 0.02, batch_now: int = 20, reminder: float = 30.0,
                 log: Callable[[str, str], None] = lambda level, line: None,
                 on_written: Callable[[dict[str, int]], None] | None = None,
                 in_lockstep: Callable[[], bool] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.bag = bag
        self._queue_size = queue_size
        self._flush_interval = flush_interval
        self._batch_delay = batch_delay
        self._batch_now = batch_now
        self._sleep = sleep
        self._reminder = reminder
        self._log = log
        self._on_written = on_written
        self._in_lockstep = in_lockstep
        self._clock = clock
        # A SimpleQueue (C, thread-safe): the writer sleeps in get() until a message comes or a flush is due.
        self._queue: SimpleQueue[tuple] = SimpleQueue()
        self.types: dict[str, str] = {}
        self.received: dict[str, int] = {}
        self.dropped: dict[str, int] = {}
        self.transport: dict[str, int] = {}   # per topic: messages the transport declared lost
        self._lost_said: dict[str, tuple[float, int]] = {}   # per topic: when the log last said so, the total then
        self.loss = LossCounter()
        self._sequence: dict[str, int] = {}   # MCAP sequence number per topic (messages given to the writer)
        self.write_errors = 0                 # unexpected exceptions (not OSError: the bag handles those)
        self._reported: WriteFailure | None = None   # the bag's write error, once logged
        self._reported_at = 0.0
        self._retry_announced = False
        self._last_flush = clock()
        self._thread: threading.Thread | None = None
        self.stop_at: int | None = None          # header stamp (ns): messages at or after it are left out
        self.after_stop: dict[str, int] = {}     # per topic: messages left out at or after the stop stamp
        self.cut_blocks: dict[str, int] = {}     # per topic: blocks cut at the stop stamp
        self._written_through: dict[str, int] = {}   # per topic: the largest stamp written (writer thread)

    # -- feeding (any thread) ---------------------------------------------------------------------------------
    def add_topic(self, topic: str, type_name: str, offered: Sequence[Mapping[str, Any]]) -> None:
        """Declare a topic before its first message."""
        self.types[topic] = type_name
        self.received.setdefault(topic, 0)
        self._queue.put(("topic", topic, type_name, offered))

    def put(self, topic: str, data: bytes, log_time: int, publish_time: int = 0, stamp: int | None = None) -> bool:
        """Queue one serialized message of a declared topic; False when the queue was full (counted)."""
        self.received[topic] = self.received.get(topic, 0) + 1
        if self._queue.qsize() >= self._queue_size:
            self.dropped[topic] = self.dropped.get(topic, 0) + 1
            return False
        self._queue.put(("msg", topic, data, log_time, publish_time, stamp))
        return True

    def transport_lost(self, topic: str, count: int) -> None:
        """The transport declared ``count`` more messages of ``topic`` lost (any thread): counted and logged.

        Every loss is counted; the log says the first at once, then what came since at most every
        ``LOSS_LOG_INTERVAL_S`` per topic (an overloaded reader gets such a status many times a second).
        """
        if count <= 0:
            return
        total = self.transport[topic] = self.transport.get(topic, 0) + count
        now = self._clock()
        said = self._lost_said.get(topic)
        if said is not None and now - said[0] < LOSS_LOG_INTERVAL_S:
            return
        since = f"{total - said[1]} message(s) lost in the last {now - said[0]:.0f} s" if said else \
            f"{count} message(s) lost"
        self._lost_said[topic] = (now, total)
        self._log(WARNING, f"{topic}: the transport declared {since} ({total} so far): they will not reach the "
                           "recording")

    def add_metadata(self, name: str, values: Mapping[str, str]) -> None:
        """Add a metadata record to the current and every later file."""
        self._queue.put(("metadata", name, dict(values)))

    def run_on_writer(self, function: Callable[[], Any], timeout: float = 10.0) -> Any:
        """Run ``function`` on the writer, after the messages queued before it; return its result.

        Raises:
            TimeoutError: The writer did not get to it in time.
        """
        done = threading.Event()
        result: list[Any] = []
        self._queue.put(("call", function, done, result))
        if self._thread is None:   # no thread: everything queued is processed here, in order
            self.process()
        elif not done.wait(timeout):
            raise TimeoutError("the writer did not answer")
        if isinstance(result[0], Exception):
            raise result[0]
        return result[0]

    def set_stop_at(self, stamp_ns: int | None) -> None:
        """Leave out every message stamped at or after ``stamp_ns`` from now on (None: none); applied in order.

        Raises:
            StopRefused: A topic has already been written at or past ``stamp_ns``.
            TimeoutError: The writer did not get to it in time.
        """
        self.run_on_writer(lambda: self._apply_stop(stamp_ns))

    def _apply_stop(self, stamp_ns: int | None) -> None:
        if stamp_ns is not None:
            past = sorted(t for t, s in self._written_through.items() if s >= stamp_ns)
            if past:
                raise StopRefused(f"stop_at {stamp_ns} ns refused: {', '.join(past)} already written at or past it")
            self._safely(self.bag.add_metadata, STOP_METADATA, {
                "stop_at_ns": str(stamp_ns),
                "rule": "every message whose header stamp is at or after stop_at_ns left out; a block that "
                        "straddles it cut to its samples before it"})
        self.stop_at = stamp_ns

    def split(self) -> FileInfo | None:
        """Finish the current file (or clear a write error): the next message opens a new file."""
        return self.run_on_writer(self.bag.split)

    @property
    def queued(self) -> int:
        """Items waiting for the writer."""
        return self._queue.qsize()

    # -- the writer -------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the writer thread."""
        self._thread = named_thread(self._loop, "rimd-recorder")
        self._thread.start()

    def close(self, timeout: float = 60.0) -> None:
        """Write everything queued, finish the file and ``metadata.yaml``, stop the writer (idempotent)."""
        if self._thread is None:
            self.process()
            self._write_loss_record()
            self._safely(self.bag.close)
            self._check_failure()
            return
        self._queue.put(("stop",))   # the last item: everything before it is written
        self._thread.join(timeout)

    def _loop(self) -> None:
        queue = self._queue
        batch: deque[tuple] = deque()
        while True:
            if not batch:
                try:   # sleep until an item comes or the next flush is due (at most 1 s: failure reminders)
                    wait = self._last_flush + self._flush_interval - self._clock()
                    batch.append(queue.get(timeout=min(1.0, max(0.001, wait))))
                except Empty:
                    self._flush_if_due()
                    continue
                # Let the rest of the rig's block arrive, then take everything: one wake-up of this thread per
                # batch instead of one per message (each wake-up is a thread switch and a GIL hand-over). When a
                # batch is already waiting (a rig faster than real time), take it now: the sleep would only delay
                # the writing, and with it the lockstep progress that the rig waits for.
                if queue.qsize() + 1 < self._batch_now:
                    self._sleep(self._batch_delay)
                while True:
                    try:
                        batch.append(queue.get_nowait())
                    except Empty:
                        break
            if not self._handle_batch(batch):
                break
        self._write_loss_record()
        self._safely(self.bag.close)
        self._check_failure()

    def process(self) -> bool:
        """Handle every item waiting, on the calling thread; False once a stop was among them."""
        batch: deque[tuple] = deque()
        while True:
            try:
                batch.append(self._queue.get_nowait())
            except Empty:
                break
        return self._handle_batch(batch)

    def _handle_batch(self, batch: deque[tuple]) -> bool:
        """Handle the items of ``batch`` (it is emptied); False at a stop."""
        written: dict[str, int] = {}
        running = True
        while batch:
            item = batch.popleft()
            kind = item[0]
            if kind == "stop":
                batch.clear()
                running = False
                break
            if kind == "msg":
                self._write(item, written)
            elif kind == "topic":
                _, topic, type_name, offered = item
                try:
                    self.bag.add_topic(topic, type_name, offered)
                except MessageDefinitionError as exc:
                    self._log(ERROR, f"cannot record {topic}: {exc}")
                    self.types[topic] = "?"
            elif kind == "metadata":
                self._safely(self.bag.add_metadata, item[1], item[2])
            elif kind == "call":
                _, function, done, result = item
                try:
                    result.append(function())
                except Exception as exc:  # reported to the service caller
                    result.append(exc)
                done.set()
            if self.bag.failure is not self._reported:   # a new write error, or cleared by a split
                self._check_failure()
        if written and self._on_written is not None:
            self._on_written(written)
        return running

    def _write(self, item: tuple, written: dict[str, int]) -> None:
        _, topic, data, log_time, publish_time, stamp = item
        stop = self.stop_at
        if stop is not None and stamp is not None:
            data = self._before_stop(topic, data, stamp, stop)
            if data is None:   # at or after the stop: handled, not written
                written[topic] = max(stamp, written.get(topic, stamp))
                return
        if self.types.get(topic) in BLOCK_TYPES:
            try:
                first, count = block_span(data)
                missing = self.loss.observe(topic, first, count)
                if missing:
                    self._log(WARNING, f"{topic}: {missing} samples missing before index {first}")
            except (ValueError, IndexError):
                pass
        sequence = self._sequence[topic] = self._sequence.get(topic, 0) + 1
        # After a write error the bag only counts the message as not written (no I/O, no log line).
        self._safely(self.bag.write, topic, data, log_time, publish_time, sequence)
        if stamp is not None:
            written[topic] = max(stamp, written.get(topic, stamp))
            self._written_through[topic] = max(stamp, self._written_through.get(topic, stamp))
        self._flush_if_due()

    def _before_stop(self, topic: str, data: bytes, stamp: int, stop: int) -> bytes | None:
        """The message as written before the stop stamp: whole, a block cut at it, or None (left out, counted)."""
        type_name = self.types.get(topic)
        if stamp < stop and type_name in BLOCK_TYPES:
            try:
                _, size = block_span(data)
                keep = samples_before(stamp, float(read_block(data, type_name, arrays=0).sample_rate), size, stop)
                if keep < size:
                    data = cut_block(data, type_name, keep)
                    self.cut_blocks[topic] = self.cut_blocks.get(topic, 0) + 1
            except (ValueError, IndexError):
                pass   # bytes that do not read as a block: written as they came (the loss counter says so)
        if stamp >= stop:
            self.after_stop[topic] = self.after_stop.get(topic, 0) + 1
            return None
        return data

    def _flush_if_due(self) -> None:
        now = self._clock()
        if now - self._last_flush >= self._flush_interval:
            self._safely(self.bag.flush)
            self._check_failure()
            self._last_flush = now

    def _safely(self, function: Callable[..., Any], *args: Any) -> None:
        """Run a writer call; an unexpected exception is counted and logged (the first 5), never fatal.

        Write errors of the disk (``OSError``) do not come here: the bag handles them (:meth:`_check_failure`).
        """
        try:
            function(*args)
        except Exception as exc:  # a bug must not kill the writer silently
            self.write_errors += 1
            if self.write_errors <= 5:
                self._log(ERROR, f"writing the recording failed: {type(exc).__name__}: {exc}")

    def not_written(self) -> int:
        """Messages that write errors kept out of the files, in all."""
        return sum(self.bag.not_written.values())

    def _check_failure(self) -> None:
        """Log a new write error of the bag once, remind of it, and log when writing resumes."""
        bag, reported = self.bag, self._reported
        failure = bag.failure
        now = self._clock()
        if failure is not None and failure is not reported:
            self._reported, self._reported_at, self._retry_announced = failure, now, False
            if failure.file is not None:
                kept = (f"{failure.file.path.name} keeps the {failure.file.message_count} messages written before "
                        "the error (it has no summary; it reads back up to there), "
                        f"{failure.lost_in_chunk} messages of the chunk in progress are lost")
            else:
                kept = "no file was open (the new file held nothing and was deleted)"
            self._log(ERROR, f"{failure.describe()}: recording stopped, the node keeps running; {kept}, and every "
                             "message from now on is counted as not written. Free space, then call ~/split (or "
                             "~/stop and ~/start) to record into a new file")
        elif failure is None and reported is not None and bag.current_path is None:
            if not self._retry_announced:   # ~/split or ~/stop cleared it
                self._retry_announced = True
                self._log(INFO, f"the {reported.headline} error is cleared: the next message recorded opens a new "
                                "file")
        elif failure is None and reported is not None:
            self._reported, self._retry_announced = None, False
            self._log(INFO, f"writing again after the {reported.headline}: recording into {bag.current_path} "
                            f"({self.not_written()} messages not written in all)")
        elif failure is not None and now - self._reported_at >= self._reminder:
            self._reported_at = now
            self._log(ERROR, f"still not recording ({failure.describe()}): {self.not_written()} messages not "
                             "written so far; call ~/split once space is back")

    # -- reporting --------------------------------------------------------------------------------------------
    def loss_report(self) -> dict[str, TopicLoss]:
        """Per topic: what was received, written and lost, whatever the cause (:class:`TopicLoss`)."""
        bag, loss = self.bag, self.loss
        late = loss.missing_at_start() if self._in_lockstep is not None and self._in_lockstep() else {}
        return {topic: TopicLoss(self.received.get(topic, 0), bag.written.get(topic, 0),
                                 loss.lost_samples.get(topic, 0), loss.lost_blocks.get(topic, 0),
                                 self.dropped.get(topic, 0), bag.not_written.get(topic, 0),
                                 self.transport.get(topic, 0), late.get(topic, 0))
                for topic in sorted(self.types)}

    def _write_loss_record(self) -> None:
        """Write what the file cannot show was lost into it (:data:`LOSS_METADATA`), if anything was."""
        values = {}
        for topic, r in self.loss_report().items():
            if r.transport_lost:
                values[f"{topic} transport_lost"] = str(r.transport_lost)
            if r.missing_at_start:
                values[f"{topic} missing_at_start"] = str(r.missing_at_start)
        if values:
            self._safely(self.bag.add_metadata, LOSS_METADATA, values)

    def summary(self) -> list[str]:
        """The lines printed when the recording ends: files, write failures, loss per topic."""
        bag = self.bag
        files = [f for f in bag.files if f.finished or f.error]
        lines = [f"recording finished: {len(files)} file(s) in {bag.output_dir}"]
        for f in files:
            lines.append(f"  {f.path.name}: {f.message_count} messages, {f.size} bytes" + (
                f"; INCOMPLETE: {f.error}; no summary, it reads back up to there" if f.error else ""))
        for failure in bag.failures:
            lines.append(f"  WRITE FAILED: {failure.describe()}; {failure.lost_in_chunk} messages of the chunk in "
                         "progress lost, the messages after it not written")
        if bag.metadata_error is not None:
            lines.append(f"  metadata.yaml not updated: {bag.metadata_error}")
        if self.stop_at is not None:
            left = sum(self.after_stop.values())
            lines.append(f"  stopped at stamp {self.stop_at} ns: {left} message(s) at or after it left out, "
                         f"{sum(self.cut_blocks.values())} block(s) cut there")
        cause = bag.failures[0].headline if bag.failures else "write error"
        for topic, r in self.loss_report().items():
            parts = [f"{r.lost_samples} samples missing (first_index gaps)" if r.lost_samples else "",
                     f"{r.queue_dropped} messages dropped (queue full)" if r.queue_dropped else "",
                     f"{r.not_written} messages not written ({cause})" if r.not_written else "",
                     f"{r.transport_lost} messages declared lost by the transport" if r.transport_lost else "",
                     f"{r.missing_at_start} samples missing at the start (lockstep)" if r.missing_at_start else ""]
            lines.append(f"  {topic}: {r.written} messages written; "
                         + ("LOSS: " + ", ".join(p for p in parts if p) if r.lost else "no loss"))
        return lines
