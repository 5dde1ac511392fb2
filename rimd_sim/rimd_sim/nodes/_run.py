"""The common life cycle of the rig's node executables: init, build, spin, close, shut down."""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node


def run_node(name: str, make_node: Callable[[], Node], refused: tuple[type[BaseException], ...], *,
             args: list[str] | None = None, refused_status: int = 2, refused_prefix: str = "",
             executor: Callable[[], Executor] = SingleThreadedExecutor,
             spin: Callable[[Node, Executor], None] | None = None,
             close: Callable[[Node], int | None] | None = None) -> int:
    """Run one node until it ends, Ctrl-C, SIGTERM or an external shutdown; return the exit status.

    Args:
        name: The executable's name, prefixing the refusal line.
        make_node: Builds the node (after ``rclpy.init``).
        refused: Exceptions of ``make_node`` that mean "bad configuration": printed as one line on stderr
            (``name: refused_prefix message``), exit status ``refused_status``. ROS parameter exceptions are
            always included.
        args: Command-line arguments (``--ros-args ...``).
        refused_status: Exit status of a refused configuration.
        refused_prefix: Text before the refusal message.
        executor: Factory of the executor.
        spin: Runs the node (default: ``executor.spin()``).
        close: Called once in every case after spinning, before the node is destroyed; a non-zero return
            becomes the exit status.
    """
    rclpy.init(args=args)
    node = None
    status = 0
    runner = executor()
    try:
        try:
            node = make_node()
        except (*refused, rclpy.exceptions.ParameterException) as exc:
            print(f"{name}: {refused_prefix}{exc}", file=sys.stderr)
            return refused_status
        runner.add_node(node)
        if spin is None:
            runner.spin()
        else:
            spin(node, runner)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            if close is not None:
                status = close(node) or 0
            node.destroy_node()
        runner.shutdown()
        if rclpy.ok():
            rclpy.shutdown()
    return status
