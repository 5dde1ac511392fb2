"""``rimd info``: print the version and facts about the environment (no ROS node is started)."""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import json
import os
import platform
import sys

from rimd_sim import __version__
from rimd_sim.settings import paths

ROS_ENVIRONMENT_VARIABLES = (
    "ROS_DOMAIN_ID",
    "ROS_AUTOMATIC_DISCOVERY_RANGE",
    "ROS_STATIC_PEERS",
    "RMW_IMPLEMENTATION",
    "AMENT_PREFIX_PATH",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd info``."""
    parser.add_argument("--json", action="store_true", help="print the facts as one JSON object")


def _distribution_version(name: str) -> str | None:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def _module_location(name: str) -> str | None:
    spec = importlib.util.find_spec(name)
    if spec is None:
        return None
    if spec.origin is not None:
        return spec.origin
    return ", ".join(spec.submodule_search_locations or ()) or None


def collect_facts() -> dict[str, object]:
    """Collect the facts ``rimd info`` prints, without importing rclpy."""
    try:
        config = str(paths.config_dir())
    except FileNotFoundError as error:
        config = f"(not found: {error})"
    root = paths.source_root()
    share = paths.installed_share_dir()
    return {
        "rimd_sim_version": __version__,
        "rimd_sim_location": _module_location("rimd_sim"),
        "source_root": str(root) if root is not None else None,
        "config_dir": config,
        "share_dir": str(share) if share is not None else None,
        "python": f"{platform.python_version()} ({sys.executable})",
        "prefix": sys.prefix,
        "ros_jazzy_rclpy": _distribution_version("ros-jazzy-rclpy"),
        "rimd_msgs_location": _module_location("rimd_msgs"),
        "ros_jazzy_rimd_msgs": _distribution_version("ros-jazzy-rimd-msgs"),
        "environment": {name: os.environ.get(name) for name in ROS_ENVIRONMENT_VARIABLES},
    }


def main(args: argparse.Namespace) -> int:
    """Print the facts, as ``key: value`` lines or as JSON."""
    facts = collect_facts()
    if args.json:
        print(json.dumps(facts, indent=2))
        return 0
    for key, value in facts.items():
        if isinstance(value, dict):
            for sub_key, sub_value in value.items():
                print(f"{sub_key}: {sub_value if sub_value is not None else '(unset)'}")
        else:
            print(f"{key}: {value if value is not None else '(not found)'}")
    return 0
