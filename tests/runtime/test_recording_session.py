"""The recorder's session (rimd_sim.runtime.recorder) without ROS, without root, without a real full disk.

Hypotheses: messages are written in the order they came and read back bit for bit by an independent reader;
gaps in ``first_index`` are counted as lost samples; a full queue drops and counts; how far each topic is
written is told after each batch; a full disk stops the writing once (logged once, reminded every
``reminder`` seconds on the session's clock), keeps a clean prefix, counts every message not written, and
``split`` retries into a new file once space is back; the summary says all of it. The disk is a fake that
fills up: the bag writes through it (``BagWriter(opener=...)``) and it answers with ENOSPC as a disk does,
after writing what fits.
"""

from __future__ import annotations

import errno
import os
import threading
import time
from pathlib import Path

from rclpy.serialization import serialize_message

from harness.clock import FakeClock
from rimd_msgs.msg import SampleBlock
from rimd_sim.io.bag import BagWriter, qos_profile_dict
from rimd_sim.io.reader import open_recording
from rimd_sim.runtime.recorder import RecordingSession

TOPIC = "/rig/cart/displacement"
BLOCK = "rimd_msgs/msg/SampleBlock"


class FakeDisk:
    """A disk of ``capacity`` bytes shared by every file opened through it (``opener``)."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.used = 0

    def opener(self, path: Path) -> FakeFile:
        return FakeFile(self, path)


class FakeFile:
    """A real file whose writes stop with ENOSPC once the disk is full (after writing what fits)."""

    def __init__(self, disk: FakeDisk, path: Path) -> None:
        self.disk, self.path = disk, path
        self._fd: int | None = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.size = 0

    def write(self, data) -> int:
        room = self.disk.capacity - self.disk.used
        view = memoryview(data)
        chunk = view[:max(0, room)]
        os.write(self._fd, chunk)
        self.size += len(chunk)
        self.disk.used += len(chunk)
        if len(chunk) < len(view):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path))
        return len(data)

    def tell(self) -> int:
        return self.size

    def flush(self) -> None:
        pass

    def truncate(self, size: int) -> None:
        os.ftruncate(self._fd, size)
        self.disk.used -= self.size - size
        self.size = size

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def os_name() -> str:
    """The calling thread's name as the kernel has it."""
    return Path(f"/proc/self/task/{threading.get_native_id()}/comm").read_text().rstrip("\n")


def block(index: int, n: int = 100) -> bytes:
    # Samples that compress poorly, so that the disk fills after a known, modest number of messages.
    return serialize_message(SampleBlock(first_index=index * n, sample_rate=2000.0, unit="m",
                                         samples=[((index * 7919 + k * 104729) % 100003) / 100003.0
                                                  for k in range(n)]))


def session(tmp_path: Path, disk: FakeDisk | None = None, **kwargs):
    log: list[tuple[str, str]] = []
    written: list[dict[str, int]] = []
    bag = BagWriter(tmp_path / "rec", chunk_size=8192, opener=disk.opener if disk else None)
    kwargs.setdefault("clock", FakeClock())
    s = RecordingSession(bag, log=lambda level, line: log.append((level, line)), on_written=written.append, **kwargs)
    s.add_topic(TOPIC, BLOCK, [qos_profile_dict(depth=100)])
    return s, log, written


def test_messages_are_written_in_order_and_gaps_counted(tmp_path):
    s, log, written = session(tmp_path)
    sent = [block(i) for i in range(50) if i != 20]          # block 20 lost upstream: 100 samples missing
    for i, data in enumerate(sent):
        assert s.put(TOPIC, data, 10**18 + i, stamp=1000 + i)
    s.process()
    assert written == [{TOPIC: 1000 + len(sent) - 1}]       # how far the topic is written, after the batch
    s.close()
    assert [m.data for m in open_recording(tmp_path / "rec").messages()] == sent
    report = s.loss_report()[TOPIC]
    assert (report.received, report.written, report.lost_samples, report.lost_blocks) == (49, 49, 100, 1)
    assert ("warning", f"{TOPIC}: 100 samples missing before index 2100") in log
    assert any("LOSS: 100 samples missing" in line for line in s.summary())


def test_a_full_queue_drops_the_newest_and_counts_it(tmp_path):
    s, _, _ = session(tmp_path, queue_size=4)                 # the topic declaration takes one place
    results = [s.put(TOPIC, block(i), 10**18 + i) for i in range(6)]
    assert results == [True, True, True, False, False, False]
    s.close()
    report = s.loss_report()[TOPIC]
    assert (report.received, report.written, report.queue_dropped) == (6, 3, 3)
    assert any("3 messages dropped (queue full)" in line for line in s.summary())


def test_a_full_disk_stops_the_writing_once_and_split_retries(tmp_path):
    disk = FakeDisk(capacity=120_000)
    s, log, _ = session(tmp_path, disk, reminder=30.0)
    given = [block(i) for i in range(400)]                    # ~340 kB: far more than the disk
    for i, data in enumerate(given):
        s.put(TOPIC, data, 10**18 + i * 50_000_000)
    s.process()
    errors = [line for level, line in log if level == "error"]
    assert len(errors) == 1, errors
    assert "disk full: " in errors[0] and "No space left on device (errno 28, ENOSPC)" in errors[0]
    assert "recording stopped, the node keeps running" in errors[0] and "~/split" in errors[0]
    failure = s.bag.failure
    n_ok = s.bag.written[TOPIC]
    assert 0 < n_ok < 400 and n_ok + s.bag.not_written[TOPIC] == 400

    # Still full: more messages are counted, not written, and the error is not repeated ...
    s.put(TOPIC, block(400), 2 * 10**18)
    s.process()
    assert s.bag.not_written[TOPIC] == 401 - n_ok and len([x for x in log if x[0] == "error"]) == 1
    # ... until the reminder is due on the session's clock.
    s._clock.now += 31.0
    s.put(TOPIC, block(401), 2 * 10**18 + 1)
    s.process()
    assert [line for level, line in log if level == "error"][-1].startswith("still not recording (disk full")

    # Space comes back: split clears the error, the next message opens a new file.
    disk.capacity = 10**9
    assert s.split() is None and s.bag.failure is None
    assert ("info", "the disk full error is cleared: the next message recorded opens a new file") in log
    for i, data in enumerate(given[:100]):
        s.put(TOPIC, data, 3 * 10**18 + i)
    s.process()
    assert any(line.startswith("writing again after the disk full: recording into ") for _, line in log)
    s.close()
    recording = open_recording(tmp_path / "rec")
    assert [r.complete for r in recording.reports] == [False, True]
    assert [m.data for m in recording.messages()] == given[:n_ok] + given[:100]
    summary = "\n".join(s.summary())
    assert f"{failure.file.path.name}: {n_ok} messages" in summary and "INCOMPLETE: disk full" in summary
    assert "WRITE FAILED: disk full" in summary and f"{402 - n_ok} messages not written (disk full)" in summary


def test_the_writer_thread_runs_calls_after_the_messages_before_them(tmp_path):
    s, _, written = session(tmp_path)
    s.start()
    for i in range(20):
        s.put(TOPIC, block(i), 10**18 + i, stamp=i)
    assert s.run_on_writer(lambda: s.bag.written[TOPIC], timeout=10) == 20
    # The writer is a thread of its own, named for Python and for the kernel (what `top -H` shows).
    assert s.run_on_writer(lambda: (threading.current_thread().name, os_name()), timeout=10) == ("rimd-recorder",) * 2
    assert threading.current_thread().name != "rimd-recorder"
    info = s.split()
    assert info is not None and info.message_count == 20 and info.finished
    s.close(timeout=10)
    assert written and written[-1][TOPIC] == 19


def test_a_stop_stamp_cuts_every_topic_there_and_the_file_stays_standard(tmp_path):
    """``stop_at`` (what ``rimd experiment`` sets to the end of its last step): messages stamped at or after it are
    left out, the block that straddles it is cut to its samples strictly before it, a message without a stamp is
    written; the lockstep progress still moves past it; independent readers read the file."""
    import pytest

    from harness.bags import read_with_mcap_ros2, read_with_rosbags
    from rimd_msgs.msg import ImpactEvent
    from rimd_sim.runtime.recorder import STOP_METADATA, StopRefused

    s, log, written = session(tmp_path)
    s.add_topic("/rig/impact/events", "rimd_msgs/msg/ImpactEvent", [qos_profile_dict(depth=100)])
    ms = 1_000_000

    def stamped_block(i: int) -> bytes:   # 100 samples at 2 kHz: block i covers [50 i, 50 i + 50) ms
        msg = SampleBlock(first_index=100 * i, sample_rate=2000.0, unit="m", samples=[float(k) for k in range(100)])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(50 * ms * i, 10**9)
        return serialize_message(msg)

    def event(t_ns: int) -> bytes:
        msg = ImpactEvent()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 10**9)
        return serialize_message(msg)

    s.put(TOPIC, stamped_block(0), 1, stamp=0)
    s.process()
    stop = 130 * ms                     # inside block 2: its samples 0..59 (100 .. 129.5 ms) are before it
    s.set_stop_at(stop)
    with pytest.raises(StopRefused, match=TOPIC):   # block 0 is written up to 0 ns: a stop at 0 cannot hold
        s.set_stop_at(0)
    assert s.stop_at == stop
    for i in range(1, 5):
        s.put(TOPIC, stamped_block(i), 1 + i, stamp=50 * ms * i)
    s.put("/rig/impact/events", event(129 * ms), 10, stamp=129 * ms)
    s.put("/rig/impact/events", event(stop), 11, stamp=stop)   # on the stop: after it
    s.put("/rig/impact/events", event(5), 12, stamp=None)       # no stamp known: written
    s.process()
    assert written[-1] == {TOPIC: 200 * ms, "/rig/impact/events": stop}   # handled through, for the lockstep
    s.close()
    rec_dir = tmp_path / "rec"
    (mcap_file,) = rec_dir.glob("*.mcap")
    messages = read_with_mcap_ros2(mcap_file)
    blocks = [m for topic, _, _, m in messages if topic == TOPIC]
    assert [b.first_index for b in blocks] == [0, 100, 200]
    assert [len(b.samples) for b in blocks] == [100, 100, 60]
    assert list(blocks[-1].samples) == [float(k) for k in range(60)] and blocks[-1].unit == "m"
    assert [m.header.stamp.nanosec for topic, _, _, m in messages if topic != TOPIC] == [129 * ms, 5]
    counts, by_rosbags = read_with_rosbags(rec_dir)
    assert counts == {TOPIC: 3, "/rig/impact/events": 2}
    assert [raw for _, raw, _, _ in by_rosbags] == [raw for _, raw, _, _ in messages]
    assert open_recording(rec_dir).metadata[STOP_METADATA]["stop_at_ns"] == str(stop)
    assert s.after_stop == {TOPIC: 2, "/rig/impact/events": 1} and s.cut_blocks == {TOPIC: 1}
    report = s.loss_report()[TOPIC]
    assert (report.written, report.lost) == (3, 0)   # left out at the stop: not loss
    assert any(f"stopped at stamp {stop} ns: 3 message(s) at or after it left out, 1 block(s) cut" in line
               for line in s.summary())


def _blocks_from(first_block: int, count: int, rate: float, n: int) -> list[bytes]:
    return [serialize_message(SampleBlock(first_index=(first_block + i) * n, sample_rate=rate, unit="m",
                                          samples=[0.0] * n)) for i in range(count)]


def test_declared_losses_are_all_counted_but_said_at_most_every_few_seconds(tmp_path):
    """An overloaded reader gets the transport's loss status many times a second: each is counted, the log says
    the first at once and then what came since, at most every LOSS_LOG_INTERVAL_S per topic."""
    from rimd_sim.runtime.recorder import LOSS_LOG_INTERVAL_S

    clock = FakeClock()
    s, log, _ = session(tmp_path, clock=clock)
    for _ in range(100):
        s.transport_lost(TOPIC, 2)
        clock.advance(0.01)
    s.transport_lost("/clock", 1)
    lines = [line for _, line in log if "declared" in line]
    assert s.transport[TOPIC] == 200 and s.transport["/clock"] == 1
    assert lines == [f"{TOPIC}: the transport declared 2 message(s) lost (2 so far): they will not reach the "
                     "recording", "/clock: the transport declared 1 message(s) lost (1 so far): they will not reach "
                     "the recording"]
    clock.advance(LOSS_LOG_INTERVAL_S)
    s.transport_lost(TOPIC, 5)
    assert log[-1][1].startswith(f"{TOPIC}: the transport declared 203 message(s) lost in the last 6 s (205 so far)")
    s.close()


def test_loss_the_file_cannot_show_is_counted_said_and_written_into_it(tmp_path):
    """What a lockstep recorder knows was lost before the file: the transport's declared losses, and a sampled
    topic that starts later than the run (a lockstep rig waits for its consumer from sample 0 on every topic).
    Counted per topic, said in the summary, written into the recording (``rimd_loss``), read back by the
    analysis' loss report; nothing of it without lockstep, or when no topic starts at the run's start."""
    from rimd_sim.analysis.recordings.recorded import RecordedData, loss_text
    from rimd_sim.runtime.recorder import LOSS_METADATA

    force = "/rig/impact/force"
    lockstep = [True]
    s, log, _ = session(tmp_path, in_lockstep=lambda: lockstep[0])
    s.add_topic(force, BLOCK, [qos_profile_dict(depth=100)])
    for i, data in enumerate(_blocks_from(0, 10, 20000.0, 200)):          # from the run's start: index 0
        s.put(force, data, 10**18 + i)
    for i, data in enumerate(_blocks_from(3, 7, 2000.0, 20)):             # its first 3 blocks never came
        s.put(TOPIC, data, 10**18 + i)
    s.transport_lost(TOPIC, 3)
    s.process()
    report = s.loss_report()
    assert (report[TOPIC].missing_at_start, report[TOPIC].transport_lost, report[TOPIC].lost_samples) == (60, 3, 0)
    assert report[force].lost == 0
    assert any(level == "warning" and "declared 3 message(s) lost" in line for level, line in log)
    line = next(x for x in s.summary() if x.startswith(f"  {TOPIC}:"))
    assert "3 messages declared lost by the transport" in line and "60 samples missing at the start" in line
    lockstep[0] = False                                                  # a free-run recorder: topics start apart
    assert s.loss_report()[TOPIC].missing_at_start == 0
    lockstep[0] = True
    s.close()
    recording = open_recording(tmp_path / "rec")
    assert recording.metadata[LOSS_METADATA] == {f"{TOPIC} transport_lost": "3", f"{TOPIC} missing_at_start": "60"}
    loss = RecordedData(tmp_path / "rec", recording, 0).loss()
    assert loss["recorder"] == {f"{TOPIC} transport_lost": 3, f"{TOPIC} missing_at_start": 60}
    assert "said by the recorder" in loss_text(loss)


def test_a_lockstep_recording_joined_mid_run_says_nothing_of_late_starts(tmp_path):
    """No topic from the run's start (a consumer that joined a run under way, its topics subscribed a block
    apart): the start says nothing, and a recording without loss has no ``rimd_loss`` record."""
    from rimd_sim.runtime.recorder import LOSS_METADATA

    force = "/rig/impact/force"
    s, _, _ = session(tmp_path, in_lockstep=lambda: True)
    s.add_topic(force, BLOCK, [qos_profile_dict(depth=100)])
    for i, data in enumerate(_blocks_from(50, 5, 20000.0, 200)):
        s.put(force, data, 10**18 + i)
    for i, data in enumerate(_blocks_from(51, 5, 2000.0, 20)):
        s.put(TOPIC, data, 10**18 + i)
    s.close()
    assert all(r.lost == 0 for r in s.loss_report().values())
    assert LOSS_METADATA not in open_recording(tmp_path / "rec").metadata


def test_the_writer_waits_for_the_rest_of_a_batch_only_when_a_message_comes_alone(tmp_path):
    # At real time a message comes alone: the writer sleeps batch_delay so that the rest of the rig's block joins
    # it (one wake-up per batch). Faster than real time a batch is waiting already: it is written at once, so the
    # lockstep progress that the rig waits for is not held back by the sleep.
    slept: list[float] = []
    s, _, written = session(tmp_path, batch_delay=0.25, batch_now=10, sleep=slept.append)
    for i in range(10):
        s.put(TOPIC, block(i), 10**18 + i, stamp=i)
    s.start()
    try:
        deadline = time.monotonic() + 30
        while not written and time.monotonic() < deadline:
            time.sleep(0.005)
        assert written[0] == {TOPIC: 9}
        assert slept == []
        s.put(TOPIC, block(10), 10**18 + 10, stamp=10)
        while len(written) < 2 and time.monotonic() < deadline:
            time.sleep(0.005)
        assert written[1] == {TOPIC: 10}
        assert slept == [0.25]
    finally:
        s.close(timeout=10)
