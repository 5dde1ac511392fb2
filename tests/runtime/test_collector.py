"""The cycle collector of a process of the package: set by its entry points, left alone by ``main`` in a program."""

from __future__ import annotations

import gc
import subprocess
import sys
from importlib.metadata import entry_points

import pytest

from rimd_sim import cli
from rimd_sim.runtime import collector

#: Prints the process's collector after the code before it: its young threshold, whether it collects, and
#: whether anything was frozen.
_REPORT = "import gc; print(gc.get_threshold()[0], gc.isenabled(), gc.get_freeze_count() > 0)"


def _python(code: str) -> list[str]:
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                            stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr
    return result.stdout.split()


def test_the_rimd_executable_is_the_entry_that_sets_the_collector():
    (script,) = [e for e in entry_points(group="console_scripts") if e.name == "rimd"]
    assert script.value == "rimd_sim.cli:entry"


@pytest.mark.process
def test_entry_runs_main_with_the_young_threshold_raised_and_freezes_at_the_end():
    out = _python("import sys; from rimd_sim.cli import entry; sys.argv = ['rimd']; status = entry(); "
                  f"print(status); {_REPORT}")
    assert out == [str(cli.EXIT_USAGE), str(collector.YOUNG_THRESHOLD), "True", "True"]


def test_a_program_calling_main_keeps_its_own_collector(capsys, monkeypatch):
    frozen: list[bool] = []
    monkeypatch.setattr(gc, "freeze", lambda: frozen.append(True))   # the count itself falls as objects die
    saved = gc.get_threshold()
    try:
        gc.set_threshold(collector.CPYTHON_YOUNG_THRESHOLD, 10, 10)   # the test session's own is raised
        assert cli.main([]) == cli.EXIT_USAGE
        assert "usage: rimd" in capsys.readouterr().err
        assert gc.get_threshold() == (collector.CPYTHON_YOUNG_THRESHOLD, 10, 10)
        assert frozen == []
    finally:
        gc.set_threshold(*saved)


@pytest.mark.process
def test_a_node_process_imports_as_a_command_then_runs_at_cpythons_threshold_with_its_imports_frozen():
    # The entry module sets the imports' collector as a command's; a node's function freezes once its module is
    # loaded and gives back CPython's young threshold (shorter pauses of its paced thread) before the node's main
    # runs (here a stand-in main that reports what it finds).
    code = ("import gc; gc.set_threshold(12345, 10, 10); import rimd_sim.ros.nodes._entry as e; "
            "print(gc.get_threshold()[0], gc.get_freeze_count() > 0); "
            "e.load = lambda target: (lambda: print(target, gc.get_threshold()[0], gc.get_freeze_count() > 0, "
            "gc.isenabled()) or 7); "
            "print(e.ENTRIES['simulator']())")
    out = _python(code)
    assert out == [str(collector.YOUNG_THRESHOLD), "False", "rimd_sim.ros.nodes.simulator:main",
                   str(collector.CPYTHON_YOUNG_THRESHOLD), "True", "True", "7"]


def test_configure_keeps_the_older_generations_thresholds():
    saved = gc.get_threshold()
    try:
        gc.set_threshold(700, 12, 13)
        collector.configure()
        assert gc.get_threshold() == (collector.YOUNG_THRESHOLD, 12, 13)
    finally:
        gc.set_threshold(*saved)
