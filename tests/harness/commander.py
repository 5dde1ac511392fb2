"""A node that commands the rig's motor at every block, for tests/ros/test_motor_command.py.

``python tests/harness/commander.py OUT.json --count N [--lead S] [--lockstep NAME]``: on each ``/rig/motor/state``
(one per block) it publishes one ``MotorCommand`` on ``/rig/motor/command`` through
:class:`rimd_sim.ros.clients.motor.MotorCommander`, stamped at that state's stamp plus ``--lead`` seconds, with a
setpoint that differs from the one before: a command per block, 100 a second of simulation time. With
``--lockstep NAME`` it reports its progress on the motor state as a controller (the rig waits for it at every
block). Once it has given ``N`` commands and seen the motor state of the block of the last one's stamp and the
next, it writes what it sent and what the motor states said (JSON: ``commands`` as [stamp ns, Hz], ``states`` as
[stamp ns, setpoint Hz]) and exits 0; 1 after ``--timeout`` s of wall time.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from rimd_msgs.msg import MotorState
from rimd_sim.ros.clients.motor import MotorCommander
from rimd_sim.ros.clients.progress import ProgressReporter


def setpoint(k: int) -> float:
    """The ``k``-th command's setpoint (Hz): never the one before it."""
    return 3.75 + 0.01 * (k % 11)


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("out")
    parser.add_argument("--count", type=int, required=True, help="commands to give, one per motor state")
    parser.add_argument("--lead", type=float, default=0.005, help="stamp = the motor state's stamp + this (s)")
    parser.add_argument("--lockstep", default="", help="report progress under this name, as a controller")
    parser.add_argument("--timeout", type=float, default=120.0)
    args = parser.parse_args()

    rclpy.init()
    node = Node("commander")
    executor = EventsExecutor()
    executor.add_node(node)
    commands: list[tuple[int, float]] = []
    states: list[tuple[int, float]] = []
    lead = round(args.lead * 1e9)

    def on_state(msg: MotorState) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        states.append((stamp, msg.frequency_setpoint))
        if len(commands) < args.count:
            commands.append((stamp + lead, setpoint(len(commands))))
            motor.command(commands[-1][1], 1000.0, commands[-1][0])
        if reporter is not None:
            reporter.done(msg.header.stamp, sub)

    sub = node.create_subscription(MotorState, "/rig/motor/state", on_state,
                                   QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    reporter = ProgressReporter(node, args.lockstep, subscriptions=[sub]) if args.lockstep else None
    motor = MotorCommander(node, reporter)

    def finished() -> bool:   # the states up to the block after the one of the last command's stamp
        return len(commands) == args.count and bool(states) and states[-1][0] >= commands[-1][0] + 20_000_000

    deadline = time.monotonic() + args.timeout
    while not finished() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    with open(args.out, "w") as f:
        json.dump({"commands": commands, "states": states}, f)
    if reporter is not None:
        reporter.leave()
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0 if finished() else 1


if __name__ == "__main__":
    sys.exit(main())
