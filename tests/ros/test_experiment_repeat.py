"""The same lockstep experiment recorded twice, the second time with a core kept busy: the same samples.

``rimd experiment`` sets its recorder's ``stop_at`` to the end of its last step (``T0 + n * dwell``): the
recording holds every message stamped strictly before it and nothing after, the block that straddles it cut
there (docs/recording.md). In lockstep, with the rig started the same way (same config, same seed, paused until
the steps are scheduled at ``--start``), the data do not depend on timing; with the cut they do not depend on
when the recorder is stopped either. Hypotheses: every channel of both recordings (the sampled ones, the motor
states, the impact events) holds the same values, first to last, bit for bit: same counts, same first and last
stamps; every sampled channel ends with its last sample before the end, and its blocks' bytes are identical; the
analysis ends the last step at the schedule's end.
"""

from __future__ import annotations

import csv
import shutil

import numpy as np
import pytest

from rimd_sim.ros.clients.experiment import RECORDER_NODE

pytestmark = [pytest.mark.ros, pytest.mark.process]

#: The experiment: two steps of 2 s from t = 1 s; the recording ends at 5 s.
START, DWELL, FREQS = 1.0, 2.0, ("3.0", "3.5")
END_NS = round((START + len(FREQS) * DWELL) * 1e9)
BLOCK_TOPICS = ("/rig/impact/force", "/rig/rimd/acceleration", "/rig/rimd/displacement", "/rig/cart/displacement")


def _record(ros_processes, rimd_rig, out, *, busy: bool):
    rig = rimd_rig(consumers=[RECORDER_NODE], record=False,
                   parameters={"motor.initial_frequency": 3.0, "motor.initial_setpoint": 3.0, "start_paused": True})
    burner = ros_processes.start_python("-c", "while True: pass", name="busy_loop") if busy else None
    try:
        executable = shutil.which("rimd")
        assert executable is not None, "rimd is not on PATH: source env.sh"
        experiment = ros_processes.start([executable, "experiment", "--frequencies", *FREQS, "--dwell", str(DWELL),
                                          "--settle", "0.5", "--ramp-rate", "2", "--start", str(START), "--out",
                                          str(out)], name=f"experiment_{out.name}", env=rig.env)
        experiment.wait_for_output(r"steps scheduled from t = ", timeout=90)
        assert rig.resume().success
        assert experiment.wait(120) == 0, experiment.tail()
        assert "the recording ends at t = 5.000000000 s" in experiment.output(), experiment.output()[-2000:]
    finally:
        if burner is not None:
            burner.stop()
        rig.stop()
    return out / "recording"


def _raw_blocks(recording) -> dict[str, list[bytes]]:
    from rimd_sim.io.reader import open_recording

    out: dict[str, list[bytes]] = {t: [] for t in BLOCK_TOPICS}
    for msg in open_recording(recording).messages(list(BLOCK_TOPICS)):
        out[msg.topic].append(bytes(msg.data))
    return out


def test_a_lockstep_experiment_recorded_twice_gives_the_same_samples(ros_processes, rimd_rig, tmp_path):
    from rimd_sim.analysis.recordings import recorded as rec

    quiet = _record(ros_processes, rimd_rig, tmp_path / "quiet", busy=False)
    loaded = _record(ros_processes, rimd_rig, tmp_path / "loaded", busy=True)
    a, b = rec.load(quiet), rec.load(loaded)
    # What the recorder knows was lost before its file (the transport's declared losses, a late start), first:
    # the comparisons below would only say that the samples differ.
    assert not a.loss()["recorder"] and not b.loss()["recorder"], (a.loss()["recorder"], b.loss()["recorder"])
    assert a.origin_ns == b.origin_ns == 0   # both from sample 0 (lockstep: the rig waits for the recorder)
    assert set(a.channels) == set(b.channels) >= set(BLOCK_TOPICS)
    for topic, ca in a.channels.items():
        cb = b.channels[topic]
        assert ca.lost_samples == cb.lost_samples == 0, topic
        assert ca.values.size == cb.values.size and ca.values.size > 0, topic
        assert np.array_equal(ca.index, cb.index) and np.array_equal(ca.time, cb.time), topic
        assert np.array_equal(ca.values, cb.values, equal_nan=True), f"{topic}: the samples differ"
        # every sample before the end, the last one one period short of it at most: cut, not dropped
        assert ca.time[0] == 0.0 and END_NS * 1e-9 - 1.0 / ca.rate <= ca.time[-1] < END_NS * 1e-9, topic
    for name, (ea, eb) in (("events", (a.events, b.events)), ("motor", (a.motor, b.motor))):
        assert set(ea) == set(eb) and ea["time"].size == eb["time"].size > 0, name
        for key in ea:
            assert np.array_equal(ea[key], eb[key], equal_nan=True), f"{name} {key} differ"
        assert ea["time"][-1] < END_NS * 1e-9, name
    assert a.counts == b.counts
    blocks_a, blocks_b = _raw_blocks(quiet), _raw_blocks(loaded)
    assert blocks_a == blocks_b, "the blocks' bytes differ"
    # The analysis ends the last step at the schedule's end (5 s), not where the recorder stopped.
    for out in (tmp_path / "quiet", tmp_path / "loaded"):
        with open(out / "steps.csv") as fh:
            rows = list(csv.DictReader(fh))
        assert [float(r["frequency_hz"]) for r in rows] == [3.0, 3.5] and float(rows[-1]["end_s"]) == 5.0
