"""Reading recordings back with the independent readers (``rosbags``, ``mcap`` + ``mcap-ros2-support``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def read_with_mcap_ros2(path: Path) -> list[tuple[str, bytes, int, Any]]:
    """(topic, raw bytes, log time, decoded message) of every message of one MCAP file, in file order."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with Path(path).open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        return [(channel.topic, bytes(message.data), message.log_time, decoded)
                for _schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False)]


def read_with_rosbags(directory: Path) -> tuple[dict[str, int], list[tuple[str, bytes, int, Any]]]:
    """Message counts from metadata and (topic, raw, log time, decoded) of every message of a bag directory."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    with AnyReader([Path(directory)], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        messages = [(c.topic, bytes(raw), t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]
    return counts, messages
