"""The test harness keeps its promises: unique domains, loopback discovery, processes always killed."""

from __future__ import annotations

import os
import signal
import sys
import textwrap

import psutil
import pytest

from harness.domains import lease_domain_id
from harness.processes import ProcessFailure, ProcessManager
from rimd_sim.errors import UnavailableError
from rimd_sim.ros.testing import configured_domain_range

pytestmark = pytest.mark.process  # every test here starts a process


def test_leases_are_exclusive_and_in_range():
    first, last = configured_domain_range()   # 1..100 unless RIMD_DOMAIN_RANGE says otherwise
    leases = [lease_domain_id() for _ in range(min(5, last - first + 1))]
    try:
        ids = [lease.domain_id for lease in leases]
        assert len(set(ids)) == len(ids)
        assert all(first <= domain_id <= last for domain_id in ids)
    finally:
        for lease in leases:
            lease.release()
            lease.release()  # idempotent


def test_all_domains_taken_is_an_error(tmp_path):
    leases = []
    try:
        first, last = configured_domain_range()
        for _ in range(last - first + 1):
            leases.append(lease_domain_id(lock_dir=tmp_path))
        with pytest.raises(UnavailableError, match="all ROS domain ids"):
            lease_domain_id(lock_dir=tmp_path)
    finally:
        for lease in leases:
            lease.release()


def test_ros_env_isolates_the_test(ros_env, ros_domain_id):
    assert ros_env["ROS_DOMAIN_ID"] == str(ros_domain_id) == os.environ["ROS_DOMAIN_ID"]
    assert ros_env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert "ROS_STATIC_PEERS" not in ros_env


def _gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


STUBBORN_PARENT = textwrap.dedent("""
    import os, signal, subprocess, sys, time
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    guard = os.environ.get("_ROS_WHEELS_BOOTSTRAP_COMPLETE")
    print(f"parent {os.getpid()} child {child.pid} bootstrapped {guard}", flush=True)
    time.sleep(600)
""")


def test_stop_kills_the_whole_group_even_when_signals_are_ignored(tmp_path, ros_env):
    manager = ProcessManager(ros_env, tmp_path)
    process = manager.start_python("-c", STUBBORN_PARENT)
    match = process.wait_for_output(r"parent (\d+) child (\d+) bootstrapped (\S+)", timeout=20)
    parent, child = int(match.group(1)), int(match.group(2))
    # The ROS wheels' bootstrapper re-executed the interpreter in place: same pid, guard now set.
    assert parent == process.pid
    assert match.group(3) == "1"
    manager.stop_all(timeout=1.0)   # (a hang would be pytest-timeout's)
    assert process.returncode == -signal.SIGKILL
    assert _gone(parent) and _gone(child)
    process.stop()  # idempotent


def test_wait_for_output_is_bounded_and_shows_the_log(tmp_path, ros_env):
    with ProcessManager(ros_env, tmp_path) as manager:
        process = manager.start_python("-c", "import time; print('hello', flush=True); time.sleep(600)")
        with pytest.raises(ProcessFailure, match=r"(?s)printed no /never/ within 0.5 s.*hello"):
            process.wait_for_output("never", timeout=0.5)


def test_wait_for_output_reports_an_early_exit(tmp_path, ros_env):
    with ProcessManager(ros_env, tmp_path) as manager:
        process = manager.start_python("-c", "import sys; print('bye'); sys.exit(3)")
        with pytest.raises(ProcessFailure, match="exited before printing"):
            process.wait_for_output("ready", timeout=20)
        assert process.wait(timeout=5) == 3


def test_start_node_refuses_a_missing_executable(ros_processes):
    with pytest.raises(FileNotFoundError, match="no executable 'no_such_node' in package 'rimd_sim'"):
        ros_processes.start_node("no_such_node")


def test_start_node_runs_an_installed_executable(ros_processes):
    process = ros_processes.start_node("rimd", "info")
    assert process.wait(timeout=30) == 0
    assert "rimd_sim_version" in process.output()


def test_processes_run_the_venv_python(tmp_path, ros_env):
    with ProcessManager(ros_env, tmp_path) as manager:
        process = manager.start_python("-c", "import sys; print(sys.prefix)")
        assert process.wait(timeout=20) == 0
        assert process.output().strip() == sys.prefix
