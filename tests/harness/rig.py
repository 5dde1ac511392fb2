"""Running the rig for recorder and replay tests: start, collect raw messages, drive through services."""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path

from harness.ros import call_service, spin_until

RIG_TOPICS = {
    "/rig/cart/displacement": "SampleBlock",
    "/rig/rimd/displacement": "SampleBlock",
    "/rig/rimd/acceleration": "SampleBlock",
    "/rig/impact/force": "SampleBlock",
    "/rig/truth": "RigState",
    "/rig/motor/state": "MotorState",
    "/rig/impact/events": "ImpactEvent",
}
BLOCK_TOPICS = [t for t, kind in RIG_TOPICS.items() if kind in ("SampleBlock", "RigState")]


class RawCollector:
    """A node in the test process holding the serialized bytes of every message of the rig topics."""

    def __init__(self, executor, topics=RIG_TOPICS, remap=None, name: str = "test_collector"):
        from rclpy.node import Node
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        import rimd_msgs.msg

        self.node = Node(name, context=executor.context)
        executor.add_node(self.node)
        self.messages: dict[str, list[bytes]] = {t: [] for t in topics}
        # When DDS received each (its reader's timestamp, s): not when this process's executor took it, which a
        # loaded test process delays enough to make a replay's span look markedly shorter than the recorded one.
        self.times: dict[str, list[float]] = {t: [] for t in topics}
        qos = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
        self.subscriptions = []
        for topic, kind in topics.items():
            def callback(data, info, topic=topic):
                self.messages[topic].append(data)
                self.times[topic].append(info["received_timestamp"] / 1e9)
            name = (remap or {}).get(topic, topic)
            self.subscriptions.append(
                self.node.create_subscription(getattr(rimd_msgs.msg, kind), name, callback, qos, raw=True))

    def matched(self, topics: Iterable[str] | None = None) -> bool:
        """Whether the subscription of each of ``topics`` (default: all) has matched a publisher: this side of the
        two-sided discovery (a volatile subscription drops what a publisher sends before it has matched it)."""
        chosen = set(self.messages if topics is None else topics)
        return all(sub.get_publisher_count() > 0 for topic, sub in zip(self.messages, self.subscriptions, strict=True)
                   if topic in chosen)


class Diagnostics:
    """The latest ``/diagnostics`` values of each node, read by the tests to wait on what a node says it did.

    The simulator reports per topic ``<topic> published`` (messages sent since its start) and ``<topic>
    subscribers`` (matched subscriptions); the recorder ``<topic> written``; both publish about once a second.
    """

    def __init__(self, node) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        self.values: dict[str, dict[str, str]] = {}
        self.received: dict[str, float] = {}   # status name -> monotonic time of its last report
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on, 100)

    def _on(self, msg) -> None:
        for status in msg.status:
            self.values[status.name] = {kv.key: kv.value for kv in status.values}
            self.received[status.name] = time.monotonic()

    def of(self, node_name: str, since: float = 0.0) -> dict[str, str]:
        """The values of the statuses of ``node_name`` reported after ``since`` (monotonic; empty if none)."""
        out: dict[str, str] = {}
        for name, values in self.values.items():
            if node_name in name and self.received[name] > since:
                out.update(values)
        return out


def wait_until_matched(executor, collector: RawCollector, diagnostics: Diagnostics, readers: int,
                       timeout: float = 30.0) -> None:
    """Wait until the collector's subscriptions have matched their publishers and the simulator's publishers
    of those topics have matched ``readers`` subscriptions each (the collector, the recorder...), so that the
    first message a resumed rig publishes reaches every one of them."""
    def matched() -> bool:
        sim = diagnostics.of("rimd_simulator")
        return (all(sub.get_publisher_count() > 0 for sub in collector.subscriptions)
                and all(int(sim.get(f"{t} subscribers", 0)) >= readers for t in collector.messages))

    assert spin_until(executor, matched, timeout), (
        "not matched: collector "
        + str({s.topic_name: s.get_publisher_count() for s in collector.subscriptions})
        + ", simulator " + str({k: v for k, v in diagnostics.of("rimd_simulator").items() if "subscribers" in k}))


def wait_until_delivered(executor, collector: RawCollector, diagnostics: Diagnostics, paused_at: float,
                         recorder: bool = True, timeout: float = 30.0) -> None:
    """After a pause (at monotonic time ``paused_at``): wait until every message the simulator says it published
    on the collector's topics has reached the collector and, with ``recorder``, reached the recorder (written, or
    counted as not written after a write failure)."""
    def counts() -> tuple[dict, dict, dict]:
        sim = diagnostics.of("rimd_simulator", since=paused_at)
        rec = diagnostics.of("rimd_recorder", since=paused_at)
        published = {t: int(sim.get(f"{t} published", -1)) for t in collector.messages}
        received = {t: len(m) for t, m in collector.messages.items()}
        written = {t: int(rec.get(f"{t} written", -1)) + int(rec.get(f"{t} not_written", 0))
                   for t in collector.messages}
        return published, received, written

    def delivered() -> bool:
        sim = diagnostics.of("rimd_simulator", since=paused_at)
        if sim.get("paused") != "true":
            return False   # counts reported before the pause took effect
        published, received, written = counts()
        return received == published and (not recorder or written == published)

    assert spin_until(executor, delivered, timeout), "published / received / written: " + str(counts())


def start_rig(ros_processes, out: Path, *recorder_args: str, paused: bool = True):
    recorder = ros_processes.start_node("rimd_recorder", "--ros-args", "-p", f"output_dir:={out}",
                                        "-p", "flush_interval:=0.5", *recorder_args)
    recorder.wait_for_output(r"recording .* into", timeout=30)
    simulator = ros_processes.start_node(
        "rimd_simulator", "--ros-args", "-p", "motor.initial_setpoint:=3.75", "-p", f"start_paused:={paused}")
    simulator.wait_for_output(r"rig ready", timeout=60)
    recorder.wait_for_output(r"recording /rig/truth", timeout=30)
    recorder.wait_for_output(r"recording /rig/impact/events", timeout=30)
    return recorder, simulator


def trigger(executor, node, service: str, timeout: float = 10.0):
    from std_srvs.srv import Trigger

    client = node.create_client(Trigger, service)
    return call_service(executor, node, client, Trigger.Request(), timeout)


def resume_when_matched(executor, collector: RawCollector, replay, topics: Iterable[str] | None = None,
                        timeout: float = 30.0) -> None:
    """Resume a replay started with ``start_paused`` and ``wait_for_subscribers`` once both sides of discovery
    have matched: the replay's (it logs ``subscribers matched on``) and the collector's (on ``topics``, the
    collector's names; default all). Then no first message can be lost, whatever the load of a parallel run."""
    replay.wait_for_output("subscribers matched on", timeout=timeout)
    assert spin_until(executor, lambda: collector.matched(topics), timeout), replay.tail()
    assert trigger(executor, collector.node, "/rimd_replay/resume").success, replay.tail()


def run_for(executor, seconds: float) -> None:
    """Spin for ``seconds`` of wall time: how long a rig runs, never a guess at delivery (wait on a condition)."""
    deadline = time.monotonic() + seconds
    spin_until(executor, lambda: time.monotonic() >= deadline, seconds + 1)


def record_rig(ros_processes, ros_executor, out: Path, seconds: float, *recorder_args: str):
    """Run the rig for ``seconds`` of simulation time with the recorder and a collector; pause it once that
    much reached the collector; return both processes and the collector once every message published has reached
    the collector and been written by the recorder (counted by the simulator and the recorder)."""
    recorder, simulator = start_rig(ros_processes, out, *recorder_args)
    collector = RawCollector(ros_executor)
    diagnostics = Diagnostics(collector.node)
    wait_until_matched(ros_executor, collector, diagnostics, readers=2)
    assert trigger(ros_executor, collector.node, "/rig/resume").success
    blocks = round(seconds * 100)   # /rig/truth: one message per block, 100 blocks/s by default
    assert spin_until(ros_executor, lambda: len(collector.messages["/rig/truth"]) >= blocks, seconds * 3 + 30)
    assert trigger(ros_executor, collector.node, "/rig/pause").success
    wait_until_delivered(ros_executor, collector, diagnostics, time.monotonic())
    return recorder, simulator, collector
