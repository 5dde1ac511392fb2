"""The simulator node's publishers: their ROS types and QoS, its diagnostics, and the composed rig's ``send``.

The node (:mod:`rimd_sim.ros.nodes.simulator`) creates one publisher per
:func:`rimd_sim.runtime.publishers.outputs` entry, of the class :func:`message_class` names and with the profile
:func:`qos_profile` gives, and publishes the runtime's statuses as :func:`diagnostic_array`. In the composed rig
(:mod:`rimd_sim.ros.nodes.composed`) it offers each topic to the in-process feed with the QoS its publisher offers
(:func:`offered`), and hands the runtime the ``send`` of :func:`feeding_send`: to the in-process consumers first,
then on DDS.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from rimd_sim.ros.nodes.feed import InProcessFeed
from rimd_sim.ros.nodes.outbox import Outbox
from rimd_sim.runtime.plain import plain
from rimd_sim.runtime.publishers import Qos
from rimd_sim.runtime.sim_answers import Status

__all__ = ["diagnostic_array", "feeding_send", "message_class", "offered", "qos_profile"]


def qos_profile(qos: Qos) -> QoSProfile:
    """The ROS QoS profile of the runtime's :class:`Qos` (keep last; the other policies ROS's defaults)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=qos.depth,
                      reliability=ReliabilityPolicy.RELIABLE if qos.reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.latched else DurabilityPolicy.VOLATILE)


def message_class(type_name: str) -> type:
    """The message class of ``package/msg/Name``."""
    package, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def diagnostic_array(statuses: Iterable[Status], stamp: Any) -> DiagnosticArray:
    """The ``/diagnostics`` message of the runtime's statuses, its header stamped ``stamp`` (a ROS ``Time``)."""
    arr = DiagnosticArray()
    arr.header.stamp = stamp
    arr.status = [DiagnosticStatus(level=bytes([s.level]), name=s.name, message=s.message, hardware_id=s.hardware_id,
                                   values=[KeyValue(key=k, value=v) for k, v in s.values.items()])
                  for s in statuses]
    return arr


def offered(node: Node, pub: Any, timeout: float) -> list[QoSProfile]:
    """The QoS ``node``'s publisher ``pub`` offers, as the graph shows it to a recorder.

    A recorder stores it with the channel. When the graph does not show the publisher within ``timeout`` s: the
    publisher's own profile.
    """
    deadline = time.monotonic() + timeout
    me = node.get_fully_qualified_name()
    while True:
        mine = [i.qos_profile for i in node.get_publishers_info_by_topic(pub.topic_name)
                if i.node_namespace.rstrip("/") + "/" + i.node_name == me]
        if mine or time.monotonic() > deadline:
            return mine or [pub.qos_profile]
        time.sleep(0.005)


def feeding_send(feed: InProcessFeed, pubs: Mapping[str, Any],
                 latched: set[str]) -> tuple[Outbox | None, Callable[[str, bytes], None]]:
    """The composed rig's ``send(key, data)``: to the in-process consumers, then on DDS; and its outbox.

    The DDS writes go through an :class:`~rimd_sim.ros.nodes.outbox.Outbox` (without the GIL, and on a thread of
    their own when the rig runs fast), which the caller flushes after each pass of the pacing loop; a message of a
    volatile topic that no other process reads is not written at all. ``pubs``: output key -> publisher;
    ``latched``: the keys of the transient local topics (always written: a later reader gets them from the
    history). With ``RIMD_PLAIN=outbox`` (a benchmarking switch, :mod:`rimd_sim.runtime.plain`) there is no
    outbox (None): rclpy's ``publish`` writes each message on the caller's thread as it is sent.
    """
    outbox = None if plain("outbox") else Outbox()
    # (topic, writer, the publisher when its topic is volatile) per key
    writers: dict[str, tuple[str, Any, Any]] = {
        key: (pub.topic_name, pub.publish if outbox is None else outbox.writer(pub), None if key in latched else pub)
        for key, pub in pubs.items()}
    hand_over = feed.send
    post = (lambda write, data: write(data)) if outbox is None else outbox.send

    def send(key: str, data: bytes) -> None:
        topic, writer, volatile = writers[key]
        hand_over(topic, data)
        # A volatile message reaches only the readers matched when it is written: with none (no process but
        # this one takes the topic) the write would be for nobody, and the rig skips it. A reader matched
        # just after the check is one matched just after the write, as DDS discovery makes it anyway.
        if volatile is None or volatile.get_subscription_count():
            post(writer, data)

    return outbox, send
