"""Rig messages from a ROS 2 MCAP recording (profile ``ros2``, ``ros2msg`` schemas, ``cdr``), without ROS.

Decoding is ``mcap_ros2``'s, from the full message definitions stored in the file, so a recording of any
build of ``rimd_msgs`` with the same fields reads the same.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rimd_sim.viz.rerun_map import TOPICS

__all__ = ["McapError", "RecordingInfo", "read_rig_messages"]


class McapError(Exception):
    """The file is missing, not an MCAP file, or holds no rig topic; one clear line."""


@dataclass
class RecordingInfo:
    """What :func:`read_rig_messages` found: rig topics present and messages per topic (filled as read)."""

    topics: dict[str, str]  # full topic -> relative topic
    counts: dict[str, int]


def _relative(topic: str, namespace: str) -> str | None:
    prefix = namespace.rstrip("/") + "/"
    if not topic.startswith(prefix):
        return None
    rel = topic[len(prefix):]
    return rel if rel in TOPICS else None


def read_rig_messages(path: str | Path, *, namespace: str = "/rig",
                      info: RecordingInfo | None = None) -> Iterator[tuple[str, Any]]:
    """Yield ``(relative topic, decoded message)`` of the rig topics of ``path`` in log-time order.

    ``path`` is one ``.mcap`` file or a recording directory (a rosbag2 bag of ``rimd_recorder``: its
    ``.mcap`` files in name order, i.e. in the order they were split).

    Raises:
        McapError: A file cannot be opened or read as MCAP, or has no rig topic under ``namespace``.
    """
    path = Path(path)
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        if not files:
            raise McapError(f"{path}: a directory without .mcap files")
        for file in files:
            yield from _read_file(file, namespace, info)
    else:
        yield from _read_file(path, namespace, info)


def _read_file(path: Path, namespace: str, info: RecordingInfo | None) -> Iterator[tuple[str, Any]]:
    from mcap.exceptions import McapError as _McapLibError
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    if not path.is_file():
        raise McapError(f"{path}: no such file")
    try:
        fh = open(path, "rb")  # noqa: SIM115 - closed in finally, the generator may be abandoned
    except OSError as exc:
        raise McapError(f"{path}: cannot open: {exc.strerror}") from None
    try:
        try:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
        except (_McapLibError, ValueError, EOFError, OSError) as exc:
            raise McapError(f"{path}: not a readable MCAP file ({exc.__class__.__name__}: {exc})") from None
        if summary is None:
            raise McapError(f"{path}: not a readable MCAP file (no summary: truncated or not MCAP)")
        topics = {ch.topic: rel for ch in summary.channels.values()
                  if (rel := _relative(ch.topic, namespace)) is not None}
        if not topics:
            found = sorted({ch.topic for ch in summary.channels.values()})
            raise McapError(f"{path}: no rig topic under {namespace} (topics: {', '.join(found) or 'none'})")
        if info is not None:
            info.topics.update(topics)
        try:
            for _schema, channel, _message, decoded in reader.iter_decoded_messages(topics=list(topics)):
                rel = topics[channel.topic]
                if info is not None:
                    info.counts[rel] = info.counts.get(rel, 0) + 1
                yield rel, decoded
        except (_McapLibError, ValueError, EOFError, KeyError, OSError) as exc:
            raise McapError(f"{path}: stopped reading at a damaged record ({exc.__class__.__name__}: {exc})") from None
    finally:
        fh.close()
