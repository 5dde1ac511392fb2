"""The composed rig (docs/rig.md, "The composed rig"): the same recording as separate processes, blocks on time.

Hypotheses:

- in lockstep, a rig whose recorder and Rerun bridge run in the simulator's process (fed its messages without
  DDS, their progress reported to it directly) records exactly what the separate processes record: the same
  topics with the same offered QoS, and on every topic but ``/diagnostics`` (wall-clock reports) and
  ``/rig/session`` (a new ``run_id`` per run: its count only) the same messages stamped before 2 s, byte for byte,
  first to last; both bridges save a non-empty ``.rrd``;
- at real time, a subscriber in another process receives the composed rig's blocks contiguous and on one time
  grid; how late they come is a figure of benchmarks/bench_latency.py, not asserted here.
"""

from __future__ import annotations

import struct
import time

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.process]

#: The recordings are compared up to this stamp (ns of simulation time): 2 s of data, from sample 0.
STOP_NS = 2_000_000_000
WINDOW_S = 0.2
FORCE = "/rig/impact/force"


def _record(rimd_rig, *, separate: bool):
    rig = rimd_rig(rerun=True, separate=separate, window=WINDOW_S)
    assert len(rig.rig.processes) == (3 if separate else 1)
    # Lockstep: once the rig is past the stop by the window, the recorder has written everything before it.
    rig.wait_until_simulated(STOP_NS / 1e9 + WINDOW_S + 0.1)
    recording, rrd = rig.recording, rig.run_dir / "rig.rrd"
    assert rig.stop() == 0
    assert rrd.stat().st_size > 0
    return recording


def _stamp(topic: str, data: bytes) -> int:
    """The message's stamp: its header's, the time of a /clock message."""
    from rimd_sim.io.cdr import header_stamp

    if topic == "/clock":
        sec, nanosec = struct.unpack_from("<iI", data, 4)
        return sec * 1_000_000_000 + nanosec
    stamp = header_stamp(data)
    assert stamp is not None, topic
    return stamp


def _messages(recording) -> tuple[dict[str, str], dict[str, list[bytes]]]:
    from rimd_sim.io.reader import open_recording

    rec = open_recording(recording)
    assert rec.complete
    out: dict[str, list[bytes]] = {t: [] for t in rec.topics}
    for msg in rec.messages():
        if msg.topic == "/diagnostics" or _stamp(msg.topic, msg.data) < STOP_NS:
            out[msg.topic].append(bytes(msg.data))
    return {t: r.offered_qos_profiles for t, r in rec.topics.items()}, out


def test_the_composed_rig_records_what_separate_processes_record_in_lockstep(rimd_rig):
    qos_separate, separate = _messages(_record(rimd_rig, separate=True))
    qos_composed, composed = _messages(_record(rimd_rig, separate=False))
    assert set(composed) == set(separate) >= {FORCE, "/rig/truth", "/rig/motor/state", "/clock", "/rig/session"}
    rig_topics = sorted(set(separate) - {"/diagnostics"})
    assert {t: qos_composed[t] for t in rig_topics} == {t: qos_separate[t] for t in rig_topics}
    assert len(composed["/rig/session"]) == len(separate["/rig/session"]) == 1
    for topic in sorted(set(rig_topics) - {"/rig/session"}):
        a, b = separate[topic], composed[topic]
        assert len(a) == len(b), f"{topic}: {len(a)} messages separate, {len(b)} composed"
        differ = [i for i, (x, y) in enumerate(zip(a, b, strict=True)) if x != y]
        assert not differ, f"{topic}: {len(differ)} messages differ, the first at {differ[:1]}"
    assert len(separate[FORCE]) == STOP_NS // 10_000_000   # 100 blocks a second from sample 0 to the stop


def test_a_subscriber_in_another_process_gets_the_composed_rigs_blocks_in_order_on_their_grid(
        ros_domain_id, rclpy_context, tmp_path):
    """The composed rig at real time writes its blocks to a reader in another process (this one) contiguous, each
    stamped ``t0 + first_index / rate`` with one ``t0``. How late they arrive is a speed figure
    (benchmarks/bench_rig.py, bench_latency.py), not asserted here."""
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from rimd_msgs.msg import SampleBlock
    from rimd_sim.io.cdr import read_block
    from rimd_sim.ros.bringup import Rig, plan_rig
    from rimd_sim.ros.nodes.polling import PolledSubscriptions

    node = rclpy.create_node("composed_timing_probe", context=rclpy_context)
    sub = node.create_subscription(SampleBlock, FORCE, lambda _: None,
                                   QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE), raw=True)
    blocks: list[tuple[int, int, int, float]] = []   # (stamp ns, first_index, samples, rate)

    def take(data: bytes, info: dict) -> None:
        block = read_block(data, arrays=1)
        stamp = block.header.stamp.sec * 1_000_000_000 + block.header.stamp.nanosec
        blocks.append((stamp, block.first_index, len(block.samples), block.sample_rate))

    plan = plan_rig(output_dir=tmp_path / "recording", real_time_factor=1.0,
                    parameters={"rimd_rerun": {"sink": "save", "save_path": str(tmp_path / "rig.rrd")}})
    assert not plan.separate and [p.name for p in plan.processes] == ["rimd_composed"]
    with Rig(plan, log_dir=tmp_path / "logs") as rig:
        deadline = time.monotonic() + 90.0   # a cold numba cache compiles first
        while len(blocks) < 260 and time.monotonic() < deadline:
            assert rig.failed() is None, (tmp_path / "logs" / "rimd_composed.log").read_text()
            PolledSubscriptions.take(sub, take)
            time.sleep(0.005)
        assert rig.failed() is None
    assert rig.stop() == 0
    assert len(blocks) >= 260, f"only {len(blocks)} blocks from the composed rig"
    t0s = {stamp - round(first * 1e9 / rate) for stamp, first, _, rate in blocks}
    assert len(t0s) == 1, sorted(t0s)[:3]
    for (_, first, n, _), (_, nxt, _, _) in zip(blocks, blocks[1:], strict=False):
        assert nxt == first + n, (first, n, nxt)
    node.destroy_node()
