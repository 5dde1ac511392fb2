"""Damaged recordings, fuzzed: the MCAP reader, ``rimd analyze``, ``rimd rerun`` and ``rimd_replay``.

Damage: truncation at every record boundary (all of them) and at random offsets, flipped bits in chunks, in the
summary section (after DataEnd) and anywhere, wrong record lengths (too large, too small, zero, huge), and valid
files holding a message type not installed here. Cases are drawn by hypothesis with explicit ``max_examples``,
``derandomize=True`` and no example database, so every run draws the same cases; the counts are printed at the
end of the module (``pytest -s``): ``fuzz: N reader cases, M analyze, K rerun, J replay``.

The rules tested (the record framing and the chunks' contents are parsed here, independently of the reader):

* the reader (``open_recording`` + ``messages()``) raises nothing but ``RecordingError``, and that only when the
  file does not start with the MCAP magic bytes; its message is one line naming the file;
* every message of a chunk that ends before the first damaged byte comes out, bit for bit and in order, and
  nothing comes out that the intact file does not hold (the messages are a subsequence of the intact file's);
* a file read as complete gives exactly the intact file's messages; damage the file can reveal is reported:
  ``complete`` is False and the report's ``describe()`` names the file and what was wrong. The writer protects
  each chunk's bytes with a CRC and the summary with the footer's summary CRC (checked below), so a flipped
  bit there must be detected; a flip that changes nothing the reader uses (a chunk's message time range, a bit
  zstd ignores) must leave every message intact;
* truncation: exactly the messages of the chunks before the cut, reported as truncated;
* a flipped bit in a chunk (zstd, lz4 and uncompressed chunks): the messages before that chunk, never altered
  bytes (reading stops at the first damage, as the README documents for replay);
* a flipped bit in the summary: every message, and the damage reported (not as a truncation);
* a wrong record length: reported, unless it swallows exactly the next record (then nothing is altered);
* ``rimd analyze`` and ``rimd rerun`` (run in-process through ``rimd_sim.cli.main`` for the hypothesis cases, an
  exception escaping it being a traceback, and as processes for a few): exit 0 with the damage reported (a LOSS
  line, a ``damaged:`` line) when something of their topics is readable, else exit 1 with one line on stderr;
  never a traceback;
* ``rimd_replay``: publishes exactly what the reader reads and exits 0 saying what was damaged, or exits 1 with
  one line saying why.
"""

from __future__ import annotations

import contextlib
import io
import re
import struct
import subprocess
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness.outputs import read_json
from harness.rig_mcap import write_rig_mcap
from rimd_sim.io.reader import RecordingError, open_recording

MAGIC = b"\x89MCAP0\r\n"
CHUNK, DATA_END, MESSAGE = 0x06, 0x0F, 0x05
ANALYSED = {"/rig/impact/force", "/rig/impact/events", "/rig/motor/state", "/rig/rimd/displacement",
            "/rig/cart/displacement"}
RIG = ANALYSED - {"/rig/motor/state"} | {"/rig/truth", "/rig/rimd/acceleration"}
GAUGE = "lab_msgs/msg/Gauge"

#: Cases run, by kind; printed at the end of the module.
CASES: Counter[str] = Counter()


def fuzz(max_examples: int):
    """Reproducible hypothesis settings: a fixed number of cases, drawn the same way every run."""
    return settings(max_examples=max_examples, derandomize=True, database=None, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@pytest.fixture(scope="module", autouse=True)
def _report_counts():
    start = time.monotonic()
    yield
    print(f"\nfuzz: {CASES['reader']} reader cases ({CASES['boundary']} truncations at every record boundary, "
          f"{CASES['cut']} at random offsets, {CASES['chunk']} bits flipped in chunks ({CASES['chunk_harmless']} "
          f"harmless and undetectable), {CASES['summary']} in the "
          f"summary, {CASES['anywhere']} anywhere, {CASES['length']} wrong lengths, {CASES['foreign']} foreign "
          f"type), {CASES['analyze']} analyze, {CASES['rerun']} rerun, {CASES['replay']} replay; "
          f"{time.monotonic() - start:.1f} s")


# ---- the recordings and their structure, parsed here ---------------------------------------------------------

@dataclass(repr=False)
class Source:
    """An intact recording: its bytes, top-level records, chunks and messages (read by mcap's own reader)."""

    path: Path
    data: bytes
    records: list[tuple[int, int, int]]          # (offset, opcode, end) of each top-level record
    chunks: list[tuple[int, int, int]]           # (offset, end, messages up to its end) of each chunk
    messages: list[tuple[str, int, bytes]]       # (topic, log time, data) in file order
    data_end: int                                # first byte of the summary section

    def __repr__(self) -> str:
        return f"Source({self.path.name}: {len(self.data)} bytes, {len(self.records)} records, " \
               f"{len(self.chunks)} chunks, {len(self.messages)} messages)"

    def _repr_pretty_(self, printer, cycle) -> None:  # hypothesis prints failing cases with it
        printer.text(repr(self))

    @property
    def boundaries(self) -> list[int]:
        """Every record boundary: after the magic, after each record, after the closing magic."""
        return [8, *(end for _, _, end in self.records), len(self.data)]

    def before(self, byte: int) -> list[tuple[str, int, bytes]]:
        """The messages of the chunks that end at or before ``byte`` (the first damaged byte)."""
        count = 0
        for _, end, upto in self.chunks:
            if end <= byte:
                count = upto
        return self.messages[:count]

    def chunk_at(self, byte: int) -> tuple[int, int, int]:
        return next(c for c in self.chunks if c[0] <= byte < c[1])


def _frame(data: bytes) -> list[tuple[int, int, int]]:
    """The top-level records (MCAP framing: opcode u8, length u64 LE, body) between the two magic strings."""
    assert data[:8] == MAGIC and data[-8:] == MAGIC
    records, position = [], 8
    while position < len(data) - 8:
        opcode, length = struct.unpack_from("<BQ", data, position)
        records.append((position, opcode, position + 9 + length))
        position += 9 + length
    assert position == len(data) - 8
    return records


def _chunk_messages(body: bytes) -> int:
    """Messages in a chunk body; also checks that the writer gave the chunk a CRC (the rule relies on it)."""
    import lz4.frame
    import zstandard

    (crc,) = struct.unpack_from("<I", body, 24)
    assert crc != 0, "the writer wrote a chunk without a CRC"
    (name_length,) = struct.unpack_from("<I", body, 28)
    compression = body[32:32 + name_length].decode()
    (size,) = struct.unpack_from("<Q", body, 32 + name_length)
    payload = body[40 + name_length:40 + name_length + size]
    raw = {"zstd": zstandard.ZstdDecompressor().decompress, "lz4": lz4.frame.decompress}.get(
        compression, bytes)(payload)
    count = position = 0
    while position < len(raw):
        opcode, length = struct.unpack_from("<BQ", raw, position)
        count += opcode == MESSAGE
        position += 9 + length
    return count


def _source(path: Path) -> Source:
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    data = path.read_bytes()
    records = _frame(data)
    chunks, total = [], 0
    for offset, opcode, end in records:
        if opcode == CHUNK:
            total += _chunk_messages(data[offset + 9:end])
            chunks.append((offset, end, total))
    topics, messages = {}, []
    for record in StreamReader(io.BytesIO(data)).records:
        if isinstance(record, Channel):
            topics[record.id] = record.topic
        elif isinstance(record, Message):
            messages.append((topics[record.channel_id], record.log_time, record.data))
    assert len(messages) == total
    (data_end,) = (end for _, opcode, end in records if opcode == DATA_END)
    footer = data[-8 - 20:-8]
    assert struct.unpack_from("<I", footer, 16)[0] != 0, "the writer wrote no summary CRC"
    return Source(path, data, records, chunks, messages, data_end)


def _rerecord(core: Path, out: Path, *, until_s: float, chunk_size: int, foreign: str | None = None,
              compression: str = "zstd") -> Path:
    """Write the messages of ``core`` (up to ``until_s``) with the recorder's writer, in chunks of ``chunk_size``.

    ``foreign``: a topic recorded with the type ``lab_msgs/msg/Gauge``, not installed here (a rig topic of that
    name is replaced by it; another name is added next to the rig topics).
    """
    from mcap.reader import make_reader

    from rimd_sim.io.bag import BagWriter, TopicInfo, qos_profile_dict
    from rimd_sim.io.msgdefs import MessageDefinition

    bag = BagWriter(out, chunk_size=chunk_size, compression=compression,
                    metadata={"rimd_recording": {"software": "test_fuzz_recordings"}})
    if foreign:
        bag.topics[foreign] = TopicInfo(foreign, GAUGE, [qos_profile_dict()],
                                        MessageDefinition(GAUGE, "float64 strain\n", ""))
    with core.open("rb") as fh:
        for n, (schema, channel, message) in enumerate(make_reader(fh).iter_messages()):
            if message.log_time > until_s * 1e9:
                break
            if foreign and (n % 7 == 0 or channel.topic == foreign):
                bag.write(foreign, b"\x00\x01\x00\x00" + struct.pack("<d", n * 1e-6), message.log_time)
            if channel.topic != foreign:
                bag.add_topic(channel.topic, schema.name, [qos_profile_dict()])
                bag.write(channel.topic, message.data, message.log_time, message.publish_time)
    bag.close()
    (path,) = out.glob("*.mcap")
    return path


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> dict[str, Source]:
    """``small``: 0.3 s of the rig in 8 KiB zstd chunks (reader cases; also ``small_lz4`` and ``small_none``);
    ``rig``: 1 s in 16 KiB chunks (verbs, replay); ``gauge`` and ``foreign_events``: valid files with a foreign
    type beside and instead of a rig topic."""
    root = tmp_path_factory.mktemp("fuzz_sources")
    core = write_rig_mcap(root / "core.mcap", seconds=1.0).path   # the physics core's output, real definitions
    return {
        "small": _source(_rerecord(core, root / "small", until_s=0.3, chunk_size=8 * 1024)),
        **{f"small_{c}": _source(_rerecord(core, root / f"small_{c}", until_s=0.3, chunk_size=8 * 1024, compression=c))
           for c in ("lz4", "none")},
        "rig": _source(_rerecord(core, root / "rig", until_s=1.0, chunk_size=16 * 1024)),
        "gauge": _source(_rerecord(core, root / "gauge", until_s=0.3, chunk_size=8 * 1024, foreign="/lab/gauge")),
        "foreign_events": _source(_rerecord(core, root / "foreign_events", until_s=1.0, chunk_size=16 * 1024,
                                            foreign="/rig/impact/events")),
    }


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz_cases")


# ---- damage ------------------------------------------------------------------------------------------------

def flip(data: bytes, byte: int, bit: int) -> bytes:
    damaged = bytearray(data)
    damaged[byte] ^= 1 << bit
    return bytes(damaged)


def set_length(source: Source, index: int, kind: str, delta: int) -> bytes:
    """``source`` with the length field of record ``index`` made wrong in the way ``kind`` says."""
    offset, _, end = source.records[index]
    length = end - offset - 9
    following = source.records[index + 1][2] if index + 1 < len(source.records) else end
    new = {"plus": length + delta, "minus": max(length - delta, 0), "zero": 0, "double": 2 * length + 1,
           "huge": 2 ** 63, "max": 2 ** 64 - 1, "swallow": following - offset - 9}[kind]
    damaged = bytearray(source.data)
    struct.pack_into("<Q", damaged, offset + 1, new)
    return bytes(damaged)


@dataclass
class Outcome:
    """What the reader made of a damaged file."""

    messages: list[tuple[str, int, bytes]]
    recording: object


def read(source: Source, damaged: bytes, work: Path, first_bad: int) -> Outcome | None:
    """Read ``damaged`` with the reader and check the rules every case obeys; None when refused as not MCAP."""
    CASES["reader"] += 1
    path = work / "damaged.mcap"
    path.write_bytes(damaged)
    try:
        recording = open_recording(path)
        got = [(m.topic, m.log_time, m.data) for m in recording.messages()]
    except RecordingError as exc:
        assert damaged[:8] != MAGIC, f"refused a file that starts as MCAP: {exc}"
        assert str(path) in str(exc) and "\n" not in str(exc)
        return None
    kept = source.before(first_bad)
    assert got[:len(kept)] == kept, f"lost messages before the damage at byte {first_bad}"
    assert _is_subsequence(got, source.messages), "a message the intact file does not hold (altered bytes)"
    (report,) = recording.reports
    assert report.messages == len(got) == recording.message_count
    if recording.complete:
        assert got == source.messages, "read as complete, but messages are missing"
    else:
        text = report.describe()
        assert text.startswith("damaged.mcap: incomplete (") and report.error and "\n" not in text, text
    return Outcome(got, recording)


def _is_subsequence(got: list, whole: list) -> bool:
    rest = iter(whole)
    return all(any(item == other for other in rest) for item in got)


# ---- the reader, in-process ----------------------------------------------------------------------------------

def test_truncation_at_every_record_boundary(sources, work):
    """Exhaustive: the file cut at every boundary between records (and inside the opening magic)."""
    source = sources["small"]
    for cut in [*range(8), *source.boundaries]:
        CASES["boundary"] += 1
        outcome = read(source, source.data[:cut], work, cut)
        if cut < 8:
            assert outcome is None
            continue
        assert outcome.messages == source.before(cut), cut
        if cut < len(source.data):
            assert "truncated" in outcome.recording.reports[0].error, (cut, outcome.recording.reports[0].error)
        else:
            assert outcome.recording.complete


@fuzz(300)
@given(st.data())
def test_truncation_at_random_offsets(sources, work, data):
    source = sources["small"]
    cut = data.draw(st.integers(0, len(source.data) - 1), label="cut")
    CASES["cut"] += 1
    outcome = read(source, source.data[:cut], work, cut)
    if outcome is not None:
        assert outcome.messages == source.before(cut)
        assert not outcome.recording.complete and "truncated" in outcome.recording.reports[0].error


#: The chunk record's head: opcode and length (9 bytes), message time range (16), uncompressed size (8), CRC (4),
#: compression name (4 + up to 4: zstd, lz4 or none) and the records' length (8); the records follow.
CHUNK_HEAD = 9 + 16 + 8 + 4 + 4 + 4 + 8


@fuzz(300)
@given(st.data())
def test_flipped_bit_in_a_chunk(sources, work, data):
    """Detected by the chunk's CRC (or its sizes): the chunks before it are kept, never altered bytes. Chunks
    compressed with zstd (the recorder's default) and lz4, and uncompressed (where only the CRC can tell).

    Half the cases flip a bit of the chunk's head (:data:`CHUNK_HEAD`), a few dozen bytes each of which the reader
    reads differently; the other half anywhere in the chunk, nearly always in its records, where every flip takes
    the same way (the CRC, or the decompression, refuses the chunk)."""
    source = sources[data.draw(st.sampled_from(["small", "small_lz4", "small_none"]), label="compression")]
    offset, end, _ = data.draw(st.sampled_from(source.chunks), label="chunk")
    head = data.draw(st.booleans(), label="in the head")
    byte = data.draw(st.integers(offset, min(offset + CHUNK_HEAD, end) - 1) if head else st.integers(offset, end - 1),
                     label="byte")
    bit = data.draw(st.integers(0, 7), label="bit")
    CASES["chunk"] += 1
    outcome = read(source, flip(source.data, byte, bit), work, byte)
    if outcome.recording.complete:
        # Undetectable and harmless: the chunk's message time range (not covered by the CRC), or a bit zstd
        # ignores; either way every message is intact (checked in read()).
        CASES["chunk_harmless"] += 1
        assert byte >= offset + 9
    elif byte >= offset + 9:
        # In the body (the framing is intact): reading stops exactly at this chunk, and says so.
        assert outcome.messages == source.before(offset), "reading must stop at the damaged chunk"
        assert f"chunk record at byte {offset}" in outcome.recording.reports[0].error or \
            f"chunk at byte {offset}" in outcome.recording.reports[0].error, outcome.recording.reports[0].error


@fuzz(300)
@given(st.data())
def test_flipped_bit_in_the_summary(sources, work, data):
    """The summary section and footer are covered by the summary CRC: every message, and the damage said."""
    source = sources["small"]
    byte = data.draw(st.integers(source.data_end, len(source.data) - 1), label="byte")
    bit = data.draw(st.integers(0, 7), label="bit")
    CASES["summary"] += 1
    outcome = read(source, flip(source.data, byte, bit), work, byte)
    assert outcome.messages == source.messages
    report = outcome.recording.reports[0]
    assert not report.complete, f"a flipped bit at byte {byte} of the summary went unnoticed"
    assert "truncated" not in report.error, report.error   # the file still ends with its magic: not cut short


@fuzz(300)
@given(st.data())
def test_flipped_bit_anywhere(sources, work, data):
    """Anywhere (headers, message indexes, metadata too): no crash, the messages before it, nothing altered."""
    source = sources["small"]
    byte = data.draw(st.integers(0, len(source.data) - 1), label="byte")
    bit = data.draw(st.integers(0, 7), label="bit")
    CASES["anywhere"] += 1
    read(source, flip(source.data, byte, bit), work, byte)


@fuzz(400)
@given(st.data())
def test_wrong_record_length(sources, work, data):
    """A record's length too large, too small, zero or huge: the records before it are kept and the damage is
    reported, except a length that happens to swallow exactly the next record (then nothing is altered)."""
    source = sources["small"]
    index = data.draw(st.integers(0, len(source.records) - 1), label="record")
    kind = data.draw(st.sampled_from(["plus", "minus", "zero", "double", "huge", "max", "swallow"]), label="kind")
    delta = data.draw(st.integers(1, 4096), label="delta")
    CASES["length"] += 1
    offset, opcode, _ = source.records[index]
    outcome = read(source, set_length(source, index, kind, delta), work, offset)
    if kind != "swallow":
        assert not outcome.recording.complete, (index, opcode, kind, delta)


def test_valid_file_with_a_foreign_type(sources, work):
    """A complete file holding a type not installed here reads completely, bytes and type name as recorded."""
    for name in ("gauge", "foreign_events"):
        source = sources[name]
        CASES["foreign"] += 1
        outcome = read(source, source.data, work, len(source.data))
        assert outcome.recording.complete and outcome.messages == source.messages
        foreign = "/lab/gauge" if name == "gauge" else "/rig/impact/events"
        assert outcome.recording.topics[foreign].type_name == GAUGE
        assert sum(topic == foreign for topic, _, _ in outcome.messages) > 10


# ---- rimd analyze and rimd rerun -----------------------------------------------------------------------------

@st.composite
def damaged_file(draw, source: Source) -> tuple[str, bytes]:
    """One damaged copy of ``source``: (what was done, bytes)."""
    kind = draw(st.sampled_from(["cut", "boundary", "chunk", "summary", "length"]))
    data = source.data
    if kind == "cut":
        cut = draw(st.integers(0, len(data) - 1))
        return f"cut at {cut}", data[:cut]
    if kind == "boundary":
        cut = draw(st.sampled_from(source.boundaries[:-1]))
        return f"cut at boundary {cut}", data[:cut]
    if kind == "length":
        index = draw(st.integers(0, len(source.records) - 1))
        how = draw(st.sampled_from(["plus", "minus", "huge", "swallow"]))
        return f"length of record {index} {how}", set_length(source, index, how, 3)
    if kind == "chunk":
        offset, end, _ = draw(st.sampled_from(source.chunks))
        byte = draw(st.integers(offset, end - 1))
    else:
        byte = draw(st.integers(source.data_end, len(data) - 1))
    return f"bit flipped at {byte}", flip(data, byte, draw(st.integers(0, 7)))


def rimd(*argv: str) -> tuple[int, str, str]:
    """``rimd ARGV`` in this process: (exit status, stdout, stderr). An exception escaping is a traceback."""
    from rimd_sim import cli

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = cli.main(list(argv))
    return status, out.getvalue(), err.getvalue()


def readable(path: Path) -> tuple[set[str], bool]:
    """Topics with a message the reader yields, and whether the file is complete (nothing for non-MCAP)."""
    try:
        recording = open_recording(path)
    except RecordingError:
        return set(), False
    return {m.topic for m in recording.messages()}, recording.complete


def check_analyze(path: Path, out: Path, status: int, stdout: str, stderr: str) -> None:
    topics, complete = readable(path)
    assert "Traceback" not in stdout + stderr
    if topics & ANALYSED:
        assert status == 0, stderr
        summary = read_json(out / "summary.json")
        assert summary["loss"]["complete"] == complete
        if not complete:
            assert re.search(rf"^LOSS: {re.escape(path.name)}: incomplete \(", stdout, re.M), stdout
    else:
        assert status == 1, stdout + stderr
        lines = stderr.strip().splitlines()
        assert lines and all(line.startswith("rimd analyze: ") for line in lines), stderr
        assert str(path) in lines[-1], lines[-1]   # the failure names the recording
        if not complete and (path.stat().st_size >= 8):
            assert "damaged" in lines[-1] or "not an MCAP file" in lines[-1], lines[-1]


def check_rerun(path: Path, rrd: Path, status: int, stdout: str, stderr: str) -> None:
    topics, complete = readable(path)
    assert "Traceback" not in stdout + stderr
    if topics & RIG:
        assert status == 0, stderr
        assert stdout.startswith(f"rimd rerun: {path} -> {rrd}: ") and rrd.stat().st_size > 0, stdout
        if not complete:
            assert f"rimd rerun: damaged: {path.name}: incomplete (" in stderr, stderr
    else:
        assert status == 1, stdout + stderr
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("rimd rerun: ") and stdout == "", stderr


#: Per conversion verb: its output option, the output's name for case N, and the check of what it did.
CONVERSIONS = {"analyze": ("--out", "analysis_{}", check_analyze), "rerun": ("--save", "rerun_{}.rrd", check_rerun)}


def convert_damaged(sources, work, verb: str, data) -> None:
    """One damaged copy of the ``rig`` recording through ``verb`` in this process, checked by the verb's rule."""
    option, output, check = CONVERSIONS[verb]
    _what, damaged = data.draw(damaged_file(sources["rig"]), label="damage")
    CASES[verb] += 1
    path, dest = work / f"{verb}.mcap", work / output.format(CASES[verb])
    path.write_bytes(damaged)
    check(path, dest, *rimd(verb, str(path), option, str(dest)))


@fuzz(8)
@given(st.data())
def test_analyze_on_damaged_recordings(sources, work, data):
    """Fewer cases than rerun's: an analysis that reads something draws its five figures, most of its time."""
    convert_damaged(sources, work, "analyze", data)


@fuzz(15)
@given(st.data())
def test_rerun_on_damaged_recordings(sources, work, data):
    convert_damaged(sources, work, "rerun", data)


def test_verbs_on_a_foreign_type(sources, work):
    """Beside the rig topics: ignored. Instead of a rig topic: analyze and rerun check the recorded type (the
    bytes of another type may well decode as the rig's), leave the topic out and say so; both convert the
    rest."""
    for name in ("gauge", "foreign_events"):
        path = sources[name].path
        out, rrd = work / f"foreign_{name}", work / f"foreign_{name}.rrd"
        CASES["analyze"] += 1
        status, stdout, stderr = rimd("analyze", str(path), "--out", str(out))
        check_analyze(path, out, status, stdout, stderr)
        loss = read_json(out / "summary.json")["loss"]
        assert not loss["undecodable_messages"], loss
        if name == "foreign_events":
            wrong = loss["wrong_type"]["/rig/impact/events"]
            assert wrong["recorded_type"] == GAUGE and wrong["expected_type"] == "rimd_msgs/msg/ImpactEvent"
            assert wrong["messages"] == sum(t == "/rig/impact/events" for t, _, _ in sources[name].messages)
            assert re.search(rf"^LOSS: .*/rig/impact/events has type {GAUGE}, not rimd_msgs/msg/ImpactEvent: "
                             rf"its {wrong['messages']} messages left out", stdout, re.M), stdout
        else:
            assert not loss["wrong_type"] and "LOSS" not in stdout, stdout
        CASES["rerun"] += 1
        status, stdout, stderr = rimd("rerun", str(path), "--save", str(rrd))
        check_rerun(path, rrd, status, stdout, stderr)
        if name == "foreign_events":
            assert f"/rig/impact/events has type {GAUGE}, not rimd_msgs/msg/ImpactEvent: left out" in stderr
            assert ", 0 impacts," in stdout


@pytest.mark.process
def test_verbs_as_processes(sources, work):
    """The console script itself, on two damaged files, one per exit status: exit status, stderr, no traceback.

    The other kinds of damage take the same way through the console script; the in-process cases cover them.
    """
    source = sources["rig"]
    middle = source.chunks[len(source.chunks) // 2]
    cases = {
        "mid_chunk.mcap": source.data[:(middle[0] + middle[1]) // 2],       # something readable: exit 0
        "first_chunk.mcap": source.data[:source.chunks[0][1] - 1],          # nothing readable: exit 1
    }
    for name, damaged in cases.items():
        path = work / name
        path.write_bytes(damaged)
        out, rrd = work / f"process_{name}", work / f"process_{name}.rrd"
        for verb, args in (("analyze", ["--out", str(out)]), ("rerun", ["--save", str(rrd)])):
            CASES[verb] += 1
            result = subprocess.run(["rimd", verb, str(path), *args], capture_output=True, text=True, timeout=120)
            (check_analyze(path, out, result.returncode, result.stdout, result.stderr) if verb == "analyze" else
             check_rerun(path, rrd, result.returncode, result.stdout, result.stderr))


# ---- rimd_replay -----------------------------------------------------------------------------------------------

@pytest.mark.ros
@pytest.mark.timeout(180)
def test_replay_of_damaged_recordings(sources, ros_processes, ros_executor, tmp_path):
    """A truncated chunk, a flipped bit in the summary, a chunk length of 2**63, nothing readable: the node
    publishes exactly what the reader reads (a subscriber receives it, byte for byte, in order) and says what was
    damaged, or exits 1 with one line. A valid file with a foreign type: refused naming it, or (``skip_unknown``)
    the other topics replayed."""
    from harness.rig import RIG_TOPICS, RawCollector, resume_when_matched
    from harness.ros import spin_until

    source = sources["rig"]
    middle = source.chunks[len(source.chunks) // 2]
    index = next(i for i, r in enumerate(source.records) if r[0] == middle[0])
    (statistics,) = (offset for offset, opcode, _ in source.records if opcode == 0x0B)
    cases = {
        "cut.mcap": source.data[:(middle[0] + middle[1]) // 2],
        "summary.mcap": flip(source.data, statistics + 9 + 20, 5),   # in the statistics' time range
        "length.mcap": set_length(source, index, "huge", 0),
        "nothing.mcap": source.data[:source.chunks[0][0]],
    }
    for name, damaged in cases.items():
        (tmp_path / name).write_bytes(damaged)
    # First the runs that publish no rig topic to a subscriber of this test, in parallel.
    nodes = {"nothing.mcap": ros_processes.start_node("rimd_replay", "--ros-args", "-p",
                                                      f"file:={tmp_path / 'nothing.mcap'}", name="nothing.mcap")}
    CASES["replay"] += 1
    gauge = sources["gauge"]
    for skip in ("false", "true"):
        CASES["replay"] += 1
        nodes[f"gauge_skip_{skip}"] = ros_processes.start_node(
            "rimd_replay", "--ros-args", "-p", f"file:={gauge.path}", "-p", "rate:=20.0", "-p", f"skip_unknown:={skip}",
            name=f"gauge_skip_{skip}")
    refused, skipped = nodes.pop("gauge_skip_false"), nodes.pop("gauge_skip_true")
    assert refused.wait(90) == 1 and "Traceback" not in refused.output()
    assert refused.output().strip().splitlines()[-1].startswith("rimd_replay: the recording has message types not "
                                                               f"installed here: {GAUGE} (/lab/gauge)")
    assert skipped.wait(90) == 0 and "Traceback" not in skipped.output()
    known = sum(topic != "/lab/gauge" for topic, _, _ in gauge.messages)
    assert f"replay finished: {known} messages published" in skipped.output(), skipped.output()
    nothing = nodes.pop("nothing.mcap")
    assert nothing.wait(90) == 1 and "Traceback" not in nothing.output()
    last = nothing.output().strip().splitlines()[-1]
    assert last.startswith("rimd_replay: nothing to replay") and "the recording is damaged" in last, last
    # Then each damaged file with messages, one at a time, to a subscriber of every topic it has: what it
    # receives is what the reader reads, byte for byte and in order.
    for name in ("cut.mcap", "summary.mcap", "length.mcap"):
        CASES["replay"] += 1
        recording = open_recording(tmp_path / name)
        read: dict[str, list[bytes]] = {}
        for msg in recording.messages():
            read.setdefault(msg.topic, []).append(msg.data)
        assert recording.message_count and set(read) <= set(RIG_TOPICS), (name, set(read))
        collector = RawCollector(ros_executor, topics={t: RIG_TOPICS[t] for t in read},
                                 name=f"collector_{name.split('.')[0]}")
        # Paused until both sides of discovery have matched (the replay's wait, then the collector's), so that
        # no first message can be lost to the load of a parallel run.
        node = nodes[name] = ros_processes.start_node(
            "rimd_replay", "--ros-args", "-p", f"file:={tmp_path / name}", "-p", "rate:=20.0",
            "-p", "wait_for_subscribers:=1", "-p", "start_paused:=true", name=name)
        resume_when_matched(ros_executor, collector, node)
        count = recording.message_count
        total = lambda c=collector: sum(len(v) for v in c.messages.values())  # noqa: E731
        assert spin_until(ros_executor, lambda n=node, t=total, k=count: n.returncode is not None and t() >= k, 60), (
            name, total(), node.tail())
        # DDS delivers a serialized message padded with zeros to a multiple of 4 bytes (the files were written
        # by mcap_ros2 unpadded; a recording of rimd_recorder holds what DDS delivered, padding included).
        padded = {t: [d + b"\0" * (-len(d) % 4) for d in data] for t, data in read.items()}
        assert collector.messages == padded, name
        output = node.output()
        assert node.returncode == 0 and "Traceback" not in output, output
        report = recording.reports[0]
        assert not report.complete and report.describe() in output
        assert f"replay finished: {recording.message_count} messages published" in output, output
    assert "the summary section is damaged" in nodes["summary.mcap"].output()
    assert "runs past the end of the file" in nodes["length.mcap"].output()
