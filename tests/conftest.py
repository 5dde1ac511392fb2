"""Fixtures shared by the whole test suite.

ROS isolation: every test that asks for ``ros_env`` (directly or through ``ros_processes`` or
``rclpy_context``) gets its own ``ROS_DOMAIN_ID`` (leased machine-wide with the ``rimd_rig`` fixture's leases, in
the same range: 1..100, or ``RIMD_DOMAIN_RANGE`` / the ini key ``rimd_domain_range``; see ``harness/domains.py``
and docs/testing.md) and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, so DDS discovery stays on loopback and parallel runs never
hear each other. The variables are also set in ``os.environ`` for the duration of the test, so rclpy in
the test process joins the same domain.

Fixtures:
    repo_root:        the repository root (Path).
    ros_domain_id:    this test's ROS_DOMAIN_ID (int, leased for the test's duration).
    ros_log_dir:      a temporary ROS_LOG_DIR for this test.
    ros_env:          the environment (dict) for ROS processes of this test.
    ros_processes:    a harness.processes.ProcessManager; every process it starts is killed at teardown,
                      process group included, and its output is printed when the test failed.
    rclpy_context:    an initialised rclpy Context on this test's domain, shut down at teardown.
    ros_executor:     a SingleThreadedExecutor on rclpy_context; nodes added to it are destroyed at teardown.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from harness.domains import lease_domain_id
from harness.processes import ProcessManager
from rimd_sim.ros.testing import configured_domain_range
from rimd_sim.runtime import collector

REPO_ROOT = Path(__file__).resolve().parent.parent

# Variables that would widen or redirect discovery; removed from the ROS test environment.
_DISCOVERY_OVERRIDES = (
    "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY", "ROS_DISCOVERY_SERVER", "FASTRTPS_DEFAULT_PROFILES_FILE",
)


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[None]:
    """Keep each phase's report on the item (``item.rep_setup``, ``item.rep_call``) for fixtures."""
    report = yield
    setattr(item, f"rep_{report.when}", report)
    return report


def _test_failed(request: pytest.FixtureRequest) -> bool:
    return any(
        getattr(getattr(request.node, f"rep_{when}", None), "failed", False) for when in ("setup", "call")
    )


#: Set by ``make test-fast``: the quick target runs only tests that start no process, and holds them to it.
FAST = os.environ.get("RIMD_TEST_FAST") == "1"


def pytest_configure(config: pytest.Config) -> None:
    """The test session sets its cycle collector as the package's own processes do (rimd_sim.runtime.collector):
    young objects collected every 10,000 allocations. Measured on the in-process tests of five directories, one
    worker, alternately: 6 % less wall time with the collection's modules frozen too."""
    del config
    collector.configure()


def pytest_collection_finish(session: pytest.Session) -> None:
    """What the collection imported (numba, rclpy, matplotlib, the package) lives as long as the session: frozen."""
    del session
    collector.keep_what_exists()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A ROS test starts processes (DDS participants, nodes): it is a ``process`` test too.

    The files run heaviest first: those holding a ``slow`` test, then a ``ros`` one, then a ``process`` one, then
    the rest, each group in collection order and each file's tests in theirs. The workers take whole files in this
    order (scripts/run_tests.sh: ``--dist loadfile --no-loadscope-reorder``), so that the many quick in-process
    files fill the end of the run instead of one worker finishing a rig test alone (longest jobs first).
    """
    weight: dict[str, int] = {}
    for item in items:
        if item.get_closest_marker("ros") is not None and item.get_closest_marker("process") is None:
            item.add_marker(pytest.mark.process)
        module = item.nodeid.split("::", 1)[0]
        mark = next((k for k, name in enumerate(("slow", "ros", "process")) if item.get_closest_marker(name)), 3)
        weight[module] = min(weight.get(module, 3), mark)
    items.sort(key=lambda item: weight[item.nodeid.split("::", 1)[0]])   # stable: the order within a group stays


@pytest.fixture(autouse=True)
def _the_quick_target_starts_no_process(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """Under ``make test-fast`` a test that starts a process (a CLI, a node, a pool or cluster of workers) fails,
    naming the marker it lacks: the quick target's promise cannot rot."""
    if not FAST or request.node.get_closest_marker("process") is not None:
        return
    import multiprocessing.process
    import subprocess

    def refuse(*args: object, **kwargs: object) -> None:
        raise RuntimeError(f"{request.node.nodeid} starts a process: mark it @pytest.mark.process "
                           "(make test-fast runs only tests that start none)")

    monkeypatch.setattr(subprocess.Popen, "__init__", refuse)
    monkeypatch.setattr(multiprocessing.process.BaseProcess, "start", refuse)
    monkeypatch.setattr(os, "fork", refuse)


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository root."""
    return REPO_ROOT


@pytest.fixture
def ros_domain_id(request: pytest.FixtureRequest) -> Iterator[int]:
    """A ROS_DOMAIN_ID held by this test alone, machine-wide, in the configured range (1..100 by default)."""
    with lease_domain_id(domain_range=configured_domain_range(request.config)) as lease:
        yield lease.domain_id


@pytest.fixture
def ros_log_dir(tmp_path: Path) -> Path:
    """ROS_LOG_DIR of this test's processes."""
    path = tmp_path / "ros_log"
    path.mkdir()
    return path


@pytest.fixture
def ros_env(ros_domain_id: int, ros_log_dir: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """The environment of this test's ROS participants, also applied to ``os.environ`` during the test."""
    settings = {
        "ROS_DOMAIN_ID": str(ros_domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_LOG_DIR": str(ros_log_dir),
        "PYTHONUNBUFFERED": "1",
        "RCUTILS_COLORIZED_OUTPUT": "0",
    }
    for name, value in settings.items():
        monkeypatch.setenv(name, value)
    for name in _DISCOVERY_OVERRIDES:
        monkeypatch.delenv(name, raising=False)
    return dict(os.environ)


@pytest.fixture
def ros_processes(
    ros_env: dict[str, str], tmp_path: Path, request: pytest.FixtureRequest
) -> Iterator[ProcessManager]:
    """Start processes with ``ros_env``; all are stopped (group-wide, SIGINT→SIGTERM→SIGKILL) at teardown."""
    manager = ProcessManager(ros_env, tmp_path / "processes")
    try:
        yield manager
    finally:
        manager.stop_all()
        if _test_failed(request):
            for process in manager.processes:
                print(f"\n--- {process.name}: {process.args} exit {process.returncode} ---")
                print(process.tail(60))


@pytest.fixture
def rclpy_context(ros_env: dict[str, str]) -> Iterator[object]:
    """An rclpy Context initialised on this test's domain (no signal handlers), shut down at teardown."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    context = Context()
    rclpy.init(context=context, domain_id=int(ros_env["ROS_DOMAIN_ID"]),
               signal_handler_options=SignalHandlerOptions.NO)
    try:
        yield context
    finally:
        context.try_shutdown()


@pytest.fixture
def ros_executor(rclpy_context: object) -> Iterator[object]:
    """A SingleThreadedExecutor on ``rclpy_context``; nodes added to it are destroyed at teardown."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=rclpy_context)
    try:
        yield executor
    finally:
        for node in list(executor.get_nodes()):
            executor.remove_node(node)
            node.destroy_node()
        executor.shutdown(timeout_sec=1.0)
