"""The replay driven like rosbag2's player, over DDS, and the replay's small refusals.

Hypotheses, with the replay node in its own process and a subscriber here: while paused, ``~/play_next``
publishes exactly one message and ``~/burst`` exactly N (none while playing); ``~/seek`` lands on the first
message recorded at or after the time (and refuses a time outside the recording, naming it); ``~/get_rate``,
``~/set_rate`` and ``~/is_paused`` answer as rosbag2's do, and a refused rate changes nothing;
``~/toggle_paused`` resumes; an integer ``rate`` is a rate; ``playback_duration`` stops the replay there;
``restamp`` makes the first message's stamp the wall time it left, every other stamp shifted by as much;
``wait_for_subscribers`` names the topics it waits for. The pace itself is tested on a fake clock
(tests/runtime/test_player.py); here only a coarse sanity bound of it.
"""

from __future__ import annotations

import time

import pytest
from builtin_interfaces.msg import Time

from harness.rig import RawCollector, resume_when_matched
from harness.rig_mcap import write_rig_mcap
from harness.ros import call_service, spin_until
from rimd_sim.io.cdr import header_stamp
from rimd_sim.io.reader import open_recording

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay_services") / "rig.mcap"
    write_rig_mcap(path, seconds=2.0)
    return path


def _call(ros_executor, node, srv, name, request=None):
    client = node.create_client(srv, f"/rimd_replay/{name}")
    return call_service(ros_executor, node, client, request or srv.Request(), timeout=10)


def _received(collector: RawCollector) -> int:
    return sum(len(v) for v in collector.messages.values())


def test_player_services_as_rosbag2(ros_processes, ros_executor, recording):
    from std_srvs.srv import Trigger

    from rimd_msgs.srv import Burst, GetRate, GetReplayState, IsPaused, PlayNext, Seek, SetRate

    messages = list(open_recording(recording).messages())
    collector = RawCollector(ros_executor)
    node = collector.node
    replay = ros_processes.start_node("rimd_replay", "--ros-args", "-p", f"file:={recording}",
                                      "-p", "start_paused:=true", "-p", "rate:=2", "-p", "wait_for_subscribers:=1")
    replay.wait_for_output(r"replaying \d+ topics .* at 2x", timeout=30)   # an integer rate is a rate
    replay.wait_for_output(r"subscribers matched on /rig/", timeout=30)    # it names the topics it waited for
    assert _call(ros_executor, node, IsPaused, "is_paused").paused
    assert _call(ros_executor, node, GetRate, "get_rate").rate == 2.0

    assert _call(ros_executor, node, PlayNext, "play_next").success
    assert spin_until(ros_executor, lambda: _received(collector) >= 1, 10)
    spin_until(ros_executor, lambda: False, 0.3)   # a window for a wrong second message to show
    assert _received(collector) == 1
    assert _call(ros_executor, node, Burst, "burst", Burst.Request(num_messages=25)).actually_burst == 25
    assert spin_until(ros_executor, lambda: _received(collector) >= 26, 10)
    spin_until(ros_executor, lambda: False, 0.3)
    assert _received(collector) == 26

    # Seek: between two log times, it lands on the first message at or after.
    logs = sorted({m.log_time for m in messages})
    middle = len(logs) // 2
    target = (logs[middle] + logs[middle + 1]) // 2
    result = _call(ros_executor, node, Seek, "seek", Seek.Request(time=Time(sec=target // 10**9,
                                                                          nanosec=target % 10**9)))
    assert result.success, result.message
    before = {t: len(v) for t, v in collector.messages.items()}
    assert _call(ros_executor, node, PlayNext, "play_next").success
    assert spin_until(ros_executor, lambda: _received(collector) >= 27, 10)
    (topic,) = [t for t, v in collector.messages.items() if len(v) > before[t]]
    landed = [m for m in messages if m.log_time >= target][0]
    assert (topic, collector.messages[topic][-1]) == (landed.topic, landed.data)
    beyond = messages[-1].log_time + 10 * 10**9
    refused = _call(ros_executor, node, Seek, "seek", Seek.Request(time=Time(sec=beyond // 10**9,
                                                                           nanosec=beyond % 10**9)))
    assert not refused.success and "refused: must be a recorded log time within" in refused.message

    bad = _call(ros_executor, node, SetRate, "set_rate", SetRate.Request(rate=-1.0))
    assert not bad.success and "rate = -1.0 refused: must be > 0" in bad.message
    assert _call(ros_executor, node, SetRate, "set_rate", SetRate.Request(rate=4.0)).success
    assert _call(ros_executor, node, GetRate, "get_rate").rate == 4.0

    # Resume (toggle) at 0.05x, so that the checks made while it plays cannot race the end of the playback (at 4x
    # the rest lasts a quarter of a second, shorter than three service calls on a loaded machine).
    assert _call(ros_executor, node, SetRate, "set_rate", SetRate.Request(rate=0.05)).success
    assert _call(ros_executor, node, Trigger, "toggle_paused").message == "resumed"
    assert not _call(ros_executor, node, IsPaused, "is_paused").paused
    assert not _call(ros_executor, node, PlayNext, "play_next").success        # playing: refused
    # The rest at 4x from where it stands, to its end (its pace on a clock: tests/runtime/test_player.py).
    assert _call(ros_executor, node, SetRate, "set_rate", SetRate.Request(rate=4.0)).success
    state = _call(ros_executor, node, GetReplayState, "get_state")
    assert not state.ended and state.rate == 4.0
    assert spin_until(ros_executor, lambda: replay.returncode is not None, 30), replay.tail()
    assert replay.returncode == 0 and "replay finished" in replay.output()


def test_restamp_and_playback_duration(ros_processes, ros_executor, recording):
    collector = RawCollector(ros_executor)
    messages = list(open_recording(recording).messages())
    first = messages[0].log_time
    replay = ros_processes.start_node("rimd_replay", "--ros-args", "-p", f"file:={recording}", "-p", "rate:=4.0",
                                      "-p", "restamp:=true", "-p", "playback_duration:=1.0",
                                      "-p", "wait_for_subscribers:=1", "-p", "start_paused:=true")
    resume_when_matched(ros_executor, collector, replay)
    started = time.time_ns()
    kept = [m for m in messages if m.log_time <= first + 10**9]
    expected = len([m for m in kept if m.topic in collector.messages])   # up to 1 s
    # The replay's end waits for the subscribers' acknowledgements, not for this test to take what arrived: wait
    # for both (at the replay's exit, many of the messages may still be untaken).
    assert spin_until(ros_executor, lambda: replay.returncode is not None and _received(collector) >= expected, 30), (
        _received(collector), expected, replay.tail())
    assert _received(collector) == expected
    force = collector.messages["/rig/impact/force"]
    recorded = [header_stamp(m.data) for m in kept if m.topic == "/rig/impact/force"]
    shifts = {header_stamp(data) - stamp for data, stamp in zip(force, recorded, strict=True)}
    assert len(shifts) == 1                                  # one shift: the data keep their own timing
    fresh = header_stamp(force[0])
    assert started <= fresh <= time.time_ns()                 # the first carries the wall time it left
