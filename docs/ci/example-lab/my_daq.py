"""A lab's DAQ software in miniature: acquires the rig's force channel, counts the samples and the holes.

Run against a rig (``python my_daq.py --until 2 --json report.json``); it reports its progress, so a rig in
lockstep waits for it and sends it everything.
"""

import argparse
import json
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from rimd_msgs.msg import SampleBlock
from rimd_sim.ros.clients.progress import ProgressReporter


def main() -> None:
    """Acquire until ``--until`` seconds of the channel, then write what was got."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--until", type=float, required=True)
    parser.add_argument("--json", required=True)
    args = parser.parse_args()
    rclpy.init()
    node = Node("my_daq")
    got = {"blocks": 0, "samples": 0, "holes": 0, "next_index": None, "reached_s": 0.0}

    def on_block(msg: SampleBlock) -> None:
        if got["next_index"] is not None and msg.first_index != got["next_index"]:
            got["holes"] += 1
        got["next_index"] = msg.first_index + len(msg.samples)
        got["blocks"] += 1
        got["samples"] += len(msg.samples)
        got["reached_s"] = got["next_index"] / msg.sample_rate
        progress.done(msg.header.stamp, sub)

    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    sub = node.create_subscription(SampleBlock, "/rig/impact/force", on_block, qos)
    progress = ProgressReporter(node, "my_daq", subscriptions=[sub])
    deadline = time.monotonic() + 120
    while got["reached_s"] < args.until and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    progress.leave()
    with open(args.json, "w") as report:
        json.dump(got, report)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
