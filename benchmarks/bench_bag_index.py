"""Memory an MCAP file's chunk index takes in the recorder while the file is written (docs/recording.md, "Recorder").

An MCAP summary indexes every chunk, so a writer keeps one entry per chunk until the file is finished; the
recorder closes a chunk at least every ``flush_interval`` (1 s): 3,600 entries per hour at real time. This writes
--hours of such chunks (one message on each of the rig's recorded topics per chunk, into a stream that keeps
nothing), once with mcap's own list of ``ChunkIndex`` objects and once packed
(:class:`rimd_sim.io.bag.PackedChunkIndexes`, what the recorder uses), alternately --rounds times, and prints the
Python memory held per chunk (tracemalloc, after a collection) and per hour at real time, and the time
``finish()`` takes to write the summary. Deterministic (no DDS, no timing in the memory figures).

Run (after ``source env.sh``): python benchmarks/bench_bag_index.py [--hours 2] [--rounds 2]
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time
import tracemalloc

from mcap.writer import CompressionType, Writer

from rimd_sim.io.bag import pack_chunk_indexes

#: The rig's recorded topics (config/rimd.yaml): one channel each.
TOPICS = ("/clock", "/diagnostics", "/rig/cart/displacement", "/rig/faults", "/rig/impact/events", "/rig/impact/force",
          "/rig/motor/state", "/rig/rimd/acceleration", "/rig/rimd/displacement", "/rig/session", "/rig/truth",
          "/rig/capture/force")


class Discard:
    """A stream that counts what it is given and keeps none of it."""

    def __init__(self) -> None:
        self.count = 0

    def write(self, data) -> int:
        self.count += len(data)
        return len(data)

    def tell(self) -> int:
        return self.count

    def flush(self) -> None:
        pass


def run(packed: bool, chunks: int) -> tuple[float, float]:
    """Bytes held per chunk after ``chunks`` chunks, and the seconds ``finish`` took."""
    gc.collect()
    tracemalloc.start()
    writer = Writer(Discard(), chunk_size=768 * 1024, compression=CompressionType.NONE)   # type: ignore[arg-type]
    if packed and not pack_chunk_indexes(writer):
        raise SystemExit("this mcap keeps its chunk indexes otherwise: nothing to compare")
    writer.start(profile="ros2", library="bench")
    schema = writer.register_schema("pkg/msg/Thing", "ros2msg", b"float64 x")
    channels = [writer.register_channel(topic, "cdr", schema) for topic in TOPICS]
    t0 = 1_795_000_000_000_000_000
    base = None
    for chunk in range(chunks):
        for k, channel in enumerate(channels):
            t = t0 + chunk * 1_000_000_000 + k * 1_000
            writer.add_message(channel, t, b"x" * 64, t, chunk)
        writer.flush()
        if chunk == 99:   # the writer's fixed part (schemas, channels, buffers) is not the index
            gc.collect()
            base = tracemalloc.get_traced_memory()[0]
    gc.collect()
    held = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    start = time.perf_counter()
    writer.finish()
    assert base is not None
    return (held - base) / (chunks - 100), time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hours", type=float, default=2.0, help="hours of chunks at real time (3,600 per hour)")
    parser.add_argument("--rounds", type=int, default=2, help="alternate rounds of the two writers")
    args = parser.parse_args()
    chunks = int(args.hours * 3600)
    figures: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
    for r in range(args.rounds):
        for packed in ((False, True) if r % 2 == 0 else (True, False)):
            figures[packed].append(run(packed, chunks))
    print(f"{chunks} chunks ({args.hours:g} h at real time, one chunk per flush_interval of 1 s), "
          f"{len(TOPICS)} channels, {args.rounds} rounds alternately")
    for packed, name in ((False, "mcap's list of ChunkIndex"), (True, "packed (the recorder)")):
        per_chunk = statistics.median(f[0] for f in figures[packed])
        finish = statistics.median(f[1] for f in figures[packed])
        print(f"  {name:26s}: {per_chunk:7.0f} bytes per chunk = {per_chunk * 3600 / 1e6:5.2f} MB per hour at real "
              f"time; finish() {finish * 1e3:6.1f} ms")
    ratio = statistics.median(f[0] for f in figures[False]) / statistics.median(f[0] for f in figures[True])
    print(f"  ratio: {ratio:.1f}x less memory per chunk packed")


if __name__ == "__main__":
    main()
