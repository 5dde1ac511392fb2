"""``rimd node NAME [--ros-args ...]``: run one node of the rig in the foreground (like ``ros2 run``)."""

from __future__ import annotations

import argparse
import importlib

#: Node name -> module with ``main(args)``.
NODES = {
    "simulator": "rimd_sim.ros.nodes.simulator",
    "recorder": "rimd_sim.ros.nodes.recorder",
    "replay": "rimd_sim.ros.nodes.replay",
    "rerun": "rimd_sim.ros.nodes.rerun_bridge",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``rimd node``."""
    parser.add_argument("name", choices=sorted(NODES), help="the node to run")
    parser.add_argument("ros_args", nargs=argparse.REMAINDER,
                        help="ROS arguments, e.g. --ros-args --params-file config/rimd.yaml -p gap:=0.001")


def main(args: argparse.Namespace) -> int:
    """Run the node until Ctrl-C; return its exit status."""
    module = importlib.import_module(NODES[args.name])
    return int(module.main(["rimd_" + args.name, *args.ros_args]) or 0)
