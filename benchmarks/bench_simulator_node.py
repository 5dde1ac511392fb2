"""Benchmark of the simulator node over real DDS (docs/rig.md).

Prints, in one run:
  * at real time with default rates: CPU of the simulator process (median of 1 s samples over --seconds,
    target <= 15 % of one core) and block lateness p50/p99 from its /diagnostics (target p99 <= 5 ms);
  * at real_time_factor 0: the achieved factor end to end, measured by a subscriber from /clock over wall
    time while it receives every impact-force block (target >= 50x).

Run: .venv/bin/python benchmarks/bench_simulator_node.py [--seconds 30]   (after `source env.sh`)
"""

from __future__ import annotations

import argparse
import os
import subprocess
import time

import _nodes as nodes  # benchmarks/_nodes.py: start and stop a node
import rclpy
from _nodes import stop
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from rimd_msgs.msg import SampleBlock


def start(*ros_args: str) -> subprocess.Popen:
    """The simulator node (the fault bench starts it this way too)."""
    return nodes.start("rimd_simulator", *ros_args)


def real_time(node: Node, seconds: float) -> None:
    proc = start()
    diag: dict[str, str] = {}
    node.create_subscription(DiagnosticArray, "/diagnostics",
                             lambda m: diag.update({kv.key: kv.value for kv in m.status[0].values}), 10)
    try:
        time.sleep(3.0)  # start-up (JIT cache load, discovery)
        cpu = nodes.cpu_median(proc, seconds, lambda: rclpy.spin_once(node, timeout_sec=0.05))
        print(f"real time, default rates: simulator CPU median {cpu:.1f} % of one core "
              f"(target <= 15 %), lateness p50 {diag.get('lateness_p50_ms')} ms, "
              f"p99 {diag.get('lateness_p99_ms')} ms "
              f"(target <= 5 ms), overruns {diag.get('overruns')}, "
              f"achieved factor {diag.get('real_time_factor_achieved')}")
    finally:
        stop(proc)


def fast(node: Node, seconds: float) -> None:
    proc = start("-p", "real_time_factor:=0.0")
    clock: list[tuple[float, float]] = []
    blocks = [0]
    node.create_subscription(Clock, "/clock",
                             lambda m: clock.append((time.monotonic(), m.clock.sec + m.clock.nanosec * 1e-9)), 100)
    node.create_subscription(SampleBlock, "/rig/impact/force", lambda m: blocks.__setitem__(0, blocks[0] + 1),
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    try:
        end = time.monotonic() + 3.0 + seconds
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
        window = [c for c in clock if c[0] >= clock[0][0] + 3.0]
        factor = (window[-1][1] - window[0][1]) / (window[-1][0] - window[0][0])
        print(f"real_time_factor 0: {factor:.1f}x real time end to end through DDS (target >= 50x), "
              f"{blocks[0]} force blocks received")
    finally:
        stop(proc)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    args = parser.parse_args()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init()
    node = Node("bench_probe")
    try:
        real_time(node, args.seconds)
        fast(node, min(args.seconds, 10.0))
    finally:
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
