"""A lockstep consumer written by hand, as one in another language would be, joins the rig (docs/rig.md, "Pacing:
lockstep", "A consumer in another language").

The simulator runs in this test's process on one ROS context, the consumer on another (two DDS participants, so
discovery and matching between them happen as between two processes); the consumer is plain rclpy, no
``ProgressReporter``: a reliable, transient local, keep-last-1 writer of ``/rig/progress`` and reliable readers of
two channels.

Hypotheses:

1. a consumer that publishes its join once, right after it created its writer and before the rig matched it (here
   before the simulator exists, so that it has matched nobody for sure; a volatile subscription would never get
   that join, and the rig would wait for it at 0 s for ever), joins: the rig's transient local subscription gets
   the join at the match, and the consumer receives every block of both channels from sample 0;
2. a consumer that names its node but no topics, started once the rig is up, holds the run only for the
   readers it has: the rig's join waits for its readers of the two channels it takes (the log names them), not
   for the topics it does not read (no "publishing although readers of ... are not matched" warning, which would
   name /rig/truth and the rest). How long that wait lasts, and the run's speed over its first
   20 s against after, are figures of benchmarks/bench_lockstep_join.py, not asserted here (wall-clock
   thresholds flake on a loaded machine).
"""

from __future__ import annotations

import re
import time
import uuid

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]

CHANNELS = ("/rig/cart/displacement", "/rig/impact/force")
#: Simulation time both channels must reach (s).
UNTIL_S = 0.5


class HandWrittenConsumer:
    """A lockstep consumer without ``ProgressReporter``: what docs/rig.md tells a client in another language to do.

    It subscribes to ``CHANNELS``, creates its progress writer (reliable, transient local, keep last 1) and
    publishes its join at once; then after each block it reports, per topic, the stamp of the last block taken.
    """

    def __init__(self, context, name: str, *, name_topics: bool) -> None:
        import rclpy
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        from rimd_msgs.msg import ConsumerProgress, SampleBlock

        self.name, self.instance = name, uuid.uuid4().hex
        self.node = rclpy.create_node(name, context=context)
        self.spans: dict[str, list[tuple[int, int]]] = {t: [] for t in CHANNELS}
        self.done = dict.fromkeys(CHANNELS, 0)
        self.reached = dict.fromkeys(CHANNELS, 0.0)
        data = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        for topic in CHANNELS:
            self.node.create_subscription(SampleBlock, topic, lambda msg, t=topic: self._on_block(t, msg), data)
        self.writer = self.node.create_publisher(ConsumerProgress, "/rig/progress", QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.matched_at_join = self.writer.get_subscription_count()
        self._message = ConsumerProgress
        # The join: once, now. Named topics are each done through zero; else none (the rig looks at the graph).
        self.report(CHANNELS if name_topics else ())

    def report(self, topics) -> None:
        from builtin_interfaces.msg import Time

        self.writer.publish(self._message(
            consumer=self.name, instance=self.instance, node=self.node.get_fully_qualified_name(),
            topics=list(topics),
            topics_done_through=[Time(sec=self.done[t] // 1_000_000_000, nanosec=self.done[t] % 1_000_000_000)
                                 for t in topics]))

    def _on_block(self, topic: str, msg) -> None:
        self.spans[topic].append((msg.first_index, len(msg.samples)))
        self.done[topic] = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.reached[topic] = (msg.first_index + len(msg.samples)) / msg.sample_rate
        self.report(CHANNELS)

    def has_reached(self, seconds: float) -> bool:
        return all(v >= seconds for v in self.reached.values())


def _run(ros_executor, name: str, *, name_topics: bool, consumer_first: bool) -> HandWrittenConsumer:
    """The simulator in lockstep with ``name`` alone (as fast as it allows), and the consumer joining it.

    ``consumer_first``: the consumer joins before the simulator exists (its writer has matched nobody, for sure);
    else once the simulator has been up for a while, as a DAQ program started after the rig.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from rimd_sim.ros.nodes.simulator import SimulatorNode

    rig_context = ros_executor.context
    context = Context()   # the consumer's own participant
    executors: list[SingleThreadedExecutor] = []
    simulator = None

    def start_simulator() -> SimulatorNode:
        node = SimulatorNode(context=rig_context, parameter_overrides=[
            Parameter("lockstep.enabled", value=True), Parameter("lockstep.consumers", value=[name]),
            Parameter("real_time_factor", value=0.0)])
        ros_executor.add_node(node)
        node.start()
        return node

    def start_consumer() -> HandWrittenConsumer:
        rclpy.init(context=context, domain_id=rig_context.get_domain_id(),
                   signal_handler_options=SignalHandlerOptions.NO)
        executors.append(SingleThreadedExecutor(context=context))
        made = HandWrittenConsumer(context, name, name_topics=name_topics)
        executors[0].add_node(made.node)
        return made

    try:
        if consumer_first:
            consumer = start_consumer()
            simulator = start_simulator()
        else:
            simulator = start_simulator()
            deadline = time.monotonic() + 2.0   # the rig up and running (held: nobody has joined)
            while time.monotonic() < deadline:
                ros_executor.spin_once(timeout_sec=0.05)
            consumer = start_consumer()
        deadline = time.monotonic() + 60.0
        while not consumer.has_reached(UNTIL_S) and time.monotonic() < deadline:
            ros_executor.spin_once(timeout_sec=0.002)
            executors[0].spin_once(timeout_sec=0.002)
        return consumer
    finally:
        if simulator is not None:
            simulator.shutdown()
        for executor in executors:
            executor.shutdown(timeout_sec=1.0)
            for node in list(executor.get_nodes()):
                node.destroy_node()
        context.try_shutdown()


def _from_sample_zero(consumer: HandWrittenConsumer) -> None:
    for topic, spans in consumer.spans.items():
        assert spans and spans[0][0] == 0, f"{topic}: first blocks {spans[:2]}"
        holes = [(a, b) for a, b in zip(spans, spans[1:], strict=False) if b[0] != a[0] + a[1]]
        assert not holes, f"{topic}: holes {holes[:3]}"
        assert consumer.reached[topic] >= UNTIL_S, topic


def test_a_join_published_once_before_the_match_reaches_the_rig(ros_executor, capfd):
    consumer = _run(ros_executor, "hand_daq", name_topics=True, consumer_first=True)
    log = capfd.readouterr().err
    assert consumer.matched_at_join == 0   # the join went out before the writer had matched the rig
    assert "consumer 'hand_daq' joined" in log, log[-2000:]
    _from_sample_zero(consumer)


def test_a_consumer_naming_no_topics_holds_the_run_only_for_its_own_readers(ros_executor, capfd):
    consumer = _run(ros_executor, "pair_daq", name_topics=False, consumer_first=False)
    log = capfd.readouterr().err
    assert "consumer 'pair_daq' joined" in log, log[-2000:]
    waited = re.search(r"lockstep: the readers of /pair_daq are matched after (\S+) s: (.*)", log)
    assert waited, log[-2000:]
    assert waited.group(2).strip() == ", ".join(CHANNELS)   # its two readers, not every topic the rig publishes
    assert "publishing although readers" not in log, log[-2000:]
    _from_sample_zero(consumer)
    print(f"the join's match wait: {float(waited.group(1)) * 1e3:.1f} ms")
