"""Our DAQ software against the RIMD twin: the rimd_rig fixture comes with `pip install rimd_sim[testing]`."""

import json
import subprocess
import sys
from pathlib import Path

MY_DAQ = Path(__file__).resolve().parent.parent / "my_daq.py"


def test_my_daq_gets_every_sample(rimd_rig, tmp_path):
    """Two seconds of the force channel, every sample, no hole."""
    rig = rimd_rig(consumers=["my_daq"], seed=7)   # in lockstep with my_daq: nothing lost, however slow
    report = tmp_path / "report.json"
    subprocess.run([sys.executable, str(MY_DAQ), "--until", "2", "--json", str(report)], env=rig.env, check=True,
                   timeout=180)
    got = json.loads(report.read_text())
    assert got["holes"] == 0 and got["samples"] >= 2 * 20_000


def test_the_rig_answers_its_motor_service(rimd_rig):
    """The motor service answers, and simulation time goes on."""
    rig = rimd_rig(seed=1)   # in lockstep with its recorder
    assert rig.motor(5.0).success
    rig.wait_until_simulated(1.0)
