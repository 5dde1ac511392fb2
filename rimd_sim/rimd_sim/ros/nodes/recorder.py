"""Node ``rimd_recorder``: records rig topics into rosbag2-compatible MCAP files (docs/recording.md).

* Discovery: every ``discovery_period`` the node lists the graph's topics and subscribes, with raw
  (serialized) subscriptions, to each topic matching one of ``topics`` (regular expressions, full match) and
  none of ``exclude``, as soon as it has a publisher. The subscription's QoS follows the publishers (reliable
  when they all are; transient local when they all are) with a deep history, and the offered profiles are
  stored with the channel, as rosbag2 does.
* The executor thread takes the subscriptions every ``POLL_PERIOD_S`` (every waiting message at once,
  :class:`rimd_sim.ros.nodes.polling.PolledSubscriptions`), stamps each message (node clock: wall time, or simulation
  time with ``use_sim_time``) and hands it to a :class:`rimd_sim.runtime.recorder.RecordingSession` (no ROS):
  its writer thread, woken once per batch, owns the files (:class:`rimd_sim.io.bag.BagWriter`), counts
  loss and closes a chunk at least every ``flush_interval`` seconds. A full queue (``queue_size`` messages)
  drops the newest message and counts it; nothing is ever dropped silently.
* Lockstep (docs/rig.md): when a rig or a replay in lockstep listens on ``/rig/progress``, the recorder joins
  under its node name once it has subscribed to every topic it records and DDS has matched them, and reports
  after each written batch how far each topic is written (:class:`rimd_sim.ros.clients.progress.ProgressReporter`).
* Loss per topic: samples missing between consecutive blocks (``first_index`` gaps of SampleBlock and
  RigState) and queue overflows, reported in ``/diagnostics`` (1 Hz), the log, and the final summary.
* On ``~/stop``, SIGINT and SIGTERM the current file is finished (summary, indexes, rosbag2 metadata) and
  ``metadata.yaml`` is written; a SIGKILL loses at most the chunk in progress.
* ``stop_at`` (integer ns, settable while it runs): every message stamped at or after it is left out and a
  sample block that straddles it is cut there (:meth:`rimd_sim.runtime.recorder.RecordingSession.set_stop_at`),
  so the recording ends at that stamp on every topic however late the node is stopped; the files carry it in
  the ``rimd_stop`` metadata record. ``rimd experiment`` sets it to the end of its last step.
* Metadata in every file: the software version and recorder settings (``rimd_recording``) and the rig's
  parameters read from ``rig_node`` (``rimd_rig_parameters``) once that node answers.
* Write errors (disk full, file size limit, quota, I/O error): the first one stops the writing, never the
  node. The file keeps every complete chunk written before the error (cut back to its last complete record,
  no summary: it reads back up to there, see :mod:`rimd_sim.io.bag`); the messages of the chunk in
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

import functools
import os
import signal
import socket
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.duration import Duration
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from std_srvs.srv import Trigger

from rimd_sim import __version__
from rimd_sim.io.bag import BagWriter
from rimd_sim.io.cdr import HEADER_FIRST_TYPES, header_stamp
from rimd_sim.ros.clients.progress import PROGRESS_TOPIC, ProgressReporter
from rimd_sim.ros.nodes.feed import DirectProgress, InProcessFeed
from rimd_sim.ros.nodes.polling import PolledSubscriptions, PollingNode
from rimd_sim.runtime.recorder import RecordingSession, StopRefused
from rimd_sim.settings.params import build
from rimd_sim.settings.recording import (
    PARAMETERS,
    PROGRESS_STAMP_KEY,
    RecorderConfigError,
    RecorderSettings,
    compile_patterns,
)

__all__ = ["PROGRESS_STAMP_KEY", "RecorderNode", "main"]

#: Message types whose stamp the recorder reads from the raw CDR bytes (no deserialisation) to report how far each
#: topic is written (/diagnostics, lockstep progress).
STAMPED_TYPES = HEADER_FIRST_TYPES


NODE_NAME = "rimd_recorder"
#: Period of the takes from the subscriptions (s): the messages of one period are taken at once. It follows the
#: traffic (:class:`~rimd_sim.ros.nodes.polling.PollPeriod`): POLL_PERIOD_S when messages come fast (lockstep, a
#: rig faster than real time), up to POLL_LONGEST_S when they come slowly (a rig at real time).
POLL_PERIOD_S = 0.01
POLL_LONGEST_S = 0.05
#: The writer thread sleeps this long after the first message of a batch, then writes all that came (s).
WRITER_BATCH_S = 0.01
#: History of each subscription (messages): what may wait between two takes.
SUBSCRIPTION_DEPTH = 10000
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

    NODE_NAME = NODE_NAME
    REFUSED = (RecorderConfigError,)
    REFUSED_PREFIX = "configuration refused: "

    def __init__(self, feed: InProcessFeed | None = None, **kwargs: Any) -> None:
        """Declare, check the output directory, start the session.

        Args:
            feed: In the composed rig (:mod:`rimd_sim.ros.nodes.composed`): the simulator's topics come from it,
                in this process (the others by discovery as usual), and the lockstep progress goes to it.
            kwargs: As rclpy's ``Node`` takes them.
        """
        super().__init__(**kwargs)
        self._p: RecorderSettings = build(RecorderSettings, self.declare(PARAMETERS))  # ConfigError: refused
        p = self._p
        self._include = compile_patterns("topics", p.topics)
        self._exclude = compile_patterns("exclude", p.exclude)
        output_dir = Path(p.output_dir).expanduser()
        try:
            output_dir.mkdir(parents=True, exist_ok=True)
            probe = output_dir / f".rimd_recorder_probe_{os.getpid()}"
            probe.write_bytes(b"")
            probe.unlink()
        except OSError as exc:
            raise RecorderConfigError("output_dir", str(output_dir), f"must be a writable directory "
                                      f"({exc.strerror or exc})") from None
        self.output_dir = output_dir.resolve()
        bag = BagWriter(self.output_dir, prefix=p.prefix, compression=p.compression, chunk_size=p.chunk_size,
                        max_duration_ns=round(p.max_duration * 1e9), max_size=p.max_size,
                        library=f"rimd_recorder {__version__}", metadata={"rimd_recording": {
                            "software": f"rimd_sim {__version__}",
                            "recorder": self.get_fully_qualified_name(),
                            "host": socket.gethostname(),
                            "ros_distro": os.environ.get("ROS_DISTRO", "jazzy"),
                            "rmw": rclpy.utilities.get_rmw_implementation_identifier(),
                            "topics": " ".join(p.topics),
                            "use_sim_time": str(self.get_parameter("use_sim_time").value),
                        }})
        self._session = RecordingSession(bag, queue_size=p.queue_size, flush_interval=p.flush_interval,
                                         batch_delay=WRITER_BATCH_S, reminder=FAILURE_REMINDER_S, log=self._log,
                                         on_written=self._on_written, in_lockstep=lambda: self._progress.ever_joined)
        self._recording = True
        self._paused = p.start_paused
        self._subs: dict[str, Any] = {}
        self._handlers: dict[str, Any] = {}
        # The subscriptions are taken by a timer, every message waiting at once (nodes.polling.PolledSubscriptions).
        self._polled = PolledSubscriptions(self, POLL_PERIOD_S, longest=POLL_LONGEST_S)
        self._last_stamp: dict[str, int] = {}   # header stamp (ns) of the last message received per topic
        self._written_stamp: dict[str, int] = {}   # and written (writer thread)
        self._skipped_paused = 0
        self._unknown: dict[str, str] = {}
        self._progress: ProgressReporter | DirectProgress = (
            ProgressReporter(self, self.get_name(), ready=self._lockstep_ready) if feed is None
            else feed.progress(self.get_name()))
        if feed is not None:
            self._take_from(feed)

        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        for name, handler in (("start", self._on_start), ("stop", self._on_stop), ("split", self._on_split),
                              ("pause", self._on_pause), ("resume", self._on_resume)):
            self.create_service(Trigger, f"~/{name}", handler)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._params_client = AsyncParameterClient(self, p.rig_node) if p.rig_node else None
        self._params_future: Future | None = None
        self._params_done = self._params_client is None
        self.create_timer(p.discovery_period, self._discover)
        self.create_timer(1.0, self._publish_diagnostics)
        self._session.start()
        if p.stop_at:
            self._session.set_stop_at(p.stop_at)
            self.get_logger().info(f"stop_at {p.stop_at} ns: messages stamped at or after it are left out")
        self.get_logger().info(f"recording {', '.join(p.topics)} into {self.output_dir}"
                               + (" (paused: call ~/resume to start)" if self._paused else ""))

    def _log(self, level: str, line: str) -> None:
        self.log(level, line)

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
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=SUBSCRIPTION_DEPTH,
                             reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
            self._session.add_topic(topic, type_name, offered)
            assert self._polled is not None   # made in __init__
            self._subs[topic] = sub = self._polled.create(msg_type, topic, qos, self._make_handler(topic, type_name),
                                                          lost=functools.partial(self._session.transport_lost, topic))
            self._progress.add_subscription(sub)
            self.get_logger().info(f"recording {topic} ({type_name}, "
                                   f"{'reliable' if reliable else 'best effort'})")
        self._fetch_rig_parameters()

    def _take_from(self, feed: InProcessFeed) -> None:
        """Record the wanted topics of the simulator in this process from ``feed`` (discovery leaves them alone)."""
        assert self._polled is not None   # made in __init__
        for topic, fed in sorted(feed.topics.items()):
            if not self._wanted(topic):
                continue
            self._session.add_topic(topic, fed.type_name, [qos_to_dict(q) for q in fed.offered])
            handler = self._make_handler(topic, fed.type_name)
            self._subs[topic] = sub = self._polled.attach(feed.subscribe(topic, SUBSCRIPTION_DEPTH), handler)
            self._progress.add_subscription(sub)
            reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in fed.offered)
            self.get_logger().info(f"recording {topic} ({fed.type_name}, "
                                   f"{'reliable' if reliable else 'best effort'}, in this process)")

    def _lockstep_ready(self) -> bool:
        """Whether it subscribes to every topic it records of each lockstep publisher (those on /rig/progress).

        Only then may it join: the publisher would go on without it having those topics otherwise.
        """
        for info in self.get_subscriptions_info_by_topic(PROGRESS_TOPIC):
            try:
                topics = self.get_publisher_names_and_types_by_node(info.node_name, info.node_namespace)
            except Exception:  # the node left the graph meanwhile
                return False
            if any(self._wanted(t) and t not in self._subs and t not in self._unknown for t, _ in topics):
                return False
        return True

    def _make_handler(self, topic: str, type_name: str):
        """Return the handler of one topic's messages, taken by :attr:`_polled` (every ``POLL_PERIOD_S``).

        It stamps the message (log time) and queues it for the writer. The stop takes what is left in every
        subscription the same way (:meth:`shutdown`).
        """
        put = self._session.put
        clock = self.get_clock()
        # The node clock: ROS time with use_sim_time, else the system clock (what clock.now() reads, without
        # building a Time object per message).
        now_ns = ((lambda: clock.now().nanoseconds) if self.get_parameter("use_sim_time").value else time.time_ns)
        last_stamp = self._last_stamp
        stamped = type_name in STAMPED_TYPES

        def handler(data: bytes, info: dict) -> None:
            if not self._recording or self._paused:
                self._skipped_paused += 1
                return
            stamp = header_stamp(data) if stamped else None
            if stamp is not None:
                last_stamp[topic] = stamp
            put(topic, data, now_ns(), info.get("source_timestamp", 0), stamp)

        self._handlers[topic] = handler
        return handler

    def _on_written(self, stamps: dict[str, int]) -> None:
        """After each batch the writer wrote (writer thread): how far each topic is written, for lockstep."""
        self._written_stamp.update(stamps)
        for topic, stamp in stamps.items():
            self._progress.done(stamp, topic=topic)
        if isinstance(self._progress, DirectProgress):   # in the composed rig: the batch's last progress now
            self._progress.flush()

    def _fetch_rig_parameters(self) -> None:
        """Ask ``rig_node`` for its parameters (list, then get), one step per discovery tick, never blocking."""
        if self._params_done:
            return
        client, future = self._params_client, self._params_future
        assert client is not None   # else _params_done
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
            self._session.add_metadata("rimd_rig_parameters", {k: str(v) for k, v in sorted(values.items())})
        self._params_done = True

    # -- services ---------------------------------------------------------------------------------------------
    def _on_start(self, request, response):
        if self._recording:
            response.success, response.message = False, "already recording"
            return response
        self._recording = True
        response.success, response.message = True, f"recording into {self.output_dir}"
        self.get_logger().info(response.message)
        return response

    def _on_stop(self, request, response):
        if not self._recording:
            response.success, response.message = False, "not recording"
            return response
        self._recording = False
        info = self._session.split()
        response.success = True
        response.message = f"stopped; finished {info.path}" if info is not None else "stopped; no file was open"
        self.get_logger().info(response.message)
        return response

    def _on_split(self, request, response):
        info = self._session.split()
        response.success = True
        response.message = f"finished {info.path}; the next message opens a new file" if info else "no file was open"
        self.get_logger().info(response.message)
        return response

    def _on_pause(self, request, response):
        if self._paused:
            response.success, response.message = False, "already paused"
        else:
            self._paused = True
            response.success, response.message = True, "paused: messages are not recorded until ~/resume"
        return response

    def _on_resume(self, request, response):
        if not self._paused:
            response.success, response.message = False, "not paused"
        else:
            self._paused = False
            response.success, response.message = True, "resumed"
        return response

    def _on_set_parameters(self, params) -> SetParametersResult:  # noqa: ANN001
        stop = None
        for param in params:
            if param.name == "stop_at":
                try:
                    stop = PARAMETERS["stop_at"].validate(param.value)
                except RecorderConfigError as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
                continue
            # use_sim_time too: switching it would change the recording's log time base in the middle of a file.
            if param.name in PARAMETERS or param.name == "use_sim_time":
                return SetParametersResult(successful=False, reason=f"{param.name} is read at start only; "
                                           "restart the recorder to change it")
        if stop is not None:
            try:   # applied by the writer after every message queued before it
                self._session.set_stop_at(stop or None)
            except (StopRefused, TimeoutError) as exc:
                return SetParametersResult(successful=False, reason=str(exc))
            self.get_logger().info(f"stop_at {stop} ns: messages stamped at or after it are left out" if stop
                                   else "stop_at 0: no stop")
        return SetParametersResult(successful=True)

    # -- reporting --------------------------------------------------------------------------------------------
    def loss_report(self) -> dict[str, dict[str, int]]:
        """Per topic: messages received, written, samples lost (first_index gaps), queue drops, not written."""
        return {topic: {"received": r.received, "written": r.written, "lost_samples": r.lost_samples,
                        "lost_blocks": r.lost_blocks, "queue_dropped": r.queue_dropped, "not_written": r.not_written}
                for topic, r in self._session.loss_report().items()}

    def _publish_diagnostics(self) -> None:
        session, bag = self._session, self._session.bag
        report = session.loss_report()
        not_written = sum(r.not_written for r in report.values())
        lost = sum(r.lost for r in report.values())
        status = DiagnosticStatus(name=f"{self.get_fully_qualified_name()}: recording",
                                  hardware_id="rimd_recorder")
        failure, failures = bag.failure, bag.failures
        state = "paused" if self._paused else ("recording" if self._recording else "stopped")
        if failure is not None:
            # The writing stopped: ERROR until ~/split (or ~/stop) clears it and a new file opens.
            status.level = DiagnosticStatus.ERROR
            state = "not writing" if state == "recording" else state
            status.message = f"{failure.describe()}; {state} ({not_written} messages not written)"
        else:
            status.level = DiagnosticStatus.WARN if lost or session.write_errors else DiagnosticStatus.OK
            status.message = f"{state}; " + ("loss: see values" if lost else "no loss")
            if not_written:
                status.message += f" ({not_written} messages not written after a {failures[-1].headline})"
        values = {"state": state, "file": str(bag.current_path or ""),
                  "queue": str(session.queued), "write_errors": str(session.write_errors),
                  "write_failure": failures[-1].describe() if failures else "",
                  "messages_written": str(sum(r.written for r in report.values())),
                  "messages_not_written": str(not_written),
                  "not_recorded_while_paused_or_stopped": str(self._skipped_paused),
                  "topics_of_unknown_type": " ".join(sorted(self._unknown)),
                  "lockstep": (f"joined as {self._progress.name}" if self._progress.joined else "not joined")}
        for topic, stamp in list(self._written_stamp.items()):
            values[topic + PROGRESS_STAMP_KEY] = str(stamp)   # how far each topic is written
        for topic, r in report.items():
            values[f"{topic} written"] = str(r.written)
            values[f"{topic} lost_samples"] = str(r.lost_samples)
            values[f"{topic} queue_dropped"] = str(r.queue_dropped)
            values[f"{topic} not_written"] = str(r.not_written)
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])   # the field is `status` (an unknown keyword is ignored)
        msg.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(msg)

    def finish(self) -> None:
        """At the stop (:meth:`RimdNode.finish`): :meth:`shutdown`."""
        self.shutdown()

    def shutdown(self) -> None:
        """Record what already reached the node, let the writer drain the queue, finish the file, print a summary.

        Every message waiting in a subscription when the stop was asked (the executor had not dispatched it
        yet: the recorder lags behind a fast rig) is taken and written, so a stop never cuts the topics at
        different times. This runs before the context is shut down (see :mod:`rimd_sim.ros.nodes.base`).
        """
        if self._recording and not self._paused and self.context.ok():
            for topic, handler in list(self._handlers.items()):
                for _ in range(10):   # bounded: a publisher faster than the takes cannot hold the stop
                    if PolledSubscriptions.take(self._subs[topic], handler, 10_000) < 10_000:
                        break
        self._recording = False
        self._session.close()
        if self.context.ok():
            self._progress.leave()   # everything is written: a rig in lockstep stops waiting for the recorder
        print("\n".join(self._session.summary()), flush=True)


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``rimd_recorder`` executable (also ``rimd node recorder``)."""
    if hasattr(signal, "SIGXFSZ"):   # a file size limit then fails the write (EFBIG), reported, not fatal
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    return RecorderNode.main(args)


if __name__ == "__main__":
    sys.exit(main())
