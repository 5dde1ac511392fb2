"""``PolledSubscriptions``: the recorder's and the bridge's way of taking their block topics.

Hypotheses: under both executors a node runs on (events, single), every message published reaches the
handler exactly once, in order, with its message info (source timestamp), through the node's own takes and
never through the executor (which would hand it over without info); the node's other entities still run.
"""

from __future__ import annotations

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy

from harness.ros import spin_until
from rimd_sim.ros.nodes.polling import PolledSubscriptions, PollingNode

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("kind", ["events", "single"])
def test_every_message_reaches_the_handler_once_with_its_info_and_never_through_the_executor(rclpy_context, kind):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from std_msgs.msg import UInt32

    class Polling(PollingNode):
        def __init__(self) -> None:
            super().__init__("polling", context=rclpy_context)
            self.got: list[tuple[bytes, dict]] = []
            self.ticks = 0
            self._polled = PolledSubscriptions(self, 0.02)
            qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
            self._polled.create(UInt32, "/polled", qos, lambda data, info: self.got.append((data, info)))
            self.create_timer(0.01, self._tick)

        def _tick(self) -> None:
            self.ticks += 1

    node = Polling()
    sender = Node("sender", context=rclpy_context)
    pub = sender.create_publisher(UInt32, "/polled", QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    executor = EventsExecutor(context=rclpy_context) if kind == "events" else SingleThreadedExecutor(
        context=rclpy_context)
    executor.add_node(node)
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() == 1, timeout=10)
        for i in range(500):
            pub.publish(UInt32(data=i))
        assert spin_until(executor, lambda: len(node.got) >= 500, timeout=20), len(node.got)
        spin_until(executor, lambda: False, timeout=0.1)   # nothing more may come
        assert [int.from_bytes(data[4:8], "little") for data, _ in node.got] == list(range(500))
        assert all(info.get("source_timestamp", 0) > 0 for _, info in node.got)   # taken by the node itself
        assert node.ticks > 0   # the executor still runs the node's timers
    finally:
        executor.shutdown()
        node.destroy_node()
        sender.destroy_node()


def test_the_poll_period_follows_the_traffic():
    """Steady fast traffic keeps the short period, even across lockstep's short holds; slow traffic stretches it to
    the longest, never beyond; a burst after a quiet spell brings the short period back at once."""
    from rimd_sim.ros.nodes.polling import PollPeriod

    def steady(pace: PollPeriod, per_second: float, seconds: float = 1.0) -> float:
        for _ in range(round(seconds / pace.period)):
            period = pace.period
            pace.after(round(per_second * period), period)
        return pace.period

    assert PollPeriod(0.01, 0.05).period == 0.01
    assert steady(PollPeriod(0.01, 0.05, aim=40), 700) == 0.05          # the rig at real time: the longest
    assert steady(PollPeriod(0.01, 0.05, aim=40), 14_000) == 0.01       # lockstep at 20x: the shortest
    assert steady(PollPeriod(0.01, 0.05, aim=40), 1_600) == pytest.approx(0.025, rel=0.05)   # 40 a poll
    pace = PollPeriod(0.01, 0.05, aim=40)
    steady(pace, 14_000)
    for _ in range(5):                     # lockstep: a window's burst, then three empty polls while the rig holds
        assert pace.after(400, 0.01) == 0.01
        assert max(pace.after(0, 0.01) for _ in range(3)) <= 0.02
    quiet = PollPeriod(0.01, 0.05, aim=40)
    assert steady(quiet, 0) == 0.05                                    # nothing comes (a paused rig)
    assert quiet.after(taken=500, elapsed=0.05) == 0.01                # a burst: short again at once
    assert PollPeriod(0.02).after(taken=1, elapsed=1.0) == 0.02        # without a longest period: fixed
    # The timer follows when the period moves by more than a fifth, and always to a bound: a period that crept up
    # to 70 ms in small steps still reaches the longest (80 ms), though that is within a fifth of it.
    creep = PollPeriod(0.01, 0.08, aim=40)
    assert creep.after(taken=0, elapsed=1.0) == 0.08
    assert creep.worth_setting(70_000_000) and creep.worth_setting(10_000_000)
    assert not creep.worth_setting(80_000_000)
    creep.after(taken=600, elapsed=1.0)                                 # 600 messages/s: 66.7 ms
    assert not creep.worth_setting(70_000_000) and creep.worth_setting(50_000_000)
    for bad in ((0.0, 0.05), (0.05, 0.01)):
        with pytest.raises(ValueError, match="poll periods"):
            PollPeriod(*bad)
    with pytest.raises(ValueError, match="aim"):
        PollPeriod(0.01, 0.05, aim=0)


def test_slow_traffic_is_polled_less_often_and_a_burst_brings_the_short_period_back(rclpy_context):
    """The timer's period itself changes (under the events executor), and ``after`` runs after each timer poll."""
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from std_msgs.msg import UInt32

    class Polling(PollingNode):
        def __init__(self) -> None:
            super().__init__("adaptive", context=rclpy_context)
            self.got: list[bytes] = []
            self.periods: list[int] = []   # the timer's period at each poll
            self._polled = PolledSubscriptions(self, 0.01, longest=0.08, aim=40)
            self._polled.after = self._after
            qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
            self._polled.create(UInt32, "/adaptive", qos, lambda data, info: self.got.append(data))

        def _after(self) -> None:
            self.periods.append(self._polled.timer.timer_period_ns)

    node = Polling()
    sender = Node("adaptive_sender", context=rclpy_context)
    pub = sender.create_publisher(UInt32, "/adaptive", QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE))
    executor = EventsExecutor(context=rclpy_context)
    executor.add_node(node)
    timer = node._polled.timer
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() == 1, timeout=10)
        assert spin_until(executor, lambda: timer.timer_period_ns == 80_000_000, timeout=10)   # nothing comes
        quiet = len(node.periods)
        assert quiet > 0   # ``after`` ran after each poll
        for i in range(2000):
            pub.publish(UInt32(data=i))
        assert spin_until(executor, lambda: len(node.got) == 2000, timeout=20), len(node.got)
        # Hundreds of messages in a poll 80 ms after the one before: the period shortens at once (to 10 ms when
        # one poll takes them all; at most 40 ms even if the transport spread them over several polls).
        assert spin_until(executor, lambda: len(node.periods) > quiet + 2, timeout=10)
        assert min(node.periods[quiet:]) <= 40_000_000, node.periods[quiet:]
        assert spin_until(executor, lambda: timer.timer_period_ns == 80_000_000, timeout=10)   # quiet again
    finally:
        executor.shutdown()
        node.destroy_node()
        sender.destroy_node()


def test_the_transports_losses_are_read_by_the_poll_never_dispatched_by_the_executor(rclpy_context):
    """The sample-lost status is read by the node's own poll: no waitable of it reaches the executor (as executor
    events, a reader falling behind got so many that the recorder stopped taking messages and ignored SIGINT)."""
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from std_msgs.msg import UInt32

    class Polling(PollingNode):
        def __init__(self) -> None:
            super().__init__("lossy", context=rclpy_context)
            self.got = 0
            self.lost: list[int] = []
            self._polled = PolledSubscriptions(self, 0.01)
            qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
            before = len(list(self.waitables))
            self._polled.create(UInt32, "/lossless", qos, self._on)
            self.waitables_plain = len(list(self.waitables)) - before   # rclpy's own (incompatible QoS, type)
            before = len(list(self.waitables))
            self._polled.create(UInt32, "/lossy", qos, self._on, lost=self.lost.append)
            self.waitables_lost = len(list(self.waitables)) - before

        def _on(self, data: bytes, info: dict) -> None:
            self.got += 1

    node = Polling()
    assert node.waitables_lost == node.waitables_plain   # the lost status adds nothing for the executor
    sender = Node("lossy_sender", context=rclpy_context)
    pub = sender.create_publisher(UInt32, "/lossy", QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    executor = EventsExecutor(context=rclpy_context)
    executor.add_node(node)
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() == 1, timeout=10)
        for i in range(50):
            pub.publish(UInt32(data=i))
        assert spin_until(executor, lambda: node.got == 50, timeout=20), node.got
        assert node.lost == []   # read at every poll, and nothing was lost
    finally:
        executor.shutdown()
        node.destroy_node()
        sender.destroy_node()
