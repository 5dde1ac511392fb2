"""The everyday one-shot commands and ``rimd status`` against a running simulator (docs/rig.md).

Hypotheses: each command prints the rig's own answer and exits 0, or exits 1 with the rig's refusal (the rig
keeps running); a bad number is refused by the command itself naming the option in its unit (exit 2); with no
rig the command says so in one line; ``rimd status --once --json`` reports the run, the motor, every channel's
rate and indices and the faults in force. The commands run in this process through ``rimd_sim.cli.main``
(what the ``rimd`` executable runs); the simulator is a node of its own.
"""

from __future__ import annotations

import json

import pytest

from rimd_sim.cli import main

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]


def rimd(capsys, *argv: str) -> tuple[int, str, str]:
    try:
        code = main(list(argv))
    except SystemExit as exc:   # argparse refusals
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def test_one_shot_commands_and_status(ros_processes, capsys):
    rig = ros_processes.start_node("rimd_simulator", "--ros-args", "-p", "motor.initial_frequency:=3.75")
    rig.wait_for_output(r"rig ready", timeout=60)

    code, out, _ = rimd(capsys, "motor", "5", "--ramp", "10")
    assert code == 0 and out.startswith("setpoint 5 Hz at 10 Hz/s from simulation time "), out
    code, _, err = rimd(capsys, "motor", "20")
    assert code == 1 and "refused by the rig: frequency_hz = 20.0 refused: above motor.max_frequency" in err, err
    code, _, err = rimd(capsys, "motor", "-3")
    assert code == 2 and "FREQ -3 refused: must be >= 0 Hz" in err, err

    code, out, _ = rimd(capsys, "perturb", "0.05")
    assert code == 0 and "hammer velocity +0.05 m/s at simulation time" in out, out
    code, _, err = rimd(capsys, "perturb", "11")
    assert code == 2 and "V 11 refused: must be >= -10 and <= 10 m/s" in err, err

    code, out, _ = rimd(capsys, "inject", "impact_force", "dropout", "--after", "0.5", "--duration", "0.2")
    assert code == 0 and out.startswith("fault 0: dropout on impact_force from simulation time "), out
    code, _, err = rimd(capsys, "inject", "impact_force", "offset", "--start", "0.001", "--magnitude", "1")
    assert code == 1 and "refused by the rig: start = 0.001 refused: in the past" in err, err
    code, _, err = rimd(capsys, "inject", "impact_force", "offset", "--start", "1", "--after", "1")
    assert code == 2 and "not allowed with argument" in err, err

    code, out, _ = rimd(capsys, "inject", "impact_force", "offset", "--magnitude", "3")
    assert code == 0
    code, out, _ = rimd(capsys, "status", "--once", "--json", "--window", "1.5")
    status = json.loads(out)
    assert code == 0 and status["heard"] and status["motor"]["setpoint_hz"] == 5.0
    assert status["session"]["time_base"] == "wall_clock" and len(status["session"]["run_id"]) == 32
    for name, channel in status["channels"].items():
        assert channel["blocks_per_s"] > 20 and channel["last_first_index"] > 0, (name, channel)
    assert [f["kind"] for f in status["faults_in_force"]] == ["offset"]
    code, out, _ = rimd(capsys, "status", "--once", "--window", "0.5")
    assert code == 0 and "impact_force" in out and "faults in force: offset on impact_force" in out, out

    code, out, _ = rimd(capsys, "clear-faults")
    assert code == 0 and out.startswith("faults cleared at simulation time"), out
    code, out, _ = rimd(capsys, "pause")
    assert code == 0 and out.startswith("paused at simulation time"), out
    code, _, err = rimd(capsys, "pause")
    assert code == 1 and "pause refused by the rig: already paused" in err, err
    code, out, _ = rimd(capsys, "resume")
    assert code == 0 and out.startswith("resumed at"), out
    code, out, _ = rimd(capsys, "reset")
    assert code == 0 and "hammer reset to its initial state" in out and "run " in out, out
    assert rig.is_running() and "Traceback" not in rig.output()


def test_without_a_rig_a_command_says_so(ros_env, capsys):
    code, _, err = rimd(capsys, "motor", "5", "--timeout", "0.5")
    assert code == 1 and "no rig: service /rig/set_motor_frequency not available after 0.5 s on ROS_DOMAIN_ID" in err
    code, _, err = rimd(capsys, "status", "--once", "--window", "0.5", "--timeout", "1")
    assert code == 1 and "no rig heard on ROS_DOMAIN_ID" in err and " in 1 s" in err, err
