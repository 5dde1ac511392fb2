"""The ``rimd`` command: verbs listed in --help, honest "not implemented yet" answers, ``rimd info``."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from rimd_sim import cli

#: The verbs of the interface (docs/interface.md, Commands), in the order of ``rimd --help``.
INTERFACE_VERBS = ("rig", "experiment", "analyze", "identify", "fit-table", "fit-paper", "paper", "sweep",
                   "bifurcation", "continue", "peterka", "map", "poincare", "basins", "pulse", "faults", "motor",
                   "perturb", "inject", "pause", "resume", "reset", "clear-faults", "status", "rerun", "replay", "crop",
                   "node", "info", "warmup")
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
    """Every number a verb takes is converted by `cli.number` (finite, within its bounds, refused naming the
    option as typed): `rimd rig --duration -5` is refused instead of running until killed, and the refusal of
    `--gap-mm 2400` speaks of the option in mm, not of the parameter in metres."""
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


def test_every_numeric_option_of_every_verb_is_a_usage_error_through_main_without_a_traceback(capsys):
    """The sweep above checks each option's converter; here each is driven through ``rimd`` itself."""
    checked = 0
    for verb, names, kind in _numeric_options():
        option = names[0]
        argv = [verb, option, "nan"] if option.startswith("-") else [verb, "nan"]
        with pytest.raises(SystemExit) as usage:
            cli.main(argv)
        err = capsys.readouterr().err
        assert usage.value.code == 2 and "Traceback" not in err, (argv, err)
        assert f"{kind.option} 'nan' refused" in err or f"{kind.option} nan refused" in err, (argv, err)
        checked += 1
    assert checked > 60


# ---- every verb that takes a file, given a bad one -----------------------------------------------------------

#: Options that name an output, not a file read.
OUTPUTS = {"out", "output_dir", "save"}
#: Inputs that are not typed as paths. (``experiment --recording`` is read only after an experiment run with
#: ``--no-record``: here it is refused for lacking it, before anything starts.)
UNTYPED_INPUTS = {("experiment", "for_identification")}
#: What else a verb needs to get as far as reading the file (a required option, or a file the verb reads first).
NEEDS = {"pulse": ["--velocity", "0.5"], "crop": ["--out", "{tmp}/cropped"],
         "map": ["--x", "natural_frequency", "--x-values", "1.82", "--y", "mass", "--y-values", "0.15",
                 "--frequency", "4"]}
#: Files a verb hands to a node it starts, which refuses them (one line, exit 1: tested through the console
#: script below); the plan only checks that the recording is there.
READ_BY_A_NODE = {("replay", "recording"): ("not MCAP", "bad YAML", "YAML text")}


def _bad_files(tmp):
    (tmp / "garbage.mcap").write_bytes(bytes(range(256)) * 8)
    (tmp / "bad.yaml").write_text("a: [1, 2\n  b: }\n")
    (tmp / "text.yaml").write_text("hello\n")
    (tmp / "empty").mkdir()
    return {"missing": tmp / "missing.mcap", "not MCAP": tmp / "garbage.mcap", "bad YAML": tmp / "bad.yaml",
            "YAML text": tmp / "text.yaml", "empty directory": tmp / "empty"}


def _file_inputs():
    """(verb, dest, option or None for a positional, required) of every file a verb reads."""
    import argparse

    parser = cli.build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for verb, sub in subparsers.choices.items():
        for action in sub._actions:
            if (action.type is Path and action.dest not in OUTPUTS) or (verb, action.dest) in UNTYPED_INPUTS:
                yield verb, action.dest, (action.option_strings or [None])[0], action.required


@pytest.fixture
def no_process(monkeypatch):
    """A verb refusing a bad file starts nothing: no process, no rig, no ROS client."""
    import multiprocessing.process
    import subprocess

    from rimd_sim.ros.bringup import Rig
    from rimd_sim.ros.clients.rig import RigClient

    def refuse(*args, **kwargs):
        pytest.fail("a bad file reached a step that starts something (a process, a rig, a ROS client)")

    monkeypatch.setattr(subprocess.Popen, "__init__", refuse)
    monkeypatch.setattr(multiprocessing.process.BaseProcess, "start", refuse)
    monkeypatch.setattr(Rig, "run", refuse)
    monkeypatch.setattr(RigClient, "__init__", refuse)


def test_every_verb_refuses_a_bad_file_in_one_line_with_status_1(tmp_path, capsys, no_process):
    """A missing file, one that is not MCAP, bad YAML, YAML that is only text, a directory without files: given to
    every verb that reads a file (positional or option), each is one line ``rimd VERB: ...`` and exit 1, never a
    traceback, and nothing is started."""
    bad = _bad_files(tmp_path)
    inputs = list(_file_inputs())
    assert {v for v, *_ in inputs} >= {"rig", "experiment", "analyze", "identify", "fit-table", "sweep",
                                       "bifurcation", "peterka", "map", "poincare", "basins", "pulse", "faults",
                                       "rerun", "replay", "crop"}, inputs
    cases = 0
    for verb, dest, option, _ in inputs:
        for what, path in bad.items():
            if what in READ_BY_A_NODE.get((verb, dest), ()):
                continue
            argv = [verb, *(a.format(tmp=tmp_path) for a in NEEDS.get(verb, []))]
            # The required positional is the bad file, or (when the option is) a file the verb reads later.
            for other, other_dest, other_option, required in inputs:
                if other == verb and other_option is None and other_dest != dest and required:
                    argv.append(str(bad["not MCAP"]))
            argv += [str(path)] if option is None else [option, str(path)]
            if verb != "rig":
                argv += ["--out", str(tmp_path / "out")] if verb not in ("rerun", "replay", "faults", "crop") else []
            status = cli.main(argv)
            err = capsys.readouterr().err
            assert status == 1, (argv, status, err)
            assert err.startswith(f"rimd {verb}: ") and err.count("\n") == 1 and "Traceback" not in err, (argv, err)
            cases += 1
    assert cases >= 70, cases


@pytest.mark.process
def test_a_file_that_is_not_a_recording_given_to_replay_is_refused_by_its_node_without_a_traceback(tmp_path):
    """``rimd replay`` checks only that the recording is there; its node reads it and refuses it (exit 1)."""
    bad = _bad_files(tmp_path)
    for what in READ_BY_A_NODE[("replay", "recording")]:
        result = _rimd("replay", str(bad[what]), timeout=60)
        assert result.returncode == 1, (what, result.stderr)
        assert "Traceback" not in result.stderr + result.stdout, (what, result.stderr)
        assert f"rimd_replay: {bad[what]} is not an MCAP file" in result.stderr, (what, result.stderr)


def test_an_output_that_cannot_be_made_is_one_line_naming_it(tmp_path, capsys, no_process):
    """An output directory under a regular file: the operating system's error, rendered in one line with the path."""
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    for argv in (["experiment", "--out", str(blocker / "out")],
                 ["pulse", "--velocity", "0.5", "--rate", "2e5", "--out", str(blocker / "out")]):
        assert cli.main(argv) == 1
        err = capsys.readouterr().err
        assert err == f"rimd {argv[0]}: {blocker / 'out'}: Not a directory\n", (argv, err)
