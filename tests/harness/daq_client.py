"""A DAQ-style client in its own process: subscribes to the rig's channels over DDS and saves what it got.

    python daq_client.py OUT.pkl --until 6.5 [--margin 0.3] [--mode store|impacts] [--topics T ...] [--timeout S]
                         [--resume]
                         [--lockstep NAME [--work-ms MS] [--jitter-ms MS] [--seed N]]

It prints ``daq ready`` once every topic has a publisher (then the test resumes the paused rig) and exits 0
after every channel has delivered samples up to ``--until`` s of simulation time (and ``--margin`` s more, for
what was still in flight), having written ``OUT.pkl``:

* ``store``: per topic, the serialized messages in arrival order with the simulation time the client had
  seen when each arrived (the largest end time of any channel block received so far; at
  ``real_time_factor 0`` topics arrive in bursts, so this is only a rough clock) and the wall-clock time
  of arrival (ns);
* ``impacts``: per channel only the indices of the samples whose magnitude reaches a threshold (the
  impacts), plus the holes in ``first_index`` (expected, received) and the count of stamps off the nominal
  grid ``first_index / sample_rate``: enough for a 600 s run without keeping 24 million samples.

With ``--lockstep NAME`` it is a lockstep consumer (``rimd_sim.ros.clients.progress.ProgressReporter``, one
line): it works ``--work-ms`` per block (plus a random ``--jitter-ms``, seeded), reports each block done, and also
writes ``OUT.pkl.timing`` (JSON): its busy time, the wall time from its first block to its last, and the simulation
time covered, so a test can tell whether the rig went as fast as this client allowed.
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time

CHANNELS = {
    "/rig/cart/displacement": 0.0,
    "/rig/rimd/displacement": 0.0,
    "/rig/rimd/acceleration": 200.0,   # impact thresholds (|x|) for the impacts mode
    "/rig/impact/force": 20.0,
}


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("out")
    parser.add_argument("--until", type=float, required=True)
    parser.add_argument("--mode", choices=("store", "impacts"), default="store")
    parser.add_argument("--topics", nargs="*", default=list(CHANNELS))
    parser.add_argument("--extra", nargs="*", default=["/rig/faults"], help="other topics stored (store mode)")
    parser.add_argument("--timeout", type=float, default=120.0)
    parser.add_argument("--margin", type=float, default=0.3,
                        help="simulation seconds received past --until before it stops (what was in flight)")
    parser.add_argument("--resume", action="store_true", help="call /rig/resume once subscribed (a paused rig)")
    parser.add_argument("--lockstep", default="", help="report progress under this name (a lockstep consumer)")
    parser.add_argument("--work-ms", type=float, default=0.0, help="time spent on each block (lockstep)")
    parser.add_argument("--jitter-ms", type=float, default=0.0, help="random extra time per block, up to this")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    import numpy as np
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message

    import rimd_msgs.msg as msgs

    rclpy.init()
    node = Node("daq_client")
    state = {"now": 0.0}
    stored: dict[str, list] = {t: [] for t in [*args.topics, *args.extra]}
    reached = {t: 0.0 for t in args.topics}
    summary = {t: {"above": [], "blocks": 0, "gaps": [], "bad_stamps": 0, "next": None} for t in args.topics}
    qos = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

    import json
    import random

    rng = random.Random(args.seed)
    timing = {"busy_s": 0.0, "first_wall": None, "last_wall": None, "blocks": 0}
    subs = {}

    def on_block(data, topic):
        started = time.perf_counter()
        if args.work_ms or args.jitter_ms:
            time.sleep((args.work_ms + rng.uniform(0.0, args.jitter_ms)) / 1e3)
        on_block_work(data, topic)
        if reporter is not None:
            msg = deserialize_message(data, msgs.SampleBlock)
            reporter.done(msg.header.stamp, subs[topic])
        now = time.perf_counter()
        timing["busy_s"] += now - started
        timing["first_wall"] = timing["first_wall"] or started
        timing["last_wall"] = now
        timing["blocks"] += 1

    def on_block_work(data, topic):
        msg = deserialize_message(data, msgs.SampleBlock)
        n = len(msg.samples)
        end = (msg.first_index + n) / msg.sample_rate
        state["now"] = max(state["now"], end)
        reached[topic] = max(reached[topic], end)
        if args.mode == "store":
            stored[topic].append((data, state["now"], time.time_ns()))
            return
        s = summary[topic]
        s["blocks"] += 1
        if s["next"] is not None and msg.first_index != s["next"]:
            s["gaps"].append((s["next"], msg.first_index))
        s["next"] = msg.first_index + n
        nominal = (msg.first_index * 1_000_000_000 * 2 + round(msg.sample_rate)) // (2 * round(msg.sample_rate))
        if msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec != nominal:
            s["bad_stamps"] += 1
        x = np.frombuffer(msg.samples, dtype=np.float64) if isinstance(msg.samples, (bytes, memoryview)) \
            else np.asarray(msg.samples)
        hits = np.flatnonzero(np.abs(x) >= CHANNELS[topic])
        if hits.size:
            s["above"].append(hits + msg.first_index)

    for topic in args.topics:
        subs[topic] = node.create_subscription(msgs.SampleBlock, topic, lambda d, t=topic: on_block(d, t), qos,
                                               raw=True)
    extra = []   # the volatile ones: a message published before they matched would never reach them
    for topic in args.extra:
        kind = {"/rig/faults": msgs.FaultEvent, "/rig/impact/events": msgs.ImpactEvent,
                "/rig/motor/state": msgs.MotorState}.get(topic, msgs.Capture)
        sub = node.create_subscription(
            kind, topic, lambda d, t=topic: stored[t].append((d, state["now"], time.time_ns())),
            latched if topic == "/rig/faults" else qos, raw=True)
        if topic != "/rig/faults":   # transient local: its history reaches a late reader (and a replay may have none)
            extra.append(sub)
    reporter = None
    if args.lockstep:   # it joins once every subscription matched: the rig's first messages reach each of them
        from rimd_sim.ros.clients.progress import ProgressReporter

        reporter = ProgressReporter(node, args.lockstep, subscriptions=[*subs.values(), *extra])

    deadline = time.monotonic() + args.timeout
    while time.monotonic() < deadline and not all(node.count_publishers(t) for t in [*args.topics, *args.extra]):
        rclpy.spin_once(node, timeout_sec=0.05)
    print("daq ready", flush=True)
    if args.resume:
        from std_srvs.srv import Trigger

        client = node.create_client(Trigger, "/rig/resume")
        while time.monotonic() < deadline and not client.service_is_ready():
            rclpy.spin_once(node, timeout_sec=0.05)
        future = client.call_async(Trigger.Request())
        while time.monotonic() < deadline and not future.done():
            rclpy.spin_once(node, timeout_sec=0.05)
        print(f"resume: {future.result().message if future.done() else 'no answer'}", flush=True)
    # Past --until by --margin of simulation time on every channel: what was still in flight at --until (delayed
    # blocks, the last fault events) has arrived by then. An observable condition, not a wall-clock wait.
    # A lockstep consumer also stays until it has joined (a rig running free after dropping it may have passed
    # --until before the reporter's first report).
    while time.monotonic() < deadline and (min(reached.values()) < args.until + args.margin
                                           or (reporter is not None and not reporter.joined)):
        rclpy.spin_once(node, timeout_sec=0.05)
    if min(reached.values()) < args.until + args.margin or (reporter is not None and not reporter.joined):
        print(f"daq timeout: reached {reached}"
              + ("" if reporter is None else f"; lockstep joined: {reporter.joined}, {reporter.reports} reports"),
              flush=True)
        return 1
    if args.mode == "impacts":
        for s in summary.values():
            s["above"] = np.concatenate(s["above"]) if s["above"] else np.zeros(0, dtype=np.int64)
        out = summary
    else:
        out = stored
    with open(args.out, "wb") as f:
        pickle.dump(out, f)
    if args.lockstep:
        timing["wall_s"] = (timing["last_wall"] or 0.0) - (timing["first_wall"] or 0.0)
        timing["simulated_s"] = min(reached.values())
        with open(args.out + ".timing", "w") as f:
            json.dump(timing, f)
    print(f"daq done: {sum(len(v) for v in stored.values())} messages", flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
