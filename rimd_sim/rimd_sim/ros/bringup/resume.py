"""The open-loop start: resume the paused simulator once its consumers subscribe and it has matched them.

Without lockstep the simulator starts paused (``start_paused``) when the rig has consumers, and
:func:`resume_once_subscribed` resumes it, so that every consumer gets sample 0. It makes a node of its own on the
rig's domain, in an rclpy context of its own, and calls ``/rig/resume`` once each consumer subscribes to every rig
topic (:data:`RIG_TOPICS`) and the simulator's ``/diagnostics`` say that each topic's publisher has matched as many
subscriptions as this process sees. rclpy is imported when the function runs, not with the module.
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Mapping
from typing import Any

__all__ = ["RIG_TOPICS", "resume_once_subscribed"]

#: Topics every open-loop consumer subscribes to before the simulator is resumed.
RIG_TOPICS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force",
              "/rig/impact/events", "/rig/motor/state", "/rig/truth")


def _subscribed(node: Any, topic: str, consumers: tuple[str, ...]) -> bool:
    names = {info.node_name for info in node.get_subscriptions_info_by_topic(topic)}
    return all(name in names for name in consumers)


def resume_once_subscribed(consumers: tuple[str, ...], procs: Mapping[str, subprocess.Popen],
                           timeout: float = 20.0, domain_id: int | None = None) -> bool:
    """Wait until each consumer node subscribes to every rig topic, then call ``/rig/resume``; True when resumed.

    Subscribed in the graph is not yet matched: a volatile topic reaches only the readers its writer has matched,
    and the simulator's own view of the graph can lag this process's under load, so that a consumer would miss
    the first blocks. The resume therefore also waits until the simulator's ``/diagnostics`` say that each rig
    topic's publisher has matched as many subscriptions as the graph shows here.

    Args:
        consumers: The consumer nodes' names; none: resume as soon as the service is served.
        procs: The rig's processes: the wait ends, False, when one of them exits.
        timeout: Seconds to wait.
        domain_id: The rig's ROS domain (default: this process's ``ROS_DOMAIN_ID``).
    """
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.signals import SignalHandlerOptions
    from std_srvs.srv import Trigger

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node("rimd_rig", context=context, start_parameter_services=False)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        matched: dict[str, int] = {}   # topic -> subscriptions its publisher has matched (the simulator says)

        def on_diagnostics(msg: DiagnosticArray) -> None:
            for status in msg.status:
                if "rimd_simulator" in status.name:
                    matched.update({kv.key[:-len(" subscribers")]: int(kv.value) for kv in status.values
                                    if kv.key.endswith(" subscribers")})

        node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
        deadline = time.monotonic() + timeout
        client = node.create_client(Trigger, "/rig/resume")
        while time.monotonic() < deadline and all(p.poll() is None for p in procs.values()):
            if (all(_subscribed(node, t, consumers) for t in RIG_TOPICS) and client.service_is_ready()
                    and (not consumers or all(matched.get(t, -1) >= node.count_subscribers(t) for t in RIG_TOPICS))):
                future = client.call_async(Trigger.Request())
                executor.spin_until_future_complete(future, timeout_sec=5.0)
                return bool(future.done() and future.result().success)
            executor.spin_once(timeout_sec=0.05)
        return False
    finally:
        context.try_shutdown()
