"""Reading the few fields the recorder needs straight from CDR bytes (no deserialisation of the samples).

``rimd_msgs/msg/SampleBlock`` and ``rimd_msgs/msg/RigState`` both start with ``std_msgs/Header header``,
``uint64 first_index``, ``float64 sample_rate`` and then a ``float64[]`` (``samples``; ``theta`` for
RigState), so the index of the first sample and the number of samples of a block are at fixed places after
the frame id. That is all loss counting needs, at a few hundred nanoseconds per message.
"""

from __future__ import annotations

import struct

import numpy as np

#: Types whose blocks carry ``first_index`` and a sample count in this layout.
BLOCK_TYPES = frozenset({"rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState"})

_U32 = {0: struct.Struct("<I"), 1: struct.Struct(">I")}
_U64 = {0: struct.Struct("<Q"), 1: struct.Struct(">Q")}


_STAMP = {0: struct.Struct("<iI"), 1: struct.Struct(">iI")}

#: Types whose first field is a ``std_msgs/Header`` (or, for Clock, a ``builtin_interfaces/Time``): their stamp
#: is the CDR body's first 8 bytes (:func:`header_stamp`, :func:`with_header_stamp`).
HEADER_FIRST_TYPES = frozenset({
    "rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState", "rimd_msgs/msg/MotorState", "rimd_msgs/msg/ImpactEvent",
    "rimd_msgs/msg/FaultEvent", "rimd_msgs/msg/Capture", "rimd_msgs/msg/RigSession",
    "diagnostic_msgs/msg/DiagnosticArray", "rosgraph_msgs/msg/Clock", "std_msgs/msg/Header",
})


def header_stamp(data: bytes) -> int | None:
    """The stamp (ns) of a serialized message whose first field is a header (or a ``Time``), None if too short."""
    if len(data) < 12:
        return None
    sec, nanosec = _STAMP[0 if data[1] & 1 else 1].unpack_from(data, 4)
    return sec * 1_000_000_000 + nanosec


def with_header_stamp(data: bytes, stamp_ns: int) -> bytes:
    """The serialized message with its leading stamp replaced by ``stamp_ns`` (same byte order, same length)."""
    out = bytearray(data)
    _STAMP[0 if data[1] & 1 else 1].pack_into(out, 4, stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)
    return bytes(out)


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


#: The ``float64[]`` fields of each block type, in message order (RigState's ``bool[] in_contact`` follows).
BLOCK_ARRAYS = {
    "rimd_msgs/msg/SampleBlock": ("samples",),
    "rimd_msgs/msg/RigState": ("theta", "theta_dot", "cart_position", "rimd_position", "rimd_velocity",
                               "rimd_acceleration", "penetration", "contact_force", "motor_phase",
                               "motor_frequency"),
}
_F8 = {0: np.dtype("<f8"), 1: np.dtype(">f8")}
_I32 = {0: struct.Struct("<i"), 1: struct.Struct(">i")}
_F64 = {0: struct.Struct("<d"), 1: struct.Struct(">d")}


class Stamp:
    """``builtin_interfaces/Time`` as read from CDR: ``sec`` and ``nanosec``."""

    __slots__ = ("sec", "nanosec")

    def __init__(self, sec: int, nanosec: int) -> None:
        self.sec, self.nanosec = sec, nanosec


class Header:
    """``std_msgs/Header`` as read from CDR."""

    __slots__ = ("stamp", "frame_id")

    def __init__(self, stamp: Stamp, frame_id: str) -> None:
        self.stamp, self.frame_id = stamp, frame_id


class BlockView:
    """The leading fields of a serialized SampleBlock or RigState, its ``float64[]`` fields as NumPy views.

    Attributes as the message's: ``header`` (``stamp.sec``, ``stamp.nanosec``, ``frame_id``), ``first_index``,
    ``sample_rate`` and each array field read (``samples``; ``theta`` ... ``motor_frequency``), read-only
    arrays over the CDR bytes (no copy). The fields after the arrays (``unit``, ranges, ``saturated_count``,
    ``in_contact``) are not read.
    """

    def __init__(self, header: Header, first_index: int, sample_rate: float, arrays: dict[str, np.ndarray]) -> None:
        self.header, self.first_index, self.sample_rate = header, first_index, sample_rate
        self.__dict__.update(arrays)


def read_block(data: bytes, type_name: str = "rimd_msgs/msg/SampleBlock", arrays: int | None = None) -> BlockView:
    """Read a serialized SampleBlock or RigState up to its ``arrays`` first ``float64[]`` fields (default all).

    About ten times cheaper than ``rclpy.serialization.deserialize_message`` for the Rerun bridge: no message
    objects, no copy of the samples. The layout is XCDR1 (ROS 2's CDR): each field aligned to its size from
    the start of the body, after the 4-byte encapsulation header.

    Raises:
        ValueError: Bytes too short for what the layout says, or not CDR.
    """
    names = BLOCK_ARRAYS[type_name]
    if arrays is not None:
        names = names[:arrays]
    try:
        big = 0 if data[1] & 1 else 1
        u32, u64 = _U32[big], _U64[big]
        sec = _I32[big].unpack_from(data, 4)[0]
        nanosec, length = u32.unpack_from(data, 8)[0], u32.unpack_from(data, 12)[0]
        frame_id = bytes(data[16:16 + max(length - 1, 0)]).decode("utf-8", "replace")
        offset = (12 + length + 7) & ~7          # body offset of first_index
        first_index = u64.unpack_from(data, 4 + offset)[0]
        sample_rate = _F64[big].unpack_from(data, 12 + offset)[0]
        offset += 16
        dtype = _F8[big]
        out = {}
        for name in names:
            offset = (offset + 3) & ~3
            count = u32.unpack_from(data, 4 + offset)[0]
            offset += 4
            if count:
                offset = (offset + 7) & ~7
            if 4 + offset + 8 * count > len(data):
                raise ValueError(f"{name}: {count} samples do not fit in {len(data)} bytes")
            out[name] = np.frombuffer(data, dtype, count, 4 + offset)
            offset += 8 * count
    except (struct.error, IndexError) as exc:
        raise ValueError(f"not a serialized {type_name}: {exc}") from None
    return BlockView(Header(Stamp(sec, nanosec), frame_id), first_index, sample_rate, out)


def _cdr_string(text: str, offset: int) -> tuple[bytes, int]:
    """A CDR string (uint32 length with the NUL, the bytes, NUL) aligned at body ``offset``; its end offset.

    A ROS 2 string is a C string: one holding NUL would be cut there by every reader (rclpy reads "a", NUL, "b" as
    ``"a"``), so it is refused here rather than published as something other than what was asked.
    """
    if "\0" in text:
        raise ValueError(f"a ROS 2 string cannot hold a NUL character: {text!r}")
    raw = text.encode("utf-8") + b"\0"
    pad = -offset % 4
    return b"\0" * pad + struct.pack("<I", len(raw)) + raw, offset + pad + 4 + len(raw)


class SampleBlockEncoder:
    """Serializes ``rimd_msgs/msg/SampleBlock`` messages of one channel straight from NumPy (little-endian CDR).

    The fields that only change with the configuration (``frame_id``, ``sample_rate``, ``unit``, the range) are
    encoded once per :meth:`configure`; each block then costs a few ``struct.pack`` calls and one copy of the
    samples, against rclpy building a message object and converting it field by field. The bytes are those
    ``rclpy.serialization.serialize_message`` gives (tested), and ``Publisher.publish`` sends them as they are.
    """

    def __init__(self, frame_id: str, sample_rate: float, unit: str, range_min: float, range_max: float) -> None:
        self.configure(frame_id, sample_rate, unit, range_min, range_max)

    def configure(self, frame_id: str, sample_rate: float, unit: str, range_min: float, range_max: float) -> None:
        """Set the fields that stay the same from block to block."""
        frame, end = _cdr_string(frame_id, 8)              # after stamp (sec, nanosec)
        self._frame = frame
        self._pad_index = b"\0" * (-end % 8)                # first_index is 8-aligned
        self._index_offset = end + len(self._pad_index)
        self._rate = struct.pack("<d", sample_rate)
        self._unit, self._range = unit, struct.pack("<dd", range_min, range_max)

    def encode(self, sec: int, nanosec: int, first_index: int, samples: np.ndarray, saturated_count: int) -> bytes:
        """The serialized message of one block (``samples``: float64, any byte order)."""
        count = int(samples.size)
        offset = self._index_offset + 16 + 4                # first_index, sample_rate, the samples' count
        pad = b"\0" * (-offset % 8) if count else b""
        offset += len(pad) + 8 * count
        unit, offset = _cdr_string(self._unit, offset)
        range_pad = b"\0" * (-offset % 8)
        offset += len(range_pad) + 16
        return b"".join((
            b"\0\x01\0\0", struct.pack("<iI", sec, nanosec), self._frame, self._pad_index,
            struct.pack("<Q", first_index), self._rate, struct.pack("<I", count), pad,
            np.ascontiguousarray(samples, dtype="<f8").tobytes(), unit, range_pad, self._range,
            struct.pack("<I", saturated_count)))   # uint32 right after the 8-aligned range: aligned


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
