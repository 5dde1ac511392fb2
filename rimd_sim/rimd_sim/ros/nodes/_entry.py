"""Entry points of the node executables, one function per node of the registry (:mod:`rimd_sim.ros.nodes.registry`).

Importing this module installs the stop handlers (SIGINT, SIGTERM) at once, before the node modules and
their heavy imports are loaded: a node stopped while it is still starting exits 0 like one stopped while it
runs; and it sets the cycle collector of the imports to come as a command's (young collections 14 times rarer).
Each function (``simulator``, ``recorder``, ...: the registry's names) then imports its node's module, freezes what
the imports built and gives the node CPython's young threshold back (:func:`rimd_sim.runtime.collector.for_node`),
starts the return of the heap's free pages (:func:`rimd_sim.runtime.heap.start`) and runs its ``main``.

``python -m rimd_sim.ros.nodes._entry NAME [--ros-args ...]`` does the same for a child process (``rimd rig``,
``rimd experiment``).
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Callable
from pathlib import Path

from rimd_sim.errors import InputError
from rimd_sim.ros.nodes._stop import install_stop_handlers
from rimd_sim.ros.nodes.registry import NODES, NodeEntry
from rimd_sim.runtime import collector, heap

install_stop_handlers()
try:
    collector.configure()   # the imports to come, as a command's (rimd_sim.runtime.collector); for_node() after them
except InputError as _refused:   # RIMD_PLAIN names no piece (rimd_sim.runtime.plain): refused before the node loads
    print(_refused, file=sys.stderr)
    sys.exit(2)

#: The Fast DDS profile of the nodes (a 0.2 s heartbeat of reliable writers; see the file). A profile the
#: user chose through the variable wins.
FASTDDS_PROFILES = Path(__file__).with_name("fastdds_profiles.xml")
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(FASTDDS_PROFILES))


def load(target: str) -> Callable[..., int | None]:
    """The function ``module:function`` names (its module imported now)."""
    module, _, function = target.partition(":")
    return getattr(importlib.import_module(module), function)


def _entry(node: NodeEntry) -> Callable[[], int]:
    def run() -> int:
        main = load(node.target)
        collector.for_node()
        heap.start()
        return int(main() or 0)

    run.__name__ = run.__qualname__ = node.name
    run.__doc__ = f"``{node.executable}``: {node.description}."
    return run


#: Short name -> entry function (the console scripts call them by name: ``_entry:simulator``).
ENTRIES: dict[str, Callable[[], int]] = {node.name: _entry(node) for node in NODES}
globals().update(ENTRIES)
__all__ = ["ENTRIES", "load", *ENTRIES]

if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in ENTRIES:
        print(f"usage: python -m rimd_sim.ros.nodes._entry {{{','.join(ENTRIES)}}} [--ros-args ...]", file=sys.stderr)
        sys.exit(2)
    sys.exit(ENTRIES[sys.argv.pop(1)]())
