"""The recorder's MCAP writer keeps its chunk indexes packed: the same file, a fraction of the memory."""

from __future__ import annotations

import gc
import io

import pytest
from mcap.reader import make_reader
from mcap.records import ChunkIndex
from mcap.writer import CompressionType, Writer

from rimd_sim.io.bag import BagWriter, PackedChunkIndexes, pack_chunk_indexes, qos_profile_dict

EVENT = "rimd_msgs/msg/ImpactEvent"


def _write(packed: bool, compression: CompressionType) -> tuple[bytes, int]:
    """A file of five channels and 400 messages in many chunks (by size and by flush); its bytes and chunks."""
    out = io.BytesIO()
    writer = Writer(out, chunk_size=2048, compression=compression)
    if packed:
        assert pack_chunk_indexes(writer)
    writer.start(profile="ros2", library="test")
    schema = writer.register_schema("pkg/msg/Thing", "ros2msg", b"float64 x")
    channels = [writer.register_channel(f"/topic{c}", "cdr", schema, {"k": str(c)}) for c in range(5)]
    for i in range(400):
        writer.add_message(channels[i % 5 if i % 7 else 0], 1_000_000_000 + 1_000_003 * i,
                           bytes([i % 251]) * (40 + i % 90), 1_000_000_000 + 1_000_003 * i + 17, i)
        if i % 37 == 0:
            writer.flush()
    writer.finish()
    summary = make_reader(io.BytesIO(out.getvalue())).get_summary()
    assert summary is not None
    return out.getvalue(), len(summary.chunk_indexes)


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.NONE])
def test_a_packed_writer_writes_the_same_file_byte_for_byte(compression):
    plain, chunks = _write(False, compression)
    packed, packed_chunks = _write(True, compression)
    assert chunks > 20   # by size and by flush: enough to compare more than one index
    assert packed_chunks == chunks
    assert packed == plain


def test_the_packed_store_reads_back_what_it_was_given():
    store = PackedChunkIndexes()
    given = [ChunkIndex(message_start_time=10 * i, message_end_time=10 * i + 9, chunk_start_offset=1000 * i,
                        chunk_length=900 + i,
                        message_index_offsets={c: 1000 * i + 900 + 30 * c for c in range(1, 1 + i % 13)},
                        message_index_length=30 * (i % 13), compression=("zstd", "lz4", "")[i % 3],
                        compressed_size=500 + i, uncompressed_size=800 + i) for i in range(60)]
    for index in given:
        store.append(index)
    assert len(store) == 60
    assert list(store) == given
    assert list(store) == given   # read again: the store is not consumed
    assert store.nbytes < 60 * 300


def test_the_recorders_files_keep_no_chunk_index_object(tmp_path, monkeypatch):
    import weakref

    from rclpy.serialization import serialize_message

    from rimd_msgs.msg import ImpactEvent

    made: list[weakref.ref] = []   # this writer's indexes only (not another thread's)

    class Tracked(ChunkIndex):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(weakref.ref(self))

    monkeypatch.setattr("mcap.writer.ChunkIndex", Tracked)
    bag = BagWriter(tmp_path / "rec", chunk_size=1024)
    bag.add_topic("/rig/impact/events", EVENT, [qos_profile_dict(depth=1000)])
    for i in range(300):
        bag.write("/rig/impact/events", serialize_message(ImpactEvent(index=i, peak_force=80.0 + i)), 10**9 + 10**7 * i)
        if i % 10 == 9:
            bag.flush()
    store = bag._current._writer._Writer__chunk_indices   # the recorder's file, as mcap's Writer holds it
    assert isinstance(store, PackedChunkIndexes) and len(store) >= 30
    gc.collect()
    assert len(made) >= len(store)   # the writer made each index as a ChunkIndex...
    assert [ref for ref in made if ref() is not None] == []   # ...and none is kept
    bag.close()
    (path,) = (tmp_path / "rec").glob("*.mcap")
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        # Every chunk, the last one closed by close(), is in the summary.
        assert summary is not None and len(summary.chunk_indexes) == len(store)
        assert sum(1 for _ in reader.iter_messages()) == 300


def test_a_writer_kept_otherwise_is_left_as_it_is():
    class Other:
        pass

    assert not pack_chunk_indexes(Other())   # type: ignore[arg-type]
    writer = Writer(io.BytesIO())
    writer._Writer__chunk_indices.append("x")   # not a new writer's empty list
    assert not pack_chunk_indexes(writer)
    assert writer._Writer__chunk_indices == ["x"]
