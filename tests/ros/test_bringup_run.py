"""``Rig.run`` and ``stop_process`` (rimd_sim.ros.bringup), the loop and the stop of ``rimd rig`` and ``rimd replay``.

On real child processes. Hypotheses: a process that exits by itself ends the run with status 1 and one line on
stderr naming the verb, the process and its status, after the announcement; the process named ``ends_itself``
ending with status 0 is the normal end (status 0, nothing on stderr); a process that ignores SIGINT is stopped
by the next signal once the first one's wait has passed, and that timeout is reported.
"""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

from harness.rig_mcap import write_rig_mcap
from rimd_sim.ros.bringup import PlannedNode, Rig, RigPlan, stop_process

pytestmark = pytest.mark.process   # child processes (no ROS)

IGNORES_SIGINT = ("import signal, sys, time\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\nprint('ready', flush=True)\n"
                  "time.sleep(60)\n")


def test_a_process_that_exits_ends_the_run_with_status_1_naming_it(capsys):
    # An entry _entry does not know: the child prints its usage and exits 2 at once (no ROS involved).
    plan = RigPlan(None, None, (PlannedNode("rimd_nothing", "no_such_entry", ()),))
    assert Rig(plan).run("rig", lambda: print("announced", flush=True)) == 1
    out, err = capsys.readouterr()
    assert out.startswith("announced")
    assert "rimd rig: rimd_nothing exited with status 2" in err, err


def test_the_process_that_ends_itself_ends_the_run_normally(ros_env, tmp_path, capfd):
    path = tmp_path / "rig.mcap"
    write_rig_mcap(path, seconds=0.5)
    replay = PlannedNode("rimd_replay", "replay", ("--ros-args", "-p", f"file:={path}", "-p", "rate:=5.0"))
    assert Rig(RigPlan(None, None, (replay,)), env=ros_env).run("replay", lambda: None,
                                                                ends_itself="rimd_replay") == 0
    assert "exited with status" not in capfd.readouterr().err


def test_stop_process_goes_on_to_the_next_signal_when_one_is_ignored():
    proc = subprocess.Popen([sys.executable, "-c", IGNORES_SIGINT], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "ready\n"   # SIGINT is ignored from here on
        timeouts: list[int] = []
        status = stop_process(proc, ((signal.SIGINT, 0.5), (signal.SIGTERM, 10.0), (signal.SIGKILL, 10.0)),
                              on_timeout=timeouts.append)
        assert (status, timeouts) == (-signal.SIGTERM, [signal.SIGINT])
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
