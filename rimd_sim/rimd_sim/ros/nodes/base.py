"""The skeleton of every node of the rig, written once: parameters, refusals that name them, and the life cycle.

:class:`RimdNode` is the base class of the four nodes (simulator, recorder, replay, Rerun bridge):

* **Parameters** from their one declaration (:class:`rimd_sim.settings.params.Param`): :meth:`RimdNode.declare`
  turns a node's table into declared ROS parameters with descriptors (type, description with unit, rule, range,
  read-only) and returns the values, from which the node builds its frozen settings.
* **Refusals that name the parameter**: rclpy refuses an undeclared name with an empty list (``Invalid access to
  undeclared parameter(s): []``) and lets an empty name through (a node then declared it), refuses a value of
  the wrong static type naming only the two types, and an attempt to unset a parameter with no name at all.
  :meth:`RimdNode.set_parameters_atomically`, the path of rclpy's parameter services, answers those with the
  name and the rule first (:func:`refuse_unnamed`), and a refusal leaves the descriptors as they were.
* **The life cycle** (:meth:`RimdNode.main`, :func:`run_node`): init, build, spin, close, shut down. Stopping is
  ours, not rclpy's. With rclpy's own signal handlers, SIGINT shuts the ROS context down from inside the signal
  handler, at any point of the executor's loop, and raises ``KeyboardInterrupt`` wherever the main thread
  happens to be: between two ``spin_once`` calls the executor then builds a wait set on a dead context
  (``RCLError: failed to initialize wait set``, exit status 1 after a clean stop), and inside a callback the
  interrupt can cut a write in half. Here SIGINT and SIGTERM only *request* a stop
  (:class:`~rimd_sim.ros.nodes._stop.StopRequest`): the executor finishes the callback it runs, the loop sees
  the request within one spin period, :meth:`RimdNode.finish` runs while the context is still valid (the
  recorder drains its subscriptions and finishes its file), and only then is the context shut down. A clean
  stop exits 0, at any moment. The stop handlers are installed by the executables' entry module
  (:mod:`rimd_sim.ros.nodes._entry`) before the heavy imports (rclpy, numba, rerun), so a signal that arrives
  while the node is still loading also ends in a clean exit.

A node sets :attr:`RimdNode.NODE_NAME` (and what else of the class attributes applies), overrides
:meth:`RimdNode.spin_node` and :meth:`RimdNode.finish` when it needs to, and its module's ``main(args)`` returns
``TheNode.main(args)``; the registry (:mod:`rimd_sim.ros.nodes.registry`) lists it.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar, cast

import rclpy
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from rimd_sim.errors import InputError
from rimd_sim.ros.nodes._stop import StopRequest, install_stop_handlers
from rimd_sim.ros.nodes.registry import READY_DIR_ENV
from rimd_sim.runtime.plain import plain
from rimd_sim.settings.config import misapplied_section, misapplied_section_message
from rimd_sim.settings.params import Param
from rimd_sim.settings.yaml_file import read_yaml

__all__ = ["EXECUTOR_ENV", "READY_DIR_ENV", "RimdNode", "declare", "descriptor", "executor_kind", "log_at",
           "make_executor", "refuse_unnamed", "run_node", "spin_until_stopped"]

#: Longest time between a stop request and the loop noticing it (s). rcl_wait cannot be interrupted by a
#: Python signal handler, so the loop waits at most this long before it looks at the request.
SPIN_PERIOD_S = 0.1

#: Environment variable choosing the nodes' executor: ``events`` (default) or ``single`` (rclpy's
#: SingleThreadedExecutor, for comparison or should the events executor misbehave on some platform). Unset, it
#: is ``single`` with ``RIMD_PLAIN=executor`` (a benchmarking switch, :mod:`rimd_sim.runtime.plain`).
EXECUTOR_ENV = "RIMD_EXECUTOR"
EXECUTORS = ("events", "single")

# ---- parameters ------------------------------------------------------------------------------------------------

#: rcl_interfaces ParameterType of each parameter kind (rimd_sim.settings.params.Param.kind).
ROS_TYPES = {"bool": ParameterType.PARAMETER_BOOL, "int": ParameterType.PARAMETER_INTEGER,
             "float": ParameterType.PARAMETER_DOUBLE, "str": ParameterType.PARAMETER_STRING,
             "str[]": ParameterType.PARAMETER_STRING_ARRAY}


def descriptor(p: Param) -> ParameterDescriptor:
    """The ROS descriptor of a declared parameter: type, description with unit, rule, range, read-only.

    A real number is dynamically typed, so that an integer is accepted where a real number is meant
    (``-p rate:=2``, ``gap: 0`` in YAML); the node converts and checks it (:meth:`Param.validate`).
    """
    desc = ParameterDescriptor(name=p.name, type=ROS_TYPES[p.kind], description=p.described(),
                               additional_constraints=p.rule, read_only=p.read_only,
                               dynamic_typing=p.kind == "float")
    low, high = (0 if p.zero else p.low), p.high
    if p.kind == "int" and p.lt is not None:
        high = p.lt - 1
    if p.kind == "int" and p.gt is not None:
        low = p.gt + 1
    if low is not None and high is not None:
        if p.kind == "float":
            desc.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
        elif p.kind == "int":
            desc.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=0)]
    return desc


def declare(node: Node, table: Mapping[str, Param]) -> dict[str, Any]:
    """Declare every parameter of ``table`` on ``node`` (overrides from ``--ros-args`` apply); return the values.

    The values are as ROS holds them (a list for a list of strings, an integer where one was given for a real
    number): build the node's settings from them (:func:`rimd_sim.settings.params.build`), which checks each one.
    """
    values = {}
    for name, p in table.items():
        default = p.default
        if p.kind == "str[]":
            # rclpy types an empty list as a byte array (and then refuses a list of strings given for it), and
            # a parameter declared by its type alone stays unset, which breaks get_parameters for every name
            # asked with it: an empty list is declared as [""], and empty entries mean nothing (Param.validate).
            default = list(default) or [""]
        node.declare_parameter(name, default, descriptor(p))
        values[name] = node.get_parameter(name).value
    return values


def refuse_unnamed(node: Node, parameters: list[Parameter]) -> SetParametersResult | None:
    """The refusals that rclpy's own checks would give without naming the parameter, with its name and rule.

    rclpy refuses an undeclared name with an empty list (``Invalid access to undeclared parameter(s): []``,
    and lets an empty name through: the recorder then declared it), a value of the wrong static type with
    the two types only, and an attempt to unset a parameter with no name at all. Returns None when none of
    these applies (rclpy's other refusals, read-only and out of range, name the parameter).
    """
    for p in parameters:
        if not p.name or not node.has_parameter(p.name):
            return SetParametersResult(successful=False, reason=(
                f"parameter '{p.name}' refused: not a parameter of {node.get_fully_qualified_name()} "
                "(list_parameters gives them)"))
        desc = node.describe_parameter(p.name)
        if desc.read_only or desc.dynamic_typing:
            continue  # rclpy names a read-only parameter; the node's callback checks a dynamically typed one
        expected = Parameter.Type(desc.type).name.lower()
        if p.type_ == Parameter.Type.NOT_SET:
            return SetParametersResult(successful=False, reason=(
                f"parameter '{p.name}' refused: cannot be unset (it must keep a value of type {expected})"))
        if p.type_.value != desc.type:
            return SetParametersResult(successful=False, reason=(
                f"parameter '{p.name}' = {p.value!r} refused: must be of type {expected}, "
                f"not {p.type_.name.lower()}"))
    return None


# ---- running -----------------------------------------------------------------------------------------------------

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

    Unset, it is ``single`` when ``RIMD_PLAIN`` makes the executor plain, else ``events``.

    Raises:
        InputError: ``RIMD_EXECUTOR`` names no known executor, or ``RIMD_PLAIN`` no known piece.
    """
    choice = os.environ.get(EXECUTOR_ENV) or ("single" if plain("executor") else "events")
    if choice not in EXECUTORS:
        raise InputError(f"{EXECUTOR_ENV}={choice!r} refused: must be one of {', '.join(EXECUTORS)}")
    return choice


def make_executor() -> Executor:
    """The executor of the rig's nodes: rclpy's events executor unless ``RIMD_EXECUTOR=single``.

    rclpy's ``SingleThreadedExecutor`` builds a wait set in Python for every callback it runs (one message,
    one pass over every subscription, timer, service and guard condition of the node): at the rig's 600
    messages per second that costs the recorder and the Rerun bridge a large share of their CPU
    (``benchmarks/bench_rig.py``, docs/benchmarks.md). The events executor (``rclpy.experimental``, in
    C++ since Jazzy) is told by the middleware which entity is ready and calls the callback directly.

    Raises:
        InputError: ``RIMD_EXECUTOR`` names no known executor.
    """
    if executor_kind() == "single":
        return SingleThreadedExecutor()
    from rclpy.experimental import EventsExecutor

    return EventsExecutor()


def spin_until_stopped(executor: Executor, stop: StopRequest, done: Callable[[], bool] | None = None) -> None:
    """Spin ``executor`` until a stop is requested, ``done()`` is true, or the context is shut down."""
    context = executor.context
    while not stop.is_set() and context.ok() and not (done is not None and done()):
        executor.spin_once(timeout_sec=SPIN_PERIOD_S)


def params_file_problem(node: Node, args: Sequence[str]) -> str | None:
    """Why a ``--params-file`` of ``args`` misleads ``node``, or None.

    Two mistakes ROS says nothing about, so that the node would run on values other than the file seems to give:
    a section meant for ``node`` that ROS does not apply to it (the node would keep its defaults,
    :func:`rimd_sim.settings.config.misapplied_section`), and a key given twice in one mapping (ROS takes the last
    one, :func:`rimd_sim.settings.yaml_file.read_yaml`). The node refuses to start instead.
    """
    fqn, base = node.get_fully_qualified_name(), node.get_name()
    for path in [args[i + 1] for i, arg in enumerate(args[:-1]) if arg == "--params-file"]:
        try:
            doc = read_yaml(path, what="parameter file")
        except InputError as exc:   # rcl took the file: a key given twice, or the file gone since
            return str(exc)
        key = misapplied_section(doc, base, fqn)
        if key is not None:
            return misapplied_section_message(path, key, base, fqn)
    return None


def run_node(name: str, make_node: Callable[[], Node], refused: tuple[type[BaseException], ...], *,
             args: list[str] | None = None, refused_status: int = 2, refused_prefix: str = "",
             executor: Callable[[], Executor] = make_executor,
             spin: Callable[[Node, Executor, StopRequest], None] | None = None,
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
        spin: Runs the node until it ends or ``stop`` is set (default: :func:`spin_until_stopped`).
        close: Called once in every case after spinning, with the context still valid, before the node is
            destroyed; a non-zero return becomes the exit status.
    """
    try:
        executor_kind()
    except InputError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return refused_status
    stop = install_stop_handlers()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    status = 0
    runner = executor()
    try:
        caught: tuple[type[BaseException], ...] = (*refused, rclpy.exceptions.ParameterException)
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


_participant_said: list[bool] = []   # the ready file is written once per process


def _say_participant_up() -> None:
    """Write this process's ready file (:data:`READY_DIR_ENV`) once, when asked: its DDS participant is up.

    A failure to write is said on stderr, not fatal.
    """
    folder = os.environ.get(READY_DIR_ENV)
    if not folder or _participant_said:
        return
    _participant_said.append(True)
    try:
        (Path(folder) / str(os.getpid())).touch()
    except OSError as exc:
        print(f"could not write the ready file of process {os.getpid()} in {folder} ({READY_DIR_ENV}): {exc}",
              file=sys.stderr)


# ---- the base class ----------------------------------------------------------------------------------------------

class RimdNode(Node):
    """A node of the rig: parameters from their declarations, refusals naming them, the common life cycle.

    Class attributes a node sets:

    Attributes:
        NODE_NAME: The ROS node name, also the executable's (prefixing a refusal line).
        NAMESPACE: Its default namespace (None: the root, or what ``--ros-args`` says).
        REFUSED: Exceptions of the constructor that mean "bad configuration" (one line on stderr, no traceback).
        REFUSED_STATUS: Exit status of a refused configuration.
        REFUSED_PREFIX: Text before the refusal message.
    """

    NODE_NAME: ClassVar[str] = ""
    NAMESPACE: ClassVar[str | None] = None
    REFUSED: ClassVar[tuple[type[BaseException], ...]] = ()
    REFUSED_STATUS: ClassVar[int] = 2
    REFUSED_PREFIX: ClassVar[str] = ""

    def __init__(self, node_name: str | None = None, **kwargs: Any) -> None:
        """A node named ``node_name`` (default :attr:`NODE_NAME`); ``kwargs`` as rclpy's ``Node`` takes them."""
        if self.NAMESPACE is not None:
            kwargs.setdefault("namespace", self.NAMESPACE)
        super().__init__(node_name or self.NODE_NAME, **kwargs)
        _say_participant_up()

    def declare(self, table: Mapping[str, Param]) -> dict[str, Any]:
        """Declare the parameters of ``table`` (:func:`declare`); return their values as ROS holds them."""
        return declare(self, table)

    def log(self, level: str, line: str) -> None:
        """Log ``line`` at ``level`` (``error``, ``warning``, else info): :func:`log_at`."""
        log_at(self, level, line)

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        """Set parameters; rclpy's parameter services (set_parameters, set_parameters_atomically) come here.

        Every refusal names the parameter and its rule (:func:`refuse_unnamed`), and a refusal leaves the
        descriptors as they were: rclpy sets a dynamically typed parameter's descriptor type (every real number
        here) to the type of the value before the value is checked, so without this ``describe_parameters`` would
        report ``gap`` as a string after ``gap := 'abc'`` is refused.
        """
        refusal = refuse_unnamed(self, parameter_list)
        if refusal is not None:
            return refusal
        types = {p.name: self.describe_parameter(p.name).type for p in parameter_list}
        result = super().set_parameters_atomically(parameter_list)
        if not result.successful:
            for name, kind in types.items():
                self.describe_parameter(name).type = kind  # rclpy's own descriptor object
        return result

    def spin_node(self, executor: Executor, stop: StopRequest) -> None:
        """Run until a stop is requested (or the node is done); the default spins until the stop."""
        spin_until_stopped(executor, stop)

    def finish(self) -> int | None:
        """Called once after spinning, the context still valid, before the node is destroyed.

        Returns:
            The exit status when not 0 (None: 0).
        """
        return None

    @classmethod
    def main(cls, args: list[str] | None = None) -> int:
        """Run this node until it ends, Ctrl-C, SIGTERM or an external shutdown; return the exit status."""
        def spin(node: Node, executor: Executor, stop: StopRequest) -> None:
            cast(RimdNode, node).spin_node(executor, stop)

        def close(node: Node) -> int | None:
            return cast(RimdNode, node).finish()

        return run_node(cls.NODE_NAME, cls, cls.REFUSED, args=args, refused_status=cls.REFUSED_STATUS,
                        refused_prefix=cls.REFUSED_PREFIX, spin=spin, close=close)
