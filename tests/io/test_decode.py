"""The one decoder of recorded messages (``rimd_sim.io.decode``) against rclpy, rosbags and a process without ROS.

Hypotheses:
* every message type of the rig's recordings and services (every ``rimd_msgs`` message, both halves of every
  ``rimd_msgs`` service, the standard types the recorder records) and a set of standard types chosen for their
  layouts (fixed arrays, bounded sequences, ``byte``/``char``, 1-, 2- and 4-byte fields before 8-byte ones)
  decodes, from its installed ``.msg`` definition, to what rclpy deserializes from rclpy's own bytes, field by
  field and bit for bit: random values (unicode strings, NaN, extreme integers, empty and non-empty arrays),
  every field at its default, and strings of every length before 8-byte fields;
* big-endian bytes (rosbags writes them; rclpy never does) decode to the same values as the little-endian ones;
* arrays of numbers are NumPy views over the message's bytes (no copy, no per-element Python);
* bytes cut short, or a length past their end, raise ValueError, never another error and never a wrong message;
* a real recording (the recorder's writer, and the physics core's file) decodes, from the definitions the file
  carries, to what rosbags' deserializer gives for the same bytes;
* ``rimd analyze`` and ``rimd rerun`` read a recording in a process where rclpy and every ROS message package
  are unimportable and no ``.msg`` file of ``rimd_msgs`` can be found.
"""

from __future__ import annotations

import importlib
import json
import os
import random
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message

from rimd_sim.io.decode import (
    SEQUENCE,
    Field,
    installed_definition,
    message_decoder,
    parse_definition,
    topic_decoder,
)
from rimd_sim.io.msgdefs import MessageDefinitionError, message_definition

ROOT = Path(__file__).resolve().parents[2]
RIMD_MESSAGES = sorted(f"rimd_msgs/msg/{p.stem}" for p in (ROOT / "rimd_msgs" / "msg").glob("*.msg"))
RIMD_SERVICES = sorted(f"rimd_msgs/srv/{p.stem}_{part}" for p in (ROOT / "rimd_msgs" / "srv").glob("*.srv")
                       for part in ("Request", "Response"))
#: What the recorder records besides the rig's own types (/diagnostics, /clock) and what the rig's nodes use.
RECORDED_STANDARD = ["diagnostic_msgs/msg/DiagnosticArray", "rosgraph_msgs/msg/Clock", "std_msgs/msg/Header",
                     "builtin_interfaces/msg/Time", "std_msgs/msg/UInt32", "std_srvs/srv/Trigger_Request",
                     "std_srvs/srv/Trigger_Response", "rcl_interfaces/msg/ParameterEvent"]
#: Standard types for their layouts: fixed arrays (float64[36], uint8[16]), bounded sequences of messages, a uint8
#: and an int32 before an int64, float32 and int16 arrays, byte arrays, bounded strings, deep nesting.
LAYOUTS = ["service_msgs/msg/ServiceEventInfo", "geometry_msgs/msg/PoseWithCovarianceStamped",
           "geometry_msgs/msg/PolygonStamped", "rcl_interfaces/msg/ParameterDescriptor", "rcl_interfaces/msg/Log",
           "std_msgs/msg/Float64MultiArray", "std_msgs/msg/Int16MultiArray", "std_msgs/msg/ByteMultiArray",
           "std_msgs/msg/Int8MultiArray", "type_description_interfaces/msg/TypeDescription",
           "unique_identifier_msgs/msg/UUID", "builtin_interfaces/msg/Duration", "std_msgs/msg/Empty"]
TYPES = RIMD_MESSAGES + RIMD_SERVICES + RECORDED_STANDARD + LAYOUTS

NUMBERS = {"bool": None, "byte": (0, 255), "char": (0, 255), "uint8": (0, 255), "int8": (-2**7, 2**7 - 1),
           "int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1), "int32": (-2**31, 2**31 - 1),
           "uint32": (0, 2**32 - 1), "int64": (-2**63, 2**63 - 1), "uint64": (0, 2**64 - 1), "float32": None,
           "float64": None}
DTYPES = {"bool": "?", "byte": "u1", "char": "u1", "uint8": "u1", "int8": "i1", "int16": "i2", "uint16": "u2",
          "int32": "i4", "uint32": "u4", "int64": "i8", "uint64": "u8", "float32": "f4", "float64": "f8"}
SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def specs_of(type_name: str) -> dict[str, tuple[Field, ...]]:
    """The fields of the type and its dependencies, from the installed definition (as the decoder reads it)."""
    return parse_definition(type_name, installed_definition(type_name))


def rclpy_class(type_name: str) -> type:
    pkg, kind, name = type_name.split("/")
    module = importlib.import_module(f"{pkg}.{kind}")
    if kind == "srv":
        service, part = name.rsplit("_", 1)
        return getattr(getattr(module, service), part)
    return getattr(module, name)


# ---- random messages, built field by field from the definition -------------------------------------------------

class Draws:
    """Values for a message's fields, from hypothesis (``data``) or a seeded generator (``rng``)."""

    TEXT = st.text(st.characters(exclude_categories=("Cs",), exclude_characters="\0"), max_size=12)

    def __init__(self, data=None, rng: random.Random | None = None) -> None:  # noqa: ANN001
        self.data, self.rng = data, rng

    def count(self, most: int) -> int:
        return self.data.draw(st.integers(0, most)) if self.data else self.rng.randint(0, most)

    def number(self, kind: str):  # noqa: ANN201
        if kind == "bool":
            return self.data.draw(st.booleans()) if self.data else self.rng.random() < 0.5
        if kind in ("float32", "float64"):
            if self.data:
                return self.data.draw(st.floats(width=32 if kind == "float32" else 64))
            big = -3.4028234663852886e38 if kind == "float32" else -2.25e300
            value = self.rng.choice([0.0, -0.0, 1.5, big, float("inf"), float("nan"), self.rng.gauss(0, 1e3)])
            return struct.unpack("<f", struct.pack("<f", value))[0] if kind == "float32" else value
        lo, hi = NUMBERS[kind]
        if self.data:
            return self.data.draw(st.integers(lo, hi))
        return self.rng.choice([lo, hi, 0, self.rng.randint(lo, hi)])

    def text(self, bound: int | None) -> str:
        most = 12 if bound is None else min(12, bound // 4)   # a bound counts bytes: 4 per character at most
        if self.data:
            return self.data.draw(self.TEXT.filter(lambda s: len(s) <= most))
        return "".join(self.rng.choice("aé€😀 z_") for _ in range(self.rng.randint(0, most)))


def scalar(draws: Draws, f: Field):  # noqa: ANN201
    if f.type == "string":
        return draws.text(f.string_bound)
    value = draws.number(f.type)
    return bytes([value]) if f.type == "byte" else value


def fill(msg, specs: dict[str, tuple[Field, ...]], type_name: str, draws: Draws):  # noqa: ANN001, ANN201
    """Set every field of the rclpy message ``msg`` (of ``type_name``) to drawn values; return it."""
    for f in specs[type_name]:
        nested = f.type in specs
        if f.array is None:
            if nested:
                fill(getattr(msg, f.name), specs, f.type, draws)
            else:
                setattr(msg, f.name, scalar(draws, f))
            continue
        n = f.array if f.array != SEQUENCE else draws.count(min(2 if nested else 6, f.bound or 99))
        if nested:
            setattr(msg, f.name, [fill(rclpy_class(f.type)(), specs, f.type, draws) for _ in range(n)])
        else:
            setattr(msg, f.name, [scalar(draws, f) for _ in range(n)])
    return msg


# ---- field-by-field comparison -----------------------------------------------------------------------------------

def _bits(value: float) -> bytes:
    return struct.pack("<d", value)


def assert_same(mine, theirs, specs: dict[str, tuple[Field, ...]], type_name: str, where: str = "") -> None:  # noqa: ANN001
    """``mine`` (our decoder's) holds, field by field and bit for bit, what ``theirs`` (rclpy's or rosbags') does."""
    fields = specs[type_name]
    assert type(mine).__msgtype__ == type_name, where
    assert list(type(mine).__dataclass_fields__) == [f.name for f in fields], where
    for f in fields:
        a, b, at = getattr(mine, f.name), getattr(theirs, f.name), f"{where}.{f.name}"
        if f.type in specs:
            if f.array is None:
                assert_same(a, b, specs, f.type, at)
            else:
                assert isinstance(a, list) and len(a) == len(b), at
                for i, (x, y) in enumerate(zip(a, b, strict=True)):
                    assert_same(x, y, specs, f.type, f"{at}[{i}]")
        elif f.type == "string":
            assert a == (list(b) if f.array is not None else b), at
            assert all(type(s) is str for s in a) if f.array is not None else type(a) is str, at
        elif f.array is not None:
            native = np.dtype(DTYPES[f.type])
            assert isinstance(a, np.ndarray) and a.dtype.kind == native.kind and a.itemsize == native.itemsize, at
            if f.type == "byte":
                # rclpy: a list of one-byte bytes; rosbags: int8 values
                b = np.frombuffer(b"".join(b), np.uint8) if not isinstance(b, np.ndarray) else b.view(np.uint8)
            assert np.asarray(a, native).tobytes() == np.asarray(b, native).tobytes(), at
            if f.array != SEQUENCE:
                assert a.size == f.array, at
        elif f.type in ("float32", "float64"):
            assert type(a) is float and _bits(a) == _bits(b), at
        elif f.type == "bool":
            assert type(a) is bool and a == bool(b), at
        elif f.type == "byte":     # ROS 2's octet, 0 to 255: rclpy gives a one-byte bytes, rosbags an int8
            assert type(a) is int and a == (b[0] if isinstance(b, bytes) else b & 0xFF), at
        else:
            assert type(a) is int and a == b, at


# ---- every type against rclpy ------------------------------------------------------------------------------------

def test_the_types_cover_every_rig_message_and_service():
    assert len(RIMD_MESSAGES) == 9 and len(RIMD_SERVICES) == 20
    assert {"rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState", "rimd_msgs/srv/GetRate_Request"} <= set(TYPES)


@pytest.mark.parametrize("type_name", TYPES)
@SETTINGS
@given(data=st.data())
def test_rclpy_bytes_decode_to_what_rclpy_deserializes(type_name, data):
    specs = specs_of(type_name)
    cls = rclpy_class(type_name)
    raw = serialize_message(fill(cls(), specs, type_name, Draws(data)))
    mine = message_decoder(type_name)(raw)
    assert_same(mine, deserialize_message(raw, cls), specs, type_name)
    assert list(type(mine).__dataclass_fields__) == list(cls.get_fields_and_field_types())


@pytest.mark.parametrize("type_name", TYPES)
def test_every_field_at_its_default_decodes(type_name):
    """Empty strings, empty sequences, zeros; a message without fields is its one placeholder byte."""
    specs = specs_of(type_name)
    cls = rclpy_class(type_name)
    raw = serialize_message(cls())
    assert_same(message_decoder(type_name)(raw), deserialize_message(raw, cls), specs, type_name)


@pytest.mark.parametrize("type_name", ["rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/Capture", "rimd_msgs/msg/RigState",
                                       "rimd_msgs/msg/FaultEvent", "rimd_msgs/msg/RigSession"])
def test_strings_of_every_length_before_eight_byte_fields(type_name):
    """Each string length moves the next 8-byte field's padding: 0 to 7 bytes of it, each with empty arrays too."""
    specs = specs_of(type_name)
    cls = rclpy_class(type_name)
    strings = [f for f in specs[type_name] if f.type == "string" and f.array is None]
    arrays = [f for f in specs[type_name] if f.array == SEQUENCE]
    decode = message_decoder(type_name)
    for length in range(10):
        for n in (0, 1, 2):
            msg = cls()
            msg.header.frame_id = "é" * (length // 2) + "x" * (length % 2)    # UTF-8: 2 bytes per é
            for f in strings:
                setattr(msg, f.name, "ü" * (length // 2) + "y" * (length % 2))
            for f in arrays:
                setattr(msg, f.name, [float(k) + 0.5 for k in range(n)] if f.type == "float64" else [True] * n)
            for f in specs[type_name]:
                if f.type == "float64" and f.array is None:
                    setattr(msg, f.name, -1.25e-7)
            raw = serialize_message(msg)
            mine = decode(raw)
            assert_same(mine, deserialize_message(raw, cls), specs, type_name, f"length {length}, {n} elements")
            assert mine.header.frame_id == msg.header.frame_id


def test_unicode_strings_and_string_arrays():
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from rimd_msgs.msg import ConsumerProgress

    text = "naïve 😀 ∞ Ω — 日本語"
    msg = DiagnosticArray(status=[DiagnosticStatus(level=b"\x02", name=text, message="", hardware_id="ħ",
                                                   values=[KeyValue(key=text, value="ß" * 300)])])
    got = message_decoder("diagnostic_msgs/msg/DiagnosticArray")(serialize_message(msg))
    assert (got.status[0].name, got.status[0].level, got.status[0].hardware_id) == (text, 2, "ħ")
    assert (got.status[0].values[0].key, got.status[0].values[0].value) == (text, "ß" * 300)
    progress = ConsumerProgress(consumer=text, topics=["", text, "/rig/impact/force"], instance="é", node="/n")
    got = message_decoder("rimd_msgs/msg/ConsumerProgress")(serialize_message(progress))
    assert got.topics == ["", text, "/rig/impact/force"] and got.consumer == text and got.topics_done_through == []


def test_number_arrays_are_views_over_the_bytes():
    from rimd_msgs.msg import RigState, SampleBlock

    raw = serialize_message(SampleBlock(samples=[1.0, 2.0, 3.0], unit="N"))
    samples = message_decoder("rimd_msgs/msg/SampleBlock")(raw).samples
    assert samples.base is raw and not samples.flags.writeable and samples.dtype == np.dtype("<f8")
    assert samples.tolist() == [1.0, 2.0, 3.0]
    raw = serialize_message(RigState(theta=[0.5], in_contact=[True, False, True]))
    state = message_decoder("rimd_msgs/msg/RigState")(raw)
    assert state.theta.base is raw and state.in_contact.base is raw
    assert state.in_contact.dtype == np.bool_ and state.in_contact.tolist() == [True, False, True]
    assert state.motor_phase.size == 0


# ---- big-endian bytes (rosbags writes them) -----------------------------------------------------------------------

def _rosbags_store(type_name: str):  # noqa: ANN202
    """A rosbags typestore holding the type (under a msg name: rosbags renames service halves), and that name."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    name = type_name.replace("/srv/", "/msg/")
    store.register(get_types_from_msg(installed_definition(type_name), name))
    return store, name


def rosbags_exact(store, name: str, raw: bytes) -> tuple[object, bytes]:  # noqa: ANN001
    """Rosbags' message from rclpy's bytes, and rosbags' little-endian bytes of it (no trailing bytes).

    rclpy's bytes can end with up to 16 bytes past the last field (its buffer's size, not the message's), which
    rosbags' ``deserialize_cdr`` refuses: its message definition's own reader is used.
    """
    msgdef = store.get_msgdef(name)
    message, _ = msgdef.deserialize_cdr_le(raw[4:], 0, msgdef.cls, store)
    return message, bytes(store.serialize_cdr(message, name))


@pytest.mark.parametrize("type_name", RIMD_MESSAGES + RIMD_SERVICES + RECORDED_STANDARD + LAYOUTS[:5])
def test_big_endian_bytes_decode_to_the_little_endian_values(type_name):
    specs = specs_of(type_name)
    cls = rclpy_class(type_name)
    store, name = _rosbags_store(type_name)
    rng = random.Random(type_name)
    decode = message_decoder(type_name)
    for _ in range(10):
        little = serialize_message(fill(cls(), specs, type_name, Draws(rng=rng)))
        big = bytes(store.serialize_cdr(rosbags_exact(store, name, little)[0], name, little_endian=False))
        assert big[1] == 0 and little[1] == 1
        mine_big = decode(big)
        assert_same(mine_big, deserialize_message(little, cls), specs, type_name)
        for f in specs[type_name]:
            value = getattr(mine_big, f.name)
            if isinstance(value, np.ndarray) and value.itemsize > 1:
                assert value.dtype.byteorder == ">", f.name     # a view in the data's byte order, not a copy


# ---- damaged bytes ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("type_name", ["rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState", "rimd_msgs/msg/Capture",
                                       "diagnostic_msgs/msg/DiagnosticArray", "rimd_msgs/msg/ConsumerProgress",
                                       "geometry_msgs/msg/PoseWithCovarianceStamped"])
def test_bytes_cut_short_raise_value_error(type_name):
    specs = specs_of(type_name)
    cls = rclpy_class(type_name)
    raw = serialize_message(fill(cls(), specs, type_name, Draws(rng=random.Random(7))))
    store, name = _rosbags_store(type_name)
    exact = rosbags_exact(store, name, raw)[1]      # the same message without rclpy's trailing bytes
    decode = message_decoder(type_name)
    assert_same(decode(exact), deserialize_message(raw, cls), specs, type_name)
    for cut in range(len(exact)):
        with pytest.raises(ValueError):
            decode(exact[:cut])


def test_a_length_past_the_end_and_bad_utf8_raise_value_error():
    from rimd_msgs.msg import FaultEvent

    raw = bytearray(serialize_message(FaultEvent(event="start", channel="impact_force")))
    decode = message_decoder("rimd_msgs/msg/FaultEvent")
    # Offsets from the bytes' start (the body starts at 4): the header's stamp (4-12), its frame_id "" (length
    # at 12, NUL at 16, padding), the event string's length at 20, its first byte at 24.
    long = bytearray(raw)
    long[20:24] = (10_000).to_bytes(4, "little")
    with pytest.raises(ValueError, match="does not fit"):
        decode(bytes(long))
    bad = bytearray(raw)
    bad[24] = 0xFF
    with pytest.raises(ValueError):
        decode(bytes(bad))
    with pytest.raises(ValueError, match="encapsulation"):
        decode(b"\0\1")
    huge = bytearray(serialize_message(rclpy_class("rimd_msgs/msg/SampleBlock")()))
    huge[36:40] = (2**32 - 1).to_bytes(4, "little")   # the samples' count (after first_index, sample_rate)
    with pytest.raises(ValueError):
        message_decoder("rimd_msgs/msg/SampleBlock")(bytes(huge))


# ---- definitions -------------------------------------------------------------------------------------------------

def test_definitions_that_cannot_be_decoded_are_refused_by_name():
    with pytest.raises(MessageDefinitionError, match="pkg/msg/Missing"):
        message_decoder("pkg/msg/T", "pkg/Missing m\n")
    with pytest.raises(MessageDefinitionError, match="wstring"):
        message_decoder("pkg/msg/T", "wstring w\n")
    with pytest.raises(MessageDefinitionError, match="line 2"):
        message_decoder("pkg/msg/T", "int32 a\nnot-a-field\n")
    with pytest.raises(MessageDefinitionError, match="foo_msgs/msg/Bar"):
        message_decoder("foo_msgs/msg/Bar")


def test_constants_defaults_and_comments_are_not_fields():
    text = ("# comment\nint32 A=1\nstring S = \"x # not a comment\"\nint32 a 5  # default 5\n"
            "string<=8[<=3] names\nuint8[4] fixed\nHeader h\n" + "=" * 80 + "\nMSG: std_msgs/Header\n"
            + message_definition("std_msgs/msg/Header").text)
    specs = parse_definition("pkg/msg/T", text)
    assert specs["pkg/msg/T"] == (Field("a", "int32"), Field("names", "string", SEQUENCE, 3, 8),
                                  Field("fixed", "uint8", 4), Field("h", "std_msgs/msg/Header"))
    assert list(specs) == ["pkg/msg/T", "std_msgs/msg/Header", "builtin_interfaces/msg/Time"]


# ---- a real recording, against rosbags ---------------------------------------------------------------------------

RECORDED_TOPICS = {"/rig/impact/force": "rimd_msgs/msg/SampleBlock", "/rig/truth": "rimd_msgs/msg/RigState",
                   "/rig/motor/state": "rimd_msgs/msg/MotorState", "/rig/impact/events": "rimd_msgs/msg/ImpactEvent",
                   "/rig/faults": "rimd_msgs/msg/FaultEvent", "/rig/capture/force": "rimd_msgs/msg/Capture",
                   "/rig/session": "rimd_msgs/msg/RigSession", "/rig/progress": "rimd_msgs/msg/ConsumerProgress",
                   "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray", "/clock": "rosgraph_msgs/msg/Clock"}


def _write_recording(directory: Path) -> int:
    """A recording of every recorded type by the recorder's writer: rclpy's bytes of seeded random messages."""
    from rimd_sim.io.bag import BagWriter, qos_profile_dict

    bag = BagWriter(directory, chunk_size=4096)
    stores = {}
    for topic, type_name in RECORDED_TOPICS.items():
        bag.add_topic(topic, type_name, [qos_profile_dict()])
        stores[type_name] = _rosbags_store(type_name)
    rng = random.Random(2024)
    written = 0
    for i in range(30):
        for topic, type_name in RECORDED_TOPICS.items():
            raw = serialize_message(fill(rclpy_class(type_name)(), specs_of(type_name), type_name, Draws(rng=rng)))
            # As DDS delivers them to the recorder: rclpy's bytes up to the message's end (see rosbags_exact).
            length = len(rosbags_exact(*stores[type_name], raw)[1])
            bag.write(topic, raw[:length], 1_000_000_000 + i * 1_000_000)
            written += 1
    bag.close()
    return written


def _rosbags_decoder(definition: str, type_name: str):  # noqa: ANN202
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(definition, type_name))
    return lambda raw: store.deserialize_cdr(raw, type_name)


def test_a_recording_decodes_from_its_own_definitions_as_rosbags_decodes_it(tmp_path):
    from harness.bags import read_with_rosbags
    from harness.rig_mcap import write_rig_mcap
    from rimd_sim.io.reader import open_recording

    written = _write_recording(tmp_path / "rec")
    counts, theirs = read_with_rosbags(tmp_path / "rec")
    recording = open_recording(tmp_path / "rec")
    mine = list(recording.messages())
    assert len(mine) == len(theirs) == written and set(counts) == set(RECORDED_TOPICS)
    seen = set()
    for msg, (topic, raw, _, decoded) in zip(mine, theirs, strict=True):
        topic_info = recording.topics[msg.topic]
        assert (msg.topic, msg.data) == (topic, raw)
        specs = parse_definition(topic_info.type_name, topic_info.definition)
        assert_same(topic_decoder(topic_info)(msg.data), decoded, specs, topic_info.type_name, topic)
        seen.add(topic_info.type_name)
    assert seen == set(RECORDED_TOPICS.values())

    # The physics core's file (mcap_ros2's writer, its own copy of the definitions).
    core = write_rig_mcap(tmp_path / "core.mcap", seconds=0.5).path   # its first impact at 0.40 s
    recording = open_recording(core)
    decoders = {}
    n = 0
    for msg in recording.messages():
        topic_info = recording.topics[msg.topic]
        if msg.topic not in decoders:
            decoders[msg.topic] = (topic_decoder(topic_info), _rosbags_decoder(topic_info.definition, msg.type_name),
                                   parse_definition(msg.type_name, topic_info.definition))
        ours, rosbags, specs = decoders[msg.topic]
        assert_same(ours(msg.data), rosbags(msg.data), specs, msg.type_name, msg.topic)
        n += 1
    assert n > 100 and len(decoders) == 7


def test_a_recording_without_schemas_decodes_with_the_installed_definitions():
    class Topic:
        name, type_name, definition, message_encoding, schema_encoding = "/rig/faults", "", "", "cdr", ""

    from rimd_msgs.msg import FaultEvent

    raw = serialize_message(FaultEvent(event="end", kind="stuck", magnitude=2.5))
    got = topic_decoder(Topic(), "rimd_msgs/msg/FaultEvent")(raw)
    assert (got.event, got.kind, got.magnitude) == ("end", "stuck", 2.5)
    with pytest.raises(MessageDefinitionError, match="no message type"):
        topic_decoder(Topic())
    Topic.type_name, Topic.message_encoding = "rimd_msgs/msg/FaultEvent", "json"
    with pytest.raises(MessageDefinitionError, match="not 'cdr'"):
        topic_decoder(Topic())


# ---- no ROS at all -----------------------------------------------------------------------------------------------

@pytest.mark.process
def test_analyze_and_rerun_read_a_recording_without_ros(tmp_path):
    """rclpy, rimd_msgs and the standard message packages unimportable; rimd_msgs' .msg files not findable."""
    from harness.rig_mcap import write_rig_mcap

    written = write_rig_mcap(tmp_path / "rig.mcap", seconds=2.0)
    code = textwrap.dedent("""
        import json, sys
        ROS = ('rclpy', 'rimd_msgs', 'std_msgs', 'builtin_interfaces', 'diagnostic_msgs', 'rosgraph_msgs',
               'rcl_interfaces', 'mcap_ros2', 'rosbags')
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in ROS:
                    raise ImportError('blocked: ' + name)
        sys.meta_path.insert(0, Block())
        from rimd_sim.cli import main
        from rimd_sim.io.msgdefs import MessageDefinitionError, message_definition
        try:
            installed = bool(message_definition('rimd_msgs/msg/SampleBlock'))
        except MessageDefinitionError:
            installed = False
        analyze = main(['analyze', sys.argv[1], '--out', sys.argv[2]])
        rerun = main(['rerun', sys.argv[1], '--save', sys.argv[3]])
        print(json.dumps({'analyze': analyze, 'rerun': rerun, 'installed': installed,
                          'imported': sorted(m for m in sys.modules if m.split('.')[0] in ROS)}))
    """)
    env = {k: v for k, v in os.environ.items() if k != "AMENT_PREFIX_PATH"}
    env["AMENT_PREFIX_PATH"] = str(tmp_path / "nothing")      # no share/rimd_msgs/msg/*.msg to fall back on
    proc = subprocess.run([sys.executable, "-c", code, str(written.path), str(tmp_path / "out"),
                           str(tmp_path / "rig.rrd")], capture_output=True, text=True, timeout=240, env=env,
                          check=False)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result == {"analyze": 0, "rerun": 0, "installed": False, "imported": []}, proc.stdout + proc.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    blocks = {topic: 200 for topic in ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration",
                                       "/rig/impact/force", "/rig/motor/state")}
    assert written.impacts > 0
    assert summary["messages"] == {**blocks, "/rig/impact/events": written.impacts}
    assert summary["loss"]["undecodable_messages"] == {} and summary["loss"]["complete"]
    assert (tmp_path / "rig.rrd").stat().st_size > 0


def test_the_fault_report_reads_fault_events_and_captures_through_the_decoder(tmp_path):
    """``/rig/faults`` and ``/rig/capture/force`` as the fault report of ``rimd analyze`` reads them; a topic of
    another type under a rig name is left out (the main analysis reports it)."""
    from rimd_msgs.msg import Capture, FaultEvent
    from rimd_sim.analysis.recordings.faultreport import fault_report
    from rimd_sim.io.bag import BagWriter, qos_profile_dict
    from rimd_sim.io.reader import open_recording

    bag = BagWriter(tmp_path / "rec")
    bag.add_topic("/rig/faults", "rimd_msgs/msg/FaultEvent", [qos_profile_dict()])
    bag.add_topic("/rig/capture/force", "rimd_msgs/msg/Capture", [qos_profile_dict()])
    bag.add_topic("/rig/impact/force", "rimd_msgs/msg/FaultEvent", [qos_profile_dict()])   # a foreign type
    events = [FaultEvent(event="start", id=3, channel="impact_force", kind="stuck", start=1.5, duration=0.25,
                         magnitude=2.0, detail="held at 0.5 N ✓"),
              FaultEvent(event="end", id=3, channel="impact_force", kind="stuck", start=1.5, duration=0.25,
                         magnitude=2.0, detail="duration elapsed")]
    for i, event in enumerate(events):
        bag.write("/rig/faults", serialize_message(event), 10 + i)
        bag.write("/rig/impact/force", serialize_message(event), 10 + i)
    capture = Capture(index=0, sample_rate=1e6, pre_trigger_samples=2, samples=[0.0, 1.0, 80.5, 3.0], unit="N")
    capture.header.stamp.sec, capture.header.stamp.nanosec = 2, 500_000_000
    bag.write("/rig/capture/force", serialize_message(capture), 20)
    bag.close()
    report = fault_report(open_recording(tmp_path / "rec"), np.array([80.0]), np.array([0.5005]), 2_000_000_000)
    assert report["faults"] == [
        {"event": "start", "id": 3, "channel": "impact_force", "kind": "stuck", "start_s": 1.5, "duration_s": 0.25,
         "magnitude": 2.0, "detail": "held at 0.5 N ✓"},
        {"event": "end", "id": 3, "channel": "impact_force", "kind": "stuck", "start_s": 1.5, "duration_s": 0.25,
         "magnitude": 2.0, "detail": "duration elapsed"}]
    assert report["channels"] == {}
    assert report["captures"]["count"] == 1 and report["captures"]["sample_rate"] == 1e6
    assert report["captures"]["capture_peak_n_max"] == 80.5 and report["captures"]["matched"] == 1
