"""Writing rosbag2-compatible MCAP recordings, without rclpy.

A recording is a directory (``output_dir``) holding MCAP files named ``<prefix>_<UTC timestamp>_<n>.mcap``
and a rosbag2 ``metadata.yaml`` listing them, so the three usual ways of opening ROS 2 recordings work:
``ros2 bag play`` / ``ros2 bag info`` on the directory or on one file, Foxglove on a file, and the
``rosbags`` library on the directory. Each file on its own is a complete rosbag2 MCAP file: profile
``ros2``, ``ros2msg`` schemas with full definitions, ``cdr`` channels carrying ``offered_qos_profiles`` and
``topic_type_hash``, statistics, chunk and message indexes, and the ``rosbag2`` metadata record written when
the file is finished.

Durability: the file is written without a user-space buffer, chunk by chunk; a chunk is closed when it
reaches ``chunk_size`` bytes or when :meth:`BagWriter.flush` is called (the recorder does this every
``flush_interval`` seconds). A process killed without warning therefore loses at most the chunk in
progress; the finished chunks read back (see :mod:`rimd_sim.io.reader`).

Memory: the summary written when a file is finished indexes every chunk, so each file keeps one index entry
per chunk until then, packed (:class:`PackedChunkIndexes`: about 200 bytes per chunk, 0.75 MB per hour of a
real-time rig's chunk a second, where mcap's writer alone keeps 1.4 KB: ``benchmarks/bench_bag_index.py``).
``max_duration`` bounds it for recordings of days.

Write errors (disk full, file too large, quota, I/O): the first ``OSError`` stops the recording. The file
being written is cut back to its last complete record (the chunk in progress, whose write may have stopped
half-way, is removed: this also gives back its space) and closed without a summary, like a file of a killed
recorder: it reads back up to that point. A file left without any message is deleted. ``metadata.yaml`` is
rewritten if there is room. From then on :meth:`BagWriter.write` writes nothing and counts every message it
is given as not written (:attr:`BagWriter.not_written`, per topic, with the messages of the lost chunk), so
a full disk costs neither CPU nor log lines. :attr:`BagWriter.failure` describes the error;
:meth:`BagWriter.split` clears it, and the next message opens a new file (a retry once space is back). No
method raises ``OSError``: the caller looks at :attr:`BagWriter.failure`.
"""

from __future__ import annotations

import datetime as _dt
import errno
import io
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.records import ChunkIndex
from mcap.writer import CompressionType, Writer

from rimd_sim.io.msgdefs import MessageDefinition, message_definition
from rimd_sim.settings.recording import COMPRESSIONS

_COMPRESSION_TYPES = {name: CompressionType[name.upper()] for name in COMPRESSIONS}
ROS_DISTRO = "jazzy"
METADATA_VERSION = 9
#: Name of the MCAP metadata record rosbag2 writes (its ``serialized_metadata`` is the file's bag metadata).
ROSBAG2_METADATA_NAME = "rosbag2"

_INFINITE = {"sec": 2147483647, "nsec": 4294967295}


def qos_profile_dict(*, reliable: bool = True, transient_local: bool = False, depth: int = 10,
                     keep_all: bool = False) -> dict[str, Any]:
    """Return one offered QoS profile in rosbag2's (metadata version 9) dictionary form."""
    return {
        "history": "keep_all" if keep_all else "keep_last",
        "depth": int(depth),
        "reliability": "reliable" if reliable else "best_effort",
        "durability": "transient_local" if transient_local else "volatile",
        "deadline": dict(_INFINITE),
        "lifespan": dict(_INFINITE),
        "liveliness": "automatic",
        "liveliness_lease_duration": dict(_INFINITE),
        "avoid_ros_namespace_conventions": False,
    }


def qos_yaml(profiles: Sequence[Mapping[str, Any]]) -> str:
    """Serialise offered QoS profiles as the YAML string rosbag2 stores in a channel's metadata."""
    if not profiles:
        return ""
    return yaml.safe_dump([dict(p) for p in profiles], default_flow_style=False, sort_keys=False).strip()


def utc_stamp(time_ns: int | None = None) -> str:
    """Return a UTC timestamp for file names, to the millisecond: ``20261121T101530.123Z``."""
    moment = _dt.datetime.fromtimestamp((time_ns if time_ns is not None else _now_ns()) / 1e9, _dt.UTC)
    return moment.strftime("%Y%m%dT%H%M%S.") + f"{moment.microsecond // 1000:03d}Z"


def _now_ns() -> int:
    import time

    return time.time_ns()


#: errno values that mean "no room for more data": disk full, file size limit (RLIMIT_FSIZE with SIGXFSZ
#: ignored, or the file system's largest file), disk quota.
DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EFBIG, errno.EDQUOT})


@dataclass
class WriteFailure:
    """Why a recording stopped writing: the error, the path it concerns and what it cost.

    Attributes:
        path: The file that could not be written (an MCAP file or ``metadata.yaml``).
        error: The ``OSError`` (its ``errno`` and ``strerror``).
        file: The MCAP file that was being written when the error came (None if none was open); it keeps
            the messages written before the error (``file.message_count``) and has no summary.
        lost_in_chunk: Messages of the chunk in progress that the error lost (their write had not completed).
        time_ns: Wall-clock time of the error.
    """

    path: Path
    error: OSError
    file: FileInfo | None = None
    lost_in_chunk: int = 0
    time_ns: int = 0

    @property
    def disk_full(self) -> bool:
        """True for "no room" errors (ENOSPC, EFBIG, EDQUOT), as opposed to other I/O errors."""
        return self.error.errno in DISK_FULL_ERRNOS

    @property
    def headline(self) -> str:
        """What happened, in two words: ``disk full``, ``file too large``, ``disk quota exceeded``, ``write error``."""
        code = self.error.errno
        names = {errno.ENOSPC: "disk full", errno.EFBIG: "file too large", errno.EDQUOT: "disk quota exceeded"}
        return names.get(code, "write error") if code is not None else "write error"

    @property
    def reason(self) -> str:
        """The system's text and the errno name, e.g. ``No space left on device (errno 28, ENOSPC)``."""
        code = self.error.errno
        name = errno.errorcode.get(code, "?") if code is not None else "?"
        return f"{self.error.strerror or self.error} (errno {code}, {name})"

    def describe(self) -> str:
        """One line: ``disk full: /path/file.mcap: No space left on device (errno 28, ENOSPC)``."""
        return f"{self.headline}: {self.path}: {self.reason}"


def _name_path(exc: OSError, path: Path) -> OSError:
    """Attach ``path`` to an ``OSError`` raised by a write (``os.write`` errors carry no file name)."""
    if exc.filename is None:
        exc.filename = str(path)
    return exc


class _UnbufferedFile:
    """A file written straight to the OS, with no user-space buffer that SIGKILL would lose.

    Not an ``io.RawIOBase``, so that ``mcap.Writer`` uses it as is instead of wrapping it in a buffer.
    ``bytes_written`` counts what reached the file, also when a write fails part-way.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fd: int | None = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.bytes_written = 0

    def write(self, data: bytes | bytearray | memoryview) -> int:
        fd = self._fd
        assert fd is not None, "write after close"
        view = memoryview(data)
        try:
            while view:
                n = os.write(fd, view)
                self.bytes_written += n
                view = view[n:]
        except OSError as exc:
            raise _name_path(exc, self.path) from None
        return len(data)

    def tell(self) -> int:
        return self.bytes_written

    def flush(self) -> None:
        pass

    def truncate(self, size: int) -> None:
        """Cut the file to ``size`` bytes (gives back the space of a half-written tail)."""
        if self._fd is not None:
            os.ftruncate(self._fd, size)
            self.bytes_written = size

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


@dataclass
class TopicInfo:
    """A topic of a recording: name, type, offered QoS profiles and the full message definition."""

    name: str
    type_name: str
    qos_profiles: list[dict[str, Any]]
    definition: MessageDefinition


@dataclass
class FileInfo:
    """One MCAP file of a recording, with what was written into it.

    The counts and times are those of the messages that reached the file (complete chunks); the messages
    of the chunk in progress join them when the chunk is written. ``error`` is set when a write error
    stopped the file (it then has no summary and ``finished`` stays False).
    """

    path: Path
    start_ns: int | None = None
    end_ns: int | None = None
    message_count: int = 0
    topic_counts: dict[str, int] = field(default_factory=dict)
    size: int = 0
    finished: bool = False
    error: str | None = None


class PackedChunkIndexes:
    """The chunk indexes an MCAP writer keeps for its summary, each held as its serialized record.

    mcap's :class:`~mcap.writer.Writer` keeps one :class:`~mcap.records.ChunkIndex` per chunk written until
    :meth:`~mcap.writer.Writer.finish` writes them into the summary: up to 1.4 KB of Python objects each (a chunk
    with a message on each of the rig's 12 topics). The recorder closes a chunk at least every ``flush_interval``
    (1 s), so a file recorded for a day held up to 120 MB of them. Here each is its record's bytes (about 200) in
    one buffer, read back into a ``ChunkIndex`` one at a time when the summary is written: the file is the same,
    byte for byte.
    """

    def __init__(self) -> None:
        self._records = bytearray()
        self._count = 0

    def append(self, index: ChunkIndex) -> None:
        """Keep ``index`` (serialized now)."""
        builder = RecordBuilder()
        index.write(builder)
        self._records += builder.end()
        self._count += 1

    def __len__(self) -> int:
        """The number of indexes held."""
        return self._count

    def __iter__(self) -> Iterator[ChunkIndex]:
        """Each index, read back from its record, in the order given."""
        stream = ReadDataStream(io.BytesIO(bytes(self._records)))
        for _ in range(self._count):
            stream.read1()   # the opcode (CHUNK_INDEX)
            stream.read8()   # the record's length
            yield ChunkIndex.read(stream)

    @property
    def nbytes(self) -> int:
        """Bytes of the serialized records held."""
        return len(self._records)


#: Where mcap's Writer keeps its chunk indexes (its private ``__chunk_indices`` list, mcap 1.x).
_WRITER_CHUNK_INDEXES = "_Writer__chunk_indices"


def pack_chunk_indexes(writer: Writer) -> bool:
    """Have a new ``writer`` keep its chunk indexes as :class:`PackedChunkIndexes`.

    Returns False, and leaves the writer as it is (correct, with the larger index), where this mcap keeps them
    otherwise (tests/io/test_bag_chunk_indexes.py fails then, so that an upgrade of mcap is looked at).
    """
    current = getattr(writer, _WRITER_CHUNK_INDEXES, None)
    if type(current) is not list or current:
        return False
    setattr(writer, _WRITER_CHUNK_INDEXES, PackedChunkIndexes())
    return True


class McapFile:
    """One rosbag2 MCAP file being written.

    It keeps track of the offset after the last complete operation (``_committed``) and of the messages
    not yet in the file (the chunk in progress), so that after a write error :meth:`fail` can cut the file
    back to a clean end and say exactly which messages are in it.
    """

    def __init__(self, path: Path, *, compression: str, chunk_size: int, library: str,
                 metadata: Mapping[str, Mapping[str, str]], opener: Callable[[Path], Any] | None = None) -> None:
        self.info = FileInfo(path)
        #: Log time of the first message given to the file (also while it is still in the chunk in progress).
        self.first_log_time: int | None = None
        self._pending: dict[str, int] = {}
        self._pending_start: int | None = None
        self._pending_end: int | None = None
        self._committed = 0
        self._raw = (opener or _UnbufferedFile)(path)
        try:
            # mcap's Writer takes any object with write() and tell() (its annotation names only files).
            self._writer = Writer(self._raw, chunk_size=chunk_size, compression=_COMPRESSION_TYPES[compression])  # type: ignore[arg-type]
            pack_chunk_indexes(self._writer)   # the summary's index kept in ~200 bytes per chunk, not ~1.4 KB
            self._writer.start(profile="ros2", library=library)
            self._compression = compression
            self._channels: dict[str, int] = {}
            self._schemas: dict[str, int] = {}
            self._topics: dict[str, TopicInfo] = {}
            for name, data in metadata.items():
                self.add_metadata(name, data)
        except OSError:
            self._raw.close()
            path.unlink(missing_ok=True)   # nothing of value in it
            raise
        self._commit(messages=False)

    @property
    def size(self) -> int:
        """Bytes written to the file so far (the chunk in progress is not counted)."""
        return self._raw.tell()

    def _commit(self, *, messages: bool) -> None:
        """Note that the file is complete up to here; with ``messages``, the pending messages are in it."""
        self._committed = self._raw.tell()
        if not messages or not self._pending:
            return
        info = self.info
        start, end = self._pending_start, self._pending_end
        assert start is not None and end is not None   # set with the first pending message
        if info.start_ns is None or start < info.start_ns:
            info.start_ns = start
        if info.end_ns is None or end > info.end_ns:
            info.end_ns = end
        for topic, count in self._pending.items():
            info.message_count += count
            info.topic_counts[topic] = info.topic_counts.get(topic, 0) + count
        self._pending = {}
        self._pending_start = self._pending_end = None

    def add_topic(self, topic: TopicInfo) -> None:
        """Register a topic's schema and channel (idempotent)."""
        if topic.name in self._channels:
            return
        before = self._raw.tell()
        schema_id = self._schemas.get(topic.type_name)
        if schema_id is None:
            schema_id = self._writer.register_schema(topic.type_name, "ros2msg", topic.definition.text.encode())
            self._schemas[topic.type_name] = schema_id
        channel_metadata = {"offered_qos_profiles": qos_yaml(topic.qos_profiles)}
        if topic.definition.type_hash:
            channel_metadata["topic_type_hash"] = topic.definition.type_hash
        self._channels[topic.name] = self._writer.register_channel(topic.name, "cdr", schema_id, channel_metadata)
        self._topics[topic.name] = topic
        if self._raw.tell() != before:   # the records closed the chunk in progress: it is in the file
            self._commit(messages=True)

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int, sequence: int = 0) -> None:
        """Add one serialized message of a registered topic."""
        before = self._raw.tell()
        self._writer.add_message(self._channels[topic], log_time_ns, data, publish_time_ns, sequence)
        if self.first_log_time is None:
            self.first_log_time = log_time_ns
        if self._pending_start is None or log_time_ns < self._pending_start:
            self._pending_start = log_time_ns
        if self._pending_end is None or log_time_ns > self._pending_end:
            self._pending_end = log_time_ns
        self._pending[topic] = self._pending.get(topic, 0) + 1
        if self._raw.tell() != before:   # the chunk (this message included) and its indexes were written
            self._commit(messages=True)

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Add an MCAP metadata record (string keys and values)."""
        self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
        self._commit(messages=False)   # a metadata record does not close the chunk in progress

    def flush(self) -> None:
        """Close the chunk in progress so that it reaches the file."""
        self._writer.flush()
        self._commit(messages=True)

    def finish(self) -> FileInfo:
        """Write the last chunk, the rosbag2 metadata record, the summary and the footer, and close the file."""
        self.flush()
        info = self.info
        bag_info = bag_metadata([info], list(self._topics.values()), relative_to=info.path.parent)
        self.add_metadata(ROSBAG2_METADATA_NAME, {
            "serialized_metadata": yaml.safe_dump(bag_info["rosbag2_bagfile_information"], sort_keys=False),
            "ros_distro": ROS_DISTRO,
        })
        self._writer.finish()
        self._raw.close()
        info.size = info.path.stat().st_size
        info.finished = True
        return info

    def fail(self, reason: str) -> dict[str, int]:
        """Stop after a write error: cut the file back to its last complete record and close it.

        The writer is not used again (after a failed write its state no longer matches the file). The file
        keeps every complete chunk and has no summary, like the file of a killed recorder. Returns the
        messages lost with the chunk in progress, per topic.
        """
        try:
            self._raw.truncate(self._committed)
        except OSError:
            pass   # the half-written tail stays; readers stop at it
        self._raw.close()
        info = self.info
        info.error = reason
        try:
            info.size = info.path.stat().st_size
        except OSError:
            info.size = self._committed
        lost, self._pending = self._pending, {}
        return lost

    def abandon(self) -> None:
        """Close the file descriptor without finishing (the file keeps its finished chunks)."""
        self._raw.close()


def bag_metadata(files: Sequence[FileInfo], topics: Sequence[TopicInfo], *, relative_to: Path,
                 previous: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Return the rosbag2 ``metadata.yaml`` content (version 9) describing ``files``.

    Args:
        files: The MCAP files, in order.
        topics: Every topic recorded in them.
        relative_to: The bag directory; file paths are stored relative to it.
        previous: The ``rosbag2_bagfile_information`` of an existing ``metadata.yaml`` of the same directory,
            whose still existing files are kept in front of ``files`` (a directory that grows run by run).
    """
    entries: list[dict[str, Any]] = []
    topic_counts: dict[str, int] = {}
    topic_meta: dict[str, dict[str, Any]] = {}
    if previous:
        for entry in previous.get("files", []) or []:
            if (relative_to / entry["path"]).exists() and entry["path"] not in {f.path.name for f in files}:
                entries.append(entry)
        for item in previous.get("topics_with_message_count", []) or []:
            name = item["topic_metadata"]["name"]
            topic_meta[name] = item["topic_metadata"]
            topic_counts[name] = topic_counts.get(name, 0) + int(item.get("message_count", 0))
    for info in files:
        start = info.start_ns or 0
        duration = (info.end_ns - start) if info.end_ns is not None else 0
        entries.append({"path": info.path.name, "starting_time": {"nanoseconds_since_epoch": start},
                        "duration": {"nanoseconds": duration}, "message_count": info.message_count})
        for name, count in info.topic_counts.items():
            topic_counts[name] = topic_counts.get(name, 0) + count
    for topic in topics:
        topic_meta[topic.name] = {
            "name": topic.name, "type": topic.type_name, "serialization_format": "cdr",
            "offered_qos_profiles": [dict(p) for p in topic.qos_profiles],
            "type_description_hash": topic.definition.type_hash,
        }
        topic_counts.setdefault(topic.name, 0)
    starts = [e["starting_time"]["nanoseconds_since_epoch"] for e in entries if e["message_count"]]
    ends = [e["starting_time"]["nanoseconds_since_epoch"] + e["duration"]["nanoseconds"]
            for e in entries if e["message_count"]]
    start = min(starts) if starts else 0
    return {"rosbag2_bagfile_information": {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": (max(ends) - start) if ends else 0},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": sum(e["message_count"] for e in entries),
        "topics_with_message_count": [
            {"topic_metadata": topic_meta[name], "message_count": topic_counts[name]} for name in topic_meta
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [e["path"] for e in entries],
        "files": entries,
        "custom_data": None,
        "ros_distro": ROS_DISTRO,
    }}


class BagWriter:
    """A recording directory: a sequence of MCAP files split by duration and size, plus ``metadata.yaml``.

    Args:
        output_dir: The directory (created if needed).
        prefix: File name prefix (``<prefix>_<UTC timestamp>_<n>.mcap``).
        compression: ``zstd``, ``lz4`` or ``none`` (chunk compression).
        chunk_size: Bytes of messages per chunk before it is compressed and written.
        max_duration_ns: Start a new file when a message's log time is this far past the file's first
            message (0: never). The message that crosses the boundary opens the new file.
        max_size: Start a new file once the file has this many bytes (0: never; the file can exceed it by
            up to one chunk).
        library: Written into each file's header.
        metadata: MCAP metadata records written into every file (name -> string mapping).
        opener: Opens a new file for writing (default: unbuffered OS writes); it must offer ``write``,
            ``tell``, ``flush``, ``truncate`` and ``close``, and raise ``OSError`` as a disk does (the tests
            give it a disk that fills up).

    Attributes:
        written: Per topic, messages accepted that are in a file or in the chunk in progress.
        not_written: Per topic, messages that a write error kept out of the files (the chunk in progress
            when it came, and every message given while :attr:`failure` is set).
        failure: The write error that stopped the recording, or None (see the module docstring).
        failures: Every write error of this writer, in order (a retry can fail again).
        metadata_error: The last error writing ``metadata.yaml``, or None once it was written.
    """

    def __init__(self, output_dir: str | Path, *, prefix: str = "rimd", compression: str = "zstd",
                 chunk_size: int = 768 * 1024, max_duration_ns: int = 0, max_size: int = 0,
                 library: str = "rimd_recorder", metadata: Mapping[str, Mapping[str, str]] | None = None,
                 opener: Callable[[Path], Any] | None = None) -> None:
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression '{compression}' is not one of {', '.join(COMPRESSIONS)}")
        self.output_dir = Path(output_dir)
        self.output_dir.mkdir(parents=True, exist_ok=True)
        self.prefix = prefix
        self.compression = compression
        self.chunk_size = int(chunk_size)
        self.max_duration_ns = int(max_duration_ns)
        self.max_size = int(max_size)
        self.library = library
        self.opener = opener
        self.metadata: dict[str, dict[str, str]] = {k: dict(v) for k, v in (metadata or {}).items()}
        self.topics: dict[str, TopicInfo] = {}
        self.files: list[FileInfo] = []
        self.written: dict[str, int] = {}
        self.not_written: dict[str, int] = {}
        self.failure: WriteFailure | None = None
        self.failures: list[WriteFailure] = []
        self.metadata_error: OSError | None = None
        self._current: McapFile | None = None
        self._next_index = 0
        self._previous = self._read_previous_metadata()

    # -- topics and metadata ---------------------------------------------------------------------------------
    def add_topic(self, name: str, type_name: str, qos_profiles: Sequence[Mapping[str, Any]],
                  definition: MessageDefinition | None = None) -> TopicInfo:
        """Declare a topic; its definition is looked up now unless given (raises MessageDefinitionError if unknown).

        ``definition``: the schema to write, e.g. the one a recording being copied carries.
        """
        topic = self.topics.get(name)
        if topic is None:
            topic = TopicInfo(name, type_name, [dict(p) for p in qos_profiles],
                              definition if definition is not None else message_definition(type_name))
            self.topics[name] = topic
        current = self._current
        if current is not None:
            try:
                current.add_topic(topic)
            except OSError as exc:
                self._fail(exc)
        return topic

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Add a metadata record to the current file and to every later file."""
        self.metadata[name] = {str(k): str(v) for k, v in data.items()}
        current = self._current
        if current is not None:
            try:
                current.add_metadata(name, self.metadata[name])
            except OSError as exc:
                self._fail(exc)

    # -- writing ---------------------------------------------------------------------------------------------
    @property
    def current_path(self) -> Path | None:
        """Path of the file being written, or None between files."""
        return self._current.info.path if self._current is not None else None

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int = 0, sequence: int = 0) -> bool:
        """Write one serialized message of a declared topic, opening or splitting files as needed.

        Returns True when the message was accepted, False when a write error keeps it out (counted in
        :attr:`not_written`; :attr:`failure` says why).
        """
        if self.failure is None:
            try:
                current = self._current
                if current is not None and self._must_split(current, log_time_ns):
                    self._split()
                    current = None
                if current is None:
                    current = self._open()
                current.write(topic, data, log_time_ns, publish_time_ns or log_time_ns, sequence)
            except OSError as exc:
                self._fail(exc)
            else:
                self.written[topic] = self.written.get(topic, 0) + 1
                return True
        self.not_written[topic] = self.not_written.get(topic, 0) + 1
        return False

    def _must_split(self, current: McapFile, log_time_ns: int) -> bool:
        start = current.first_log_time
        if self.max_duration_ns > 0 and start is not None and log_time_ns - start >= self.max_duration_ns:
            return True
        return self.max_size > 0 and current.size >= self.max_size

    def _open(self) -> McapFile:
        while True:
            path = self.output_dir / f"{self.prefix}_{utc_stamp()}_{self._next_index}.mcap"
            self._next_index += 1
            try:
                current = McapFile(path, compression=self.compression, chunk_size=self.chunk_size,
                                   library=self.library, metadata=self.metadata, opener=self.opener)
                break
            except FileExistsError:
                continue
        self._current = current
        self.files.append(current.info)
        for topic in self.topics.values():
            current.add_topic(topic)
        self._write_metadata_yaml()
        return current

    def flush(self) -> None:
        """Put the chunk in progress into the file (bounds what a crash can lose)."""
        current = self._current
        if current is not None:
            try:
                current.flush()
            except OSError as exc:
                self._fail(exc)

    def split(self) -> FileInfo | None:
        """Finish the current file; the next message opens a new one. Returns the finished file's info.

        After a write error (:attr:`failure` set) there is no file to finish: the error is cleared and the
        next message opens a new file (a retry once space is back). Returns None then, and when no file was
        open or finishing it failed.
        """
        if self.failure is not None:
            self.failure = None
            return None
        try:
            return self._split()
        except OSError as exc:
            self._fail(exc)
            return None

    def _split(self) -> FileInfo | None:
        current = self._current
        if current is None:
            return None
        info = current.finish()
        self._current = None
        self._write_metadata_yaml()
        return info

    def close(self) -> None:
        """Finish the current file and write ``metadata.yaml`` (after a write error: only the latter, if it fits)."""
        try:
            self._split()
            self._write_metadata_yaml()
        except OSError as exc:
            self._fail(exc)

    def abandon(self) -> None:
        """Stop without finishing (for tests of crash behaviour): the file keeps its finished chunks."""
        if self._current is not None:
            self._current.abandon()
            self._current = None

    def _fail(self, exc: OSError) -> None:
        """Stop writing after ``exc``: keep what the current file holds, count what it lost, record why."""
        current, self._current = self._current, None
        path = Path(exc.filename) if exc.filename else (current.info.path if current else self.output_dir)
        lost: dict[str, int] = {}
        info = None
        if current is not None:
            info = current.info
            reason = WriteFailure(path, exc).describe()
            lost = current.fail(reason)
            if info.message_count == 0:   # nothing worth keeping: give the space back
                info.path.unlink(missing_ok=True)
                self.files.remove(info)
            for topic, count in lost.items():
                self.written[topic] -= count
                self.not_written[topic] = self.not_written.get(topic, 0) + count
        failure = WriteFailure(path, exc, info, sum(lost.values()), _now_ns())
        if self.failure is None:   # the first error is the one to report; a later one (close) adds nothing
            self.failure = failure
            self.failures.append(failure)
        if not (current is None and path.name in ("metadata.yaml", ".metadata.yaml.tmp")):
            try:   # list the files as they are now, if there is room for it
                self._write_metadata_yaml()
            except OSError:
                pass

    # -- metadata.yaml ---------------------------------------------------------------------------------------
    def _read_previous_metadata(self) -> dict[str, Any] | None:
        path = self.output_dir / "metadata.yaml"
        try:
            content = yaml.safe_load(path.read_text(encoding="utf-8"))
            info = content["rosbag2_bagfile_information"]
            return info if info.get("storage_identifier") == "mcap" else None
        except (OSError, yaml.YAMLError, KeyError, TypeError):
            return None

    def _write_metadata_yaml(self) -> None:
        content = bag_metadata(self.files, list(self.topics.values()), relative_to=self.output_dir,
                               previous=self._previous)
        tmp = self.output_dir / ".metadata.yaml.tmp"
        try:
            tmp.write_text(yaml.safe_dump(content, sort_keys=False), encoding="utf-8")
            tmp.replace(self.output_dir / "metadata.yaml")
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            self.metadata_error = _name_path(exc, self.output_dir / "metadata.yaml")
            raise self.metadata_error from None
        self.metadata_error = None
