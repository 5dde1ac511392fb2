"""Testing your DAQ software against the twin: a pytest plugin (registered as ``pytest11`` entry point).

The fixture ``rimd_rig`` brings up rigs in lockstep, each in a ROS domain of its own (leased machine-wide, so
parallel tests and parallel CI jobs never hear each other), with a seed, parameters and a fault scenario, and
stops them at the end of the test. In lockstep the rig waits for every consumer you name before its first
block and never runs ahead of the slowest, so your test is exactly as fast as your software and loses nothing,
however loaded the machine is (docs/rig.md, "Pacing: lockstep"; docs/testing.md)::

    def test_my_daq_counts_every_block(rimd_rig, tmp_path):
        rig = rimd_rig(consumers=["my_daq"], seed=7)
        subprocess.run([sys.executable, "my_daq.py", "--until", "3"], env=rig.env, check=True, timeout=120)
        ...

``rimd_rig(...)`` returns a :class:`RigHandle` once the rig is ready: every node in the ROS graph, the simulator's
services served, and its lockstep wait armed (:mod:`rimd_sim.ros.rig_handle`). A first run on an empty numba cache
compiles the model's kernels before the simulator is ready. The wait is bounded (``ready_timeout``; the ini key
``rimd_ready_timeout``, the environment variable ``RIMD_READY_TIMEOUT``; default :data:`DEFAULT_READY_TIMEOUT_S`),
says what it waits for every few seconds on stderr, and fails naming what was missing and the nodes' last log
lines. A node that exits fails the test at once with :class:`rimd_sim.errors.UnavailableError`, naming the node,
its exit status and its last log lines.

The domains are leased from 1..100, or the range of ``RIMD_DOMAIN_RANGE`` (which wins) or of the ini key
``rimd_domain_range`` (``51-80``; :func:`configured_domain_range`).

This module is the plugin: the ini keys, :class:`RigFactory` and the fixture. It re-exports the names of the
modules it stands on, so that ``from rimd_sim.ros.testing import ...`` reaches them all:
:mod:`rimd_sim.ros.fixture_settings` (the domain range and the ready timeout), :mod:`rimd_sim.ros.domains` (the
leases) and :mod:`rimd_sim.ros.rig_handle` (the handle). Only pytest loads this module; nothing in the package
imports it.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest

from rimd_sim.ros.domains import LOCK_DIR, DomainLease, lease_domain_id, ros_environment
from rimd_sim.ros.fixture_settings import (
    DEFAULT_READY_TIMEOUT_S,
    DOMAIN_ID_MAX,
    DOMAIN_ID_MIN,
    DOMAIN_RANGE_ENV,
    DOMAIN_RANGE_INI,
    READY_TIMEOUT_ENV,
    READY_TIMEOUT_INI,
    ROS_DOMAIN_ID_LIMIT,
    configured_domain_range,
    configured_ready_timeout,
    parse_domain_range,
    parse_ready_timeout,
)
from rimd_sim.ros.rig_handle import (
    LOG_TAIL_LINES,
    PACING_STATUS,
    READY_REPORT_S,
    RIG_SERVICES,
    RUN_TIMEOUT_S,
    SERVICE_TIMEOUT_S,
    TRUTH_TIMEOUT_S,
    RigHandle,
)

# The plugin's names and those of the modules it stands on, re-exported.
__all__ = ["DEFAULT_READY_TIMEOUT_S", "DOMAIN_ID_MAX", "DOMAIN_ID_MIN", "DOMAIN_RANGE_ENV", "DOMAIN_RANGE_INI",
           "LOCK_DIR", "LOG_TAIL_LINES", "PACING_STATUS", "READY_REPORT_S", "READY_TIMEOUT_ENV", "READY_TIMEOUT_INI",
           "RIG_SERVICES", "ROS_DOMAIN_ID_LIMIT", "RUN_TIMEOUT_S", "SERVICE_TIMEOUT_S", "TRUTH_TIMEOUT_S",
           "DomainLease", "RigFactory", "RigHandle", "configured_domain_range", "configured_ready_timeout",
           "fault_entries", "lease_domain_id", "parse_domain_range", "parse_ready_timeout", "rimd_rig",
           "ros_environment"]


def pytest_addoption(parser: pytest.Parser) -> None:
    """The plugin's ini keys (``--strict-config`` refuses an unregistered one)."""
    parser.addini(DOMAIN_RANGE_INI, f"ROS domain ids the rimd_rig fixture leases, FIRST-LAST (default "
                                    f"{DOMAIN_ID_MIN}-{DOMAIN_ID_MAX}; {DOMAIN_RANGE_ENV} wins)", default="")
    parser.addini(READY_TIMEOUT_INI, f"seconds rimd_rig waits for a rig to be ready (default "
                                     f"{DEFAULT_READY_TIMEOUT_S:g}; {READY_TIMEOUT_ENV} wins)", default="")


def fault_entries(faults: Sequence[Mapping[str, Any] | str]) -> list[str]:
    """A fault scenario (entries as in a scenario file, docs/faults.md) as the simulator's ``faults`` strings."""
    return [f if isinstance(f, str) else " ".join(f"{k}={v}" for k, v in f.items()) for f in faults]


class RigFactory:
    """What the ``rimd_rig`` fixture gives: call it to bring up a rig (as many as you like in one test).

    Args:
        base_dir: Where each rig's run directory goes.
        config: The pytest configuration, for the ini keys (None: the environment variables and defaults only).
    """

    def __init__(self, base_dir: Path, config: pytest.Config | None = None) -> None:
        self._base = base_dir
        self._config = config
        self._rigs: list[RigHandle] = []

    def __call__(self, *, consumers: Sequence[str] = (), seed: int = 0,
                 parameters: Mapping[str, Any] | None = None, faults: Sequence[Mapping[str, Any] | str] = (),
                 config: str | Path | None = None, record: bool = True, rerun: bool = False,
                 real_time_factor: float = 0.0, window: float | None = None, timeout: float | None = None,
                 on_timeout: str | None = None, env: Mapping[str, str] | None = None,
                 ready_timeout: float | None = None, separate: bool = False,
                 until: float | None = None) -> RigHandle:
        """Bring up a rig in lockstep in a domain of its own; return it once it is ready.

        Args:
            consumers: The names your consumers report progress under (``ProgressReporter``); the rig also waits
                for its recorder (``record``) and Rerun bridge (``rerun``, saving an ``.rrd`` in the run directory).
            seed: The seed of every random stream.
            parameters: More simulator parameters (flat ROS names: ``{"gap": 1e-3, "motor.initial_setpoint": 7.25}``).
            faults: A fault scenario: entries as in a scenario file (``{"channel": "impact_force", "kind":
                "dropout", "start": 2.0, "duration": 0.3}``).
            config: The rig's parameter file (default config/rimd.yaml).
            record: Record the run (``RigHandle.recording``).
            rerun: Run the Rerun bridge too.
            real_time_factor: The speed cap (0: as fast as the consumers allow).
            window: ``lockstep.window`` (s of simulation time a consumer may lag).
            timeout: ``lockstep.timeout`` (s without progress before ``on_timeout`` applies).
            on_timeout: ``lockstep.on_timeout``: ``wait`` or ``drop``.
            env: More environment variables of the rig's processes (``{"NUMBA_CACHE_DIR": ...}``); not in
                ``RigHandle.env``, the environment of your processes.
            ready_timeout: Seconds to wait for the rig to be ready (default: ``RIMD_READY_TIMEOUT``, the ini key
                ``rimd_ready_timeout``, else :data:`DEFAULT_READY_TIMEOUT_S`).
            until: Simulation time (s) at which the rig holds: it simulates up to the first block end at or after it
                (10 ms blocks by default), its recording ends at ``until`` exactly, and it publishes nothing more
                until it is stopped. None: it runs until stopped.
            separate: Each node in a process of its own (logs ``<node>.log``). By default the rig is composed:
                the recorder and the bridge run in the simulator's process, fed without DDS (one log,
                ``rimd_composed.log``; :meth:`RigHandle.log` finds a node's lines there), docs/rig.md.

        Raises:
            UnavailableError: A node exited while the rig came up, or the rig was not ready in time (the rig is
                stopped; the message names the node or what was missing, with the nodes' last log lines).
            InputError: The configuration, a parameter, the domain range or the ready timeout is refused
                (nothing started).
        """
        from rimd_sim.ros.bringup.plan import plan_rig
        from rimd_sim.ros.bringup.processes import Rig
        from rimd_sim.ros.nodes.registry import READY_DIR_ENV

        wait = configured_ready_timeout(self._config) if ready_timeout is None else float(ready_timeout)
        if not (math.isfinite(wait) and wait > 0):
            raise ValueError(f"ready_timeout = {ready_timeout!r}: must be a number of seconds > 0")
        lease = lease_domain_id(domain_range=configured_domain_range(self._config))
        run_dir = Path(tempfile.mkdtemp(prefix=f"rig{lease.domain_id}_", dir=self._base))
        sim = {"seed": seed, **(parameters or {})}
        if faults:
            sim["faults"] = fault_entries(faults)
        for key, value in (("window", window), ("timeout", timeout), ("on_timeout", on_timeout)):
            if value is not None:
                sim[f"lockstep.{key}"] = value
        bridge = {"sink": "save", "save_path": str(run_dir / "rig.rrd")}
        recorder = {}
        if until is not None:
            sim["until"] = until
            if isinstance(until, (int, float)) and math.isfinite(until) and until > 0:
                recorder["stop_at"] = round(until * 1e9)   # stamps are simulation time from 0 in lockstep
        rig = None
        try:
            plan = plan_rig(config, output_dir=run_dir / "recording" if record else None, record=record,
                            rerun=rerun, lockstep=True, consumers=consumers, real_time_factor=real_time_factor,
                            parameters={"rimd_simulator": sim, "rimd_rerun": bridge,
                                        **({"rimd_recorder": recorder} if record and recorder else {})},
                            run_dir=run_dir,
                            separate=separate)
            handle_env = ros_environment(lease.domain_id, run_dir / "ros_log")
            ready_dir = run_dir / "ready"
            ready_dir.mkdir()
            rig = Rig(plan, env={**handle_env, **(env or {}), READY_DIR_ENV: str(ready_dir)},
                      log_dir=run_dir / "logs")
            rig.start()
        except BaseException:
            if rig is not None:
                rig.stop()
            lease.release()
            raise
        handle = RigHandle(lease.domain_id, handle_env, run_dir, plan.recording_dir, plan.lockstep_consumers, rig,
                           lease, _ready_dir=ready_dir, until=until)
        self._rigs.append(handle)
        try:
            handle.ready_after = handle.wait_ready(wait)
        except BaseException:
            self._rigs.remove(handle)
            handle.stop()
            raise
        return handle

    def stop_all(self) -> None:
        """Stop every rig this factory started (idempotent)."""
        while self._rigs:
            self._rigs.pop().stop()


@pytest.fixture
def rimd_rig(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest) -> Iterator[RigFactory]:
    """Bring up rigs in lockstep, each in a ROS domain of its own, ready when returned; all stopped after the test."""
    factory = RigFactory(tmp_path_factory.mktemp("rimd_rig"), config=request.config)
    try:
        yield factory
    finally:
        factory.stop_all()
