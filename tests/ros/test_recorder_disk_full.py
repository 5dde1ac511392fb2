"""Disk full while recording: the recorder says so, keeps what it wrote, counts what it did not, keeps running.

How the full disk is made: each test mounts its own small tmpfs (``mount -t tmpfs -o size=...``) and
records into it, so the kernel answers the writes with the real ``ENOSPC`` (``No space left on device``), as
on a full disk; no file-size limit (``RLIMIT_FSIZE``, which gives ``EFBIG`` or kills with ``SIGXFSZ``) is
used. Mounting needs root (or CAP_SYS_ADMIN): without it the tests are skipped, saying so. The file system is
always unmounted at teardown (lazily if a process still holds a file in it). "Space comes back" is a remount
of the same tmpfs with a larger size.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from harness.rig import Diagnostics, RawCollector, start_rig, trigger, wait_until_delivered, wait_until_matched
from harness.ros import spin_until
from rimd_sim.io.bag import BagWriter, qos_profile_dict
from rimd_sim.io.reader import open_recording

pytestmark = pytest.mark.ros

BLOCK = "rimd_msgs/msg/SampleBlock"


class SmallDisk:
    """A tmpfs mounted by the test at ``path``; ``resize`` remounts it with another size."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def resize(self, size: str) -> None:
        subprocess.run(["mount", "-o", f"remount,size={size}", str(self.path)], check=True,
                       capture_output=True, text=True)

    def fill(self) -> None:
        """Take every byte left (a filler file written until ENOSPC)."""
        with open(self.path / "filler", "wb", buffering=0) as filler:
            block = b"\0" * 4096
            try:
                while True:
                    filler.write(block)
            except OSError as exc:
                assert exc.errno == errno.ENOSPC


def _mount_small_disk(path: Path, size: str) -> Iterator[SmallDisk]:
    path.mkdir()
    if shutil.which("mount") is None or shutil.which("umount") is None:
        pytest.skip("no mount/umount command here: cannot make a small file system to fill")
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0755", "tmpfs", str(path)],
                            capture_output=True, text=True)
    if result.returncode != 0:
        pytest.skip(f"cannot mount a {size} tmpfs to fill (needs root or CAP_SYS_ADMIN): "
                    f"{result.stderr.strip() or f'mount exit status {result.returncode}'}; the recorder's disk-full "
                    "handling is still tested without privileges by tests/runtime/test_recording_session.py")
    try:
        assert os.path.ismount(path), f"{path} is not a mount point after mount"
        yield SmallDisk(path)
    finally:
        if subprocess.run(["umount", str(path)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(path)], capture_output=True)   # busy: detach now, free later


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[SmallDisk]:
    """A 1 MiB tmpfs: a few seconds of the rig at real time."""
    yield from _mount_small_disk(tmp_path / "disk", "1m")


@pytest.fixture
def tiny_disk(tmp_path: Path) -> Iterator[SmallDisk]:
    """A 256 KiB tmpfs for the writer alone."""
    yield from _mount_small_disk(tmp_path / "tiny", "256k")


def _ends_on_a_record_boundary(path: Path) -> bool:
    """Whether the file is the MCAP magic followed by whole records (opcode, length, body), nothing cut."""
    data = path.read_bytes()
    position = 8
    while position + 9 <= len(data):
        position += 9 + int.from_bytes(data[position + 1:position + 9], "little")
    return data[:8] == b"\x89MCAP0\r\n" and position == len(data)


def _block(index: int, n: int = 100) -> bytes:
    from rclpy.serialization import serialize_message

    from rimd_msgs.msg import SampleBlock

    # Incompressible-ish samples, so that the disk fills after a known, modest number of messages.
    msg = SampleBlock(first_index=index * n, sample_rate=2000.0,
                      samples=[((index * 7919 + k * 104729) % 100003) / 100003.0 for k in range(n)], unit="m")
    return serialize_message(msg)


def test_writer_stops_at_enospc_keeps_a_clean_prefix_and_retries(tiny_disk):
    """The writer alone (no ROS): ENOSPC stops it without an exception, the file keeps whole chunks only."""
    out = tiny_disk.path / "rec"
    bag = BagWriter(out, chunk_size=8192)
    bag.add_topic("/rig/cart/displacement", BLOCK, [qos_profile_dict(depth=100)])
    given = [_block(i) for i in range(2000)]   # ~1.7 MB: far more than the 256 KiB disk
    accepted = [bag.write("/rig/cart/displacement", data, 10**18 + i * 50_000_000) for i, data in enumerate(given)]

    failure = bag.failure
    assert failure is not None and failure.disk_full and failure.error.errno == errno.ENOSPC
    assert failure.headline == "disk full" and "No space left on device (errno 28, ENOSPC)" in failure.describe()
    assert failure.path.parent == out and failure.path.suffix == ".mcap"
    n_ok = bag.written["/rig/cart/displacement"]
    assert 0 < n_ok < 2000 and bag.written["/rig/cart/displacement"] + bag.not_written["/rig/cart/displacement"] == 2000
    assert failure.file is not None and failure.file.message_count == n_ok and failure.file.error
    # Every message after the error is refused at once (no retry per message); those of the lost chunk were
    # accepted first, then counted as not written.
    first_refused = accepted.index(False)
    assert not any(accepted[first_refused:])
    assert first_refused - n_ok == failure.lost_in_chunk

    bag.close()   # nothing to finish; metadata.yaml is rewritten in the space the cut-off chunk gave back
    assert bag.failure is failure and bag.metadata_error is None
    recording = open_recording(out)
    (report,) = recording.reports
    assert not report.complete and report.error
    assert report.size == failure.file.size and _ends_on_a_record_boundary(failure.path)   # the half-written
    # chunk was cut off
    got = [m.data for m in recording.messages()]
    assert got == given[:n_ok]
    meta = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == n_ok and meta["relative_file_paths"] == [failure.path.name]

    # A retry while the disk is still full: the new file cannot even take its header; it is deleted.
    bag = BagWriter(out, chunk_size=8192)
    bag.add_topic("/rig/cart/displacement", BLOCK, [qos_profile_dict(depth=100)])
    tiny_disk.fill()
    assert not bag.write("/rig/cart/displacement", given[0], 2 * 10**18)
    assert bag.failure is not None and bag.failure.file is None and bag.failure.disk_full
    assert sorted(p.name for p in out.glob("*.mcap")) == [failure.path.name]
    # Space comes back: split clears the error, the next message opens a new file, which is finished normally.
    (tiny_disk.path / "filler").unlink()
    tiny_disk.resize("4m")
    assert bag.split() is None and bag.failure is None
    for i, data in enumerate(given[:300]):
        assert bag.write("/rig/cart/displacement", data, 3 * 10**18 + i)
    bag.close()
    assert bag.failure is None and len(bag.failures) == 1
    recording = open_recording(out)
    assert [r.complete for r in recording.reports] == [False, True]
    assert [m.data for m in recording.messages()] == given[:n_ok] + given[:300]


def _not_written(status) -> int:
    return int(re.search(r"\((\d+) messages not written\)$", status.message).group(1))


def _statuses(store: list):
    from diagnostic_msgs.msg import DiagnosticArray

    def callback(msg: DiagnosticArray) -> None:
        store.extend(s for s in msg.status if s.hardware_id == "rimd_recorder")
    return callback


def test_disk_full_while_recording_the_rig(small_disk, ros_processes, ros_executor):
    """The rig records into a 1 MiB file system until it is full, then the disk grows and ~/split resumes."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    out = small_disk.path / "rec"
    recorder, simulator = start_rig(ros_processes, out)
    collector = RawCollector(ros_executor)
    statuses: list = []
    collector.node.create_subscription(DiagnosticArray, "/diagnostics", _statuses(statuses), 100)
    diagnostics = Diagnostics(collector.node)
    wait_until_matched(ros_executor, collector, diagnostics, readers=2)
    assert trigger(ros_executor, collector.node, "/rig/resume").success

    # The log says it, once, naming the file and the system's reason.
    full = re.compile(r"disk full: (\S+\.mcap): No space left on device \(errno 28, ENOSPC\): recording stopped")
    assert spin_until(ros_executor, lambda: full.search(recorder.output()), 30), recorder.tail()
    log = recorder.output()
    failed_file = Path(full.search(log).group(1))
    assert failed_file.parent == out and "the node keeps running" in log and "~/split" in log

    # /diagnostics: ERROR, saying so, with the count of messages not written.
    def error_status():
        return next((s for s in reversed(statuses) if s.level == DiagnosticStatus.ERROR), None)
    assert spin_until(ros_executor, lambda: error_status() is not None, 5), [s.message for s in statuses]
    status = error_status()
    assert status.message.startswith(f"disk full: {failed_file}: No space left on device"), status.message
    assert _not_written(status) > 0, status.message
    values = {kv.key: kv.value for kv in status.values}
    assert values["state"] == "not writing" and values["write_failure"].startswith("disk full: ")

    # The rig keeps publishing, the recorder keeps running and answering, and does not repeat the error.
    seen = sum(len(v) for v in collector.messages.values())
    assert spin_until(ros_executor, lambda: sum(len(v) for v in collector.messages.values()) > seen + 300, 10)
    assert simulator.is_running() and recorder.is_running()
    response = trigger(ros_executor, collector.node, "/rimd_recorder/resume")
    assert not response.success and response.message == "not paused"
    n_before = _not_written(error_status())
    assert spin_until(ros_executor, lambda: _not_written(error_status()) > n_before, 5)   # counted as it goes
    output = recorder.output()
    assert output.count("No space left on device") == 1, output
    assert "writing the recording failed" not in output and "Traceback" not in output

    # Space comes back; ~/split clears the error and the recorder writes a new file.
    small_disk.resize("64m")
    assert trigger(ros_executor, collector.node, "/rimd_recorder/split").success
    again = re.compile(r"writing again after the disk full: recording into (\S+\.mcap)")
    assert spin_until(ros_executor, lambda: again.search(recorder.output()), 10), recorder.tail()
    assert "the disk full error is cleared: the next message recorded opens a new file" in recorder.output()
    statuses.clear()
    assert spin_until(ros_executor, lambda: any(s.level == DiagnosticStatus.WARN for s in statuses), 5)
    assert "messages not written after a disk full" in statuses[-1].message
    seen = len(collector.messages["/rig/truth"])
    assert spin_until(ros_executor, lambda: len(collector.messages["/rig/truth"]) >= seen + 100, 30)   # 1 s more
    assert trigger(ros_executor, collector.node, "/rig/pause").success
    wait_until_delivered(ros_executor, collector, diagnostics, time.monotonic())   # reached both sides

    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(30) == 0
    output = recorder.output()
    assert "Traceback" not in output
    assert f"{failed_file.name}: " in output and "INCOMPLETE: disk full" in output
    assert "WRITE FAILED: disk full" in output
    summary = {topic: (int(n), rest) for topic, n, rest in re.findall(
        r"^\s+(/\S+): (\d+) messages written; (.*)$", output, re.MULTILINE)}

    # The files read back: the first up to the error (a prefix of what the rig published, per topic), the
    # second from the retry to the end (a suffix); what the summary counts matches, message for message.
    recording = open_recording(out)
    assert [f.name for f in recording.files][0] == failed_file.name and len(recording.files) == 2
    first, second = recording.reports
    assert not first.complete and first.messages > 0 and failed_file.name in first.describe()
    assert second.complete, second.describe()
    per_file: list[dict[str, list[bytes]]] = []
    for path in recording.files:
        per_file.append({})
        for msg in open_recording(path).messages():
            per_file[-1].setdefault(msg.topic, []).append(msg.data)
    for topic, sent in collector.messages.items():
        head, tail = per_file[0].get(topic, []), per_file[1].get(topic, [])
        assert head and tail, topic
        assert head == sent[:len(head)], topic            # bit-identical prefix
        assert tail == sent[len(sent) - len(tail):], topic  # bit-identical suffix after the retry
        written, rest = summary[topic]
        assert written == len(head) + len(tail), topic
        not_written = int(re.search(r"(\d+) messages not written \(disk full\)", rest).group(1))
        assert written + not_written == len(sent), (topic, written, not_written, len(sent))
