"""``rimd rig``: brings up the rig's nodes from a config file and stops them cleanly."""

from __future__ import annotations

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy

from harness.ros import spin_until
from rimd_msgs.msg import MotorState
from rimd_sim.io.cdr import block_span
from rimd_sim.io.reader import open_recording

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]


def test_rig_brings_up_the_simulator_and_stops_cleanly(ros_processes, ros_executor, tmp_path):
    import rclpy

    out = tmp_path / "rec"
    rig = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--duration", "8", "--output-dir", str(out),
                                     name="rimd_rig")
    rig.wait_for_output(r"rimd rig: running rimd_recorder, rimd_rerun, rimd_simulator", timeout=30)
    node = rclpy.create_node("probe_rig", context=ros_executor.context)
    ros_executor.add_node(node)
    motor: list[MotorState] = []
    node.create_subscription(MotorState, "/rig/motor/state", motor.append,
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    # The default config spins the motor up to 3.75 Hz at 2 Hz/s.
    assert spin_until(ros_executor, lambda: len(motor) > 100 and motor[-1].frequency > 1.0, timeout=20)
    assert motor[-1].frequency_setpoint == 3.75
    assert rig.wait(30) == 0, rig.tail()  # --duration elapsed: the nodes were stopped in order
    assert f"rimd rig: stopped; the recording is in {out}" in rig.output()
    assert "the rig runs from sample 0" in rig.output()
    # Stopped in order (simulator, then recorder): the recording is complete and starts at sample 0.
    recording = open_recording(out)
    assert recording.complete
    blocks = [block_span(m.data) for m in recording.messages(["/rig/impact/force"])]
    assert blocks[0][0] == 0 and len(blocks) > 300
    assert all(b[0] == a[0] + a[1] for a, b in zip(blocks, blocks[1:], strict=False))
    assert "LOSS" not in rig.output()
    # The Rerun bridge ran with the default sink (a web viewer on loopback) and was closed with the rig.
    assert "rerun bridge ready: sink serve_web -> http://127.0.0.1:" in rig.output()
    assert "channels as a display stream (min and max per 5 ms" in rig.output()   # the default live view
    assert "rimd_rerun: closed" in rig.output() and "display points)" in rig.output()


def test_rig_with_rerun_full_rate_sends_every_sample_to_rerun(ros_processes, tmp_path):
    rig = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--duration", "3", "--rerun-full-rate",
                                     "--output-dir", str(tmp_path / "rec"), name="rimd_rig_full_rate")
    assert rig.wait(60) == 0, rig.tail()
    assert "channels at full rate (every sample)" in rig.output()
    assert "rimd_rerun: closed" in rig.output() and "display points" not in rig.output()
    assert not list((tmp_path / "rec").glob(".rimd_rig_overrides_*")), "the override file is removed at the end"
    refused = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--no-rerun", "--rerun-full-rate",
                                         name="rimd_rig_full_rate_no_rerun")
    assert refused.wait(30) == 1
    assert "--rerun-full-rate is for the Rerun view: not with --no-rerun" in refused.output()


def test_rig_without_recorder(ros_processes, tmp_path):
    rig = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--duration", "3", "--no-record", "--no-rerun",
                                     name="rimd_rig_norec")
    assert rig.wait(40) == 0, rig.tail()
    assert "rimd rig: running rimd_simulator with" in rig.output() and "Not recording" in rig.output()


def test_rig_refuses_a_bad_recorder_section(ros_processes, tmp_path, repo_root):
    bad = tmp_path / "bad.yaml"
    bad.write_text((repo_root / "config" / "rimd.yaml").read_text().replace("compression: zstd", "compression: rar"))
    rig = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--config", str(bad), name="rimd_rig_badrec")
    assert rig.wait(30) == 1
    refusal = "section rimd_recorder: parameter 'compression' = 'rar' refused: must be one of: zstd, lz4, none"
    assert refusal in rig.output()
    assert "running" not in rig.output()


def test_rig_refuses_a_bad_config_before_starting(ros_processes, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**/rimd_simulator:\n  ros__parameters:\n    mass: -1.0\n")
    rig = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--config", str(bad), name="rimd_rig_bad")
    assert rig.wait(30) == 1
    assert (f"rimd rig: {bad}, section rimd_simulator: parameter 'mass' = -1.0 refused: must be >= 0.001 and "
            "<= 1000 kg") in rig.output()
    assert "running" not in rig.output()


def test_rig_refuses_a_bad_rerun_section(ros_processes, tmp_path, repo_root):
    bad = tmp_path / "bad.yaml"
    bad.write_text((repo_root / "config" / "rimd.yaml").read_text().replace("sink: serve_web", "sink: hologram"))
    rig = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--config", str(bad), name="rimd_rig_badrerun")
    assert rig.wait(30) == 1
    assert "unknown sink 'hologram'" in rig.output() and "running" not in rig.output()


def test_a_node_refuses_a_parameter_file_that_gives_a_key_twice(ros_processes, tmp_path):
    """Hypothesis: ROS takes a parameter file whose mapping gives a key twice and applies the last value without a
    word, so a node started with ``--params-file`` (``ros2 run``, ``rimd node``, a launch file) would run on a value
    its reader may not see. The node refuses the file, naming both lines."""
    twice = tmp_path / "twice.yaml"
    twice.write_text("/**/rimd_simulator:\n  ros__parameters:\n    gap: 0.001\n    gap: 0.002\n")
    node = ros_processes.start_node("rimd_simulator", "--ros-args", "--params-file", str(twice))
    assert node.wait(60) == 2, node.tail()
    assert (f"parameter file is not valid YAML: {twice}:4:5: key 'gap' given twice (first on line 3)"
            in node.output()), node.tail()
    assert "Traceback" not in node.output()


def test_a_section_ros_would_not_apply_is_refused_and_a_wildcard_one_is_applied(ros_processes, tmp_path):
    """Hypothesis: ROS applies a parameter-file section only to the node whose fully qualified name it matches,
    and says nothing otherwise; a plain ``rimd_simulator:`` key is ``/rimd_simulator``, not the simulator in
    ``/rig``, so a file with that key would leave the node silently on its defaults. The node and ``rimd rig``
    refuse such a file naming the section and the key that works, and the presets' ``/**/rimd_simulator`` key
    is applied (the node reports the file's gap)."""
    plain = tmp_path / "plain.yaml"
    plain.write_text("rimd_simulator:\n  ros__parameters:\n    gap: 0.001\n")
    node = ros_processes.start_node("rimd_simulator", "--ros-args", "--params-file", str(plain))
    assert node.wait(60) == 2, node.tail()
    assert (f"parameter file {plain}: section 'rimd_simulator' is meant for rimd_simulator but ROS applies it only "
            "to a node named /rimd_simulator, not to /rig/rimd_simulator; name the section '/**/rimd_simulator'"
            in node.output()), node.tail()
    rig = ros_processes.start_python("-m", "rimd_sim.cli", "rig", "--config", str(plain), "--no-record", "--no-rerun",
                                     name="rimd_rig_plain")
    assert rig.wait(30) == 1
    assert "section 'rimd_simulator' is meant for rimd_simulator" in rig.output() and "running" not in rig.output()

    wildcard = tmp_path / "wildcard.yaml"
    wildcard.write_text("/**/rimd_simulator:\n  ros__parameters:\n    gap: 0.001\n")
    node = ros_processes.start_node("rimd_simulator", "--ros-args", "--params-file", str(wildcard),
                                    "-p", "start_paused:=true")
    node.wait_for_output(r"rig ready: gap 1 mm", timeout=60)
