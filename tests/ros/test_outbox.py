"""The composed rig's DDS writes (``rimd_sim.ros.nodes.outbox``).

Hypotheses:

- the GIL-free writer puts on the wire exactly the bytes rclpy's own ``publish`` would: a reader gets every message,
  in order, byte for byte (that a ctypes call releases the GIL is ctypes' own documented behaviour; what it buys
  is measured by bench_lockstep.py);
- where it cannot be built (an object without a publisher's address) it says so (None), and the outbox falls back
  to rclpy's ``publish``;
- the outbox writes every message once, in the order sent, whether a flush writes on the caller's thread (a small
  batch, nothing waiting) or hands the batch to its thread (a large batch, or flushes back to back), and a message
  sent from another thread goes at the next flush;
- at most ``max_waiting`` batches wait for the thread: a caller faster than the writes waits for them (a rig running
  free does not queue its blocks without end);
- a write that fails on the outbox's thread is raised by the caller's next flush, and nothing after it is written;
  ``close`` writes what is waiting first.
"""

from __future__ import annotations

import threading
import time

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy

from harness.ros import spin_until
from rimd_sim.ros.nodes.outbox import Outbox, PublishFailed, gil_free_writer


class Recorder:
    """Fake writers that note (name, data, thread) for every write."""

    def __init__(self) -> None:
        self.writes: list[tuple[str, bytes, str]] = []

    def writer(self, name: str, fail_on: bytes | None = None):
        def write(data: bytes) -> None:
            if data == fail_on:
                raise PublishFailed(f"publishing on {name} failed")
            self.writes.append((name, data, threading.current_thread().name))
        return write, write


def wait_idle(outbox: Outbox) -> None:
    assert outbox.drain(timeout=20)


def test_every_message_is_written_once_in_order_on_either_thread():
    rec = Recorder()
    a, b = rec.writer("a"), rec.writer("b")
    outbox = Outbox(thread_batch=5, gap=0.0)
    sent: list[tuple[str, bytes]] = []
    try:
        for n, size in enumerate([1, 3, 7, 2, 12, 1, 4, 30, 2]):   # small batches inline, large ones threaded
            for k in range(size):
                name, w = ("a", a) if k % 2 else ("b", b)
                data = f"{n}:{k}".encode()
                outbox.send(w, data)
                sent.append((name, data))
            outbox.flush()
        wait_idle(outbox)
    finally:
        outbox.close()
    assert [(name, data) for name, data, _ in rec.writes] == sent
    threads = {thread for _, _, thread in rec.writes}
    assert threads == {threading.current_thread().name, "rimd-dds"}   # both ways were taken
    assert outbox.inline + outbox.threaded == len(sent) and outbox.threaded >= 7 + 12 + 30


def test_flushes_back_to_back_go_to_the_thread_and_a_message_from_another_thread_goes_at_the_next_flush():
    rec = Recorder()
    w = rec.writer("a")
    outbox = Outbox(thread_batch=100, gap=60.0)   # every flush within a minute of the last is back to back
    try:
        outbox.send(w, b"first")
        outbox.flush()                       # the first flush: nothing before it, so on this thread
        other = threading.Thread(target=outbox.send, args=(w, b"from another thread"))
        other.start()
        other.join()
        assert rec.writes == [("a", b"first", threading.current_thread().name)]   # not written by the sender
        outbox.send(w, b"second")
        outbox.flush()
        wait_idle(outbox)
    finally:
        outbox.close()
    assert [(d, t) for _, d, t in rec.writes] == [(b"first", threading.current_thread().name),
                                                  (b"from another thread", "rimd-dds"), (b"second", "rimd-dds")]


def test_a_failed_write_on_the_thread_is_raised_by_the_next_flush_and_stops_the_writing():
    rec = Recorder()
    w = rec.writer("a", fail_on=b"bad")
    outbox = Outbox(thread_batch=1, gap=0.0)
    try:
        for data in (b"ok", b"bad", b"never"):
            outbox.send(w, data)
        outbox.flush()
        wait_idle(outbox)
        with pytest.raises(PublishFailed, match="publishing on a failed"):
            outbox.flush()
        outbox.send(w, b"after")
        with pytest.raises(PublishFailed):
            outbox.flush()
    finally:
        outbox.close()
    assert [d for _, d, _ in rec.writes] == [b"ok"]


def test_a_caller_faster_than_the_writes_waits_for_room():
    release = threading.Event()
    written: list[bytes] = []

    def slow(data: bytes) -> None:
        release.wait(30)
        written.append(data)

    outbox = Outbox(thread_batch=1, gap=0.0, max_waiting=2)
    flushed = [0]

    def caller() -> None:
        for i in range(5):
            outbox.send((slow, slow), bytes([i]))
            outbox.flush()
            flushed[0] += 1

    worker = threading.Thread(target=caller)
    worker.start()
    try:
        deadline = time.monotonic() + 20
        while flushed[0] < 2 and time.monotonic() < deadline:
            time.sleep(0.005)
        assert flushed[0] == 2
        worker.join(0.2)   # the third flush waits: two batches wait for the thread, which is stuck on the first
        assert worker.is_alive() and flushed[0] == 2
    finally:
        release.set()
        worker.join(20)
        outbox.close()
    assert flushed[0] == 5 and written == [bytes([i]) for i in range(5)]


def test_close_writes_what_is_waiting():
    rec = Recorder()
    w = rec.writer("a")
    outbox = Outbox(thread_batch=1, gap=0.0)
    for i in range(50):
        outbox.send(w, bytes([i]))
        if i % 10 == 9:
            outbox.flush()
    outbox.close()   # the last five were never flushed by the caller
    assert [d for _, d, _ in rec.writes] == [bytes([i]) for i in range(50)]


def test_an_object_without_a_publishers_address_gets_no_gil_free_writer():
    class NotAPublisher:
        topic_name = "/x"
        handle = object()

        def publish(self, data: bytes) -> None:
            pass

    assert gil_free_writer(NotAPublisher()) is None
    fallback = NotAPublisher()
    inline, threaded = Outbox.writer(fallback)
    assert inline == fallback.publish and threaded == fallback.publish


@pytest.mark.ros
def test_the_gil_free_writer_puts_rclpys_bytes_on_the_wire(rclpy_context):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    writer_node = Node("outbox_writer", context=rclpy_context)
    reader_node = Node("outbox_reader", context=rclpy_context)
    pub = writer_node.create_publisher(String, "/outbox_test", qos)
    got: list[bytes] = []
    reader_node.create_subscription(String, "/outbox_test", got.append, qos, raw=True)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(reader_node)
    try:
        write = gil_free_writer(pub)
        assert write is not None, "librcl's rcl_publish_serialized_message was not found"
        assert spin_until(executor, lambda: pub.get_subscription_count() == 1, timeout=10)
        sent = [serialize_message(String(data="x" * n)) for n in range(0, 300, 7)]
        for data in sent:
            write(data)
        for data in sent:
            pub.publish(data)   # rclpy's own
        assert spin_until(executor, lambda: len(got) >= 2 * len(sent), timeout=20), len(got)
        spin_until(executor, lambda: False, timeout=0.1)   # nothing more may come
        assert len(got) == 2 * len(sent)
        assert got[:len(sent)] == got[len(sent):]
        assert [g[:len(d)] for g, d in zip(got, sent, strict=False)] == sent

    finally:
        executor.shutdown()
        writer_node.destroy_node()
        reader_node.destroy_node()


@pytest.mark.ros
def test_many_messages_in_one_gil_free_call_reach_the_reader_in_order_and_a_failed_one_stops_them(rclpy_context):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from rimd_sim.ros.nodes.outbox import GilFreeWriter, _batch_kernel, write_many

    found = _batch_kernel()
    assert found is not None, "the compiled loop of write_many could not be made"
    assert found[0].targetoptions.get("nogil") is True   # the point of it: one GIL release for the whole batch
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    writer_node = Node("outbox_many_writer", context=rclpy_context)
    reader_node = Node("outbox_many_reader", context=rclpy_context)
    pubs = [writer_node.create_publisher(String, f"/outbox_many_{k}", qos) for k in range(2)]
    got: list[tuple[int, bytes]] = []
    for k in range(2):
        reader_node.create_subscription(String, f"/outbox_many_{k}", lambda data, k=k: got.append((k, data)), qos,
                                        raw=True)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(reader_node)
    try:
        writers = [gil_free_writer(p) for p in pubs]
        assert all(isinstance(w, GilFreeWriter) for w in writers)
        assert spin_until(executor, lambda: all(p.get_subscription_count() == 1 for p in pubs), timeout=10)
        sent = [(n % 3 % 2, serialize_message(String(data=f"{n}:" + "y" * (n * 13 % 251)))) for n in range(60)]
        write_many([(writers[k], data) for k, data in sent])
        assert spin_until(executor, lambda: len(got) >= len(sent), timeout=20), len(got)
        for k in range(2):   # each topic in order, byte for byte (rclpy's bytes, a reader's padding aside)
            mine = [d for t, d in sent if t == k]
            theirs = [d for t, d in got if t == k]
            assert [g[:len(d)] for g, d in zip(theirs, mine, strict=True)] == mine

        # A write that rcl refuses (no publisher at that address) raises naming the topic; the ones before it are
        # written, none after it.
        bad = GilFreeWriter(writers[0]._publish, writers[0]._reset, writers[0].handle, 0, "/nowhere")
        got.clear()
        later = [serialize_message(String(data=f"later {n}")) for n in range(3)]
        with pytest.raises(PublishFailed, match="publishing on /nowhere failed"):
            write_many([(writers[1], later[0]), (bad, later[1]), (writers[1], later[2])])
        assert spin_until(executor, lambda: len(got) >= 1, timeout=20)
        spin_until(executor, lambda: False, timeout=0.2)   # nothing more may come
        assert [(t, d[:len(later[0])]) for t, d in got] == [(1, later[0])]
    finally:
        executor.shutdown()
        writer_node.destroy_node()
        reader_node.destroy_node()
