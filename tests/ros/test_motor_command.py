"""Motor commands on /rig/motor/command at 100 Hz: applied at their stamps, in lockstep and at real time.

Hypotheses, with a commander in its own process (tests/harness/commander.py: one command per block, each stamped
a little after the block the rig has just published, each with another setpoint):

- in lockstep (the commander a controller: it reports its progress on the motor state) every command applies
  exactly at its stamp, between two samples: the recorded ground truth is, bit for bit, the core's with the same
  commands at the same times (RigSimulator offline), and each block's motor state shows the setpoint of the
  command stamped in it;
- at real time (wall-clock stamps, no lockstep), commands stamped 1 s ahead apply within the block of their stamp:
  the motor state at that block's end shows each one's setpoint;
- the rig's log does not grow per command: no line names one, a summary sums them up;
- the command client a controller imports (rimd_sim.ros.clients.motor) loads rclpy, rimd_msgs and the standard
  library only, as the progress reporter does.
"""

from __future__ import annotations

import json
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import pytest
from rclpy.serialization import deserialize_message

from rimd_msgs.msg import MotorState
from rimd_sim.instruments.rig_simulator import RigSimulator
from rimd_sim.io.cdr_write import encode_truth
from rimd_sim.io.reader import open_recording
from rimd_sim.runtime.stamps import sample_stamp_ns

pytestmark = pytest.mark.ros

COMMANDER = str(Path(__file__).resolve().parents[1] / "harness" / "commander.py")
COUNT = 300   # 3 s of simulation time at one command per 10 ms block
START = {"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75}


LOADED = """
import json, sys
import rclpy, rclpy.node, rclpy.qos, rclpy.duration, rimd_msgs.msg
before = set(sys.modules)
import rimd_sim.ros.clients.motor
print(json.dumps(sorted(set(sys.modules) - before)))
"""


def test_the_command_client_loads_only_rclpy_rimd_msgs_and_the_standard_library():
    result = subprocess.run([sys.executable, "-c", LOADED], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    extra = json.loads(result.stdout.strip().splitlines()[-1])
    theirs = sorted({m.split(".")[0] for m in extra} - set(sys.stdlib_module_names) - {"rimd_sim"})
    ours = sorted(m for m in extra if m.startswith("rimd_sim") and m not in {
        "rimd_sim", "rimd_sim.ros", "rimd_sim.ros.clients", "rimd_sim.ros.clients.motor",
        "rimd_sim.ros.clients.progress", "rimd_sim.runtime", "rimd_sim.runtime.progress", "rimd_sim.io",
        "rimd_sim.io.cdr_progress"})
    assert not theirs and not ours, (theirs, ours)


def shown_at_block_end(commands: list[list], states: list[list]) -> list[tuple[int, float, float]]:
    """For each command (stamp, Hz): the setpoint the first motor state stamped after it shows, where it differs."""
    by_stamp = dict((stamp, f) for stamp, f in states)
    ends = sorted(by_stamp)
    wrong = []
    for stamp, frequency in commands:
        end = next(e for e in ends if e > stamp)   # the end of the block the stamp lies in
        if by_stamp[end] != frequency:
            wrong.append((stamp, frequency, by_stamp[end]))
    return wrong


def command_lines(log: str) -> tuple[list[str], list[str]]:
    """The log's lines about single commands (none expected) and its summaries."""
    lines = log.splitlines()
    single = [line for line in lines if "motor command " in line or "set_motor_frequency at" in line]
    return single, [line for line in lines if "motor commands:" in line]


def test_in_lockstep_100_commands_a_second_apply_exactly_at_their_stamps(rimd_rig, tmp_path):
    rig = rimd_rig(consumers=["commander"], parameters=START)
    out = tmp_path / "commands.json"
    subprocess.run([sys.executable, COMMANDER, str(out), "--count", str(COUNT), "--lockstep", "commander"],
                   env=rig.env, check=True, timeout=180)
    sent = json.loads(out.read_text())
    commands = [(stamp, f) for stamp, f in sent["commands"]]
    assert len(commands) == COUNT and all(stamp % 10_000_000 == 5_000_000 for stamp, _ in commands)   # mid-block
    assert shown_at_block_end(sent["commands"], sent["states"]) == []
    config = rig.config
    log = rig.log()
    assert rig.stop() == 0

    # The recording: the same motor states, and the truth the core gives with the commands at their stamps.
    recording = open_recording(rig.recording)
    until = commands[-1][0] + 5_000_000
    states = [deserialize_message(m.data, MotorState) for m in recording.messages(["/rig/motor/state"])]
    recorded = [[s.header.stamp.sec * 10**9 + s.header.stamp.nanosec, s.frequency_setpoint] for s in states]
    assert shown_at_block_end(sent["commands"], recorded) == []
    truth = [m.data for m in recording.messages(["/rig/truth"])]
    blocks = until // 10_000_000
    sim = RigSimulator(config)
    for stamp, frequency in commands:
        sim.set_motor_frequency(frequency, 1000.0, at=Fraction(stamp, 10**9), kind="motor_command")
    rate = Fraction(repr(config.truth_rate))
    expected = []
    for block in sim.advance_blocks([Fraction(k, 100) for k in range(1, blocks + 1)]):
        assert block.truth is not None
        first, rows = block.truth
        expected.append(encode_truth(sample_stamp_ns(0, first, rate), first, config.truth_rate, rows))
    # The recorder keeps a message's bytes padded to a multiple of four, as the middleware hands them over.
    assert len(truth) >= blocks
    assert [data[:len(e)] for data, e in zip(truth, expected, strict=False)] == expected
    assert all(not data[len(e):].strip(b"\0") for data, e in zip(truth, expected, strict=False))

    single, summaries = command_lines(log)
    assert single == [] and 1 <= len(summaries) < COUNT // 10, summaries
    assert all("; 0 late," in line for line in summaries), summaries   # the rig waited for every command


@pytest.mark.timeout(180)
def test_at_real_time_100_commands_a_second_apply_within_the_block_of_their_stamp(ros_processes, tmp_path):
    sim = ros_processes.start_node("rimd_simulator", "--ros-args", *(a for k, v in START.items()
                                                                    for a in ("-p", f"{k}:={v}")),
                                   name="sim_real_time")
    sim.wait_for_output(r"rig ready: .* stamps: wall clock", timeout=90)
    out = tmp_path / "commands.json"
    commander = ros_processes.start_python(COMMANDER, str(out), "--count", str(COUNT), "--lead", "1.0",
                                           "--timeout", "120", name="commander")
    assert commander.wait(150) == 0, commander.tail()
    sent = json.loads(out.read_text())
    assert len(sent["commands"]) == COUNT
    assert shown_at_block_end(sent["commands"], sent["states"]) == []
    sim.stop()
    single, summaries = command_lines(sim.output())
    assert single == [] and 1 <= len(summaries) < COUNT // 10, summaries
