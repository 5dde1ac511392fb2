"""The composed rig's DDS writes: off the pacing thread when it runs fast, and without the GIL.

In the composed rig (:mod:`rimd_sim.ros.nodes.composed`) one interpreter runs the simulator, the recorder and the
Rerun bridge, so every thread's Python work shares one GIL. A DDS write of an already serialized message costs
tens of microseconds per matched reader in another process (Fast DDS publishes synchronously: the sample goes to
the reader's transport in the caller's thread), and rclpy's ``Publisher.publish`` of bytes holds the GIL all that
time (its ``publish_raw`` does not release it). With an external reader of the five block topics, a rig in
lockstep far faster than real time would spend a large share of its pacing thread's time there, on the path that
decides how fast the rig runs, while the machine's other core idles (docs/benchmarks.md, "Lockstep").

:class:`Outbox` takes those writes. A message is written at once on the caller's thread, by rclpy's ``publish``, when
nothing is waiting to be written (a rig at real time: one block every 10 ms, no thread hand-over). When the pacing
thread sends several blocks at once or its passes come back to back (faster than real time), the whole batch goes,
in order, to a thread of its own that writes while the pacing thread computes the next blocks, and that thread
calls ``rcl_publish_serialized_message`` (the C function rclpy calls) through ctypes, which releases the GIL during
the call (:func:`gil_free_writer`); where that is not possible (no ``librcl`` to be found, an rclpy without the
publisher's address) it uses rclpy's ``publish`` too. The messages of all topics keep one order: a batch waits
behind the ones before it, and a message is written on the caller's thread only when none is waiting.

``bench_lockstep.py`` compares the speeds with and without the thread, with and without an external lockstep
reader (docs/benchmarks.md, "Lockstep").

The thread writes everything waiting for it in one call (:func:`write_many`): a compiled loop (numba, ``nogil``)
calls rcl's function for each message, so the GIL is released and taken back once per call instead of once per
message. Taken back while another thread runs Python, the GIL costs up to the interpreter's switch interval
(5 ms): with one call per message, the thread would spend most of its wall time waiting for the GIL and fall
behind an external reader of a rig far faster than real time.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import math
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from queue import SimpleQueue
from typing import Any

from rimd_sim.errors import RimdError
from rimd_sim.runtime.threads import named_thread

__all__ = ["GilFreeWriter", "Outbox", "PublishFailed", "compile_batch_writer", "gil_free_writer", "write_many"]

#: A batch of at least this many messages goes to the outbox's thread (one block of the rig is about eight).
THREAD_BATCH = 12
#: So does a batch that comes less than this long after the one before (s): the pacing loop runs back to back (in
#: lockstep faster than real time, one block per pass); at real time its passes are a block (10 ms) apart.
BACK_TO_BACK_S = 0.003
#: At most this many batches (passes of the pacing loop, up to 10 blocks each) wait for the thread; the next flush
#: waits for room. Without a bound a rig running free (open loop) faster than the external readers' writes would
#: queue its blocks without end; with it, it runs at the writes' speed, as if it wrote them itself. In lockstep a
#: pass is often one block, so a bound of a few batches would hold back a rig with an external reader
#: (docs/benchmarks.md, "Lockstep", compares bounds).
MAX_WAITING = 64


class PublishFailed(RimdError):
    """A DDS write failed (rcl's return code and the topic in the message)."""


class _Allocator(ctypes.Structure):
    """``rcutils_allocator_t``: not used by a publish (rclpy passes a zero one too)."""

    _fields_ = [("allocate", ctypes.c_void_p), ("deallocate", ctypes.c_void_p), ("reallocate", ctypes.c_void_p),
                ("zero_allocate", ctypes.c_void_p), ("state", ctypes.c_void_p)]


class _SerializedMessage(ctypes.Structure):
    """``rcl_serialized_message_t`` (``rcutils_uint8_array_t``)."""

    _fields_ = [("buffer", ctypes.c_char_p), ("buffer_length", ctypes.c_size_t),
                ("buffer_capacity", ctypes.c_size_t), ("allocator", _Allocator)]


def _loaded_library(name: str) -> ctypes.CDLL | None:
    """The shared library ``name`` this process has loaded (rclpy loaded it), else the loader's own search."""
    try:
        for line in Path("/proc/self/maps").read_text().splitlines():
            path = line.rpartition(" ")[2]
            if path.endswith("/" + name):
                return ctypes.CDLL(path)
    except OSError:
        pass
    try:
        return ctypes.CDLL(name)
    except OSError:
        return None


@functools.cache
def _rcl_functions() -> tuple[Any, Any]:
    """The C functions ``rcl_publish_serialized_message`` and ``rcutils_reset_error`` (None each where not found)."""
    rcl, rcutils = _loaded_library("librcl.so"), _loaded_library("librcutils.so")
    publish = getattr(rcl, "rcl_publish_serialized_message", None) if rcl is not None else None
    reset = getattr(rcutils, "rcutils_reset_error", None) if rcutils is not None else None
    if publish is not None:
        publish.argtypes = [ctypes.c_void_p, ctypes.POINTER(_SerializedMessage), ctypes.c_void_p]
        publish.restype = ctypes.c_int32
    if reset is not None:
        reset.argtypes, reset.restype = [], None
    return publish, reset


class GilFreeWriter:
    """Writes serialized bytes on one publisher with the GIL released (:func:`gil_free_writer` makes one).

    Called with one message, it writes it (one ctypes call); :func:`write_many` writes many messages of such
    writers in one call. For one thread at a time (it reuses one message header). The publisher's handle is held
    during each write, as rclpy does, so that the publisher cannot be destroyed under it.
    """

    def __init__(self, publish: Any, reset: Any, handle: Any, address: int, topic: str) -> None:
        self._publish, self._reset = publish, reset
        self.handle, self.address, self.topic = handle, address, topic
        self._header = _SerializedMessage()
        self._ref = ctypes.byref(self._header)

    def __call__(self, data: bytes) -> None:
        """Write one message (one ctypes call, the GIL released during it)."""
        header = self._header
        header.buffer = data
        header.buffer_length = header.buffer_capacity = len(data)
        with self.handle:
            ret = self._publish(self.address, self._ref, None)
        header.buffer = None
        if ret:
            self.failed(ret)

    def failed(self, ret: int) -> None:
        """Raise :class:`PublishFailed` for rcl's return code ``ret`` (rcl's error state reset)."""
        if self._reset is not None:
            self._reset()
        raise PublishFailed(f"publishing on {self.topic} failed (rcl_publish_serialized_message returned {ret})")


def gil_free_writer(publisher: Any) -> GilFreeWriter | None:
    """A :class:`GilFreeWriter` of ``publisher``; None where it cannot be made (no librcl, no publisher address)."""
    publish, reset = _rcl_functions()
    handle: Any = getattr(publisher, "handle", None)
    address = getattr(handle, "pointer", None)
    if publish is None or not address:
        return None
    return GilFreeWriter(publish, reset, handle, address, publisher.topic_name)


def _write_all(publish, targets, buffer, offsets, lengths, header):  # pragma: no cover - compiled (numba)
    """Call ``publish(targets[i], &header, NULL)`` for each message ``i``, ``header`` pointing at its bytes.

    ``header`` is an ``rcl_serialized_message_t`` laid out as uint64 words (buffer, length, capacity, then the
    allocator, left zero). Returns (index of the first failed write, its return code), or (-1, 0).
    """
    base = buffer.ctypes.data
    address = header.ctypes.data
    for i in range(len(targets)):
        header[0] = base + offsets[i]
        header[1] = lengths[i]
        header[2] = lengths[i]
        ret = publish(targets[i], address, 0)
        if ret != 0:
            return i, ret
    return -1, 0


#: ``rcl_publish_serialized_message`` as the compiled loop calls it: its three pointers passed as 64-bit words.
_PUBLISH_WORDS = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t)


@functools.cache
def _batch_kernel() -> tuple[Any, Any] | None:
    """The compiled loop (numba, without the GIL, in numba's cache) and rcl's function for it; None where not."""
    publish, _ = _rcl_functions()
    address = ctypes.cast(publish, ctypes.c_void_p).value if publish is not None else None
    if not address or ctypes.sizeof(ctypes.c_void_p) != 8:
        return None
    try:
        import numba

        kernel = numba.njit(nogil=True, cache=True)(_write_all)
    except Exception:  # noqa: BLE001 - without numba the writes go one call per message
        return None
    return kernel, _PUBLISH_WORDS(address)


def compile_batch_writer() -> bool:
    """Compile :func:`write_many`'s loop into numba's cache without writing anything (``rimd warmup``)."""
    import numba
    import rclpy  # noqa: F401 - loads librcl, where rcl's function is looked up

    found = _batch_kernel()
    if found is None:
        return False
    kernel, publish = found
    words, u8, i64 = numba.types.uint64[::1], numba.types.uint8[::1], numba.types.int64[::1]
    kernel.compile((numba.typeof(publish), words, u8, i64, i64, words))
    return True


def write_many(items: Sequence[tuple[GilFreeWriter, bytes]]) -> None:
    """Write every message, in order, each on its writer's publisher, releasing the GIL once for all of them.

    A thread that takes the GIL back after each write waits, while another thread runs Python, up to the
    interpreter's switch interval (5 ms), so with the pacing thread busy, one call per message caps the outbox's
    thread at a fraction of the rate a fast rig needs. Here one compiled loop (numba, ``nogil``) calls rcl's
    ``rcl_publish_serialized_message`` for each message, on the bytes joined into one buffer. Raises
    :class:`PublishFailed` for the first write that fails (the ones before it are written, none after it). Where
    the loop cannot be compiled, one call per message.
    """
    found = _batch_kernel() if len(items) > 1 else None
    if found is None:
        for write, data in items:
            write(data)
        return
    import numpy as np

    kernel, publish = found
    n = len(items)
    chunks = [data for _, data in items]
    lengths = np.fromiter(map(len, chunks), np.int64, n)
    offsets = np.zeros(n, np.int64)
    np.cumsum(lengths[:-1], out=offsets[1:])
    targets = np.fromiter((w.address for w, _ in items), np.uint64, n)
    buffer = np.frombuffer(b"".join(chunks), np.uint8)
    header = np.zeros(8, np.uint64)
    with contextlib.ExitStack() as held:   # each publisher held once for the whole batch, as rclpy holds it
        for handle in {id(w.handle): w.handle for w, _ in items}.values():
            held.enter_context(handle)
        failed, ret = kernel(publish, targets, buffer, offsets, lengths, header)
    if failed >= 0:
        items[failed][0].failed(ret)


class Outbox:
    """DDS writes in order, on the caller's thread or on a thread of its own (see the module docstring).

    The caller (the pacing thread) :meth:`send` s messages and :meth:`flush` es after each pass (another thread may
    :meth:`send` too: its message goes at that flush); a flush waits while ``max_waiting`` batches wait for the
    thread. :meth:`close` writes what is waiting and stops the thread. Only the caller flushes, so a publisher is
    never written from two threads at once. A failed write on the thread is raised by the next :meth:`flush` (the
    caller stops as if it had failed itself).
    """

    def __init__(self, name: str = "rimd-dds", thread_batch: int = THREAD_BATCH, gap: float = BACK_TO_BACK_S,
                 max_waiting: int = MAX_WAITING) -> None:
        self._pending: list[tuple[tuple[Callable[[bytes], None], Callable[[bytes], None]], bytes]] = []
        self._queue: SimpleQueue[list | None] = SimpleQueue()
        self._idle = threading.Event()
        self._idle.set()
        self._lock = threading.Lock()
        self._waiting = 0   # batches handed to the thread and not written yet
        self._room = threading.BoundedSemaphore(max_waiting)
        self._thread_batch = thread_batch
        self._gap = gap
        self._last_flush = -math.inf   # monotonic time of the last flush that had messages
        self._name = name
        self._thread: threading.Thread | None = None
        self.failure: BaseException | None = None
        self.threaded = 0   # messages written on the thread (what the tests check)
        self.inline = 0     # messages written on the caller's thread

    @staticmethod
    def writer(publisher: Any) -> tuple[Callable[[bytes], None], Callable[[bytes], None]]:
        """How ``publisher`` is written: on the caller's thread (rclpy's ``publish``), on the outbox's thread.

        The caller's thread keeps the GIL through the write: released and taken back, the GIL can cost the pacing
        thread up to the interpreter's switch interval (5 ms) per message while another thread runs Python. The
        outbox's thread releases it (:func:`gil_free_writer`) where it can: its waits for it delay no one.
        """
        return publisher.publish, gil_free_writer(publisher) or publisher.publish

    def send(self, writer: tuple[Callable[[bytes], None], Callable[[bytes], None]], data: bytes) -> None:
        """Queue one message for ``writer`` (:meth:`writer`), from any thread (written at the next :meth:`flush`)."""
        with self._lock:
            self._pending.append((writer, data))

    def flush(self) -> None:
        """Write what was sent since the last flush: here when it is small and nothing waits, else on the thread."""
        if self.failure is not None:
            raise self.failure
        with self._lock:
            batch, self._pending = self._pending, []
        if not batch:
            return
        now = time.monotonic()
        back_to_back, self._last_flush = now - self._last_flush < self._gap, now
        if len(batch) < self._thread_batch and not back_to_back and self._idle.is_set():
            self.inline += len(batch)
            for (write, _), data in batch:
                write(data)
            return
        if self._thread is None:
            self._thread = named_thread(self._loop, self._name)
            self._thread.start()
        self._room.acquire()   # at most max_waiting batches wait: a rig faster than its writes slows to them
        with self._lock:
            self._waiting += 1
            self._idle.clear()
        self._queue.put(batch)

    def drain(self, timeout: float = 5.0) -> bool:
        """Flush and wait until every message is written (or ``timeout`` s); whether it was."""
        self.flush()
        return self._idle.wait(timeout)

    def close(self, timeout: float = 5.0) -> None:
        """Write what is waiting, stop the thread (idempotent). A failure is left in :attr:`failure`."""
        try:
            self.flush()
        except BaseException:  # noqa: BLE001 - kept in self.failure: the caller is stopping anyway
            pass
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join(timeout)
            self._thread = None

    def _loop(self) -> None:
        stopping = False
        while not stopping:
            taken = [self._queue.get()]
            while not self._queue.empty():   # everything waiting goes in one write: one GIL release for all
                taken.append(self._queue.get_nowait())
            stopping = taken[-1] is None   # close() puts it after its flush: nothing comes after it
            batches = [batch for batch in taken if batch is not None]
            try:
                if self.failure is None and batches:
                    self._write([message for batch in batches for message in batch])
            except BaseException as exc:  # noqa: BLE001 - raised on the caller's thread by its next flush
                self.failure = exc
            finally:
                with self._lock:
                    self._waiting -= len(batches)
                    if not self._waiting:
                        self._idle.set()
                for _ in batches:
                    self._room.release()

    def _write(self, messages: list[tuple[tuple[Callable[[bytes], None], Callable[[bytes], None]], bytes]]) -> None:
        """Write on this thread, in order: the runs of GIL-free writers' messages each in one call."""
        run: list[tuple[GilFreeWriter, bytes]] = []
        for (_, write), data in messages:
            if isinstance(write, GilFreeWriter):
                run.append((write, data))
                continue
            if run:
                write_many(run)
                run = []
            write(data)
        if run:
            write_many(run)
        self.threaded += len(messages)
