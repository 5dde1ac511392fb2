"""How long a lockstep consumer that names its node but no topics holds the rig at its join, and the run's speed.

The product's rig in lockstep as ``rimd rig --lockstep --real-time-factor 0 --consumer pair_daq`` starts it
(composed: simulator, recorder, Rerun bridge with sink ``save``; a ROS domain of its own, a temporary directory),
and in this process a consumer written by hand, as one in another language would be (docs/rig.md, "A consumer in
another language"; no ``ProgressReporter``): it subscribes to ``/rig/cart/displacement`` and ``/rig/impact/force``
(reliable, raw bytes: it reads the stamp and the first index), creates its progress writer (reliable, transient
local, keep last 1) and publishes its join at once, naming its node and no topics, then reports per topic after each
block. Once the rig is up and held by this consumer alone (its /diagnostics: the recorder and the bridge joined,
this one not yet), the consumer is made; then, in wall time from the join:

* **hold at the join**: until the consumer has the first block of both topics (the rig's own figure, its logged
  wait for the consumer's readers, is printed too);
* **speed over the first 20 s of simulation** (from the join until both topics reached 20 s) against the speed
  from 20 s to 40 s: the ratio. A join that waited for readers the consumer does not have held the rig 15 s
  before its first block, a ratio of about 0.1 at this speed; the goal is within 20 % (0.8 to 1.2).

The machine's load average is printed with the figures. Run on an otherwise idle machine:
    python benchmarks/bench_lockstep_join.py [--runs 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import struct
import sys
import tempfile
import time
import uuid
from pathlib import Path

NAME = "pair_daq"
TOPICS = ("/rig/cart/displacement", "/rig/impact/force")
FIRST_S, AFTER_S = 20.0, 40.0
_HEAD = struct.Struct("<iI")   # header.stamp after the 4-byte encapsulation (little-endian CDR)


def run(base: Path) -> dict:
    import rclpy
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions

    from rimd_msgs.msg import ConsumerProgress, SampleBlock
    from rimd_sim.ros.bringup import Rig, plan_rig
    from rimd_sim.ros.testing import lease_domain_id, ros_environment
    from rimd_sim.runtime.progress import PACING_STATUS

    run_dir = Path(tempfile.mkdtemp(prefix="join_", dir=base))
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    with lease_domain_id() as lease:
        plan = plan_rig(None, output_dir=run_dir / "recording", lockstep=True, real_time_factor=0.0,
                        parameters={"rimd_rerun": {"sink": "save", "save_path": str(run_dir / "rig.rrd")}},
                        run_dir=run_dir, consumers=[NAME])
        env = ros_environment(lease.domain_id, run_dir / "ros_log")
        rig = Rig(plan, env=env, log_dir=run_dir / "logs")
        rig.start()
        context = Context()
        rclpy.init(context=context, domain_id=lease.domain_id, signal_handler_options=SignalHandlerOptions.NO)
        executor = EventsExecutor(context=context)
        try:
            # The rig is up and held by this consumer alone: its other consumers (the recorder, the bridge) have
            # joined, and it waits for this one (its /diagnostics say so).
            probe = rclpy.create_node("bench_join_probe", context=context)
            executor.add_node(probe)
            states: dict[str, str] = {}

            def on_diagnostics(msg: DiagnosticArray) -> None:
                for status in msg.status:
                    if status.name.endswith(PACING_STATUS):
                        states.update({kv.key[len("lockstep "):-len(" state")]: kv.value for kv in status.values
                                       if kv.key.startswith("lockstep ") and kv.key.endswith(" state")})

            probe.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
            deadline = time.monotonic() + 120
            while not (states.get(NAME) == "not joined" and len(states) > 1
                       and all(v == "joined" for k, v in states.items() if k != NAME)):
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the rig did not get ready: lockstep states {states}")
                executor.spin_once(timeout_sec=0.05)
            executor.remove_node(probe)
            probe.destroy_node()
            node = rclpy.create_node(NAME, context=context)
            executor.add_node(node)
            done = dict.fromkeys(TOPICS, 0)
            reached: dict[str, dict[float, float]] = {t: {} for t in TOPICS}   # topic -> {mark s: wall}
            first: dict[str, float] = {}
            data_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
            writer = None
            instance = uuid.uuid4().hex
            fqn = node.get_fully_qualified_name()

            def report(topics) -> None:
                writer.publish(ConsumerProgress(
                    consumer=NAME, instance=instance, node=fqn, topics=list(topics),
                    topics_done_through=[Time(sec=done[t] // 1_000_000_000, nanosec=done[t] % 1_000_000_000)
                                         for t in topics]))

            def on_block(topic: str, data: bytes) -> None:
                now = time.monotonic()
                sec, nanosec = _HEAD.unpack_from(data, 4)
                done[topic] = stamp = sec * 1_000_000_000 + nanosec
                first.setdefault(topic, now)
                for mark in (FIRST_S, AFTER_S):
                    if stamp >= mark * 1e9 and mark not in reached[topic]:
                        reached[topic][mark] = now
                report(TOPICS)

            for topic in TOPICS:
                node.create_subscription(SampleBlock, topic, lambda d, t=topic: on_block(t, d), data_qos, raw=True)
            writer = node.create_publisher(ConsumerProgress, "/rig/progress", QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL))
            joined = time.monotonic()
            report(())   # the join: once, at once, no topics named
            deadline = joined + 300
            while (not all(AFTER_S in reached[t] for t in TOPICS)) and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
        finally:
            executor.shutdown(timeout_sec=1.0)
            context.try_shutdown()
            status = rig.stop()
    log = "\n".join(f.read_text(errors="replace") for f in sorted((run_dir / "logs").glob("*.log")))
    waited = re.search(rf"lockstep: the readers of /{NAME} are matched after (\S+) s: (.*)", log)
    if not all(AFTER_S in reached[t] for t in TOPICS):
        raise RuntimeError(f"the consumer did not reach {AFTER_S:g} s (rig exit {status}); the rig's log ends:\n"
                           + log[-3000:])
    hold = max(first.values()) - joined
    t20 = max(reached[t][FIRST_S] for t in TOPICS)
    t40 = max(reached[t][AFTER_S] for t in TOPICS)
    speed_first, speed_after = FIRST_S / (t20 - joined), (AFTER_S - FIRST_S) / (t40 - t20)
    return {"hold_s": hold, "rig_match_wait_s": float(waited.group(1)) if waited else None,
            "rig_waited_for": waited.group(2).strip() if waited else None,
            "warned": "publishing although readers" in log, "speed_first_20s": speed_first,
            "speed_after": speed_after, "ratio": speed_first / speed_after, "load_average": load,
            "exit_status": status}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    results = []
    with tempfile.TemporaryDirectory(prefix="bench_lockstep_join_") as tmp:
        for i in range(args.runs):
            r = run(Path(tmp))
            results.append(r)
            wait = "not logged" if r["rig_match_wait_s"] is None else f"{r['rig_match_wait_s'] * 1e3:.1f} ms"
            print(f"run {i + 1}: hold at the join {r['hold_s']:.3f} s (the rig's match wait {wait}, for "
                  f"{r['rig_waited_for']}{'; WARNED about unmatched readers' if r['warned'] else ''}); speed over "
                  f"the first {FIRST_S:g} s {r['speed_first_20s']:.1f}x, after {r['speed_after']:.1f}x, ratio "
                  f"{r['ratio']:.2f} ({'within' if abs(r['ratio'] - 1) <= 0.2 else 'NOT within'} 20 %); load "
                  f"average at the start {r['load_average']}", flush=True)
    if results:
        from _figures import record  # the headline figures for report.py

        ratios = sorted(r["ratio"] for r in results)
        record("lockstep", "hold at a consumer's join, worst run", max(r["hold_s"] for r in results), "s", "<= 1")
        record("lockstep", "after the join: speed in 20 s / next 20 s", ratios[len(ratios) // 2], "", "0.8..1.2")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
