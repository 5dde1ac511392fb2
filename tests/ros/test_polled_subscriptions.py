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
