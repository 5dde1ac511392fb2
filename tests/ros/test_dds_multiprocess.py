"""The simulator node in its own process talks to the test process over DDS, on the test's own domain only.

Hypotheses: the real ``rimd_simulator`` publishing ``rimd_msgs/msg/SampleBlock`` and serving
``rimd_msgs/srv/SetMotorFrequency`` is heard on the test's own ROS_DOMAIN_ID with loopback-only discovery;
the blocks arrive contiguous (first_index) with every field as the core computes it, and a frequency change
takes effect exactly at the stamp the service response names: the force channel received is, sample for
sample, the core's offline run with that command at that stamp. A rig on another domain stays unheard.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy

from harness.domains import lease_domain_id
from harness.ros import call_service, spin_until
from rimd_msgs.msg import SampleBlock
from rimd_msgs.srv import SetMotorFrequency

pytestmark = [pytest.mark.ros, pytest.mark.timeout(90)]

TOPIC = "/rig/impact/force"


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def test_sample_blocks_and_the_motor_service_across_processes(ros_processes, ros_executor):
    import rclpy

    from rimd_sim.instruments.rig_simulator import RigSimulator
    from rimd_sim.settings.config import SimConfig

    config = SimConfig().with_parameters({"gap": 0.0})
    # Paused, at 4x (stamps are simulation time): nothing is published before the subscription matched.
    rig = ros_processes.start_node("rimd_simulator", "--ros-args", "-p", "real_time_factor:=4.0",
                                   "-p", "start_paused:=true", "-p", "gap:=0.0")
    rig.wait_for_output(r"rig ready", timeout=60)
    node = rclpy.create_node("test_client", context=ros_executor.context)
    ros_executor.add_node(node)
    blocks: list[SampleBlock] = []
    sub = node.create_subscription(SampleBlock, TOPIC, blocks.append,
                                   QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE))
    client = node.create_client(SetMotorFrequency, "/rig/set_motor_frequency")
    assert spin_until(ros_executor, lambda: sub.get_publisher_count() > 0, 20)

    # A setpoint at an exact stamp, asked before the rig moves; then bad requests, refused, changing nothing.
    new_frequency, at_ns = 7.25, 500_000_000
    response = call_service(ros_executor, node, client, SetMotorFrequency.Request(
        frequency_hz=new_frequency, ramp_rate=4.0, start_stamp=_time(at_ns)), timeout=10)
    assert response.success, response.message
    assert response.frequency_hz == new_frequency and _ns(response.effective_stamp) == at_ns
    for bad_frequency, reason in ((math.nan, "finite"), (-1.0, ">= 0"), (1000.0, "above motor.max_frequency = 12 Hz")):
        refused = call_service(ros_executor, node, client,
                               SetMotorFrequency.Request(frequency_hz=bad_frequency), timeout=10)
        assert not refused.success and reason in refused.message, refused.message
        # The setpoint in force is the initial one (the change is scheduled for 0.5 s); it stays scheduled: the
        # samples below show it taking effect at its stamp.
        assert refused.frequency_hz == config.motor.initial_setpoint, refused

    trigger = node.create_client(__import__("std_srvs.srv", fromlist=["Trigger"]).Trigger, "/rig/resume")
    assert call_service(ros_executor, node, trigger, trigger.srv_type.Request(), timeout=10).success
    rate = 20000
    assert spin_until(ros_executor, lambda: blocks and blocks[-1].first_index >= 2 * rate, timeout=30)

    # Contiguous from sample 0, each block stamped at its first sample, every field as configured.
    channel = config.channel("impact_force")
    assert blocks[0].first_index == 0
    for previous, block in zip(blocks, blocks[1:], strict=False):
        assert block.first_index == previous.first_index + len(previous.samples)
    for block in blocks:
        assert _ns(block.header.stamp) == round(block.first_index * 1e9 / rate)
        assert block.header.frame_id == channel.frame_id and block.unit == channel.unit
        assert block.sample_rate == rate and (block.range_min, block.range_max) == (channel.range_min,
                                                                                     channel.range_max)
    # The samples are the core's, with the setpoint taking effect at the stamp the response named.
    core = RigSimulator(config, truth=False)
    core.set_motor_frequency(new_frequency, 4.0, at=Fraction(at_ns, 10**9))
    ends = sorted({Fraction(b.first_index + len(b.samples), rate) for b in blocks})
    expected = np.concatenate([c.channels["impact_force"].samples for c in core.advance_blocks(ends)])
    received = np.concatenate([np.asarray(b.samples) for b in blocks])
    assert np.array_equal(received, expected[:received.size])
    assert sum(b.saturated_count for b in blocks) == 0 and received.max() > 20.0   # impacts, within range
    assert "7.25 Hz" in rig.output()
    assert rig.stop() == 0, f"the simulator did not shut down cleanly on SIGINT:\n{rig.tail()}"


def _time(ns: int):
    from builtin_interfaces.msg import Time

    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def test_another_domain_hears_nothing(ros_processes, ros_executor):
    """A rig on another domain stays unheard: the isolation between tests relies on it. A listener on that
    domain hears it (the positive control), while one on the test's own domain, matched on the same topic name
    for as long, hears nothing."""
    import rclpy

    from rimd_sim.ros.clients.rig import RigClient

    with lease_domain_id() as other:
        rig = ros_processes.start_node("rimd_simulator", name="other_domain_rig",
                                       env={"ROS_DOMAIN_ID": str(other.domain_id)})
        rig.wait_for_output(r"rig ready", timeout=60)
        node = rclpy.create_node("listener", context=ros_executor.context)
        ros_executor.add_node(node)
        ours: list[SampleBlock] = []
        node.create_subscription(SampleBlock, TOPIC, ours.append, 10)
        theirs: list[SampleBlock] = []
        with RigClient(domain_id=other.domain_id, name="other_listener") as there:
            there.node.create_subscription(SampleBlock, TOPIC, theirs.append, 10)
            # Both listeners spin together until the other domain's has heard 50 blocks (0.5 s of data).
            assert spin_until(ros_executor, lambda: there.spin_until(lambda: len(theirs) >= 50, 0.01), 30)
        ros_executor.spin_once(timeout_sec=0.1)
        assert ours == [] and rig.is_running()
        assert node.count_publishers(TOPIC) == 0   # not even discovered
        rig.stop()
