"""CPU of the Rerun bridge with and without its Foxglove sink, in one run (docs/benchmarks.md, Foxglove sink).

What it runs, on a ROS domain of its own (the test suite's leases, ROS_AUTOMATIC_DISCOVERY_RANGE LOCALHOST):
the simulator at real time with the default config, and two bridges side by side, fed by the same rig over
the same seconds:

  * ``rerun only``: ``rimd_rerun`` with sink ``save`` (an .rrd in a temporary directory);
  * ``rerun + foxglove``: the same, plus ``foxglove.enabled`` (a free port), with a Foxglove WebSocket client
    (this process, ``tests/harness/foxglove_client.py``) subscribed to every channel the server advertises,
    so every message of the rig is sent to it.

After --warmup s, each bridge's CPU (utime + stime from /proc through psutil, over --seconds of wall time) in
% of one core; the difference is the Foxglove sink's cost. Goal: at most 5 points more than Rerun alone.
The machine's load average is printed with the figures: on a shared machine they are preliminary.

Run (after ``source env.sh``, from the repository root): python benchmarks/bench_foxglove.py [--seconds 60]
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import time
from pathlib import Path

import psutil
from _nodes import start, stop  # benchmarks/_nodes.py

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))
GOAL_POINTS = 5.0


def wait_for(log: Path, pattern: str, timeout: float) -> re.Match:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        match = re.search(pattern, log.read_text(errors="replace"))
        if match:
            return match
        time.sleep(0.2)
    raise SystemExit(f"{log.name}: '{pattern}' not seen within {timeout} s:\n{log.read_text(errors='replace')[-2000:]}")


def cpu_seconds(pid: int) -> float:
    times = psutil.Process(pid).cpu_times()
    return times.user + times.system + times.children_user + times.children_system


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="measured wall time (default 60)")
    parser.add_argument("--warmup", type=float, default=10.0, help="s after the rig runs before measuring")
    args = parser.parse_args()

    from harness.domains import lease_domain_id
    from harness.foxglove_client import FoxgloveClient

    with lease_domain_id() as lease, tempfile.TemporaryDirectory(prefix="bench_foxglove_") as tmp_name:
        tmp = Path(tmp_name)
        env = dict(os.environ, ROS_DOMAIN_ID=str(lease.domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                   ROS_LOG_DIR=str(tmp / "ros_log"))
        env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
        procs = []
        try:
            alone = start("rimd_rerun", "-r", "__node:=rimd_rerun_alone", "-p", "sink:=save",
                          "-p", f"save_path:={tmp / 'alone.rrd'}", log=tmp / "alone.log", env=env)
            both = start("rimd_rerun", "-r", "__node:=rimd_rerun_fox", "-p", "sink:=save",
                         "-p", f"save_path:={tmp / 'both.rrd'}", "-p", "foxglove.enabled:=true",
                         "-p", "foxglove.port:=0", log=tmp / "both.log", env=env)
            procs += [alone, both]
            wait_for(tmp / "alone.log", r"rerun bridge ready", 60)
            url = wait_for(tmp / "both.log", r"foxglove server ready: (ws://\S+)", 60).group(1)
            sim = start("rimd_simulator", "--params-file", str(REPO / "config" / "rimd.yaml"), log=tmp / "sim.log",
                        env=env)
            procs.append(sim)
            wait_for(tmp / "sim.log", r"rig ready", 120)
            with FoxgloveClient(url) as client:
                client.wait_for(lambda r: len(r.channels) >= 9, 30, "the rig's channels")
                subscriptions = [client.subscribe(c["id"]) for c in list(client.received.channels.values())]
                time.sleep(args.warmup)
                load = os.getloadavg()
                before = {p.pid: cpu_seconds(p.pid) for p in (alone, both)}
                received_before = sum(len(client.received.messages.get(s, ())) for s in subscriptions)
                t0 = time.monotonic()
                time.sleep(args.seconds)
                wall = time.monotonic() - t0
                after = {p.pid: cpu_seconds(p.pid) for p in (alone, both)}
                received = sum(len(client.received.messages.get(s, ())) for s in subscriptions) - received_before
                load_after = os.getloadavg()
        finally:
            for proc in reversed(procs):
                stop(proc)
        cpu = {name: 100.0 * (after[p.pid] - before[p.pid]) / wall for name, p in (("rerun only", alone),
                                                                                  ("rerun + foxglove", both))}
        extra = cpu["rerun + foxglove"] - cpu["rerun only"]
        print(f"bench_foxglove: {wall:.1f} s measured at real time, the rig's default config; load average "
              f"{load[0]:.2f} before, {load_after[0]:.2f} after (2 cores)")
        for name, value in cpu.items():
            print(f"  {name:18s} {value:5.1f} % of one core")
        print(f"  Foxglove client received {received} messages on {len(subscriptions)} channels "
              f"({received / wall:.0f}/s)")
        print(f"  Foxglove sink: {extra:+.1f} points (goal <= {GOAL_POINTS:g}): "
              f"{'met' if extra <= GOAL_POINTS else 'NOT met'}")
        from _figures import record  # the headline figures for report.py

        record("foxglove", "CPU the Foxglove sink adds to the bridge", extra, "points", f"<= {GOAL_POINTS:g}")


if __name__ == "__main__":
    main()
