"""The serialized ``rimd_msgs/msg/ConsumerProgress``, written with the standard library only.

A consumer's progress reporter (:mod:`rimd_sim.ros.clients.progress`) is what a user's DAQ node imports, and it
loads rclpy, ``rimd_msgs`` and the standard library only (tests/ros/test_progress_lean.py): this module therefore
writes the few field kinds of the message with :mod:`struct` rather than with :class:`rimd_sim.io.cdr.CdrWriter`,
which needs NumPy. The bytes are the writer's for the same fields (tests/ros/test_progress_lean.py) and rclpy's
(tests/io/test_cdr_blocks.py).
"""

from __future__ import annotations

import struct

__all__ = ["encode_progress"]

#: CDR's encapsulation header of a little-endian message (what ROS 2 publishes).
_CDR_LE = b"\0\x01\0\0"
_U32 = struct.Struct("<I")
_TIME = struct.Struct("<iI")   # builtin_interfaces/Time: int32 sec, uint32 nanosec (4-byte aligned, no padding)


class _Cdr:
    """The little-endian CDR of ConsumerProgress's field kinds, each aligned to its size from the body's start."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.pos = 0

    def _put(self, data: bytes, align: int) -> None:
        pad = -self.pos % align
        if pad:
            self.parts.append(b"\0" * pad)
        self.parts.append(data)
        self.pos += pad + len(data)

    def u32(self, value: int) -> None:
        self._put(_U32.pack(value), 4)

    def string(self, text: str) -> None:
        if "\0" in text:   # a ROS 2 string is a C string: every reader would cut it there
            raise ValueError(f"a ROS 2 string cannot hold a NUL character: {text!r}")
        raw = text.encode("utf-8") + b"\0"
        self.u32(len(raw))
        self._put(raw, 1)

    def boolean(self, value: bool) -> None:
        self._put(b"\1" if value else b"\0", 1)

    def time(self, ns: int) -> None:
        self._put(_TIME.pack(*divmod(ns, 1_000_000_000)), 4)

    def message(self) -> bytes:
        return _CDR_LE + b"".join(self.parts)


def encode_progress(consumer: str, done_ns: int, instance: str, topics: dict[str, int] | None = None,
                    leaving: bool = False, node: str = "", controls: bool = False, commands: int = 0) -> bytes:
    """A serialized ``rimd_msgs/msg/ConsumerProgress`` (what ``serialize_message`` gives, tested), for a raw publish.

    A consumer reports up to a few hundred times a second: writing the bytes directly spares rclpy's conversion
    of the message object, its arrays of Time above all. ``topics``: topic -> done through (ns), written sorted by
    topic; the overall ``done_through`` is then their minimum, else ``done_ns``.

    Raises:
        ValueError: A string holds a NUL character.
    """
    per_topic = dict(topics) if topics else {}
    names = sorted(per_topic)
    w = _Cdr()
    w.string(consumer)
    w.time(min(per_topic.values()) if per_topic else done_ns)
    w.u32(len(names))
    for name in names:
        w.string(name)
    w.u32(len(names))
    for name in names:
        w.time(per_topic[name])
    w.string(instance)
    w.boolean(leaving)
    w.string(node)
    w.boolean(controls)
    w.u32(commands)
    return w.message()
