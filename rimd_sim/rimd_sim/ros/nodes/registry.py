"""The rig's nodes, listed once: name, executable, ``module:function``, description, and how ``rimd rig`` starts them.

Pure data with no import beyond the standard library: ``rimd_sim/setup.py`` loads this file by its path at build
time (the console scripts), and so do, by import, the entry module (:mod:`rimd_sim.ros.nodes._entry`, the
executables and ``python -m rimd_sim.ros.nodes._entry NAME``), ``rimd node NAME`` and the bring-up
(:mod:`rimd_sim.ros.bringup`, ``rimd rig``). Adding a node is one entry here (docs/development.md).
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["ENTRY_MODULE", "NODES", "READY_DIR_ENV", "NodeEntry", "by_name", "console_scripts", "rig_nodes"]

#: The module whose functions the console scripts run (it installs the stop handlers before any heavy import).
ENTRY_MODULE = "rimd_sim.ros.nodes._entry"

#: Environment variable naming a directory where a node process, once its first node is made (its DDS participant
#: is up), writes an empty file named after its process id (:class:`rimd_sim.ros.nodes.base.RimdNode`). The pytest
#: plugin waits for it before it makes its own participant: one made earlier sends its first announcements to
#: nobody and may be found only at its next periodic one, seconds later (docs/testing.md).
READY_DIR_ENV = "RIMD_READY_DIR"


class NodeEntry(NamedTuple):
    """One node of the rig.

    Attributes:
        name: Its short name: ``rimd node NAME``, ``python -m rimd_sim.ros.nodes._entry NAME``, the entry function.
        executable: The console script (``ros2 run rimd_sim EXECUTABLE``); also the ROS node name.
        target: ``module:function`` of its ``main(args)``.
        description: One line, for ``rimd node --help``.
        namespace: The namespace it runs in when ``rimd rig`` starts it.
        rig: Order in which ``rimd rig`` starts it (stopped in reverse); 0: not part of the rig.
        consumer: Open loop, ``rimd rig`` resumes the simulator only once this node subscribes to every rig topic.
    """

    name: str
    executable: str
    target: str
    description: str
    namespace: str = "/"
    rig: int = 0
    consumer: bool = False


NODES: tuple[NodeEntry, ...] = (
    NodeEntry("simulator", "rimd_simulator", "rimd_sim.ros.nodes.simulator:main",
              "the rig: the simulated instruments on /rig, with its services", namespace="/rig", rig=3),
    NodeEntry("recorder", "rimd_recorder", "rimd_sim.ros.nodes.recorder:main",
              "records the rig's topics into MCAP files", namespace="/", rig=1, consumer=True),
    NodeEntry("replay", "rimd_replay", "rimd_sim.ros.nodes.replay:main",
              "publishes a recording again, paced like the rig"),
    NodeEntry("composed", "rimd_composed", "rimd_sim.ros.nodes.composed:main",
              "the rig in one process: the simulator with the recorder and the bridge fed in the process"),
    NodeEntry("rerun", "rimd_rerun", "rimd_sim.ros.nodes.rerun_bridge:main",
              "streams the rig's topics to Rerun and, if asked, to Foxglove", namespace="/rig", rig=2),
)


def by_name(name: str) -> NodeEntry:
    """The node of short name ``name``.

    Raises:
        KeyError: No such node.
    """
    for node in NODES:
        if node.name == name:
            return node
    raise KeyError(name)


def rig_nodes() -> tuple[NodeEntry, ...]:
    """The nodes ``rimd rig`` may start, in start order."""
    return tuple(sorted((n for n in NODES if n.rig), key=lambda n: n.rig))


def console_scripts() -> list[str]:
    """``"executable = module:function"`` of every node, for setuptools (the entry module's function of each)."""
    return [f"{n.executable} = {ENTRY_MODULE}:{n.name}" for n in NODES]
