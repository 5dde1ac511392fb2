"""Rig messages from a ROS 2 MCAP recording (profile ``ros2``, ``ros2msg`` schemas, ``cdr``), without ROS.

The files are read by the damage-tolerant reader (:mod:`rimd_sim.io.reader`): a truncated or damaged
file gives every message before the damage (chunks checked against their CRC, so never altered bytes), and
what was lost is reported in :class:`RecordingInfo`. Decoding is :mod:`rimd_sim.io.decode`'s (the decoder of
every reader of a recording), from the full message definitions stored in the file, so a recording of any
build of ``rimd_msgs`` with the same fields reads the same.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimd_sim.errors import RecordingError
from rimd_sim.viz.rerun_map import CHANNELS, EVENTS_TOPIC, TOPICS, TRUTH_TOPIC

__all__ = ["McapError", "RecordingInfo", "read_rig_messages"]

#: The message type of each rig topic (relative name): a topic recorded with another type is not rig data.
RIG_TYPES = {**{ch.topic: "rimd_msgs/msg/SampleBlock" for ch in CHANNELS},
             EVENTS_TOPIC: "rimd_msgs/msg/ImpactEvent", TRUTH_TOPIC: "rimd_msgs/msg/RigState"}


class McapError(RecordingError):
    """The file is missing, not an MCAP file, or holds no readable rig topic; one clear line."""


@dataclass
class RecordingInfo:
    """What :func:`read_rig_messages` found: rig topics present and messages per topic (filled as read).

    ``damaged``: one line per damaged file (what was lost); ``problems``: rig topics left out (foreign type,
    undecodable definition) and messages that could not be decoded.
    """

    topics: dict[str, str]  # full topic -> relative topic
    counts: dict[str, int]
    damaged: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def _relative(topic: str, namespace: str) -> str | None:
    prefix = namespace.rstrip("/") + "/"
    if not topic.startswith(prefix):
        return None
    rel = topic[len(prefix):]
    return rel if rel in TOPICS else None


def read_rig_messages(path: str | Path, *, namespace: str = "/rig",
                      info: RecordingInfo | None = None) -> Iterator[tuple[str, Any]]:
    """Yield ``(relative topic, decoded message)`` of the rig topics of ``path`` in file order.

    ``path`` is one ``.mcap`` file or a recording directory (a rosbag2 bag of ``rimd_recorder``: its
    ``.mcap`` files in the order they were split). The recorder writes in log-time order.

    Raises:
        McapError: A file cannot be opened or is not MCAP, no rig topic under ``namespace`` can be read, or a
            damaged recording holds no readable rig message.
    """
    from rimd_sim.io.decode import topic_decoder
    from rimd_sim.io.reader import RecordingError, open_recording

    path = Path(path)
    info = info if info is not None else RecordingInfo({}, {})
    if path.is_dir() and not any(path.glob("*.mcap")):
        raise McapError(f"{path}: a directory without .mcap files")
    if not path.exists():
        raise McapError(f"{path}: no such file")
    try:
        recording = open_recording(path)
    except RecordingError as exc:
        raise McapError(f"not a readable MCAP file: {exc}") from None
    info.damaged.extend(r.describe() for r in recording.reports if not r.complete)
    damage = "; ".join(info.damaged)

    decoders = {}
    for name, topic in sorted(recording.topics.items()):
        rel = _relative(name, namespace)
        if rel is None:
            continue
        if topic.type_name != RIG_TYPES[rel]:
            info.problems.append(f"{name} has type {topic.type_name or '(no schema)'}, not {RIG_TYPES[rel]}: "
                                 "left out")
            continue
        try:
            decoder = topic_decoder(topic)
        except Exception as exc:  # noqa: BLE001 - a definition that cannot be read: the topic is left out
            info.problems.append(f"{name}: cannot decode its messages ({type(exc).__name__}: {exc}): left out")
            continue
        decoders[name] = decoder
        info.topics[name] = rel
    if not decoders:
        found = sorted(recording.topics)
        why = f"; {'; '.join(info.problems)}" if info.problems else ""
        if damage:
            raise McapError(f"{path}: no rig topic under {namespace} could be read before the damage ({damage})"
                            f"{why}")
        raise McapError(f"{path}: no rig topic under {namespace} (topics: {', '.join(found) or 'none'}){why}")

    undecodable: dict[str, int] = {}
    yielded = 0
    for msg in recording.messages(decoders):
        rel = info.topics[msg.topic]
        try:
            decoded = decoders[msg.topic](msg.data)
        except Exception:  # bytes that do not decode with their definition: counted, skipped
            undecodable[msg.topic] = undecodable.get(msg.topic, 0) + 1
            continue
        info.counts[rel] = info.counts.get(rel, 0) + 1
        yielded += 1
        yield rel, decoded
    info.problems.extend(f"{name}: {count} messages could not be decoded" for name, count in undecodable.items())
    if not yielded and damage:
        raise McapError(f"{path}: no rig message could be read before the damage ({damage})")
