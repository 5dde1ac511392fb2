"""Reading recordings, including damaged ones, without rclpy.

:func:`open_recording` takes an MCAP file or a recording directory (its ``*.mcap`` files in name order). Each
file is read record by record, framed by each record's length, up to its footer or up to the first record that
cannot be read: everything before that record is kept, and :class:`FileReport` says what was wrong and how
much was lost. Nothing damaged is passed on: a chunk is decompressed and checked against its CRC before any of
its messages counts, and a chunk that fails (CRC mismatch, undecodable, inconsistent sizes) ends the reading
of its file there. A file that reads to its footer is complete only if its summary is intact too (the
footer's summary CRC, the statistics' message count). A file that is not MCAP at all is refused with
:class:`RecordingError`, naming the file.
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema, Statistics
from mcap.stream_reader import CRCValidationError, get_chunk_data_stream

from rimd_sim.errors import RecordingError

__all__ = ["FileReport", "RecordedMessage", "RecordedTopic", "Recording", "RecordingError", "open_recording",
           "recording_files"]

_MAGIC = b"\x89MCAP0\r\n"
#: Largest record (and decompressed chunk) accepted: a longer one is taken for a damaged length field.
_RECORD_LIMIT = 1 << 30
#: The records the reader needs, parsed; any other (indexes, attachments, summary offsets) is skipped by length.
_PARSED: dict[int, Callable[[ReadDataStream], Any]] = {
    Opcode.SCHEMA: Schema.read, Opcode.CHANNEL: Channel.read, Opcode.CHUNK: Chunk.read, Opcode.METADATA: Metadata.read,
    Opcode.DATA_END: DataEnd.read, Opcode.FOOTER: Footer.read, Opcode.STATISTICS: Statistics.read}
#: Where each record may stand (MCAP spec; the Header only first): a record found elsewhere has a damaged opcode.
#: Private records (opcodes 0x80 and up) may stand anywhere and are skipped, as the spec says.
_DATA_SECTION = {Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE, Opcode.CHUNK, Opcode.MESSAGE_INDEX, Opcode.ATTACHMENT,
                 Opcode.METADATA, Opcode.DATA_END}
_SUMMARY_SECTION = {Opcode.SCHEMA, Opcode.CHANNEL, Opcode.STATISTICS, Opcode.CHUNK_INDEX, Opcode.ATTACHMENT_INDEX,
                    Opcode.METADATA_INDEX, Opcode.SUMMARY_OFFSET, Opcode.FOOTER}
_TRUNCATED = "the file ends in the middle of a record: truncated, or the recorder did not finish it"


@dataclass(frozen=True)
class RecordedTopic:
    """A topic found in a recording."""

    name: str
    type_name: str
    offered_qos_profiles: str
    definition: str
    message_encoding: str
    schema_encoding: str = ""


@dataclass(frozen=True)
class RecordedMessage:
    """One message: topic, times (ns), the serialized (CDR) bytes, and the file it was read from."""

    topic: str
    type_name: str
    log_time: int
    publish_time: int
    data: bytes
    path: Path | None = None


@dataclass
class FileReport:
    """What reading one file gave: complete or not, messages read, and what was lost."""

    path: Path
    size: int
    complete: bool = False
    messages: int = 0
    bytes_read: int = 0
    error: str | None = None
    #: Log times (ns) of the first and the last message read (None: no message).
    start_ns: int | None = None
    end_ns: int | None = None

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

    @property
    def start_ns(self) -> int | None:
        """Log time (ns) of the earliest message that can be read (None: none)."""
        return min((r.start_ns for r in self.reports if r.start_ns is not None), default=None)

    @property
    def end_ns(self) -> int | None:
        """Log time (ns) of the latest message that can be read (None: none)."""
        return max((r.end_ns for r in self.reports if r.end_ns is not None), default=None)

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[RecordedMessage]:
        """Yield the readable messages in file order (log-time order for the recorder's files).

        Exactly the messages :func:`open_recording` counted: the same checks stop at the same record.
        """
        wanted = set(topics) if topics is not None else None
        for path, report in zip(self.files, self.reports, strict=True):
            channels: dict[int, Channel] = {}
            schemas: dict[int, Schema] = {}
            yielded = 0
            for record, _ in _records(path, None):
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    channel = channels.get(record.channel_id)
                    if channel is None:   # its channel was never defined: not counted by the scan either
                        continue
                    if yielded >= report.messages:   # the file grew since it was opened
                        break
                    yielded += 1
                    if wanted is not None and channel.topic not in wanted:
                        continue
                    schema = schemas.get(channel.schema_id)
                    yield RecordedMessage(channel.topic, schema.name if schema else "", record.log_time,
                                          record.publish_time, record.data, path)
                elif isinstance(record, DataEnd):
                    break   # the summary section holds no messages


class _Body(ReadDataStream):
    """One record's bytes; reading past their end raises (mcap's stream returns a short read silently)."""

    def __init__(self, data: bytes) -> None:
        super().__init__(io.BytesIO(data))

    def read(self, length: int) -> bytes:
        if length < 0:
            raise ValueError(f"negative field length {length}")
        try:
            data = super().read(length) if length else b""
        except EndOfFile:
            data = b""
        if len(data) != length:
            raise ValueError("a field runs past the end of its record")
        return data


def _parse(opcode: int, body: bytes) -> Any:
    """The record of ``opcode`` from its body, or None for a record the reader does not need."""
    if opcode == Opcode.MESSAGE_INDEX:
        # Not needed, but cheap to check: its entries (16 bytes each) must fill its length. Damaged bytes taken
        # for a message index (a chunk with a flipped opcode) fail here instead of being skipped, chunk and all.
        size = struct.unpack_from("<I", body, 2)[0] if len(body) >= 6 else -1
        if size != len(body) - 6 or size % 16:
            raise ValueError("its entries do not fill its length")
        return None
    if opcode == Opcode.MESSAGE:
        if len(body) < 22:
            raise ValueError(f"a message record of {len(body)} bytes (at least 22)")
        return Message.read(_Body(body), len(body))
    read = _PARSED.get(opcode)
    return read(_Body(body)) if read is not None else None


def _chunk_records(chunk: Chunk) -> list:
    """The records of a chunk, after checking its sizes and its CRC: never altered bytes, or an exception."""
    if chunk.compression not in ("", "zstd", "lz4"):
        raise ValueError(f"unknown compression {chunk.compression!r}")
    if chunk.uncompressed_size > _RECORD_LIMIT:
        raise ValueError(f"uncompressed size {chunk.uncompressed_size} is beyond any chunk")
    # A damaged frame header can announce any size: decompress only when it agrees with the chunk's.
    if chunk.compression == "zstd":
        import zstandard

        announced = zstandard.frame_content_size(chunk.data)
    elif chunk.compression == "lz4":
        import lz4.frame

        announced = lz4.frame.get_frame_info(chunk.data).get("content_size") or -1
    else:
        announced = -1
    if announced not in (-1, chunk.uncompressed_size):
        raise ValueError(f"the {chunk.compression} frame holds {announced} bytes, the chunk says "
                         f"{chunk.uncompressed_size}")
    stream, size = get_chunk_data_stream(chunk, validate_crc=True)   # raises CRCValidationError on a mismatch
    data = stream.read(size) if size else b""
    if len(data) != chunk.uncompressed_size:
        raise ValueError(f"{len(data)} bytes uncompressed, the chunk says {chunk.uncompressed_size}")
    records = []
    position = 0
    while position < len(data):
        opcode, length = struct.unpack_from("<BQ", data, position)
        body = data[position + 9:position + 9 + length]
        if len(body) != length:
            raise ValueError("a record runs past the end of the chunk")
        record = _parse(opcode, body)
        if record is not None:
            records.append(record)
        position += 9 + length
    return records


def _records(path: Path, report: FileReport | None) -> Iterator[tuple[object, int]]:
    """Yield ``(record, end offset)`` of a file in order (a chunk's records once the chunk checked out).

    Stops at the footer or at the first record that cannot be read; with ``report`` (the scan), says why in
    ``report.error`` and checks the summary and the end of the file. A chunk's records are yielded only when
    the whole chunk was read and verified, so a consumer never sees part of a damaged chunk.

    Raises:
        RecordingError: The file does not start with the MCAP magic bytes.
        OSError: The file cannot be read.
    """
    def damaged(reason: str) -> None:
        if report is not None:
            report.error = reason

    size = path.stat().st_size
    with path.open("rb") as stream:
        head = stream.read(len(_MAGIC))
        if head != _MAGIC:
            raise RecordingError(_not_mcap(path, head))
        # A file that still ends with the closing magic bytes was not cut short: a record running past its end
        # has a damaged length.
        stream.seek(max(size - len(_MAGIC), len(_MAGIC)))
        ends_with_magic = size >= 2 * len(_MAGIC) and stream.read(len(_MAGIC)) == _MAGIC
        stream.seek(len(_MAGIC))
        position = len(_MAGIC)
        data_crc = zlib.crc32(head)     # of the data section, up to DataEnd (the scan only)
        data_end: int | None = None     # where the summary section starts
        data_end_record: DataEnd | None = None
        chunked = False
        while True:
            header = stream.read(9)
            if not header:
                return damaged("the file ends without its footer: truncated, or the recorder did not finish it")
            if len(header) < 9:
                return damaged(_TRUNCATED)
            opcode, length = struct.unpack("<BQ", header)
            if opcode == 0 or 0x10 <= opcode < 0x80:   # reserved opcodes: this is not a record header
                return damaged(f"damaged record at byte {position}: opcode 0x{opcode:02x} is not an MCAP record")
            first = position == len(_MAGIC)
            if first != (opcode == Opcode.HEADER) or (
                    not first and opcode < 0x80
                    and opcode not in (_DATA_SECTION if data_end is None else _SUMMARY_SECTION)):
                where = "first" if first else "in the data section" if data_end is None else "in the summary section"
                name = Opcode(opcode).name.lower() if opcode < 0x80 else f"private (0x{opcode:02x})"
                return damaged(f"damaged record at byte {position}: a {name} record cannot stand {where}")
            if opcode == Opcode.MESSAGE and chunked:
                # A writer that chunks puts every message in a chunk (CRC-protected); a message record between
                # chunks is another record with a flipped opcode (a message index), not data to pass on.
                return damaged(f"damaged record at byte {position}: a message record between the chunks")
            if length > size - position - 9:
                if ends_with_magic:
                    return damaged(f"damaged record at byte {position}: its length ({length} bytes) runs past the "
                                   "end of the file")
                return damaged(_TRUNCATED)
            if length > _RECORD_LIMIT:
                return damaged(f"damaged record at byte {position}: a length of {length} bytes")
            body = stream.read(length)
            if len(body) != length:
                return damaged(_TRUNCATED)   # the file shrank while being read
            try:
                record = _parse(opcode, body)
                inner = _chunk_records(record) if isinstance(record, Chunk) else ()
            except CRCValidationError:
                return damaged(f"damaged chunk at byte {position}: its contents do not match its CRC")
            except Exception as exc:  # any failure to read a record is damage, reported
                name = Opcode(opcode).name.lower() if opcode < 0x80 else f"0x{opcode:02x}"
                return damaged(f"unreadable {name} record at byte {position}: {type(exc).__name__}: "
                               f"{str(exc) or 'damaged'}")
            if report is not None and data_end is None:
                data_crc = zlib.crc32(body, zlib.crc32(header, data_crc)) if opcode != Opcode.DATA_END else data_crc
            position += 9 + length
            chunked = chunked or isinstance(record, Chunk)
            for item in inner:
                yield item, position
            if record is None or isinstance(record, Chunk):
                continue
            yield record, position
            if isinstance(record, DataEnd) and data_end is None:
                data_end, data_end_record = position, record
            elif isinstance(record, Footer):
                if report is not None:
                    problem, good_until = _check_end(stream, position, size, record, data_end, data_end_record,
                                                     data_crc)
                    if problem:
                        damaged(problem)
                        report.bytes_read = good_until
                return


def _check_end(stream: BinaryIO, footer_end: int, size: int, footer: Footer, data_end: int | None,
               data_end_record: DataEnd | None, data_crc: int) -> tuple[str | None, int]:
    """What is wrong with a file read to its footer, and up to which byte it is good.

    Checked: the closing magic bytes, the data section's CRC (when written), the footer's summary position and
    the summary's CRC.
    """
    tail = stream.read(len(_MAGIC))
    if tail != _MAGIC:
        if _MAGIC.startswith(tail):
            return "the file ends within its closing magic bytes: truncated", footer_end
        return "damaged end of file: the footer is not followed by the MCAP magic bytes", footer_end
    if footer_end + len(_MAGIC) != size:
        return f"{size - footer_end - len(_MAGIC)} bytes after the end of the MCAP data", footer_end + len(_MAGIC)
    if data_end is None or data_end_record is None:   # found together
        return "damaged file: no DataEnd record before the footer", footer_end
    if data_end_record.data_section_crc not in (0, data_crc):
        return "the data section's CRC does not match: a record outside the chunks is damaged", data_end
    if footer.summary_start not in (0, data_end) or (footer.summary_start == 0 and footer_end - 29 != data_end):
        return (f"damaged footer: it places the summary at byte {footer.summary_start}, after the data section "
                f"ending at byte {data_end}"), data_end
    if footer.summary_crc:
        stream.seek(data_end)
        crc = zlib.crc32(stream.read(footer_end - 4 - data_end))   # up to the footer's summary_crc field
        if crc != footer.summary_crc:
            return "the summary section is damaged (its CRC does not match)", data_end
    return None, size


def _not_mcap(path: Path, head: bytes) -> str:
    if not head:
        return f"{path} is not an MCAP file (it is empty)"
    if _MAGIC.startswith(head):
        return f"{path} is not an MCAP file (it ends after {len(head)} bytes, within the MCAP magic bytes)"
    return f"{path} is not an MCAP file (it does not start with the MCAP magic bytes)"


def _scan(path: Path, recording: Recording) -> FileReport:
    """Read a file record by record, collecting topics and metadata, up to its end or its damage."""
    report = FileReport(path, path.stat().st_size)
    schemas: dict[int, Schema] = {}
    statistics: Statistics | None = None
    in_summary = False
    channels: set[int] = set()
    orphans = 0   # messages of channels never defined: their Channel record was lost
    for record, end in _records(path, report):
        report.bytes_read = end     # every record up to here was read whole (a chunk: and verified)
        if isinstance(record, DataEnd):
            in_summary = True       # topics and counts come from the data section; the summary repeats them
        elif isinstance(record, Statistics):
            statistics = record
        elif in_summary:
            continue
        elif isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels.add(record.id)
            schema = schemas.get(record.schema_id)
            recording.topics.setdefault(record.topic, RecordedTopic(
                record.topic, schema.name if schema else "", record.metadata.get("offered_qos_profiles", ""),
                schema.data.decode(errors="replace") if schema else "", record.message_encoding,
                schema.encoding if schema else ""))
        elif isinstance(record, Message):
            if record.channel_id in channels:
                report.messages += 1
                t = record.log_time
                if report.start_ns is None or t < report.start_ns:
                    report.start_ns = t
                if report.end_ns is None or t > report.end_ns:
                    report.end_ns = t
            else:
                orphans += 1
        elif isinstance(record, Metadata):
            recording.metadata.setdefault(record.name, dict(record.metadata))
    if report.error is None:
        if orphans:
            report.error = f"{orphans} messages of channels the file does not define (their channel record is lost)"
        elif statistics is not None and statistics.message_count != report.messages:
            report.error = (f"the summary counts {statistics.message_count} messages, "
                            f"{report.messages} could be read")
        else:
            report.complete = True
            report.bytes_read = report.size
    return report


def _summary_ok(path: Path) -> bool:
    try:
        with path.open("rb") as stream:
            return make_reader(stream).get_summary() is not None
    except Exception:  # any failure means: no usable summary, scan instead
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
