"""The serialized messages the rig publishes besides its sample blocks, written straight from the core's values.

Each ``encode_*`` function returns the little-endian CDR bytes of one message (the encapsulation header, then the
body), the bytes ``rclpy.serialization.serialize_message`` gives for the same fields (tests/io/test_cdr_blocks.py,
tests/runtime/test_simulator_runtime.py), so a publisher sends them as they are. The values come as the core
hands them (duck-typed: a motor state, an impact, a fault event, a capture), stamps as integer nanoseconds. The
sample blocks' encoder, :class:`rimd_sim.io.cdr.SampleBlockEncoder`, stands beside the block layout it shares with
the readers in :mod:`rimd_sim.io.cdr`.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

from rimd_sim.io.cdr import BLOCK_ARRAYS, ENCAPSULATION, CdrWriter

__all__ = ["TRUTH_ARRAY_FIELDS", "encode_capture", "encode_clock", "encode_fault", "encode_impact", "encode_motor",
           "encode_session", "encode_truth"]

#: RigState's ``float64[]`` fields, in the order of the core's truth rows (the 11th row, in_contact, is bool[]).
TRUTH_ARRAY_FIELDS = BLOCK_ARRAYS["rimd_msgs/msg/RigState"]


def _header(w: CdrWriter, stamp: int, frame_id: str) -> CdrWriter:
    """``std_msgs/Header``."""
    sec, nanosec = divmod(stamp, 1_000_000_000)
    return w.time(sec, nanosec).string(frame_id)


def _bools(w: CdrWriter, values: np.ndarray) -> CdrWriter:
    """``bool[]`` (one byte each)."""
    w.u32(int(values.size))
    w.parts.append(values.astype(np.uint8).tobytes())
    w.pos += int(values.size)
    return w


def _frame(frame_id: str) -> bytes:
    """A header's ``frame_id`` as it follows the 8-byte stamp, padded so that an 8-byte field comes next."""
    w = CdrWriter(at=8).string(frame_id)
    w.f64(0.0)
    return w.body()[:-8]


# Each block sends a motor state and a truth block: their layouts are fixed, so they are packed at once rather
# than field by field (the bytes rosbags serializes from the same fields: tests/io/test_cdr_blocks.py).
_STAMP, _U32 = struct.Struct("<iI"), struct.Struct("<I")
_MOTOR_FRAME, _MOTOR = _frame("motor"), struct.Struct("<dddQdd")
_TRUTH_FRAME, _TRUTH_HEAD = _frame("truth"), struct.Struct("<Qd")
_ENCAPSULATION = ENCAPSULATION["<"]


def encode_motor(stamp: int, m: Any) -> bytes:
    """``rimd_msgs/msg/MotorState`` of the core's motor state ``m``."""
    return b"".join((_ENCAPSULATION, _STAMP.pack(*divmod(stamp, 1_000_000_000)), _MOTOR_FRAME,
                     _MOTOR.pack(m.frequency_setpoint, m.frequency, m.phase, max(m.cycle_index, 0), m.ramp_rate,
                                 m.cart_position)))


def encode_truth(stamp: int, first_index: int, sample_rate: float, rows: np.ndarray) -> bytes:
    """``rimd_msgs/msg/RigState`` of the core's truth rows (10 float rows, then in_contact)."""
    k, n = len(TRUTH_ARRAY_FIELDS), rows.shape[1]
    if n == 0:
        w = _header(CdrWriter(), stamp, "truth").u64(first_index).f64(sample_rate)
        for i in range(k):
            w.f64_array(rows[i])
        return _bools(w, rows[k] != 0.0).message()
    # From the 8-aligned first array on, each float64[] is its count, 4 bytes of padding and its values: one
    # row of n + 1 float64 slots whose first slot holds the count and the padding.
    arrays = np.empty((k, n + 1), dtype="<f8")
    arrays[:, 1:] = rows[:k]
    head = arrays.view(np.uint32)
    head[:, 0], head[:, 1] = n, 0
    return b"".join((_ENCAPSULATION, _STAMP.pack(*divmod(stamp, 1_000_000_000)), _TRUTH_FRAME,
                     _TRUTH_HEAD.pack(first_index, sample_rate), arrays.tobytes(), _U32.pack(n),
                     (rows[k] != 0.0).astype(np.uint8).tobytes()))


def encode_impact(stamp: int, imp: Any) -> bytes:
    """``rimd_msgs/msg/ImpactEvent`` of one impact."""
    w = _header(CdrWriter(), stamp, "impact_force_sensor")
    for value in (imp.duration, imp.peak_force, imp.impulse, imp.impact_velocity, imp.max_penetration,
                  imp.excitation_frequency, imp.excitation_phase):
        w.f64(value)
    return w.u64(imp.cycle_index).u64(imp.index).message()


def encode_fault(stamp: int, frame_id: str, event: Any) -> bytes:
    """``rimd_msgs/msg/FaultEvent`` of a fault's start or end."""
    spec = event.fault
    w = _header(CdrWriter(), stamp, frame_id).string(event.event).u32(spec.number).string(spec.channel)
    w.string(spec.kind).f64(float(spec.start)).f64(float(spec.duration)).f64(spec.magnitude)
    return w.string(event.detail).message()


def encode_capture(stamp: int, frame_id: str, unit: str, cap: Any, values: np.ndarray) -> bytes:
    """``rimd_msgs/msg/Capture`` of one triggered capture's channel."""
    w = _header(CdrWriter(), stamp, frame_id).u32(cap.number).f64(cap.sample_rate).u32(cap.pre_trigger_samples)
    return w.f64_array(values).string(unit).f64(cap.threshold).message()


def encode_clock(stamp: int) -> bytes:
    """``rosgraph_msgs/msg/Clock``."""
    return CdrWriter().time(*divmod(stamp, 1_000_000_000)).message()


def encode_session(s: Any, frame_id: str) -> bytes:
    """``rimd_msgs/msg/RigSession`` of a run's identity ``s``, its header stamped at the run's start stamp.

    ``s`` has the message's fields: ``run_id``, ``reason``, ``sequence``, ``start_stamp`` (ns),
    ``simulation_time``, ``time_base``, ``real_time_factor``, ``lockstep``, ``seed``, ``config_hash``, ``node``.
    """
    w = _header(CdrWriter(), s.start_stamp, frame_id).string(s.run_id).string(s.reason)
    w.u32(s.sequence).time(*divmod(s.start_stamp, 1_000_000_000)).f64(s.simulation_time)
    w.string(s.time_base).f64(s.real_time_factor).boolean(s.lockstep).u64(s.seed)
    return w.string(s.config_hash).string(s.node).message()
