"""Every start of the rig is a named run whose blocks are stamped on the exact grid of the wall clock.

Hypotheses, with the simulator at real time in its own process and a subscriber in this one that takes the
force blocks by hand (DDS's own reception, not when Python got round to them):

- each block's stamp is ``t0 + first_index / rate`` exactly (integer nanoseconds, ``t0`` the run's start stamp on
  ``/rig/session``), for a rig started unpaused, for the same rig after ``/rig/reset`` and for a rig started
  paused and then resumed, whose first block is sample 0;
- ``/rig/session`` (transient local) reaches a subscriber for each run: a start (``reason`` start), a reset (a
  new ``run_id``, ``reason`` reset), another start of the node (another ``run_id``, and a first_index from 0).
  The session's fields (sequence, start stamp, seed, hash, time base) are the runtime's test
  (tests/runtime/test_simulator_runtime.py).

How late the blocks leave (the reception minus the stamp of their last sample) is a speed figure: measured by
``benchmarks/bench_simulator_node.py`` (the rig's /diagnostics) and ``benchmarks/bench_latency.py``, not asserted
here; that a block is due when its stamp says is the runtime's test on a fake clock.
"""

from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from harness.ros import call_service, spin_until
from rimd_msgs.msg import RigSession, SampleBlock
from rimd_sim.io.cdr import read_block
from rimd_sim.ros.nodes.polling import PolledSubscriptions

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]

FORCE = "/rig/impact/force"


class Arrivals:
    """The force blocks' stamps and first indices, from a raw subscription taken by hand."""

    def __init__(self, context) -> None:
        self.node = rclpy.create_node("timing_probe", context=context)
        self.sub = self.node.create_subscription(SampleBlock, FORCE, lambda _: None,
                                                 QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE),
                                                 raw=True)
        self.blocks: list[tuple[int, int, float]] = []   # (stamp ns, first_index, sample_rate)

    def _take(self, data: bytes, info: dict) -> None:
        block = read_block(data, arrays=1)
        stamp = block.header.stamp.sec * 1_000_000_000 + block.header.stamp.nanosec
        self.blocks.append((stamp, block.first_index, block.sample_rate))

    def take(self, count: int, *, drop_waiting: bool = True, timeout: float = 30.0) -> list[tuple[int, int, float]]:
        """The next ``count`` blocks (after dropping what waited), waiting for them at most ``timeout`` s."""
        if drop_waiting:
            PolledSubscriptions.take(self.sub, lambda d, i: None)
        self.blocks.clear()
        deadline = time.monotonic() + timeout
        while len(self.blocks) < count and time.monotonic() < deadline:
            PolledSubscriptions.take(self.sub, self._take)
            time.sleep(0.005)
        assert len(self.blocks) >= count, f"{len(self.blocks)} of {count} blocks in {timeout:g} s"
        return self.blocks[:count]


def on_grid(blocks: list[tuple[int, int, float]], t0_ns: int) -> None:
    """Every stamp is ``t0 + first_index / rate`` to the nanosecond, and the indices follow without a hole."""
    for stamp, first, rate in blocks:
        assert stamp == t0_ns + round(first * 1e9 / rate), (stamp, t0_ns, first)
    firsts = [first for _, first, _ in blocks]
    assert firsts == sorted(firsts) and len(set(firsts)) == len(firsts)


def test_every_start_is_a_named_run_on_the_exact_grid_of_its_stamps(ros_processes, ros_executor):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_srvs.srv import Trigger

    node = rclpy.create_node("timing_client", context=ros_executor.context)
    ros_executor.add_node(node)
    sessions: list[RigSession] = []
    node.create_subscription(RigSession, "/rig/session", sessions.append, QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    diagnostics: list[dict] = []

    def on_diag(msg) -> None:
        for status in msg.status:
            if status.name.endswith("rimd_simulator: pacing"):
                diagnostics.append({kv.key: kv.value for kv in status.values})

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    arrivals = Arrivals(ros_executor.context)

    # 1. Started unpaused (the rig's default), as `rimd node simulator` or `rimd rig --no-record` start it.
    rig = ros_processes.start_node("rimd_simulator")
    rig.wait_for_output(r"rig ready", timeout=60)
    assert spin_until(ros_executor, lambda: sessions, timeout=10), "no /rig/session"
    first = sessions[-1]
    assert (first.reason, first.time_base) == ("start", "wall_clock")
    t0 = first.start_stamp.sec * 1_000_000_000 + first.start_stamp.nanosec
    on_grid(arrivals.take(100), t0)

    # 2. After a reset: a new run of the same count (the stamps stay on its grid).
    trigger = node.create_client(Trigger, "/rig/reset")
    assert call_service(ros_executor, node, trigger, Trigger.Request(), timeout=10).success
    assert spin_until(ros_executor, lambda: len(sessions) >= 2, timeout=10), "no new session after reset"
    reset = sessions[-1]
    assert reset.reason == "reset" and reset.run_id != first.run_id
    on_grid(arrivals.take(100), t0)
    assert rig.stop() == 0, rig.tail()

    # 3. Started paused, then resumed (as `rimd rig` does with a recorder): sample 0 at the resume.
    sessions.clear()
    PolledSubscriptions.take(arrivals.sub, lambda d, i: None)   # the stopped rig's blocks still in the reader's cache
    rig = ros_processes.start_node("rimd_simulator", "--ros-args", "-p", "start_paused:=true")
    rig.wait_for_output(r"rig ready", timeout=60)
    resume = node.create_client(Trigger, "/rig/resume")
    # Matched on the simulator's side: its /diagnostics count the subscriptions its publisher has matched (the
    # probe's own count can still include the stopped rig's writer, and the new rig's view of the graph may lag).
    diagnostics.clear()
    assert spin_until(ros_executor, lambda: diagnostics and int(diagnostics[-1].get(f"{FORCE} subscribers", 0)) >= 1,
                      timeout=30), diagnostics[-1:]
    assert call_service(ros_executor, node, resume, Trigger.Request(), timeout=10).success
    blocks = arrivals.take(100, drop_waiting=False)
    assert blocks[0][1] == 0, "the restarted rig's first block heard is not sample 0"
    assert spin_until(ros_executor, lambda: sessions, timeout=10)
    again = sessions[-1]
    assert again.reason == "start" and again.run_id not in (first.run_id, reset.run_id)
    on_grid(blocks, again.start_stamp.sec * 1_000_000_000 + again.start_stamp.nanosec)
    assert rig.stop() == 0, rig.tail()
    arrivals.node.destroy_node()
