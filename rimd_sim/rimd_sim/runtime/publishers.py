"""The simulator's publishers: one :class:`Output` per topic, with its message type and QoS.

The node (:mod:`rimd_sim.ros.nodes.simulator`) creates one publisher per :func:`outputs` entry; the runtime
(:class:`rimd_sim.runtime.simulator.SimulatorRuntime`) sends each message on its output's key.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from rimd_sim.runtime.sim_settings import wall_clock_stamps
from rimd_sim.settings.config import SimConfig, SimulatorNodeSettings

__all__ = ["CHANNEL_TOPICS", "Output", "Qos", "default_topics", "history_depth", "outputs"]

#: Channel -> topic (the output's key), relative to the node's namespace (``/rig`` by default).
CHANNEL_TOPICS = {
    "cart_displacement": "cart/displacement",
    "rimd_displacement": "rimd/displacement",
    "rimd_acceleration": "rimd/acceleration",
    "impact_force": "impact/force",
}
#: Seconds of blocks each data publisher keeps at real time for a reliable subscriber that stalls.
REAL_TIME_HISTORY_S = 3.0


@dataclass(frozen=True)
class Qos:
    """A publisher's QoS: keep-last ``depth``, reliable or best effort, volatile or transient local (``latched``)."""

    depth: int
    reliable: bool = True
    latched: bool = False


@dataclass(frozen=True)
class Output:
    """One publisher of the node: its key (the topic, relative to the namespace unless absolute), type and QoS."""

    key: str
    type_name: str
    qos: Qos


def history_depth(config: SimConfig, settings: SimulatorNodeSettings) -> int:
    """The history of each data publisher, in messages: the blocks of some seconds, plus 10.

    At real time, :data:`REAL_TIME_HISTORY_S` of blocks: a reliable subscriber, such as the recorder, may stall
    that long without losing a block, for about 0.5 MB per 20 kHz channel (3 s of 8-byte samples). Faster than
    real time, 20 s of simulation time, which at 20x is still one second of wall time (about 3.2 MB per 20 kHz
    channel). In lockstep no consumer falls further behind than the window: twice the window and a second.
    """
    seconds = REAL_TIME_HISTORY_S if wall_clock_stamps(config, settings) else 20.0
    if settings.lockstep.enabled:
        seconds = max(1.0, 2 * settings.lockstep.window + 1.0)
    return max(10, math.ceil(config.block_rate * seconds) + 10)


def outputs(config: SimConfig, settings: SimulatorNodeSettings) -> tuple[Output, ...]:
    """The node's publishers, in the order of their per-topic diagnostics.

    ``/clock`` is reliable (compatible with the best-effort subscription of ROS time sources and with reliable
    ones), one per block, so it has the blocks' depth (a recorder that lags must not lose ticks either);
    ``faults`` and ``session`` are transient local (a late subscriber gets them).
    """
    depth = history_depth(config, settings)
    out = [Output(CHANNEL_TOPICS[ch.name], "rimd_msgs/msg/SampleBlock", Qos(depth, ch.reliable))
           for ch in config.channels]
    out += [Output("impact/events", "rimd_msgs/msg/ImpactEvent", Qos(1000)),
            Output("motor/state", "rimd_msgs/msg/MotorState", Qos(depth)),
            Output("truth", "rimd_msgs/msg/RigState", Qos(depth)),
            Output("faults", "rimd_msgs/msg/FaultEvent", Qos(1000, latched=True)),
            Output("/clock", "rosgraph_msgs/msg/Clock", Qos(depth)),
            Output("session", "rimd_msgs/msg/RigSession", Qos(1, latched=True))]
    if settings.capture.enabled:
        out += [Output("capture/force", "rimd_msgs/msg/Capture", Qos(200)),
                Output("capture/acceleration", "rimd_msgs/msg/Capture", Qos(200))]
    return tuple(out)


def default_topics(keys: Sequence[str], namespace: str = "/rig") -> dict[str, str]:
    """Key -> topic as ROS resolves it in ``namespace`` (absolute keys stay), without remapping."""
    return {k: k if k.startswith("/") else f"{namespace.rstrip('/')}/{k}" for k in keys}
