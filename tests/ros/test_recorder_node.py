"""The recorder node on the running rig: real processes over DDS, real files read by independent readers.

Each test starts the simulator paused (``start_paused``), lets the recorder and a test subscriber connect,
then resumes it, so that every published block (from sample 0) is expected in the recording: the counts are
checked from ``first_index`` (contiguous from 0 to the last block) and, message by message, against the
bytes the test subscriber received.
"""

from __future__ import annotations

import signal

import pytest

from harness.bags import read_with_mcap_ros2, read_with_rosbags
from harness.rig import BLOCK_TOPICS, RIG_TOPICS, Diagnostics, record_rig, start_rig, trigger
from harness.ros import spin_until
from rimd_sim.io.cdr import block_span
from rimd_sim.io.reader import open_recording

pytestmark = pytest.mark.ros

def _check_contiguous_from_zero(blocks: list[bytes]) -> int:
    expected = 0
    for data in blocks:
        first, count = block_span(data)
        assert first == expected, f"block at {first}, expected {expected}"
        expected = first + count
    return expected


def test_records_5_s_of_the_rig_completely(ros_processes, ros_executor, tmp_path):
    out = tmp_path / "rec"
    recorder, _, collector = record_rig(ros_processes, ros_executor, out, 5.0)
    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(30) == 0
    assert "no loss" in recorder.output() and "LOSS" not in recorder.output()

    (path,) = out.glob("*.mcap")
    recorded = read_with_mcap_ros2(path)
    by_topic: dict[str, list[bytes]] = {}
    for topic, data, _, _ in recorded:
        by_topic.setdefault(topic, []).append(data)
    for topic in BLOCK_TOPICS:
        # Every block published from sample 0 on, in order, none missing: what the rig published.
        samples = _check_contiguous_from_zero(by_topic[topic])
        assert samples > 0
        assert by_topic[topic] == collector.messages[topic], topic
    assert len(by_topic["/rig/truth"]) >= 475   # 5 s at 100 blocks/s
    for topic in ("/rig/motor/state", "/rig/impact/events"):
        assert by_topic[topic] == collector.messages[topic], topic
    assert len(by_topic["/rig/impact/events"]) >= 10   # one impact per cycle at 3.75 Hz, from about 2 s

    # Every message decodes, with both independent readers, to the values published.
    decoded = {(topic, data): msg for topic, data, _, msg in recorded}
    from rclpy.serialization import deserialize_message

    import rimd_msgs.msg
    for topic in ("/rig/impact/force", "/rig/impact/events", "/rig/truth"):
        cls = getattr(rimd_msgs.msg, RIG_TOPICS[topic])
        for data in collector.messages[topic][::25]:
            original = deserialize_message(data, cls)
            copy = decoded[(topic, data)]
            if hasattr(original, "samples"):
                assert list(copy.samples) == list(original.samples) and copy.first_index == original.first_index
            elif hasattr(original, "theta"):
                assert list(copy.theta) == list(original.theta) and list(copy.in_contact) == list(original.in_contact)
            else:
                assert (copy.peak_force, copy.index, copy.header.stamp.nanosec) == (
                    original.peak_force, original.index, original.header.stamp.nanosec)
    counts, via_rosbags = read_with_rosbags(out)
    assert [(t, d) for t, d, _, _ in via_rosbags] == [(t, d) for t, d, _, _ in recorded]
    assert counts["/rig/impact/force"] == len(collector.messages["/rig/impact/force"])
    force = [m for t, _, _, m in via_rosbags if t == "/rig/impact/force"]
    assert max(max(m.samples) for m in force) > 50.0   # the impacts are in the recorded force channel

    recording = open_recording(out)
    assert recording.complete
    # publish_time is the DDS source timestamp of each message (the message info the recorder asks rclpy for,
    # whatever the executor), stamped on the same host clock before the recorder received it (log_time).
    times = [(m.publish_time, m.log_time) for m in recording.messages()]
    assert times and all(0 < publish <= log for publish, log in times), times[:5]
    assert "rimd_rig_parameters" in recording.metadata and recording.metadata["rimd_rig_parameters"]["gap"] == "0.0"
    assert recording.metadata["rimd_recording"]["software"].startswith("rimd_sim ")


@pytest.mark.parametrize("how", ["SIGTERM", "SIGKILL"])
def test_stopped_by_a_signal(ros_processes, ros_executor, tmp_path, how):
    out = tmp_path / "rec"
    chunk = 64 * 1024
    recorder, _, collector = record_rig(ros_processes, ros_executor, out, 3.0,
                                     "-p", f"chunk_size:={chunk}", "-p", "flush_interval:=100.0")
    recorder.send_signal(getattr(signal, how))
    recorder.wait(30)
    recording = open_recording(out)
    got = {}
    for msg in recording.messages():
        got.setdefault(msg.topic, []).append(msg.data)
    if how == "SIGTERM":
        assert recording.complete, [r.describe() for r in recording.reports]
        for topic in RIG_TOPICS:
            assert got[topic] == collector.messages[topic], topic
        return
    # SIGKILL: no summary, but everything up to the last finished chunk reads back, in order, and what is
    # missing is at most one chunk's worth of bytes.
    assert not recording.complete
    lost = 0
    for topic, sent in collector.messages.items():
        kept = got.get(topic, [])
        assert kept == sent[:len(kept)], topic
        lost += sum(len(d) for d in sent[len(kept):])
    assert 0 < recording.message_count
    assert lost <= chunk + 8192, f"{lost} bytes lost with chunks of {chunk}"


def test_split_by_duration_is_seamless(ros_processes, ros_executor, tmp_path):
    out = tmp_path / "rec"
    recorder, _, collector = record_rig(ros_processes, ros_executor, out, 5.0, "-p", "max_duration:=1.5")
    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(30) == 0
    recording = open_recording(out)
    assert len(recording.files) >= 3 and recording.complete
    names = [f.name for f in recording.files]
    assert [int(n.rsplit("_", 1)[1].split(".")[0]) for n in names] == list(range(len(names)))
    got: dict[str, list[bytes]] = {}
    for msg in recording.messages():
        got.setdefault(msg.topic, []).append(msg.data)
    for topic in RIG_TOPICS:
        assert got[topic] == collector.messages[topic], topic   # none missing or duplicated at boundaries
    for topic in BLOCK_TOPICS:
        _check_contiguous_from_zero(got[topic])
    for path in recording.files[:-1]:
        messages = read_with_mcap_ros2(path)
        span = (messages[-1][2] - messages[0][2]) / 1e9
        assert span < 1.5


def test_services_and_refusals(ros_processes, ros_executor, tmp_path):
    bad = ros_processes.start_node("rimd_recorder", "--ros-args", "-p", "compression:=rar",
                                   "-p", f"output_dir:={tmp_path / 'x'}", name="bad_recorder")
    assert bad.wait(30) == 2
    assert "parameter 'compression' = 'rar' refused: must be one of: zstd, lz4, none" in bad.output()
    assert "Traceback" not in bad.output()

    out = tmp_path / "rec"
    recorder, _ = start_rig(ros_processes, out, "-p", "start_paused:=true", paused=False)
    from rclpy.node import Node

    node = Node("test_client", context=ros_executor.context)
    ros_executor.add_node(node)
    diagnostics = Diagnostics(node)

    def recorder_says(key: str, above: int) -> int:
        """Wait until the recorder reports ``key`` above ``above`` (what it did, not a guess of time)."""
        value = lambda: int(diagnostics.of("rimd_recorder").get(key, -1))  # noqa: E731
        assert spin_until(ros_executor, lambda: value() > above, 30), (key, diagnostics.of("rimd_recorder"))
        return value()

    skipped = recorder_says("not_recorded_while_paused_or_stopped", 0)   # the rig's messages arrive...
    assert not list(out.glob("*.mcap"))                                  # ...paused: nothing recorded
    assert trigger(ros_executor, node, "/rimd_recorder/resume").success
    written = recorder_says("messages_written", 0)
    response = trigger(ros_executor, node, "/rimd_recorder/split")
    assert response.success and "finished" in response.message
    recorder_says("messages_written", written)
    # That report came after the resume: its count of messages not recorded is the paused phase's, final (the
    # first one above can be an earlier report's, lower: more came while still paused); the stop's must pass it.
    skipped = int(diagnostics.of("rimd_recorder")["not_recorded_while_paused_or_stopped"])
    response = trigger(ros_executor, node, "/rimd_recorder/stop")
    assert response.success
    assert not trigger(ros_executor, node, "/rimd_recorder/stop").success    # already stopped
    files = sorted(out.glob("*.mcap"))
    assert len(files) == 2
    recorder_says("not_recorded_while_paused_or_stopped", skipped)          # messages arrive while stopped...
    assert len(list(out.glob("*.mcap"))) == 2                                # ...and no new file
    written = recorder_says("messages_written", -1)
    assert trigger(ros_executor, node, "/rimd_recorder/start").success
    recorder_says("messages_written", written)
    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(30) == 0
    recording = open_recording(out)
    assert len(recording.files) == 3 and recording.complete
    # Loss accounting sees the stop/start gap in first_index and reports it, per topic.
    assert "LOSS" in recorder.output() and "samples missing" in recorder.output()


def test_records_completely_under_rclpys_single_threaded_executor(ros_processes, ros_executor, tmp_path):
    """RIMD_EXECUTOR=single (rclpy's SingleThreadedExecutor, the fallback to the events executor): the same
    complete recording, with each message's source timestamp."""
    ros_processes.env["RIMD_EXECUTOR"] = "single"
    out = tmp_path / "rec"
    recorder, _, collector = record_rig(ros_processes, ros_executor, out, 3.0)
    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(30) == 0
    assert "no loss" in recorder.output() and "LOSS" not in recorder.output()
    recording = open_recording(out)
    by_topic: dict[str, list[bytes]] = {}
    for m in recording.messages():
        by_topic.setdefault(m.topic, []).append(m.data)
        assert 0 < m.publish_time <= m.log_time
    for topic in BLOCK_TOPICS:
        assert _check_contiguous_from_zero(by_topic[topic]) > 0
        assert by_topic[topic] == collector.messages[topic], topic
