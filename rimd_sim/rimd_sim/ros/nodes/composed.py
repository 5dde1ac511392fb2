"""``rimd_composed``: the rig in one process, as ROS 2 composition runs C++ nodes (docs/rig.md, "The composed rig").

The simulator node, and with it the recorder node and the Rerun bridge node (each when asked), run in this one
process on one executor, each the node it is as a separate process: same name, namespace, parameters (each its
section of the parameter files), services, ``/diagnostics``, log lines and outputs. What changes is how the
simulator's messages reach them: handed over in the process (:class:`rimd_sim.ros.nodes.feed.InProcessFeed`), the
serialized bytes the simulator has already written, before it publishes them on DDS for the other processes. No
DDS round trip, no second deserialisation, no executor per consumer. Their lockstep progress goes straight to the
simulator's runtime (:class:`~rimd_sim.ros.nodes.feed.DirectProgress`): the rig waits for the recorder's writer
and the bridge as it does for separate processes. A consumer in another process reports on ``/rig/progress`` as
before.

Command line (``python -m rimd_sim.ros.nodes._entry composed``, ``rimd node composed``; ``rimd rig`` builds it)::

    rimd_composed [--record true|false] [--bridge true|false] [--param NODE:NAME:=VALUE ...] --ros-args ...

``--param`` sets one parameter of one node (``rimd_recorder:output_dir:=/data``; the value is YAML, as ROS's
``-p``): a ``-p`` after ``--ros-args`` would set it on every node of the process. Stopping: as a node
(:mod:`rimd_sim.ros.nodes.base`): the simulator stops first, then the bridge closes its stream, then the recorder
writes what it has and finishes its file. The exit status is the first non-zero one of the three; a refused
configuration exits 2 naming the node.
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Sequence
from typing import Any

import yaml
from rclpy.executors import Executor
from rclpy.parameter import Parameter

from rimd_sim.errors import InputError
from rimd_sim.ros.nodes._stop import StopRequest
from rimd_sim.ros.nodes.base import RimdNode, params_file_problem, run_node, spin_until_stopped
from rimd_sim.ros.nodes.feed import InProcessFeed
from rimd_sim.ros.nodes.simulator import SimulatorNode

__all__ = ["ComposedRig", "main", "parse_arguments"]

NAME = "rimd_composed"
#: Period of the timer that sends the in-process consumers' last lockstep progress (s): a backstop, each consumer
#: sends its last progress after its own batch (the bridge after each poll, the recorder after each write).
PROGRESS_PERIOD_S = 0.25


class PartRefused(InputError):
    """A node of the composed rig refused its configuration (the message names it)."""


def _flag(text: str) -> bool:
    value = yaml.safe_load(text)
    if not isinstance(value, bool):
        raise argparse.ArgumentTypeError(f"{text!r}: must be true or false")
    return value


def _param(text: str) -> tuple[str, Parameter]:
    node, sep, rest = text.partition(":")
    name, sep2, value = rest.partition(":=")
    if not (node and sep and name and sep2):
        raise argparse.ArgumentTypeError(f"{text!r}: must be NODE:NAME:=VALUE (rimd_recorder:output_dir:=/data)")
    return node, Parameter(name, value=yaml.safe_load(value) if value else "")


def parse_arguments(args: Sequence[str]) -> tuple[argparse.Namespace, list[str]]:
    """The composed rig's own options and the ROS arguments (from ``--ros-args`` on)."""
    args = list(args)
    cut = args.index("--ros-args") if "--ros-args" in args else len(args)
    parser = argparse.ArgumentParser(prog=NAME, description="the rig in one process (docs/rig.md)")
    parser.add_argument("--record", type=_flag, default=False, metavar="BOOL", help="run the recorder in it")
    parser.add_argument("--bridge", type=_flag, default=False, metavar="BOOL",
                        help="run the Rerun bridge (Rerun and/or Foxglove) in it")
    parser.add_argument("--param", type=_param, action="append", default=[], metavar="NODE:NAME:=VALUE",
                        help="a parameter of one node of the process (repeatable)")
    return parser.parse_args(args[:cut]), args[cut:]


class ComposedRig:
    """The nodes of the process and how they start and stop together (see the module docstring)."""

    def __init__(self, options: argparse.Namespace, ros_args: list[str]) -> None:
        self.feed = InProcessFeed()
        overrides: dict[str, list[Parameter]] = {}
        for node, param in options.param:
            overrides.setdefault(node, []).append(param)
        self.consumers: list[RimdNode] = []
        self.simulator = self._make(SimulatorNode, overrides, ros_args)
        try:
            if options.record:
                from rimd_sim.ros.nodes.recorder import RecorderNode

                self.consumers.append(self._make(RecorderNode, overrides, ros_args))
            if options.bridge:
                from rimd_sim.ros.nodes.rerun_bridge import RerunBridgeNode

                self.consumers.append(self._make(RerunBridgeNode, overrides, ros_args))
        except BaseException:
            for node in [*self.consumers, self.simulator]:
                node.destroy_node()
            raise
        self.simulator.create_timer(PROGRESS_PERIOD_S, self.feed.flush)

    def _make(self, cls: type[RimdNode], overrides: dict[str, list[Parameter]], ros_args: list[str]) -> Any:
        """Build one node of the process, its refusals naming it."""
        try:
            node = cls(feed=self.feed, parameter_overrides=overrides.get(cls.NODE_NAME, []))
        except cls.REFUSED as exc:
            raise PartRefused(f"{cls.NODE_NAME}: {cls.REFUSED_PREFIX}{exc}") from None
        problem = params_file_problem(node, ros_args)
        if problem:
            node.destroy_node()
            raise PartRefused(f"{cls.NODE_NAME}: {problem}")
        return node

    def spin(self, executor: Executor, stop: StopRequest) -> None:
        """Every node on the executor; the consumers join the lockstep; the simulator starts; spin until the stop."""
        for node in self.consumers:
            executor.add_node(node)
        self.feed.join()
        self.simulator.start()
        spin_until_stopped(executor, stop)

    def close(self) -> int:
        """The simulator stops first, then each consumer takes what was handed over and finishes (in reverse order)."""
        self.simulator.shutdown()
        status = 0
        for node in reversed(self.consumers):
            polled = getattr(node, "_polled", None)
            if polled is not None and node.context.ok():
                polled.poll()   # what was handed over before the stop is taken, as from a DDS history
            status = status or int(node.finish() or 0)
            node.destroy_node()
        return status


def main(args: list[str] | None = None) -> int:
    """Entry point of ``rimd_composed`` (also ``rimd node composed``)."""
    options, ros_args = parse_arguments(sys.argv[1:] if args is None else args)
    if options.record and hasattr(signal, "SIGXFSZ"):   # as the recorder: a file size limit fails the write
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    rig: list[ComposedRig] = []

    def make() -> SimulatorNode:
        rig.append(ComposedRig(options, ros_args))
        return rig[0].simulator

    return run_node(NAME, make, (PartRefused,), args=[NAME, *ros_args], refused_status=2,
                    spin=lambda node, executor, stop: rig[0].spin(executor, stop),
                    close=lambda node: rig[0].close())


if __name__ == "__main__":
    sys.exit(main())
