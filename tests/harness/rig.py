"""Running the rig for recorder and replay tests: start, collect raw messages, drive through services."""

from __future__ import annotations

import time
from pathlib import Path

from harness.ros import call_service, spin_until

RIG_TOPICS = {
    "/rig/cart/displacement": "SampleBlock",
    "/rig/rimd/displacement": "SampleBlock",
    "/rig/rimd/acceleration": "SampleBlock",
    "/rig/impact/force": "SampleBlock",
    "/rig/truth": "RigState",
    "/rig/motor/state": "MotorState",
    "/rig/impact/events": "ImpactEvent",
}
BLOCK_TOPICS = [t for t, kind in RIG_TOPICS.items() if kind in ("SampleBlock", "RigState")]


class RawCollector:
    """A node in the test process holding the serialized bytes of every message of the rig topics."""

    def __init__(self, executor, topics=RIG_TOPICS, remap=None):  # noqa: ANN001
        from rclpy.node import Node
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        import rimd_msgs.msg

        self.node = Node("test_collector", context=executor.context)
        executor.add_node(self.node)
        self.messages: dict[str, list[bytes]] = {t: [] for t in topics}
        self.times: dict[str, list[float]] = {t: [] for t in topics}
        qos = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
        for topic, kind in topics.items():
            def callback(data, topic=topic):  # noqa: ANN001
                self.messages[topic].append(data)
                self.times[topic].append(time.monotonic())
            name = (remap or {}).get(topic, topic)
            self.node.create_subscription(getattr(rimd_msgs.msg, kind), name, callback, qos, raw=True)


def start_rig(ros_processes, out: Path, *recorder_args: str, paused: bool = True):  # noqa: ANN001
    recorder = ros_processes.start_node("rimd_recorder", "--ros-args", "-p", f"output_dir:={out}",
                                        "-p", "flush_interval:=0.5", *recorder_args)
    recorder.wait_for_output(r"recording .* into", timeout=30)
    simulator = ros_processes.start_node(
        "rimd_simulator", "--ros-args", "-p", "motor.initial_setpoint:=3.75", "-p", f"start_paused:={paused}")
    simulator.wait_for_output(r"rig ready", timeout=60)
    recorder.wait_for_output(r"recording /rig/truth", timeout=30)
    recorder.wait_for_output(r"recording /rig/impact/events", timeout=30)
    return recorder, simulator


def trigger(executor, node, service: str, timeout: float = 10.0):  # noqa: ANN001
    from std_srvs.srv import Trigger

    client = node.create_client(Trigger, service)
    return call_service(executor, node, client, Trigger.Request(), timeout)


def run_for(executor, seconds: float) -> None:  # noqa: ANN001
    deadline = time.monotonic() + seconds
    spin_until(executor, lambda: time.monotonic() >= deadline, seconds + 1)


def record_rig(ros_processes, ros_executor, out: Path, seconds: float, *recorder_args: str):  # noqa: ANN001
    """Run the rig for ``seconds`` with recorder and collector; pause the rig; return both processes."""
    recorder, simulator = start_rig(ros_processes, out, *recorder_args)
    collector = RawCollector(ros_executor)
    for topic in RIG_TOPICS:  # the collector is matched with every publisher before the rig starts
        spin_until(ros_executor, lambda t=topic: collector.node.count_publishers(t) > 0, 10)
    run_for(ros_executor, 0.5)
    assert trigger(ros_executor, collector.node, "/rig/resume").success
    run_for(ros_executor, seconds)
    assert trigger(ros_executor, collector.node, "/rig/pause").success
    run_for(ros_executor, 1.0)  # everything published reaches both sides
    return recorder, simulator, collector


