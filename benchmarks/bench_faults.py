"""Benchmark of the simulator with triggered capture at 1 MHz and 3 faults active (docs/faults.md).

Prints, in one run, for the default rig ("plain") and for the default channels + capture at 1 MHz + 3 faults
("faulted": offset on the force, clock drift of 80 ppm on the acceleration, 10 % block loss on the cart laser):
  * the core alone (no ROS): CPU seconds per second of simulation time;
  * at real time: CPU of the simulator process (median of 1 s samples over --seconds; target <= 10 % of one
    core for "faulted");
  * at real_time_factor 0: the factor achieved end to end, from /clock over wall time, with a subscriber
    receiving every force block (target >= 30x for "faulted").
The machine is shared: run it when it is quiet, or read the ratio of the two variants measured in one run.

Run: .venv/bin/python benchmarks/bench_faults.py [--seconds 20]   (after `source env.sh`)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from fractions import Fraction
from pathlib import Path

from _figures import record  # benchmarks/_figures.py: the headline figures for report.py
from _nodes import cpu_median  # benchmarks/_nodes.py
from bench_simulator_node import start, stop  # the node as the simulator bench runs it

FAULTS = ["channel=impact_force kind=offset start=0 duration=0 magnitude=0.5",
          "channel=rimd_acceleration kind=clock_drift start=0 duration=0 magnitude=80",
          "channel=cart_displacement kind=block_loss start=0 duration=0 magnitude=0.1"]
VARIANTS = {
    "plain": [],
    "faulted": ["-p", "capture.enabled:=true", "-p", "faults:=[" + ",".join(f"'{f}'" for f in FAULTS) + "]"],
}


def core(seconds: float) -> dict[str, float]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "rimd_sim"))
    from rimd_sim.instruments.faults import parse_fault_entry
    from rimd_sim.instruments.rig_simulator import RigSimulator
    from rimd_sim.settings.capture import CaptureConfig
    from rimd_sim.settings.config import SimConfig

    cfg = SimConfig().with_parameters({"motor.initial_frequency": 3.75})
    out = {}
    for name in VARIANTS:
        capture = CaptureConfig(enabled=name == "faulted")
        sim = RigSimulator(cfg, capture=capture)
        if name == "faulted":
            for i, f in enumerate(FAULTS):
                sim.inject_fault(**parse_fault_entry(f, f"faults[{i}]"))
        sim.advance_blocks([Fraction(k + 1, 100) for k in range(10)])   # compile / warm up
        t0 = time.process_time()
        n = int(seconds * 10)
        for i in range(1, n + 1):
            sim.advance_blocks([Fraction(10 * i + k + 1, 100) for k in range(10)])
        out[name] = (time.process_time() - t0) / (n / 10)
    return out


def real_time(node, args: list[str], seconds: float) -> float:
    import rclpy

    proc = start(*args)
    try:
        time.sleep(4.0)  # start-up (JIT cache load, discovery)
        return cpu_median(proc, seconds, lambda: rclpy.spin_once(node, timeout_sec=0.05))
    finally:
        stop(proc)


def fast(node, args: list[str], seconds: float) -> tuple[float, int]:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    from rimd_msgs.msg import SampleBlock

    proc = start("-p", "real_time_factor:=0.0", *args)
    clock: list[tuple[float, float]] = []
    blocks = [0]
    subs = [node.create_subscription(Clock, "/clock", lambda m: clock.append(
                (time.monotonic(), m.clock.sec + m.clock.nanosec * 1e-9)), 100),
            node.create_subscription(SampleBlock, "/rig/impact/force", lambda m: blocks.__setitem__(0, blocks[0] + 1),
                                     QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))]
    try:
        end = time.monotonic() + 4.0 + seconds
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
        window = [c for c in clock if c[0] >= clock[0][0] + 3.0]
        return (window[-1][1] - window[0][1]) / (window[-1][0] - window[0][0]), blocks[0]
    finally:
        stop(proc)
        for s in subs:
            node.destroy_subscription(s)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    args = parser.parse_args()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    load = os.getloadavg()
    print(f"load average at start: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    for name, cpu in core(args.seconds).items():
        print(f"core alone, {name}: {cpu * 1e3:.1f} ms CPU per s of simulation ({1 / cpu:.0f}x real time)")
    import rclpy
    from rclpy.node import Node

    rclpy.init()
    node = Node("bench_faults_probe")
    try:
        for name, extra in VARIANTS.items():
            cpu = real_time(node, extra, args.seconds)
            target = " (target <= 10 %)" if name == "faulted" else ""
            print(f"real time, {name}: simulator CPU median {cpu:.1f} % of one core{target}")
            if name == "faulted":
                record("rig", "simulator with capture and 3 faults", cpu, "%", "<= 10")
        for name, extra in VARIANTS.items():
            factor, n = fast(node, extra, min(args.seconds, 10.0))
            target = " (target >= 30x)" if name == "faulted" else ""
            print(f"real_time_factor 0, {name}: {factor:.1f}x real time end to end{target}, {n} force blocks received")
    finally:
        node.destroy_node()
        rclpy.shutdown()
    load = os.getloadavg()
    print(f"load average at end: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")


if __name__ == "__main__":
    main()
