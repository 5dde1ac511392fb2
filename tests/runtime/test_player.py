"""The replay's player (rimd_sim.runtime.replay), without ROS and without waiting: a fake clock.

Hypotheses, each the behaviour of rosbag2's player: messages leave in log-time order when due at the rate;
``seek`` lands on the first message recorded at or after the time and refuses a time outside the part played;
``set_rate`` changes the pace from where the player stands; ``play_next`` and ``burst`` publish exactly one
and N messages while paused (none while playing); ``start_offset`` and ``playback_duration`` cut the part
played; ``loop`` starts a new pass (a new run); ``restamp`` shifts every stamp by one offset so the first is
the wall time; in lockstep a consumer that has not reported holds the run.
"""

from __future__ import annotations

import time

import pytest

from harness.clock import FakeClock
from harness.rig_mcap import write_rig_mcap
from rimd_sim.errors import ConfigError
from rimd_sim.io.cdr import header_stamp
from rimd_sim.io.reader import open_recording
from rimd_sim.runtime.pacing import Hold, Wait
from rimd_sim.runtime.replay import Finished, Paused, Player, ReplaySettings
from rimd_sim.settings.params import build

S = 1_000_000_000


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("player") / "rig.mcap"
    write_rig_mcap(path, seconds=1.0)
    return open_recording(path)


def player(recording, clock=None, **values):
    settings = build(ReplaySettings, {"file": "rig.mcap", **values})
    return Player(recording, recording.topics, settings, clock=clock or FakeClock())


def drain(p: Player, clock: FakeClock, step: float = 0.001, limit: float = 60.0) -> list[tuple[float, int]]:
    """Run the player on the fake clock; (wall time, log time) of every message, until it finishes."""
    out = []
    end = clock.now + limit
    while clock.now < end:
        got = p.step()
        if isinstance(got, Finished):
            return out
        if isinstance(got, list):
            out += [(clock.now, m.log_time) for m in got]
        else:
            clock.now += step
    raise AssertionError("the player did not finish")


def test_messages_leave_in_order_on_the_recorded_timing_at_the_rate(recording):
    for rate in (1.0, 2.0):
        clock = FakeClock()
        p = player(recording, clock, rate=rate)
        p.start()
        sent = drain(p, clock)
        logs = [m.log_time for m in recording.messages()]
        assert [log for _, log in sent] == sorted(logs) and len(sent) == len(logs)
        t0, l0 = sent[0]
        for wall, log in sent:   # due at (log - first) / rate, within the fake clock's step
            assert 0 <= wall - t0 - (log - l0) / S / rate <= 0.0011


def test_seek_lands_on_the_first_message_at_or_after_the_time(recording):
    p = player(recording, start_paused=True)
    logs = sorted(m.log_time for m in recording.messages())
    target = (logs[100] + logs[101]) // 2 if logs[101] > logs[100] else logs[100]
    landed = p.seek(target)
    first_after = min(t for t in logs if t >= target)
    assert str(first_after // S) in landed
    assert p.play_next().log_time == first_after
    with pytest.raises(ConfigError, match="must be a recorded log time within the part being played"):
        p.seek(logs[-1] + S)
    p.seek(logs[0])                                   # backwards: from the start again
    assert p.play_next().log_time == logs[0]


def test_set_rate_changes_the_pace_from_where_the_player_stands(recording):
    clock = FakeClock()
    p = player(recording, clock)
    p.start()
    first = drain_for(p, clock, 0.3)
    p.set_rate(4.0)
    rest = drain(p, clock)
    (w0, l0), (w1, l1) = rest[0], rest[-1]
    assert (w1 - w0) == pytest.approx((l1 - l0) / S / 4.0, abs=0.002)
    assert first and p.rate == 4.0
    with pytest.raises(ConfigError, match=r"'rate' = 0.0 refused: must be > 0"):
        p.set_rate(0.0)


def drain_for(p: Player, clock: FakeClock, seconds: float) -> list:
    out = []
    end = clock.now + seconds
    while clock.now < end:
        got = p.step()
        if isinstance(got, list):
            out += [(clock.now, m.log_time) for m in got]
        else:
            clock.now += 0.001
    return out


def test_play_next_and_burst_publish_exactly_one_and_n_while_paused(recording):
    p = player(recording, start_paused=True)
    assert isinstance(p.step(), Paused)
    logs = sorted(m.log_time for m in recording.messages())
    assert p.play_next().log_time == logs[0]
    burst = p.burst(25)
    assert [m.log_time for m in burst] == logs[1:26]
    assert p.published == 26
    assert p.resume() and p.play_next() is None and p.burst(5) == []   # playing: no effect
    assert p.pause() and not p.pause()
    assert len(p.burst(10**6)) == len(logs) - 26                      # to the end, not further
    assert p.play_next() is None


def test_start_offset_and_duration_cut_the_part_played(recording):
    clock = FakeClock()
    p = player(recording, clock, start_offset=0.25, playback_duration=0.5, rate=10.0)
    p.start()
    logs = [log for _, log in drain(p, clock)]
    first = recording.start_ns
    assert min(logs) >= first + 0.25 * S and max(logs) <= first + 0.75 * S
    expected = [m.log_time for m in recording.messages() if first + 0.25 * S <= m.log_time <= first + 0.75 * S]
    assert logs == expected
    with pytest.raises(ConfigError, match="start_offset"):
        player(recording, start_offset=100.0)


def test_loop_starts_a_new_pass_and_restamp_shifts_every_stamp(recording):
    clock = FakeClock()
    p = player(recording, clock, loop=True, restamp=True, rate=100.0)
    p.start()
    assert p.take_new_pass() and p.passes == 1
    before = time.time_ns()
    sent = []
    while p.passes < 2:
        got = p.step()
        if isinstance(got, list):
            sent += got
        else:
            clock.now += 0.001
    assert p.take_new_pass() and p.run_id
    originals = [header_stamp(m.data) for m in recording.messages()]
    pairs = [(out, original) for out, original in zip(sent, originals, strict=False) if out.stamp is not None]
    stamped = [out for out, _ in pairs]
    offsets = {out.stamp - original for out, original in pairs}
    assert len(offsets) == 1                                   # one shift for everything: the timing is kept
    assert stamped[0].stamp >= before and header_stamp(stamped[0].data) == stamped[0].stamp


def test_in_lockstep_a_consumer_that_has_not_reported_holds_the_replay(recording):
    clock = FakeClock()
    settings = {"lockstep.enabled": True, "lockstep.consumers": ["daq"], "lockstep.window": 0.05, "rate": 100.0}
    p = player(recording, clock, **settings)
    p.start()
    decision = p.step()
    assert isinstance(decision, Hold) and decision.waiting_for == ("daq",)
    assert p.progress("daq", 0).joined
    got = p.step()
    assert isinstance(got, list) and got
    # It goes no further than the window past what the consumer has finished with.
    while isinstance(got := p.step(), list) or isinstance(got, Wait):
        clock.now += 0.001
    assert isinstance(got, Hold)
    assert "daq" in p.holders_text()


def test_in_lockstep_a_restamped_replay_holds_on_the_stamps_its_consumers_report(recording):
    """With ``restamp`` the consumers report the stamps they received (shifted to the replay's clock): the replay
    must hold on those, not on the recorded ones (which lie far in the past and would never hold anything)."""
    clock = FakeClock()
    p = player(recording, clock, restamp=True, rate=100.0, **{"lockstep.enabled": True, "lockstep.consumers": ["daq"],
                                                             "lockstep.window": 0.05})
    p.start()
    assert isinstance(p.step(), Hold)
    assert p.progress("daq", 0).joined
    sent = []
    while isinstance(got := p.step(), list) or isinstance(got, Wait):
        sent += got if isinstance(got, list) else []
        clock.now += 0.001
    assert isinstance(got, Hold) and sent, got
    stamps = [m.stamp for m in sent if m.stamp is not None]
    assert stamps[-1] - stamps[0] <= 0.05e9 + 0.02e9   # the window past the join, plus at most a block or two
    assert p.progress("daq", stamps[-1]).accepted       # a report in the restamped base is taken, not "future"
    assert isinstance(p.step(), list)
