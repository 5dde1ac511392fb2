"""The pacing of the simulator and the replay (rimd_sim.runtime.pacing), on a fake clock: no wall time is waited.

Hypotheses: the schedule makes data time t due at ``anchor + t / factor`` and lets a late publisher catch up;
factor 0 sets no limit; in lockstep a block ending at t goes only once every consumer has finished with
t - window, never before every consumer has joined, and after a join the lead grows from one block (slow
start); a consumer caught up on a topic holds nothing (a hole in
its data cannot stall the run); a restarted consumer joins where the run stands; reports from unknown
consumers, from the future or going back are ignored with a reason; after ``timeout`` seconds of silence the
``drop`` policy goes on without the consumer and ``wait`` keeps holding; the cap never bursts after a hold.
"""

from __future__ import annotations

import pytest

from harness.clock import FakeClock
from rimd_sim.errors import ConfigError
from rimd_sim.runtime.pacing import Go, Hold, Lockstep, Pacer, Schedule, Wait
from rimd_sim.settings.lockstep import LockstepSettings
from rimd_sim.settings.params import build

MS = 1_000_000
S = 1_000_000_000


def blocks(start_ms: int, count: int = 10, period_ms: int = 10) -> list[int]:
    """Ends of ``count`` blocks after ``start_ms`` (ns)."""
    return [(start_ms + period_ms * (i + 1)) * MS for i in range(count)]


def lockstep(*consumers: str, window: float = 0.05, timeout: float = 2.0, on_timeout: str = "wait"):
    return LockstepSettings(enabled=True, consumers=consumers, window=window, timeout=timeout, on_timeout=on_timeout)


# ---- the clock ------------------------------------------------------------------------------------------------

def test_schedule_at_real_time_and_faster():
    clock = FakeClock()
    schedule = Schedule(1.0, clock)
    schedule.anchor(0)
    assert schedule.ready(blocks(0)) == (0, pytest.approx(0.010))   # the first block ends 10 ms from now
    clock.advance(0.010)
    assert schedule.ready(blocks(0))[0] == 1
    clock.advance(0.025)                                             # late: two more are due at once
    assert schedule.ready(blocks(0))[0] == 3
    schedule.set_factor(4.0, 30 * MS)                                # 4x from here: 10 ms of data per 2.5 ms
    assert schedule.ready(blocks(30))[1] == pytest.approx(0.0025)


def test_factor_zero_sets_no_limit():
    pacer = Pacer(0.0, clock=FakeClock())
    assert pacer.next(blocks(0)) == Go(10)


# ---- lockstep ------------------------------------------------------------------------------------------------

def test_nothing_goes_before_every_consumer_joined_then_the_window_holds_each():
    clock = FakeClock()
    pacer = Pacer(0.0, lockstep("recorder", "daq"), clock=clock)
    decision = pacer.next(blocks(0))
    assert isinstance(decision, Hold) and set(decision.waiting_for) == {"recorder", "daq"}
    assert pacer.lockstep.progress("recorder", 0).joined
    assert pacer.next(blocks(0)).waiting_for == ("daq",)
    pacer.lockstep.progress("daq", 0)
    # Slow start: the first block alone, then as much again as both have confirmed since they joined (10, 20,
    # 40 ms...), up to the window: a new reader gets the first blocks one by one, not a window's burst at once.
    assert pacer.next(blocks(0)) == Go(1)
    pacer.published(10 * MS)
    assert isinstance(pacer.next(blocks(10)), Hold)            # until both have it
    published = 10
    for confirmed, allowed in ((10, 1), (20, 2), (40, 4), (80, 5)):   # lead 10, 20, 40 ms, then the 50 ms window
        pacer.lockstep.progress("recorder", confirmed * MS)
        pacer.lockstep.progress("daq", confirmed * MS)
        assert pacer.next(blocks(published)) == Go(allowed), confirmed
        for end in blocks(published, allowed):
            pacer.published(end)
        published += 10 * allowed
    assert published == 130
    pacer.lockstep.progress("recorder", 130 * MS)
    pacer.lockstep.progress("daq", 80 * MS)
    decision = pacer.next(blocks(130))
    assert isinstance(decision, Hold) and decision.waiting_for == ("daq",)   # the slowest holds the run
    pacer.lockstep.progress("daq", 100 * MS)
    assert pacer.next(blocks(130)) == Go(2)        # daq at 100 ms plus the window: up to 150 ms


def test_the_run_goes_as_fast_as_the_slowest_consumer():
    """A consumer that takes 5 ms per 10 ms block, with the rig free to go as fast as it can: the run's speed
    is the consumer's (2x real time), whatever the window."""
    clock = FakeClock()
    pacer = Pacer(0.0, lockstep("slow", window=0.1), clock=clock)
    pacer.lockstep.progress("slow", 0)
    published, done, t0 = 0, 0, clock.now
    while done < 10 * S:
        decision = pacer.next(blocks(published // MS))
        if isinstance(decision, Go):
            for end in blocks(published // MS, decision.count):
                pacer.published(end)
            published = blocks(published // MS, decision.count)[-1]
        clock.advance(0.005)                       # the consumer finishes one block
        done = min(done + 10 * MS, published)
        pacer.lockstep.progress("slow", done)
    assert (done / S) / (clock.now - t0) == pytest.approx(2.0, rel=0.01)


def test_a_consumer_caught_up_on_a_topic_holds_nothing_there():
    """A dropout: no force block for a while. The consumer of the force channel has everything published on it,
    so it does not hold the run, however long the hole (per-topic reports)."""
    pacer = Pacer(0.0, lockstep("daq", window=0.05), topics=["/rig/impact/force", "/rig/motor/state"],
                  clock=FakeClock())
    pacer.lockstep.progress("daq", 0, topics={"/rig/impact/force": 0})
    pacer.published(0, "/rig/impact/force")
    for end in blocks(0, 5):
        pacer.published(end, "/rig/motor/state")     # the force channel is in a dropout
    assert pacer.next(blocks(50)) == Go(5)         # at the front of the run (50 ms) plus the window
    pacer.published(600 * MS, "/rig/impact/force")   # the dropout ends: a force block the consumer has not taken
    assert isinstance(pacer.next(blocks(600)), Hold)
    pacer.lockstep.progress("daq", 600 * MS, topics={"/rig/impact/force": 600 * MS})
    assert pacer.next(blocks(600)) == Go(5)


def test_bad_reports_are_ignored_with_a_reason():
    pacer = Pacer(0.0, lockstep("daq"), topics=["/rig/impact/force"], clock=FakeClock())
    verdict = pacer.lockstep.progress("stranger", 0)
    assert not verdict.accepted and verdict.reason == "unknown" and "lockstep.consumers: daq" in verdict.log
    verdict = pacer.lockstep.progress("daq", 5 * S)
    assert not verdict.accepted and verdict.reason == "future" and "beyond what was published" in verdict.log
    verdict = pacer.lockstep.progress("daq", 0, topics={"/elsewhere": 0})
    assert not verdict.accepted and verdict.reason == "topics" and "/elsewhere" in verdict.log
    verdict = pacer.lockstep.progress("daq", 0, topics={"/elsewhere": 0, "/rig/impact/force": 0})
    assert verdict.accepted and "/elsewhere left out" in verdict.log   # the topics published here count
    pacer.lockstep.consumers["daq"].done.clear()
    assert pacer.lockstep.progress("daq", 0, instance="a").joined
    pacer.published(30 * MS)
    assert pacer.lockstep.progress("daq", 30 * MS, instance="a").accepted
    verdict = pacer.lockstep.progress("daq", 10 * MS, instance="a")
    assert not verdict.accepted and verdict.reason == "back"
    assert pacer.lockstep.consumers["daq"].done_ns == 30 * MS


def test_a_consumer_may_switch_from_one_report_to_reports_per_topic():
    """The progress reporter joins with one report (zero: nothing taken yet), then reports per topic."""
    pacer = Pacer(0.0, lockstep("daq"), topics=["/a", "/b"], clock=FakeClock())
    pacer.lockstep.progress("daq", 0)
    for end in blocks(0, 3):
        pacer.published(end, "/a")
        pacer.published(end, "/b")
    pacer.lockstep.progress("daq", 0, topics={"/a": 30 * MS, "/b": 20 * MS})
    assert pacer.lockstep.consumers["daq"].done == {"/a": 30 * MS, "/b": 20 * MS}
    assert pacer.next(blocks(30)) == Go(1)         # /b at 20 ms, 20 ms confirmed since the join: up to 40 ms


def test_each_report_is_the_whole_state_a_topic_left_out_holds_nothing():
    """The reporter joins naming every topic it subscribes to (so the publisher matches its readers of each), done
    through zero, then reports only the topics it keeps progress on: a topic named at the join and never again
    (a client's extra subscription) must not hold the run at the join time for ever."""
    pacer = Pacer(0.0, lockstep("daq"), topics=["/a", "/extra"], clock=FakeClock())
    assert pacer.lockstep.progress("daq", 0, topics={"/a": 0, "/extra": 0}).joined
    for end in blocks(0, 3):
        pacer.published(end, "/a")
        pacer.published(end, "/extra")
    assert pacer.lockstep.progress("daq", 0, topics={"/a": 30 * MS}).accepted
    assert pacer.lockstep.consumers["daq"].done == {"/a": 30 * MS}
    assert pacer.next(blocks(30)) == Go(3)         # /a at 30 ms, 30 ms confirmed since the join: up to 60 ms


def test_a_restarted_consumer_joins_where_the_run_stands():
    pacer = Pacer(0.0, lockstep("daq"), clock=FakeClock())
    pacer.lockstep.progress("daq", 0, instance="first")
    for end in blocks(0, 5):
        pacer.published(end)
    assert isinstance(pacer.next(blocks(50)), Hold)           # the consumer died at 0
    verdict = pacer.lockstep.progress("daq", 0, instance="second")   # restarted: it has taken nothing yet
    assert verdict.accepted and verdict.joined and "restarted" in verdict.log
    assert pacer.lockstep.consumers["daq"].done_ns == 50 * MS   # what was published before cannot reach it
    assert isinstance(pacer.next(blocks(50)), Go)


def test_a_second_copy_of_a_join_is_no_news_and_no_warning():
    """A transient local join comes on both of the publisher's subscriptions: the copy is taken silently."""
    pacer = Pacer(0.0, lockstep("daq"), clock=FakeClock())
    pacer.lockstep.progress("daq", 0, instance="first")
    for end in blocks(0, 5):
        pacer.published(end)
    assert pacer.lockstep.progress("daq", 0, instance="second").joined   # taken nothing yet: done through 0
    copy = pacer.lockstep.progress("daq", 0, instance="second")
    assert copy.accepted and not copy.joined and copy.log == "" and copy.reason == ""
    assert pacer.lockstep.consumers["daq"].done_ns == 50 * MS
    # A report that goes back from where it joined is still refused with its reason.
    back = pacer.lockstep.progress("daq", 10 * MS, instance="second")
    assert not back.accepted and back.reason == "back"


def test_a_consumer_that_leaves_cleanly_is_no_longer_waited_for_until_it_reports_again():
    clock = FakeClock()
    pacer = Pacer(0.0, lockstep("daq", "recorder", timeout=1e9), clock=clock)
    pacer.lockstep.progress("daq", 0, instance="a")
    pacer.lockstep.progress("recorder", 0)
    for end in blocks(0, 5):
        pacer.published(end)
    pacer.lockstep.progress("recorder", 50 * MS)
    assert isinstance(pacer.next(blocks(50)), Hold)                   # daq stands at 0
    stale = pacer.lockstep.progress("daq", 0, instance="old", leaving=True)
    assert not stale.accepted and stale.reason == "stale"             # an earlier process's leave: no effect
    assert isinstance(pacer.next(blocks(50)), Hold)
    left = pacer.lockstep.progress("daq", 0, instance="a", leaving=True)
    assert left.accepted and "left at 0.000000000 s" in left.log and pacer.lockstep.consumers["daq"].left
    assert isinstance(pacer.next(blocks(50)), Go)                     # no timeout needed: the recorder decides
    clock.advance(1e10)
    assert not pacer.lockstep.take_events()                           # and no timeout fires for it
    back = pacer.lockstep.progress("daq", 0, instance="b")            # it starts again: waited for again
    assert back.joined and "returned after leaving" in back.log and not pacer.lockstep.consumers["daq"].left
    # A consumer that leaves before it ever joined does not hold the first block either.
    pacer = Pacer(0.0, lockstep("daq"), clock=FakeClock())
    assert isinstance(pacer.next(blocks(0)), Hold)
    assert "before joining" in pacer.lockstep.progress("daq", 0, leaving=True).log
    assert isinstance(pacer.next(blocks(0)), Go)


def test_a_consumer_that_has_not_joined_yet_is_waited_for_however_long():
    """A consumer still starting (imports, discovery) is never timed out or dropped: the first block waits."""
    clock = FakeClock()
    pacer = Pacer(0.0, lockstep("daq", timeout=1.0, on_timeout="drop"), clock=clock)
    for _ in range(5):
        clock.advance(10.0)
        assert isinstance(pacer.next(blocks(0)), Hold)
    assert not pacer.lockstep.take_events() and not pacer.lockstep.consumers["daq"].dropped


@pytest.mark.parametrize("policy", ["wait", "drop"])
def test_a_silent_consumer_is_named_and_the_timeout_policy_applies(policy):
    clock = FakeClock()
    pacer = Pacer(0.0, lockstep("daq", "recorder", timeout=2.0, on_timeout=policy), clock=clock)
    pacer.lockstep.progress("daq", 0)
    pacer.lockstep.progress("recorder", 0)
    for end in blocks(0, 5):
        pacer.published(end)
    pacer.lockstep.progress("recorder", 50 * MS)
    hold = pacer.next(blocks(50))
    assert isinstance(hold, Hold) and hold.waiting_for == ("daq",) and hold.since == clock.now
    clock.advance(1.9)
    assert isinstance(pacer.next(blocks(50)), Hold) and not pacer.lockstep.take_events()
    clock.advance(0.2)
    decision = pacer.next(blocks(50))
    events = pacer.lockstep.take_events()
    if policy == "drop":
        assert isinstance(decision, Go)           # the recorder allows up to 100 ms
        assert events and "dropped" in events[0][1] and "daq" in events[0][1]
        back = pacer.lockstep.progress("daq", 50 * MS)        # it comes back: it is waited for again
        assert back.joined and "returned after being dropped" in back.log
        assert not pacer.lockstep.consumers["daq"].dropped
    else:
        assert isinstance(decision, Hold) and pacer.lockstep.consumers["daq"].timed_out
        assert events == [("error", events[0][1])] and "still waiting" in events[0][1]
        assert pacer.lockstep.progress("daq", 0).log == ""       # a heartbeat: no progress, still timed out
        assert pacer.lockstep.consumers["daq"].timed_out
        assert "answers again" in pacer.lockstep.progress("daq", 10 * MS).log


def test_the_cap_does_not_burst_after_a_hold():
    """real_time_factor 1 in lockstep caps the speed: after a 5 s hold, blocks go at real time again, not all
    at once to catch up."""
    clock = FakeClock()
    pacer = Pacer(1.0, lockstep("daq", window=10.0), clock=clock)
    pacer.schedule.anchor(0)
    assert isinstance(pacer.next(blocks(0)), Hold)
    clock.advance(5.0)
    pacer.lockstep.progress("daq", 0)
    assert pacer.next(blocks(0)) == Go(1)      # the first block goes at once, the next at real time
    pacer.published(10 * MS)
    pacer.lockstep.progress("daq", 10 * MS)
    assert pacer.next(blocks(10)) == Wait(pytest.approx(0.010))


def test_settings_are_declared_and_checked():
    settings = build(LockstepSettings, {"enabled": True, "consumers": ["rimd_recorder"], "window": 2})
    assert settings.window == 2.0 and settings.window_ns == 2 * S
    for values, message in (({"enabled": True}, "must name at least one consumer"),
                            ({"consumers": ["a", "a"]}, "distinct"), ({"consumers": [" a"]}, "surrounding"),
                            ({"window": 0.0}, "> 0"), ({"timeout": -1.0}, ">= 0"),
                            ({"on_timeout": "retry"}, "one of: wait, drop")):
        with pytest.raises(ConfigError, match=message):
            build(LockstepSettings, values)
    with pytest.raises(ValueError, match="no candidate"):
        Pacer(0.0, clock=FakeClock()).next([])
    assert Lockstep(lockstep("a")).limit(Lockstep(lockstep("a")).consumers["a"]) == float("-inf")


def test_the_first_message_goes_whatever_its_stamp_then_the_window_holds():
    """A replay of a real-time recording: its stamps are wall-clock epoch times (1.8e18 ns), far beyond a joined
    consumer's zero plus the window. Nothing published yet, so nothing can be waited for: the first message goes,
    then the consumer holds the run at its report plus the window (holding the first message too would hold the
    replay for ever)."""
    epoch = 1_795_525_000 * S
    pacer = Pacer(0.0, lockstep("daq", window=0.05), clock=FakeClock())
    ends = [epoch + 10 * MS * (i + 1) for i in range(10)]
    assert isinstance(pacer.next(ends), Hold)          # not joined yet
    pacer.lockstep.progress("daq", 0)
    assert pacer.next(ends[:1]) == Go(1)
    pacer.published(ends[0])
    assert isinstance(pacer.next(ends[1:]), Hold)      # done through 0: it has not taken the first one
    assert pacer.lockstep.progress("daq", ends[0]).accepted
    assert pacer.next(ends[1:]) == Go(5)               # 10 ms blocks up to 50 ms past what it has done


def test_the_slow_start_lets_the_next_block_go_whatever_was_published_at_the_join():
    """The least lead is the next block: after a message stamped at the start (the rig's session), and for a
    consumer that joins a run under way (it has nothing to confirm yet), the next block goes, and only it."""
    pacer = Pacer(0.0, lockstep("rec", window=1.0), topics=["/session", "/a"], clock=FakeClock())
    pacer.lockstep.progress("rec", 0, topics={"/session": 0, "/a": 0})
    pacer.published(0, "/session")
    assert pacer.next(blocks(0)) == Go(1)
    for end in blocks(0, 50):
        pacer.published(end, "/a")
    assert pacer.lockstep.progress("rec", 0, topics={"/a": 0}, instance="restarted").joined   # at 500 ms
    assert pacer.next(blocks(500)) == Go(1)
    pacer.published(510 * MS, "/a")
    assert isinstance(pacer.next(blocks(510)), Hold)
    pacer.lockstep.progress("rec", 0, topics={"/a": 510 * MS}, instance="restarted")
    assert pacer.next(blocks(510)) == Go(1)


def test_a_leave_says_where_the_consumer_stood_not_a_topic_that_never_had_a_message():
    """The recorder reports /rig/faults at zero all run long (no fault, no message): it has everything there, so
    its leave is logged where it stands on the topics with data, not at 0 s."""
    pacer = Pacer(0.0, lockstep("rec"), topics=["/a", "/faults"], clock=FakeClock())
    pacer.lockstep.progress("rec", 0, topics={"/a": 0, "/faults": 0})
    for end in blocks(0, 3):
        pacer.published(end, "/a")
    pacer.lockstep.progress("rec", 0, topics={"/a": 20 * MS, "/faults": 0})
    left = pacer.lockstep.progress("rec", 0, leaving=True)
    assert left.accepted and "left at 0.020000000 s" in left.log, left.log
