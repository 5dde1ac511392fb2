"""Node ``rimd_simulator``: the rig on DDS, behaving like hardware for DAQ software (docs/rig.md).

A thin adapter over :class:`rimd_sim.runtime.simulator.SimulatorRuntime`, which decides everything (pacing,
commands, the run's identity, diagnostics) and serializes every message; this node only

* declares the parameters (:class:`~rimd_sim.settings.config.SimConfig` and the node's own
  :class:`~rimd_sim.settings.config.SimulatorNodeSettings`, one declaration each) and builds the runtime;
* creates one publisher per :func:`rimd_sim.runtime.publishers.outputs` entry (:mod:`._sim_publishers`) and
  publishes the runtime's bytes on it, from a pacing thread that runs :meth:`SimulatorRuntime.run`;
* maps the services, parameter changes, ``/rig/progress`` reports and ``/rig/motor/command`` commands onto the
  runtime, and its answers onto the responses and ``/diagnostics``;
* waits, bounded, for DDS to match the readers the ROS graph shows before the first block and when a lockstep
  consumer joins (the one decision that needs the graph).
"""

from __future__ import annotations

import functools
import sys
import threading
import time
import traceback
from collections.abc import Callable, Mapping
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.executors import Executor
from std_srvs.srv import Trigger

from rimd_msgs.msg import ConsumerProgress, MotorCommand
from rimd_msgs.srv import InjectFault, Perturb, SetMotorFrequency
from rimd_sim.errors import ConfigError
from rimd_sim.ros.clients.motor import COMMAND_QOS
from rimd_sim.ros.clients.progress import listen_for_progress
from rimd_sim.ros.nodes._sim_publishers import diagnostic_array, feeding_send, message_class, offered, qos_profile
from rimd_sim.ros.nodes._stop import StopRequest
from rimd_sim.ros.nodes.base import RimdNode, spin_until_stopped
from rimd_sim.ros.nodes.feed import InProcessFeed
from rimd_sim.ros.nodes.outbox import Outbox
from rimd_sim.runtime.progress import stamp_ns
from rimd_sim.runtime.reader_matches import MATCH_TIMEOUT_LOCKSTEP_S, MATCH_TIMEOUT_S
from rimd_sim.runtime.simulator import Answer, SimulatorRuntime, load_settings, outputs
from rimd_sim.runtime.threads import named_thread
from rimd_sim.settings.config import NODE_PARAMETERS, PARAMETERS

__all__ = ["SimulatorNode", "main"]

NODE_NAME = "rimd_simulator"
DEFAULT_NAMESPACE = "rig"


class SimulatorNode(RimdNode):
    """The simulator node. See the module docstring."""

    NODE_NAME = NODE_NAME
    NAMESPACE = DEFAULT_NAMESPACE
    REFUSED = (ConfigError,)
    REFUSED_PREFIX = "configuration refused: "

    def __init__(self, feed: InProcessFeed | None = None, **kwargs: Any) -> None:
        """Declare, build the runtime, create the publishers and services.

        Args:
            feed: In the composed rig (:mod:`rimd_sim.ros.nodes.composed`): every message is handed to the
                feed's in-process consumers first, then published; their lockstep progress goes straight to the
                runtime.
            kwargs: As rclpy's ``Node`` takes them.
        """
        super().__init__(**kwargs)
        config, settings = load_settings(self.declare({**PARAMETERS, **NODE_PARAMETERS}))  # ConfigError: refused
        outs = outputs(config, settings)
        self._pubs = {out.key: self.create_publisher(message_class(out.type_name), out.key, qos_profile(out.qos))
                      for out in outs}
        # Every second, and at once for a reader that has just matched (a client waiting for the rig to be ready
        # hears it then, not up to a second later); the executor runs the callback, so only once it spins.
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10, event_callbacks=(
            PublisherEventCallbacks(matched=self._on_diagnostics_matched)))
        self._stop = threading.Event()
        self._outbox: Outbox | None = None   # the composed rig's DDS writes (feeding_send)
        send: Callable[[str, bytes], None] = lambda key, data: self._pubs[key].publish(data)  # noqa: E731
        if feed is not None:
            for out in outs:
                pub = self._pubs[out.key]
                feed.offer(pub.topic_name, out.type_name, offered(self, pub, MATCH_TIMEOUT_S))
            self._outbox, send = feeding_send(feed, self._pubs, {out.key for out in outs if out.qos.latched})
        self._lockstep = settings.lockstep.enabled   # read by the wait for matches
        self._rt = SimulatorRuntime(
            config, settings, send=send,
            topics={key: pub.topic_name for key, pub in self._pubs.items()}, node=self.get_fully_qualified_name(),
            log=self._log_line, alive=self.context.ok, match=self._wait_for_matches)
        if feed is not None:
            feed.bind(self._rt.progress)
        if settings.lockstep.enabled:   # a transient local writer's join reaches it at the match, too
            listen_for_progress(self, self._on_progress, "progress")
        # Commands at any rate (docs/control.md); reliable, volatile, as the controllers' writer (COMMAND_QOS).
        self.create_subscription(MotorCommand, "motor/command", self._on_motor_command, COMMAND_QOS)
        rt, at = self._rt, lambda r: (r.start_stamp.sec, r.start_stamp.nanosec)  # noqa: E731
        for kind, name, call in (   # each service's request onto the runtime's method, answered by _serve
                (SetMotorFrequency, "set_motor_frequency",
                 lambda r: rt.set_motor_frequency(r.frequency_hz, r.ramp_rate, at(r))),
                (Perturb, "perturb", lambda r: rt.perturb(r.velocity, at(r))),
                (Trigger, "reset", lambda r: rt.reset()), (Trigger, "pause", lambda r: rt.pause()),
                (Trigger, "resume", lambda r: rt.resume()), (Trigger, "clear_faults", lambda r: rt.clear_faults()),
                (InjectFault, "inject_fault",
                 lambda r: rt.inject_fault(r.channel, r.kind, r.start, r.duration, r.magnitude, after=r.after))):
            self.create_service(kind, name, functools.partial(self._serve, call))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.create_timer(1.0, self._publish_diagnostics)
        self._thread = named_thread(self._run, "rimd-pacing")
        self.get_logger().info(self._rt.describe())

    @property
    def runtime(self) -> SimulatorRuntime:
        """The runtime this node adapts."""
        return self._rt

    # ---- life cycle --------------------------------------------------------------------------------

    def start(self) -> None:
        """Start the pacing thread (publishing begins now, or at the first resume when started paused)."""
        self._rt.start()
        self._thread.start()

    def shutdown(self) -> None:
        """Stop the pacing thread (idempotent)."""
        self._stop.set()
        self._rt.wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        if self._outbox is not None:   # what the pacing thread sent goes out before the publishers go
            self._outbox.close()

    def spin_node(self, executor: Executor, stop: StopRequest) -> None:
        """Start publishing, spin until the stop."""
        self.start()
        spin_until_stopped(executor, stop)

    def finish(self) -> None:
        """At the stop: :meth:`shutdown`."""
        self.shutdown()

    def _run(self) -> None:
        """The pacing thread: the runtime's loop (:meth:`SimulatorRuntime.run`) until the stop."""
        try:   # the outbox's flush raises a write that failed on its thread
            self._rt.run(self._stop, after_pass=self._outbox.flush if self._outbox is not None else None,
                         report=self._publish_diagnostics)
        except Exception as exc:  # noqa: BLE001 - at shutdown the context goes away while publishing: not an error
            if self.context.ok():   # a defect: say so where a user looks (log, /diagnostics ERROR), keep services
                self._rt.fail(f"internal error {type(exc).__name__}: {exc}")
                self.get_logger().error(f"simulation stopped by an internal error (please report it):\n"
                                        f"{traceback.format_exc()}")

    def _wait_for_matches(self, joining: Mapping[str, list[str] | None]) -> None:
        """Wait (bounded) until DDS has matched the readers the graph shows to their publishers.

        A volatile topic reaches only the readers its writer has matched, and the graph can show a new
        subscriber some milliseconds before the match: without this wait a reader the caller saw (`rimd rig`, a
        lockstep consumer that just joined) could miss the first blocks. With ``joining`` empty (before the first
        block): every subscription of a published topic. Otherwise only the joining consumers' readers: ``joining``
        maps each one's node to the topics its report named, or to None (it named none): the published topics the
        graph shows that node reading. This node's own view of the graph can lag the consumer's (under load, by
        more than the match): the wait lasts until the graph here shows the node and its readers, and they are
        matched. A join's wait is logged with the readers it waited for.
        """
        timeout = MATCH_TIMEOUT_LOCKSTEP_S if self._lockstep else MATCH_TIMEOUT_S
        start = time.monotonic()
        if self._outbox is not None:   # the blocks before the match reach the readers matched before it only
            self._outbox.drain(timeout)
        deadline = start + timeout
        while True:
            unmatched, readers = self._unmatched(joining)
            if not unmatched or time.monotonic() >= deadline or self._stop.is_set():
                break
            time.sleep(0.005)
        if self._stop.is_set():
            return
        if unmatched:
            self.get_logger().warning(f"publishing although readers of {', '.join(unmatched)} are not matched after "
                                      f"{timeout:g} s: they may miss blocks; {self._graph_view(joining)}")
            return
        for node, topics in readers.items():
            self.get_logger().info(f"lockstep: the readers of {node} are matched after {time.monotonic() - start:.3f} "
                                   f"s: {', '.join(topics) if topics else 'none of the published topics'}")

    def _graph_view(self, joining: Mapping[str, list[str] | None]) -> str:
        """What this node's graph shows of the joining nodes: for the log line of a wait that timed out."""
        nodes = sorted(ns.rstrip("/") + "/" + name for name, ns in self.get_node_names_and_namespaces())
        seen = ", ".join(n for n in nodes if n in joining) or "none joining"
        parts = [f"the graph shows {len(nodes)} nodes ({seen})"]
        for p in self._pubs.values():
            readers = [i.node_namespace.rstrip("/") + "/" + i.node_name
                       for i in self.get_subscriptions_info_by_topic(p.topic_name)]
            parts.append(f"{p.topic_name}: {p.get_subscription_count()} matched of {len(readers)} "
                         f"({', '.join(sorted(readers))})")
        return "; ".join(parts)

    def _unmatched(self, joining: Mapping[str, list[str] | None]) -> tuple[list[str], dict[str, list[str]]]:
        """What is not matched yet, and per joining node the published topics whose readers are waited for.

        Unmatched: the topics whose publisher has matched fewer subscriptions than the graph shows (every published
        topic with ``joining`` empty, else the joining nodes' topics), the topics a joining node names whose reader
        this node's graph does not show yet, and a joining node that named no topics and that graph does not show.
        """
        pubs = {p.topic_name: p for p in self._pubs.values()}
        if not joining:
            return [t for t, p in pubs.items() if p.get_subscription_count() < self.count_subscribers(t)], {}
        out: list[str] = []
        readers: dict[str, list[str]] = {}
        for node, named in joining.items():
            topics = named if named is not None else self._reads(node)
            if topics is None:
                out.append(f"the topics of {node} (a node this node's graph does not show)")
                continue
            readers[node] = topics = sorted(t for t in topics if t in pubs)
            for topic in topics:
                infos = self.get_subscriptions_info_by_topic(topic)
                shown = {i.node_namespace.rstrip("/") + "/" + i.node_name for i in infos}
                if node not in shown or pubs[topic].get_subscription_count() < len(infos):
                    out.append(f"{topic} (by {node})")
        return out, readers

    def _reads(self, node: str) -> list[str] | None:
        """The published topics the graph shows ``node`` (``/ns/name``) subscribing to; None when it does not show it.

        Read from each published topic's endpoints rather than by node name: a consumer restarted under the name of
        one that was killed shares that name with the dead node until its lease expires, and a lookup by name
        answers for one of the two only.
        """
        shown = {ns.rstrip("/") + "/" + name for name, ns in self.get_node_names_and_namespaces()}
        if node not in shown:
            return None
        return [topic for topic in (p.topic_name for p in self._pubs.values())
                if any(i.node_namespace.rstrip("/") + "/" + i.node_name == node
                       for i in self.get_subscriptions_info_by_topic(topic))]

    def _log_line(self, level: str, line: str) -> None:
        """The runtime's log: ``debug`` (each motor command from the topic) on its own call site, the rest as usual."""
        if level == "debug":
            self.get_logger().debug(line)
        else:
            self.log(level, line)

    def _on_progress(self, msg: ConsumerProgress) -> None:
        self._rt.progress(msg.consumer, stamp_ns(msg.done_through), instance=msg.instance, topics=list(msg.topics),
                          topics_done_ns=[stamp_ns(d) for d in msg.topics_done_through], leaving=msg.leaving,
                          node=msg.node, controls=msg.controls, commands=msg.commands)

    def _on_motor_command(self, msg: MotorCommand) -> None:
        self._rt.motor_command(msg.frequency_hz, msg.ramp_rate, (msg.header.stamp.sec, msg.header.stamp.nanosec),
                               consumer=msg.consumer, instance=msg.instance, sequence=msg.sequence)

    def _on_diagnostics_matched(self, status: Any) -> None:
        """A reader of /diagnostics matched (or left): a new one hears the status now.

        Readers matched before the executor spins come as one event whose change may say 0 (the count says them).
        """
        if status.current_count > 0 and status.current_count_change >= 0:
            self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        subscribers = {p.topic_name: p.get_subscription_count() for p in self._pubs.values()}
        self._pub_diag.publish(diagnostic_array(self._rt.diagnostics(subscribers), self.get_clock().now().to_msg()))

    # ---- services and parameters -------------------------------------------------------------------

    @staticmethod
    def _serve(call: Callable[[Any], Answer], request: Any, response: Any) -> Any:
        """Answer a service: ``response`` filled from the runtime's :class:`Answer` to ``request``, ``call(request)``.

        Its success and message, and its effective_stamp and frequency_hz where the service's response has them.
        """
        answer = call(request)
        response.success, response.message = answer.success, answer.message
        if answer.stamp_ns is not None:
            sec, nanosec = divmod(answer.stamp_ns, 1_000_000_000)
            response.effective_stamp = Time(sec=sec, nanosec=nanosec)
        if answer.frequency_hz is not None:
            response.frequency_hz = answer.frequency_hz
        return response

    def _on_set_parameters(self, params: list) -> SetParametersResult:
        reason = self._rt.set_parameters([(p.name, p.value) for p in params])
        return SetParametersResult(successful=reason is None, reason=reason or "")


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``rimd_simulator`` executable (also ``rimd node simulator``)."""
    return SimulatorNode.main(args)


if __name__ == "__main__":
    sys.exit(main())
