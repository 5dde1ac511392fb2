"""Timing of the replay node over real DDS: how closely it keeps a recording's timing, at 1x and 2x.

What it runs: a recording of --seconds of the rig written from the core (``tests/harness/rig_mcap.py``: the four
channels, truth, motor states and impacts at their exact stamps), replayed by the ``rimd_replay`` node in its
own process on a ROS domain of its own, to a subscriber in this process that notes when each message arrives.

Printed, per rate: the timing error (arrival minus due time, the due time being the recorded log time over
the rate, centred on the median offset) median and p99 in ms (target: median <= 1 ms), and the ratio of the
replay's duration to the recording's (target: 1/rate within 3 %); every message checked to arrive.
The targets are figures of a benchmark, not assertions: on a shared machine a test can hold only coarse bounds
(tests/ros/test_replay_node.py keeps those).

Run (after ``source env.sh``, from the repository root; the machine otherwise idle):
    python benchmarks/bench_replay.py [--seconds 6]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

TOPICS = {"/rig/cart/displacement": "SampleBlock", "/rig/rimd/displacement": "SampleBlock",
          "/rig/rimd/acceleration": "SampleBlock", "/rig/impact/force": "SampleBlock", "/rig/truth": "RigState",
          "/rig/motor/state": "MotorState", "/rig/impact/events": "ImpactEvent"}


def replay(path: Path, rate: float, env: dict[str, str]) -> None:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    import rimd_msgs.msg
    from rimd_sim.io.reader import open_recording

    recorded: dict[str, list[int]] = {}
    for msg in open_recording(path).messages():
        recorded.setdefault(msg.topic, []).append(msg.log_time)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("bench_replay_probe", context=context)
    arrivals: dict[str, list[float]] = {t: [] for t in TOPICS}
    qos = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
    for topic, kind in TOPICS.items():
        node.create_subscription(getattr(rimd_msgs.msg, kind), topic,
                                 lambda _m, t=topic: arrivals[t].append(time.monotonic()), qos, raw=True)
    exe = shutil.which("rimd_replay")
    if exe is None:
        raise SystemExit("rimd_replay not on PATH: run `source env.sh` first")
    proc = subprocess.Popen([exe, "--ros-args", "-p", f"file:={path}", "-p", f"rate:={rate}",
                             "-p", "wait_for_subscribers:=1"], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    expected = {t: len(recorded.get(t, [])) for t in TOPICS}
    deadline = time.monotonic() + 120
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    while time.monotonic() < deadline and any(len(arrivals[t]) < n for t, n in expected.items()):
        executor.spin_once(timeout_sec=0.05)
    proc.wait(30)
    executor.shutdown()
    node.destroy_node()
    context.try_shutdown()
    got = {t: len(a) for t, a in arrivals.items()}
    pairs = [(log / 1e9 / rate, arrived) for t in TOPICS for log, arrived in zip(recorded.get(t, []), arrivals[t],
                                                                                  strict=False)]
    offsets = [arrived - due for due, arrived in pairs]
    centre = statistics.median(offsets)
    errors = sorted(abs(o - centre) for o in offsets)
    truth_log, truth_at = recorded["/rig/truth"], arrivals["/rig/truth"]
    ratio = (truth_at[-1] - truth_at[0]) / ((truth_log[-1] - truth_log[0]) / 1e9)
    median, p99 = errors[len(errors) // 2], errors[int(0.99 * (len(errors) - 1))]
    print(f"rate {rate:g}: {len(pairs)} messages ({'all arrived' if got == expected else f'MISSING: {got}'}); "
          f"timing error median {median * 1e3:.3f} ms, p99 {p99 * 1e3:.3f} ms (target median <= 1 ms: "
          f"{'met' if median <= 1e-3 else 'NOT met'}); duration ratio {ratio:.4f} (target {1 / rate:.3f} "
          f"within 3 %: {'met' if abs(ratio * rate - 1) <= 0.03 else 'NOT met'})")
    if rate == 1.0:   # the headline figures for report.py
        from _figures import record

        record("recording", "replay at 1×: timing error, median", median * 1e3, "ms", "<= 1")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=6.0, help="length of the recording (s)")
    args = parser.parse_args()
    from harness.domains import lease_domain_id
    from harness.rig_mcap import write_rig_mcap

    print(f"load average {os.getloadavg()[0]:.2f} (a figure counts on an idle machine)")
    with tempfile.TemporaryDirectory() as tmp, lease_domain_id() as lease:
        path = Path(tmp) / "rec.mcap"
        write_rig_mcap(path, seconds=args.seconds)
        env = {**os.environ, "ROS_DOMAIN_ID": str(lease.domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
               "ROS_LOG_DIR": str(Path(tmp) / "log")}
        for rate in (1.0, 2.0):
            replay(path, rate, env)


if __name__ == "__main__":
    main()
