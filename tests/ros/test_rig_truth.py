"""What a DAQ test asks the ``rimd_rig`` handle: the run's ground truth, a rig that holds at ``until``, bad input
refused before anything starts (rimd_sim.ros.testing, docs/testing.md).

Hypotheses:

- ``rimd_rig(until=T)`` simulates up to T and holds there: ``/clock`` reaches T, the recording's every channel
  ends at T exactly (its last sample one sample period before), and the simulator says it holds; a wait beyond T
  is refused at once;
- the handle's events, faults, motor states and channels equal what the recording holds, decoded independently
  (rclpy's deserializer), read while the rig runs (waiting until the recording holds the window) and after it
  stopped;
- a fault scenario naming an unknown channel or kind is refused before any process starts, with the closest name;
- ``rig.run(...)`` fails with the rig's diagnosis when the program does not exit in time, and with the program's
  exit status and its stderr when it fails.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from rimd_sim.errors import InputError

pytestmark = pytest.mark.ros

UNTIL = 1.5
FAULTS = [{"channel": "impact_force", "kind": "dropout", "start": 0.4, "duration": 0.2},
          {"channel": "rimd_displacement", "kind": "offset", "start": 0.9, "duration": 0.0, "magnitude": 0.002}]


@pytest.fixture(scope="module")
def held_rig(tmp_path_factory):
    """A rig at an impacting frequency with two faults, held at UNTIL, its recorder its only consumer."""
    from rimd_sim.ros.testing import RigFactory

    factory = RigFactory(tmp_path_factory.mktemp("held"))
    try:
        rig = factory(seed=5, until=UNTIL, faults=FAULTS,
                      parameters={"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
        live = {"events": rig.events(0.0, 1.0), "faults": rig.faults(0.0, 1.0), "force": rig.channel("impact_force",
                                                                                                         0.0, 1.0)}
        rig.wait_until_simulated(UNTIL)
        yield rig, live
    finally:
        factory.stop_all()


def _recorded(rig, topic, type_):
    """(stamp in s, message) of every message of ``topic`` in the rig's recording, decoded by rclpy."""
    from rclpy.serialization import deserialize_message

    from rimd_sim.io.reader import open_recording

    out = []
    for m in open_recording(rig.recording).messages([topic]):
        msg = deserialize_message(m.data, type_)
        out.append((msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, msg))
    return out


def test_until_holds_the_rig_and_its_recording_ends_there(held_rig):
    rig, _ = held_rig
    with pytest.raises(InputError, match="holds at until = 1.5 s"):
        rig.wait_until_simulated(UNTIL + 1.0)
    force = rig.channel("impact_force")
    assert rig.stop() == 0
    assert "until: holding at simulation time 1.500000 s" in rig.log()
    for name in ("cart_displacement", "rimd_displacement", "rimd_acceleration", "impact_force"):
        samples = rig.channel(name)
        rate = 1.0 / np.median(np.diff(samples.time))
        assert samples.time[-1] == pytest.approx(UNTIL - 1.0 / rate, abs=1e-9), name
        assert samples.index[-1] == round(UNTIL * rate) - 1, name
    assert rig.motor_states().time.max() <= UNTIL
    assert len(force) <= len(rig.channel("impact_force"))


def test_the_handles_ground_truth_is_the_recordings(held_rig):
    from rimd_msgs.msg import FaultEvent, ImpactEvent, MotorState

    rig, live = held_rig
    rig.stop()
    events = rig.events()
    recorded = _recorded(rig, "/rig/impact/events", ImpactEvent)
    assert len(events) == len(recorded) > 0
    assert events.time.tolist() == pytest.approx([t for t, _ in recorded], abs=1e-9)
    assert events.peak_force.tolist() == [m.peak_force for _, m in recorded]
    assert events.index.tolist() == list(range(len(recorded)))   # numbered from 0, nothing left out
    early = rig.events(0.0, 1.0)
    assert live["events"].time.tolist() == early.time.tolist()   # read while the rig ran: the same
    assert live["events"].peak_force.tolist() == early.peak_force.tolist()

    faults = rig.faults()
    assert faults.kind.tolist() == ["dropout", "offset"]
    assert faults.start.tolist() == pytest.approx([0.4, 0.9], abs=1e-9)
    assert faults.end.tolist()[0] == pytest.approx(0.6, abs=1e-9) and faults.end[1] == np.inf
    raw = _recorded(rig, "/rig/faults", FaultEvent)
    assert sorted((m.event, m.kind, round(t, 9)) for t, m in raw) == [
        ("end", "dropout", 0.6), ("start", "dropout", 0.4), ("start", "offset", 0.9)]
    assert live["faults"].kind.tolist() == ["dropout", "offset"]
    assert live["faults"].end[0] == pytest.approx(0.6, abs=1e-9)
    assert rig.faults(0.65, 0.8).kind.tolist() == []   # the window keeps the faults acting in it

    force = rig.channel("impact_force", 0.0, 1.0)
    hole = rig.faults().active(np.arange(0, 20_000) / 20_000.0, "impact_force")
    assert force.index.tolist() == np.flatnonzero(~hole).tolist()   # every sample but the dropout's
    assert live["force"].value.tolist() == force.value.tolist()

    motor = rig.motor_states()
    raw_motor = _recorded(rig, "/rig/motor/state", MotorState)
    assert motor.frequency.tolist() == [m.frequency for _, m in raw_motor]


def test_an_unknown_channel_of_the_handle_is_refused_with_the_closest_name(held_rig):
    rig, _ = held_rig
    with pytest.raises(InputError, match="did you mean impact_force"):
        rig.channel("impact_forse")


@pytest.mark.parametrize(("fault", "message"), [
    ({"channel": "impact_forse", "kind": "dropout", "start": 1.0}, "channel = 'impact_forse' refused: .*did you "
                                                                   "mean impact_force"),
    ({"channel": "impact_force", "kind": "drop_out", "start": 1.0}, "kind = 'drop_out' refused: .*did you mean "
                                                                    "dropout"),
    ({"channel": "impact_force", "kind": "dropout", "begin": 1.0}, r"faults\[0\].begin refused: unknown field"),
])
def test_a_bad_fault_scenario_is_refused_before_anything_starts(tmp_path, fault, message):
    from rimd_sim.ros.testing import RigFactory

    factory = RigFactory(tmp_path)
    with pytest.raises(InputError, match=message):
        factory(consumers=["daq"], faults=[fault])
    assert not factory._rigs
    assert not list(tmp_path.glob("*/logs/*")), "a process was started"


def test_run_names_the_rig_s_state_when_the_program_hangs_and_its_error_when_it_fails(rimd_rig):
    rig = rimd_rig(consumers=["never_joins"], record=False)
    with pytest.raises(AssertionError, match=r"did not exit within 3 s; the rig has not simulated anything yet"):
        rig.run([sys.executable, "-c", "import time; time.sleep(60)"], timeout=3.0)
    with pytest.raises(AssertionError, match=r"exited with status 3.*\n.*stderr:\n    it broke"):
        rig.run([sys.executable, "-c", "import sys; sys.stderr.write('it broke\\n'); sys.exit(3)"])
    done = rig.run([sys.executable, "-c", "import os; print(os.environ['ROS_DOMAIN_ID'])"])
    assert done.stdout.strip() == str(rig.domain_id)
    with pytest.raises(InputError, match="keeps no recording"):
        rig.events()
