"""``rimd rig``: brings up the rig's nodes from a config file and stops them cleanly."""

from __future__ import annotations

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy

from harness.ros import spin_until
from rimd_msgs.msg import MotorState

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]


def test_rig_brings_up_the_simulator_and_stops_cleanly(ros_processes, ros_executor):
    import rclpy

    rig = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--duration", "8", name="rimd_rig")
    rig.wait_for_output(r"rimd rig: running rimd_simulator", timeout=30)
    node = rclpy.create_node("probe_rig", context=ros_executor.context)
    ros_executor.add_node(node)
    motor: list[MotorState] = []
    node.create_subscription(MotorState, "/rig/motor/state", motor.append,
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    # The default config spins the motor up to 3.75 Hz at 2 Hz/s.
    assert spin_until(ros_executor, lambda: len(motor) > 100 and motor[-1].frequency > 1.0, timeout=20)
    assert motor[-1].frequency_setpoint == 3.75
    assert rig.wait(30) == 0, rig.tail()  # --duration elapsed: the nodes were stopped in order
    assert "rimd rig: stopped" in rig.output()


def test_rig_refuses_a_bad_config_before_starting(ros_processes, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("rimd_simulator:\n  ros__parameters:\n    mass: -1.0\n")
    rig = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--config", str(bad), name="rimd_rig_bad")
    assert rig.wait(30) == 1
    assert "rimd rig: parameter 'mass' = -1.0 refused: must be > 0" in rig.output()
    assert "running" not in rig.output()
