"""``RIMD_PLAIN`` (``rimd_sim.runtime.plain``): the benchmarking switch that puts plain rclpy and Python in place of
pieces of the rig's tuning, for ``benchmarks/bench_layers.py``.

Hypotheses: each piece named selects its plain path where the piece is chosen, and only that piece: the composed
rig's ``send`` publishes through rclpy on the caller's thread with no outbox (``outbox``); a polled node's DDS
subscription is an ordinary one that the executor dispatches, without the message info, and an in-process
hand-over is taken by a timer at the fixed shortest period (``polling``); the nodes' executor is rclpy's
SingleThreadedExecutor unless ``RIMD_EXECUTOR`` says otherwise (``executor``); the collector keeps CPython's
settings (``collector``); a thread keeps its name from the kernel (``threads``). ``all`` names every piece, unset
or empty none; a name that is no piece is refused naming the valid ones, by the library, a node and ``rimd``.
"""

from __future__ import annotations

import gc
import threading
from pathlib import Path

import pytest

from rimd_sim.errors import InputError
from rimd_sim.runtime import collector
from rimd_sim.runtime.plain import PIECES, PLAIN_ENV, plain, plain_pieces
from rimd_sim.runtime.threads import named_thread


def test_the_switch_reads_a_comma_list_all_or_nothing_and_refuses_a_name_that_is_no_piece(monkeypatch):
    monkeypatch.delenv(PLAIN_ENV, raising=False)
    assert plain_pieces() == frozenset() and not any(plain(p) for p in PIECES)
    monkeypatch.setenv(PLAIN_ENV, " outbox, polling ,")
    assert plain_pieces() == {"outbox", "polling"} and plain("polling") and not plain("executor")
    monkeypatch.setenv(PLAIN_ENV, "all")
    assert plain_pieces() == set(PIECES)
    monkeypatch.setenv(PLAIN_ENV, "outbox,gil")
    with pytest.raises(InputError, match=r"RIMD_PLAIN='outbox,gil' refused: gil is not a piece; give a "
                                         r"comma-separated list of outbox, polling, executor, collector, threads, "
                                         r"heap, or all"):
        plain("outbox")


def test_a_node_and_rimd_refuse_a_name_that_is_no_piece_before_they_start(monkeypatch, capsys):
    from rimd_sim import cli
    from rimd_sim.ros.nodes.base import run_node

    monkeypatch.setenv(PLAIN_ENV, "gil")
    made: list[bool] = []
    assert run_node("rimd_test", lambda: made.append(True), ()) == 2 and made == []
    assert "rimd_test: RIMD_PLAIN='gil' refused: gil is not a piece" in capsys.readouterr().err
    assert cli.entry() == cli.EXIT_USAGE
    assert "rimd: RIMD_PLAIN='gil' refused" in capsys.readouterr().err


def test_collector_plain_keeps_cpythons_settings(monkeypatch):
    frozen: list[bool] = []
    monkeypatch.setattr(gc, "freeze", lambda: frozen.append(True))
    saved = gc.get_threshold()
    try:
        gc.set_threshold(collector.CPYTHON_YOUNG_THRESHOLD, *saved[1:])
        monkeypatch.setenv(PLAIN_ENV, "collector")
        collector.configure()
        collector.for_node()
        collector.keep_what_exists()
        assert gc.get_threshold()[0] == collector.CPYTHON_YOUNG_THRESHOLD and frozen == []
        monkeypatch.setenv(PLAIN_ENV, "outbox,polling,executor,threads")   # every other piece: tuned
        collector.configure()
        collector.keep_what_exists()
        assert gc.get_threshold()[0] == collector.YOUNG_THRESHOLD and frozen == [True]
    finally:
        gc.set_threshold(*saved)


def test_threads_plain_are_named_for_python_only(monkeypatch):
    def names() -> tuple[str, str]:
        seen: list[tuple[str, str]] = []

        def target() -> None:
            comm = Path(f"/proc/self/task/{threading.get_native_id()}/comm").read_text().rstrip("\n")
            seen.append((threading.current_thread().name, comm))

        thread = named_thread(target, "rimd-pacing")
        thread.start()
        thread.join(timeout=10)
        return seen[0]

    monkeypatch.setenv(PLAIN_ENV, "threads")
    python_name, kernel = names()
    assert python_name == "rimd-pacing" and kernel != "rimd-pacing"
    monkeypatch.setenv(PLAIN_ENV, "all")
    assert names()[1] != "rimd-pacing"
    monkeypatch.setenv(PLAIN_ENV, "collector")
    assert names() == ("rimd-pacing", "rimd-pacing")


def test_executor_plain_is_the_single_threaded_executor_unless_rimd_executor_says_otherwise(monkeypatch):
    from rimd_sim.ros.nodes.base import EXECUTOR_ENV, executor_kind

    monkeypatch.delenv(EXECUTOR_ENV, raising=False)
    monkeypatch.delenv(PLAIN_ENV, raising=False)
    assert executor_kind() == "events"
    monkeypatch.setenv(PLAIN_ENV, "executor")
    assert executor_kind() == "single"
    monkeypatch.setenv(EXECUTOR_ENV, "events")
    assert executor_kind() == "events"


class FakePublisher:
    """What ``feeding_send`` uses of an rclpy publisher; notes each write and the thread it ran on."""

    def __init__(self, topic: str) -> None:
        self.topic_name = topic
        self.written: list[tuple[bytes, str]] = []

    def publish(self, data: bytes) -> None:
        self.written.append((data, threading.current_thread().name))

    def get_subscription_count(self) -> int:
        return 1


def test_outbox_plain_publishes_through_rclpy_on_the_callers_thread_without_an_outbox(monkeypatch):
    from rimd_sim.ros.nodes._sim_publishers import feeding_send
    from rimd_sim.ros.nodes.feed import InProcessFeed
    from rimd_sim.ros.nodes.outbox import Outbox

    monkeypatch.setenv(PLAIN_ENV, "outbox")
    pub = FakePublisher("/rig/truth")
    outbox, send = feeding_send(InProcessFeed(), {"truth": pub}, set())
    assert outbox is None
    send("truth", b"block")
    assert pub.written == [(b"block", threading.current_thread().name)]   # at once, on this thread

    monkeypatch.setenv(PLAIN_ENV, "polling")   # another piece: the outbox is there, and writes at its flush
    pub = FakePublisher("/rig/truth")
    outbox, send = feeding_send(InProcessFeed(), {"truth": pub}, set())
    try:
        assert isinstance(outbox, Outbox)
        send("truth", b"block")
        assert pub.written == []
        outbox.flush()
        assert [data for data, _ in pub.written] == [b"block"]
    finally:
        outbox.close()


@pytest.mark.ros
def test_polling_plain_subscribes_ordinarily_and_takes_hand_overs_at_the_fixed_period(rclpy_context, monkeypatch):
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import UInt32

    from harness.ros import spin_until
    from rimd_sim.ros.nodes.polling import LocalSubscription, PolledSubscriptions, PollingNode

    monkeypatch.setenv(PLAIN_ENV, "polling")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)

    class Plain(PollingNode):
        def __init__(self) -> None:
            super().__init__("plain_polling", context=rclpy_context)
            self.got: list[tuple[bytes, dict]] = []
            self._polled = PolledSubscriptions(self, 0.01, longest=0.05)
            self.sub = self._polled.create(UInt32, "/plain", qos, lambda data, info: self.got.append((data, info)),
                                           lost=lambda count: None)

    node = Plain()
    polled = node._polled
    assert polled is not None and polled.plain and polled.timer is None   # no timer until a hand-over is attached
    assert node.sub in node.subscriptions   # the executor takes it
    sender = Node("plain_sender", context=rclpy_context)
    pub = sender.create_publisher(UInt32, "/plain", qos)
    executor = EventsExecutor(context=rclpy_context)
    executor.add_node(node)
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() == 1, timeout=10)
        for i in range(20):
            pub.publish(UInt32(data=i))
        assert spin_until(executor, lambda: len(node.got) >= 20, timeout=20), len(node.got)
        assert [int.from_bytes(data[4:8], "little") for data, _ in node.got] == list(range(20))
        assert all(info == {} for _, info in node.got)   # dispatched by the executor, not taken by the node

        handed: list[bytes] = []
        local = polled.attach(LocalSubscription("/local", 10), lambda data, info: handed.append(data))
        assert polled.timer.timer_period_ns == 10_000_000 and polled.pace.longest == polled.pace.shortest
        local.put(b"hand-over")
        assert spin_until(executor, lambda: handed == [b"hand-over"], timeout=10)
    finally:
        executor.shutdown()
        node.destroy_node()
        sender.destroy_node()
