"""The ``rimd`` command: verbs listed in --help, honest "not implemented yet" answers, ``rimd info``."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from rimd_sim import cli

#: The verbs of the interface (docs/interface.md, Commands), in the order of ``rimd --help``.
INTERFACE_VERBS = ("rig", "experiment", "analyze", "identify", "fit-table", "sweep", "bifurcation", "peterka",
                   "poincare", "basins", "pulse", "faults", "motor", "perturb", "inject", "pause", "resume", "reset",
                   "clear-faults", "status", "rerun", "replay", "crop", "node", "info")
#: Verbs listed without a module, and what their refusal says is missing: none left.
NOT_IMPLEMENTED: dict[str, str] = {}


def _rimd(*args: str, timeout: float = 30) -> subprocess.CompletedProcess[str]:
    executable = shutil.which("rimd")
    assert executable is not None, "rimd is not on PATH: source env.sh (make test does)"
    return subprocess.run([executable, *args], capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


@pytest.mark.process
def test_rimd_on_path_is_the_ros2_run_executable():
    executable = Path(shutil.which("rimd") or "")
    assert executable.parent.parts[-2:] == ("lib", "rimd_sim"), executable


@pytest.mark.process
def test_help_lists_every_subcommand():
    result = _rimd("--help")
    assert result.returncode == 0, result.stderr
    listed = {line.split()[0] for line in result.stdout.splitlines()
              if line.startswith("    ") and line.split()}
    assert set(INTERFACE_VERBS) <= listed, f"missing: {set(INTERFACE_VERBS) - listed}"


def test_verb_table_matches_the_interface():
    assert tuple(verb.name for verb in cli.VERBS) == INTERFACE_VERBS
    for verb in cli.VERBS:
        assert (verb.module is None) == (verb.name in NOT_IMPLEMENTED), verb.name
        if verb.name in NOT_IMPLEMENTED:
            assert verb.missing == NOT_IMPLEMENTED[verb.name]


def test_not_implemented_verb_says_so_and_exits_2(monkeypatch, capsys):
    """The mechanism stays for verbs added later: a verb without a module says so on stderr, exit 2."""
    verb = cli.Verb("teleport", "a verb not written yet", None, "the transporter driver")
    monkeypatch.setattr(cli, "VERBS", (*cli.VERBS, verb))
    status = cli.main(["teleport", "some-argument", "--some-option"])
    captured = capsys.readouterr()
    assert status == 2
    assert captured.out == "", "no fake output"
    assert captured.err.strip() == "rimd teleport: not implemented yet (the transporter driver)"
    monkeypatch.setattr(cli, "VERBS", (*cli.VERBS, cli.Verb("beam", "another one", None)))
    assert cli.main(["beam"]) == 2
    assert capsys.readouterr().err.strip() == "rimd beam: not implemented yet"


@pytest.mark.process
def test_a_failing_verb_is_one_line_and_status_1_through_the_console_script(tmp_path):
    missing = tmp_path / "missing.mcap"
    result = _rimd("rerun", str(missing), "--save", str(tmp_path / "out.rrd"))
    assert result.returncode == 1
    assert result.stdout == ""
    assert result.stderr.strip() == f"rimd rerun: {missing}: no such file"


def test_no_subcommand_is_a_usage_error(capsys):
    assert cli.main([]) == 2
    assert "usage: rimd" in capsys.readouterr().err


def test_unknown_subcommand_is_a_usage_error():
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["fly"])
    assert exit_info.value.code == 2


@pytest.mark.process
def test_info_reports_version_and_source_tree(repo_root):
    result = _rimd("info", "--json")
    assert result.returncode == 0, result.stderr
    facts = json.loads(result.stdout)
    assert facts["rimd_sim_version"] == cli.__version__
    assert Path(facts["rimd_sim_location"]).resolve().is_relative_to(repo_root / "rimd_sim" / "rimd_sim")
    assert Path(facts["config_dir"]) == repo_root / "config"
    assert facts["ros_jazzy_rclpy"] is not None
    assert facts["rimd_msgs_location"] is not None


@pytest.mark.process
def test_info_plain_text():
    result = _rimd("info")
    assert result.returncode == 0, result.stderr
    assert "rimd_sim_version: " in result.stdout


def test_command_error_prints_one_line_and_exits_1(monkeypatch, capsys):
    def failing_main(args):
        raise cli.CommandError("gap must be >= 0 m, got -1")

    monkeypatch.setattr("rimd_sim.cli.verbs.info.main", failing_main)
    assert cli.main(["info"]) == 1
    assert capsys.readouterr().err == "rimd info: gap must be >= 0 m, got -1\n"


def _numeric_options():
    """Every option of every verb that takes a number: (verb, option strings, its argparse type)."""
    parser = cli.build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, __import__("argparse")._SubParsersAction))
    for verb, sub in subparsers.choices.items():
        for action in sub._actions:
            if action.type in (float, int) or hasattr(action.type, "rule"):
                yield verb, action.option_strings or [action.metavar or action.dest], action.type


def test_every_numeric_option_of_every_verb_is_checked_and_names_itself_in_its_refusal():
    """Once `rimd rig --duration -5` ran until killed and `--gap-mm 2400` answered in metres. Every number a
    verb takes is converted by `cli.number` (finite, within its bounds, refused naming the option as typed)."""
    import argparse

    options = list(_numeric_options())
    bare = [(verb, names) for verb, names, kind in options if kind in (float, int)]
    assert not bare, f"options taking a bare float/int (no bounds, nan and inf accepted): {bare}"
    assert len(options) > 60
    for verb, names, kind in options:
        for text in ("nan", "inf", "-inf", "abc"):
            with pytest.raises(argparse.ArgumentTypeError) as refused:
                kind(text)
            message = str(refused.value)
            assert message.startswith(f"{kind.option} ") and " refused: must be " in message, (verb, names, message)
        assert kind.option in names, (verb, names, kind.option)   # the refusal names the option as typed


@pytest.mark.parametrize(("argv", "refusal"), [
    (["rig", "--duration", "-5"], "--duration -5 refused: must be >= 0 s"),
    (["poincare", "--gap-mm", "2400"], "--gap-mm 2400 refused: must be >= 0 and <= 50 mm"),
    (["peterka", "--gap-max-mm", "-1"], "--gap-max-mm -1 refused: must be >= 0 and <= 50 mm"),
    (["sweep", "--cycles", "1.5"], "--cycles '1.5' refused: must be an integer"),
    (["experiment", "--dwell", "0"], "--dwell 0 refused: must be > 0 s"),
    (["pulse", "--velocity", "11"], "--velocity 11 refused: must be > 0 and <= 10 m/s"),
])
def test_a_bad_number_is_refused_before_anything_runs_naming_the_option_in_its_unit(argv, refusal, capsys):
    with pytest.raises(SystemExit) as usage:
        cli.main(argv)
    assert usage.value.code == 2
    assert refusal in capsys.readouterr().err
