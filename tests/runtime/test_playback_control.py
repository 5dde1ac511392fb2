"""Foxglove's timeline driving a replay (docs/foxglove.md), in-process: the mapping and the state machine of
rimd_sim.runtime.playback_control over the replay's real player (rimd_sim.runtime.replay) on a fake clock, no ROS.

Hypotheses:

- a request maps onto rosbag2's player calls: Pause while playing -> pause, first (nothing leaves from the seek's
  time before it), a seek time -> seek, a speed other than the rate -> set_rate (the 32-bit float the protocol
  carries read as the number meant: 0.1, not 0.10000000149), Play while paused -> resume, last; nothing when the
  replay is already so; Play at the end -> from the start;
- carried out on the player (planned on its state at that moment), the answer is the player's state read back:
  Playing/Paused/Ended, the position, the rate, ``did_seek`` only when a seek was done; after a seek the next
  message is the first recorded at or after the time (rosbag2's seek);
- a seek or a rate the replay refuses comes back as one error line naming the replay and the call, with the
  replay's own message, and the state unchanged;
- a change made by someone else (pause, rate, seek, a new loop pass, the end) is reported once, a seek as a jump;
  a replay that stops answering is reported Ended, once, and said when it answers again;
- the playback time runs at the rate from the last reading, at most 0.5 s ahead of it, never backwards except
  at a jump, within the range;
- the sink (the Foxglove SDK's real server, in this process) offers the range and carries a request from the
  test's protocol client to the replay and its answer back, with the request id; a refusal as an error status.
"""

from __future__ import annotations

import struct
import time

import pytest

from harness.clock import FakeClock
from harness.foxglove_client import FoxgloveClient
from harness.rig_mcap import write_rig_mcap
from rimd_sim.errors import ConfigError
from rimd_sim.io.reader import open_recording
from rimd_sim.runtime.playback_control import (
    MAX_EXTRAPOLATION_S,
    PlaybackControl,
    PlaybackRequest,
    ReplayUnavailable,
    plan,
    requested_speed,
)
from rimd_sim.runtime.replay import Player, PlayerState, ReplaySettings
from rimd_sim.settings.params import build

S = 1_000_000_000
NAME = "/rimd_replay"


class PlayerControls:
    """The player's controls as the replay node's services answer them (rimd_sim/ros/nodes/replay.py)."""

    def __init__(self, player: Player) -> None:
        self.player = player
        self.answering = True
        self.calls: list[str] = []

    def _check(self, call: str) -> None:
        self.calls.append(call)
        if not self.answering:
            raise ReplayUnavailable(f"{NAME}/{call}: no such service is running")

    def state(self) -> PlayerState:
        self._check("get_state")
        return self.player.state()

    def seek(self, t_ns: int) -> tuple[bool, str]:
        self._check("seek")
        try:
            return True, f"sought: {self.player.seek(t_ns)}"
        except ConfigError as exc:
            return False, str(exc)

    def set_rate(self, rate: float) -> tuple[bool, str]:
        self._check("set_rate")
        try:
            self.player.set_rate(rate)
        except ConfigError as exc:
            return False, str(exc)
        return True, f"rate {rate:g}"

    def pause(self) -> tuple[bool, str]:
        self._check("pause")
        return self.player.pause(), ""

    def resume(self) -> tuple[bool, str]:
        self._check("resume")
        return self.player.resume(), ""


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("playback") / "rig.mcap"
    write_rig_mcap(path, seconds=1.0)
    return open_recording(path)


def replay(recording, **values):
    clock = FakeClock()
    player = Player(recording, recording.topics, build(ReplaySettings, {"file": "rig.mcap", **values}), clock=clock)
    player.start()
    controls = PlayerControls(player)
    return PlaybackControl(controls, NAME, clock=clock), controls, player, clock


def f32(x: float) -> float:
    """What a 32-bit float field carries of ``x``."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def state(**changes) -> PlayerState:
    base = {"start_ns": 0, "end_ns": 10 * S, "position_ns": 2 * S, "paused": True, "ended": False, "rate": 1.0,
            "passes": 1, "seeks": 0}
    return PlayerState(**{**base, **changes})


def test_a_request_maps_onto_the_players_calls():
    assert plan(PlaybackRequest(play=True, speed=1.0), state()) == [("resume", None)]
    assert plan(PlaybackRequest(play=False, speed=1.0), state(paused=False)) == [("pause", None)]
    assert plan(PlaybackRequest(play=True, speed=1.0), state(paused=False)) == []        # already playing
    assert plan(PlaybackRequest(play=False, speed=1.0), state()) == []                   # already paused
    # Pause first, then seek, then the rate (it counts from where the seek landed), then play.
    assert plan(PlaybackRequest(play=True, speed=f32(0.1), seek_ns=5 * S), state()) == \
        [("seek", 5 * S), ("set_rate", 0.1), ("resume", None)]
    assert plan(PlaybackRequest(play=False, speed=2.0, seek_ns=5 * S), state(paused=False)) == \
        [("pause", None), ("seek", 5 * S), ("set_rate", 2.0)]
    assert f32(0.1) != 0.1 and requested_speed(f32(0.1)) == 0.1 and requested_speed(f32(2.5)) == 2.5
    assert plan(PlaybackRequest(play=True, speed=f32(0.1)), state(rate=0.1)) == [("resume", None)]
    # At the end: Play plays again from the start; Pause pauses there.
    assert plan(PlaybackRequest(play=True, speed=1.0), state(ended=True, paused=False)) == [("seek", 0)]
    assert plan(PlaybackRequest(play=True, speed=1.0), state(ended=True)) == [("seek", 0), ("resume", None)]
    assert plan(PlaybackRequest(play=False, speed=1.0), state(ended=True, paused=False)) == [("pause", None)]
    assert state(ended=True).status == "ended" and state().status == "paused"
    assert state(paused=False).status == "playing"


def test_requests_carried_out_on_the_player_answer_with_its_state(recording):
    control, controls, player, clock = replay(recording, start_paused=True)
    assert control.poll()[0].status == "paused"
    start, end = control.time_range
    assert (start, end) == (recording.start_ns, recording.end_ns)   # the whole recording: its log times

    report, errors = control.handle(PlaybackRequest(play=True, speed=1.0, request_id="a"))
    assert (report.status, report.speed, report.did_seek, errors) == ("playing", 1.0, False, [])
    assert not player.paused
    report, errors = control.handle(PlaybackRequest(play=True, speed=f32(2.0)))
    assert (report.status, report.speed, errors, player.rate) == ("playing", 2.0, [], 2.0)
    player.pause()   # by someone else, not read yet: a Play is planned on the state now, so it resumes
    report, errors = control.handle(PlaybackRequest(play=True, speed=2.0))
    assert (report.status, errors, player.paused) == ("playing", [], False)

    # Seek between two recorded log times while paused: the next message is the first at or after it.
    logs = sorted({m.log_time for m in recording.messages()})
    target = (logs[40] + logs[41]) // 2
    report, errors = control.handle(PlaybackRequest(play=False, speed=2.0, seek_ns=target))
    assert (report.status, report.did_seek, report.current_ns, errors) == ("paused", True, target, [])
    assert player.paused
    out = player.play_next()
    assert out.log_time == logs[41] and out.log_time >= target

    # Played to the end: Ended; Play then plays again from the start.
    control.handle(PlaybackRequest(play=True, speed=2.0))
    while not player.state().ended:
        player.step()
        clock.now += 0.01
    assert control.poll()[0].status == "ended"
    report, errors = control.handle(PlaybackRequest(play=True, speed=2.0))
    assert (report.status, report.did_seek, report.current_ns, errors) == ("playing", True, start, [])


def test_a_refusal_comes_back_with_the_replays_own_message(recording):
    control, controls, player, _clock = replay(recording, start_paused=True)
    control.poll()
    beyond = recording.end_ns + 5 * S
    with pytest.raises(ConfigError) as refusal:    # what the replay itself says of that time
        player.seek(beyond)
    report, errors = control.handle(PlaybackRequest(play=False, speed=1.0, seek_ns=beyond))
    assert errors == [f"playback: {NAME} ~/seek refused: {refusal.value}"]
    assert (report.status, report.did_seek, player.seeks) == ("paused", False, 0)

    report, errors = control.handle(PlaybackRequest(play=True, speed=-1.0))
    assert len(errors) == 1 and errors[0].startswith(f"playback: {NAME} ~/set_rate refused: ")
    assert "-1.0 refused: must be > 0" in errors[0]
    assert (report.status, report.speed, player.rate) == ("playing", 1.0, 1.0)   # the resume was still done


def test_changes_by_someone_else_are_reported_once(recording):
    control, controls, player, clock = replay(recording, loop=True)
    first, _ = control.poll()
    assert (first.status, first.did_seek) == ("playing", False)
    assert control.poll() == (None, None)                       # nothing changed: nothing to tell
    player.pause()                                              # as `ros2 service call /rimd_replay/pause`
    assert control.poll()[0].status == "paused"
    assert control.poll() == (None, None)
    player.set_rate(0.5)
    assert control.poll()[0].speed == 0.5
    player.seek(recording.start_ns + S // 2)
    report, _ = control.poll()
    assert report.did_seek and report.current_ns == recording.start_ns + S // 2
    player.resume()
    while player.passes == 1:                                   # a loop starts again: a jump too
        player.step()
        clock.now += 0.01
    report, _ = control.poll()
    assert (report.status, report.did_seek) == ("playing", True)

    controls.answering = False
    report, line = control.poll()
    assert report.status == "ended" and line == (f"playback: the replay {NAME} stopped answering "
                                                 f"({NAME}/get_state: no such service is running)")
    assert control.poll() == (None, None)                       # said once
    report, errors = control.handle(PlaybackRequest(play=True, speed=0.5))
    assert report.status == "ended" and errors == [
        f"playback: the replay {NAME} is not answering ({NAME}/get_state: no such service is running)"]
    controls.answering = True
    report, line = control.poll()
    assert report.status == "playing" and line == f"playback: the replay {NAME} answers again"


def test_the_playback_time_runs_at_the_rate_and_never_backwards_between_jumps():
    clock = FakeClock()
    current = state(paused=False, rate=2.0)

    class Fixed:
        def state(self) -> PlayerState:
            return current

    control = PlaybackControl(Fixed(), NAME, clock=clock)
    assert control.now_ns() is None                             # nothing read yet
    control.poll()
    assert control.now_ns() == 2 * S
    clock.now += 0.1
    assert control.now_ns() == 2 * S + round(0.2 * S)           # 0.1 s at 2x
    clock.now += 10.0
    assert control.now_ns() == 2 * S + round(MAX_EXTRAPOLATION_S * 2 * S)   # at most 0.5 s past the reading
    ahead = control.now_ns()
    current = state(paused=False, rate=2.0, position_ns=2 * S + S // 10)   # held (lockstep): behind the guess
    control.poll()
    assert control.now_ns() == ahead                            # not backwards
    current = state(paused=True, rate=2.0, position_ns=S, seeks=1)         # a seek back
    control.poll()
    assert control.now_ns() == S
    current = state(paused=False, rate=2.0, position_ns=10 * S - 1, seeks=1)
    control.poll()
    clock.now += 1.0
    assert control.now_ns() == 10 * S                           # within the range


def test_the_sink_offers_the_range_and_carries_requests_both_ways(recording):
    from rimd_sim.viz.foxglove_sink import FoxgloveSink

    control, controls, player, _clock = replay(recording, start_paused=True)
    control.poll()
    with FoxgloveSink(port=0, playback=control) as sink:
        assert sink.set_playback_range(*control.time_range)
        assert not sink.set_playback_range(*control.time_range)     # the same range: no restart
        with FoxgloveClient(sink.url) as client:
            info = client.wait_for(lambda r: r.server_info, 10, "serverInfo")
            assert "playbackControl" in info["capabilities"]
            start, end = control.time_range
            assert info["dataStartTime"] == {"sec": start // S, "nsec": start % S}
            assert info["dataEndTime"] == {"sec": end // S, "nsec": end % S}
            client.playback_control(True, 1.5, None, "play-1")
            reply = client.wait_for(client.playback_reply("play-1"), 10, "the answer to play-1")
            assert (reply.status, reply.speed, reply.did_seek) == ("playing", 1.5, False)
            assert not player.paused and player.rate == 1.5
            client.playback_control(False, 1.5, end + 5 * S, "seek-out")
            reply = client.wait_for(client.playback_reply("seek-out"), 10, "the answer to seek-out")
            assert (reply.status, reply.did_seek) == ("paused", False)
            status = client.wait_for(lambda r: [s for s in r.statuses if "~/seek refused" in s["message"]], 10,
                                     "the refusal")
            assert status[0]["level"] == 2 and "must be a recorded log time within" in status[0]["message"]
            player.resume()                                         # by someone else: broadcast, no request id
            report, _ = control.poll()
            sink.broadcast_playback(report)
            told = client.wait_for(lambda r: [s for s in r.playback if not s.request_id], 10, "a broadcast")
            assert told[0].status == "playing"


def test_the_sink_is_not_called_while_it_restarts(recording):
    """Offering a range restarts the SDK's server (stop, then a new one), on the relay's watcher thread, while the
    executor's timer broadcasts the time: the SDK refuses a call made during the stop ("Already mutably borrowed"),
    which would kill the bridge. Hypothesis: broadcasts from another thread through restarts raise nothing,
    and reach the server again after them."""
    import threading

    from rimd_sim.viz.foxglove_sink import FoxgloveSink

    control, _controls, _player, _clock = replay(recording, start_paused=True)
    control.poll()
    start, end = control.time_range
    failures: list[BaseException] = []
    sent = [0]
    done = threading.Event()

    def broadcast() -> None:
        while not done.is_set():
            try:
                sink.broadcast_time(start)
                sink.status("busy", status_id="test")
                sent[0] += 1
            except BaseException as exc:  # noqa: BLE001 - the test reports it
                failures.append(exc)
                return

    with FoxgloveSink(port=0, playback=control) as sink:
        thread = threading.Thread(target=broadcast, daemon=True)
        thread.start()
        try:
            for k in range(6):
                assert sink.set_playback_range(start, end - k)   # a new range each time: a restart each time
            after = sent[0]   # the calls go on after the restarts (none is left waiting on the server's lock)
            deadline = time.monotonic() + 10
            while sent[0] < after + 20 and not failures and time.monotonic() < deadline:
                time.sleep(0.005)
            assert sent[0] >= after + 20, f"{sent[0] - after} calls in 10 s after the last restart"
        finally:
            done.set()
            thread.join(timeout=10)
        sink.broadcast_time(end)
    assert not failures, f"a call during a restart raised: {failures[0]!r}"
    assert not thread.is_alive() and after > 0
