"""Reading the few fields the recorder needs straight from CDR bytes (no deserialisation of the samples).

``rimd_msgs/msg/SampleBlock`` and ``rimd_msgs/msg/RigState`` both start with ``std_msgs/Header header``,
``uint64 first_index``, ``float64 sample_rate`` and then a ``float64[]`` (``samples``; ``theta`` for
RigState), so the index of the first sample and the number of samples of a block are at fixed places after
the frame id. That is all loss counting needs, at a few hundred nanoseconds per message.
"""

from __future__ import annotations

import struct

#: Types whose blocks carry ``first_index`` and a sample count in this layout.
BLOCK_TYPES = frozenset({"rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState"})

_U32 = {0: struct.Struct("<I"), 1: struct.Struct(">I")}
_U64 = {0: struct.Struct("<Q"), 1: struct.Struct(">Q")}


def block_span(data: bytes) -> tuple[int, int]:
    """Return ``(first_index, sample_count)`` of a serialized SampleBlock or RigState.

    Raises:
        ValueError: The bytes are too short or not CDR.
    """
    if len(data) < 4 + 12:
        raise ValueError("too short for a CDR block message")
    big = 0 if data[1] & 1 else 1          # encapsulation kind: CDR_BE = 0x0000, CDR_LE = 0x0001
    u32, u64 = _U32[big], _U64[big]
    offset = 8                              # body offset of frame_id's length (after sec, nanosec)
    (length,) = u32.unpack_from(data, 4 + offset)
    offset += 4 + length
    offset = (offset + 7) & ~7              # align 8 for uint64 first_index
    (first_index,) = u64.unpack_from(data, 4 + offset)
    offset += 16                            # first_index, sample_rate
    offset = (offset + 3) & ~3
    (count,) = u32.unpack_from(data, 4 + offset)
    return first_index, count


class LossCounter:
    """Counts, per topic, samples missing between consecutive blocks (gaps in ``first_index``).

    The first block seen on a topic sets the start (a recorder started after the rig loses nothing). A block
    that starts before the expected index (the rig was restarted, or replayed) restarts the count and is
    counted in ``restarts``, not as loss.
    """

    def __init__(self) -> None:
        self.expected: dict[str, int] = {}
        self.first: dict[str, int] = {}
        self.lost_samples: dict[str, int] = {}
        self.lost_blocks: dict[str, int] = {}
        self.restarts: dict[str, int] = {}

    def observe(self, topic: str, first_index: int, count: int) -> int:
        """Record one block; return the number of samples missing just before it."""
        expected = self.expected.get(topic)
        missing = 0
        if expected is None:
            self.first[topic] = first_index
        elif first_index > expected:
            missing = first_index - expected
            self.lost_samples[topic] = self.lost_samples.get(topic, 0) + missing
            self.lost_blocks[topic] = self.lost_blocks.get(topic, 0) + max(1, round(missing / max(count, 1)))
        elif first_index < expected:
            self.restarts[topic] = self.restarts.get(topic, 0) + 1
        self.expected[topic] = first_index + count
        return missing
