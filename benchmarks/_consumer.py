"""An external consumer of the rig for the rig benchmarks: another process that takes the block topics and counts them.

It subscribes (reliable, raw bytes: it counts, it does not deserialise) to the rig's five block topics (the
truth a RigState, the others SampleBlock), checks that
each one's blocks are contiguous (``first_index`` = the previous one's + its sample count), and on SIGINT or SIGTERM
writes what it saw as JSON to ``--out``. With ``--lockstep NAME`` it is also a lockstep consumer of that name, the
way docs/rig.md ("Pacing: lockstep") tells a Python node to be one: a
:class:`rimd_sim.ros.clients.progress.ProgressReporter` and ``done(stamp, subscription)`` after each message (it
does nothing else with them: what it costs the rig is the transport and the reporting). ``--batched``: instead of a
callback per message, a timer every ``--period`` s takes every message waiting and reports once per topic
(:class:`rimd_sim.ros.nodes.polling.PolledSubscriptions`, as the recorder and the bridge take theirs).

Run by ``bench_rig.py`` and ``bench_lockstep.py`` (not alone), in the rig's ROS domain::

    python benchmarks/_consumer.py --out counts.json [--lockstep bench_consumer] [--batched] [--period 0.005]

It prints ``matched`` once each subscription has matched the simulator's publisher.
"""

from __future__ import annotations

import argparse
import json
import signal
import struct
import sys
from pathlib import Path

TOPICS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force",
          "/rig/truth")
NAME = "bench_consumer"
_TIME = {True: struct.Struct("<iI"), False: struct.Struct(">iI")}


class Count:
    """What one topic brought: messages, samples, the first index, and the holes between blocks."""

    def __init__(self) -> None:
        self.messages = self.samples = self.holes = 0
        self.first: int | None = None
        self.next: int | None = None

    def add(self, first: int, count: int) -> None:
        if self.first is None:
            self.first = first
        elif first != self.next:
            self.holes += 1
        self.messages += 1
        self.samples += count
        self.next = first + count

    def as_dict(self) -> dict:
        return {"messages": self.messages, "samples": self.samples, "first_index": self.first, "holes": self.holes}


def stamp_ns(data: bytes) -> int:
    """header.stamp of a serialized message (CDR: sec int32 and nanosec uint32 after the encapsulation), in ns."""
    sec, nsec = _TIME[bool(data[1] & 1)].unpack_from(data, 4)
    return sec * 1_000_000_000 + nsec


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="where the counts go (JSON), at the stop")
    parser.add_argument("--lockstep", metavar="NAME", default=None, help="report lockstep progress under NAME")
    parser.add_argument("--batched", action="store_true", help="take every waiting message from a timer")
    parser.add_argument("--period", type=float, default=0.005, help="s between takes with --batched")
    args = parser.parse_args()

    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions

    from rimd_msgs.msg import RigState, SampleBlock
    from rimd_sim.io.cdr import block_span
    from rimd_sim.ros.clients.progress import ProgressReporter
    from rimd_sim.ros.nodes.polling import PolledSubscriptions

    class Consumer(Node):
        """A node whose executor leaves its polled subscriptions alone (as PollingNode, without the rig node)."""

        polled: PolledSubscriptions | None = None

        @property
        def subscriptions(self) -> list:  # type: ignore[override]
            subs = super().subscriptions
            return list(subs) if self.polled is None else self.polled.visible(subs)

    class Batched(PolledSubscriptions):
        """Take every waiting message, then report once per topic (its last stamp)."""

        def poll(self) -> int:
            taken = super().poll()
            if reporter is not None:
                for topic, ns in last.items():
                    reporter.done(ns, topic=topic)
                last.clear()
            return taken

    stop = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.append(True))
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Consumer(args.lockstep or NAME)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    counts = {topic: Count() for topic in TOPICS}
    TYPES = {"/rig/truth": RigState}   # noqa: N806 - the others are SampleBlock
    subs: dict[str, object] = {}
    reporter: ProgressReporter | None = None
    last: dict[str, int] = {}

    def on_message(topic: str, data: bytes) -> None:
        counts[topic].add(*block_span(data))
        if reporter is None:
            return
        if args.batched:
            last[topic] = stamp_ns(data)
        else:
            reporter.done(stamp_ns(data), subs[topic])

    if args.batched:
        polled = node.polled = Batched(node, args.period)
        for topic in TOPICS:
            subs[topic] = polled.create(TYPES.get(topic, SampleBlock), topic, qos,
                                        lambda data, info, t=topic: on_message(t, data))
    else:
        for topic in TOPICS:
            subs[topic] = node.create_subscription(TYPES.get(topic, SampleBlock), topic,
                                                   lambda data, t=topic: on_message(t, data), qos, raw=True)
    if args.lockstep:
        reporter = ProgressReporter(node, args.lockstep, subscriptions=list(subs.values()))
    executor = EventsExecutor()
    executor.add_node(node)
    matched = False
    while not stop:
        executor.spin_once(timeout_sec=0.1)
        if not matched and all(s.get_publisher_count() > 0 for s in subs.values()):
            matched = True
            print("matched", flush=True)
    if args.batched:
        polled.poll()
    if reporter is not None:
        reporter.leave()
    result = {"topics": {t: c.as_dict() for t, c in counts.items()},
              "reports": reporter.reports if reporter is not None else 0, "batched": args.batched}
    args.out.write_text(json.dumps(result, indent=1))
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
