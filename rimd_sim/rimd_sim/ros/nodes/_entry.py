"""Entry points of the node executables (``rimd_simulator``, ``rimd_recorder``, ``rimd_replay``, ``rimd_rerun``).

Importing this module installs the stop handlers (SIGINT, SIGTERM) at once, before the node modules and
their heavy imports are loaded: a node stopped while it is still starting exits 0 like one stopped while it
runs. Each function then imports its node module and runs its ``main``.

``python -m rimd_sim.ros.nodes._entry NAME [--ros-args ...]`` does the same for a child process (``rimd rig``,
``rimd experiment``).
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path

from rimd_sim.ros.nodes._stop import install_stop_handlers

install_stop_handlers()

#: The Fast DDS profile of the nodes (a 0.2 s heartbeat of reliable writers; see the file). A profile the
#: user chose through the variable wins.
FASTDDS_PROFILES = Path(__file__).with_name("fastdds_profiles.xml")
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(FASTDDS_PROFILES))

__all__ = ["recorder", "replay", "rerun", "simulator"]


def _main(module: str) -> int:
    return int(importlib.import_module(module).main() or 0)


def simulator() -> int:
    """``rimd_simulator``."""
    return _main("rimd_sim.ros.nodes.simulator")


def recorder() -> int:
    """``rimd_recorder``."""
    return _main("rimd_sim.ros.nodes.recorder")


def replay() -> int:
    """``rimd_replay``."""
    return _main("rimd_sim.ros.nodes.replay")


def rerun() -> int:
    """``rimd_rerun``."""
    return _main("rimd_sim.ros.nodes.rerun_bridge")


ENTRIES = {"simulator": simulator, "recorder": recorder, "replay": replay, "rerun": rerun}

if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in ENTRIES:
        print(f"usage: python -m rimd_sim.ros.nodes._entry {{{','.join(ENTRIES)}}} [--ros-args ...]", file=sys.stderr)
        sys.exit(2)
    sys.exit(ENTRIES[sys.argv.pop(1)]())
