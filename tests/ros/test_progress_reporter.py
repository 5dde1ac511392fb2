"""The progress reporter of a user's DAQ node, in-process over DDS: what it says when it cannot join.

Hypothesis: a subscription on a misspelt topic matches no publisher, so the reporter never joins and a rig in
lockstep waits for it before its first block, silently on the DAQ's side (a node on ``/rig/impact_force``
would print nothing and time out). Once a lockstep publisher listens and a subscription has
gone ``unmatched_warning`` seconds without a publisher, the reporter's node warns, naming that topic and the
published topics of its type; a reporter whose subscriptions all matched joins and says nothing.
"""

from __future__ import annotations

import time

import pytest

pytestmark = [pytest.mark.ros]


def test_a_misspelt_topic_is_named_with_the_published_topics_of_its_type(ros_executor, capfd):
    from rclpy.node import Node

    from rimd_msgs.msg import ConsumerProgress, SampleBlock
    from rimd_sim.ros.clients.progress import PROGRESS_QOS, PROGRESS_TOPIC, ProgressReporter

    context = ros_executor.context
    # The rig's side: a lockstep publisher listens for progress, and the force channel is published.
    rig = Node("rig_side", context=context)
    joined = []
    rig.create_subscription(ConsumerProgress, PROGRESS_TOPIC, lambda m: joined.append(m.consumer), PROGRESS_QOS)
    rig.create_publisher(SampleBlock, "/rig/impact/force", 10)
    misspelt = Node("misspelt_daq", context=context)
    subs = [misspelt.create_subscription(SampleBlock, topic, lambda m: None, 10)
            for topic in ("/rig/impact/force", "/rig/impact_force")]
    ProgressReporter(misspelt, "misspelt_daq", subscriptions=subs, unmatched_warning=0.5)
    right = Node("right_daq", context=context)
    sub = right.create_subscription(SampleBlock, "/rig/impact/force", lambda m: None, 10)
    ProgressReporter(right, "right_daq", subscriptions=[sub], unmatched_warning=0.5)
    for node in (rig, misspelt, right):
        ros_executor.add_node(node)
    said = ""
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and not ("misspelt_daq: no publisher" in said and "right_daq" in joined):
        ros_executor.spin_once(timeout_sec=0.05)
        said += capfd.readouterr().err
    assert "right_daq" in joined and "misspelt_daq" not in joined, joined
    assert ("misspelt_daq: no publisher after 0.5 s on /rig/impact_force (rimd_msgs/msg/SampleBlock; published "
            "topics of that type: /rig/impact/force). A rig in lockstep waits for this consumer") in said, said
    assert "/rig/impact/force (" not in said and "right_daq: no publisher" not in said, said
