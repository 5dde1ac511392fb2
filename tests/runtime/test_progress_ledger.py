"""The lockstep consumer's progress ledger (``rimd_sim.runtime.progress``): what a report says and when it is due.

Both reporters (over ``/rig/progress`` and in the composed rig's process) keep their books here; the ROS tests
(tests/ros/test_lockstep.py, tests/ros/test_composed_rig.py) show them reporting; these the books themselves.
And the publisher's side, :class:`ReportOrder`: of the reports that come twice (a transient local writer matches
both of its subscriptions) each counts once, in the order written (tests/ros/test_lockstep_join.py over DDS).
"""

from __future__ import annotations

import threading
from types import SimpleNamespace

from rimd_sim.runtime.progress import ProgressLedger, ReportOrder, stamp_ns


def test_stamp_ns_of_a_time_and_of_an_integer():
    assert stamp_ns(SimpleNamespace(sec=3, nanosec=25)) == 3_000_000_025
    assert stamp_ns(7) == 7


def test_nothing_is_reported_before_the_join_and_the_join_names_every_topic_at_zero():
    ledger = ProgressLedger(min_interval=0.0)
    assert ledger.done(5, "/a") is False            # not joined: never due
    assert ledger.take_report() is None
    assert ledger.join()
    assert ledger.done_ns == {}                      # a join starts from scratch
    assert ledger.take_report(["/a", "/b"]) == (0, {"/a": 0, "/b": 0})
    assert ledger.reports == 1


def test_a_heartbeat_before_the_first_message_repeats_the_join_and_does_not_hold_the_run():
    """A consumer joins a rig that has run on (paused, or after dropping it) and its first block is late.

    Its heartbeat repeats the join: the publisher reads no news (not "done through 0 with everything", which
    would hold the run at 0 for it), and the next block still goes.
    """
    from harness.clock import FakeClock
    from rimd_sim.runtime.pacing import Go, Pacer
    from rimd_sim.settings.lockstep import LockstepSettings

    ms = 1_000_000
    pacer = Pacer(0.0, LockstepSettings(enabled=True, consumers=("daq",), window=0.05), clock=FakeClock())
    pacer.lockstep.progress("daq", 0, instance="before", topics={"/a": 0})
    for end in range(10, 9_870, 10):
        pacer.published(end * ms, "/a")
    ledger = ProgressLedger(min_interval=0.0)
    ledger.join()

    def send(report: tuple[int, dict[str, int]]):
        overall, done = report
        return pacer.lockstep.progress("daq", overall, instance="after", topics=done or None)

    assert send(ledger.take_report(["/a"])).joined
    heartbeat = ledger.take_report()
    assert heartbeat == (0, {"/a": 0})
    verdict = send(heartbeat)
    assert verdict.accepted and verdict.log == ""
    assert isinstance(pacer.next([9_870 * ms]), Go)
    ledger.done(9_860 * ms, "/a")                    # its first message: from now on it reports what it took
    assert ledger.take_report() == (0, {"/a": 9_860 * ms})


def test_progress_only_moves_forward_per_topic_and_overall():
    ledger = ProgressLedger(min_interval=0.0)
    ledger.join()
    assert ledger.done(20, "/a")
    ledger.done(10, "/a")                            # an older message finished later: no step back
    ledger.done(15, "/b")
    ledger.done(40, None)
    ledger.done(30, None)
    assert ledger.dirty
    assert ledger.take_report() == (40, {"/a": 20, "/b": 15})
    assert not ledger.dirty


def test_a_report_is_due_only_after_min_interval_and_the_last_one_stays_dirty():
    ledger = ProgressLedger(min_interval=3600.0)
    ledger.join()
    ledger.take_report(["/a"])                       # the join report was just sent
    assert ledger.done(1, "/a") is False             # within min_interval: not due ...
    assert ledger.dirty                              # ... but left for the caller's timer


def test_after_leaving_nothing_joins_or_reports_again():
    ledger = ProgressLedger(min_interval=0.0)
    assert ledger.join()
    assert ledger.leave() is True                    # it had joined: the caller says "leaving"
    assert ledger.leave() is False
    assert ledger.join() is False
    assert ledger.done(1, "/a") is False
    assert ledger.take_report() is None


def test_concurrent_done_calls_keep_the_largest_stamp():
    ledger = ProgressLedger(min_interval=0.0)
    ledger.join()

    def finish(offset: int) -> None:
        for ns in range(offset, 20_000, 4):
            ledger.done(ns, "/a")

    threads = [threading.Thread(target=finish, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=30)
    assert ledger.take_report() == (0, {"/a": 19_999})


def test_a_volatile_writers_reports_all_count():
    order = ReportOrder()
    assert all(order.take("daq", "a", latched=False) for _ in range(3))   # repeats too: a heartbeat is no progress


def test_a_transient_local_writers_reports_count_once_on_the_transient_local_subscription():
    order = ReportOrder()
    # Its join, written before the match, comes on the transient local subscription alone: it counts.
    assert order.take("daq", "a", latched=True)
    # From then on each report comes on both: the transient local copy counts, the volatile one is a copy,
    # whichever comes first (a leave then a late copy of the report before it would make the consumer join again).
    assert not order.take("daq", "a", latched=False)
    assert order.take("daq", "a", latched=True)
    assert order.take("daq", "a", latched=True)        # the leave
    assert not order.take("daq", "a", latched=False)   # the late copy of the report before it
    assert not order.take("daq", "a", latched=False)


def test_before_its_first_transient_local_report_a_writers_volatile_reports_count():
    order = ReportOrder()
    assert order.take("daq", "a", latched=False)       # the volatile subscription matched the writer first
    assert order.take("daq", "a", latched=True)        # the same report's transient local copy: a repeat (no-op)
    assert not order.take("daq", "a", latched=False)


def test_each_consumer_and_instance_is_counted_apart():
    order = ReportOrder()
    assert order.take("daq", "a", latched=True)
    assert order.take("daq", "b", latched=False)       # a restart with a volatile writer: a new instance
    assert order.take("recorder", "a", latched=False)  # another consumer
    assert not order.take("daq", "a", latched=False)
