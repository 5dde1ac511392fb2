"""Foxglove, live (docs/foxglove.md): the bridge's Foxglove WebSocket server against a running rig.

The client is the test process (:mod:`tests.harness.foxglove_client`, on the ``websockets`` library, written
from the protocol's specification); the simulator and the bridge run as separate processes over DDS. What a
client receives is decoded with ``mcap_ros2`` (an independent ROS 2 CDR decoder) from the schema the server
advertised, never with the rig's own code.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from mcap_ros2._dynamic import generate_dynamic
from rclpy.serialization import deserialize_message, serialize_message

from harness.foxglove_client import FoxgloveClient
from rimd_msgs.srv import SetMotorFrequency

#: Every topic the simulator publishes by default (docs/interface.md, Topics), with its type.
RIG_TOPICS = {
    "/rig/cart/displacement": "rimd_msgs/msg/SampleBlock",
    "/rig/rimd/displacement": "rimd_msgs/msg/SampleBlock",
    "/rig/rimd/acceleration": "rimd_msgs/msg/SampleBlock",
    "/rig/impact/force": "rimd_msgs/msg/SampleBlock",
    "/rig/impact/events": "rimd_msgs/msg/ImpactEvent",
    "/rig/motor/state": "rimd_msgs/msg/MotorState",
    "/rig/truth": "rimd_msgs/msg/RigState",
    "/rig/faults": "rimd_msgs/msg/FaultEvent",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}
RIG_SERVICES = {"/rig/set_motor_frequency", "/rig/perturb", "/rig/inject_fault", "/rig/clear_faults", "/rig/pause",
                "/rig/resume", "/rig/reset"}
FORCE_RATE_HZ = 20_000   # config/rimd.yaml: the force sensor's sample rate (20 kHz)


def _decoder(schema: dict):
    """The mcap_ros2 decoder of an advertised channel or service message, built from its schema text alone."""
    return generate_dynamic(schema["schemaName"], schema["schema"])[schema["schemaName"]]


def _start_rig(ros_processes, *bridge_args: str):
    sim = ros_processes.start_node("rimd_simulator", "--ros-args", "-p", "motor.initial_frequency:=3.75")
    bridge = ros_processes.start_node("rimd_rerun", "--ros-args", "-p", "foxglove.enabled:=true",
                                      "-p", "foxglove.port:=0", *bridge_args)
    url = bridge.wait_for_output(r"foxglove server ready: (ws://\S+)", timeout=60).group(1)
    sim.wait_for_output(r"rig ready", timeout=90)
    return sim, bridge, url


@pytest.mark.ros
@pytest.mark.timeout(150)
def test_a_client_gets_every_rig_topic_with_its_schema_and_the_force_blocks_on_the_grid(ros_processes, tmp_path):
    # Both sinks at once: Rerun (an .rrd) and Foxglove share the bridge's subscriptions.
    sim, bridge, url = _start_rig(ros_processes, "-p", "sink:=save", "-p", f"save_path:={tmp_path / 'b.rrd'}")
    with FoxgloveClient(url) as client:
        info = client.wait_for(lambda r: r.server_info, 10, "serverInfo")
        assert {"time", "services", "parameters"} <= set(info["capabilities"]), info
        assert "cdr" in info["supportedEncodings"]
        # The bridge discovers the topics it does not share with Rerun within a second of their appearing.
        channels = client.wait_for(
            lambda r: all(client.channel(t) for t in RIG_TOPICS) and {t: client.channel(t) for t in RIG_TOPICS},
            20, f"channels {sorted(RIG_TOPICS)}")
        for topic, channel in channels.items():
            assert (channel["encoding"], channel["schemaEncoding"], channel["schemaName"]) == \
                ("cdr", "ros2msg", RIG_TOPICS[topic]), channel
            _decoder(channel)   # the schema alone, dependencies included, is enough to build a decoder
        assert "MSG: std_msgs/Header" in channels["/rig/impact/force"]["schema"]
        assert "MSG: builtin_interfaces/Time" in channels["/rig/impact/force"]["schema"]
        assert RIG_SERVICES <= set(client.wait_for(lambda r: len(r.services) >= 7 and r.services, 10, "services"))

        force = _decoder(channels["/rig/impact/force"])
        subscription = client.subscribe(channels["/rig/impact/force"]["id"])
        client.wait_for(lambda r: len(r.messages.get(subscription, ())) >= 100, 30, "100 force blocks")
        blocks = [force(data) for _, data in list(client.received.messages[subscription])]
        # Contiguous first_index (no block lost or repeated) and every stamp on the 20 kHz grid of the first:
        # sample n at t0 + n / rate, so 50 us per sample exactly (docs/interface.md, Conventions).
        for before, after in zip(blocks, blocks[1:], strict=False):
            assert after.first_index == before.first_index + len(before.samples), after.first_index
        first = blocks[0]
        stamp0 = first.header.stamp.sec * 10**9 + first.header.stamp.nanosec
        for block in blocks:
            assert block.sample_rate == FORCE_RATE_HZ
            stamp = block.header.stamp.sec * 10**9 + block.header.stamp.nanosec
            assert stamp - stamp0 == (block.first_index - first.first_index) * (10**9 // FORCE_RATE_HZ)
        assert max(max(b.samples) for b in blocks) > 10.0, "impacts (tens of N) in 1 s of band A at 3.75 Hz"
        # The rig clock is broadcast (the Time capability), moving forward.
        times = client.wait_for(lambda r: len(r.times) >= 10 and list(r.times), 10, "time broadcasts")
        assert times == sorted(times) and times[-1] > times[0]
    assert bridge.stop() == 0, bridge.tail()
    assert re.search(r"rimd_rerun: closed the Foxglove server .*: \d+ messages forwarded", bridge.output())
    assert re.search(r"rimd_rerun: closed .*impact_force \d+ samples", bridge.output()), bridge.tail()
    assert sim.stop() == 0


@pytest.mark.ros
@pytest.mark.timeout(150)
def test_a_client_commands_the_motor_and_sets_parameters_with_the_nodes_answers(ros_processes):
    _sim, bridge, url = _start_rig(ros_processes, "-p", "rerun:=false")
    with FoxgloveClient(url) as client:
        client.wait_for(lambda r: "/rig/set_motor_frequency" in r.services, 10, "the service advertised")
        service = client.received.services["/rig/set_motor_frequency"]
        assert (service["type"], service["request"]["schemaName"], service["response"]["encoding"]) == \
            ("rimd_msgs/srv/SetMotorFrequency", "rimd_msgs/srv/SetMotorFrequency_Request", "cdr")
        response_type = _decoder(service["response"])

        def call(frequency_hz: float, ramp_rate: float = 0.0):
            request = SetMotorFrequency.Request(frequency_hz=frequency_hz, ramp_rate=ramp_rate)
            call_id = client.call_service("/rig/set_motor_frequency", bytes(serialize_message(request)))
            encoding, payload = client.wait_for(lambda r: r.responses.get(call_id), 10, "the service's response")
            assert encoding == "cdr"
            assert response_type(payload) is not None   # decodes with the advertised response schema
            return deserialize_message(payload, SetMotorFrequency.Response)

        motor = client.wait_for(lambda r: client.channel("/rig/motor/state"), 10, "motor state channel")
        state = _decoder(motor)
        subscription = client.subscribe(motor["id"])
        answer = call(5.0, ramp_rate=50.0)
        assert answer.success and answer.frequency_hz == 5.0, answer
        # The motor follows: the setpoint at once, the actual frequency within the 0.025 s ramp (1.25 Hz at 50 Hz/s).
        try:
            client.wait_for(lambda r: any(state(d).frequency_setpoint == 5.0 and abs(state(d).frequency - 5.0) < 1e-9
                                          for _, d in r.messages.get(subscription, ())), 15, "motor at 5 Hz")
        except AssertionError as failure:   # say what did arrive
            states = [state(d) for _, d in client.received.messages.get(subscription, ())]
            got = [(m.frequency_setpoint, m.frequency) for m in states]
            raise AssertionError(f"{failure}: {len(got)} motor states on the subscription, the last {got[-3:]}; "
                                 f"bridge: {bridge.tail()}") from None
        refused = call(-1.0)
        assert not refused.success and refused.frequency_hz == 5.0, refused
        assert refused.message == "frequency_hz = -1.0 refused: must be >= 0"   # the simulator's own words

        # Parameters through the simulator's parameter services, named <node>.<parameter> like foxglove_bridge.
        gap = "/rig/rimd_simulator.gap"
        client.set_parameters([{"name": gap, "value": 0.001, "type": "float64"}], "set-good")
        assert client.wait_for(client.parameters_reply("set-good"), 10, "set reply") == {gap: 0.001}
        client.get_parameters([gap], "get-1")
        assert client.wait_for(client.parameters_reply("get-1"), 10, "get reply") == {gap: 0.001}
        client.set_parameters([{"name": gap, "value": -0.5, "type": "float64"}], "set-bad")
        assert client.wait_for(client.parameters_reply("set-bad"), 10, "set reply") == {gap: 0.001}, "unchanged"
        status = client.wait_for(lambda r: [s for s in r.statuses if gap in s["message"]], 10, "the refusal")
        assert status[0]["level"] == 2, status   # error
        assert "out of range" in status[0]["message"] and "-0.5" in status[0]["message"], status
        client.get_parameters([], "get-all")
        everything = client.wait_for(client.parameters_reply("get-all"), 10, "every parameter")
        assert everything[gap] == 0.001 and everything["/rig/rimd_simulator.contact.model"] == "spring_dashpot"
    assert bridge.stop() == 0, bridge.tail()


def test_bad_addresses_and_a_taken_port_are_refused_in_one_line():
    from rimd_sim.viz.foxglove_sink import FoxgloveError, FoxgloveSink

    with pytest.raises(FoxgloveError, match=r"^foxglove.host 'localhost:80' refused: must be an IP address"):
        FoxgloveSink(host="localhost:80", port=0)
    with pytest.raises(FoxgloveError, match=r"^foxglove.port 70000 refused: must be an integer in 0..65535"):
        FoxgloveSink(port=70000)
    with FoxgloveSink(port=0) as first:
        with pytest.raises(FoxgloveError, match=rf"could not listen on ws://127.0.0.1:{first.port}: "):
            FoxgloveSink(port=first.port)


def test_rig_foxglove_starts_the_bridge_with_foxglove_only_when_asked(repo_root, tmp_path):
    from rimd_sim.ros.bringup import plan_rig

    config = (Path(repo_root) / "config" / "rimd.yaml").resolve()   # config/ links to rimd_sim/config

    def plan(**options) -> dict[str, list[str]]:
        nodes = plan_rig(config, output_dir=tmp_path / "rec", **options).nodes
        return {node.name: list(node.args[node.args.index(str(config)) + 1:]) for node in nodes}

    assert "foxglove.enabled:=true" not in plan()["rimd_rerun"]   # off by default (config/rimd.yaml)
    assert plan(foxglove=True)["rimd_rerun"] == ["-p", "foxglove.enabled:=true"]
    assert plan(foxglove=True, rerun=False)["rimd_rerun"] == ["-p", "foxglove.enabled:=true", "-p", "rerun:=false"]
    assert "rimd_rerun" not in plan(rerun=False)



@pytest.mark.ros
@pytest.mark.timeout(150)
def test_foxglove_s_timeline_drives_a_replay(ros_processes, ros_executor, tmp_path):
    """The replay and the bridge in their own processes; the test is Foxglove (the protocol client), a subscriber of
    the replayed topics and a `ros2 service call`-like client of the replay: the replay obeys each request, and
    its state, whoever changed it, comes back to Foxglove."""
    from builtin_interfaces.msg import Time
    from mcap.reader import make_reader

    from harness.rig import RawCollector
    from harness.rig_mcap import write_rig_mcap
    from harness.ros import call_service, spin_until
    from rimd_msgs.srv import GetRate, GetReplayState, IsPaused, PlayNext, Seek, SetRate
    from rimd_sim.io.reader import open_recording

    path = tmp_path / "rig.mcap"
    write_rig_mcap(path, seconds=2.0)
    with path.open("rb") as f:   # the range, by an independent reader: the recording's first and last log times
        stats = make_reader(f).get_summary().statistics
    first, last = stats.message_start_time, stats.message_end_time
    messages = list(open_recording(path).messages())
    collector = RawCollector(ros_executor)
    node = collector.node

    def replay_call(srv, name, request=None):  # as `ros2 service call /rimd_replay/NAME`
        return call_service(ros_executor, node, node.create_client(srv, f"/rimd_replay/{name}"),
                            request or srv.Request(), timeout=10)

    # Every replayed topic matched by the bridge and the collector before anything plays (nothing lost in transit).
    replay = ros_processes.start_node("rimd_replay", "--ros-args", "-p", f"file:={path}", "-p", "start_paused:=true",
                                      "-p", "keep_alive:=true", "-p", "wait_for_subscribers:=2",
                                      "-p", "wait_topics:=['/rig/.*']")
    bridge = ros_processes.start_node("rimd_rerun", "--ros-args", "-p", "foxglove.enabled:=true", "-p", "rerun:=false",
                                      "-p", "foxglove.port:=0", "-p", "foxglove.playback_node:=/rimd_replay",
                                      "-p", "foxglove.parameter_nodes:=['/rimd_replay']")
    url = bridge.wait_for_output(r"playback control of /rimd_replay over .* \((ws://\S+)\)", timeout=60).group(1)
    replay.wait_for_output(r"subscribers matched on /rig/", timeout=30)
    with FoxgloveClient(url) as client:
        info = client.wait_for(lambda r: r.server_info, 10, "serverInfo")
        assert "playbackControl" in info["capabilities"], info
        assert (info["dataStartTime"], info["dataEndTime"]) == (
            {"sec": first // 10**9, "nsec": first % 10**9}, {"sec": last // 10**9, "nsec": last % 10**9})
        assert {f"/rimd_replay/{n}" for n in ("play_next", "burst", "seek", "get_state")} <= set(
            client.wait_for(lambda r: len(r.services) >= 10 and r.services, 10, "the replay's services"))
        force = client.wait_for(lambda r: client.channel("/rig/impact/force"), 20, "the force channel")
        subscription = client.subscribe(force["id"])

        def request(play: bool, speed: float, seek_ns: int | None, rid: str):
            client.playback_control(play, speed, seek_ns, rid)
            return client.wait_for(client.playback_reply(rid), 15, f"the answer to {rid}")

        # Play at 2x: the replay resumes at that rate and publishes.
        reply = request(True, 2.0, None, "play")
        assert (reply.status, reply.speed) == ("playing", 2.0), reply
        assert not replay_call(IsPaused, "is_paused").paused and replay_call(GetRate, "get_rate").rate == 2.0
        assert spin_until(ros_executor, lambda: len(collector.messages["/rig/impact/force"]) >= 5, 20)
        client.wait_for(lambda r: r.messages.get(subscription), 10, "force blocks through Foxglove")
        # Pause, seeking between two recorded log times: paused there; the next message is the first at or after.
        logs = sorted({m.log_time for m in messages})
        target = (logs[-60] + logs[-59]) // 2
        reply = request(False, 2.0, target, "seek")
        assert (reply.status, reply.did_seek, reply.current_ns) == ("paused", True, target), reply
        assert replay_call(IsPaused, "is_paused").paused
        published = replay_call(GetReplayState, "get_state").published

        def received() -> int:
            return sum(map(len, collector.messages.values()))

        assert spin_until(ros_executor, lambda: received() == published, 10), (received(), published)
        before = {t: len(v) for t, v in collector.messages.items()}
        call = client.call_service("/rimd_replay/play_next", bytes(serialize_message(PlayNext.Request())))
        answer = deserialize_message(client.wait_for(lambda r: r.responses.get(call), 10, "play_next")[1],
                                     PlayNext.Response)
        assert answer.success
        assert spin_until(ros_executor, lambda: received() == published + 1, 10), (received(), published)
        landed = next(m for m in messages if m.log_time >= target)
        (topic,) = [t for t, v in collector.messages.items() if len(v) > before[t]]
        assert (topic, collector.messages[topic][-1]) == (landed.topic, landed.data)
        # A change by someone else (a ROS client of the replay): broadcast to Foxglove, no request id.
        assert replay_call(SetRate, "set_rate", SetRate.Request(rate=8.0)).success
        told = client.wait_for(lambda r: [s for s in r.playback if not s.request_id and s.speed == 8.0], 10,
                               "the rate set by another client")
        assert told[0].status == "paused"
        # A refusal: the replay's own message, as an error status.
        beyond = last + 5 * 10**9
        own = replay_call(Seek, "seek", Seek.Request(time=Time(sec=beyond // 10**9, nanosec=beyond % 10**9))).message
        reply = request(False, 8.0, beyond, "refused")
        assert (reply.status, reply.did_seek) == ("paused", False)
        status = client.wait_for(lambda r: [s for s in r.statuses if "~/seek refused" in s["message"]], 10, "refusal")
        assert status[0]["level"] == 2 and status[0]["message"] == f"playback: /rimd_replay ~/seek refused: {own}"
        # Played to the end at 8x: Ended (the replay stays up: keep_alive).
        request(True, 8.0, None, "to the end")
        ended = client.wait_for(lambda r: [s for s in r.playback if s.status == "ended"], 20, "Ended")
        assert ended[0].current_ns == last and replay.is_running()
        # The time Foxglove gets is the playback time (log times of the recording), and so are the log times of
        # the messages forwarded, never the wall clock.
        assert client.received.times and all(first <= t <= last for t in client.received.times)
        assert all(first <= t <= last for t, _ in client.received.messages[subscription])
    assert bridge.stop() == 0, bridge.tail()
    assert replay.stop() == 0, replay.tail()


def test_rimd_replay_plans_the_replay_and_the_bridge_pointed_at_it(tmp_path, capsys):
    from rimd_sim import cli
    from rimd_sim.ros.bringup import plan_replay

    path = tmp_path / "rig.mcap"
    path.write_bytes(b"")   # the plan only checks that the recording is there; the replay node reads it
    (replay,) = plan_replay(path, parameters={"rate": 2.0}).nodes
    assert replay.args == ("--ros-args", "-p", f"file:={path.resolve()}", "-p", "rate:=2.0")
    replay, bridge = plan_replay(path, foxglove=True, port=0).nodes
    assert replay.args == ("--ros-args", "-p", "start_paused:=true", "-p", "keep_alive:=true",
                           "-p", f"file:={path.resolve()}")
    assert (bridge.name, bridge.fqn) == ("rimd_rerun", "/rig/rimd_rerun")
    assert bridge.args == ("--ros-args", "-p", "rerun:=false", "-p", "foxglove.enabled:=true",
                           "-p", "foxglove.host:=127.0.0.1", "-p", "foxglove.port:=0",
                           "-p", "foxglove.playback_node:=/rimd_replay",
                           "-p", "foxglove.parameter_nodes:=['/rimd_replay']")
    # Refused in one line before anything starts, naming what was wrong as typed.
    for argv, refusal in ((["replay", str(tmp_path / "none.mcap")], f"{tmp_path / 'none.mcap'} does not exist"),
                          (["replay", str(path), "--topics", "/rig/.*", "("], "--topics /rig/.* ( refused: must be a "
                                                                                "list of regular expressions"),
                          (["replay", str(path), "--port", "9000"], "--port is for --foxglove")):
        assert cli.main(argv) == 1
        err = capsys.readouterr().err
        assert err.startswith(f"rimd replay: {refusal}") and err.count("\n") == 1, err
