"""Two processes talk over DDS with the project's own interfaces (rimd_msgs built by colcon).

Hypothesis: a separate process publishing ``rimd_msgs/msg/SampleBlock`` and serving
``rimd_msgs/srv/SetMotorFrequency`` is heard by the test process on the test's own ROS_DOMAIN_ID with
loopback-only discovery; the blocks arrive contiguous (first_index), with every field as sent, and a
frequency change takes effect exactly at the sample the service response names.
"""

from __future__ import annotations

import math

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy

from harness import sample_block_server as server
from harness.domains import lease_domain_id
from harness.ros import call_service, spin_until
from rimd_msgs.msg import SampleBlock
from rimd_msgs.srv import SetMotorFrequency

pytestmark = [pytest.mark.ros, pytest.mark.timeout(60)]


def _time_to_index(stamp, sample_rate: float) -> int:
    return round((stamp.sec + stamp.nanosec * 1e-9) * sample_rate)


def test_sample_blocks_and_service_across_processes(ros_processes, ros_executor, ros_domain_id):
    rig = ros_processes.start_python(server.__file__, "--ros-args", "-r", "__ns:=/rig",
                                     name="sample_block_server")
    rig.wait_for_output(rf"sample_block_server ready: namespace /rig, domain {ros_domain_id}\b", timeout=20)

    import rclpy

    node = rclpy.create_node("test_client", context=ros_executor.context)
    ros_executor.add_node(node)
    blocks: list[SampleBlock] = []
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(SampleBlock, "/rig/test/samples", blocks.append, qos)
    client = node.create_client(SetMotorFrequency, "/rig/set_motor_frequency")

    assert spin_until(ros_executor, lambda: len(blocks) >= 10, timeout=15), f"received {len(blocks)} blocks"

    new_frequency = 7.25
    response = call_service(ros_executor, node, client,
                            SetMotorFrequency.Request(frequency_hz=new_frequency, ramp_rate=0.0), timeout=10)
    assert response.success, response.message
    assert response.frequency_hz == new_frequency
    switch_index = _time_to_index(response.effective_stamp, server.SAMPLE_RATE)
    assert switch_index > 0 and switch_index % server.BLOCK_SIZE == 0

    for bad_frequency, reason in ((math.nan, "finite"), (-1.0, ">= 0"), (1000.0, "maximum")):
        refused = call_service(ros_executor, node, client,
                               SetMotorFrequency.Request(frequency_hz=bad_frequency), timeout=10)
        assert not refused.success
        assert reason in refused.message
        assert refused.frequency_hz == new_frequency, "a refused request must leave the setpoint unchanged"

    target = switch_index + 10 * server.BLOCK_SIZE
    assert spin_until(ros_executor, lambda: blocks[-1].first_index >= target, timeout=15)

    # Contiguity: a consumer detects drops from first_index; over loopback with reliable QoS there are none.
    for previous, block in zip(blocks, blocks[1:], strict=False):
        assert block.first_index == previous.first_index + len(previous.samples)
    assert any(b.first_index < switch_index for b in blocks)
    assert any(b.first_index >= switch_index for b in blocks)

    for block in blocks:
        assert block.header.frame_id == server.FRAME_ID
        assert _time_to_index(block.header.stamp, server.SAMPLE_RATE) == block.first_index
        assert block.sample_rate == server.SAMPLE_RATE
        assert block.unit == "m"
        assert (block.range_min, block.range_max) == server.RANGE
        assert len(block.samples) == server.BLOCK_SIZE
        indices = range(block.first_index, block.first_index + len(block.samples))
        frequencies = [new_frequency if n >= switch_index else server.INITIAL_FREQUENCY for n in indices]
        expected = [server.expected_sample(n, f) for n, f in zip(indices, frequencies, strict=True)]
        assert list(block.samples) == expected, f"block at {block.first_index}"
        saturated = sum(1 for n, f in zip(indices, frequencies, strict=True)
                        if abs(math.sin(2 * math.pi * f * n / server.SAMPLE_RATE)) > server.RANGE[1])
        assert block.saturated_count == saturated
    assert sum(b.saturated_count for b in blocks) > 0, "the test signal should saturate the range"

    assert "set_motor_frequency(7.25): frequency set to 7.25 Hz" in rig.output()
    assert rig.stop() == 0, f"the server did not shut down cleanly on SIGINT:\n{rig.tail()}"


def test_other_domain_hears_nothing(ros_processes, ros_executor):
    """A publisher on another domain must stay unheard: isolation between tests relies on it."""
    with lease_domain_id() as other:
        other_domain = other.domain_id
        rig = ros_processes.start_python(server.__file__, name="other_domain_server",
                                         env={"ROS_DOMAIN_ID": str(other_domain)})
        _listen_for_nothing(rig, other_domain, ros_executor)
        rig.stop()


def _listen_for_nothing(rig, other_domain, ros_executor):
    rig.wait_for_output(rf"ready: namespace /, domain {other_domain}\b", timeout=20)

    import rclpy

    node = rclpy.create_node("listener", context=ros_executor.context)
    ros_executor.add_node(node)
    blocks: list[SampleBlock] = []
    node.create_subscription(SampleBlock, "/test/samples", blocks.append, 10)
    spin_until(ros_executor, lambda: bool(blocks), timeout=2.0)
    assert blocks == []
    assert "sample_block_server ready" in rig.output() and rig.is_running()
