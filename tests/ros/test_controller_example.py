"""The reference controller (rimd_sim.ros.examples.resonance_seeker) against the running rig in lockstep.

Hypotheses:

* wired as docs/control.md says (its commands on /rig/motor/command through MotorCommander, its progress as a
  controller's), the node in lockstep with the rig makes the decisions the offline closed loop makes against the
  rig's core, bit for bit: the same observations (frequency, mean true peak, the impacts' times), the same
  setpoints, converged at the same simulation time, within 0.05 Hz of the rest sweep's resonance, at gap 0 and at
  gap 1.0 mm (tests/runtime/test_closed_loop.py checks the algorithm's convergence offline too); each
  setpoint shows on /rig/motor/state from the end of the block after the impact that decided it (one block of
  dead time);
* (two runs make the same decisions: each equals the offline run bit for bit; that the rig's data repeat in
  lockstep is tests/ros/test_lockstep.py's)
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
from rimd_sim.ros.examples.resonance_seeker import PerturbObserve, seek_offline
from rimd_sim.ros.testing import RigFactory
from rimd_sim.settings.config import load_config

pytestmark = pytest.mark.ros

class Runs:
    """Runs of the controller against rigs of one module-scoped factory, one per gap, each made once (the tests
    share them)."""

    def __init__(self, factory: RigFactory, base: Path) -> None:
        self.factory, self.base = factory, base
        self.done: dict[float, dict[str, Any]] = {}

    def get(self, gap: float) -> dict[str, Any]:
        if gap not in self.done:
            rig = self.factory(consumers=["seeker"], record=False, parameters={"gap": gap})
            out = self.base / f"seeker_{gap * 1e3:g}mm.json"
            subprocess.run([sys.executable, "-m", "rimd_sim.ros.examples.resonance_seeker", "--lockstep", "seeker",
                            "--until", "120", "--json", str(out)], env=rig.env, check=True, timeout=300,
                           stdout=subprocess.DEVNULL)
            assert rig.stop() == 0
            self.done[gap] = {"report": json.loads(out.read_text()), "log": rig.log()}
        return self.done[gap]


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


def test_the_rigs_log_does_not_grow_with_the_commands(runs):
    run = runs.get(0.0)
    lines = run["log"].splitlines()
    assert not [line for line in lines if "set_motor_frequency at" in line or "motor command " in line]
    summaries = [line for line in lines if "motor commands:" in line]
    assert summaries   # the commands are summed up
    assert len(summaries) < len(run["report"]["commands"])
