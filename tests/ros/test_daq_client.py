"""The reference DAQ client (rimd_sim.ros.examples.daq_client) and the pytest plugin users test their DAQ with.

Hypotheses:

- continuity with a reorder window: a block that comes after a later one is reordered, not lost; a hole
  that later data has passed by more than the window is lost, counted once with its samples;
- impacts are measured from the running baseline: after an offset fault's step the impacts keep their height
  and the step itself is no impact (a fixed threshold would have seen one long "impact" and then peaks 40 N
  too high: the trap docs/daq-client.md names);
- the documented fixture example (docs/testing.md, copied here verbatim) passes: against a rig in lockstep held
  at 5 s, with a dropout and an offset on the force channel, the client finds every impact the rig's ground
  truth says it was sent (once, where it happened), names the dropout and the offset where the rig says they
  started, loses no block it was sent, measures its heights from the baseline, and the recording ends at 5 s;
- two rigs of one test do not hear each other (each its own domain).
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from rimd_sim.ros.examples.daq_client import Continuity, PeakDetector

pytestmark = pytest.mark.ros


def test_a_reordered_block_is_not_a_lost_block():
    c = Continuity(reorder_window=0.05)     # 2 kHz blocks of 20 samples: 10 ms each
    assert c.add(0, 20, 2000.0) == []
    assert c.add(40, 20, 2000.0) == []      # block 20 is late, not lost yet
    assert c.add(20, 20, 2000.0) == []      # here it is
    assert (c.reordered, c.lost_blocks, c.next_index) == (1, 0, 60)
    lost = {first: c.add(first, 20, 2000.0) for first in (80, 100, 120, 140, 160)}
    # Block 60 never comes: lost once 50 ms of later data have passed it (at block 140, ending at 160).
    assert lost == {80: [], 100: [], 120: [], 140: [(60, 20)], 160: []}
    assert (c.lost_blocks, c.lost_samples, c.next_index) == (1, 20, 180)
    assert c.add(60, 20, 2000.0) == [] and c.duplicates == 1   # too late: counted, not taken twice


def test_impacts_are_measured_from_the_baseline_through_an_offset_step():
    rate, t = 20_000.0, np.arange(40_000) / 20_000.0
    force = np.zeros_like(t)
    impacts = [0.25, 0.52, 0.79, 1.31, 1.58, 1.85]
    for at in impacts:                       # half-sine pulses of 0.4 ms and 80 N
        pulse = (t >= at) & (t < at + 4e-4)
        force[pulse] += 80.0 * np.sin(np.pi * (t[pulse] - at) / 4e-4)
    force[t >= 1.0] += 40.0                  # an offset fault from 1 s
    detector = PeakDetector(threshold=10.0)
    for start in range(0, t.size, 200):      # 10 ms blocks, as the rig sends them
        detector.add(start / rate, rate, force[start:start + 200])
    assert [round(at, 3) for at, _ in detector.peaks] == [round(at + 2e-4, 3) for at in impacts]
    assert all(h == pytest.approx(80.0, rel=0.02) for _, h in detector.peaks)
    assert len(detector.steps) == 1 and detector.steps[0][0] == pytest.approx(1.0, abs=1e-3)
    assert detector.steps[0][1] == pytest.approx(40.0, abs=0.5)


# ---- the documented example (docs/testing.md), verbatim -----------------------------------------------------
def test_my_daq_sees_every_impact_and_names_the_faults(rimd_rig, tmp_path):
    rig = rimd_rig(consumers=["daq"], seed=3, until=5.0, parameters={"motor.initial_frequency": 3.75}, faults=[
        {"channel": "impact_force", "kind": "dropout", "start": 2.0, "duration": 0.3},
        {"channel": "impact_force", "kind": "offset", "start": 3.0, "duration": 1.0, "magnitude": 40.0}])
    rig.run([sys.executable, "-m", "rimd_sim.ros.examples.daq_client", "--lockstep", "daq", "--until", "5",
             "--json", str(tmp_path / "report.json")])
    report = json.loads((tmp_path / "report.json").read_text())
    impacts, faults = rig.events(0.0, 5.0), rig.faults(0.0, 5.0)      # the twin's ground truth
    sent = impacts.time[(impacts.peak_force > 15.0) & ~faults.active(impacts.time, kind="dropout")]
    assert np.allclose([peak["at"] for peak in report["peaks"]], sent, atol=1e-3)   # each impact, found once
    assert {(f["kind"], round(f["at"], 2)) for f in report["faults_detected"]} == {("dropout", 2.0), ("offset", 3.0)}
# ---- end of the documented example --------------------------------------------------------------------------

    # Beyond the example: the client lost no block it was sent (the dropout's hole, nothing else), its heights
    # are measured from the baseline (the offset changes none), and the rig recorded no more than it was asked.
    force = report["channels"]["impact_force"]
    assert force["lost_samples"] == 0.3 * 20_000 and force["lost_blocks"] == 1
    assert all(c["lost_blocks"] == 0 for name, c in report["channels"].items() if name != "impact_force")
    assert rig.stop() == 0
    recorded = rig.channel("impact_force")
    assert recorded.time[-1] == pytest.approx(5.0 - 1 / 20_000, abs=1e-9)
    values = np.full(recorded.index[-1] + 1, np.nan)
    values[recorded.index] = recorded.value
    for peak in report["peaks"]:
        n = round(peak["at"] * 20_000)
        expected = np.nanmax(values[n - 5:n + 30]) - np.nanmedian(values[n - 400:n - 40])
        assert peak["height_n"] == pytest.approx(expected, abs=0.5), peak


@pytest.mark.timeout(180)
def test_against_a_rig_at_real_time_joined_late_the_client_counts_the_runs_seconds(ros_processes, tmp_path):
    """``rimd rig`` runs at real time and stamps in wall-clock time; the client, started after it, acquires
    ``--until`` seconds from the first sample it gets, and its times are the run's simulation seconds (a client
    that took the stamps for simulation time would stop at once, after one block per channel, with exit 0)."""
    sim = ros_processes.start_node("rimd_simulator", name="sim_wall_clock")
    sim.wait_for_output(r"rig ready: .* stamps: wall clock", timeout=90)
    report_file = tmp_path / "report.json"
    client = ros_processes.start_python("-m", "rimd_sim.ros.examples.daq_client", "--until", "1.5", "--json",
                                        str(report_file), "--timeout", "90", name="daq_wall_clock")
    assert client.wait(120) == 0, client.tail()
    sim.stop()
    report = json.loads(report_file.read_text())
    assert report["acquired_s"] >= 1.5 and 1.5 <= report["reached_s"] < 300, report["reached_s"]   # not 1.8e9
    assert report["reached_s"] - report["acquired_s"] > 0   # it joined a running rig: its first sample was not 0
    for name, channel in report["channels"].items():
        # 1.5 s of 10 ms blocks from the first sample of all channels: a channel whose first block came one block
        # after that has one block fewer.
        assert channel["blocks"] >= 149 and channel["lost_blocks"] == 0, (name, channel)
    (step,) = report["steps"]
    assert step["setpoint_hz"] == 3.75 and 0 <= step["from_s"] <= report["reached_s"]
    assert all(0 <= p["at"] <= report["reached_s"] for p in report["peaks"]) and report["peaks"]


def test_a_consumer_that_never_joins_is_named_when_the_rig_does_not_advance(rimd_rig):
    """``wait_until_simulated`` on a rig held by a consumer that never joined (a misspelt topic, a wrong name)
    says where the rig stands, the rig's last report of what holds it, and why a consumer may never join."""
    rig = rimd_rig(consumers=["nobody"], record=False)
    with pytest.raises(AssertionError) as held:
        rig.wait_until_simulated(0.5, timeout=5)
    message = str(held.value)
    assert message.startswith("the rig did not reach 0.5 s within 5 s: the rig has not simulated anything yet")
    assert "; its last lockstep report:" in message, message
    assert "waiting for nobody (not joined" in message and "one on a misspelt topic never does" in message, message


def test_two_rigs_in_one_test_do_not_hear_each_other(rimd_rig, capfd):
    a = rimd_rig(consumers=["nobody"], seed=1, record=False)   # held before its first block: cheap
    b = rimd_rig(consumers=["nobody"], seed=2, record=False)
    assert a.domain_id != b.domain_id and a.env["ROS_DOMAIN_ID"] != b.env["ROS_DOMAIN_ID"]
    session_a, session_b = a.session(), b.session()
    assert session_a.run_id != session_b.run_id and (session_a.seed, session_b.seed) == (1, 2)
    assert a.motor(5.0).success
    node = a.client().node
    assert node.count_publishers("/rig/session") == 1   # rig b is not in rig a's domain
    assert b.motor(4.0).success
    # Each rig's client node has a name of its own: rclpy's logger registry warns of none registered twice.
    assert "already registered" not in capfd.readouterr().err
