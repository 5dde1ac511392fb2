"""The ``rimd_rig`` fixture (rimd_sim.ros.testing, docs/testing.md): ready when it returns, a dead node named at once,
service helpers bounded by their timeouts, the leased domains within a configurable range.

Hypotheses:

- with an empty numba cache (``NUMBA_CACHE_DIR`` a new directory, given to the rig's processes through the
  fixture's ``env``) the simulator compiles for half a minute before it serves anything; the fixture returns only
  once the rig is ready, saying on stderr what it waits for meanwhile, so the first ``rig.motor`` with a short
  timeout is answered;
- a simulator that cannot start (its environment lacks ``rimd_msgs``: it dies at import, as in a venv without
  the message package) fails the fixture within 10 s, naming the node, its exit status and its error;
- a rig not ready within the ready timeout is stopped and fails the fixture, naming what was missing, the
  settings of the timeout and the nodes' logs;
- a held simulator (stopped with SIGSTOP) makes a helper with a 1 s timeout fail after about 1 s, naming the
  service and the domain; once it runs again it answers; killed, the next helper fails at once (not after its
  30 s timeout), naming the node and how it ended, with its last log lines;
- the domain range (``RIMD_DOMAIN_RANGE``, which wins, or the ini key ``rimd_domain_range``) is parsed and refused
  with a clear message, and the leases stay within it; the ready timeout likewise; the ini keys are registered (a
  pytest run with ``--strict-config`` takes them).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import rimd_sim
from rimd_sim.errors import CommandError, InputError, UnavailableError
from rimd_sim.ros.testing import (
    DEFAULT_READY_TIMEOUT_S,
    configured_domain_range,
    configured_ready_timeout,
    lease_domain_id,
    parse_domain_range,
    parse_ready_timeout,
)

# ---- the domain range and the ready timeout (in-process) ------------------------------------------------------------


@pytest.mark.parametrize(("text", "expected"), [("101-150", (101, 150)), (" 101 - 150 ", (101, 150)),
                                                ("7", (7, 7)), ("0-232", (0, 232))])
def test_a_domain_range_is_parsed(text, expected):
    assert parse_domain_range(text) == expected


@pytest.mark.parametrize(("text", "why"), [("150-101", "reversed"), ("0-233", "beyond the largest ROS domain id"),
                                           ("500", "beyond"), ("abc", "must be FIRST-LAST"),
                                           ("1-", "must be FIRST-LAST"), ("-5", "must be FIRST-LAST"),
                                           ("1..100", "must be FIRST-LAST"), ("1-2-3", "must be FIRST-LAST")])
def test_a_bad_domain_range_is_refused_naming_where_it_came_from(text, why):
    with pytest.raises(InputError, match=f"^RIMD_DOMAIN_RANGE = {text!r} refused: .*{why}") as refused:
        parse_domain_range(text, "RIMD_DOMAIN_RANGE")
    assert "0 <= FIRST <= LAST <= 232" in str(refused.value)


class IniFile:
    """A pytest configuration's ini side, as the plugin reads it (``getini``, ``inipath``)."""

    def __init__(self, **values: str) -> None:
        self.values, self.inipath = values, Path("/ci/pytest.ini")

    def getini(self, name: str) -> str:
        return self.values.get(name, "")


def test_the_environment_wins_over_the_ini_key_which_wins_over_the_default():
    ini = IniFile(rimd_domain_range="101-150", rimd_ready_timeout="200")
    assert configured_domain_range(None, {}) == (1, 100)
    assert configured_domain_range(ini, {}) == (101, 150)
    assert configured_domain_range(ini, {"RIMD_DOMAIN_RANGE": "160-170"}) == (160, 170)
    assert configured_domain_range(ini, {"RIMD_DOMAIN_RANGE": " "}) == (101, 150)   # empty: not set
    assert configured_ready_timeout(None, {}) == DEFAULT_READY_TIMEOUT_S == 120.0
    assert configured_ready_timeout(ini, {}) == 200.0
    assert configured_ready_timeout(ini, {"RIMD_READY_TIMEOUT": "45.5"}) == 45.5
    with pytest.raises(InputError, match=r"^rimd_domain_range in pytest.ini = '101-300' refused"):
        configured_domain_range(IniFile(rimd_domain_range="101-300"), {})


@pytest.mark.parametrize("text", ["0", "-3", "abc", "inf", "nan", ""])
def test_a_bad_ready_timeout_is_refused(text):
    with pytest.raises(InputError, match=f"^RIMD_READY_TIMEOUT = {text!r} refused: must be a number of seconds > 0"):
        parse_ready_timeout(text, "RIMD_READY_TIMEOUT")


def test_leases_stay_within_the_range_until_it_is_full(tmp_path):
    leases = [lease_domain_id(lock_dir=tmp_path, domain_range=(140, 142)) for _ in range(3)]
    try:
        assert sorted(lease.domain_id for lease in leases) == [140, 141, 142]
        with pytest.raises(UnavailableError, match=r"all ROS domain ids 140\.\.142 are leased .*RIMD_DOMAIN_RANGE"):
            lease_domain_id(lock_dir=tmp_path, domain_range=(140, 142))
        with lease_domain_id(lock_dir=tmp_path, domain_range=(140, 143)) as more:   # the same lock files
            assert more.domain_id == 143
    finally:
        for lease in leases:
            lease.release()
    with lease_domain_id(lock_dir=tmp_path, domain_range=(140, 142)) as again:   # given back
        assert 140 <= again.domain_id <= 142


def test_a_lease_without_a_range_takes_the_environment_s(tmp_path, monkeypatch):
    monkeypatch.setenv("RIMD_DOMAIN_RANGE", "201-202")
    with lease_domain_id(lock_dir=tmp_path) as a, lease_domain_id(lock_dir=tmp_path) as b:
        assert {a.domain_id, b.domain_id} == {201, 202}
    monkeypatch.setenv("RIMD_DOMAIN_RANGE", "202-201")
    with pytest.raises(InputError, match="RIMD_DOMAIN_RANGE = '202-201' refused: reversed"):
        lease_domain_id(lock_dir=tmp_path)


USER_SUITE = textwrap.dedent("""
    from rimd_sim.ros.testing import configured_domain_range, configured_ready_timeout, lease_domain_id

    def test_the_ini_keys_apply(request, tmp_path):
        assert configured_domain_range(request.config) == (131, 133)
        assert configured_ready_timeout(request.config) == 77.0
        with lease_domain_id(lock_dir=tmp_path, domain_range=configured_domain_range(request.config)) as lease:
            assert 131 <= lease.domain_id <= 133
""")


@pytest.mark.process
def test_a_user_suite_sets_the_ini_keys_under_strict_config(tmp_path):
    (tmp_path / "pytest.ini").write_text("[pytest]\naddopts = --strict-config -p no:cacheprovider\n"
                                         "rimd_domain_range = 131-133\nrimd_ready_timeout = 77\n")
    (tmp_path / "test_user.py").write_text(USER_SUITE)
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("PYTEST_") and k not in ("RIMD_DOMAIN_RANGE", "RIMD_READY_TIMEOUT")}
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:xdist", "test_user.py"], cwd=tmp_path,
                            env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "1 passed" in result.stdout, result.stdout + result.stderr


# ---- rigs (processes) -----------------------------------------------------------------------------------------------


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_with_an_empty_numba_cache_the_fixture_returns_a_ready_rig(rimd_rig, tmp_path, capsys):
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    started = time.monotonic()
    rig = rimd_rig(consumers=["nobody"], record=False, env={"NUMBA_CACHE_DIR": str(cache)})
    returned = time.monotonic() - started
    answer = rig.motor(4.0, timeout=5.0)   # the first call: served at once, no waiting for the rig
    assert answer.success, answer.message
    assert any(cache.rglob("*.nbi")), "the rig's processes did not compile into the empty cache"
    err = capsys.readouterr().err
    waits = [line for line in err.splitlines() if line.startswith("rimd_rig: waiting for ")]
    print(f"ready after {rig.ready_after:.1f} s (returned after {returned:.1f} s); {len(waits)} progress lines")
    assert waits and all(line.endswith(" s of 120 s)") for line in waits), err
    assert any("simulator" in line for line in waits), waits
    assert "NUMBA_CACHE_DIR" not in rig.env   # the rig's own environment, not the one for the test's processes


def _rimd_sim_source() -> str:
    return str(Path(rimd_sim.__file__).resolve().parents[1])


@pytest.mark.ros
def test_a_simulator_that_cannot_start_fails_the_fixture_at_once_naming_it(rimd_rig):
    with pytest.raises(UnavailableError) as failed:   # rimd_sim importable, rimd_msgs not: dies at import
        rimd_rig(consumers=["nobody"], record=False, env={"PYTHONPATH": _rimd_sim_source()})
    message = str(failed.value)
    # At once: the fixture names the process's exit, not its own timeout running out.
    assert "rimd_rig: node rimd_simulator exited with status 1 while the rig came up" in message, message
    # ModuleNotFoundError where no rimd_msgs is on the path at all; ImportError where the working directory holds
    # the repository's rimd_msgs sources (a namespace package without the generated modules).
    assert re.search(r"(ModuleNotFound|Import)Error: .*'rimd_msgs(\.msg)?'", message), message
    assert "last " in message and "rimd_simulator.log" in message, message


@pytest.mark.ros
def test_helpers_time_out_on_a_held_rig_and_a_dead_node_is_named_at_once(rimd_rig):
    rig = rimd_rig(consumers=["nobody"], record=False)
    simulator = rig.rig.processes["rimd_simulator"]
    os.kill(simulator.pid, signal.SIGSTOP)
    try:
        with pytest.raises(CommandError, match=rf"^/rig/set_motor_frequency did not answer within 1 s on "
                                               rf"ROS_DOMAIN_ID {rig.domain_id}$"):
            rig.motor(4.0, timeout=1.0)
    finally:
        os.kill(simulator.pid, signal.SIGCONT)
    assert rig.pause(timeout=30.0).success   # running again, the same rig answers
    simulator.kill()
    with pytest.raises(UnavailableError) as dead:
        rig.resume()   # default timeout: 30 s; named at once, not a timeout (the message says which)
    message = str(dead.value)
    assert message.startswith(f"rimd_rig: node rimd_simulator was killed by SIGKILL while the test waited on it "
                              f"(ROS_DOMAIN_ID {rig.domain_id}"), message
    assert "paused at simulation time" in message, message   # its last log lines


@pytest.mark.ros
def test_a_rig_not_ready_in_time_fails_naming_what_was_missing(rimd_rig):
    with pytest.raises(UnavailableError) as late:   # no Python process imports rclpy and serves in 0.2 s
        rimd_rig(consumers=["nobody"], record=False, ready_timeout=0.2)
    message = str(late.value)
    assert message.startswith("rimd_rig: the rig was not ready within 0.2 s (ROS_DOMAIN_ID "), message
    assert "; still waiting for " in message and "rimd_simulator" in message, message
    assert "RIMD_READY_TIMEOUT" in message and "--- rimd_simulator: " in message, message


@pytest.mark.ros
def test_the_test_s_participant_is_made_once_every_process_of_the_rig_has_its_own(rimd_rig, monkeypatch):
    from rimd_sim.ros.clients import rig as rig_client

    made: list[int] = []   # wall-clock ns at which the test's client (its participant) was made
    make = rig_client.RigClient.__init__

    def recorded(self, *args, **kwargs):
        made.append(time.time_ns())
        make(self, *args, **kwargs)

    monkeypatch.setattr(rig_client.RigClient, "__init__", recorded)
    before = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")
    rig = rimd_rig(consumers=["nobody"], separate=True)   # the recorder and the simulator: two processes
    files = {p.name: p.stat().st_mtime_ns for p in (rig.run_dir / "ready").iterdir()}
    assert sorted(files) == sorted(str(proc.pid) for proc in rig.rig.processes.values()), files
    assert len(made) == 1 and max(files.values()) <= made[0], (files, made)
    assert os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") == before   # set for the client's context only
    assert "RIMD_READY_DIR" not in rig.env   # the rig's processes', not the test's
    assert rig.motor(4.0, timeout=5.0).success

