"""The simulator node in its own process, heard over DDS on the test's own domain.

Hypotheses: the node publishes every channel as contiguous blocks whose stamps are exactly
``t0 + first_index / sample_rate``; a bad motor request is refused with a reason while the rig keeps
publishing; a good one takes effect at the block boundary the response names; at gap 0 and 3.75 Hz the
impact events arrive one per excitation cycle with the core's steady peak force; a bad parameter set is
refused with the rule.
"""

from __future__ import annotations

import math

import pytest
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from harness.ros import call_service, spin_until
from rimd_msgs.msg import ImpactEvent, MotorState, SampleBlock
from rimd_msgs.srv import SetMotorFrequency
from rimd_sim.core import RigModel, SimConfig

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]

RATES = {"cart/displacement": 2000.0, "rimd/displacement": 2000.0, "rimd/acceleration": 20000.0,
         "impact/force": 20000.0}


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


@pytest.fixture
def fast_rig(ros_processes, ros_executor):
    """The simulator at real_time_factor 0, gap 0, motor started at 3.75 Hz without ramp."""
    rig = ros_processes.start_node(
        "rimd_simulator", "--ros-args", "-p", "real_time_factor:=0.0", "-p", "motor.initial_frequency:=3.75",
        "-p", "motor.initial_setpoint:=3.75")
    rig.wait_for_output(r"rig ready", timeout=30)
    import rclpy

    node = rclpy.create_node("probe", context=ros_executor.context)
    ros_executor.add_node(node)
    return rig, node


def test_channels_contiguous_exact_stamps_and_impacts(fast_rig, ros_executor):
    rig, node = fast_rig
    qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
    blocks: dict[str, list[SampleBlock]] = {topic: [] for topic in RATES}
    for topic in RATES:
        node.create_subscription(SampleBlock, "/rig/" + topic, blocks[topic].append, qos)
    events: list[ImpactEvent] = []
    node.create_subscription(ImpactEvent, "/rig/impact/events", events.append, qos)
    motor: list[MotorState] = []
    node.create_subscription(MotorState, "/rig/motor/state", motor.append, qos)
    clock: list[Clock] = []
    node.create_subscription(Clock, "/clock", clock.append, 10)

    assert spin_until(ros_executor, lambda: len(blocks["impact/force"]) >= 1200 and len(events) >= 30, timeout=60)
    for topic, received in blocks.items():
        rate = RATES[topic]
        # Late joining is allowed (the node started first); from the first block heard on, nothing is lost.
        for prev, blk in zip(received, received[1:], strict=False):
            assert blk.first_index == prev.first_index + len(prev.samples), topic
        for blk in received:
            assert blk.sample_rate == rate
            assert len(blk.samples) == rate / 100
            assert _ns(blk.header.stamp) == round(blk.first_index * 1e9 / rate), topic  # t0 = 0 at factor 0
    force = [max(b.samples) for b in blocks["impact/force"]]
    assert max(force) > 60.0
    assert clock and motor and motor[-1].frequency == 3.75

    # Steady state: one impact per cycle, peak force as the core computes it for this point (79.2 N).
    steady = [e for e in events if _ns(e.header.stamp) > 6e9]
    assert len(steady) >= 10
    cycles = [e.cycle_index for e in steady]
    assert cycles == list(range(cycles[0], cycles[0] + len(cycles)))
    core = RigModel(SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75}),
                    channels=False, truth=False).advance(10.0).impacts
    assert steady[-1].peak_force == pytest.approx(core[-1].peak_force, rel=1e-6)


def test_bad_requests_refused_and_the_rig_keeps_publishing(fast_rig, ros_executor):
    rig, node = fast_rig
    qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
    motor: list[MotorState] = []
    node.create_subscription(MotorState, "/rig/motor/state", motor.append, qos)
    client = node.create_client(SetMotorFrequency, "/rig/set_motor_frequency")
    assert spin_until(ros_executor, lambda: len(motor) > 5, timeout=30)
    bad = [(math.nan, 0.0, "finite"), (math.inf, 0.0, "finite"), (-math.inf, 0.0, "finite"), (-1.0, 0.0, ">= 0"),
           (13.0, 0.0, "max_frequency"), (3.0, -1.0, "ramp_rate"), (3.0, math.nan, "ramp_rate")]
    for freq, ramp, reason in bad:
        count = len(motor)
        response = call_service(ros_executor, node, client,
                                SetMotorFrequency.Request(frequency_hz=freq, ramp_rate=ramp), timeout=10)
        assert not response.success and reason in response.message, (freq, ramp, response.message)
        assert response.frequency_hz == 3.75
        assert spin_until(ros_executor, lambda c=count: len(motor) > c + 3, timeout=10), "rig stopped publishing"
    response = call_service(ros_executor, node, client, SetMotorFrequency.Request(frequency_hz=5.0, ramp_rate=10.0),
                            timeout=10)
    assert response.success and response.frequency_hz == 5.0
    effective = _ns(response.effective_stamp)
    assert effective % 10_000_000 == 0  # a block boundary (100 blocks/s)
    assert spin_until(ros_executor, lambda: motor[-1].frequency == 5.0, timeout=20)
    before = [m for m in motor if _ns(m.header.stamp) <= effective]
    assert before and all(m.frequency == 3.75 for m in before)
    assert f"set_motor_frequency at t = {effective / 1e9:.6f} s" in rig.output()

    params = node.create_client(SetParameters, "/rig/rimd_simulator/set_parameters")
    for name, value, reason in (("gap", -1e-3, ">= 0"), ("contact.model", "rubber", "one of"),
                                ("channels.impact_force.sample_rate", 0.0, "> 0")):
        pv = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value) if isinstance(value, float) \
            else ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
        result = call_service(ros_executor, node, params,
                              SetParameters.Request(parameters=[Parameter(name=name, value=pv)]), timeout=10)
        assert not result.results[0].successful
        text = result.results[0].reason
        # Either rclpy's descriptor range check or the core's rule answers; both name key and value.
        assert name in text and (reason in text or "out of range" in text), text
    count = len(motor)
    assert spin_until(ros_executor, lambda: len(motor) > count + 3, timeout=10)
    assert rig.stop() == 0, rig.tail()
