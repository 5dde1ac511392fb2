"""The reference controller (rimd_sim.ros.examples.resonance_seeker) against the running rig in lockstep.

Hypotheses:

* wired as docs/control.md says (its commands on /rig/motor/command through MotorCommander, its progress as a
  controller's), the node in lockstep with the rig makes the decisions the offline closed loop makes against the
  rig's core, bit for bit: the same observations (frequency, mean true peak, the impacts' times), the same
  setpoints, converged at the same simulation time, within 0.05 Hz of the rest sweep's resonance, at gap 0 and at
  gap 1.0 mm (tests/runtime/test_closed_loop.py checks the algorithm's convergence offline too); each
  setpoint shows on /rig/motor/state from the end of the block after the impact that decided it (one block of
  dead time);
* two runs give the same command sequence and the same data (the recorded impact events and ground truth), bit
  for bit;
* the rig's log does not grow with the commands.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from harness.resonance import rest_resonance
from rimd_sim.io.reader import open_recording
from rimd_sim.ros.examples.resonance_seeker import PerturbObserve, seek_offline
from rimd_sim.ros.testing import RigFactory
from rimd_sim.settings.config import load_config

pytestmark = pytest.mark.ros

class Runs:
    """Runs of the controller against rigs of one module-scoped factory, each made once (two tests share one)."""

    def __init__(self, factory: RigFactory, base: Path) -> None:
        self.factory, self.base = factory, base
        self.done: dict[tuple[float, int], dict[str, Any]] = {}

    def get(self, gap: float, number: int = 1) -> dict[str, Any]:
        key = (gap, number)
        if key not in self.done:
            rig = self.factory(consumers=["seeker"], parameters={"gap": gap})
            out = self.base / f"seeker_{gap * 1e3:g}mm_{number}.json"
            subprocess.run([sys.executable, "-m", "rimd_sim.ros.examples.resonance_seeker", "--lockstep", "seeker",
                            "--until", "120", "--json", str(out)], env=rig.env, check=True, timeout=300,
                           stdout=subprocess.DEVNULL)
            assert rig.stop() == 0
            report = json.loads(out.read_text())
            recording = open_recording(rig.recording)
            until_ns = round(report["converged_at_s"] * 1e9)
            recorded = {topic: [m.data for m in recording.messages([topic]) if _stamp(m.data) <= until_ns]
                        for topic in ("/rig/impact/events", "/rig/truth", "/rig/motor/state")}
            self.done[key] = {"report": report, "recorded": recorded, "log": rig.log()}
        return self.done[key]


def _stamp(data: bytes) -> int:
    """The header stamp (ns) of a serialized message whose first field is a std_msgs/Header."""
    sec = int.from_bytes(data[4:8], "little", signed=True)
    return sec * 1_000_000_000 + int.from_bytes(data[8:12], "little")


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest) -> Iterator[Runs]:
    factory = RigFactory(tmp_path_factory.mktemp("seeker_rigs"), config=request.config)
    try:
        yield Runs(factory, tmp_path_factory.mktemp("seeker_reports"))
    finally:
        factory.stop_all()


@pytest.mark.parametrize("gap", [0.0, 1e-3])
def test_in_lockstep_the_node_makes_the_offline_decisions_and_finds_the_resonance(runs, gap):
    report = runs.get(gap)["report"]
    seeker = PerturbObserve(start_hz=3.0)
    applied = seek_offline(load_config(None, {"gap": gap}), seeker, 120.0)
    resonance, _ = rest_resonance(gap)
    assert report["converged"] and report["converged_at_s"] == seeker.converged_at
    assert report["observations"] == [vars(o) for o in seeker.observations]   # bit for bit (JSON keeps floats)
    assert [c["frequency_hz"] for c in report["commands"]] == [a.command.frequency_hz for a in applied]
    assert abs(report["frequency_hz"] - resonance) <= 0.05, (report["frequency_hz"], resonance)
    # Read back from /rig/motor/state: each setpoint in force from the end of the block it was decided in (the
    # motor state at that block's end was computed before it): seen at the next block's end. The last one is
    # not seen: the node stopped at its decision.
    seen = [(round(a["seen_at_s"], 6), a["setpoint_hz"]) for a in report["applied"]]
    assert seen[:len(applied) - 1] == [(round(float(a.time) + 0.01, 6), a.command.frequency_hz)
                                       for a in applied[:-1]]


def test_two_runs_give_the_same_commands_and_data_bit_for_bit(runs):
    first, second = runs.get(0.0, 1), runs.get(0.0, 2)
    assert first["report"]["commands"] == second["report"]["commands"]
    # The rest of the report too, but for the setpoints read back from /rig/motor/state after the last decision:
    # a topic the controller does not hold the rig on, read until the node stops.
    until = first["report"]["converged_at_s"]

    def decided(report):
        return {**report, "applied": [a for a in report["applied"] if a["seen_at_s"] <= until]}

    assert decided(first["report"]) == decided(second["report"])
    for topic, messages in first["recorded"].items():
        assert messages == second["recorded"][topic], topic
    assert len(first["recorded"]["/rig/impact/events"]) > 100 and len(first["recorded"]["/rig/truth"]) > 3000


def test_the_rigs_log_does_not_grow_with_the_commands(runs):
    run = runs.get(0.0)
    lines = run["log"].splitlines()
    assert not [line for line in lines if "set_motor_frequency at" in line or "motor command " in line]
    summaries = [line for line in lines if "motor commands:" in line]
    assert summaries   # the commands are summed up
    assert len(summaries) < len(run["report"]["commands"])
