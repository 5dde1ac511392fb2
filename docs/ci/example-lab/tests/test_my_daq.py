"""Our DAQ software against the RIMD twin: the rimd_rig fixture comes with `pip install rimd_sim[testing]`."""

import json
import sys
from pathlib import Path

MY_DAQ = Path(__file__).resolve().parent.parent / "my_daq.py"


def test_my_daq_gets_every_sample(rimd_rig, tmp_path):
    """Two seconds of the force channel, every sample, no hole."""
    rig = rimd_rig(consumers=["my_daq"], seed=7, until=2.0)   # in lockstep with my_daq; holds at 2 s
    report = tmp_path / "report.json"
    rig.run([sys.executable, str(MY_DAQ), "--until", "2", "--json", str(report)])
    got = json.loads(report.read_text())
    assert got["holes"] == 0 and got["samples"] == len(rig.channel("impact_force", 0.0, 2.0))


def test_the_rig_answers_its_motor_service(rimd_rig):
    """The motor service answers, and simulation time goes on."""
    rig = rimd_rig(seed=1)   # in lockstep with its recorder
    assert rig.motor(5.0).success
    rig.wait_until_simulated(1.0)
