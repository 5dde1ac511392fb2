"""``rimd experiment`` on the running rig, then ``rimd analyze``: real simulator, recorder and CLI processes.

The simulator runs at 8x real time. The experiment is a continued upward stepped sweep with ramps, so the
reference is the core's ``sweep(..., direction="up")`` from the same starting frequency with the same ramp
rate; its steady peaks are compared with what ``rimd analyze`` reads from the recording alone.
"""

from __future__ import annotations

import csv
import json
import shutil
import signal
from pathlib import Path

import pytest

from harness.rig import run_for
from harness.ros import call_service, spin_until
from rimd_sim.analysis.sweep import sweep
from rimd_sim.core import SimConfig

pytestmark = pytest.mark.ros

RTF = "8.0"


def _rimd(ros_processes, *args: str, name: str):  # noqa: ANN001
    executable = shutil.which("rimd")
    assert executable is not None, "rimd is not on PATH: source env.sh"
    return ros_processes.start([executable, *args], name=name)


def _simulator(ros_processes, gap: float, f0: float):  # noqa: ANN001
    sim = ros_processes.start_node(
        "rimd_simulator", "--ros-args", "-p", f"real_time_factor:={RTF}", "-p", f"gap:={gap}",
        "-p", f"motor.initial_frequency:={f0}", "-p", f"motor.initial_setpoint:={f0}")
    sim.wait_for_output(r"rig ready", timeout=60)
    return sim


def _steps(out: Path) -> list[dict]:
    with open(out / "steps.csv") as fh:
        return list(csv.DictReader(fh))


def test_experiment_then_analyze_agrees_with_the_up_sweep(ros_processes, ros_executor, tmp_path):
    freqs = [3.0, 3.5, 3.75, 4.0]
    dwell, settle, ramp = 6.0, 2.0, 2.0
    simulator = _simulator(ros_processes, 0.0, freqs[0])
    out = tmp_path / "exp"
    experiment = _rimd(ros_processes, "experiment", "--frequencies", *map(str, freqs), "--dwell", str(dwell),
                       "--settle", str(settle), "--ramp-rate", str(ramp), "--out", str(out), name="experiment")
    assert experiment.wait(90) == 0, experiment.tail()
    assert "step 4/4" in experiment.output()   # progress shown

    summary = json.loads((out / "summary.json").read_text())
    assert summary["loss"]["complete"] and not summary["loss"]["lost_samples"]
    rows = _steps(out)
    assert [float(r["frequency_hz"]) for r in rows][-len(freqs):] == freqs
    rows = rows[-len(freqs):]
    # The reference: the core's continued upward sweep from the same start, same ramp rate.
    ref = sweep(SimConfig().with_parameters({"gap": 0.0}), freqs, "up", cycles=18, measure_cycles=8, ramp_rate=ramp)
    report = []
    for row, point in zip(rows, ref.points, strict=True):
        events, channel = float(row["peak_force_events_n"]), float(row["peak_force_channel_n"])
        report.append((point.frequency_hz, point.peak_force_n, events, channel))
        assert float(row["steady_seconds"]) >= dwell - settle - 1.0
        assert abs(float(row["impacts_per_cycle_events"]) - point.impacts_per_cycle) < 0.1
    print("f, sweep up, events, channel:", report)
    for f, expected, events, channel in report:
        assert abs(events / expected - 1) <= 0.02, (f, expected, events)
        # The target for the force channel alone is 5 %; it is NOT met (README, "rimd analyze"): the
        # spring-dashpot force is largest at contact start (it jumps to c v0) and falls by up to 18 % within one
        # 50 us sample, so the largest sample of a 0.37 ms contact is low by 0-18 %, and at 4 Hz (5000 samples
        # per impact period) every impact of a step is sampled at the same phase, so the step maximum does not
        # average it out (measured: 2-9 % low in one run, 18 % low at 4 Hz in another). Asserted here is what
        # sampling allows: never above the true peak (plus noise), at most one sample's fall (20 %) below.
        assert expected * 0.80 <= channel <= expected + 0.1, (f, expected, channel)
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

    # A setpoint above motor.max_frequency: one clear line naming it, exit 1, the rig keeps running.
    refused = _rimd(ros_processes, "experiment", "--no-record", "--frequencies", "50", "--dwell", "1",
                    "--settle", "0.2", "--out", str(tmp_path / "refused"), name="refused")
    assert refused.wait(60) == 1
    error = refused.output().strip().splitlines()[-1]
    assert error.startswith("rimd experiment: setpoint 50 Hz") and "refused" in error
    assert "Traceback" not in refused.output()
    import rclpy

    from rimd_msgs.msg import MotorState
    node = rclpy.create_node("probe", context=ros_executor.context)
    ros_executor.add_node(node)
    states = []
    node.create_subscription(MotorState, "/rig/motor/state", states.append, 10)
    assert spin_until(ros_executor, lambda: len(states) >= 5, 20)
    assert simulator.is_running and states[-1].frequency_setpoint == 4.0

    # The same recording cut at 60 %: analysed as far as it is valid, the loss reported.
    (mcap,) = (out / "recording").glob("*.mcap")
    cut = tmp_path / "cut.mcap"
    data = mcap.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    analysis = _rimd(ros_processes, "analyze", str(cut), "--out", str(tmp_path / "cut_out"), "--settle", str(settle),
                     name="analyze_cut")
    assert analysis.wait(60) == 0, analysis.tail()
    cut_summary = json.loads((tmp_path / "cut_out" / "summary.json").read_text())
    assert not cut_summary["loss"]["complete"]
    assert "incomplete" in cut_summary["loss"]["files"][0] and "LOSS" in analysis.output()
    assert 0 < cut_summary["impacts"]["events"] < impacts["events"]
    cut_rows = {float(r["frequency_hz"]): r for r in _steps(tmp_path / "cut_out")}
    assert len(cut_rows) < len(freqs) + 1   # the later steps are lost with the tail
    assert cut_rows[3.0]["peak_force_events_n"] == rows[0]["peak_force_events_n"]   # the valid part: same result


def test_gap_2_4mm_up_sweep_stays_off_band_b_until_perturbed(ros_processes, ros_executor, tmp_path):
    from rimd_msgs.msg import ImpactEvent
    from rimd_msgs.srv import Perturb

    _simulator(ros_processes, 0.0024, 2.5)
    out = tmp_path / "exp"
    recorder = ros_processes.start_node("rimd_recorder", "--ros-args", "-p", f"output_dir:={out / 'rec'}",
                                        "-p", "topics:=['/rig/.*']")
    recorder.wait_for_output(r"recording /rig/impact/events", timeout=30)
    experiment = _rimd(ros_processes, "experiment", "--no-record", "--frequencies", "2.5", "3.0", "4.0", "5.25",
                       "--dwell", "6", "--settle", "2", "--ramp-rate", "2", "--out", str(out), name="experiment")
    assert experiment.wait(90) == 0, experiment.tail()

    import rclpy
    node = rclpy.create_node("probe", context=ros_executor.context)
    ros_executor.add_node(node)
    events = []
    node.create_subscription(ImpactEvent, "/rig/impact/events", events.append, 100)
    run_for(ros_executor, 1.0)   # 8 s of simulation at 5.25 Hz
    assert events == [], "the upward sweep should stay on the non-impacting motion at 5.25 Hz"
    # A kick lands on band B from about 8 of 10 phases of the cycle (measured with the core): kick again,
    # as an operator would, until the impacts come (at most 5 kicks).
    client = node.create_client(Perturb, "/rig/perturb")
    for _ in range(5):
        response = call_service(ros_executor, node, client, Perturb.Request(velocity=0.1), 10)
        assert response.success, response.message
        events.clear()
        run_for(ros_executor, 2.0)   # 16 s of simulation
        if len(events) >= 20:
            break
    assert len(events) >= 20, "no kick put the rig on band B"
    steady = events[-12:]
    gaps = {b.cycle_index - a.cycle_index for a, b in zip(steady, steady[1:], strict=False)}
    assert gaps == {2}, f"band B: one impact every two cycles, got cycle gaps {gaps}"
    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(30) == 0

    analysis = _rimd(ros_processes, "analyze", str(out / "rec"), "--out", str(out / "an"), "--settle", "2",
                     name="analyze")
    assert analysis.wait(60) == 0, analysis.tail()
    rows = {float(r["frequency_hz"]): r for r in _steps(out / "an")}
    assert float(rows[2.5]["impacts_per_cycle_events"]) > 0.9                 # band A: impacting
    assert int(rows[3.0]["impacts_events"]) == int(rows[4.0]["impacts_events"]) == 0   # fell off, stays off
    summary = json.loads((out / "an" / "summary.json").read_text())
    t_kick = (response.effective_stamp.sec * 10**9 + response.effective_stamp.nanosec - summary["origin_ns"]) * 1e-9
    with open(out / "an" / "impact_events.csv") as fh:
        recorded = [float(r["time_s"]) for r in csv.DictReader(fh)]
    at_5_25 = [t for t in recorded if t >= float(rows[5.25]["start_s"])]
    assert at_5_25 and min(at_5_25) >= t_kick   # no impact at 5.25 Hz before the kick
    assert float(rows[5.25]["peak_force_events_n"]) > 50.0
