"""The CDR layout of the rig's messages, written once: read in place, and encoded, in either byte order.

ROS 2 serializes messages as XCDR1: a 4-byte encapsulation header (``00 00``: big-endian, ``00 01``: little-endian,
then two option bytes), then the body, each primitive aligned to its own size from the body's start. The rig's
block messages, ``rimd_msgs/msg/SampleBlock`` and ``rimd_msgs/msg/RigState``, start alike: ``std_msgs/Header``
(``int32 sec``, ``uint32 nanosec``, ``string frame_id``), ``uint64 first_index``, ``float64 sample_rate``, then
``float64[]`` fields. :class:`CdrReader` and :class:`CdrWriter` are the one implementation of that alignment and
of the two byte orders; :func:`_read_block_head` and :meth:`SampleBlockEncoder.configure` the one description of
the leading fields. On them stand what the nodes need without deserialising: the stamp (:func:`header_stamp`,
:func:`with_header_stamp`, for any message whose first field is a header), the span of a block
(:func:`block_span`: loss counting without reading the samples), the block's arrays as NumPy views
(:func:`read_block`: the Rerun bridge), and the simulator's encoder (:class:`SampleBlockEncoder`).

The rig's other messages are encoded in :mod:`rimd_sim.io.cdr_write`, with :class:`CdrWriter`; a consumer's
progress report in :mod:`rimd_sim.io.cdr_progress`, with the standard library only, for the clients that load no
NumPy.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from fractions import Fraction
from typing import Any

import numpy as np

__all__ = ["BLOCK_ARRAYS", "BLOCK_TYPES", "HEADER_FIRST_TYPES", "BlockView", "CdrReader", "CdrWriter",
           "SampleBlockEncoder", "block_span", "cut_block", "header_stamp", "read_block", "samples_before",
           "with_header_stamp"]

#: Types whose blocks carry ``first_index`` and a sample count in this layout.
BLOCK_TYPES = frozenset({"rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState"})

#: Types whose first field is a ``std_msgs/Header`` (or, for Clock, a ``builtin_interfaces/Time``): their stamp
#: is the CDR body's first 8 bytes (:func:`header_stamp`, :func:`with_header_stamp`).
HEADER_FIRST_TYPES = frozenset({
    "rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState", "rimd_msgs/msg/MotorState", "rimd_msgs/msg/ImpactEvent",
    "rimd_msgs/msg/FaultEvent", "rimd_msgs/msg/Capture", "rimd_msgs/msg/RigSession",
    "diagnostic_msgs/msg/DiagnosticArray", "rosgraph_msgs/msg/Clock", "std_msgs/msg/Header",
})

#: The ``float64[]`` fields of each block type, in message order (RigState's ``bool[] in_contact`` follows).
BLOCK_ARRAYS = {
    "rimd_msgs/msg/SampleBlock": ("samples",),
    "rimd_msgs/msg/RigState": ("theta", "theta_dot", "cart_position", "rimd_position", "rimd_velocity",
                               "rimd_acceleration", "penetration", "contact_force", "motor_phase",
                               "motor_frequency"),
}

#: The encapsulation header of each byte order (CDR_LE: 0x0001, CDR_BE: 0x0000), options zero.
ENCAPSULATION = {"<": b"\0\x01\0\0", ">": b"\0\0\0\0"}
_PRIMITIVES = {order: {code: struct.Struct(order + code) for code in "iIQdB"} for order in "<>"}
_TIME = {order: struct.Struct(order + "iI") for order in "<>"}
_F8 = {"<": np.dtype("<f8"), ">": np.dtype(">f8")}


def byte_order(data: bytes | bytearray | memoryview) -> str:
    """``"<"`` or ``">"``, from the encapsulation header (its second byte's low bit: 1 for little-endian).

    Raises:
        ValueError: Fewer than the header's 4 bytes.
    """
    if len(data) < 4:
        raise ValueError(f"{len(data)} bytes: too short for a CDR encapsulation header")
    return "<" if data[1] & 1 else ">"


def _aligned(offset: int, size: int) -> int:
    """``offset`` rounded up to a multiple of ``size`` (1, 2, 4 or 8): XCDR1 aligns a primitive to its size."""
    return (offset + size - 1) & ~(size - 1)


class CdrReader:
    """A cursor over the body of serialized bytes (offsets count from the end of the encapsulation header).

    Raises:
        ValueError: On construction, bytes without an encapsulation header; on a read, bytes too short for it.
    """

    __slots__ = ("data", "order", "pos", "_p")

    def __init__(self, data: bytes | bytearray | memoryview) -> None:
        self.data, self.order, self.pos = data, byte_order(data), 0
        self._p = _PRIMITIVES[self.order]

    def _primitive(self, code: str) -> Any:   # an int or a float, by ``code``
        s = self._p[code]
        self.pos = _aligned(self.pos, s.size)
        try:
            (value,) = s.unpack_from(self.data, 4 + self.pos)
        except struct.error:
            raise ValueError(f"{len(self.data)} bytes: too short for a field at body offset {self.pos}") from None
        self.pos += s.size
        return value

    def u32(self) -> int:
        """``uint32``."""
        return self._primitive("I")

    def u64(self) -> int:
        """``uint64``."""
        return self._primitive("Q")

    def f64(self) -> float:
        """``float64``."""
        return self._primitive("d")

    def time(self) -> tuple[int, int]:
        """``builtin_interfaces/Time``: ``(sec, nanosec)``."""
        return self._primitive("i"), self._primitive("I")

    def string(self, *, skip: bool = False) -> str:
        """``string``: a ``uint32`` length counting the terminating NUL, the bytes, the NUL ('' with ``skip``)."""
        length = self.u32()
        end = 4 + self.pos + length
        if end > len(self.data):
            raise ValueError(f"a string of {length} bytes does not fit in {len(self.data)} bytes")
        text = "" if skip else bytes(self.data[4 + self.pos:end - 1 if length else end]).decode("utf-8", "replace")
        self.pos += length
        return text

    def f64_array(self) -> np.ndarray:
        """``float64[]``: a read-only NumPy view over the bytes (no copy), in the data's byte order."""
        count = self.u32()
        if count:
            self.pos = _aligned(self.pos, 8)
        if 4 + self.pos + 8 * count > len(self.data):
            raise ValueError(f"{count} float64 values do not fit in {len(self.data)} bytes")
        values = np.frombuffer(self.data, _F8[self.order], count, 4 + self.pos)
        self.pos += 8 * count
        return values

    def array_length(self) -> int:
        """The element count of the sequence that starts here (the cursor stays on it)."""
        pos = self.pos
        count = self.u32()
        self.pos = pos
        return count


class CdrWriter:
    """Serialized bytes built field by field, in either byte order (``"<"``, as ROS 2 publishes; or ``">"``)."""

    __slots__ = ("order", "parts", "pos", "_p")

    def __init__(self, order: str = "<", *, at: int = 0) -> None:
        self.parts: list[bytes] = []
        self.order, self.pos = order, at
        self._p = _PRIMITIVES[order]

    def _pad(self, size: int) -> None:
        aligned = _aligned(self.pos, size)
        if aligned > self.pos:
            self.parts.append(b"\0" * (aligned - self.pos))
            self.pos = aligned

    def _primitive(self, code: str, value: int | float) -> CdrWriter:
        s = self._p[code]
        self._pad(s.size)
        self.parts.append(s.pack(value))
        self.pos += s.size
        return self

    def u32(self, value: int) -> CdrWriter:
        """``uint32``."""
        return self._primitive("I", value)

    def u64(self, value: int) -> CdrWriter:
        """``uint64``."""
        return self._primitive("Q", value)

    def f64(self, value: float) -> CdrWriter:
        """``float64``."""
        return self._primitive("d", value)

    def time(self, sec: int, nanosec: int) -> CdrWriter:
        """``builtin_interfaces/Time``."""
        return self._primitive("i", sec)._primitive("I", nanosec)

    def string(self, text: str) -> CdrWriter:
        """``string``, NUL-terminated.

        A ROS 2 string is a C string: one holding NUL would be cut there by every reader (rclpy reads "a", NUL,
        "b" as ``"a"``), so it is refused rather than published as something other than asked.

        Raises:
            ValueError: The text holds a NUL character.
        """
        if "\0" in text:
            raise ValueError(f"a ROS 2 string cannot hold a NUL character: {text!r}")
        raw = text.encode("utf-8") + b"\0"
        self.u32(len(raw))
        self.parts.append(raw)
        self.pos += len(raw)
        return self

    def boolean(self, value: bool) -> CdrWriter:
        """``bool`` (one byte)."""
        return self._primitive("B", 1 if value else 0)

    def strings(self, texts: Sequence[str]) -> CdrWriter:
        """``string[]``."""
        self.u32(len(texts))
        for text in texts:
            self.string(text)
        return self

    def times(self, stamps: Sequence[tuple[int, int]]) -> CdrWriter:
        """``builtin_interfaces/Time[]`` from ``(sec, nanosec)`` pairs."""
        self.u32(len(stamps))
        for sec, nanosec in stamps:
            self.time(sec, nanosec)
        return self

    def f64_array(self, values: np.ndarray | Sequence[float]) -> CdrWriter:
        """``float64[]``."""
        values = np.ascontiguousarray(values, dtype=_F8[self.order])
        self.u32(int(values.size))
        if values.size:
            self._pad(8)
            self.parts.append(values.tobytes())
            self.pos += 8 * int(values.size)
        return self

    def body(self) -> bytes:
        """The body written so far (no encapsulation header)."""
        return b"".join(self.parts)

    def message(self) -> bytes:
        """The serialized message: the encapsulation header, then the body."""
        return ENCAPSULATION[self.order] + self.body()


# ---- the stamp of any message whose first field is a header -----------------------------------------------------

def header_stamp(data: bytes) -> int | None:
    """The stamp (ns) of a serialized message whose first field is a header (or a ``Time``), None if too short."""
    if len(data) < 12:
        return None
    sec, nanosec = _TIME[byte_order(data)].unpack_from(data, 4)
    return sec * 1_000_000_000 + nanosec


def with_header_stamp(data: bytes, stamp_ns: int) -> bytes:
    """The serialized message with its leading stamp replaced by ``stamp_ns`` (same byte order, same length).

    Raises:
        ValueError: A stamp ``builtin_interfaces/Time`` cannot hold (``sec`` is a signed 32-bit integer).
    """
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    if not -2**31 <= sec < 2**31:
        raise ValueError(f"stamp {stamp_ns} ns refused: builtin_interfaces/Time holds seconds from -2**31 to "
                         "2**31 - 1")
    out = bytearray(data)
    _TIME[byte_order(data)].pack_into(out, 4, sec, nanosec)
    return bytes(out)


# ---- the block messages ------------------------------------------------------------------------------------------

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


def _read_block_head(r: CdrReader, *, header: bool = True) -> tuple[Header | None, int, float]:
    """The leading fields of a block message: header (None: skipped), ``first_index``, ``sample_rate``.

    The cursor is left on the first array.
    """
    if header:
        sec, nanosec = r.time()
        head = Header(Stamp(sec, nanosec), r.string())
    else:
        r.pos = 8           # after the stamp: int32 sec, uint32 nanosec, at the body's start
        r.string(skip=True)
        head = None
    return head, r.u64(), r.f64()


def block_span(data: bytes) -> tuple[int, int]:
    """Return ``(first_index, sample_count)`` of a serialized SampleBlock or RigState.

    Raises:
        ValueError: The bytes are too short or not CDR.
    """
    r = CdrReader(data)
    _, first_index, _ = _read_block_head(r, header=False)
    return first_index, r.array_length()


def read_block(data: bytes, type_name: str = "rimd_msgs/msg/SampleBlock", arrays: int | None = None) -> BlockView:
    """Read a serialized SampleBlock or RigState up to its ``arrays`` first ``float64[]`` fields (default all).

    What the Rerun bridge reads its blocks with: unlike ``rclpy.serialization.deserialize_message``, it builds no
    message object and copies no sample.

    Raises:
        ValueError: Bytes too short for what the layout says, or not CDR.
    """
    names = BLOCK_ARRAYS[type_name]
    if arrays is not None:
        names = names[:arrays]
    try:
        return _read_block_fast(data, names)
    except (ValueError, IndexError, struct.error):
        pass   # bytes that do not fit the layout: read field by field below, which names what is wrong
    r = CdrReader(data)
    header, first_index, sample_rate = _read_block_head(r)
    assert header is not None   # read: header=True
    return BlockView(header, first_index, sample_rate, {name: r.f64_array() for name in names})


#: A block's leading fields by byte order: the stamp (int32 sec, uint32 nanosec) and frame_id's uint32 length.
_BLOCK_HEAD = {order: struct.Struct(order + "iiI") for order in "<>"}
#: ``first_index`` (uint64) and ``sample_rate`` (float64), 8-aligned after frame_id.
_INDEX_RATE = {order: struct.Struct(order + "Qd") for order in "<>"}


def _read_block_fast(data: bytes | bytearray | memoryview, names: tuple[str, ...]) -> BlockView:
    """:func:`read_block` in three unpacks and a view per array, for bytes that fit the layout.

    The same reads as :class:`CdrReader`'s, without a call per field (the Rerun bridge reads hundreds of blocks a
    second). Raises ValueError, IndexError or struct.error on bytes that do not fit; the caller then reads them
    field by field, whose errors say where.
    """
    order = "<" if data[1] & 1 else ">"
    size = len(data)
    sec, nanosec, length = _BLOCK_HEAD[order].unpack_from(data, 4)
    end = 16 + length   # absolute offset after frame_id and its NUL
    if end > size:
        raise ValueError("frame_id does not fit")
    frame_id = bytes(data[16:end - 1]).decode("utf-8", "replace") if length else ""
    pos = (12 + length + 7) & ~7
    first_index, sample_rate = _INDEX_RATE[order].unpack_from(data, 4 + pos)
    pos += 16
    count_of = _PRIMITIVES[order]["I"].unpack_from
    dtype = _F8[order]
    arrays = {}
    for name in names:
        (count,) = count_of(data, 4 + pos)
        pos += 4
        if count:
            pos = (pos + 7) & ~7
        if 4 + pos + 8 * count > size:
            raise ValueError("array does not fit")
        arrays[name] = np.frombuffer(data, dtype, count, 4 + pos)
        pos += 8 * count
    return BlockView(Header(Stamp(sec, nanosec), frame_id), first_index, sample_rate, arrays)


def samples_before(stamp_ns: int, sample_rate: float, count: int, end_ns: int) -> int:
    """How many of a block's ``count`` samples lie strictly before ``end_ns``.

    Sample ``n`` of a block is at ``stamp_ns + n / sample_rate`` (the block's grid, docs/interface.md), compared
    exactly (integer nanoseconds against the rate as the exact binary fraction it is), so a sample on ``end_ns``
    is not before it.
    """
    if end_ns <= stamp_ns or count <= 0:
        return 0
    if not (sample_rate > 0 and math.isfinite(sample_rate)):
        return count   # no grid to cut on: the block is before the end by its stamp
    kept = math.ceil(Fraction(end_ns - stamp_ns) * Fraction(sample_rate) / 1_000_000_000)
    return max(0, min(count, kept))


def cut_block(data: bytes, type_name: str, count: int) -> bytes:
    """A serialized SampleBlock or RigState cut to its first ``count`` samples, every other field as it was.

    The bytes up to the first array (the header, ``first_index``, ``sample_rate``) are kept as they are; each
    array is cut to ``count`` (RigState's ``bool[] in_contact`` too); a SampleBlock keeps its unit and range, and
    its ``saturated_count`` counts the kept samples at either end of the range (0 stays 0). ``count`` at or
    beyond the block's length gives the bytes unchanged.

    Raises:
        ValueError: The bytes are too short for what the layout says, or not CDR.
    """
    r = CdrReader(data)
    _read_block_head(r, header=False)
    head = r.pos
    if count >= r.array_length():
        return bytes(data)
    count = max(0, count)
    arrays = [r.f64_array() for _ in BLOCK_ARRAYS[type_name]]
    w = CdrWriter(r.order, at=head)
    for values in arrays:
        w.f64_array(values[:count])
    if type_name == "rimd_msgs/msg/SampleBlock":
        unit, low, high, saturated = r.string(), r.f64(), r.f64(), r.u32()
        kept = arrays[0][:count]
        w.string(unit).f64(low).f64(high).u32(int(np.count_nonzero((kept <= low) | (kept >= high)))
                                             if saturated else 0)
    else:   # RigState: bool[] in_contact, one byte per sample
        n = r.u32()
        flags = bytes(data[4 + r.pos:4 + r.pos + n])
        if len(flags) != n:
            raise ValueError(f"{n} bool values do not fit in {len(data)} bytes")
        flags = flags[:count]
        w.u32(len(flags))
        w.parts.append(flags)
        w.pos += len(flags)
    return bytes(data[:4 + head]) + w.body()


class SampleBlockEncoder:
    """Serializes ``rimd_msgs/msg/SampleBlock`` messages of one channel straight from NumPy.

    The fields that only change with the configuration (``frame_id``, ``sample_rate``, ``unit``, the range) are
    encoded once per :meth:`configure` with :class:`CdrWriter`, as are the alignments that follow from them;
    each block then costs a few ``struct.pack`` calls and one copy of the samples, against rclpy building a
    message object and converting it field by field. The bytes are those ``rclpy.serialization.serialize_message``
    gives (tested), and ``Publisher.publish`` sends them as they are. ``order`` ``">"`` encodes big-endian (what
    rclpy never sends, but other serializers may: the readers take both).
    """

    def __init__(self, frame_id: str, sample_rate: float, unit: str, range_min: float, range_max: float,
                 order: str = "<") -> None:
        self.order = order
        self.configure(frame_id, sample_rate, unit, range_min, range_max)

    def configure(self, frame_id: str, sample_rate: float, unit: str, range_min: float, range_max: float) -> None:
        """Set the fields that stay the same from block to block (the layout's leading fields, written once)."""
        head = CdrWriter(self.order).time(0, 0).string(frame_id)
        head.parts = head.parts[2:]   # the stamp changes per block: written in encode
        self._frame = head.body()
        self._index_at = _aligned(head.pos, 8)      # first_index, then sample_rate, then the samples' count
        self._pad_index = b"\0" * (self._index_at - head.pos)
        p = _PRIMITIVES[self.order]
        self._time, self._u64, self._u32 = _TIME[self.order], p["Q"], p["I"]
        self._rate = p["d"].pack(sample_rate)
        # After a non-empty samples array the position is 8-aligned: what follows up to the saturated count
        # (unit, range) is then the same bytes in every block. Refuses a NUL in the unit now, not at the first block.
        self._after = CdrWriter(self.order).string(unit).f64(range_min).f64(range_max).body()
        self._unit, self._range = unit, (range_min, range_max)

    def encode(self, sec: int, nanosec: int, first_index: int, samples: np.ndarray, saturated_count: int) -> bytes:
        """The serialized message of one block (``samples``: float64, any byte order)."""
        count = len(samples)
        if count:   # the samples' count, 4 bytes of padding, the samples, then the fields after them (8-aligned)
            return b"".join((ENCAPSULATION[self.order], self._time.pack(sec, nanosec), self._frame, self._pad_index,
                             self._u64.pack(first_index), self._rate, self._u32.pack(count), b"\0\0\0\0",
                             np.ascontiguousarray(samples, dtype=_F8[self.order]).tobytes(), self._after,
                             self._u32.pack(saturated_count)))
        tail = CdrWriter(self.order, at=self._index_at + 16)   # from the samples' count on
        tail.f64_array(samples).string(self._unit).f64(self._range[0]).f64(self._range[1]).u32(saturated_count)
        return b"".join((ENCAPSULATION[self.order], self._time.pack(sec, nanosec), self._frame, self._pad_index,
                         self._u64.pack(first_index), self._rate, tail.body()))
