"""Benchmark of the recorder and the replay over real DDS (docs/recording.md).

Prints, in one run:
  * recorder throughput with zero loss: the simulator at real_time_factor 0 (as fast as it can) for
    --seconds of wall time, recorded with the default recorder settings; messages/s, MB/s (serialized bytes)
    and the factor over the default real-time data rate (target >= 20x), with the loss the recorder reports
    and an independent check that every block from sample 0 is in the file (first_index contiguous);
    recorder CPU (median of 1 s samples);
  * replay CPU at 1x (median of 1 s samples) of a real-time recording of --replay-seconds.

Run: .venv/bin/python benchmarks/bench_recorder.py [--seconds 30] [--replay-seconds 15]   (after `source env.sh`)
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import psutil
import rclpy
from _nodes import start, stop  # benchmarks/_nodes.py
from rclpy.node import Node
from std_srvs.srv import Trigger

from rimd_sim.io.cdr import block_span
from rimd_sim.io.reader import open_recording

BLOCK_TOPICS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force",
                "/rig/truth")


def call(node: Node, service: str) -> None:
    client = node.create_client(Trigger, service)
    if not client.wait_for_service(timeout_sec=20):
        raise SystemExit(f"{service} did not appear")
    future = client.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(node, future, timeout_sec=10)


def wait_subscribed(node: Node, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(node.count_subscribers(t) >= 1 for t in BLOCK_TOPICS):
            return
        time.sleep(0.05)
    raise SystemExit("the recorder did not subscribe to the rig topics")


def cpu_samples(proc: subprocess.Popen, seconds: float) -> list[float]:
    ps = psutil.Process(proc.pid)
    ps.cpu_percent(None)
    samples = []
    end = time.monotonic() + seconds
    while time.monotonic() < end and proc.poll() is None:
        time.sleep(1.0)
        samples.append(ps.cpu_percent(None))
    return samples


def record(node: Node, out: Path, seconds: float, rtf: float, log: Path) -> tuple[float, list[float]]:
    recorder = start("rimd_recorder", "-p", f"output_dir:={out}", "-p", "topics:=['/rig/.*']", log=log)
    simulator = start("rimd_simulator", "-p", "start_paused:=true", "-p", f"real_time_factor:={rtf}",
                      "-p", "motor.initial_setpoint:=3.75")
    try:
        wait_subscribed(node)
        time.sleep(0.5)
        call(node, "/rig/resume")
        t0 = time.monotonic()
        cpu = cpu_samples(recorder, seconds)
        call(node, "/rig/pause")
        wall = time.monotonic() - t0
    finally:
        stop(simulator)
        stop(recorder)
    return wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--replay-seconds", type=float, default=15.0)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("bench_recorder")
    tmp = Path(tempfile.mkdtemp(prefix="bench_recorder_"))
    try:
        # ---- throughput at real_time_factor 0 --------------------------------------------------------------
        out = tmp / "fast"
        wall, cpu = record(node, out, args.seconds, 0.0, tmp / "fast.log")
        log = (tmp / "fast.log").read_text()
        recording = open_recording(out)
        messages, payload = 0, 0
        blocks: dict[str, list[tuple[int, int]]] = {}
        for msg in recording.messages():
            messages += 1
            payload += len(msg.data)
            if msg.topic in BLOCK_TOPICS:
                blocks.setdefault(msg.topic, []).append(block_span(msg.data))
        complete = all(spans[0][0] == 0 and all(b[0] == a[0] + a[1] for a, b in zip(spans, spans[1:], strict=False))
                       for spans in blocks.values())
        truth = blocks["/rig/truth"]
        sim_seconds = (truth[-1][0] + truth[-1][1]) / 1000.0   # truth at 1 kHz
        factor = sim_seconds / wall
        size = sum(p.stat().st_size for p in recording.files)
        print(f"recorder at real_time_factor 0, {wall:.1f} s wall, {sim_seconds:.1f} s simulated:")
        print(f"  {messages} messages, {payload / 1e6:.1f} MB serialized, {size / 1e6:.1f} MB on disk (zstd)")
        print(f"  throughput: {messages / wall:,.0f} messages/s, {payload / wall / 1e6:.2f} MB/s")
        print(f"  = {factor:.1f}x the default real-time data rate "
              f"({messages / sim_seconds:.0f} messages/s, {payload / sim_seconds / 1e6:.3f} MB/s at 1x); target >= 20x")
        print(f"  every block from sample 0 present (independent check): {complete}; "
              f"recorder reports loss: {'LOSS' in log}")
        print(f"  recorder CPU: median {statistics.median(cpu):.0f} % of one core")
        import _figures  # the headline figures for report.py (its record is not this file's record)

        lost = "" if complete and "LOSS" not in log else ", WITH LOSS"
        _figures.record("recording", f"rig speed the recorder takes{lost}", factor, "×",
                        ">= 20" if not lost else None)

        # ---- replay CPU at 1x ------------------------------------------------------------------------------
        out = tmp / "real_time"
        record(node, out, args.replay_seconds, 1.0, tmp / "rt.log")
        replay = start("rimd_replay", "-p", f"file:={out}", log=tmp / "replay.log")
        time.sleep(1.0)
        cpu = cpu_samples(replay, args.replay_seconds - 2.0)
        stop(replay)
        print(f"replay at 1x of {args.replay_seconds:.0f} s of the rig: CPU median {statistics.median(cpu):.1f} % "
              f"of one core (samples {', '.join(f'{c:.0f}' for c in cpu)})")
    finally:
        node.destroy_node()
        rclpy.shutdown()
        if os.environ.get("BENCH_KEEP") is None:
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            print(f"kept {tmp}")


if __name__ == "__main__":
    main()
