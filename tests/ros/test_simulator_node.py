"""The simulator node in its own process, heard over DDS on the test's own domain: its wiring.

The runtime's logic (stamps, impacts per cycle, refusals, commands at exact stamps, pause, perturbation, reset,
the run's identity) is tested in-process on a fake clock, tests/runtime/test_simulator_runtime.py. Here:
every topic arrives over DDS as contiguous blocks stamped ``t0 + first_index / sample_rate``; the services
answer with the runtime's answers (a refusal with its reason and the setpoint in force, an acceptance with the
stamp it takes effect, also a requested stamp) and the rig keeps publishing; the parameter services refuse a bad
value with the rule; pause stops the stream and resume continues it without a gap. At real time, every channel on
one wall-clock t0 is tests/ros/test_cyclone_reader.py's (a reader in another process) and
tests/ros/test_rig_timing.py's. In this process: the first /diagnostics come as soon as
the node spins, to a reader that has matched, not at the 1 Hz timer's first tick.
"""

from __future__ import annotations

import math
import re

import pytest
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from harness.ros import call_service, spin_until
from rimd_msgs.msg import ImpactEvent, MotorState, SampleBlock
from rimd_msgs.srv import SetMotorFrequency

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]

RATES = {"cart/displacement": 2000.0, "rimd/displacement": 2000.0, "rimd/acceleration": 20000.0,
         "impact/force": 20000.0}


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


@pytest.fixture
def fast_rig(ros_processes, ros_executor, request):
    """The simulator at real_time_factor 0 (or the factor given as indirect parameter), gap 0; the motor at
    rest, or at 3.75 Hz from t = 0 when the
    test is marked ``running``."""
    setpoint = "3.75" if request.node.get_closest_marker("running") else "0.0"
    factor = getattr(request, "param", "0.0")
    rig = ros_processes.start_node(
        "rimd_simulator", "--ros-args", "-p", f"real_time_factor:={factor}",
        "-p", f"motor.initial_frequency:={setpoint}", "-p", f"motor.initial_setpoint:={setpoint}")
    rig.wait_for_output(r"rig ready", timeout=30)
    import rclpy

    node = rclpy.create_node("probe", context=ros_executor.context)
    ros_executor.add_node(node)
    return rig, node


# Paced at 4x: a Python subscriber in the test process takes a few thousand messages per second, and at
# factor 0 (about 30,000 messages/s) a reliable subscriber that falls further behind than the publishers'
# history (20 s of simulation time) loses blocks by the DDS contract, more so on a loaded machine.
@pytest.mark.parametrize("fast_rig", ["4.0"], indirect=True)
def test_channels_contiguous_exact_stamps_and_impacts(fast_rig, ros_executor):
    """Motor at rest, then set_motor_frequency(3.75 Hz) at gap 0 through the service: impacts start.

    Their steady state, one per cycle with the core's peak force, is the runtime's test.
    """
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

    assert spin_until(ros_executor, lambda: len(motor) > 10, timeout=30)
    assert not events, "no impact with the cart at rest"
    client = node.create_client(SetMotorFrequency, "/rig/set_motor_frequency")
    response = call_service(ros_executor, node, client, SetMotorFrequency.Request(frequency_hz=3.75, ramp_rate=50.0),
                            timeout=10)
    assert response.success, response.message
    start = _ns(response.effective_stamp)
    assert spin_until(ros_executor, lambda: len(events) >= 3, timeout=60)
    # The events and the blocks come on topics of their own: the blocks holding the impacts may still be on their
    # way when the third event is taken (under load, only the first, weaker impact's blocks may be in).
    third = _ns(events[2].header.stamp)
    assert spin_until(ros_executor, lambda: all(received and _ns(received[-1].header.stamp) > third + 20_000_000
                                                for received in blocks.values()), timeout=30), \
        "the blocks did not reach the third impact"
    for topic, received in blocks.items():
        rate = RATES[topic]
        # Late joining is allowed (the node started first); from the first block heard on, nothing is lost.
        for prev, blk in zip(received, received[1:], strict=False):
            assert blk.first_index == prev.first_index + len(prev.samples), topic
        for blk in received:
            assert blk.sample_rate == rate
            assert len(blk.samples) == rate / 100
            assert _ns(blk.header.stamp) == round(blk.first_index * 1e9 / rate), topic  # t0 = 0 when not at real time
    force = [max(b.samples) for b in blocks["impact/force"]]
    assert max(force) > 60.0
    assert clock and motor and motor[-1].frequency == 3.75
    assert all(_ns(e.header.stamp) > start for e in events)


@pytest.mark.running
def test_bad_requests_refused_and_the_rig_keeps_publishing(fast_rig, ros_executor):
    rig, node = fast_rig
    qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
    motor: list[MotorState] = []
    node.create_subscription(MotorState, "/rig/motor/state", motor.append, qos)
    # The rig runs as fast as it can and outruns this process's reader on a loaded machine: ``motor`` holds every
    # state, in order, some way behind the rig; ``latest`` keeps only the newest (depth 1), where the rig is now.
    latest: list[MotorState] = []
    node.create_subscription(MotorState, "/rig/motor/state", latest.append,
                             QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
    client = node.create_client(SetMotorFrequency, "/rig/set_motor_frequency")
    assert spin_until(ros_executor, lambda: len(motor) > 5 and latest, timeout=30)
    bad = [(math.nan, 0.0, "finite"), (3.0, -1.0, "ramp_rate")]   # the runtime's test has every rule
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
    assert spin_until(ros_executor, lambda: latest[-1].frequency == 5.0, timeout=20)
    before = [m for m in motor if _ns(m.header.stamp) <= effective]
    assert before and all(m.frequency == 3.75 for m in before)
    assert f"set_motor_frequency at simulation time {effective / 1e9:.6f} s" in rig.output()

    # start_stamp: a stamp already passed is refused naming the field and the rule.
    from builtin_interfaces.msg import Time
    now = _ns(motor[-1].header.stamp)
    for stamp, reason in ((now - 1_000_000_000, "already passed"),):
        request = SetMotorFrequency.Request(frequency_hz=4.0, start_stamp=Time(sec=stamp // 10**9,
                                                                                nanosec=stamp % 10**9))
        response = call_service(ros_executor, node, client, request, timeout=10)
        assert not response.success and "start_stamp" in response.message and reason in response.message, \
            response.message
        assert response.frequency_hz == 5.0
    # A stamp ahead, between two samples, answered exactly (that the ramp starts exactly there is the runtime's
    # test). The rig runs as fast as it can, so it is paused while the request travels (the stamp is then surely
    # ahead of it).
    from std_srvs.srv import Trigger
    pause, resume = (node.create_client(Trigger, f"/rig/{name}") for name in ("pause", "resume"))
    paused = call_service(ros_executor, node, pause, Trigger.Request(), timeout=10)
    assert paused.success, paused.message
    # t0 = 0 here: the simulation time is the stamp
    paused_at = round(float(re.search(r"paused at simulation time (\S+) s", paused.message).group(1)) * 1e9)
    at = paused_at + 3_000_000_000 + 123_457
    request = SetMotorFrequency.Request(frequency_hz=4.0, ramp_rate=1000.0,
                                        start_stamp=Time(sec=at // 10**9, nanosec=at % 10**9))
    response = call_service(ros_executor, node, client, request, timeout=10)
    assert response.success and _ns(response.effective_stamp) == at, response.message
    assert call_service(ros_executor, node, resume, Trigger.Request(), timeout=10).success
    assert spin_until(ros_executor, lambda: _ns(latest[-1].header.stamp) > at + 50_000_000, timeout=30)
    assert latest[-1].frequency_setpoint == 4.0

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
    count = len(latest)
    assert spin_until(ros_executor, lambda: len(latest) > count + 3, timeout=10)
    assert rig.stop() == 0, rig.tail()


@pytest.mark.running
# At 4x too (see above): at factor 0 this test's own subscriber, under load, can fall more than the publishers'
# history behind after the resume (a loss by the DDS contract, not a gap in the rig).
@pytest.mark.parametrize("fast_rig", ["4.0"], indirect=True)
def test_pause_resume_reset_and_perturb(fast_rig, ros_executor):
    """Pause freezes the stream (no new blocks), resume continues it without a gap in first_index; perturb and
    reset answer with the stamp they take effect, and are logged with their simulation time when applied.

    The kick's size and instant, and the hammer at rest after the reset, are the runtime's test.
    """
    from std_srvs.srv import Trigger

    from rimd_msgs.msg import RigState
    from rimd_msgs.srv import Perturb

    rig, node = fast_rig
    qos = QoSProfile(depth=20000, reliability=ReliabilityPolicy.RELIABLE)
    force: list[SampleBlock] = []
    truth: list[RigState] = []
    node.create_subscription(SampleBlock, "/rig/impact/force", force.append, qos)
    node.create_subscription(RigState, "/rig/truth", truth.append, qos)
    trig = {name: node.create_client(Trigger, f"/rig/{name}") for name in ("pause", "resume", "reset")}
    perturb = node.create_client(Perturb, "/rig/perturb")
    assert spin_until(ros_executor, lambda: len(force) > 50, timeout=30)

    paused = call_service(ros_executor, node, trig["pause"], Trigger.Request(), timeout=10)
    assert paused.success, paused.message
    # The simulation time where it froze (stamps are simulation time here): every block published before
    # the pause arrives (an observable condition, however loaded the machine), and none after it.
    frozen_ns = round(float(re.search(r"paused at simulation time (\S+) s", paused.message).group(1)) * 1e9)

    def end_ns(blk: SampleBlock) -> int:
        return _ns(blk.header.stamp) + round(len(blk.samples) * 1e9 / blk.sample_rate)

    assert spin_until(ros_executor, lambda: force and end_ns(force[-1]) >= frozen_ns, timeout=20)
    frozen = len(force)
    spin_until(ros_executor, lambda: len(force) > frozen, timeout=1.0)   # a window for a wrong block to show
    assert len(force) == frozen and end_ns(force[-1]) == frozen_ns, "blocks kept coming while paused"
    again = call_service(ros_executor, node, trig["pause"], Trigger.Request(), timeout=10)
    assert not again.success and "already paused" in again.message
    assert call_service(ros_executor, node, trig["resume"], Trigger.Request(), timeout=10).success
    assert spin_until(ros_executor, lambda: len(force) > frozen + 20, timeout=10)
    for prev, blk in zip(force, force[1:], strict=False):
        assert blk.first_index == prev.first_index + len(prev.samples)

    response = call_service(ros_executor, node, perturb, Perturb.Request(velocity=0.2), timeout=10)
    assert response.success, response.message
    when = _ns(response.effective_stamp)
    assert when % 10_000_000 == 0 and response.message.startswith("hammer velocity +0.2 m/s at simulation time")
    assert spin_until(ros_executor, lambda: _ns(truth[-1].header.stamp) > when + 50_000_000, timeout=10)
    assert f"perturb at simulation time {when / 1e9:.6f} s" in rig.output() or spin_until(
        ros_executor, lambda: f"perturb at simulation time {when / 1e9:.6f} s" in rig.output(), timeout=5)

    reset = call_service(ros_executor, node, trig["reset"], Trigger.Request(), timeout=10)
    assert reset.success and "reset" in reset.message
    t_reset = float(reset.message.split("simulation time ")[1].split(" s")[0])
    target = round(t_reset * 1e9)
    assert spin_until(ros_executor, lambda: _ns(truth[-1].header.stamp) > target, timeout=10)
    assert any(_ns(t.header.stamp) == target for t in truth)   # a truth block starts at the reset's boundary
    assert spin_until(ros_executor, lambda: f"reset at simulation time {t_reset:.6f} s" in rig.output(), timeout=10)
    assert rig.stop() == 0, rig.tail()


def test_a_reader_of_diagnostics_hears_the_simulator_once_it_spins_not_at_its_first_tick(rclpy_context,
                                                                                         ros_executor):
    """In process: /diagnostics come to a reader as soon as it has matched, before the 1 Hz timer's first tick."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray

    from rimd_sim.ros.nodes.simulator import SimulatorNode

    listener = rclpy.create_node("diagnostics_listener", context=rclpy_context)
    ros_executor.add_node(listener)
    ticks: list[int] = [0]       # calls of the simulator's 1 s diagnostics timer so far
    heard: list[int] = []        # per /diagnostics message heard, the timer's ticks by then
    listener.create_subscription(DiagnosticArray, "/diagnostics", lambda msg: heard.append(ticks[0]), 10)
    simulator = SimulatorNode(context=rclpy_context)
    timer = next(t for t in simulator.timers if t.callback == simulator._publish_diagnostics)
    tick = timer.callback

    def counted() -> None:
        ticks[0] += 1
        tick()

    timer.callback = counted
    ros_executor.add_node(simulator)
    assert spin_until(ros_executor, lambda: bool(heard), timeout=10), "no /diagnostics in 10 s"
    assert heard[0] == 0, f"the first /diagnostics came after {heard[0]} tick(s) of the 1 s timer"
