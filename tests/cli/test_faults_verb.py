"""``rimd faults SCENARIO.yaml`` against a running rig, and its refusals (docs/faults.md)."""

from __future__ import annotations

import shutil
import subprocess

import pytest

pytestmark = [pytest.mark.ros]


def _rimd(*args: str, env: dict, timeout: float = 60.0) -> subprocess.CompletedProcess:
    executable = shutil.which("rimd")
    assert executable, "rimd is not on PATH (source env.sh)"
    return subprocess.run([executable, *args], env=env, capture_output=True, text=True,
                          timeout=timeout, check=False)


@pytest.mark.timeout(120)
def test_faults_verb_schedules_a_scenario_and_the_rig_publishes_it(tmp_path, ros_env, ros_processes):
    sim = ros_processes.start_node("rimd_simulator", "--ros-args", "-p", "real_time_factor:=1.0")
    sim.wait_for_output(r"rig ready", timeout=90)
    scenario = tmp_path / "scenario.yaml"
    # `after`: relative to when the rig takes the request, for a rig that has been up a while (an absolute start
    # written for a fresh rig would be refused as past).
    scenario.write_text("faults:\n"
                        "  - {channel: impact_force, kind: offset, start: 0, duration: 0.2, magnitude: 2.5}\n"
                        "  - {channel: cart_displacement, kind: dropout, after: 0.5, duration: 0.1}\n")
    done = _rimd("faults", str(scenario), "--clear", env=ros_env)
    assert done.returncode == 0, done.stderr
    assert "faults[0]: fault 0: offset on impact_force" in done.stdout
    assert "faults[1]: fault 1: dropout on cart_displacement" in done.stdout
    assert "2 fault(s) scheduled" in done.stdout
    sim.wait_for_output(r"fault 0 end at simulation time .*duration elapsed", timeout=30)
    sim.wait_for_output(r"fault 1 end at simulation time .*duration elapsed", timeout=30)

    # refused by the rig: one line naming the entry, the field and the rule; the rig keeps running
    bad = tmp_path / "bad.yaml"
    bad.write_text("faults:\n  - {channel: impact_force, kind: block_loss, start: 0, magnitude: 2}\n")
    refused = _rimd("faults", str(bad), env=ros_env)
    assert refused.returncode == 1
    assert refused.stderr.strip().count("\n") == 0
    assert "faults[0] refused by the rig" in refused.stderr and "magnitude = 2.0 refused" in refused.stderr
    assert sim.is_running()


@pytest.mark.parametrize(("text", "expected"), [
    ("faults: 3\n", "must hold a 'faults:' list"),
    ("faults:\n  - {channel: impact_force, start: 1}\n", "faults[0].kind missing"),
    ("faults:\n  - {channel: impact_force, kind: stuck, start: 1, colour: red}\n", "faults[0].colour refused"),
    ("faults:\n  - {channel: impact_force, kind: stuck, start: soon}\n", "faults[0].start = 'soon' refused"),
    ("faults:\n  - {channel: impact_force, kind: stuck, start: 1, after: 2}\n", "give start"),
    ("faults: [\n", "is not valid YAML: {path}:2:1: expected the node content"),
    ("faults:\n  - a: b: c\n", "is not valid YAML: {path}:2:9: mapping values are not allowed here"),
])
def test_faults_verb_refuses_a_malformed_scenario_before_sending_anything(tmp_path, text, expected):
    from rimd_sim.cli.verbs.faults import load_scenario
    from rimd_sim.errors import RimdError

    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(RimdError) as refused:
        load_scenario(path)
    assert expected.format(path=path) in str(refused.value) and "\n" not in str(refused.value), str(refused.value)


def test_faults_verb_exits_1_with_one_line_for_a_malformed_file(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("faults:\n  - {channel: impact_force, kind: stuck, start: 1, colour: red}\n")
    done = _rimd("faults", str(path), env=None)
    assert done.returncode == 1 and "faults[0].colour refused" in done.stderr, done.stderr
    assert done.stderr.strip().count("\n") == 0
