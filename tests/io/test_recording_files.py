"""Recording files without ROS running: definitions, writing, splitting, damage, independent readers.

The messages are real ``rimd_msgs`` messages serialized by rclpy's serializer (a pure function, no node),
and the files are read back by two independent readers (``rosbags`` and ``mcap-ros2-support``) besides our
own, so a file that only we could read fails here.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader

from harness.bags import read_with_mcap_ros2, read_with_rosbags
from rimd_sim.io.bag import BagWriter, qos_profile_dict
from rimd_sim.io.cdr import block_span
from rimd_sim.io.msgdefs import MessageDefinitionError, message_definition
from rimd_sim.io.reader import RecordingError, open_recording
from rimd_sim.runtime.recorder import LossCounter

BLOCK = "rimd_msgs/msg/SampleBlock"
EVENT = "rimd_msgs/msg/ImpactEvent"


def _block(index: int, n: int = 20) -> bytes:
    from rclpy.serialization import serialize_message

    from rimd_msgs.msg import SampleBlock

    msg = SampleBlock(first_index=index * n, sample_rate=2000.0, samples=[index + k / n for k in range(n)],
                      unit="m", range_min=-0.01, range_max=0.01)
    msg.header.frame_id = "cart_laser"
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(index * 10_000_000, 1_000_000_000)
    return serialize_message(msg)


def _event(index: int) -> bytes:
    from rclpy.serialization import serialize_message

    from rimd_msgs.msg import ImpactEvent

    return serialize_message(ImpactEvent(index=index, peak_force=80.0 + index, duration=1e-3))


def _write(path: Path, blocks: int, **options) -> tuple[BagWriter, list[tuple[str, bytes, int]]]:
    bag = BagWriter(path, **options)
    bag.add_topic("/rig/cart/displacement", BLOCK, [qos_profile_dict(depth=100)])
    bag.add_topic("/rig/impact/events", EVENT, [qos_profile_dict(depth=1000)])
    written = []
    for i in range(blocks):
        t = 1_000_000_000 + i * 10_000_000
        bag.write("/rig/cart/displacement", data := _block(i), t)
        written.append(("/rig/cart/displacement", data, t))
        if i % 10 == 0:
            bag.write("/rig/impact/events", data := _event(i // 10), t + 1)
            written.append(("/rig/impact/events", data, t + 1))
    return bag, written


def test_full_definition_carries_dependencies_in_rosbag2_layout():
    definition = message_definition(BLOCK)
    assert definition.type_name == BLOCK
    assert "uint64 first_index" in definition.text
    assert "\nMSG: std_msgs/Header\n" in definition.text and "\nMSG: builtin_interfaces/Time\n" in definition.text
    assert definition.text.count("=" * 80) == 2
    assert definition.type_hash.startswith("RIHS01_")
    assert message_definition("diagnostic_msgs/msg/DiagnosticArray").text.count("MSG: ") == 4


def test_unknown_type_is_named():
    with pytest.raises(MessageDefinitionError, match="foo_msgs/msg/Bar"):
        message_definition("foo_msgs/msg/Bar")
    with pytest.raises(MessageDefinitionError, match="not a message type name"):
        message_definition("not a type")


def test_block_span_and_loss_counter():
    assert block_span(_block(7, n=20)) == (140, 20)
    loss = LossCounter()
    assert loss.observe("/a", 100, 10) == 0          # the first block sets the start: nothing lost
    assert loss.observe("/a", 110, 10) == 0
    assert loss.observe("/a", 140, 10) == 20         # two blocks missing
    assert loss.lost_samples == {"/a": 20} and loss.lost_blocks == {"/a": 2}
    assert loss.observe("/a", 0, 10) == 0            # a restart is not a loss
    assert loss.restarts == {"/a": 1}


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_roundtrip_through_independent_readers(tmp_path, compression):
    bag, written = _write(tmp_path / "rec", 300, compression=compression, chunk_size=16 * 1024)
    bag.close()
    files = sorted((tmp_path / "rec").glob("*.mcap"))
    assert len(files) == 1 and files[0].name.startswith("rimd_") and files[0].name.endswith("_0.mcap")

    # rosbags: the directory (metadata.yaml) with its own CDR decoder, types from the schemas alone.
    counts, got = read_with_rosbags(tmp_path / "rec")
    assert counts == {"/rig/cart/displacement": 300, "/rig/impact/events": 30}
    assert [(topic, data, t) for topic, data, t, _ in got] == written
    blocks = [m for *_, m in got if hasattr(m, "samples")]
    assert [int(m.first_index) for m in blocks] == [20 * i for i in range(300)]
    assert blocks[5].samples[3] == pytest.approx(5.15) and blocks[5].header.frame_id == "cart_laser"

    # mcap-ros2-support: one file, decoded from the ros2msg schema.
    messages = read_with_mcap_ros2(files[0])
    assert [(topic, data, t) for topic, data, t, _ in messages] == written
    events = [m for topic, _, _, m in messages if topic == "/rig/impact/events"]
    assert [e.index for e in events] == list(range(30)) and events[3].peak_force == 83.0
    with files[0].open("rb") as stream:
        summary = make_reader(stream).get_summary()
    channel = next(iter(summary.channels.values()))
    assert channel.metadata["offered_qos_profiles"].startswith("- history: keep_last")
    assert channel.message_encoding == "cdr"
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}


def test_file_has_rosbag2_metadata_record_and_summary(tmp_path):
    bag, written = _write(tmp_path, 50, metadata={"rimd_rig_parameters": {"gap": "0.001"}})
    bag.close()
    (path,) = tmp_path.glob("*.mcap")
    with path.open("rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary.statistics.message_count == len(written)
        assert summary.chunk_indexes and all(c.compression == "zstd" for c in summary.chunk_indexes)
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert metadata["rimd_rig_parameters"] == {"gap": "0.001"}
    info = yaml.safe_load(metadata["rosbag2"]["serialized_metadata"])
    assert info["message_count"] == len(written) and info["relative_file_paths"] == [path.name]
    assert metadata["rosbag2"]["ros_distro"] == "jazzy"


def test_split_by_duration_loses_and_duplicates_nothing(tmp_path):
    bag, written = _write(tmp_path, 500, max_duration_ns=1_000_000_000)   # 5 s of 10 ms blocks: 5 files
    bag.close()
    recording = open_recording(tmp_path)
    assert len(recording.files) == 5 and recording.complete
    got = [(m.topic, m.data, m.log_time) for m in recording.messages()]
    assert got == written
    # Each file spans less than the limit, and the boundary message opens the next file.
    for info in bag.files:
        assert info.end_ns - info.start_ns < 1_000_000_000
    assert [f.start_ns for f in bag.files] == [1_000_000_000 + k * 1_000_000_000 for k in range(5)]
    meta = yaml.safe_load((tmp_path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["relative_file_paths"] == [f.name for f in recording.files]
    assert meta["message_count"] == len(written)


def test_split_by_size(tmp_path):
    bag, written = _write(tmp_path, 600, max_size=20_000, chunk_size=4096)
    bag.close()
    recording = open_recording(tmp_path)
    assert len(recording.files) >= 3
    assert [(m.topic, m.data, m.log_time) for m in recording.messages()] == written
    for info in bag.files[:-1]:
        assert info.size < 20_000 + 3 * 4096   # at most a chunk and the file's summary past the limit


def test_a_directory_grows_run_by_run(tmp_path):
    first, written1 = _write(tmp_path, 40)
    first.close()
    second, written2 = _write(tmp_path, 60)
    second.close()
    assert len(list(tmp_path.glob("*.mcap"))) == 2
    counts, messages = read_with_rosbags(tmp_path)
    assert len(messages) == len(written1) + len(written2) == sum(counts.values())


def test_crash_loses_at_most_the_chunk_in_progress(tmp_path):
    chunk = 8192
    bag, written = _write(tmp_path, 400, chunk_size=chunk)
    bag.abandon()   # as after SIGKILL: no summary, no footer
    recording = open_recording(tmp_path)
    (report,) = recording.reports
    assert not report.complete and "not finished" not in (report.error or "")
    got = [(m.topic, m.data, m.log_time) for m in recording.messages()]
    assert 0 < len(got) < len(written)
    assert got == written[:len(got)]                            # a prefix, intact
    lost_bytes = sum(len(d) for _, d, _ in written[len(got):])
    assert lost_bytes <= chunk + max(len(d) for _, d, _ in written)


@pytest.mark.parametrize("fraction", [0.3, 0.6, 0.9, 0.999])
def test_truncated_file_reads_up_to_the_damage(tmp_path, fraction):
    bag, written = _write(tmp_path / "rec", 400, chunk_size=8192)
    bag.close()
    (path,) = (tmp_path / "rec").glob("*.mcap")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: int(path.stat().st_size * fraction)])
    recording = open_recording(cut)
    (report,) = recording.reports
    assert not report.complete and "truncated" in report.error
    got = [(m.topic, m.data, m.log_time) for m in recording.messages()]
    # What is read is the intact prefix of whole chunks before the cut (a chunk holds about 30 messages).
    # Cut in the summary section (0.9, 0.999), every message is still there.
    assert 0 < len(got) <= len(written) and got == written[:len(got)]
    assert len(got) < len(written) or fraction > 0.6
    assert report.bytes_read <= cut.stat().st_size
    assert "incomplete" in report.describe() and str(len(got)) in report.describe()


def test_garbage_and_missing_files_are_refused_by_name(tmp_path):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"this is not a recording" * 100)
    with pytest.raises(RecordingError, match="garbage.mcap is not an MCAP file"):
        open_recording(garbage)
    with pytest.raises(RecordingError, match="does not exist"):
        open_recording(tmp_path / "nothing.mcap")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(RecordingError, match="holds no .mcap files"):
        open_recording(empty)


def test_corrupt_chunk_in_the_middle(tmp_path):
    bag, written = _write(tmp_path / "rec", 400, chunk_size=8192, compression="none")
    bag.close()
    (path,) = (tmp_path / "rec").glob("*.mcap")
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 64] = b"\xff" * 64       # garbage over a record header or body
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    shutil.copy(broken, tmp_path / "copy.mcap")
    recording = open_recording(broken)
    got = [(m.topic, m.data, m.log_time) for m in recording.messages()]
    # What is read is an intact prefix; what was lost is reported.
    assert got == written[:len(got)] and len(got) < len(written)
    assert not recording.complete and recording.reports[0].error
