"""Reading recordings, including damaged ones, without rclpy.

:func:`open_recording` takes an MCAP file or a recording directory (its ``*.mcap`` files in name order). A
complete file is read through its summary. A file without a summary (the recorder was killed) or with a
damaged tail is read record by record up to the first record that cannot be read: everything before it is
kept, and :class:`FileReport` says how much was lost. A file that is not MCAP at all is refused with
:class:`RecordingError`, naming the file.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

_MAGIC = b"\x89MCAP0\r\n"


class RecordingError(Exception):
    """A recording cannot be read at all; the message names the file and the reason."""


@dataclass(frozen=True)
class RecordedTopic:
    """A topic found in a recording."""

    name: str
    type_name: str
    offered_qos_profiles: str
    definition: str
    message_encoding: str


@dataclass(frozen=True)
class RecordedMessage:
    """One message: topic, times (ns) and the serialized (CDR) bytes."""

    topic: str
    type_name: str
    log_time: int
    publish_time: int
    data: bytes


@dataclass
class FileReport:
    """What reading one file gave: complete or not, messages read, and what was lost."""

    path: Path
    size: int
    complete: bool = False
    messages: int = 0
    bytes_read: int = 0
    error: str | None = None

    def describe(self) -> str:
        """One line for a person."""
        if self.complete:
            return f"{self.path.name}: complete, {self.messages} messages"
        lost = self.size - self.bytes_read
        return (f"{self.path.name}: incomplete ({self.error}); read {self.messages} messages from the first "
                f"{self.bytes_read} of {self.size} bytes, {lost} bytes at the end could not be read")


@dataclass
class Recording:
    """An opened recording: its files, topics and metadata; :meth:`messages` streams the messages."""

    files: list[Path]
    topics: dict[str, RecordedTopic] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    reports: list[FileReport] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        """True when every file was read to its end."""
        return all(r.complete for r in self.reports)

    @property
    def message_count(self) -> int:
        """Messages that can be read."""
        return sum(r.messages for r in self.reports)

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[RecordedMessage]:
        """Yield the readable messages in file order (log-time order for the recorder's files)."""
        wanted = set(topics) if topics is not None else None
        for path, report in zip(self.files, self.reports, strict=True):
            channels: dict[int, Channel] = {}
            schemas: dict[int, Schema] = {}
            yielded = 0
            for record in _records(path, report.complete):
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    if yielded >= report.messages:
                        break
                    yielded += 1
                    channel = channels.get(record.channel_id)
                    if channel is None or (wanted is not None and channel.topic not in wanted):
                        continue
                    schema = schemas.get(channel.schema_id)
                    yield RecordedMessage(channel.topic, schema.name if schema else "", record.log_time,
                                          record.publish_time, record.data)


def _records(path: Path, complete: bool) -> Iterator:
    """Records of a file in order; stops quietly at the first unreadable record of an incomplete file."""
    with path.open("rb") as stream:
        reader = StreamReader(stream, record_size_limit=1 << 30)
        iterator = iter(reader.records)
        while True:
            try:
                record = next(iterator)
            except StopIteration:
                return
            except Exception:  # noqa: BLE001 - a damaged tail; the scan in open_recording reported it
                if complete:
                    raise
                return
            yield record


def _scan(path: Path, recording: Recording) -> FileReport:
    """Read a file record by record, collecting topics and metadata, up to its end or its damage."""
    report = FileReport(path, path.stat().st_size)
    schemas: dict[int, Schema] = {}
    with path.open("rb") as stream:
        if stream.read(len(_MAGIC)) != _MAGIC:
            raise RecordingError(f"{path} is not an MCAP file (it does not start with the MCAP magic bytes)")
        stream.seek(0)
        reader = StreamReader(stream, record_size_limit=1 << 30)
        iterator = iter(reader.records)
        pending_messages = 0
        while True:
            try:
                record = next(iterator)
            except StopIteration:
                report.complete = True
                report.bytes_read = report.size
                break
            except (McapError, struct.error, ValueError, EOFError, OSError, MemoryError, Exception) as exc:  # noqa: BLE001
                at_end = stream.tell() >= report.size
                report.error = _describe(exc, at_end)
                break
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                schema = schemas.get(record.schema_id)
                recording.topics.setdefault(record.topic, RecordedTopic(
                    record.topic, schema.name if schema else "", record.metadata.get("offered_qos_profiles", ""),
                    schema.data.decode(errors="replace") if schema else "", record.message_encoding))
            elif isinstance(record, Message):
                pending_messages += 1
            elif isinstance(record, Metadata):
                recording.metadata.setdefault(record.name, dict(record.metadata))
            # Messages of a chunk count once the whole chunk was read (the stream position moved past it).
            position = stream.tell()
            if position != report.bytes_read:
                report.bytes_read = position
                report.messages += pending_messages
                pending_messages = 0
        if report.complete:
            report.messages += pending_messages
    return report


def _describe(exc: BaseException, at_end: bool) -> str:
    text = str(exc) or type(exc).__name__
    if at_end or "EndOfFile" in type(exc).__name__ or isinstance(exc, EOFError):
        return "the file ends in the middle of a record: truncated, or the recorder did not finish it"
    return f"unreadable record: {type(exc).__name__}: {text}"


def _summary_ok(path: Path) -> bool:
    try:
        with path.open("rb") as stream:
            return make_reader(stream).get_summary() is not None
    except Exception:  # noqa: BLE001 - any failure means: no usable summary, scan instead
        return False


def recording_files(path: str | Path) -> list[Path]:
    """Return the MCAP files of a recording (a file, or a directory's ``*.mcap`` files in name order)."""
    path = Path(path)
    if path.is_dir():
        files = sorted(path.glob("*.mcap"), key=_file_order)
        if not files:
            raise RecordingError(f"{path} holds no .mcap files")
        return files
    if not path.exists():
        raise RecordingError(f"{path} does not exist")
    return [path]


def _file_order(path: Path) -> tuple:
    # <prefix>_<stamp>_<n>.mcap: order by stamp then n (numerically), falling back to the name.
    parts = path.stem.rsplit("_", 2)
    if len(parts) == 3 and parts[2].isdigit():
        return (parts[1], int(parts[2]), path.name)
    return (path.stem, 0, path.name)


def open_recording(path: str | Path) -> Recording:
    """Open a recording (file or directory) and find out what each file holds and what was lost.

    Raises:
        RecordingError: The path does not exist, holds no MCAP file, or a file is not MCAP at all.
    """
    files = recording_files(path)
    recording = Recording(files)
    for file in files:
        try:
            report = _scan(file, recording)
        except OSError as exc:
            raise RecordingError(f"cannot read {file}: {exc.strerror or exc}") from None
        if report.complete and not _summary_ok(file):
            report.complete = False
            report.error = "no summary section (the file was not finished)"
        recording.reports.append(report)
    return recording
