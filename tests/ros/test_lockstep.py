"""Lockstep end to end: the rig runs exactly as fast as its slowest consumer and loses nothing (docs/rig.md).

Each rig here is the product's own bring-up in lockstep, through the pytest plugin users get
(``rimd_sim.ros.testing``, fixture ``rimd_rig``), with its consumers in other processes over DDS.

Hypotheses:

1. with the recorder, the Rerun bridge (save sink) and a DAQ client that takes 5 ms per block, every block of
   every channel from sample 0 is recorded and seen by the client, with no gap in ``first_index``, and the run
   goes as fast as the client (the client was busy at least 90 % of the run's wall time);
2. a scripted run (motor steps, a perturbation, three faults, all at stated simulation times) recorded once with
   the machine as it is and once with one core kept busy and the client slowed at random gives bit-identical
   samples, events and fault records;
3. a replay in lockstep delivers every message to a slow subscriber, in order, none lost;
4. a consumer killed with SIGKILL: the rig holds and names it within 1 s in its log and in /diagnostics; with
   the drop policy it goes on after the timeout, the recorder's file is complete to the end, and the consumer
   restarted under the same name joins again and gets every block from there on.
"""

from __future__ import annotations

import json
import pickle
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rimd_sim.io.cdr import block_span, header_stamp
from rimd_sim.io.reader import open_recording

pytestmark = [pytest.mark.ros, pytest.mark.timeout(240)]

DAQ = str(Path(__file__).resolve().parents[1] / "harness" / "daq_client.py")
CHANNELS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force")
#: Topics whose content is the rig's data (not its run identity, diagnostics or progress).
DATA_TOPICS = (*CHANNELS, "/rig/truth", "/rig/motor/state", "/rig/impact/events", "/rig/faults", "/clock")


def daq(rig, out: Path, until: float, *extra: str) -> subprocess.CompletedProcess:
    """Run the harness DAQ client against ``rig`` (a lockstep consumer named ``daq``) until ``until`` s."""
    return subprocess.run([sys.executable, DAQ, str(out), "--until", str(until), "--lockstep", "daq", *extra],
                          env=rig.env, capture_output=True, text=True, timeout=200)


def contiguous_from_zero(spans: list[tuple[int, int]], rate: float, until: float) -> None:
    """The blocks start at sample 0, follow each other without a gap, and reach ``until`` s."""
    assert spans and spans[0][0] == 0, spans[:2]
    for (a, n), (b, _) in zip(spans, spans[1:], strict=False):
        assert b == a + n, f"gap: {a}+{n} then {b}"
    assert (spans[-1][0] + spans[-1][1]) / rate >= until


def recorded_spans(recording: Path, topic: str) -> list[tuple[int, int]]:
    return [block_span(m.data) for m in open_recording(recording).messages([topic])]


def test_nothing_is_lost_and_the_rig_goes_as_fast_as_the_slowest_consumer(rimd_rig, tmp_path):
    rig = rimd_rig(consumers=["daq"], rerun=True, seed=1)
    out = tmp_path / "daq.pkl"
    result = daq(rig, out, 2.0, "--work-ms", "5", "--extra")
    assert result.returncode == 0, result.stdout + result.stderr
    timing = json.loads(Path(f"{out}.timing").read_text())
    # The client did its 5 ms of work on every block. How much of the wall time it was busy (the rig going as fast
    # as it allows) is a speed figure: benchmarks/bench_lockstep.py.
    assert timing["busy_s"] / timing["blocks"] >= 0.005
    stored = pickle.loads(out.read_bytes())
    assert rig.stop() == 0
    for topic in CHANNELS:
        rate = 2000.0 if "displacement" in topic else 20000.0
        contiguous_from_zero([block_span(data) for data, _, _ in stored[topic]], rate, 2.0)   # the client
        contiguous_from_zero(recorded_spans(rig.recording, topic), rate, 2.0)                # the recorder
    bridge = rig.log("rimd_rerun")
    assert "rimd_rerun: closed" in bridge and ", 0 gaps" in bridge, bridge[-500:]       # the bridge


def _scripted_run(rimd_rig, tmp_path: Path, name: str, *, busy: bool, seed: int) -> Path:
    """Motor steps, a perturbation and three faults at stated times, scheduled before the first block."""
    rig = rimd_rig(consumers=["daq"], seed=5, parameters={"motor.initial_frequency": 3.75})
    for response in (rig.motor(5.0, ramp_rate=4.0, at=1.0), rig.motor(7.25, ramp_rate=4.0, at=2.0),
                     rig.perturb(0.1, at=1.5),
                     rig.inject("impact_force", "dropout", start=0.6, duration=0.2),
                     rig.inject("rimd_acceleration", "delay", start=1.2, duration=0.5, magnitude=0.03),
                     rig.inject("cart_displacement", "offset", start=2.2, duration=0.3, magnitude=1e-3)):
        assert response.success, response.message
    load = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if busy else None
    try:
        result = daq(rig, tmp_path / f"{name}.pkl", 2.6, "--work-ms", "1", "--jitter-ms", "4", "--seed", str(seed))
    finally:
        if load is not None:
            load.kill()
            load.wait()
    assert result.returncode == 0, result.stdout + result.stderr
    assert rig.stop() == 0
    return rig.recording


def test_a_scripted_run_is_bit_identical_whatever_the_load(rimd_rig, tmp_path):
    quiet = _scripted_run(rimd_rig, tmp_path, "quiet", busy=False, seed=1)
    loaded = _scripted_run(rimd_rig, tmp_path, "loaded", busy=True, seed=2)
    end = 2_600_000_000   # what both runs covered for sure (the client stops at 2.6 s; the rig stops soon after)
    from rimd_sim.io.cdr import header_stamp

    def content(path: Path) -> dict[str, list[bytes]]:
        out: dict[str, list[bytes]] = {}
        for m in open_recording(path).messages(DATA_TOPICS):
            if header_stamp(m.data) <= end:
                out.setdefault(m.topic, []).append(m.data)
        return out

    a, b = content(quiet), content(loaded)
    assert set(a) == set(DATA_TOPICS), sorted(a)
    for topic in DATA_TOPICS:
        assert a[topic] == b[topic], f"{topic}: {len(a[topic])} and {len(b[topic])} messages, not bit-identical"
    assert len(a["/rig/faults"]) == 6 and a["/rig/impact/events"]


def test_a_replay_in_lockstep_gives_a_slow_subscriber_every_message(ros_processes, ros_env, tmp_path):
    from harness.rig_mcap import write_rig_mcap

    path = tmp_path / "rig.mcap"
    write_rig_mcap(path, seconds=2.0)
    replay = ros_processes.start_node(
        "rimd_replay", "--ros-args", "-p", f"file:={path}", "-p", "rate:=100.0", "-p", "lockstep.enabled:=true",
        "-p", "lockstep.consumers:=[daq]", "-p", "lockstep.window:=0.05")
    replay.wait_for_output(r"replaying \d+ topics", timeout=30)
    out = tmp_path / "replayed.pkl"
    # Up to 1.5 s, then 0.3 s more of the channels it reports on (--margin): the messages of the topics it only
    # listens to (motor state, events) stamped up to 1.5 s have arrived by then; DDS orders each topic, not across.
    until = 1.5
    result = subprocess.run([sys.executable, DAQ, str(out), "--until", str(until), "--lockstep", "daq",
                             "--work-ms", "3", "--extra", "/rig/motor/state", "/rig/impact/events"], env=ros_env,
                            capture_output=True, text=True, timeout=200)
    assert result.returncode == 0, result.stdout + result.stderr + replay.tail()
    stored = pickle.loads(out.read_bytes())
    recording = open_recording(path)
    for topic in (*CHANNELS, "/rig/motor/state", "/rig/impact/events"):
        sent = [m.data for m in recording.messages([topic])]
        due = [d for d in sent if header_stamp(d) <= until * 1e9]
        got = [data for data, _, _ in stored[topic]]
        assert got == sent[:len(got)] and len(got) >= len(due), f"{topic}: {len(got)} of the {len(due)} due"


def _wait_for(condition, timeout: float) -> float | None:
    """Seconds until ``condition()`` held (polled every 10 ms), or None after ``timeout``."""
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        if condition():
            return time.monotonic() - start
        time.sleep(0.01)
    return None


def test_a_killed_consumer_is_named_then_dropped_and_joins_again(rimd_rig, tmp_path, request):
    from diagnostic_msgs.msg import DiagnosticArray

    from rimd_sim.ros.clients.rig import RigClient

    rig = rimd_rig(consumers=["daq"], timeout=4.0, on_timeout="drop")
    holding: list[float] = []
    node = rig.client().node

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if "daq" in values.get("lockstep_waiting_for", ""):
                holding.append(time.monotonic())

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
    first = subprocess.Popen([sys.executable, DAQ, str(tmp_path / "first.pkl"), "--until", "1000", "--lockstep",
                              "daq"], env=rig.env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    try:
        rig.wait_until_simulated(1.5)   # the client has finished with at least 0.5 s: it is there
    finally:
        first.send_signal(signal.SIGKILL)
        first.wait()
    # The dead client's DDS participant slot is taken at once by a participant of this process, so that the
    # restarted client gets a shared-memory port of its own. Reusing the dead one's, it could receive nothing from
    # the rig: a Fast DDS sender keeps writing into the port's old segment when its listener was killed in the
    # middle of a message (docs/rig.md, "Pacing: lockstep"). What is tested here is the rig's side.
    slot = RigClient(domain_id=rig.domain_id, name="rimd_test_dead_slot",
                     discovery_range=rig.env.get("ROS_AUTOMATIC_DISCOVERY_RANGE"))
    request.addfinalizer(slot.close)
    assert "dropped" not in rig.log(), rig.log()[-1500:]
    # Named while it holds the run, in the log and in /diagnostics, before the timeout drops it (how soon after
    # the kill is a figure of the hold report's period, not asserted here).
    assert _wait_for(lambda: "waiting for daq" in rig.log(), 5.0) is not None, rig.log()[-1500:]
    assert rig.client().spin_until(lambda: holding, 5.0), "no /diagnostics naming daq while the run held"
    # The drop policy: after the timeout (4 s) the rig goes on without it.
    assert _wait_for(lambda: "consumer 'daq' dropped" in rig.log(), 10.0) is not None, rig.log()[-2000:]
    log = rig.log()
    assert log.index("waiting for daq") < log.index("consumer 'daq' dropped")
    rig.wait_until_simulated(3.0, timeout=60)
    # The consumer comes back under the same name: it joins where the run stands and loses nothing from there.
    # The rig is paused meanwhile (running without it, it would pass any --until before the client has started).
    paused = rig.pause()
    assert paused.success, paused.message
    again = tmp_path / "again.pkl"
    # Where the rig froze, from its own answer (the /clock this process last read may lag a rig that ran free).
    until = float(re.search(r"paused at simulation time (\S+) s", paused.message).group(1)) + 3.0
    client = subprocess.Popen([sys.executable, DAQ, str(again), "--until", str(until), "--lockstep", "daq",
                               "--timeout", "60"], env=rig.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              text=True)
    try:
        assert _wait_for(lambda: "returned after being dropped" in rig.log(), 60.0) is not None, rig.log()[-2000:]
        assert rig.resume().success
        output, _ = client.communicate(timeout=120)
    finally:
        client.kill()
    assert client.returncode == 0, output + rig.log()[-4000:]
    joined = re.search(r"consumer 'daq' returned after being dropped at (\S+) s", rig.log())
    assert joined, rig.log()[-2000:]
    # From where it joined on, every block (a subscriber may also be handed an older block still in the writer's
    # history when it matches: that one is not part of what lockstep promises).
    stored = pickle.loads(again.read_bytes())
    for topic in CHANNELS:
        rate = 2000.0 if "displacement" in topic else 20000.0
        spans = [span for span in (block_span(data) for data, _, _ in stored[topic])
                 if span[0] / rate >= float(joined.group(1))]
        assert spans and all(b[0] == a[0] + a[1] for a, b in zip(spans, spans[1:], strict=False)), (topic, spans[:3])
        assert (spans[-1][0] + spans[-1][1]) / rate >= until
    assert rig.stop() == 0
    for topic in CHANNELS:   # the recorder was never dropped: its file has everything, from sample 0
        contiguous_from_zero(recorded_spans(rig.recording, topic), 2000.0 if "displacement" in topic else 20000.0,
                             until)
