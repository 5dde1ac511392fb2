"""Benchmark of the Rerun bridge (docs/rerun.md).

Prints, in one run:
  * live, at real time with default rates: the simulator node and the ``rimd_rerun`` node over DDS, the bridge
    logging to ``--sink`` (default ``save``, an .rrd in a temporary directory); CPU of the bridge process
    (median of 1 s samples over ``--seconds``, target <= 20 % of one core) and its lag behind the data from
    its status lines (wall time at logging minus the stamp of the block's last sample; "keeps up" = the lag
    does not grow from the first to the last status window, no dropped block);
  * offline: ``rimd rerun`` conversion speed (MCAP of the core's output -> .rrd) in samples/s.

The lag includes a constant offset of the simulator (its stamps start at the whole millisecond before its
start-up pass), so its growth, not its value, is the figure.

Run: python benchmarks/bench_rerun.py [--seconds 60] [--sink save|serve_web] [--batch 5]   (after `source env.sh`)
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

REPO = Path(__file__).resolve().parent.parent
STATUS = re.compile(r"status: (\d+) messages, (\d+) samples, (\d+) impacts, (\d+) Poincare points, (\d+) gaps; "
                    r"lag p50 ([\d.]+) ms, max ([\d.]+) ms, slowest message ([\d.]+) ms")


def start(exe_name: str, *ros_args: str, log: Path) -> subprocess.Popen:
    exe = shutil.which(exe_name)
    if exe is None:
        raise SystemExit(f"{exe_name} not on PATH: run `source env.sh` first")
    return subprocess.Popen([exe, "--ros-args", *ros_args], stdout=open(log, "wb"), stderr=subprocess.STDOUT,
                            start_new_session=True)


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is not None:
        return
    os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(20)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)


def wait_for(log: Path, pattern: str, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if re.search(pattern, log.read_text(errors="replace")):
            return
        time.sleep(0.1)
    raise SystemExit(f"no /{pattern}/ in {log} within {timeout} s:\n{log.read_text(errors='replace')[-2000:]}")


def live(seconds: float, sink: str, tmp: Path, batch: int) -> None:
    sim_log, bridge_log = tmp / "sim.log", tmp / "bridge.log"
    sim = start("rimd_simulator", "-p", "motor.initial_frequency:=3.75", log=sim_log)
    bridge = None
    try:
        wait_for(sim_log, r"rig ready", 60)
        bridge = start("rimd_rerun", "-p", f"sink:={sink}", "-p", f"save_path:={tmp / 'live.rrd'}",
                       "-p", "status_period:=5.0", "-p", f"batch_blocks:={batch}", log=bridge_log)
        wait_for(bridge_log, r"rerun bridge ready", 60)
        time.sleep(2.0)
        ps = psutil.Process(bridge.pid)
        ps.cpu_percent(None)
        cpu = []
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            time.sleep(1.0)
            cpu.append(ps.cpu_percent(None))
    finally:
        if bridge is not None:
            stop(bridge)
        stop(sim)
    status = [tuple(float(x) for x in m.groups()) for m in STATUS.finditer(bridge_log.read_text(errors="replace"))]
    if len(status) < 3:
        raise SystemExit(f"too few status lines:\n{bridge_log.read_text(errors='replace')[-2000:]}")
    p50 = [s[5] for s in status[1:]]  # the first window includes start-up
    samples, gaps = status[-1][1], status[-1][4]
    size = (tmp / "live.rrd").stat().st_size if (tmp / "live.rrd").exists() else 0
    print(f"live, real time, default rates, sink {sink}, batch_blocks {batch}, {seconds:.0f} s: bridge CPU median "
          f"{statistics.median(cpu):.1f} % of one core (p90 {sorted(cpu)[int(0.9 * len(cpu))]:.1f} %; target <= 20 %); "
          f"lag p50 per 5 s window first {p50[0]:.1f} ms, last {p50[-1]:.1f} ms, max of windows "
          f"{max(s[6] for s in status[1:]):.1f} ms (growth {p50[-1] - p50[0]:+.1f} ms); {samples:.0f} samples, "
          f"{status[-1][2]:.0f} impacts, {gaps:.0f} dropped blocks"
          + (f"; .rrd {size / 1e6:.1f} MB ({size / 1e6 / (seconds + 2):.2f} MB/s)" if size else ""))
    from _figures import record  # the headline figures for report.py

    record("rerun", f"bridge node at real time, sink `{sink}`", statistics.median(cpu), "%", "<= 20")
    if gaps or max(s[6] for s in status[1:]) > 1000:
        print("  status lines (a stall or dropped blocks: see the lag and slowest message per window):")
        for m in STATUS.finditer(bridge_log.read_text(errors="replace")):
            print("   ", m.group(0))


def offline(seconds: float, tmp: Path) -> None:
    sys.path.insert(0, str(REPO / "tests"))
    from harness.rig_mcap import write_rig_mcap
    from rimd_sim.cli.verbs.rerun import convert
    from rimd_sim.viz.sinks import SinkSpec

    rec = write_rig_mcap(tmp / "rec.mcap", seconds=seconds)
    stats, _info, wall = convert(rec.path, SinkSpec("save", path=str(tmp / "offline.rrd")))
    samples = sum(stats.samples.values())
    print(f"offline: {seconds:.0f} s of rig data ({rec.path.stat().st_size / 1e6:.1f} MB MCAP, {samples} samples, "
          f"{stats.impacts} impacts) -> .rrd in {wall:.2f} s: {samples / wall:,.0f} samples/s "
          f"({seconds / wall:.1f}x real time)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="live measurement, s (default 60)")
    parser.add_argument("--sink", default="save", choices=("save", "serve_web"))
    parser.add_argument("--batch", type=int, default=10, help="batch_blocks of the bridge (default 10, as configured)")
    parser.add_argument("--offline-seconds", type=float, default=20.0, help="simulated s converted offline")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_rerun_") as tmp:
        offline(args.offline_seconds, Path(tmp))
        live(args.seconds, args.sink, Path(tmp), args.batch)


if __name__ == "__main__":
    main()
