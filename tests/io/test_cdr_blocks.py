"""The CDR fast paths of the rig's block messages against rclpy's own serialization.

Hypotheses:
* ``SampleBlockEncoder`` (the simulator publishes its channel blocks as these bytes) gives bytes that rclpy
  deserializes to exactly the message that rclpy would have serialized from the same fields, for any strings,
  sample counts (0 included), indices and values;
* ``read_block`` (the Rerun bridge reads the channel and truth blocks in place) reads from rclpy's bytes the
  header, ``first_index``, ``sample_rate`` and every ``float64[]`` field, bit for bit;
* bytes cut short are refused with ValueError, never read past their end;
* ``cut_block`` (the recorder cuts the block that straddles its ``stop_at``) gives the block rosbags serializes
  from the same fields with every array cut, byte for byte in either byte order (rclpy reads it back as that
  message), and ``samples_before`` counts the samples strictly before a stamp on the block's exact grid;
* the simulator's packed encoders of every block's truth and motor state give the bytes rosbags serializes from
  the same fields, for any values and truth lengths (0 included);
* both byte orders: what rosbags (an independent serializer, the one that writes big-endian CDR) writes either
  way reads back field for field (span, arrays, stamp, restamp), and the encoder writes each order byte for
  byte as rosbags does.
"""

from __future__ import annotations

import array
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message

from rimd_msgs.msg import RigState, SampleBlock
from rimd_sim.io.cdr import (
    BLOCK_ARRAYS,
    SampleBlockEncoder,
    block_span,
    cut_block,
    header_stamp,
    read_block,
    samples_before,
    with_header_stamp,
)

TEXT = st.text(st.characters(exclude_categories=("Cs",), exclude_characters="\0"), max_size=24)  # C strings, UTF-8
FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=64)
SAMPLES = st.lists(FLOATS, max_size=64).map(lambda xs: np.array(xs, dtype=np.float64))
SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _same(a: np.ndarray, b: array.array | np.ndarray) -> bool:
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


@SETTINGS
@given(frame=TEXT, unit=TEXT, samples=SAMPLES, first=st.integers(0, 2**64 - 1), sec=st.integers(0, 2**31 - 1),
       nanosec=st.integers(0, 999_999_999), rate=FLOATS, lo=FLOATS, hi=FLOATS, saturated=st.integers(0, 2**32 - 1))
def test_the_encoder_gives_what_rclpy_deserializes_to_the_same_message(frame, unit, samples, first, sec, nanosec,
                                                                       rate, lo, hi, saturated):
    encoded = SampleBlockEncoder(frame, rate, unit, lo, hi).encode(sec, nanosec, first, samples, saturated)
    msg = deserialize_message(encoded, SampleBlock)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id, msg.first_index, msg.unit,
            msg.saturated_count) == (sec, nanosec, frame, first, unit, saturated)
    assert _same(msg.samples, samples)
    assert _same([msg.sample_rate, msg.range_min, msg.range_max], [rate, lo, hi])
    assert block_span(encoded) == (first, samples.size)


@SETTINGS
@given(frame=TEXT, samples=SAMPLES, first=st.integers(0, 2**64 - 1), rate=FLOATS)
def test_read_block_reads_a_sample_block_as_rclpy_serialized_it(frame, samples, first, rate):
    msg = SampleBlock(first_index=first, sample_rate=rate, unit="N", samples=array.array("d", samples))
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1_795_420_000, 123
    view = read_block(serialize_message(msg))
    assert (view.header.stamp.sec, view.header.stamp.nanosec, view.header.frame_id, view.first_index) == (
        1_795_420_000, 123, frame, first)
    assert _same([view.sample_rate], [rate]) and _same(view.samples, samples)


@SETTINGS
@given(arrays=st.lists(SAMPLES, min_size=10, max_size=10), contact=st.lists(st.booleans(), max_size=8),
       frame=TEXT)
def test_read_block_reads_every_array_of_a_rig_state(arrays, contact, frame):
    names = BLOCK_ARRAYS["rimd_msgs/msg/RigState"]
    msg = RigState(first_index=42, sample_rate=1000.0, in_contact=contact)
    msg.header.frame_id = frame
    for name, values in zip(names, arrays, strict=True):
        setattr(msg, name, array.array("d", values))
    view = read_block(serialize_message(msg), "rimd_msgs/msg/RigState")
    assert view.first_index == 42 and view.sample_rate == 1000.0
    for name, values in zip(names, arrays, strict=True):
        assert _same(getattr(view, name), values), name


def test_a_string_holding_nul_is_refused_not_cut():
    # rclpy would publish "rimd\0laser" as "rimd": the encoder refuses it instead (and the config rule of
    # channels.<name>.frame_id refuses it before it gets there).
    with pytest.raises(ValueError, match="NUL"):
        SampleBlockEncoder("rimd\0laser", 2000.0, "m", -0.01, 0.01)
    with pytest.raises(ValueError, match="NUL"):
        SampleBlockEncoder("rimd_laser", 2000.0, "m\0", -0.01, 0.01).encode(1, 2, 3, np.arange(2.0), 0)


def test_bytes_cut_short_are_refused():
    data = SampleBlockEncoder("cart_laser", 2000.0, "m", -0.01, 0.01).encode(1, 2, 3, np.arange(20.0), 0)
    assert read_block(data).samples.size == 20
    for cut in (0, 3, 10, 30, 40, 100, 150):
        with pytest.raises(ValueError):
            read_block(data[:cut])


# ---- both byte orders, against an independent serializer (rosbags can write big-endian CDR) --------------------

def _rosbags_typestore():
    from pathlib import Path

    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    msg_dir = Path(__file__).resolve().parents[2] / "rimd_msgs" / "msg"
    types = {}
    for name in ("SampleBlock", "RigState", "MotorState"):
        types.update(get_types_from_msg((msg_dir / f"{name}.msg").read_text(), f"rimd_msgs/msg/{name}"))
    store.register(types)
    return store


STORE = _rosbags_typestore()


def _rosbags_block(kind: str, frame: str, first: int, rate: float, arrays: dict, sec: int, nanosec: int):
    Time, Header = STORE.types["builtin_interfaces/msg/Time"], STORE.types["std_msgs/msg/Header"]
    cls = STORE.types[kind]
    header = Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame)
    if kind.endswith("SampleBlock"):
        return cls(header=header, first_index=first, sample_rate=rate, samples=arrays["samples"], unit="N",
                   range_min=-1.0, range_max=1.0, saturated_count=3)
    return cls(header=header, first_index=first, sample_rate=rate, **arrays,
               in_contact=np.zeros(arrays["theta"].size, dtype=np.bool_))


@SETTINGS
@given(frame=TEXT, first=st.integers(0, 2**64 - 1), rate=FLOATS, sec=st.integers(0, 2**31 - 1),
       nanosec=st.integers(0, 999_999_999), sizes=st.lists(st.integers(0, 9), min_size=10, max_size=10),
       little=st.booleans(), rig_state=st.booleans())
def test_both_byte_orders_read_as_rosbags_wrote_them(frame, first, rate, sec, nanosec, sizes, little, rig_state):
    kind = "rimd_msgs/msg/RigState" if rig_state else "rimd_msgs/msg/SampleBlock"
    names = BLOCK_ARRAYS[kind]
    arrays = {name: np.arange(n, dtype=np.float64) * (i + 1.5) for i, (name, n) in enumerate(zip(names, sizes,
                                                                                                strict=False))}
    data = bytes(STORE.serialize_cdr(_rosbags_block(kind, frame, first, rate, arrays, sec, nanosec), kind,
                                     little_endian=little))
    assert data[1] == (1 if little else 0)
    assert block_span(data) == (first, arrays[names[0]].size)
    view = read_block(data, kind)
    assert (view.header.stamp.sec, view.header.stamp.nanosec, view.header.frame_id, view.first_index) == (
        sec, nanosec, frame, first)
    assert _same([view.sample_rate], [rate])
    for name in names:
        assert _same(getattr(view, name), arrays[name]), name
    stamp = sec * 1_000_000_000 + nanosec
    assert header_stamp(data) == stamp
    if (stamp + 1_500_000_001) // 1_000_000_000 >= 2**31:   # past what a Time holds: refused by name, never wrapped
        with pytest.raises(ValueError, match="builtin_interfaces/Time holds seconds"):
            with_header_stamp(data, stamp + 1_500_000_001)
        return
    moved = with_header_stamp(data, stamp + 1_500_000_001)
    assert header_stamp(moved) == stamp + 1_500_000_001 and len(moved) == len(data)
    again = STORE.deserialize_cdr(moved, kind)
    assert (again.header.stamp.sec, again.header.stamp.nanosec) == divmod(stamp + 1_500_000_001, 1_000_000_000)


@SETTINGS
@given(frame=TEXT, samples=SAMPLES, first=st.integers(0, 2**64 - 1), sec=st.integers(0, 2**31 - 1),
       nanosec=st.integers(0, 999_999_999))
def test_the_encoder_writes_each_byte_order_as_rosbags_does(frame, samples, first, sec, nanosec):
    for order, little in (("<", True), (">", False)):
        ours = SampleBlockEncoder(frame, 20000.0, "N", -1.0, 1.0, order=order).encode(sec, nanosec, first, samples, 3)
        theirs = bytes(STORE.serialize_cdr(_rosbags_block("rimd_msgs/msg/SampleBlock", frame, first, 20000.0,
                                                          {"samples": samples}, sec, nanosec),
                                           "rimd_msgs/msg/SampleBlock", little_endian=little))
        assert ours == theirs, order


@SETTINGS
@given(consumer=TEXT, instance=TEXT, done=st.integers(0, 2**31 * 10**9 - 1), leaving=st.booleans(),
       topics=st.dictionaries(TEXT, st.integers(0, 2**31 * 10**9 - 1), max_size=6), node=TEXT,
       controls=st.booleans(), commands=st.integers(0, 2**32 - 1))
def test_progress_reports_encode_as_rclpy_serializes_them(consumer, instance, done, leaving, topics, node, controls,
                                                          commands):
    """The lockstep reporter publishes its ConsumerProgress as bytes it encodes itself: what rclpy reads back as
    the message, in rclpy's layout."""
    from builtin_interfaces.msg import Time

    from rimd_msgs.msg import ConsumerProgress
    from rimd_sim.ros.clients.progress import encode_progress

    names = sorted(topics)
    reference = ConsumerProgress(consumer=consumer, instance=instance, leaving=leaving, topics=names, node=node,
                                 controls=controls, commands=commands,
                                 topics_done_through=[Time(sec=topics[t] // 10**9, nanosec=topics[t] % 10**9)
                                                      for t in names])
    overall = min(topics.values()) if topics else done
    reference.done_through = Time(sec=overall // 10**9, nanosec=overall % 10**9)
    ours = encode_progress(consumer, done, instance, topics, leaving, node, controls, commands)
    # rclpy leaves its alignment padding uninitialised (stray bytes there), so compare what the bytes mean, and
    # the length: the same layout.
    assert deserialize_message(ours, ConsumerProgress) == reference
    assert len(ours) == len(serialize_message(reference))


@SETTINGS
@given(frame=TEXT, first=st.integers(0, 2**64 - 1), size=st.integers(0, 12), keep=st.integers(-1, 14),
       little=st.booleans(), rig_state=st.booleans(), sec=st.integers(0, 2**31 - 1))
def test_a_cut_block_is_the_block_of_its_first_samples(frame, first, size, keep, little, rig_state, sec):
    kind = "rimd_msgs/msg/RigState" if rig_state else "rimd_msgs/msg/SampleBlock"
    names = BLOCK_ARRAYS[kind]
    # samples 0, 1, ... scaled: the range ends -1 and 1 clip the first two (saturated_count 3 in the original)
    arrays = {name: np.arange(size, dtype=np.float64) * (i + 1.5) - 1.0 for i, name in enumerate(names)}
    data = bytes(STORE.serialize_cdr(_rosbags_block(kind, frame, first, 2000.0, arrays, sec, 7), kind,
                                     little_endian=little))
    cut = cut_block(data, kind, keep)
    if keep >= size:
        assert cut == data
        return
    n = max(keep, 0)
    expected = _rosbags_block(kind, frame, first, 2000.0, {k: v[:n] for k, v in arrays.items()}, sec, 7)
    if not rig_state:   # the kept samples at an end of the range [-1, 1]: -1.0 (sample 0) and 1.0 (sample 2)
        expected.saturated_count = int(np.count_nonzero((arrays["samples"][:n] <= -1.0)
                                                        | (arrays["samples"][:n] >= 1.0)))
    assert cut == bytes(STORE.serialize_cdr(expected, kind, little_endian=little))
    if little:
        msg = deserialize_message(cut, RigState if rig_state else SampleBlock)
        assert msg.first_index == first and msg.header.frame_id == frame
        assert all(_same(getattr(msg, name), arrays[name][:n]) for name in names)


def test_samples_before_counts_on_the_exact_grid():
    # 20 kHz from stamp 1 s: sample n at 1 s + n * 50 us; a sample on the end is not before it
    assert samples_before(10**9, 20000.0, 200, 10**9 + 50_000 * 120) == 120
    assert samples_before(10**9, 20000.0, 200, 10**9 + 50_000 * 120 + 1) == 121
    assert samples_before(10**9, 20000.0, 200, 10**9 + 1) == 1
    assert samples_before(10**9, 20000.0, 200, 10**9) == 0
    assert samples_before(10**9, 20000.0, 200, 2 * 10**9) == 200
    assert samples_before(10**9, 3.0, 5, 10**9 + 666_666_667) == 3   # 2/3 s lies before ...667 ns, not on it
    assert samples_before(10**9, 3.0, 5, 10**9 + 666_666_666) == 2


@SETTINGS
@given(first=st.integers(0, 2**64 - 1), rate=FLOATS, stamp=st.integers(0, 2**31 * 10**9 - 1),
       size=st.integers(0, 40), seed=st.integers(0, 2**32 - 1), motor=st.lists(FLOATS, min_size=5, max_size=5),
       cycle=st.integers(-3, 2**63 - 1))
def test_the_truth_and_motor_encoders_give_what_rosbags_serializes(first, rate, stamp, size, seed, motor, cycle):
    from types import SimpleNamespace

    from rimd_sim.io.cdr_write import TRUTH_ARRAY_FIELDS, encode_motor, encode_truth

    rng = np.random.default_rng(seed)
    rows = rng.normal(size=(len(TRUTH_ARRAY_FIELDS) + 1, size))
    rows[-1] = rng.integers(0, 2, size)   # in_contact
    sec, nanosec = divmod(stamp, 1_000_000_000)
    Time, Header = STORE.types["builtin_interfaces/msg/Time"], STORE.types["std_msgs/msg/Header"]
    truth = STORE.types["rimd_msgs/msg/RigState"](
        header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id="truth"), first_index=first, sample_rate=rate,
        **{name: rows[i] for i, name in enumerate(TRUTH_ARRAY_FIELDS)}, in_contact=rows[-1] != 0.0)
    assert encode_truth(stamp, first, rate, rows) == bytes(STORE.serialize_cdr(truth, "rimd_msgs/msg/RigState"))
    m = SimpleNamespace(frequency_setpoint=motor[0], frequency=motor[1], phase=motor[2], cycle_index=cycle,
                        ramp_rate=motor[3], cart_position=motor[4])
    state = STORE.types["rimd_msgs/msg/MotorState"](
        header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id="motor"), frequency_setpoint=motor[0],
        frequency=motor[1], phase=motor[2], cycle_index=max(cycle, 0), ramp_rate=motor[3], cart_position=motor[4])
    assert encode_motor(stamp, m) == bytes(STORE.serialize_cdr(state, "rimd_msgs/msg/MotorState"))


@SETTINGS
@given(frame=TEXT, sizes=st.lists(st.integers(0, 6), min_size=10, max_size=10), little=st.booleans(),
       rig_state=st.booleans())
def test_the_fast_block_reader_reads_what_the_field_reader_reads_and_refuses_what_it_refuses(frame, sizes, little,
                                                                                            rig_state):
    # read_block takes a path of three unpacks for bytes that fit the layout, else reads field by field (whose
    # errors say where): for every prefix of a message, both refuse it or both read the same fields.
    from rimd_sim.io.cdr import CdrReader, _read_block_fast, _read_block_head

    kind = "rimd_msgs/msg/RigState" if rig_state else "rimd_msgs/msg/SampleBlock"
    names = BLOCK_ARRAYS[kind]
    arrays = {name: np.arange(n, dtype=np.float64) - i for i, (name, n) in enumerate(zip(names, sizes, strict=False))}
    data = bytes(STORE.serialize_cdr(_rosbags_block(kind, frame, 7, 20_000.0, arrays, 12, 34), kind,
                                     little_endian=little))
    for cut in range(len(data) + 1):
        part = data[:cut]
        try:
            r = CdrReader(part)
            header, first, rate = _read_block_head(r)
            fields = {name: r.f64_array() for name in names}
        except ValueError:
            with pytest.raises((ValueError, IndexError, struct.error)):
                _read_block_fast(part, names)
            with pytest.raises(ValueError):
                read_block(part, kind)
            continue
        view = _read_block_fast(part, names)
        assert (view.header.stamp.sec, view.header.stamp.nanosec, view.header.frame_id, view.first_index,
                view.sample_rate) == (header.stamp.sec, header.stamp.nanosec, header.frame_id, first, rate)
        for name in names:
            assert _same(getattr(view, name), fields[name]), name
