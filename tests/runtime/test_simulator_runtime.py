"""The simulator's runtime (rimd_sim.runtime.simulator) in-process, on a fake clock: no DDS, no wall time waited.

Hypotheses:

* pacing: at real time a block leaves when it is due by the clock, one per pass, stamped with the wall clock
  (``t0`` a whole millisecond taken with the pacing's anchor); at a factor F, F times as much simulation time
  per second, stamped from 0 with a ``/clock`` tick per block; as fast as possible, ten blocks per pass; in
  lockstep nothing goes before every consumer has joined, each consumer holds the run at its progress plus the
  window, a hold is reported (log, diagnostics) after 0.5 s, and on timeout ``drop`` goes on without the
  consumer while ``wait`` keeps holding and reports it timed out;
* every channel's blocks are contiguous and stamped exactly ``t0 + first_index / rate``; at gap 0 and 3.75 Hz the
  impacts come one per excitation cycle with the core's steady peak force;
* commands: a refused request answers why (naming the field) and changes nothing; an accepted one takes
  effect at the next block boundary, or exactly at the stamp it names, also between two samples; pause freezes
  the stream, resume continues it without a gap; a perturbation kicks the hammer exactly at its stamp; reset
  puts the hammer back at rest and opens a new run;
* run identity: start (or the first resume of a run started paused) and each reset publish a session with a
  new run id, its reason and sequence, the stamp of its first sample, the seed, the configuration's hash;
* diagnostics: the lateness, overruns, counts per topic and lockstep states are what the clocks make them;
* every message is CDR that rimd_sim.io.cdr reads, and that rclpy reads as exactly the message built field by
  field from the same data with rclpy's message classes (only the alignment padding differs: the runtime writes
  zeros, where rclpy leaves whatever the buffer held).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from harness.runtime_rig import WALL0, make_rig
from rimd_sim.errors import ConfigError
from rimd_sim.io.cdr import CdrReader, block_span, header_stamp, read_block
from rimd_sim.model.rig_model import RigModel
from rimd_sim.runtime.simulator import (
    CHANNEL_TOPICS,
    ERROR,
    OK,
    WARN,
    Step,
    load_settings,
)
from rimd_sim.settings.config import SimConfig

MS = 1_000_000
S = 1_000_000_000
#: The fake wall clock at the fake monotonic clock's start: not a whole millisecond, so that t0's rounding shows.
RATES = {"cart/displacement": 2000, "rimd/displacement": 2000, "rimd/acceleration": 20000, "impact/force": 20000}
CHANNELS = tuple(RATES)


# ---- decoding, with rimd_sim.io.cdr ------------------------------------------------------------------------------

def motor(data: bytes) -> dict:
    r = CdrReader(data)
    sec, nanosec = r.time()
    r.string()
    return {"stamp": sec * S + nanosec, "setpoint": r.f64(), "frequency": r.f64(), "phase": r.f64(),
            "cycle": r.u64(), "ramp": r.f64(), "cart": r.f64()}


def session(data: bytes) -> dict:
    r = CdrReader(data)
    stamp = r.time()
    frame, run_id, reason, sequence = r.string(), r.string(), r.string(), r.u32()
    start = r.time()
    sim_time, time_base, rtf = r.f64(), r.string(), r.f64()
    lockstep = bool(r.data[4 + r.pos])
    r.pos += 1
    seed, digest, node = r.u64(), r.string(), r.string()
    assert stamp == start and frame == "rimd_virtual_rig"
    return {"run_id": run_id, "reason": reason, "sequence": sequence, "start": start[0] * S + start[1],
            "simulation_time": sim_time, "time_base": time_base, "rtf": rtf, "lockstep": lockstep, "seed": seed,
            "hash": digest, "node": node}


def impact(data: bytes) -> dict:
    r = CdrReader(data)
    sec, nanosec = r.time()
    r.string()
    values = [r.f64() for _ in range(7)]
    return {"stamp": sec * S + nanosec, "peak_force": values[1], "cycle": r.u64(), "index": r.u64()}


def stamp_of(block) -> int:  # noqa: ANN001 - a BlockView
    return block.header.stamp.sec * S + block.header.stamp.nanosec


# ---- pacing ------------------------------------------------------------------------------------------------------

def test_at_real_time_a_block_leaves_when_due_one_per_pass_stamped_with_the_wall_clock():
    rig = make_rig()
    rt, clock = rig.rt, rig.clock
    t0 = (WALL0 // MS) * MS
    assert rt.t0_ns == t0 and rt.time_base == "wall_clock"
    assert session(rig.on("session")[0])["start"] == t0
    # The stamp t0 + 10 ms is due at the wall time it names: 10 ms minus t0's rounding after the anchor.
    step = rt.step()
    assert not rig.on("impact/force") and step.wait == pytest.approx(0.010 - (WALL0 - t0) / 1e9)
    clock.advance(step.wait)
    assert rt.step() == Step()
    force = read_block(rig.on("impact/force")[0])
    assert (force.first_index, len(force.samples), stamp_of(force)) == (0, 200, t0)
    assert not rig.on("/clock"), "/clock only when the stamps are simulation time"
    clock.advance(0.025)                      # late by 25 ms: the two blocks due go one per pass, none skipped
    assert rt.step() == Step() and rt.step() == Step()
    assert rt.step().wait == pytest.approx(0.005)
    assert [block_span(b) for b in rig.on("impact/force")] == [(0, 200), (200, 200), (400, 200)]
    assert [stamp_of(read_block(b)) for b in rig.on("impact/force")] == [t0, t0 + 10 * MS, t0 + 20 * MS]


@pytest.mark.parametrize("factor", [4.0, 0.5])
def test_at_a_factor_the_simulation_time_runs_that_fast_stamped_from_zero_with_clock(factor):
    rig = make_rig(real_time_factor=factor)
    rt, clock = rig.rt, rig.clock
    assert rt.t0_ns == 0 and rt.time_base == "simulation"
    clock.advance(0.1)                        # 0.1 s of wall time: 0.1 * factor s of simulation time
    for _ in range(10):                       # at most ten blocks per pass
        if rt.step().wait:
            break
    blocks = len(rig.on("motor/state"))
    assert blocks == round(10 * factor)
    assert rt.simulation_time == Fraction(blocks, 100)
    ticks = [header_stamp(b) for b in rig.on("/clock")]
    assert ticks == [(i + 1) * 10 * MS for i in range(blocks)]   # one per block, at its end


def test_as_fast_as_possible_ten_blocks_per_pass():
    rig = make_rig(real_time_factor=0.0)
    assert rig.rt.step() == Step()
    assert len(rig.on("motor/state")) == 10 and rig.rt.simulation_time == Fraction(1, 10)


def lockstep(**extra) -> dict:
    return {"real_time_factor": 0.0, "lockstep.enabled": True, "lockstep.consumers": ["daq"],
            "lockstep.window": 0.05, **extra}


def test_lockstep_holds_until_the_consumer_joins_then_by_its_progress_and_reports_a_hold():
    rig = make_rig(**lockstep())
    rt, clock = rig.rt, rig.clock
    assert rt.step() == Step(0.1) and not rig.on("motor/state")
    clock.advance(0.6)
    assert rt.step() == Step(0.1, report=True)   # held 0.6 s: said in the log, and the diagnostics go out now
    assert rig.said("lockstep: holding at simulation time 0.000000 s for 0.6 s, waiting for daq (not joined, "
                    "never heard)", "warning")
    pacing = rt.diagnostics()[0]
    assert pacing.level == WARN and "waiting for daq" in pacing.message
    assert pacing.values["lockstep daq state"] == "not joined" and pacing.values["lockstep_waiting_for"]
    assert rt.step() == Step(0.1)                # said again only after HOLD_REPEAT_S
    topics = [rt.topics[k] for k in CHANNELS]
    rt.progress("daq", 0, instance="a", topics=topics, topics_done_ns=[0] * 4, node="/my/daq")
    assert rt.wake.is_set() and rig.said("consumer 'daq' joined")
    assert rt.step() == Step()
    # Before the first block, and when a consumer joins, the node waits for DDS to match the readers.
    assert rig.matches == [{}, {"/my/daq": topics}]
    rig.run(1)
    # Slow start: the first two blocks (a block is stamped at its first sample: a consumer that has the first
    # block's stamp has everything published on its topics), then as much as confirmed, up to the 50 ms window.
    assert len(rig.on("motor/state")) == 2
    assert rt.step().wait > 0
    for done, total in ((20, 4), (40, 8), (80, 13)):
        rt.progress("daq", done * MS, instance="a")
        rig.run(1)
        assert len(rig.on("motor/state")) == total, done
    rt.progress("daq", 900 * MS, instance="a")   # beyond what was published: ignored, said once
    rt.progress("daq", 900 * MS, instance="a")
    assert sum("beyond what was published" in line for _, line in rig.logs) == 1


def test_a_join_waits_for_the_readers_of_the_topics_it_names_or_else_those_of_its_node():
    """What the node is asked to wait for when a consumer joins (tests/ros/test_lockstep_join.py: over DDS)."""
    rig = make_rig(**lockstep(**{"lockstep.consumers": ["daq", "pair", "anon"]}))
    rt = rig.rt
    force = rt.topics["impact/force"]
    rt.progress("daq", 0, instance="a", topics=[force, "/elsewhere"], topics_done_ns=[0, 0], node="/my/daq")
    rt.progress("pair", 0, instance="b", node="/pair")    # no topics named: those the graph shows it reading
    rt.progress("anon", 0, instance="c")                  # no node: every reader the graph shows
    rig.run(1)
    assert rig.matches == [{}, {}, {"/my/daq": [force], "/pair": None}]   # the start, "anon", the named nodes


def test_joins_before_a_paused_rigs_first_resume_wait_after_every_reader():
    rig = make_rig(start=False, start_paused=True, **lockstep())
    rig.rt.start()
    rig.rt.progress("daq", 0, instance="a", node="/my/daq")
    assert rig.rt.resume().success
    assert rig.matches == [{}, {"/my/daq": None}]   # sample 0: every reader, then the joining node's


@pytest.mark.parametrize("policy", ["drop", "wait"])
def test_a_silent_consumer_is_dropped_or_waited_for_on_timeout(policy):
    rig = make_rig(**lockstep(**{"lockstep.timeout": 2.0, "lockstep.on_timeout": policy}))
    rt, clock = rig.rt, rig.clock
    rt.progress("daq", 0)
    rig.run(2)
    held = len(rig.on("motor/state"))
    clock.advance(2.5)                           # no progress for longer than the timeout
    rig.run(3)
    state = rt.diagnostics()[0]
    if policy == "drop":
        assert rig.said("consumer 'daq' dropped: no progress for 2.5 s", "warning")
        assert len(rig.on("motor/state")) > held and state.values["lockstep daq state"] == "dropped"
    else:
        assert rig.said("consumer 'daq' has not answered for 2.5 s", "error")
        assert len(rig.on("motor/state")) == held and state.values["lockstep daq state"] == "timed out"
        assert state.level == ERROR and "lockstep holding" in state.message


# ---- the data ----------------------------------------------------------------------------------------------------

def test_channels_are_contiguous_and_stamped_exactly_and_impacts_come_one_per_cycle():
    """Moved from the DDS test of the node: gap 0, 3.75 Hz from the start, 10 s as fast as possible."""
    rig = make_rig(real_time_factor=0.0, **{"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
    rig.run(100)
    for key in CHANNELS:
        spans = [block_span(b) for b in rig.on(key)]
        assert spans[0][0] == 0 and all(b[0] == a[0] + a[1] for a, b in zip(spans, spans[1:], strict=False)), key
        for data in rig.on(key):
            block = read_block(data)
            assert block.sample_rate == RATES[key] and len(block.samples) == RATES[key] // 100
            assert stamp_of(block) == round(block.first_index * S / RATES[key]), key
    assert max(max(read_block(b).samples) for b in rig.on("impact/force")) > 60.0
    events = [impact(b) for b in rig.on("impact/events")]
    steady = [e for e in events if e["stamp"] > 6 * S]
    assert len(steady) >= 10
    cycles = [e["cycle"] for e in steady]
    assert cycles == list(range(cycles[0], cycles[0] + len(cycles)))
    core = RigModel(SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75}),
                    channels=False, truth=False).advance(10.0).impacts
    assert steady[-1]["peak_force"] == pytest.approx(core[-1].peak_force, rel=1e-3)
    assert rig.rt.diagnostics()[0].values["impacts_published"] == str(len(events))


def test_a_refused_motor_request_says_why_and_changes_nothing():
    """Moved from the DDS test of the node (the values it sent one by one over a service)."""
    rig = make_rig(real_time_factor=0.0, **{"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
    rig.run(1)
    now = rig.rt.stamp_of(rig.rt.simulation_time)
    for freq, ramp, stamp, reason in (
            (math.nan, 0.0, (0, 0), "finite"), (math.inf, 0.0, (0, 0), "finite"), (-1.0, 0.0, (0, 0), ">= 0"),
            (13.0, 0.0, (0, 0), "max_frequency"), (3.0, -1.0, (0, 0), "ramp_rate"),
            (3.0, math.nan, (0, 0), "ramp_rate"),
            (3.0, 1e300, (0, 0), "ramp_rate = 1e+300 refused: must be <= 10000 Hz/s"),
            (4.0, 0.0, divmod(now - S // 2, S), "already passed"),
            (4.0, 0.0, divmod(now + 200_000 * S, S), "ahead of the rig"),
            (4.0, 0.0, (1, 10**9), "start_stamp.nanosec = 1000000000 refused: must be < 1000000000")):
        answer = rig.rt.set_motor_frequency(freq, ramp, stamp)
        assert not answer.success and reason in answer.message, (freq, ramp, stamp, answer.message)
        assert answer.frequency_hz == 3.75 and answer.stamp_ns is None
    assert rig.rt._sim.pending_commands() == 0
    rig.run(1)
    assert all(motor(b)["setpoint"] == 3.75 for b in rig.on("motor/state"))


def test_commands_take_effect_at_the_next_boundary_or_exactly_at_their_stamp():
    """Moved from the DDS test of the node: a ramp starting between two samples, and a perturbation."""
    rig = make_rig(real_time_factor=0.0, **{"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
    rt = rig.rt
    rig.run(1)
    answer = rt.set_motor_frequency(5.0, 10.0)
    assert answer.success and answer.frequency_hz == 5.0 and answer.stamp_ns == 100 * MS   # the next boundary
    at = 300 * MS + 123_457
    answer = rt.set_motor_frequency(4.0, 1000.0, divmod(at, S))
    assert answer.success and answer.stamp_ns == at, answer.message
    kick = rt.perturb(0.2, divmod(500 * MS, S))
    assert kick.success and kick.stamp_ns == 500 * MS and kick.message.startswith("hammer velocity +0.2 m/s")
    rig.run(6)
    states = [motor(b) for b in rig.on("motor/state")]
    assert all(m["setpoint"] == 3.75 for m in states if m["stamp"] <= 100 * MS)
    assert all(m["setpoint"] == 5.0 for m in states if 100 * MS < m["stamp"] < at)
    assert all(m["setpoint"] == 4.0 for m in states if m["stamp"] > at)
    assert rig.said(f"set_motor_frequency at simulation time {at / S:.6f} s (stamp 0.{at:09d})")
    truth = [read_block(b, "rimd_msgs/msg/RigState") for b in rig.on("truth")]
    velocity = [(stamp_of(t) + i * MS, v) for t in truth for i, v in enumerate(t.rimd_velocity)]
    after = next(i for i, (ts, _) in enumerate(velocity) if ts >= 500 * MS)
    assert velocity[after][0] == 500 * MS          # the kick lands exactly on a truth sample
    assert velocity[after][1] - velocity[after - 1][1] == pytest.approx(0.2, abs=0.01)
    assert rt.perturb(math.nan).message == "velocity = nan refused: must be a finite number within +-10 m/s"


def test_pause_freezes_the_stream_and_resume_continues_it_without_a_gap():
    """Moved from the DDS test of the node."""
    rig = make_rig(real_time_factor=0.0)
    rt = rig.rt
    rig.run(2)
    paused = rt.pause()
    assert paused.success and paused.message == ("paused at simulation time 0.200000 s (stamp 0.200000000) "
                                                 "(simulation time frozen)")
    count = len(rig.sent)
    assert rt.step() == Step(0.1) and len(rig.sent) == count
    assert rt.pause().message == "already paused at simulation time 0.200000 s (stamp 0.200000000)"
    assert rt.diagnostics()[0].values["paused"] == "true" and rt.diagnostics()[0].message == "paused"
    assert rt.resume().message == "resumed at simulation time 0.200000 s (stamp 0.200000000)"
    assert not rt.resume().success and rt.resume().message == "not paused"
    rig.run(2)
    spans = [block_span(b) for b in rig.on("impact/force")]
    assert len(spans) == 40 and all(b[0] == a[0] + a[1] for a, b in zip(spans, spans[1:], strict=False))


def test_paused_at_real_time_the_stamps_stay_on_their_grid_and_lag_the_wall_clock():
    rig = make_rig()
    rt, clock = rig.rt, rig.clock
    clock.advance(rt.step().wait)
    rig.run(1)
    for _ in range(4):                        # each block on time
        clock.advance(0.010)
        rig.run(1)
    rt.pause()
    clock.advance(2.0)
    rt.resume()
    assert rt.step().wait == pytest.approx(0.010)   # the clock goes on from the resume
    clock.advance(0.010)
    rig.run(1)
    force = [read_block(b) for b in rig.on("impact/force")]
    assert stamp_of(force[-1]) == rt.t0_ns + 50 * MS   # the stamps go on from where they stopped
    values = rt.diagnostics()[0].values
    assert values["stamps_behind_wall_clock_s"] == "2.000"
    assert float(values["lateness_p50_ms"]) == pytest.approx(0.05, abs=0.002)   # against the grid, not the pause


def test_reset_puts_the_hammer_at_rest_and_each_run_has_an_identity():
    """Moved from the DDS tests of the node (reset) and of the rig's timing (the session's fields)."""
    values = {"real_time_factor": 0.0, "seed": 7, "motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75}
    rig = make_rig(**values)
    rt = rig.rt
    first = session(rig.on("session")[0])
    assert first["reason"] == "start" and first["sequence"] == 0 and first["start"] == 0
    assert (first["seed"], first["time_base"], first["lockstep"], first["rtf"]) == (7, "simulation", False, 0.0)
    assert len(first["hash"]) == 64 and len(first["run_id"]) == 32 and first["node"] == "/rig/rimd_simulator"
    assert rig.said(f"run {first['run_id']} (start, session 0) from simulation time 0.000000 s, stamp "
                    "0.000000000 (simulation time base)")
    rig.run(3)
    answer = rt.reset()
    assert answer.message == ("hammer reset to its initial state at simulation time 0.300000 s (stamp 0.300000000) "
                              f"(motor unchanged); run {rt.run_id}")
    second = session(rig.on("session")[1])
    assert (second["reason"], second["sequence"], second["start"]) == ("reset", 1, 300 * MS)
    assert second["run_id"] == rt.run_id != first["run_id"] and second["hash"] == first["hash"]
    rig.run(1)
    at_reset = next(t for t in map(lambda b: read_block(b, "rimd_msgs/msg/RigState"), rig.on("truth"))
                    if stamp_of(t) == 300 * MS)
    assert at_reset.theta[0] == 0.0 and at_reset.theta_dot[0] == 0.0
    # Another start of the rig: another run id, the same configuration's hash, first_index from 0 again.
    again = make_rig(**values)
    assert session(again.on("session")[0])["run_id"] != first["run_id"]
    assert session(again.on("session")[0])["hash"] == first["hash"]
    again.run(1)
    assert block_span(again.on("impact/force")[0])[0] == 0
    assert session(make_rig(**{**values, "gap": 1e-3}).on("session")[0])["hash"] != first["hash"]


def test_a_rig_started_paused_starts_at_the_first_resume():
    rig = make_rig(start=False, start_paused=True)
    rt, clock = rig.rt, rig.clock
    rt.start()
    assert not rig.sent and not rt.started and rt.diagnostics()[0].message == "paused"
    clock.advance(3.0)
    assert rt.resume().success
    assert rig.matches == [{}]             # sample 0 waits for DDS to match the readers the caller saw
    start = session(rig.on("session")[0])
    assert start["reason"] == "start" and start["start"] == rt.t0_ns == ((WALL0 + 3 * S) // MS) * MS
    assert rt.diagnostics()[0].values["stamps_behind_wall_clock_s"] == "0.000"


def test_faults_are_published_at_their_stamp_and_in_the_diagnostics():
    rig = make_rig(real_time_factor=0.0, faults=["channel=impact_force kind=offset start=0.05 duration=0.1 "
                                                 "magnitude=2.0", ""])
    rt = rig.rt
    answer = rt.inject_fault("cart_displacement", "stuck", after=0.02)
    assert answer.success and answer.stamp_ns == 20 * MS
    assert answer.message == ("fault 1: stuck on cart_displacement from simulation time 0.020000 s (stamp "
                              "0.020000000) until cleared")
    assert not rt.inject_fault("nope", "offset").success and rig.said("inject_fault refused: channel = 'nope'")
    rig.run(1)
    faults = rt.diagnostics()[1]
    assert faults.level == WARN and faults.message == ("2 fault(s) active: offset on impact_force, stuck on "
                                                       "cart_displacement")
    assert faults.values["fault_0"].startswith("offset on impact_force from simulation time 0.050000 s, duration")
    starts = [(header_stamp(b), CdrReader(b)) for b in rig.on("faults")]
    assert [s for s, _ in starts] == [20 * MS, 50 * MS]
    cleared = rt.clear_faults()
    assert cleared.message == ("faults cleared at simulation time 0.100000 s (stamp 0.100000000): 2 ended, 0 "
                               "scheduled ones cancelled")
    rig.run(1)
    assert rt.diagnostics()[1].level == OK and rt.diagnostics()[1].values["fault_events_published"] == "4"
    with pytest.raises(ConfigError, match=r"faults\[0\]"):
        make_rig(faults=["channel=impact_force kind=melt start=1"])


# ---- parameters --------------------------------------------------------------------------------------------------

def test_parameter_changes_take_effect_at_a_boundary_and_refusals_change_nothing():
    rig = make_rig(real_time_factor=4.0)
    rt = rig.rt
    rig.clock.advance(0.01)
    rig.run(1)
    assert rt.set_parameters([("use_sim_time", True)]) == ("parameter 'use_sim_time' = True refused: read at start "
                                                          "only, it cannot change while the rig runs")
    assert "QoS cannot change" in rt.set_parameters([("channels.impact_force.reliable", False)])
    assert "cannot switch to 1 while running" in rt.set_parameters([("real_time_factor", 1.0)])
    assert "'gap' = -0.001 refused" in rt.set_parameters([("gap", 0.001), ("gap", -0.001)])
    assert "seed" in rt.set_parameters([("seed", 3)])
    assert rt.config.rig.gap == 0.0
    assert rt.set_parameters([("gap", 0.001), ("channels.impact_force.frame_id", "other")]) is None
    assert rig.said("parameters {'gap': 0.001, 'channels.impact_force.frame_id': 'other'} take effect at "
                    "simulation time 0.040000 s")
    assert rt.set_parameters([("block_rate", 50.0), ("real_time_factor", 0.0)]) is None
    rig.run(1)
    force = [read_block(b) for b in rig.on("impact/force")]
    assert force[-1].header.frame_id == "other" and len(force[-1].samples) == 400   # 50 blocks/s from 40 ms on
    spans = [block_span(b) for b in rig.on("impact/force")]
    assert all(b[0] == a[0] + a[1] for a, b in zip(spans, spans[1:], strict=False))
    assert rt.diagnostics()[0].values["real_time_factor_target"] == "0"
    wall = make_rig()
    assert "cannot switch from 1 while running" in wall.rt.set_parameters([("real_time_factor", 2.0)])


def test_a_lockstep_window_under_two_blocks_is_refused():
    with pytest.raises(ConfigError, match=r"lockstep.window.*two block periods"):
        load_settings(lockstep(**{"lockstep.window": 0.015}))


# ---- diagnostics ------------------------------------------------------------------------------------------------

def test_diagnostics_say_how_late_the_blocks_left_and_what_went_out():
    rig = make_rig()
    rt, clock = rig.rt, rig.clock
    step = rt.step()
    clock.advance(step.wait + 0.004)          # every block 4 ms late
    for _ in range(20):
        rig.run(1)
        clock.advance(0.010)
    pacing = rt.diagnostics({rt.topics["impact/force"]: 2})[0]
    values = pacing.values
    assert pacing.level == OK and pacing.message == "running" and pacing.name == "rimd_simulator: pacing"
    assert float(values["lateness_p50_ms"]) == pytest.approx(4.05, abs=0.01)   # 4 ms, and the last sample's 50 us
    assert values["overruns"] == "0" and values["blocks_published"] == "20"
    assert values["/rig/impact/force published"] == "20" and values["/rig/impact/force subscribers"] == "2"
    assert values["/rig/session published"] == "1" and values["/rig/cart/displacement subscribers"] == "0"
    assert values["run_id"] == rt.run_id and values["time_base"] == "wall_clock"
    since_anchor = clock.now - (100.0 - (WALL0 - rt.t0_ns) / 1e9)
    assert float(values["real_time_factor_achieved"]) == pytest.approx(0.2 / since_anchor, abs=1e-3)
    clock.advance(0.050)                      # 50 ms late: overruns (later than one block period)
    rig.run(3)
    pacing = rt.diagnostics()[0]
    assert pacing.level == WARN and pacing.values["overruns"] == "3" and "3 overruns" in pacing.message


def test_an_integration_error_stops_the_loop_and_says_why():
    from rimd_sim.errors import IntegrationError

    rig = make_rig(real_time_factor=0.0)

    def broken(bounds):  # noqa: ANN001, ARG001
        raise IntegrationError("the step size fell below its floor")

    rig.rt._sim.advance_blocks = broken
    assert rig.rt.step() == Step(stopped=True)
    assert rig.said("simulation stopped: the step size fell below its floor", "error")
    pacing = rig.rt.diagnostics()[0]
    assert pacing.level == ERROR and pacing.message == "stopped: the step size fell below its floor"


# ---- the bytes --------------------------------------------------------------------------------------------------

def test_every_message_is_what_rclpy_builds_field_by_field():
    """The runtime's bytes against rclpy's serialization of the same messages filled field by field with rclpy's
    message classes (the reference builder below): rclpy reads them as equal messages, and the bytes are equal but
    for the alignment padding, which rclpy leaves as the buffer held it and the runtime zeroes."""
    serialization = pytest.importorskip("rclpy.serialization")
    msgs = pytest.importorskip("rimd_msgs.msg")
    from rosgraph_msgs.msg import Clock

    rig = make_rig(real_time_factor=0.0, seed=3, **{
        "capture.enabled": True, "motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75,
        "faults": ["channel=impact_force kind=offset start=0.3 duration=0.2 magnitude=2.0",
                   "channel=rimd_acceleration kind=dropout start=0.4 duration=0.05"]})
    rt = rig.rt
    blocks = []
    advance = rt._sim.advance_blocks
    rt._sim.advance_blocks = lambda bounds: blocks.extend(advance(bounds)) or blocks[-len(bounds):]
    rig.run(3)
    before = rt.config
    rt.set_parameters([("channels.impact_force.frame_id", "force_frame")])   # the node's config at once
    rt.reset()
    rig.run(7)
    expected = []   # (key, message) as rclpy's message classes build them
    for number, block in enumerate(blocks):
        config = before if number < 30 else rt.config
        for name in ("cart_displacement", "rimd_displacement", "rimd_acceleration", "impact_force"):
            ch = config.channel(name)
            for d in block.deliveries[name]:
                m = msgs.SampleBlock(first_index=d.first_index, sample_rate=ch.sample_rate, samples=d.samples.tolist(),
                                     unit=ch.unit, range_min=ch.range_min, range_max=ch.range_max,
                                     saturated_count=d.saturated)
                m.header.stamp.sec, m.header.stamp.nanosec = divmod(d.first_index * S // int(ch.sample_rate), S)
                m.header.frame_id = ch.frame_id
                expected.append((CHANNEL_TOPICS[name], m))
        for cap in block.captures:
            for which, values, channel in (("force", cap.force, "impact_force"),
                                           ("acceleration", cap.acceleration, "rimd_acceleration")):
                m = msgs.Capture(index=cap.number, sample_rate=cap.sample_rate,
                                 pre_trigger_samples=cap.pre_trigger_samples, samples=values.tolist(),
                                 unit=config.channel(channel).unit, trigger_level=cap.threshold)
                m.header.stamp.sec, m.header.stamp.nanosec = divmod(rt.stamp_of(cap.trigger_time), S)
                m.header.frame_id = config.channel(channel).frame_id
                expected.append((f"capture/{which}", m))
        for event in block.fault_events:
            spec = event.fault
            m = msgs.FaultEvent(event=event.event, id=spec.number, channel=spec.channel, kind=spec.kind,
                                start=float(spec.start), duration=float(spec.duration), magnitude=spec.magnitude,
                                detail=event.detail)
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(rt.stamp_of(event.time), S)
            m.header.frame_id = config.channel(spec.channel).frame_id
            expected.append(("faults", m))
        first, rows = block.truth
        m = msgs.RigState(first_index=first, sample_rate=config.truth_rate, in_contact=(rows[10] != 0.0).tolist())
        for i, name in enumerate(("theta", "theta_dot", "cart_position", "rimd_position", "rimd_velocity",
                                  "rimd_acceleration", "penetration", "contact_force", "motor_phase",
                                  "motor_frequency")):
            setattr(m, name, rows[i].tolist())
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(round(first * S / config.truth_rate), S)
        m.header.frame_id = "truth"
        expected.append(("truth", m))
        for imp in block.impacts:
            m = msgs.ImpactEvent(duration=imp.duration, peak_force=imp.peak_force, impulse=imp.impulse,
                                 impact_velocity=imp.impact_velocity, max_penetration=imp.max_penetration,
                                 excitation_frequency=imp.excitation_frequency,
                                 excitation_phase=imp.excitation_phase, cycle_index=imp.cycle_index, index=imp.index)
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(round(imp.t_start * 1e9), S)
            m.header.frame_id = "impact_force_sensor"
            expected.append(("impact/events", m))
        mo = block.motor
        m = msgs.MotorState(frequency_setpoint=mo.frequency_setpoint, frequency=mo.frequency, phase=mo.phase,
                            cycle_index=max(mo.cycle_index, 0), ramp_rate=mo.ramp_rate, cart_position=mo.cart_position)
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(rt.stamp_of(block.t_stop), S)
        m.header.frame_id = "motor"
        expected.append(("motor/state", m))
        expected.append(("/clock", Clock(clock=m.header.stamp)))
    sent = [(k, d) for k, d in rig.sent if k != "session"]
    assert [k for k, _ in sent] == [k for k, _ in expected]
    assert {k for k, _ in expected} == {*CHANNEL_TOPICS.values(), "capture/force", "capture/acceleration", "faults",
                                        "truth", "impact/events", "motor/state", "/clock"}, "every message type"
    assert any(m.header.frame_id == "force_frame" for k, m in expected if k == "impact/force")
    for (key, data), (_, message) in zip(sent, expected, strict=True):
        theirs = serialization.serialize_message(message)
        assert serialization.deserialize_message(data, type(message)) == message, key
        assert len(theirs) == len(data) and all(a == b or b == 0 for a, b in zip(theirs, data, strict=True)), key
    # The run's identity: every field as the node set it.
    for data, reason, sequence in zip(rig.on("session"), ("start", "reset"), (0, 1), strict=True):
        s = serialization.deserialize_message(data, msgs.RigSession)
        assert (s.reason, s.sequence, s.seed, s.node, s.time_base, s.header.frame_id) == (
            reason, sequence, 3, "/rig/rimd_simulator", "simulation", "rimd_virtual_rig")
        assert s.header.stamp == s.start_stamp and s.simulation_time == (s.start_stamp.nanosec / 1e9)
    assert np.isfinite([read_block(d, "rimd_msgs/msg/RigState").theta[0] for d in rig.on("truth")]).all()


@settings(max_examples=300, deadline=None)
@given(t0=st.integers(0, 2**62), first=st.integers(0, 10**12), count=st.integers(1, 12),
       num=st.integers(1, 4 * 10**9), den=st.integers(1, 1000))
def test_block_end_stamps_are_the_rounded_exact_boundaries(t0, first, count, num, den):
    """The pacing's integer boundaries are ``stamp_ns`` of the exact Fractions, ties rounded to even included."""
    from rimd_sim.runtime.simulator import block_end_stamps, stamp_ns

    rate = Fraction(num, den)
    assert block_end_stamps(t0, first, count, rate) == [stamp_ns(t0, Fraction(k) / rate)
                                                        for k in range(first, first + count)]
    assert block_end_stamps(0, 1, 3, Fraction(2 * 10**9)) == [0, 1, 2]   # 0.5, 1, 1.5 ns: half to even
