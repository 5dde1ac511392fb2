"""A node stopped by SIGINT or SIGTERM exits 0 with no traceback, whatever it is doing (docs/rig.md, Stopping).

Each of the four node executables is started and stopped several times at random moments: while it is
still loading (right after its stop handlers are in place, which ``/proc/PID/status`` shows: SIGTERM
becomes a caught signal when the entry module has run), and while it runs under heavy traffic (the
simulator as fast as possible, about 30,000 messages/s). The moments come from a seeded generator; the seed
is printed so that a failure can be replayed: half the stops of each node come from a fixed seed (the same
moments in every run, so a failure there reproduces by itself), half from a seed drawn from the clock (new
moments every run; ``RIMD_STOP_SEED`` replays one).

Before the entry module runs (interpreter start-up, a few tens of milliseconds), Python's own SIGINT
handling applies, as for any Python program; that window is not what these tests exercise.
"""

from __future__ import annotations

import os
import random
import signal
import time
from pathlib import Path

import pytest

from rimd_sim.io.reader import open_recording

pytestmark = pytest.mark.ros

STOPS_PER_NODE = 4   # loading and running, each from the fixed seed and from the clock's
#: The fixed seed of the first half of the stops; the second half's is drawn from the clock (or RIMD_STOP_SEED).
FIXED_SEED = 20261124
SEED = int(os.environ.get("RIMD_STOP_SEED", time.time_ns() % 1_000_000))


def _handlers_installed(pid: int) -> bool:
    """Whether the process catches SIGTERM (bit 15 of SigCgt): our entry module has run."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    for line in status.splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) & (1 << (signal.SIGTERM - 1)))
    return False


def _wait_handlers(process, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not _handlers_installed(process.pid):
        assert process.is_running(), f"{process.name} exited early:\n{process.tail()}"
        assert time.monotonic() < deadline, f"{process.name}: no stop handlers after {timeout} s"
        time.sleep(0.005)


def _stop_at_random_moments(ros_processes, executable: str, args: list[str], ready: str, offset: int,
                            check=None) -> list[str]:
    """Start ``executable`` STOPS_PER_NODE times; stop each at a random moment (the first half from the fixed
    seed, the second from the clock's; ``offset`` tells the nodes apart); return what was done."""
    done = []
    fixed, drawn = random.Random(FIXED_SEED + offset), random.Random(SEED + offset)
    for i in range(STOPS_PER_NODE):
        rng = fixed if i < STOPS_PER_NODE // 2 else drawn
        process = ros_processes.start_node(executable, *[a.format(i=i) for a in args], name=f"{executable}_{i}")
        _wait_handlers(process)
        if i % 2 == 0:
            when = f"loading +{rng.uniform(0.0, 0.5):.3f} s"
            time.sleep(float(when.split("+")[1][:-2]))
        else:
            process.wait_for_output(ready, timeout=60)
            when = f"running +{rng.uniform(0.0, 1.5):.3f} s"
            time.sleep(float(when.split("+")[1][:-2]))
        signum = signal.SIGINT if rng.random() < 0.75 else signal.SIGTERM
        process.send_signal(signum)
        status = process.wait(30)
        output = process.output()
        done.append(f"{signal.Signals(signum).name} at {when}: exit {status}")
        seed = f"seed {FIXED_SEED if rng is fixed else SEED} (+{offset}), stop {i}"
        assert status == 0, f"{seed}: {executable} stopped by {done[-1]}\n{process.tail()}"
        assert "Traceback" not in output, f"{seed}: {executable} {done[-1]}\n{process.tail()}"
        if check is not None:
            check(i, output)
    print(f"{executable} (seeds {FIXED_SEED}, then {SEED}, +{offset}):", "; ".join(done))
    return done


def _fast_simulator(ros_processes):
    sim = ros_processes.start_node("rimd_simulator", "--ros-args", "-p", "real_time_factor:=0.0",
                                   "-p", "motor.initial_setpoint:=3.75", name="fast_simulator")
    sim.wait_for_output(r"rig ready", timeout=60)
    return sim


def test_simulator_stopped_at_random_moments_exits_0(ros_processes):
    _stop_at_random_moments(ros_processes, "rimd_simulator",
                            ["--ros-args", "-p", "real_time_factor:=0.0", "-p", "motor.initial_setpoint:=3.75"],
                            r"rig ready", 0)


def test_recorder_stopped_at_random_moments_exits_0_and_its_file_reads(ros_processes, tmp_path):
    _fast_simulator(ros_processes)

    def check(i: int, output: str) -> None:
        assert "recording finished" in output, output
        files = sorted((tmp_path / f"rec{i}").rglob("*.mcap"))
        if "recording finished: 0 file(s)" in output:   # stopped before the first topic was found
            assert not files, output
            return
        assert files, output
        recording = open_recording(tmp_path / f"rec{i}")
        assert recording.complete, [r.describe() for r in recording.reports]

    _stop_at_random_moments(ros_processes, "rimd_recorder",
                            ["--ros-args", "-p", f"output_dir:={tmp_path}/rec{{i}}", "-p", "topics:=['/rig/.*']"],
                            r"recording /rig/truth", 1, check)


def test_rerun_bridge_stopped_at_random_moments_exits_0(ros_processes, tmp_path):
    _fast_simulator(ros_processes)
    _stop_at_random_moments(ros_processes, "rimd_rerun",
                            ["--ros-args", "-p", "sink:=save", "-p", f"save_path:={tmp_path}/bridge{{i}}.rrd",
                             "-p", "status_period:=0.0"],
                            r"rerun bridge ready", 2)


def test_replay_stopped_at_random_moments_exits_0(ros_processes, tmp_path):
    from harness.rig_mcap import write_rig_mcap

    recording = tmp_path / "rig.mcap"
    write_rig_mcap(recording, seconds=3.0)
    _stop_at_random_moments(ros_processes, "rimd_replay",
                            ["--ros-args", "-p", f"file:={recording}", "-p", "rate:=20.0", "-p", "loop:=true"],
                            r"replaying", 3)


def test_the_nodes_use_the_fast_dds_profile_with_a_short_heartbeat(tmp_path):
    """The entry module points Fast DDS at the package's profile (unless the user chose one), and the profile
    sets the reliable writers' heartbeat to 0.2 s (with Fast DDS's default, 3 s, a reader loses blocks under
    load)."""
    import subprocess
    import sys
    import xml.etree.ElementTree as ET

    code = "import os, rimd_sim.ros.nodes._entry; print(os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'])"
    env = {k: v for k, v in os.environ.items() if k != "FASTRTPS_DEFAULT_PROFILES_FILE"}
    path = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60,
                          check=True).stdout.strip()
    ns = {"p": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    writer = ET.parse(path).getroot().find("p:data_writer", ns)
    assert writer is not None and writer.get("is_default_profile") == "true"
    period = writer.find("p:times/p:heartbeatPeriod", ns)
    assert (int(period.find("p:sec", ns).text), int(period.find("p:nanosec", ns).text)) == (0, 200_000_000)
    mine = tmp_path / "mine.xml"
    env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(mine)
    chosen = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60,
                            check=True).stdout.strip()
    assert chosen == str(mine)   # the user's own profile wins


@pytest.mark.ros
@pytest.mark.parametrize(("node", "status"), [("rimd_simulator", 2), ("rimd_recorder", 2), ("rimd_rerun", 1)])
def test_an_unknown_executor_is_refused_by_name(ros_processes, node, status):
    """RIMD_EXECUTOR chooses the nodes' executor (events, the default, or single): any other value is refused
    before the node starts, naming the variable and the choices."""
    proc = ros_processes.start_node(node, env={"RIMD_EXECUTOR": "fast"})
    assert proc.wait(60) == status, proc.tail()
    assert "RIMD_EXECUTOR='fast' refused: must be one of events, single" in proc.output(), proc.tail()
