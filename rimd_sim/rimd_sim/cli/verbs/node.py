"""``rimd node NAME [--ros-args ...]``: run one node of the rig in the foreground (like ``ros2 run``).

The nodes are those of the registry, :mod:`rimd_sim.ros.nodes.registry`. The process becomes the node's: its
cycle collector is set as the node executables set theirs (:func:`rimd_sim.runtime.collector.for_node`).
"""

from __future__ import annotations

import argparse
import importlib
import os

from rimd_sim.ros.nodes.registry import NODES, by_name
from rimd_sim.runtime import collector, heap


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``rimd node``."""
    parser.add_argument("name", choices=sorted(n.name for n in NODES), help="the node to run")
    parser.epilog = "nodes: " + "; ".join(f"{n.name} ({n.executable}): {n.description}" for n in sorted(NODES))
    parser.add_argument("ros_args", nargs=argparse.REMAINDER,
                        help="ROS arguments, e.g. --ros-args --params-file config/rimd.yaml -p gap:=0.001")


def main(args: argparse.Namespace) -> int:
    """Run the node until Ctrl-C; return its exit status."""
    node = by_name(args.name)
    # What the node executables do first (rimd_sim.ros.nodes._entry, whose import also installs their stop handlers):
    # the nodes' Fast DDS profile unless the user set FASTRTPS_DEFAULT_PROFILES_FILE, so that the reliable writers
    # send a heartbeat every 0.2 s instead of Fast DDS's 3 s. A reader on another DDS implementation (Cyclone DDS)
    # delivers nothing from a writer until that writer's first heartbeat after their match and keeps only the first
    # 128 samples meanwhile: with 3 s, one that joins the rig at real time loses 0.7 s of the 2 kHz channels
    # (docs/rig.md, "Readers on other DDS implementations").
    from rimd_sim.ros.nodes._entry import FASTDDS_PROFILES

    os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(FASTDDS_PROFILES))
    module, _, function = node.target.partition(":")
    run = getattr(importlib.import_module(module), function)
    collector.for_node()   # the process is the node's from here on: a node's collector, as its executable sets
    heap.start()           # and its heap's free pages returned, as there
    return int(run([node.executable, *args.ros_args]) or 0)
