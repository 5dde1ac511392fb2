"""Cropping a recording to a time window, without ROS: what ``ros2 bag convert`` does with a start and end time.

:func:`crop` reads a recording (one MCAP file or a recording directory, damaged files included, through
:mod:`rimd_sim.io.reader`) and writes the messages of a window, bytes and times unchanged, to a new
recording directory with :class:`rimd_sim.io.bag.BagWriter`: the recorder's conventions (files
``<prefix>_<UTC timestamp>_<n>.mcap``, profile ``ros2``, the recorded ``ros2msg`` schemas and offered QoS,
statistics and indexes, the ``rosbag2`` metadata record, ``metadata.yaml``). The source's MCAP metadata
records are copied, and a ``rimd_crop`` record says where the window came from.

The window is in seconds from the recording's first message (log time), both ends included:
``start <= log_time - first <= end``. ``end`` None = up to the last message.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from rimd_sim.io.bag import ROSBAG2_METADATA_NAME, BagWriter
from rimd_sim.io.msgdefs import MessageDefinition, MessageDefinitionError, message_definition
from rimd_sim.io.reader import Recording, RecordingError, open_recording

__all__ = ["CropError", "CropResult", "crop"]


class CropError(RecordingError):
    """The crop cannot be done as asked; the message (one line) names the option, the value and the rule."""


@dataclass
class CropResult:
    """What :func:`crop` wrote.

    Attributes:
        output_dir: The new recording directory.
        files: Its MCAP files.
        start_ns, end_ns: The window, absolute log times (ns), both included.
        topic_counts: Messages written per topic (every selected topic is listed, 0 included).
        source_duration: s from the first to the last message of the source.
        notes: What was wrong with the source (damaged files), one line each.
    """

    output_dir: Path
    files: list[Path]
    start_ns: int
    end_ns: int
    topic_counts: dict[str, int] = field(default_factory=dict)
    source_duration: float = 0.0
    notes: list[str] = field(default_factory=list)

    @property
    def message_count(self) -> int:
        """Messages written."""
        return sum(self.topic_counts.values())


def _qos_profiles(text: str) -> list[dict]:
    try:
        profiles = yaml.safe_load(text) if text else []
    except yaml.YAMLError:
        return []
    return [dict(p) for p in profiles if isinstance(p, dict)] if isinstance(profiles, list) else []


def _bounds(recording: Recording) -> tuple[int, int] | None:
    first: int | None = None
    last: int | None = None
    for msg in recording.messages():
        first = msg.log_time if first is None else min(first, msg.log_time)
        last = msg.log_time if last is None else max(last, msg.log_time)
    return None if first is None or last is None else (first, last)


def crop(source: str | Path, output_dir: str | Path, *, start: float = 0.0, end: float | None = None,
         topics: Sequence[str] | None = None, prefix: str = "rimd", compression: str = "zstd") -> CropResult:
    """Write the messages of ``source`` between ``start`` and ``end`` s (and of ``topics``) to ``output_dir``.

    Raises:
        CropError: The source cannot be read or has no message; the window is empty or outside the recording
            (``end`` before ``start``, ``start`` negative or past the last message, ``end`` past it); a topic is
            not in the recording; ``output_dir`` exists and is not empty, or is the source.
    """
    source, output_dir = Path(source), Path(output_dir)
    if not all(map(_finite, (start, 0.0 if end is None else end))):
        raise CropError(f"--start {start} s / --end {end} s refused: must be finite numbers of seconds")
    if end is not None and end < start:
        raise CropError(f"--end {end:g} s refused: must not be before --start {start:g} s")
    if start < 0:
        raise CropError(f"--start {start:g} s refused: must be >= 0 (seconds from the recording's first message)")
    if output_dir.exists() and (not output_dir.is_dir() or any(output_dir.iterdir())):
        raise CropError(f"--out {output_dir} refused: exists and is not an empty directory")
    if output_dir.resolve() == source.resolve():
        raise CropError(f"--out {output_dir} refused: it is the source recording")
    try:
        recording = open_recording(source)
    except RecordingError as exc:
        raise CropError(str(exc)) from None
    notes = [r.describe() for r in recording.reports if not r.complete]
    selected = list(recording.topics) if topics is None else list(topics)
    unknown = [t for t in selected if t not in recording.topics]
    if unknown:
        raise CropError(f"--topics {' '.join(unknown)} refused: not in {source} (its topics: "
                        f"{', '.join(sorted(recording.topics))})")
    bounds = _bounds(recording)
    if bounds is None:
        raise CropError(f"{source} holds no readable message: nothing to crop")
    first, last = bounds
    duration = (last - first) / 1e9
    if start > duration:
        raise CropError(f"--start {start:g} s refused: outside the recording, which spans 0 to {duration:.9g} s")
    if end is not None and end > duration:
        raise CropError(f"--end {end:g} s refused: outside the recording, which spans 0 to {duration:.9g} s "
                        "(leave --end out to crop to the end)")
    start_ns = first + round(start * 1e9)
    end_ns = last if end is None else first + round(end * 1e9)

    metadata = {name: data for name, data in recording.metadata.items() if name != ROSBAG2_METADATA_NAME}
    metadata["rimd_crop"] = {"source": str(source.resolve()), "start_s": repr(start),
                             "end_s": repr(end if end is not None else duration),
                             "start_ns": str(start_ns), "end_ns": str(end_ns), "topics": " ".join(selected)}
    writer = BagWriter(output_dir, prefix=prefix, compression=compression, library="rimd crop", metadata=metadata)
    counts = dict.fromkeys(selected, 0)
    try:
        for name in selected:
            recorded = recording.topics[name]
            try:
                type_hash = message_definition(recorded.type_name).type_hash
            except MessageDefinitionError:
                type_hash = ""   # a type not installed here: its recorded schema is all that is needed
            writer.add_topic(name, recorded.type_name, _qos_profiles(recorded.offered_qos_profiles),
                             definition=MessageDefinition(recorded.type_name, recorded.definition, type_hash))
        for msg in recording.messages(selected):
            if start_ns <= msg.log_time <= end_ns:
                writer.write(msg.topic, msg.data, msg.log_time, msg.publish_time)
                counts[msg.topic] += 1
    finally:
        writer.close()
    if writer.failure is not None:
        raise CropError(f"writing {output_dir} failed: {writer.failure.describe()}")
    return CropResult(output_dir, [f.path for f in writer.files], start_ns, end_ns, counts, duration, notes)


def _finite(value: float) -> bool:
    return isinstance(value, (int, float)) and value == value and abs(value) != float("inf")

