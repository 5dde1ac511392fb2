"""The common life cycle of the rig's node executables: init, build, spin, close, shut down.

Stopping is ours, not rclpy's. With rclpy's own signal handlers, SIGINT shuts the ROS context down from
inside the signal handler, at any point of the executor's loop, and raises ``KeyboardInterrupt`` wherever
the main thread happens to be: between two ``spin_once`` calls the executor then builds a wait set on a
dead context (``RCLError: failed to initialize wait set``, exit status 1 after a clean stop), and inside a
callback the interrupt can cut a write in half. Here SIGINT and SIGTERM only *request* a stop
(:class:`StopRequest`): the executor finishes the callback it runs, the loop sees the request within one
spin period, ``close`` runs while the context is still valid (the recorder drains its subscriptions and
finishes its file), and only then is the context shut down. A clean stop exits 0, at any moment.

:func:`~rimd_sim.ros.nodes._stop.install_stop_handlers` is called by the executables' entry module
(:mod:`rimd_sim.ros.nodes._entry`) before the heavy imports (rclpy, numba, rerun), so a signal that arrives
while the node is still loading also ends in a clean exit.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import rclpy
import yaml
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from rimd_sim.ros.nodes._stop import StopRequest, install_stop_handlers
from rimd_sim.settings.config import misapplied_section, misapplied_section_message

#: Longest time between a stop request and the loop noticing it (s). rcl_wait cannot be interrupted by a
#: Python signal handler, so the loop waits at most this long before it looks at the request.
SPIN_PERIOD_S = 0.1

#: Environment variable choosing the nodes' executor: ``events`` (default) or ``single`` (rclpy's
#: SingleThreadedExecutor, for comparison or should the events executor misbehave on some platform).
EXECUTOR_ENV = "RIMD_EXECUTOR"
EXECUTORS = ("events", "single")

#: The node class an executable runs (what its ``spin`` and ``close`` receive).
NodeT = TypeVar("NodeT", bound=Node)


def log_at(node: Node, level: str, line: str) -> None:
    """Log ``line`` at ``level`` (``error``, ``warning``, else info) on ``node``'s logger.

    One call site per severity: rclpy's logger refuses a call site that changes severity between calls, so a
    level chosen at run time cannot go through one call.
    """
    logger = node.get_logger()
    if level == "error":
        logger.error(line)
    elif level == "warning":
        logger.warning(line)
    else:
        logger.info(line)


def executor_kind() -> str:
    """The executor chosen by ``RIMD_EXECUTOR``: ``events`` or ``single``.

    Raises:
        ValueError: ``RIMD_EXECUTOR`` names no known executor.
    """
    choice = os.environ.get(EXECUTOR_ENV, "events") or "events"
    if choice not in EXECUTORS:
        raise ValueError(f"{EXECUTOR_ENV}={choice!r} refused: must be one of {', '.join(EXECUTORS)}")
    return choice


def make_executor() -> Executor:
    """The executor of the rig's nodes: rclpy's events executor unless ``RIMD_EXECUTOR=single``.

    rclpy's ``SingleThreadedExecutor`` builds a wait set in Python for every callback it runs (one message,
    one pass over every subscription, timer, service and guard condition of the node): at the rig's 600
    messages per second that was half the CPU of the recorder and of the Rerun bridge
    (``benchmarks/bench_rig.py``, docs/benchmarks.md). The events executor (``rclpy.experimental``, in
    C++ since Jazzy) is told by the middleware which entity is ready and calls the callback directly.

    Raises:
        ValueError: ``RIMD_EXECUTOR`` names no known executor.
    """
    if executor_kind() == "single":
        return SingleThreadedExecutor()
    from rclpy.experimental import EventsExecutor

    return EventsExecutor()


class PolledSubscriptions:
    """Raw subscriptions that their node takes itself, every ready message at once, every ``period`` s.

    Under the events executor each message costs a dispatch from C++ to Python on top of its take; a
    timer that takes everything waiting (``take_message`` in a loop, one C call per message) serves the
    rig's 600 messages a second in 50 wake-ups. The messages wait at most one period in their DDS history
    (the subscriptions' depth must hold a period of traffic), and the take gives the message info (source
    timestamp) with the bytes. The executor must not take these subscriptions too: the node is a
    :class:`PollingNode`, which hides them from it.
    Should an executor dispatch one all the same, the message still reaches its handler (without info).
    """

    def __init__(self, node: Node, period: float) -> None:
        self._node = node
        self._subs: list[tuple[Any, Callable[[bytes, dict], None]]] = []
        self._hidden: set[int] = set()
        self.timer = node.create_timer(period, self.poll)

    def create(self, msg_type: type, topic: str, qos: Any, handler: Callable[[bytes, dict], None]) -> Any:
        """Create a raw subscription of the node whose messages go to ``handler(data, info)``."""
        # raw=True: the callback gets the serialized bytes (rclpy's annotation says a message).
        sub = self._node.create_subscription(msg_type, topic, lambda data: handler(data, {}),  # type: ignore[arg-type]
                                             qos, raw=True)
        self._hidden.add(id(sub))
        self._subs.append((sub, handler))
        return sub

    def visible(self, subscriptions: Iterable[Any]) -> list[Any]:
        """The subscriptions an executor should take: all but the polled ones."""
        return [s for s in subscriptions if id(s) not in self._hidden]

    @staticmethod
    def take(sub: Any, handler: Callable[[bytes, dict], None], limit: int = 100_000) -> int:
        """Hand up to ``limit`` messages waiting in ``sub`` to ``handler``; return how many."""
        handle = sub.handle
        for n in range(limit):
            try:
                with handle:
                    taken = handle.take_message(sub.msg_type, True)
            except Exception:  # the subscription is being destroyed
                return n
            if taken is None:
                return n
            handler(taken[0], taken[1])
        return limit

    def poll(self) -> int:
        """Take every message waiting in every polled subscription; return how many."""
        return sum(self.take(sub, handler) for sub, handler in self._subs)


class PollingNode(Node):
    """A node whose executor does not take its :class:`PolledSubscriptions` (``self._polled``).

    rclpy's executors read ``Node.subscriptions``; this property leaves the polled ones out. The subclass
    sets ``self._polled`` in its ``__init__``.
    """

    _polled: PolledSubscriptions | None = None   # None until the subclass creates it

    @property
    def subscriptions(self) -> list:  # type: ignore[override]  # rclpy says Iterator; the executors iterate it
        """The subscriptions the executor takes: all but the polled ones."""
        subs = super().subscriptions
        return list(subs) if self._polled is None else self._polled.visible(subs)


def spin_until_stopped(executor: Executor, stop: StopRequest, done: Callable[[], bool] | None = None) -> None:
    """Spin ``executor`` until a stop is requested, ``done()`` is true, or the context is shut down."""
    context = executor.context
    while not stop.is_set() and context.ok() and not (done is not None and done()):
        executor.spin_once(timeout_sec=SPIN_PERIOD_S)


def params_file_problem(node: Node, args: Sequence[str]) -> str | None:
    """Why a ``--params-file`` of ``args`` has a section meant for ``node`` that ROS does not apply to it, or None.

    ROS says nothing then and the node would run with its defaults: it refuses to start instead
    (:func:`rimd_sim.settings.config.misapplied_section`).
    """
    fqn, base = node.get_fully_qualified_name(), node.get_name()
    for path in [args[i + 1] for i, arg in enumerate(args[:-1]) if arg == "--params-file"]:
        try:
            doc = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError):
            continue   # rcl read it (or refused it) when the node was made
        key = misapplied_section(doc, base, fqn)
        if key is not None:
            return misapplied_section_message(path, key, base, fqn)
    return None


def run_node(name: str, make_node: Callable[[], NodeT], refused: tuple[type[BaseException], ...], *,
             args: list[str] | None = None, refused_status: int = 2, refused_prefix: str = "",
             executor: Callable[[], Executor] = make_executor,
             spin: Callable[[NodeT, Executor, StopRequest], None] | None = None,
             close: Callable[[NodeT], int | None] | None = None) -> int:
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
        spin: Runs the node until it ends or ``stop`` is set (default: :func:`spin_until_stopped`).
        close: Called once in every case after spinning, with the context still valid, before the node is
            destroyed; a non-zero return becomes the exit status.
    """
    try:
        executor_kind()
    except ValueError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return refused_status
    stop = install_stop_handlers()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node: NodeT | None = None
    status = 0
    runner = executor()
    caught: tuple[type[BaseException], ...] = (*refused, rclpy.exceptions.ParameterException)
    try:
        try:
            node = make_node()
        except caught as exc:
            print(f"{name}: {refused_prefix}{exc}", file=sys.stderr)
            return refused_status
        problem = params_file_problem(node, sys.argv if args is None else args)
        if problem:
            print(f"{name}: {problem}", file=sys.stderr)
            return refused_status
        runner.add_node(node)
        if not stop.is_set():
            if spin is None:
                spin_until_stopped(runner, stop)
            else:
                spin(node, runner, stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass   # KeyboardInterrupt: only if a caller replaced the handlers (e.g. an embedding program)
    finally:
        if node is not None:
            if close is not None:
                status = close(node) or 0
            node.destroy_node()
        runner.shutdown()
        if rclpy.ok():
            rclpy.shutdown()
    return status
