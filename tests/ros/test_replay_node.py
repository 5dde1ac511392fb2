"""The replay node: original timing, rate, loop, selection and remapping, byte-identical data, damaged files.

One recording of the running rig (simulator + recorder, 3 s) is made once for the module, in its own ROS
domain; the rig is then stopped, so every message a test subscriber sees comes from the replay.
"""

from __future__ import annotations

import re
import shutil
import signal
import statistics
from pathlib import Path

import pytest

from harness.domains import lease_domain_id
from harness.processes import ProcessManager
from harness.rig import RIG_TOPICS, Diagnostics, RawCollector, resume_when_matched, trigger
from harness.ros import call_service, spin_until
from rimd_sim.io.reader import open_recording
from rimd_sim.ros.clients.rig import RigClient

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """A recording of 3 s of the rig at gap 0, 3.75 Hz (impacting), made with the real nodes."""
    import os

    root = tmp_path_factory.mktemp("replay_source")
    out = root / "rec"
    with lease_domain_id() as lease:
        env = {**os.environ, "ROS_DOMAIN_ID": str(lease.domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
               "ROS_LOG_DIR": str(root / "log"), "PYTHONUNBUFFERED": "1"}
        with ProcessManager(env, root / "processes") as processes:
            recorder = processes.start_node("rimd_recorder", "--ros-args", "-p", f"output_dir:={out}",
                                            "-p", "topics:=['/rig/.*']")
            recorder.wait_for_output(r"recording .* into", timeout=30)
            simulator = processes.start_node("rimd_simulator", "--ros-args", "-p", "motor.initial_setpoint:=3.75")
            simulator.wait_for_output(r"rig ready", timeout=60)
            recorder.wait_for_output(r"recording /rig/impact/events", timeout=30)
            with RigClient(domain_id=lease.domain_id, name="replay_source_watch") as client:
                diagnostics = Diagnostics(client.node)   # 3 s recorded: 300 truth blocks written
                written = lambda: int(diagnostics.of("rimd_recorder").get("/rig/truth written", 0))  # noqa: E731
                assert client.spin_until(lambda: written() >= 300, 60), diagnostics.of("rimd_recorder")
            recorder.send_signal(signal.SIGINT)
            assert recorder.wait(30) == 0, recorder.tail()
            simulator.stop()
    assert open_recording(out).complete
    return out


def _recorded(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    got: dict[str, list[tuple[int, bytes]]] = {}
    for msg in open_recording(path).messages():
        got.setdefault(msg.topic, []).append((msg.log_time, msg.data))
    return got


def _replay(ros_processes, ros_executor, collector, *params: str, expected: int, timeout: float = 30.0):
    """Run a replay to its end; return it once the collector holds the ``expected`` messages it published (they
    travel after the node has exited: a wait on what arrived, not on time). It starts paused and is resumed once
    both sides of discovery have matched: no first message is lost to the load of a parallel run."""
    args = ["--ros-args", "-p", "wait_for_subscribers:=1", "-p", "start_paused:=true"]
    for param in params:
        args += ["-p", param]
    replay = ros_processes.start_node("rimd_replay", *args)
    resume_when_matched(ros_executor, collector, replay)
    total = lambda: sum(len(v) for v in collector.messages.values())  # noqa: E731
    assert spin_until(ros_executor, lambda: replay.returncode is not None and total() >= expected, timeout), (
        total(), expected, replay.tail())
    return replay


def _count(recorded, topics=RIG_TOPICS) -> int:
    return sum(len(recorded.get(t, [])) for t in topics)


def _timing_errors(recorded, collector, rate: float) -> list[float]:
    """Receive time minus due time (recorded log time / rate), centred on the median offset, in s."""
    pairs = []
    for topic, items in recorded.items():
        for (log_time, _), received in zip(items, collector.times.get(topic, []), strict=False):
            pairs.append((log_time / 1e9 / rate, received))
    offsets = [received - due for due, received in pairs]
    centre = statistics.median(offsets)
    return [abs(o - centre) for o in offsets]


def test_replay_at_1x_keeps_timing_and_bytes(ros_processes, ros_executor, recording):
    recorded = _recorded(recording)
    collector = RawCollector(ros_executor)
    replay = _replay(ros_processes, ros_executor, collector, f"file:={recording}", expected=_count(recorded))
    assert replay.returncode == 0, replay.tail()
    # Its first line counts the recording's messages and names the topics it does not replay (the recorded
    # /rig/session: the replay names its own runs): the last line's count is the difference.
    out = replay.output()
    started = re.search(r"\((\d+) messages in the recording; not replayed: ([^)]*)\)", out)
    finished = re.search(r"replay finished: (\d+) messages published", out)
    assert started and finished, out
    left = started.group(2).split(", ")
    assert "/rig/session" in left and int(started.group(1)) == sum(len(v) for v in recorded.values())
    assert int(finished.group(1)) == int(started.group(1)) - sum(len(recorded.get(t, [])) for t in left)
    for topic in RIG_TOPICS:
        assert collector.messages[topic] == [data for _, data in recorded[topic]], topic   # identical bytes
    errors = _timing_errors(recorded, collector, 1.0)
    assert len(errors) > 1500
    # A coarse bound (the recorded timing, not a burst): the figure, median <= 1 ms, is benchmarks/bench_replay.py's.
    assert statistics.median(errors) <= 20e-3, f"median timing error {statistics.median(errors) * 1e3:.2f} ms"


def test_replay_at_2x_takes_half_the_time(ros_processes, ros_executor, recording):
    recorded = _recorded(recording)
    collector = RawCollector(ros_executor)
    replay = _replay(ros_processes, ros_executor, collector, f"file:={recording}", "rate:=2.0",
                     expected=_count(recorded))
    assert replay.returncode == 0, replay.tail()
    times = collector.times["/rig/truth"]
    logs = [t for t, _ in recorded["/rig/truth"]]
    assert len(times) == len(logs)
    ratio = (times[-1] - times[0]) / ((logs[-1] - logs[0]) / 1e9)
    # Coarse bounds (2x, not 1x nor a burst); the figures (0.5 within 3 %, median <= 1 ms) are bench_replay's.
    assert ratio == pytest.approx(0.5, abs=0.15)
    assert statistics.median(_timing_errors(recorded, collector, 2.0)) <= 20e-3


def test_loop_selection_remap_pause_and_clock(ros_processes, ros_executor, recording):
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock

    recorded = _recorded(recording)
    collector = RawCollector(ros_executor, topics={"/rig/truth": "RigState", "/rig/motor/state": "MotorState"},
                             remap={"/rig/truth": "/replayed/truth"})
    clocks = []
    node = Node("clock_listener", context=ros_executor.context)
    ros_executor.add_node(node)
    node.create_subscription(Clock, "/clock", lambda m: clocks.append(m.clock.sec * 10**9 + m.clock.nanosec), 100)
    replay = ros_processes.start_node(
        "rimd_replay", "--ros-args", "-p", f"file:={recording}", "-p", "loop:=true", "-p", "rate:=3.0",
        "-p", "topics:=['/rig/truth']", "-p", "remap:=['/rig/truth:=/replayed/truth']", "-p", "clock:=true",
        "-p", "wait_for_subscribers:=1", "-p", "start_paused:=true")
    resume_when_matched(ros_executor, collector, replay, topics=["/rig/truth"])
    truth = collector.messages["/rig/truth"]   # keyed by the original name, subscribed to /replayed/truth
    # 3 s at 3x: a pass takes about 1 s once the node runs (start-up takes longer on a loaded machine).
    assert spin_until(ros_executor, lambda: len(truth) > 1.5 * len(recorded["/rig/truth"]), 30), replay.tail()
    assert truth[len(recorded["/rig/truth"])] == recorded["/rig/truth"][0][1]       # the loop starts over
    assert not collector.messages["/rig/motor/state"]                                # not selected
    assert clocks and clocks[0] >= recorded["/rig/truth"][0][0] - 10**7

    # Paused: the replay says how many messages it had published; exactly those arrive, then one more per
    # play_next, and the replay's own count confirms that nothing else left while paused.
    paused = trigger(ros_executor, node, "/rimd_replay/pause")
    count = int(re.fullmatch(r"paused after (\d+) messages published", paused.message).group(1))
    assert spin_until(ros_executor, lambda: len(truth) >= count, 10) and len(truth) == count
    from rimd_msgs.srv import PlayNext

    client = node.create_client(PlayNext, "/rimd_replay/play_next")
    assert call_service(ros_executor, node, client, PlayNext.Request(), 10).success
    assert spin_until(ros_executor, lambda: len(truth) >= count + 1, 10) and len(truth) == count + 1
    again = trigger(ros_executor, node, "/rimd_replay/pause")
    assert not again.success and again.message == f"already paused ({count + 1} messages published)"
    assert trigger(ros_executor, node, "/rimd_replay/resume").success
    assert spin_until(ros_executor, lambda: len(truth) > count + 1, 10)               # going again
    replay.send_signal(signal.SIGINT)
    assert replay.wait(10) == 0


def test_truncated_recording_replays_what_is_valid(ros_processes, ros_executor, recording, tmp_path):
    (source,) = recording.glob("*.mcap")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(source.read_bytes()[: source.stat().st_size // 2])
    # Every readable message but the recorded /rig/session: the replay names its own runs there.
    readable = sum(1 for m in open_recording(cut).messages() if m.topic != "/rig/session")
    collector = RawCollector(ros_executor)
    replay = _replay(ros_processes, ros_executor, collector, f"file:={cut}", "rate:=4.0",
                     expected=sum(1 for m in open_recording(cut).messages() if m.topic in RIG_TOPICS))
    assert replay.returncode == 0, replay.tail()
    output = replay.output()
    assert "cut.mcap: incomplete" in output and f"read {open_recording(cut).message_count} messages" in output
    assert "Traceback" not in output
    assert sum(len(v) for v in collector.messages.values()) == readable > 0


def test_garbage_and_unknown_types_are_named(ros_processes, tmp_path, recording):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"\x00garbage" * 1000)
    bad = ros_processes.start_node("rimd_replay", "--ros-args", "-p", f"file:={garbage}", name="garbage")
    assert bad.wait(30) == 1
    assert "garbage.mcap is not an MCAP file" in bad.output() and "Traceback" not in bad.output()

    # A recording with a type this machine does not have (as from another lab's package).
    from rimd_sim.io.bag import BagWriter, TopicInfo, qos_profile_dict
    from rimd_sim.io.msgdefs import MessageDefinition

    unknown_dir = tmp_path / "unknown"
    shutil.copytree(recording, unknown_dir)
    bag = BagWriter(unknown_dir, prefix="other")
    bag.topics["/lab/gauge"] = TopicInfo("/lab/gauge", "lab_msgs/msg/Gauge", [qos_profile_dict()],
                                         MessageDefinition("lab_msgs/msg/Gauge", "float64 strain\n", ""))
    bag.write("/lab/gauge", b"\x00\x01\x00\x00" + b"\x00" * 8, 10**18)
    bag.close()
    refused = ros_processes.start_node("rimd_replay", "--ros-args", "-p", f"file:={unknown_dir}", name="unknown")
    assert refused.wait(30) == 1
    output = refused.output()
    assert "lab_msgs/msg/Gauge (/lab/gauge)" in output and "not installed" in output
    assert "skip_unknown" in output and "Traceback" not in output

    missing = ros_processes.start_node("rimd_replay", "--ros-args", "-p", "rate:=0.0",
                                       "-p", f"file:={recording}", name="bad_rate")
    assert missing.wait(30) == 1 and "parameter 'rate' = 0.0 refused: must be > 0" in missing.output()


def test_start_offset_skips_the_beginning(ros_processes, ros_executor, recording):
    recorded = _recorded(recording)
    collector = RawCollector(ros_executor, topics={"/rig/truth": "RigState"})
    first_log = min(items[0][0] for items in recorded.values())   # the offset counts from the first message
    expected = [data for log_time, data in recorded["/rig/truth"] if log_time - first_log >= 1_500_000_000]
    replay = _replay(ros_processes, ros_executor, collector, f"file:={recording}", "rate:=4.0",
                     "start_offset:=1.5", "topics:=['/rig/truth']", expected=len(expected))
    assert replay.returncode == 0, replay.tail()
    assert collector.messages["/rig/truth"] == expected and 0 < len(expected) < len(recorded["/rig/truth"])


def test_a_subscriber_that_stops_acknowledging_is_named_and_the_replay_still_ends(ros_processes, recording,
                                                                                    tmp_path):
    """A reliable subscriber frozen mid-replay (SIGSTOP) never acknowledges the last messages: the replay waits
    a bounded time for it at the end, names its topic, and exits 0 (it does not hang on a dead consumer)."""
    import os

    from harness import daq_client
    from rimd_sim.ros.nodes.replay import ACKNOWLEDGE_WAIT_S

    topic = "/rig/cart/displacement"
    replay = ros_processes.start_node("rimd_replay", "--ros-args", "-p", f"file:={recording}",
                                      "-p", f"topics:=['{topic}']", "-p", "wait_for_subscribers:=1")
    client = ros_processes.start_python(daq_client.__file__, str(tmp_path / "out.pkl"), "--until", "1e6",
                                        "--topics", topic, "--extra", "--timeout", "60")
    # Both sides of the match, before the replay's 3 s of messages have all left.
    client.wait_for_output("daq ready", timeout=30)                          # the subscription's side
    replay.wait_for_output(f"subscribers matched on {topic}", timeout=30)    # the publisher's side
    os.kill(client.pid, signal.SIGSTOP)
    try:
        assert replay.wait(60) == 0, replay.tail()
    finally:
        os.kill(client.pid, signal.SIGCONT)
    assert (f"not acknowledged within {ACKNOWLEDGE_WAIT_S:g} s by every subscriber: {topic}: they may miss the "
            "last messages") in replay.output(), replay.tail()
