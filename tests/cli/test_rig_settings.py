"""``rimd rig --set NAME=VALUE`` and ``-p NAME:=VALUE``: a simulator parameter from the command line, checked like a
configuration file's before anything starts.

Hypotheses: a known name with a good value reaches the plan (the rig's configuration and its overrides file), the
last one given winning; an unknown name is refused in one line naming the option as typed and the closest names;
a value against its rule, or against the file's other values (a setpoint above the file's ``motor.max_frequency``),
is refused naming the option and the rule; a malformed option is a usage error; nothing is started by a refusal.
"""

from __future__ import annotations

import pytest
import yaml

from rimd_sim import cli
from rimd_sim.ros.bringup import Rig, plan_rig


@pytest.fixture
def nothing_starts(monkeypatch):
    def refuse(*args, **kwargs):
        pytest.fail("a refused --set reached the start of the rig")

    monkeypatch.setattr(Rig, "__init__", refuse)


@pytest.mark.parametrize(("argv", "line"), [
    (["--set", "gapp=1e-3"], "rimd rig: --set gapp=1e-3 refused: unknown parameter; did you mean gap? (every "
                             "parameter: docs/configuration.md)"),
    (["-p", "motor.initial_setpont:=3.0"], "rimd rig: -p motor.initial_setpont:=3.0 refused: unknown parameter; "
                                           "did you mean motor.initial_setpoint"),
    (["--set", "gap=-1"], "rimd rig: --set gap=-1 refused: must be >= 0"),
    (["--set", "lockstep.on_timeout=later"], "rimd rig: --set lockstep.on_timeout=later refused: must be one of"),
    (["--set", "motor.initial_setpoint=30"], "rimd rig: --set motor.initial_setpoint=30 refused: must be <= "
                                             "motor.max_frequency = 12 Hz (with "),
])
def test_a_bad_name_or_value_is_refused_in_one_line_before_anything_starts(argv, line, capsys, nothing_starts):
    assert cli.main(["rig", *argv, "--no-record", "--no-rerun"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(line) and err.count("\n") == 1, err


@pytest.mark.parametrize("argv", [["--set", "gap"], ["--set", "=1"], ["-p", "gap=1"], ["-p", "gap:="]])
def test_a_malformed_setting_is_a_usage_error(argv, capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["rig", *argv])
    assert exit_.value.code == 2 and "refused: must be NAME" in capsys.readouterr().err


def test_the_settings_reach_the_plan_the_last_one_winning(tmp_path):
    from rimd_sim.cli.verbs.rig import _ros_setting, _setting, simulator_settings

    given = [_setting("gap=1e-3"), _ros_setting("motor.initial_setpoint:=3.0"), _setting("motor.initial_setpoint=3.5"),
             _setting("capture.enabled=true")]
    values = simulator_settings(given, None)
    assert values == {"gap": 1e-3, "motor.initial_setpoint": 3.5, "capture.enabled": True}
    plan = plan_rig(None, record=False, rerun=False, parameters={"rimd_simulator": values}, run_dir=tmp_path)
    assert plan.config.rig.gap == 1e-3 and plan.config.motor.initial_setpoint == 3.5
    assert plan.overrides_path is not None
    overrides = yaml.safe_load(plan.overrides_path.read_text())
    assert overrides["/**/rimd_simulator"]["ros__parameters"]["capture.enabled"] is True
