"""Motor commands on ``/rig/motor/command`` for a Python node: a controller's one object (docs/control.md).

::

    from rimd_sim.ros.clients.motor import MotorCommander
    from rimd_sim.ros.clients.progress import ProgressReporter

    class MyController(Node):
        def __init__(self):
            super().__init__("my_controller")
            self.events = self.create_subscription(ImpactEvent, "/rig/impact/events", self.on_impact, 1000)
            self.progress = ProgressReporter(self, "my_controller", subscriptions=[self.events])
            self.motor = MotorCommander(self, self.progress)     # before the node spins

        def on_impact(self, msg):
            if ...:                                               # the decision, on what it has taken
                self.motor.command(3.8)                           # stamp zero: where the rig waits for it
            self.progress.done(msg.header.stamp, self.events)     # after the commands it led to

What :class:`MotorCommander` does for you:

* it publishes ``rimd_msgs/msg/MotorCommand`` (reliable, volatile, keep last 1000: :data:`COMMAND_QOS`) with your
  consumer name, instance and a running ``sequence``, and counts each one in the reporter's next report
  (``ConsumerProgress.commands``); in lockstep the rig takes that report only once it has received as many
  commands, so a command and the report after it cannot cross (DDS orders no two topics);
* it makes the reporter a controller's (:meth:`ProgressReporter.take_control`): the rig stops after each block that
  brought you a message until you have finished with it, and a command with stamp zero applies exactly there,
  at the end of the block you decided on: the same run whatever the load, one block of dead time at most;
* a command given before the rig's command reader has matched the writer (at start: the initial setpoint) waits
  in a queue and goes out once it has matched; the reporter joins only after that, so the rig knows of it before
  its first block and applies it at the start.

Without a reporter (a rig at real time, or not in lockstep) the commands go out the same way, stamped as given;
the rig applies each at its stamp, or at the next block boundary when the stamp is zero or already simulated (a
late command: counted in the rig's ``/diagnostics``).

Like :mod:`rimd_sim.ros.clients.progress`, this module imports rclpy, ``rimd_msgs`` and the standard library
only, so a controller does not load the twin's numerical stack.
"""

from __future__ import annotations

from collections import deque
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from rimd_msgs.msg import MotorCommand
from rimd_sim.ros.clients.progress import ProgressReporter

__all__ = ["COMMAND_QOS", "COMMAND_TOPIC", "RIG_NODE", "MotorCommander"]

#: Where the rig takes motor commands.
COMMAND_TOPIC = "/rig/motor/command"
#: QoS of the command writer (and of the rig's reader): reliable (a lost command would change the run), volatile
#: (a rig started later must not apply old commands), deep enough for a burst of commands at any rate.
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
#: The name of the node that takes the commands (the simulator): a command waits until it has matched its reader.
RIG_NODE = "rimd_simulator"


class MotorCommander:
    """Publishes motor commands; given the consumer's reporter, counted in its progress (module docstring).

    Args:
        node: The controller's node (a publisher and a timer are created on it).
        progress: The consumer's :class:`ProgressReporter` (lockstep); None for a rig not in lockstep with it.
        topic: The command topic.
        rig_node: The node name of the command reader waited for before the first command goes out.
    """

    def __init__(self, node: Node, progress: ProgressReporter | None = None, *, topic: str = COMMAND_TOPIC,
                 rig_node: str = RIG_NODE) -> None:
        self._node = node
        self._progress = progress
        self._rig_node = rig_node
        self._pub = node.create_publisher(MotorCommand, topic, COMMAND_QOS)
        self._queue: deque[tuple[float, float, int]] = deque()
        self._seen = False   # the rig's reader has matched the writer once (then a count is enough)
        #: The last command's ``sequence`` (per instance of the reporter, when there is one).
        self.sequence = 0
        if progress is not None:
            progress.take_control(self.ready)
        self._timer = node.create_timer(0.02, self._flush)

    @property
    def queued(self) -> int:
        """Commands given but not published yet (the rig's reader has not matched the writer)."""
        return len(self._queue)

    def command(self, frequency_hz: float, ramp_rate: float = 0.0, stamp: Any = 0) -> None:
        """Ramp the motor to ``frequency_hz`` at ``ramp_rate`` Hz/s (0: the rig's ``motor.ramp_rate``) from ``stamp``.

        Args:
            frequency_hz: The new setpoint (Hz).
            ramp_rate: Hz/s; 0 = the rig's default.
            stamp: When the ramp starts, in the rig's time base: a ``builtin_interfaces/Time`` or integer
                nanoseconds; 0 = the next block boundary (in lockstep with a reporter: where the rig waits for
                this controller, the end of the block it decided on).
        """
        ns = stamp if isinstance(stamp, int) else int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
        self._queue.append((float(frequency_hz), float(ramp_rate), ns))
        self._flush()

    def ready(self) -> bool:
        """Whether the writer has matched the rig's reader and every command given so far is published.

        The reporter joins only then, so the graph is asked before the first command: a reader that appears later
        (a recorder subscribing to every rig topic) cannot hold a command back, uncounted, while the run goes on.
        """
        self._flush()
        return not self._queue and self._matched()

    def _matched(self) -> bool:
        """Whether the writer has matched the rig's reader: every reader the graph shows, the rig's among them.

        Asked of the graph until it is so once; from then on (a command at every block) the count of matched
        readers says it: a rig that restarts shows as none.
        """
        if self._seen and self._pub.get_subscription_count() > 0:
            return True
        infos = self._node.get_subscriptions_info_by_topic(self._pub.topic_name)
        self._seen = (any(i.node_name == self._rig_node for i in infos)
                      and self._pub.get_subscription_count() >= len(infos))
        return self._seen

    def _flush(self) -> None:
        """Publish the queued commands once the rig's reader has matched the writer."""
        if not self._queue or not self._matched():
            return
        while self._queue:
            frequency_hz, ramp_rate, ns = self._queue.popleft()
            self.sequence = (self._progress.commands if self._progress is not None else self.sequence) + 1
            msg = MotorCommand(frequency_hz=frequency_hz, ramp_rate=ramp_rate, sequence=self.sequence)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
            if self._progress is not None:
                msg.consumer, msg.instance = self._progress.name, self._progress.instance
            self._pub.publish(msg)
            if self._progress is not None:
                self._progress.command_sent()
