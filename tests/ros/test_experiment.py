"""``rimd experiment`` on the running rig, then ``rimd analyze``: real simulator, recorder and experiment processes;
the analysis, which needs no ROS, in the test's process.

The rig runs in lockstep (the ``rimd_rig`` fixture) as fast as its consumer, the experiment's own recorder,
allows: nothing is lost and no wall-clock pacing is waited for. It starts paused and is resumed once the
experiment has scheduled its steps, so the whole run, from rest at t = 0, is the same however loaded the
machine is. The experiment is a continued upward stepped sweep with ramps, so the reference is the core's
``sweep(..., direction="up")`` from the same starting frequency with the same ramp rate; its steady peaks are
compared with what ``rimd analyze`` reads from the recording alone.
"""

from __future__ import annotations

import contextlib
import csv
import io
import shutil
from pathlib import Path

import numpy as np
import pytest

from harness.outputs import read_json
from rimd_sim.analysis.dynamics.sweep import sweep
from rimd_sim.ros.clients.experiment import RECORDER_NODE

pytestmark = pytest.mark.ros


def _rimd(ros_processes, rig, *args: str, name: str):
    executable = shutil.which("rimd")
    assert executable is not None, "rimd is not on PATH: source env.sh"
    return ros_processes.start([executable, *args], name=name, env=rig.env)


#: Stamp (s) of the first step.
START = 4.0
#: The same for the kicked sweep at 2.4 mm, whose kick stamp (60 s) was measured on the core with this schedule.
KICKED_START = 10.0


def _rig(rimd_rig, gap: float, f0: float, *, experiment_records: bool):
    """A paused rig in lockstep with the experiment's recorder (``experiment_records``), else the rig's own."""
    return rimd_rig(consumers=[RECORDER_NODE] if experiment_records else [], record=not experiment_records,
                    parameters={"gap": gap, "motor.initial_frequency": f0, "motor.initial_setpoint": f0,
                                "start_paused": True})


def _resume_when_scheduled(experiment, rig) -> None:
    """Resume the paused rig once the experiment says its steps are scheduled."""
    experiment.wait_for_output(r"steps scheduled from t = ", timeout=90)
    assert rig.resume().success


def _analyze(recording: Path, out: Path, settle: float) -> tuple[int, str]:
    """``rimd analyze`` in this process (it needs no ROS): the exit status and what it printed."""
    from rimd_sim import cli

    said = io.StringIO()
    with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
        status = cli.main(["analyze", str(recording), "--out", str(out), "--settle", str(settle), "--no-plot"])
    return status, said.getvalue()


def _stamp(t) -> int:  # builtin_interfaces/Time
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def _steps(out: Path) -> list[dict]:
    with open(out / "steps.csv") as fh:
        return list(csv.DictReader(fh))


def _assert_recording_is_the_core_run(recording: Path, config, freqs: list[float], ramp: float,
                                      starts_ns: list[int]) -> None:
    """The recorded force channel and events equal the core's offline run of the schedule, sample for sample."""
    from fractions import Fraction

    from rimd_sim.analysis.recordings import recorded as rec
    from rimd_sim.instruments.rig_simulator import RigSimulator

    data = rec.load(recording)
    force = data.channels[rec.FORCE]
    core = RigSimulator(config, truth=False)
    for f, start in zip(freqs, starts_ns, strict=True):   # in lockstep the stamps are the simulation time
        core.set_motor_frequency(f, ramp, at=Fraction(start, 10**9))
    rate = Fraction(20000)
    last = int(force.index[-1])
    # Offline as far as the recording goes on any topic (the topics of a stopped recorder end at different
    # times: the events may reach past the force channel's last sample).
    until = max((last + 1) / 20000, float(data.events["time"][-1]) + data.origin_ns * 1e-9 if data.events["time"].size
                else 0.0)
    blocks = core.advance_blocks([Fraction(k, 10) for k in range(1, int(until * 10) + 3)])
    values = np.concatenate([b.channels["impact_force"].samples for b in blocks])
    first = int(force.index[0])
    assert force.rate == float(rate) and force.lost_samples == 0
    assert np.array_equal(force.values, values[first:last + 1]), "the recorded force is not the core's"
    peaks = {i.index: i.peak_force for b in blocks for i in b.impacts}
    recorded = dict(zip(data.events["index"].astype(int).tolist(), data.events["peak_force"].tolist(), strict=True))
    assert len(recorded) > 10 and all(peaks[i] == p for i, p in recorded.items()), "the events are not the core's"


def test_experiment_then_analyze_agrees_with_the_up_sweep(ros_processes, rimd_rig, tmp_path):
    freqs = [3.0, 3.5, 3.75, 4.0]
    dwell, settle, ramp = 6.0, 2.0, 2.0
    rig = _rig(rimd_rig, 0.0, freqs[0], experiment_records=True)
    out = tmp_path / "exp"
    experiment = _rimd(ros_processes, rig, "experiment", "--frequencies", *map(str, freqs), "--dwell", str(dwell),
                       "--settle", str(settle), "--ramp-rate", str(ramp), "--out", str(out), "--start", str(START),
                       name="experiment")
    _resume_when_scheduled(experiment, rig)
    assert experiment.wait(120) == 0, experiment.tail()
    assert "step 4/4" in experiment.output()   # progress shown
    end = START + len(freqs) * dwell   # the recorder's stop_at: the end of the last step
    assert f"the recording ends at t = {end:.9f} s" in experiment.output(), experiment.output()[-2000:]
    # Its recorder left the lockstep cleanly when it stopped: the rig goes on without waiting for it.
    assert f"consumer '{RECORDER_NODE}' left at" in rig.log(), rig.log()[-2000:]

    summary = read_json(out / "summary.json")
    assert summary["loss"]["complete"] and not summary["loss"]["lost_samples"]
    rows = _steps(out)
    assert [float(r["frequency_hz"]) for r in rows][-len(freqs):] == freqs
    rows = rows[-len(freqs):]
    # The reference: the core's continued upward sweep from the same start, same ramp rate.
    ref = sweep(rig.config, freqs, "up", cycles=18, measure_cycles=8, ramp_rate=ramp)
    report = []
    for row, point in zip(rows, ref.points, strict=True):
        events, channel = float(row["peak_force_events_n"]), float(row["peak_force_channel_n"])
        raw = float(row["peak_force_channel_largest_sample_n"])
        report.append((point.frequency_hz, point.peak_force_n, events, channel, raw))
        assert float(row["steady_seconds"]) >= dwell - settle - 1.0
        assert row["settled"] == "True", row   # the two halves of each steady window agree
        assert abs(float(row["impacts_per_cycle_events"]) - point.impacts_per_cycle) < 0.1
    print("f, sweep up, events, channel (fit), channel (largest sample):", report)
    for f, expected, events, channel, raw in report:
        assert abs(events / expected - 1) <= 0.02, (f, expected, events)
        # Force channel alone, within 5 % (docs/analyses.md): the spring-dashpot force is largest at contact
        # start (it jumps to c v0) and falls by up to 18 % within one 50 us sample, so the largest sample of a
        # 0.37 ms contact is 0-18 % low (at 4 Hz every impact of a step is sampled at the same phase); the
        # analysis fits the law's pulse to each impact's samples and reads its peak at the onset.
        assert abs(channel / expected - 1) <= 0.05, (f, expected, channel)
        assert expected * 0.80 <= raw <= expected + 0.1, (f, expected, raw)   # the raw reading: what sampling allows
    # The cross-check of the detection against the recorded events.
    impacts = summary["impacts"]
    assert impacts["events"] > 4 * 10 and impacts["matches"] >= impacts["events"] - impacts["not_covered"] - 1
    assert impacts["extras"] <= 1 and impacts["misses"] <= 1
    for figure in ("peak_force_vs_frequency.png", "impacts.png", "phase_planes.png"):
        assert (out / figure).stat().st_size > 10_000
    with open(out / "poincare.csv") as fh:
        strobe = [r for r in csv.DictReader(fh) if float(r["frequency_hz"]) == 3.75]
    assert len(strobe) >= 0.9 * (dwell - settle - 0.5) * 3.75   # one point per cycle of the steady window
    xs = [float(r["x_rel_m"]) for r in strobe]
    assert max(xs) - min(xs) < 5e-5   # period 1: the Poincare points of a steady step coincide (laser noise 10 um)

    # Every step took effect at its scheduled stamp, one dwell apart, and the recording is exactly what the
    # core computes offline for that schedule: the same schedule gives the same data however loaded the
    # machine is (the requests travel late; the rig applies them at the stamps they name).
    schedule = read_json(out / "experiment.json")["steps"]
    starts = [s["scheduled_stamp_ns"] for s in schedule]
    assert [s["effective_stamp_ns"] for s in schedule] == starts and starts[0] == round(START * 1e9)
    assert {b - a for a, b in zip(starts, starts[1:], strict=False)} == {round(dwell * 1e9)}
    _assert_recording_is_the_core_run(out / "recording", rig.config, freqs, ramp, starts)
    # Cut at the end of the last step, not where the recorder stopped: every sampled channel's last sample one
    # period short of it at most, no event or motor state after it; the analysis ends the last step there.
    from rimd_sim.analysis.recordings import recorded as rec

    data = rec.load(out / "recording")
    assert data.origin_ns == 0   # in lockstep from sample 0: recording times are simulation times
    for topic, channel in data.channels.items():
        assert end - 1.0 / channel.rate <= channel.time[-1] < end, (topic, channel.time[-1])
    assert data.events["time"][-1] < end and data.motor["time"][-1] < end
    assert float(rows[-1]["end_s"]) == end

    # A setpoint above motor.max_frequency: one clear line naming it, exit 1, the rig keeps running.
    refused = _rimd(ros_processes, rig, "experiment", "--no-record", "--frequencies", "50", "--dwell", "1",
                    "--settle", "0.2", "--out", str(tmp_path / "refused"), name="refused")
    assert refused.wait(60) == 1
    error = refused.output().strip().splitlines()[-1]
    assert error.startswith("rimd experiment: setpoint 50 Hz") and "refused" in error
    assert "Traceback" not in refused.output()
    from rimd_msgs.msg import MotorState

    states = []
    client = rig.client()
    client.node.create_subscription(MotorState, "/rig/motor/state", states.append, 10)
    assert client.spin_until(lambda: len(states) >= 5, 20), "the rig stopped publishing after the refusal"
    assert rig.rig.failed() is None and states[-1].frequency_setpoint == 4.0

    # The same recording cut at 60 %: analysed as far as it is valid, the loss reported.
    (mcap,) = (out / "recording").glob("*.mcap")
    cut = tmp_path / "cut.mcap"
    data = mcap.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    status, said = _analyze(cut, tmp_path / "cut_out", settle)
    assert status == 0, said[-2000:]
    cut_summary = read_json(tmp_path / "cut_out" / "summary.json")
    assert not cut_summary["loss"]["complete"]
    assert "incomplete" in cut_summary["loss"]["files"][0] and "LOSS" in said
    assert 0 < cut_summary["impacts"]["events"] < impacts["events"]
    cut_rows = {float(r["frequency_hz"]): r for r in _steps(tmp_path / "cut_out")}
    assert len(cut_rows) < len(freqs) + 1   # the later steps are lost with the tail
    cut3, full3 = cut_rows[3.0], rows[0]
    if cut3["end_s"] == full3["end_s"]:   # the step is whole in the valid part: the same result
        assert cut3["peak_force_events_n"] == full3["peak_force_events_n"]
    else:                                 # the cut fell inside the step: a shorter window, never a larger peak
        assert float(cut3["end_s"]) < float(full3["end_s"])
        assert float(cut3["peak_force_events_n"]) <= float(full3["peak_force_events_n"])


def test_gap_2_4mm_up_sweep_stays_off_band_b_until_perturbed(ros_processes, rimd_rig, tmp_path):
    from rimd_msgs.msg import ImpactEvent

    rig = _rig(rimd_rig, 0.0024, 2.5, experiment_records=False)   # the rig's recorder, in lockstep
    out = tmp_path / "exp"
    events = []
    client = rig.client()
    client.node.create_subscription(ImpactEvent, "/rig/impact/events", events.append, 10_000)
    experiment = _rimd(ros_processes, rig, "experiment", "--no-record", "--frequencies", "2.5", "3.0", "4.0",
                       "5.25", "--dwell", "6", "--settle", "2", "--ramp-rate", "2", "--out", str(out), "--start",
                       str(KICKED_START), name="experiment")
    experiment.wait_for_output(r"steps scheduled from t = ", timeout=90)
    # A kick at an exact stamp, at 5.25 Hz, asked before the rig moves: the whole run is deterministic (from rest,
    # every command names its stamp). Measured with the core, a kick of +0.1 m/s lands on band B from t = 56, 60
    # or 64 s and falls off again from 58 or 62 s: the phase decides, so the stamp is fixed.
    kick_ns = 60 * 10**9
    response = rig.perturb(0.1, at=60.0)
    assert response.success, response.message
    assert _stamp(response.effective_stamp) == kick_ns
    assert rig.resume().success
    assert experiment.wait(120) == 0, experiment.tail()

    def after_kick() -> list:
        return [e for e in events if _stamp(e.header.stamp) >= kick_ns]

    assert client.spin_until(lambda: len(after_kick()) >= 20, 120), "the kick did not put the rig on band B"
    last_step = read_json(out / "experiment.json")["steps"][-1]["effective_stamp_ns"]
    before = [e for e in events if last_step <= _stamp(e.header.stamp) < kick_ns]
    assert before == [], "the upward sweep should stay on the non-impacting motion at 5.25 Hz until the kick"
    steady = after_kick()[-12:]
    gaps = {b.cycle_index - a.cycle_index for a, b in zip(steady, steady[1:], strict=False)}
    assert gaps == {2}, f"band B: one impact every two cycles, got cycle gaps {gaps}"
    assert rig.stop() == 0   # the recorder finishes its file with everything the rig published

    status, said = _analyze(rig.recording, out / "an", 2.0)
    assert status == 0, said[-2000:]
    rows = {float(r["frequency_hz"]): r for r in _steps(out / "an")}
    assert float(rows[2.5]["impacts_per_cycle_events"]) > 0.9                 # band A: impacting
    assert int(rows[3.0]["impacts_events"]) == int(rows[4.0]["impacts_events"]) == 0   # fell off, stays off
    summary = read_json(out / "an" / "summary.json")
    assert summary["loss"]["complete"] and not summary["loss"]["lost_samples"]   # lockstep: nothing lost
    t_kick = (kick_ns - summary["origin_ns"]) * 1e-9
    with open(out / "an" / "impact_events.csv") as fh:
        recorded = [float(r["time_s"]) for r in csv.DictReader(fh)]
    at_5_25 = [t for t in recorded if t >= float(rows[5.25]["start_s"])]
    assert at_5_25 and min(at_5_25) >= t_kick   # no impact at 5.25 Hz before the kick
    assert float(rows[5.25]["peak_force_events_n"]) > 50.0
