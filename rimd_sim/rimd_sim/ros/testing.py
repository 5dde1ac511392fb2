"""Testing your DAQ software against the twin: a pytest plugin (registered as ``pytest11`` entry point).

The fixture ``rimd_rig`` brings up rigs in lockstep, each in a ROS domain of its own (leased machine-wide, so
parallel tests and parallel CI jobs never hear each other), with a seed, parameters and a fault scenario, and
stops them at the end of the test. In lockstep the rig waits for every consumer you name before its first
block and never runs ahead of the slowest, so your test is exactly as fast as your software and loses nothing,
however loaded the CI runner is (docs/rig.md, "Pacing: lockstep"; docs/testing.md)::

    def test_my_daq_counts_every_block(rimd_rig, tmp_path):
        rig = rimd_rig(consumers=["my_daq"], seed=7)
        subprocess.run([sys.executable, "my_daq.py", "--until", "3"], env=rig.env, check=True, timeout=120)
        ...

:class:`RigHandle` gives the domain's environment (``env``, for the processes you start), the recording
directory, the rig's services as one-liners (``motor``, ``perturb``, ``inject``, ``pause``, ``resume``, ``reset``,
``clear_faults``), waits on simulation time, each node's log, and ``stop``.
"""

from __future__ import annotations

import fcntl
import itertools
import os
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

__all__ = ["DomainLease", "RigHandle", "lease_domain_id", "rimd_rig"]

DOMAIN_ID_MIN = 1
DOMAIN_ID_MAX = 100
LOCK_DIR = Path(tempfile.gettempdir()) / "rimd-ros-domain-locks"
_lease_counter = itertools.count()


class DomainLease:
    """An exclusively held ROS_DOMAIN_ID; a context manager, ``release()`` is safe to call twice.

    A lease is an exclusive ``flock`` on ``<tmp>/rimd-ros-domain-locks/<id>.lock``: shared by every process on
    the machine (two test runs, pytest-xdist workers), and released by the kernel when the holder dies.
    """

    def __init__(self, domain_id: int, lock_file: int) -> None:
        self.domain_id = domain_id
        self._lock_file: int | None = lock_file

    def release(self) -> None:
        """Give the domain back (closing the descriptor drops the lock)."""
        if self._lock_file is not None:
            os.close(self._lock_file)
            self._lock_file = None

    def __enter__(self) -> DomainLease:
        """Return the lease."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Release the lease."""
        self.release()


def lease_domain_id(*, lock_dir: Path = LOCK_DIR) -> DomainLease:
    """Take the first free domain id of 1..100 (0 is left to people), from a start that differs per process.

    Raises:
        RuntimeError: Every id is held by someone else.
    """
    lock_dir.mkdir(mode=0o777, parents=True, exist_ok=True)
    span = DOMAIN_ID_MAX - DOMAIN_ID_MIN + 1
    start = (os.getpid() * 7 + next(_lease_counter)) % span
    for offset in range(span):
        domain_id = DOMAIN_ID_MIN + (start + offset) % span
        descriptor = os.open(lock_dir / f"{domain_id}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(descriptor)
            continue
        return DomainLease(domain_id, descriptor)
    raise RuntimeError(f"all ROS domain ids {DOMAIN_ID_MIN}..{DOMAIN_ID_MAX} are leased (lock files in {lock_dir})")


def ros_environment(domain_id: int, log_dir: Path) -> dict[str, str]:
    """This process's environment on ``domain_id``, discovery kept on this machine, ROS logs in ``log_dir``."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY", "ROS_DISCOVERY_SERVER",
                        "_ROS_WHEELS_BOOTSTRAP_COMPLETE")}
    env.update({"ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                "ROS_LOG_DIR": str(log_dir), "PYTHONUNBUFFERED": "1", "RCUTILS_COLORIZED_OUTPUT": "0"})
    return env


def fault_entries(faults: Sequence[Mapping[str, Any] | str]) -> list[str]:
    """A fault scenario (entries as in a scenario file, docs/faults.md) as the simulator's ``faults`` strings."""
    return [f if isinstance(f, str) else " ".join(f"{k}={v}" for k, v in f.items()) for f in faults]


@dataclass
class RigHandle:
    """A running rig of the ``rimd_rig`` fixture. See the module docstring."""

    domain_id: int
    env: dict[str, str]
    run_dir: Path
    recording: Path | None
    consumers: tuple[str, ...]
    rig: Any
    _lease: DomainLease
    _client: Any = None
    _clock_ns: int = -1

    @property
    def config(self) -> Any:
        """The simulator's configuration as started (a :class:`rimd_sim.settings.config.SimConfig`).

        The core reproduces the run offline from it: ``RigSimulator(rig.config)`` with the same commands at the
        same stamps.
        """
        return self.rig.plan.config

    @property
    def node_names(self) -> list[str]:
        """The rig's node names."""
        return self.rig.plan.names

    def log(self, node: str = "rimd_simulator") -> str:
        """What a node has written so far."""
        path = self.run_dir / "logs" / f"{node}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    # -- rclpy in this process, on the rig's domain ------------------------------------------------------------
    def client(self) -> Any:
        """The rig's services and a node on its domain (:class:`rimd_sim.ros.clients.rig.RigClient`, made once)."""
        if self._client is None:
            from rclpy.qos import QoSProfile, ReliabilityPolicy
            from rosgraph_msgs.msg import Clock

            from rimd_sim.ros.clients.rig import RigClient

            self._client = RigClient(domain_id=self.domain_id, timeout=30.0, name="rimd_test_rig")

            def on_clock(msg: Clock) -> None:
                self._clock_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec

            self._client.node.create_subscription(Clock, "/clock", on_clock,
                                                  QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        return self._client

    def _ros(self) -> Any:
        """A node of this process on the rig's domain (for subscriptions of the test's own)."""
        return self.client().node

    def _spin_until(self, condition: Any, timeout: float) -> bool:
        return self.client().spin_until(condition, timeout)

    def motor(self, frequency_hz: float, ramp_rate: float = 0.0, at: float | None = None) -> Any:
        """Set the motor frequency (at simulation time ``at`` s, else the next block); the response."""
        return self.client().motor(frequency_hz, ramp_rate, at)

    def perturb(self, velocity: float, at: float | None = None) -> Any:
        """Add ``velocity`` (m/s) to the hammer (at simulation time ``at`` s); the response."""
        return self.client().perturb(velocity, at)

    def inject(self, channel: str, kind: str, *, start: float = 0.0, after: float = 0.0, duration: float = 0.0,
               magnitude: float = 0.0) -> Any:
        """Inject a fault (docs/faults.md); the response."""
        return self.client().inject(channel, kind, start=start, after=after, duration=duration, magnitude=magnitude)

    def pause(self) -> Any:
        """``/rig/pause``."""
        return self.client().trigger("pause")

    def resume(self) -> Any:
        """``/rig/resume``."""
        return self.client().trigger("resume")

    def reset(self) -> Any:
        """``/rig/reset``."""
        return self.client().trigger("reset")

    def clear_faults(self) -> Any:
        """``/rig/clear_faults``."""
        return self.client().trigger("clear_faults")

    def session(self, timeout: float = 30.0) -> Any:
        """The rig's current run (``rimd_msgs/msg/RigSession`` from /rig/session: run id, seed, configuration hash)."""
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        from rimd_msgs.msg import RigSession

        node = self._ros()
        got: list[Any] = []
        sub = node.create_subscription(RigSession, "/rig/session", got.append, QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        try:
            assert self._spin_until(lambda: got, timeout), f"no /rig/session in {timeout:g} s"
            return got[-1]
        finally:
            node.destroy_subscription(sub)

    def simulated(self) -> float:
        """The rig's simulation time as last heard on its /clock (s; -1e-9 before any)."""
        self.client().executor.spin_once(timeout_sec=0.0)
        return self._clock_ns / 1e9

    def wait_until_simulated(self, seconds: float, timeout: float = 120.0) -> None:
        """Wait until the rig's simulation time (its /clock) reaches ``seconds``.

        Raises:
            AssertionError: Not in ``timeout`` s of wall time; the message says where the rig stands and what
                it waits for (its log's last lockstep line).
        """
        target = round(seconds * 1e9)
        if not self._spin_until(lambda: self._clock_ns >= target, timeout):
            waiting = [line for line in self.log().splitlines() if "lockstep: holding" in line]
            raise AssertionError(f"the rig is at {self._clock_ns / 1e9:.3f} s, not {seconds:g} s, after {timeout:g} s"
                                 + (f"; {waiting[-1]}" if waiting else ""))

    def stop(self) -> int:
        """Stop the rig (the recorder finishes its file) and give the domain back; the rig's exit status."""
        status = self.rig.stop()
        if self._client is not None:
            self._client.close()
            self._client = None
        self._lease.release()
        return status


class RigFactory:
    """What the ``rimd_rig`` fixture gives: call it to bring up a rig (as many as you like in one test)."""

    def __init__(self, base_dir: Path) -> None:
        self._base = base_dir
        self._rigs: list[RigHandle] = []

    def __call__(self, *, consumers: Sequence[str] = (), seed: int = 0,
                 parameters: Mapping[str, Any] | None = None, faults: Sequence[Mapping[str, Any] | str] = (),
                 config: str | Path | None = None, record: bool = True, rerun: bool = False,
                 real_time_factor: float = 0.0, window: float | None = None, timeout: float | None = None,
                 on_timeout: str | None = None) -> RigHandle:
        """Bring up a rig in lockstep in a domain of its own.

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
        """
        from rimd_sim.ros.bringup import Rig, plan_rig

        lease = lease_domain_id()
        run_dir = Path(tempfile.mkdtemp(prefix=f"rig{lease.domain_id}_", dir=self._base))
        sim = {"seed": seed, **(parameters or {})}
        if faults:
            sim["faults"] = fault_entries(faults)
        for key, value in (("window", window), ("timeout", timeout), ("on_timeout", on_timeout)):
            if value is not None:
                sim[f"lockstep.{key}"] = value
        bridge = {"sink": "save", "save_path": str(run_dir / "rig.rrd")}
        try:
            plan = plan_rig(config, output_dir=run_dir / "recording" if record else None, record=record,
                            rerun=rerun, lockstep=True, consumers=consumers, real_time_factor=real_time_factor,
                            parameters={"rimd_simulator": sim, "rimd_rerun": bridge}, run_dir=run_dir)
            env = ros_environment(lease.domain_id, run_dir / "ros_log")
            rig = Rig(plan, env=env, log_dir=run_dir / "logs")
            rig.start()
        except BaseException:
            lease.release()
            raise
        handle = RigHandle(lease.domain_id, env, run_dir, plan.recording_dir, plan.lockstep_consumers, rig, lease)
        self._rigs.append(handle)
        return handle

    def stop_all(self) -> None:
        """Stop every rig this factory started (idempotent)."""
        while self._rigs:
            self._rigs.pop().stop()


@pytest.fixture
def rimd_rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RigFactory]:
    """Bring up rigs in lockstep, each in a ROS domain of its own; every one is stopped after the test."""
    factory = RigFactory(tmp_path_factory.mktemp("rimd_rig"))
    try:
        yield factory
    finally:
        factory.stop_all()
