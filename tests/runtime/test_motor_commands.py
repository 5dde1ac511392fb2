"""Motor commands from /rig/motor/command and the controller's lockstep, in process on a fake clock (docs/control.md).

Hypotheses:

* the pacing (rimd_sim.runtime.pacing.Lockstep): a consumer that says it ``controls`` is held one block after
  each message on a topic its report names, and not at all where it has everything; a report that counts more
  commands than were received waits for them (DDS orders no two topics), a leave too; a newer report replaces
  one that waited;
* the runtime (rimd_sim.runtime.simulator.SimulatorRuntime.motor_command): a command is applied exactly at its
  stamp (the truth is bit for bit the core's with the same commands at the same times), at the next block
  boundary for stamp zero, and at the next block boundary when its stamp was already simulated (counted late,
  with the lateness); a refused one changes nothing and is counted, said once per sender; no log line per
  command at info level, a summary every 10 s of wall time while they come; the diagnostics count them;
* the closed loop: a controller driven through the runtime's own entry points (its reports and commands
  delivered in either order, passes of the pacing loop in between) gets the commands applied where
  rimd_sim.runtime.closed_loop applies them offline, and the same data bit for bit, whatever the order.
"""

from __future__ import annotations

import random
from fractions import Fraction

import pytest

from harness.clock import FakeClock
from harness.runtime_rig import Rig
from harness.runtime_rig import make_rig as make_runtime_rig
from rimd_sim.instruments.rig_simulator import RigSimulator
from rimd_sim.io.cdr import CdrReader
from rimd_sim.io.cdr_write import encode_truth
from rimd_sim.runtime.closed_loop import Command, run_closed_loop
from rimd_sim.runtime.pacing import Go, Hold, Pacer
from rimd_sim.runtime.stamps import sample_stamp_ns
from rimd_sim.settings.lockstep import LockstepSettings

MS = 1_000_000
S = 1_000_000_000
EVENTS = "/rig/impact/events"
STATE = "/rig/motor/state"


def ends(start_ms: int, count: int = 10) -> list[int]:
    """The ends of ``count`` 10 ms blocks after ``start_ms`` (ns)."""
    return [(start_ms + 10 * (i + 1)) * MS for i in range(count)]


def controller_pacer() -> Pacer:
    settings = LockstepSettings(enabled=True, consumers=("ctl",), window=0.5, timeout=2.0)
    return Pacer(0.0, settings, topics=[EVENTS, STATE], clock=FakeClock())


# ---- the pacing ------------------------------------------------------------------------------------------------

def test_a_controller_is_held_one_block_after_each_message_it_takes_and_not_where_it_has_everything():
    pacer = controller_pacer()
    lock = pacer.lockstep
    lock.progress("ctl", 0, "i", {EVENTS: 0}, controls=True)
    assert pacer.next(ends(0)) == Go(1)          # one block at a time: its next one may bring a message
    pacer.published(10 * MS, STATE)             # a block without an event: it has everything it takes
    assert pacer.next(ends(10)) == Go(1)
    pacer.published(13 * MS, EVENTS)            # a block with an impact event (stamped at the contact's start)
    pacer.published(20 * MS, STATE)
    assert isinstance(pacer.next(ends(20)), Hold)   # held at 20 ms until the controller has taken it
    lock.progress("ctl", 13 * MS, "i", {EVENTS: 13 * MS}, controls=True)
    assert pacer.next(ends(20)) == Go(1)


def test_a_report_that_counts_commands_not_received_waits_for_them():
    pacer = controller_pacer()
    lock = pacer.lockstep
    # The join counts a command sent before it (the initial setpoint): nothing goes until it is here.
    verdict = lock.progress("ctl", 0, "i", {EVENTS: 0}, controls=True, commands=1)
    assert verdict.reason == "pending" and not verdict.accepted and lock.consumers["ctl"].awaiting == (1, 0)
    assert isinstance(pacer.next(ends(0)), Hold)
    joined = lock.command("ctl", "i")
    assert joined is not None and joined.joined and lock.consumers["ctl"].awaiting is None
    assert pacer.next(ends(0)) == Go(1)
    pacer.published(5 * MS, EVENTS)
    pacer.published(10 * MS, STATE)
    # The report after two commands comes before them: still held; a newer report replaces the one that waited.
    lock.progress("ctl", 5 * MS, "i", {EVENTS: 5 * MS}, controls=True, commands=3)
    assert isinstance(pacer.next(ends(10)), Hold)
    assert lock.command("ctl", "i") is None and lock.consumers["ctl"].awaiting == (3, 2)
    assert lock.command("other instance", "x") is None
    assert isinstance(pacer.next(ends(10)), Hold)
    assert lock.command("ctl", "i") is not None
    assert pacer.next(ends(10)) == Go(1)
    # A leave waits for the commands it counts, too: the last of them still applies where the run is held.
    pacer.published(15 * MS, EVENTS)
    lock.progress("ctl", 0, "i", leaving=True, controls=True, commands=4)
    assert isinstance(pacer.next(ends(20)), Hold)
    verdict = lock.command("ctl", "i")
    assert verdict is not None and verdict.reason == "left"
    assert pacer.next(ends(20)) == Go(10)


# ---- the runtime -----------------------------------------------------------------------------------------------

def make_rig(**values) -> Rig:
    """A started runtime with the motor at 3.75 Hz from t = 0."""
    return make_runtime_rig(**{"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75, **values})


def truth_bytes(config, commands: list[tuple[Fraction | None, float, float]], blocks: int) -> list[bytes]:
    """The truth messages of ``blocks`` 10 ms blocks of the core with ``commands`` (at, Hz, Hz/s) scheduled first."""
    sim = RigSimulator(config)
    for at, f, rate in commands:
        sim.set_motor_frequency(f, rate, at=at, kind="motor_command")
    rate = Fraction(repr(config.truth_rate))
    out = []
    for block in sim.advance_blocks([Fraction(k, 100) for k in range(1, blocks + 1)]):
        assert block.truth is not None
        first, rows = block.truth
        out.append(encode_truth(sample_stamp_ns(0, first, rate), first, config.truth_rate, rows))
    return out


def setpoints(rig: Rig) -> list[tuple[int, float]]:
    """(stamp, setpoint) of every motor state sent."""
    out = []
    for data in rig.on("motor/state"):
        r = CdrReader(data)
        sec, nanosec = r.time()
        r.string()
        out.append((sec * S + nanosec, r.f64()))
    return out


def test_commands_apply_exactly_at_their_stamps_or_at_the_next_boundary_when_zero_or_late():
    rig = make_rig(real_time_factor=0.0)
    rt = rig.rt
    rig.run(1)                                             # 10 blocks: the rig stands at 100 ms
    rt.motor_command(4.0, 50.0, divmod(250 * MS + 123_457, S), consumer="ctl", sequence=1)   # between two samples
    rt.motor_command(4.5, 50.0, (0, 0), sequence=2)                                          # stamp zero: at 100 ms
    rt.motor_command(5.0, 50.0, divmod(40 * MS, S), sequence=3)                              # already simulated
    rig.run(4)
    assert rt.diagnostics()[0].values["motor_commands_late"] == "1"
    assert rt.diagnostics()[0].values["motor_commands_worst_late_ms"] == "60.000"
    # The zero and the late one apply at the boundary the rig stood at (in the order received), the other at its
    # stamp: the data is the core's with those commands at those times, bit for bit.
    expected = truth_bytes(rt.config, [(Fraction(100, 1000), 4.5, 50.0), (Fraction(100, 1000), 5.0, 50.0),
                                       (Fraction(250 * MS + 123_457, S), 4.0, 50.0)], 50)
    assert rig.on("truth") == expected
    assert [f for t, f in setpoints(rig) if t in (100 * MS, 110 * MS, 250 * MS, 260 * MS)] == [3.75, 5.0, 5.0, 4.0]
    values = rt.diagnostics()[0].values
    assert (values["motor_commands_received"], values["motor_commands_applied"]) == ("3", "3")
    assert values["motor_command_last"].startswith("setpoint 4 Hz, ramp 50 Hz/s at simulation time 0.250123 s")


def test_refused_commands_change_nothing_are_counted_and_said_once_per_sender():
    rig = make_rig(real_time_factor=0.0)
    rt = rig.rt
    rig.run(1)
    for bad in (float("nan"), 13.0, -1.0):
        rt.motor_command(bad, 0.0, consumer="ctl", sequence=7)
    rt.motor_command(4.0, 2e4, consumer="ctl")                       # ramp above 1e4 Hz/s
    rt.motor_command(4.0, 0.0, (200_000, 0), consumer="ctl")          # more than a day ahead
    rt.motor_command(4.0, 0.0, (0, 2_000_000_000))                   # nanosec out of its range
    rig.run(2)
    assert all(f == 3.75 for _, f in setpoints(rig))
    values = rt.diagnostics()[0].values
    assert (values["motor_commands_refused"], values["motor_commands_applied"]) == ("6", "0")
    assert "nanosec" in values["motor_command_last_refusal"]
    warnings = [line for level, line in rig.logs if level == "warning"]
    assert warnings == ["motor command 7 from ctl refused: frequency_hz = nan refused: must be finite; the next "
                        "refusals are counted in /diagnostics and the summary (said once)",
                        "motor command 0 from an unnamed sender refused: header.stamp.nanosec = 2000000000 "
                        "refused: must be in [0, 1000000000); the next refusals are counted in /diagnostics and "
                        "the summary (said once)"]


def test_no_line_per_command_a_summary_every_ten_seconds_while_they_come():
    rig = make_rig(real_time_factor=0.0)
    rt, clock = rig.rt, rig.clock
    for k in range(240):                                 # 100 commands a second of simulation time, 2.4 s
        rt.motor_command(3.75 + 0.001 * (k % 7), 0.0, sequence=k + 1)
        rig.run(1)                                       # ten blocks each pass
        clock.advance(0.125)                             # 30 s of wall time in all
    info = [line for level, line in rig.logs if level == "info" and "motor command" in line]
    assert len(info) == 3, info                          # at the first, then every 10 s of wall time
    assert info[0].startswith("motor commands: 1 applied since the start (1 in all; 0 late")
    assert info[1].startswith("motor commands: 80 applied in the last 10.0 s (81 in all")
    assert sum(level == "debug" for level, _ in rig.logs) == 240   # each one at debug level only


# ---- the closed loop through the runtime ---------------------------------------------------------------------

def impacts_of(data: bytes) -> tuple[int, float]:
    """(stamp, peak force) of an ImpactEvent."""
    r = CdrReader(data)
    sec, nanosec = r.time()
    r.string()
    r.f64()
    return sec * S + nanosec, r.f64()


def rule(k: int) -> float:
    """The test controller's decision at its ``k``-th impact (1-based): a new setpoint every third impact."""
    return 3.6 + 0.05 * (k // 3 % 5)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_controller_through_the_runtime_gets_what_the_offline_closed_loop_gives_whatever_the_order(seed):
    rng = random.Random(seed)
    rig = make_rig(real_time_factor=0.0, **{"lockstep.enabled": True, "lockstep.consumers": ["ctl"],
                                            "lockstep.window": 0.5})
    rt = rig.rt
    # The initial setpoint goes before the join, which counts it: applied at time 0.
    rt.progress("ctl", 0, instance="i", topics=[EVENTS], topics_done_ns=[0], controls=True, commands=1)
    rig.run(3)
    assert not rig.on("motor/state")                     # waits for the command the join counts
    rt.motor_command(3.6, 0.0, consumer="ctl", instance="i", sequence=1)
    sent, seen, commands = 0, 0, 1
    while not rig.on("motor/state") or setpoints(rig)[-1][0] < 3 * S:
        step = rt.step()
        fresh = [data for key, data in rig.sent[sent:] if key == "impact/events"]
        sent = len(rig.sent)
        for data in fresh:
            stamp, _ = impacts_of(data)
            seen += 1
            out = []
            if seen % 3 == 0:
                commands += 1
                out.append(("command", rule(seen), commands))
            out.append(("progress", stamp, commands))
            rng.shuffle(out)                             # DDS orders no two topics
            for kind, value, count in out:
                for _ in range(rng.randrange(3)):        # passes of the pacing loop meanwhile: it holds
                    before = len(rig.on("motor/state"))
                    assert rt.step().wait > 0 and len(rig.on("motor/state")) == before
                if kind == "command":
                    rt.motor_command(value, 0.0, consumer="ctl", instance="i", sequence=count)
                else:
                    rt.progress("ctl", 0, instance="i", topics=[EVENTS], topics_done_ns=[value], controls=True,
                                commands=count)
        assert not step.stopped
    assert seen >= 9

    k = [0]

    def decide(block):
        out = []
        for _ in block.impacts:
            k[0] += 1
            if k[0] % 3 == 0:
                out.append(Command(rule(k[0])))
        return out

    applied = run_closed_loop(rt.config, decide, 3.0, initial=[Command(3.6)])
    assert [(a.time, a.command.frequency_hz) for a in applied][:1] == [(0, 3.6)]
    blocks = len(rig.on("truth"))
    expected = truth_bytes(rt.config, [(a.time, a.command.frequency_hz, 0.0) for a in applied], blocks)
    assert rig.on("truth") == expected                   # the same run, bit for bit
    assert len(applied) == 1 + seen // 3
