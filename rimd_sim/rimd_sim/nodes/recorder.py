"""Node ``rimd_recorder``: records rig topics into rosbag2-compatible MCAP files (SPEC section 6).

* Discovery: every ``discovery_period`` the node lists the graph's topics and subscribes, with raw
  (serialized) subscriptions, to each topic matching one of ``topics`` (regular expressions, full match) and
  none of ``exclude``, as soon as it has a publisher. The subscription's QoS follows the publishers (reliable
  when they all are; transient local when they all are) with a deep history, and the offered profiles are
  stored with the channel, as rosbag2 does.
* The executor thread takes the subscriptions every ``POLL_PERIOD_S`` (every waiting message at once,
  :class:`rimd_sim.nodes._run.PolledSubscriptions`), stamps each message (node clock: wall time, or simulation
  time with ``use_sim_time``) and queues it; a writer thread, woken once per batch, owns the files
  (:class:`rimd_sim.recording.bag.BagWriter`), counts loss and closes a chunk at least every
  ``flush_interval`` seconds. A full queue (``queue_size`` messages) drops the newest message and counts it;
  nothing is ever dropped silently.
* Loss per topic: samples missing between consecutive blocks (``first_index`` gaps of SampleBlock and
  RigState) and queue overflows, reported in ``/diagnostics`` (1 Hz), the log, and the final summary.
* On ``~/stop``, SIGINT and SIGTERM the current file is finished (summary, indexes, rosbag2 metadata) and
  ``metadata.yaml`` is written; a SIGKILL loses at most the chunk in progress.
* Metadata in every file: the software version and recorder settings (``rimd_recording``) and the rig's
  parameters read from ``rig_node`` (``rimd_rig_parameters``) once that node answers.
* Write errors (disk full, file size limit, quota, I/O error): the first one stops the writing, never the
  node. The file keeps every complete chunk written before the error (cut back to its last complete record,
  no summary: it reads back up to there, see :mod:`rimd_sim.recording.bag`); the messages of the chunk in
  progress and every later message are counted per topic as *not written*, which is loss like any other.
  The log says it once, at ERROR, naming the path and the system's reason (and again every
  ``FAILURE_REMINDER_S`` while it lasts); ``/diagnostics`` is at ERROR (``disk full: PATH: No space left on
  device (errno 28, ENOSPC); not writing (N messages not written)``) until the writing resumes; the final
  summary lists the incomplete file and the messages not written. Services keep answering, the other nodes
  are not affected. Nothing is retried by itself (a full disk would be hammered): ``~/split``, or ``~/stop``
  then ``~/start``, clears the error and the next message opens a new file; if the disk is still full, that
  is reported the same way. SIGXFSZ is ignored, so a file size limit (``ulimit -f``) gives EFBIG, handled
  as above, instead of killing the recorder with its file unfinished.
"""

from __future__ import annotations

import os
import signal
import socket
import struct
import sys
import threading
import time
from collections import deque
from pathlib import Path
from queue import Empty, SimpleQueue
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.duration import Duration
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger

from rimd_sim import __version__
from rimd_sim.nodes._params import refuse_unnamed
from rimd_sim.nodes._run import PolledSubscriptions, PollingNode, run_node
from rimd_sim.recording.bag import BagWriter, WriteFailure
from rimd_sim.recording.cdr import BLOCK_TYPES, LossCounter, block_span
from rimd_sim.recording.msgdefs import MessageDefinitionError
from rimd_sim.recording.settings import PARAMETERS, RecorderConfigError, check_parameter, compile_patterns

__all__ = ["RecorderNode", "main"]

#: Message types whose first field is a std_msgs/Header: the recorder reads their stamp from the raw CDR
#: bytes (no deserialisation) to report in /diagnostics how far each topic has reached it.
STAMPED_TYPES = frozenset({"rimd_msgs/msg/SampleBlock", "rimd_msgs/msg/RigState", "rimd_msgs/msg/MotorState",
                           "rimd_msgs/msg/ImpactEvent", "diagnostic_msgs/msg/DiagnosticArray"})
_STAMP_LE, _STAMP_BE = struct.Struct("<iI"), struct.Struct(">iI")

NODE_NAME = "rimd_recorder"
#: Period of the takes from the subscriptions (s): the messages of one period are taken at once.
POLL_PERIOD_S = 0.02
#: The writer thread sleeps this long after the first message of a batch, then writes all that came (s).
WRITER_BATCH_S = 0.02
#: While the writing is stopped by a write error, the log reminds of it this often (s).
FAILURE_REMINDER_S = 30.0

def _duration_dict(duration: Duration) -> dict[str, int]:
    ns = duration.nanoseconds
    if ns <= 0 or ns >= 2147483647 * 1_000_000_000:
        return {"sec": 2147483647, "nsec": 4294967295}
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def qos_to_dict(qos: QoSProfile) -> dict[str, Any]:
    """An offered QoS profile (from graph discovery) in rosbag2's dictionary form."""
    return {
        "history": qos.history.name.lower(),
        "depth": int(qos.depth),
        "reliability": qos.reliability.name.lower(),
        "durability": qos.durability.name.lower(),
        "deadline": _duration_dict(qos.deadline),
        "lifespan": _duration_dict(qos.lifespan),
        "liveliness": qos.liveliness.name.lower(),
        "liveliness_lease_duration": _duration_dict(qos.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(qos.avoid_ros_namespace_conventions),
    }


class RecorderNode(PollingNode):
    """The recorder node. See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        for name, (default, description) in PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=description))
        values = {name: self.get_parameter(name).value for name in PARAMETERS}
        for name, value in values.items():
            check_parameter(name, value)
        self._p = values
        self._include = compile_patterns("topics", values["topics"])
        self._exclude = compile_patterns("exclude", values["exclude"])
        output_dir = Path(values["output_dir"]).expanduser()
        try:
            output_dir.mkdir(parents=True, exist_ok=True)
            probe = output_dir / f".rimd_recorder_probe_{os.getpid()}"
            probe.write_bytes(b"")
            probe.unlink()
        except OSError as exc:
            raise RecorderConfigError(f"output_dir: '{output_dir}' is not a writable directory "
                                      f"({exc.strerror or exc})") from None
        self.output_dir = output_dir.resolve()
        self._bag = BagWriter(self.output_dir, prefix=values["prefix"], compression=values["compression"],
                              chunk_size=values["chunk_size"],
                              max_duration_ns=round(values["max_duration"] * 1e9), max_size=values["max_size"],
                              library=f"rimd_recorder {__version__}", metadata={"rimd_recording": {
                                  "software": f"rimd_sim {__version__}",
                                  "recorder": self.get_fully_qualified_name(),
                                  "host": socket.gethostname(),
                                  "ros_distro": os.environ.get("ROS_DISTRO", "jazzy"),
                                  "rmw": rclpy.utilities.get_rmw_implementation_identifier(),
                                  "topics": " ".join(values["topics"]),
                                  "use_sim_time": str(self.get_parameter("use_sim_time").value),
                              }})
        # Shared between the executor thread and the writer thread. A SimpleQueue (C, thread-safe): the writer
        # sleeps in get() until a message comes or a flush is due, instead of polling.
        self._queue: SimpleQueue[tuple] = SimpleQueue()
        self._queue_size = values["queue_size"]
        self._recording = True
        self._paused = bool(values["start_paused"])
        self._subs: dict[str, Any] = {}
        self._handlers: dict[str, Any] = {}
        # The subscriptions are taken by a timer, every message waiting at once (nodes._run.PolledSubscriptions).
        self._polled = PolledSubscriptions(self, POLL_PERIOD_S)
        self._types: dict[str, str] = {}
        self._received: dict[str, int] = {}
        self._last_stamp: dict[str, int] = {}   # header stamp (ns) of the last message received per topic
        self._dropped: dict[str, int] = {}  # queue overflow
        self._skipped_paused = 0
        self._unknown: dict[str, str] = {}
        # Writer-thread state.
        self._loss = LossCounter()
        self._sequence: dict[str, int] = {}   # MCAP sequence number per topic (messages given to the writer)
        self._write_errors = 0                # unexpected exceptions (not OSError: the bag handles those)
        self._reported_failure: WriteFailure | None = None   # the bag's write error, once logged
        self._failure_logged_at = 0.0
        self._retry_announced = False
        self._stop = threading.Event()
        self._writer = threading.Thread(target=self._write_loop, name="rimd_recorder_writer", daemon=True)

        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        for name, handler in (("start", self._on_start), ("stop", self._on_stop), ("split", self._on_split),
                              ("pause", self._on_pause), ("resume", self._on_resume)):
            self.create_service(Trigger, f"~/{name}", handler)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._params_client = AsyncParameterClient(self, values["rig_node"]) if values["rig_node"] else None
        self._params_future = None
        self._params_done = self._params_client is None
        self.create_timer(values["discovery_period"], self._discover)
        self.create_timer(1.0, self._publish_diagnostics)
        self._writer.start()
        self.get_logger().info(f"recording {', '.join(values['topics'])} into {self.output_dir}"
                               + (" (paused: call ~/resume to start)" if self._paused else ""))


    # -- discovery and subscriptions --------------------------------------------------------------------------
    def _wanted(self, topic: str) -> bool:
        return (any(p.fullmatch(topic) for p in self._include)
                and not any(p.fullmatch(topic) for p in self._exclude))

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self._subs or topic in self._unknown or not self._wanted(topic):
                continue
            publishers = [p for p in self.get_publishers_info_by_topic(topic) if p.node_name != NODE_NAME
                          or p.node_namespace != self.get_namespace()]
            if not publishers:
                continue
            type_name = types[0]
            try:
                module, _, cls = type_name.rpartition("/")
                msg_type = getattr(__import__(module.replace("/", "."), fromlist=[cls]), cls)
            except (ImportError, AttributeError):
                self._unknown[topic] = type_name
                self.get_logger().error(f"cannot record {topic}: its type {type_name} is not installed here")
                continue
            offered = [qos_to_dict(p.qos_profile) for p in publishers]
            reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
            latched = all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000,
                             reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
            self._types[topic] = type_name
            self._received[topic] = 0
            self._queue.put(("topic", topic, type_name, offered))
            self._subs[topic] = self._polled.create(msg_type, topic, qos, self._make_handler(topic))
            self.get_logger().info(f"recording {topic} ({type_name}, "
                                   f"{'reliable' if reliable else 'best effort'})")
        self._fetch_rig_parameters()

    def _make_handler(self, topic: str):
        """Return the handler of one topic's messages, taken by :attr:`_polled` (every ``POLL_PERIOD_S``).

        It stamps the message (log time) and queues it for the writer. The stop takes what is left in every
        subscription the same way (:meth:`shutdown`).
        """
        queue = self._queue
        clock = self.get_clock()
        # The node clock: ROS time with use_sim_time, else the system clock (what clock.now() reads, without
        # building a Time object per message).
        now_ns = ((lambda: clock.now().nanoseconds) if self.get_parameter("use_sim_time").value else time.time_ns)
        received = self._received
        dropped = self._dropped
        last_stamp = self._last_stamp
        stamped = self._types.get(topic) in STAMPED_TYPES

        def accept(data: bytes, info: dict) -> None:
            received[topic] += 1
            if stamped and len(data) >= 12:   # header.stamp: the CDR's first field after the 4-byte encapsulation
                sec, nanosec = _STAMP_LE.unpack_from(data, 4) if data[1] == 1 else _STAMP_BE.unpack_from(data, 4)
                last_stamp[topic] = sec * 1_000_000_000 + nanosec
            if queue.qsize() >= self._queue_size:
                dropped[topic] = dropped.get(topic, 0) + 1
                return
            queue.put(("msg", topic, data, now_ns(), info.get("source_timestamp", 0)))

        def handler(data: bytes, info: dict) -> None:
            if not self._recording or self._paused:
                self._skipped_paused += 1
                return
            accept(data, info)

        self._handlers[topic] = handler
        return handler

    def _fetch_rig_parameters(self) -> None:
        """Ask ``rig_node`` for its parameters (list, then get), one step per discovery tick, never blocking."""
        if self._params_done:
            return
        client, future = self._params_client, self._params_future
        if future is None:
            if client.services_are_ready():
                self._params_future = client.list_parameters()
            return
        if not future.done():
            return
        response = future.result()
        if response is not None and hasattr(response, "result"):  # ListParameters answered
            self._params_names = list(response.result.names)
            self._params_future = client.get_parameters(self._params_names)
            return
        if response is not None:  # GetParameters answered
            values = {name: parameter_value_to_python(value)
                      for name, value in zip(self._params_names, response.values, strict=False)}
            self._queue.put(("metadata", "rimd_rig_parameters", {k: str(v) for k, v in sorted(values.items())}))
        self._params_done = True

    # -- writer thread ----------------------------------------------------------------------------------------
    def _write_loop(self) -> None:
        queue, bag = self._queue, self._bag
        last_flush = time.monotonic()
        interval = self._p["flush_interval"]
        batch: deque[tuple] = deque()
        while True:
            if not batch:
                try:   # sleep until an item comes or the next flush is due (at most 1 s: failure reminders)
                    first = queue.get(timeout=min(1.0, max(0.001, last_flush + interval - time.monotonic())))
                except Empty:
                    now = time.monotonic()
                    if now - last_flush >= interval:
                        self._safely(bag.flush)
                        self._check_failure()
                        last_flush = now
                    continue
                # Let the rest of the rig's block arrive, then take everything: one wake-up of this thread per
                # batch instead of one per message (each wake-up is a thread switch and a GIL hand-over).
                time.sleep(WRITER_BATCH_S)
                batch.append(first)
                while True:
                    try:
                        batch.append(queue.get_nowait())
                    except Empty:
                        break
            item = batch.popleft()
            kind = item[0]
            if kind == "stop":
                break
            if kind == "msg":
                _, topic, data, log_time, publish_time = item
                if self._types[topic] in BLOCK_TYPES:
                    try:
                        first, count = block_span(data)
                        missing = self._loss.observe(topic, first, count)
                        if missing:
                            self.get_logger().warning(f"{topic}: {missing} samples missing before index {first}")
                    except (ValueError, IndexError):
                        pass
                sequence = self._sequence[topic] = self._sequence.get(topic, 0) + 1
                # After a write error the bag only counts the message as not written (no I/O, no log line).
                self._safely(bag.write, topic, data, log_time, publish_time, sequence)
                now = time.monotonic()
                if now - last_flush >= interval:
                    self._safely(bag.flush)
                    self._check_failure()
                    last_flush = now
            elif kind == "topic":
                _, topic, type_name, offered = item
                try:
                    bag.add_topic(topic, type_name, offered)
                except MessageDefinitionError as exc:
                    self.get_logger().error(f"cannot record {topic}: {exc}")
                    self._types[topic] = "?"
            elif kind == "metadata":
                self._safely(bag.add_metadata, item[1], item[2])
            elif kind == "call":
                _, function, done, result = item
                try:
                    result.append(function())
                except Exception as exc:  # noqa: BLE001 - reported to the service caller
                    result.append(exc)
                done.set()
            if bag.failure is not self._reported_failure:   # a new write error, or cleared by ~/split
                self._check_failure()
        self._safely(bag.close)
        self._check_failure()

    def _safely(self, function, *args) -> None:  # noqa: ANN001
        """Run a writer call; an unexpected exception is counted and logged (the first 5), never fatal.

        Write errors of the disk (``OSError``) do not come here: the bag handles them (see
        :meth:`_check_failure`).
        """
        try:
            function(*args)
        except Exception as exc:  # noqa: BLE001 - a bug must not kill the writer silently
            self._write_errors += 1
            if self._write_errors <= 5:
                self.get_logger().error(f"writing the recording failed: {type(exc).__name__}: {exc}")

    def _not_written(self) -> int:
        return sum(self._bag.not_written.values())

    def _check_failure(self) -> None:
        """Log a new write error of the bag once, remind of it, and log when writing resumes (writer thread)."""
        bag, reported = self._bag, self._reported_failure
        failure = bag.failure
        now = time.monotonic()
        if failure is not None and failure is not reported:
            self._reported_failure, self._failure_logged_at, self._retry_announced = failure, now, False
            if failure.file is not None:
                kept = (f"{failure.file.path.name} keeps the {failure.file.message_count} messages written before "
                        "the error (it has no summary; it reads back up to there), "
                        f"{failure.lost_in_chunk} messages of the chunk in progress are lost")
            else:
                kept = "no file was open (the new file held nothing and was deleted)"
            self.get_logger().error(
                f"{failure.describe()}: recording stopped, the node keeps running; {kept}, and every message "
                "from now on is counted as not written. Free space, then call ~/split (or ~/stop and ~/start) "
                "to record into a new file")
        elif failure is None and reported is not None and bag.current_path is None:
            if not self._retry_announced:   # ~/split or ~/stop cleared it
                self._retry_announced = True
                self.get_logger().info(f"the {reported.headline} error is cleared: the next message recorded opens a "
                                       "new file")
        elif failure is None and reported is not None:
            self._reported_failure, self._retry_announced = None, False
            self.get_logger().info(f"writing again after the {reported.headline}: recording into {bag.current_path} "
                                   f"({self._not_written()} messages not written in all)")
        elif failure is not None and now - self._failure_logged_at >= FAILURE_REMINDER_S:
            self._failure_logged_at = now
            self.get_logger().error(f"still not recording ({failure.describe()}): {self._not_written()} messages "
                                    "not written so far; call ~/split once space is back")

    def _on_writer(self, function, timeout: float = 10.0):  # noqa: ANN001
        """Run ``function`` on the writer thread, after the messages queued before it; return its result."""
        done, result = threading.Event(), []
        self._queue.put(("call", function, done, result))
        if not done.wait(timeout):
            raise TimeoutError("the writer did not answer")
        if isinstance(result[0], Exception):
            raise result[0]
        return result[0]

    # -- services ---------------------------------------------------------------------------------------------
    def _on_start(self, request, response):  # noqa: ARG002
        if self._recording:
            response.success, response.message = False, "already recording"
            return response
        self._recording = True
        response.success, response.message = True, f"recording into {self.output_dir}"
        self.get_logger().info(response.message)
        return response

    def _on_stop(self, request, response):  # noqa: ARG002
        if not self._recording:
            response.success, response.message = False, "not recording"
            return response
        self._recording = False
        info = self._on_writer(self._bag.split)
        response.success = True
        response.message = f"stopped; finished {info.path}" if info is not None else "stopped; no file was open"
        self.get_logger().info(response.message)
        return response

    def _on_split(self, request, response):  # noqa: ARG002
        info = self._on_writer(self._bag.split)
        response.success = True
        response.message = f"finished {info.path}; the next message opens a new file" if info else "no file was open"
        self.get_logger().info(response.message)
        return response

    def _on_pause(self, request, response):  # noqa: ARG002
        if self._paused:
            response.success, response.message = False, "already paused"
        else:
            self._paused = True
            response.success, response.message = True, "paused: messages are not recorded until ~/resume"
        return response

    def _on_resume(self, request, response):  # noqa: ARG002
        if not self._paused:
            response.success, response.message = False, "not paused"
        else:
            self._paused = False
            response.success, response.message = True, "resumed"
        return response

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        """Set parameters; rclpy's parameter services come here. Every refusal names the parameter."""
        refusal = refuse_unnamed(self, parameter_list)
        return refusal if refusal is not None else super().set_parameters_atomically(parameter_list)

    def _on_set_parameters(self, params) -> SetParametersResult:  # noqa: ANN001
        for param in params:
            # use_sim_time too: switching it would change the recording's log time base in the middle of a file.
            if param.name in PARAMETERS or param.name == "use_sim_time":
                return SetParametersResult(successful=False, reason=f"{param.name} is read at start only; "
                                           "restart the recorder to change it")
        return SetParametersResult(successful=True)

    # -- reporting --------------------------------------------------------------------------------------------
    def loss_report(self) -> dict[str, dict[str, int]]:
        """Per topic: messages received, written, samples lost (first_index gaps), queue drops, not written.

        ``not_written``: messages a write error (disk full...) kept out of the files.
        """
        report = {}
        bag = self._bag
        for topic in sorted(self._types):
            report[topic] = {"received": self._received.get(topic, 0), "written": bag.written.get(topic, 0),
                             "lost_samples": self._loss.lost_samples.get(topic, 0),
                             "lost_blocks": self._loss.lost_blocks.get(topic, 0),
                             "queue_dropped": self._dropped.get(topic, 0),
                             "not_written": bag.not_written.get(topic, 0)}
        return report

    def _publish_diagnostics(self) -> None:
        report = self.loss_report()
        not_written = sum(r["not_written"] for r in report.values())
        lost = sum(r["lost_samples"] + r["queue_dropped"] for r in report.values()) + not_written
        status = DiagnosticStatus(name=f"{self.get_fully_qualified_name()}: recording",
                                  hardware_id="rimd_recorder")
        failure = self._bag.failure
        failures = self._bag.failures
        state = "paused" if self._paused else ("recording" if self._recording else "stopped")
        if failure is not None:
            # The writing stopped: ERROR until ~/split (or ~/stop) clears it and a new file opens.
            status.level = DiagnosticStatus.ERROR
            state = "not writing" if state == "recording" else state
            status.message = f"{failure.describe()}; {state} ({not_written} messages not written)"
        else:
            status.level = DiagnosticStatus.WARN if lost or self._write_errors else DiagnosticStatus.OK
            status.message = f"{state}; " + ("loss: see values" if lost else "no loss")
            if not_written:
                status.message += f" ({not_written} messages not written after a {failures[-1].headline})"
        values = {"state": state, "file": str(self._bag.current_path or ""),
                  "queue": str(self._queue.qsize()), "write_errors": str(self._write_errors),
                  "write_failure": failures[-1].describe() if failures else "",
                  "messages_written": str(sum(r["written"] for r in report.values())),
                  "messages_not_written": str(not_written),
                  "not_recorded_while_paused_or_stopped": str(self._skipped_paused),
                  "topics_of_unknown_type": " ".join(sorted(self._unknown))}
        for topic, stamp in list(self._last_stamp.items()):
            values[f"{topic} last_stamp_ns"] = str(stamp)   # how far each topic has reached the recorder
        for topic, r in report.items():
            values[f"{topic} lost_samples"] = str(r["lost_samples"])
            values[f"{topic} queue_dropped"] = str(r["queue_dropped"])
            values[f"{topic} not_written"] = str(r["not_written"])
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])   # the field is `status` (an unknown keyword is ignored)
        msg.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(msg)

    def shutdown(self) -> None:
        """Record what already reached the node, let the writer drain the queue, finish the file, print a summary.

        Every message waiting in a subscription when the stop was asked (the executor had not dispatched it
        yet: the recorder lags behind a fast rig) is taken and written, so a stop never cuts the topics at
        different times. This runs before the context is shut down (see :mod:`rimd_sim.nodes._run`).
        """
        if self._recording and not self._paused and self.context.ok():
            for topic, handler in list(self._handlers.items()):
                for _ in range(10):   # bounded: a publisher faster than the takes cannot hold the stop
                    if PolledSubscriptions.take(self._subs[topic], handler, 10_000) < 10_000:
                        break
        self._recording = False
        self._stop.set()
        self._queue.put(("stop",))   # wakes the writer; it is the last item, so everything before is written
        self._writer.join(timeout=60.0)
        bag = self._bag
        files = [f for f in bag.files if f.finished or f.error]
        lines = [f"recording finished: {len(files)} file(s) in {self.output_dir}"]
        for f in files:
            lines.append(f"  {f.path.name}: {f.message_count} messages, {f.size} bytes" + (
                f"; INCOMPLETE: {f.error}; no summary, it reads back up to there" if f.error else ""))
        for failure in bag.failures:
            lines.append(f"  WRITE FAILED: {failure.describe()}; {failure.lost_in_chunk} messages of the chunk in "
                         "progress lost, the messages after it not written")
        if bag.metadata_error is not None:
            lines.append(f"  metadata.yaml not updated: {bag.metadata_error}")
        cause = bag.failures[0].headline if bag.failures else "write error"
        for topic, r in self.loss_report().items():
            loss = r["lost_samples"] + r["queue_dropped"] + r["not_written"]
            lines.append(f"  {topic}: {r['written']} messages written; "
                         + (f"LOSS: {r['lost_samples']} samples missing (first_index gaps), "
                            f"{r['queue_dropped']} messages dropped (queue full)"
                            + (f", {r['not_written']} messages not written ({cause})" if r["not_written"] else "")
                            if loss else "no loss"))
        print("\n".join(lines), flush=True)


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``rimd_recorder`` executable (also ``rimd node recorder``)."""
    if hasattr(signal, "SIGXFSZ"):   # a file size limit then fails the write (EFBIG), reported, not fatal
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    return run_node("rimd_recorder", RecorderNode, (RecorderConfigError,), args=args,
                    refused_prefix="configuration refused: ", close=lambda node: node.shutdown())

if __name__ == "__main__":
    sys.exit(main())
