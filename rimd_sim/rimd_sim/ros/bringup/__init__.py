"""Bringing up the rig from a configuration, like a launch file: behind ``rimd rig``, ``rimd replay``, the plugin.

Three modules, one job each:

* :mod:`~rimd_sim.ros.bringup.plan` reads and checks a configuration and decides what to start
  (:func:`plan_rig`, :func:`plan_replay`, :class:`RigPlan`). It starts nothing and imports no rclpy: a refused
  configuration starts nothing.
* :mod:`~rimd_sim.ros.bringup.processes` starts a plan's processes, watches them and stops them in reverse order
  (:class:`Rig`, :func:`stop_process`, :class:`StopSignals`).
* :mod:`~rimd_sim.ros.bringup.resume` resumes a paused simulator once its consumers are matched (rclpy).

The consumers see sample 0 in one of two ways:

* open loop (default): the simulator starts paused and is resumed once every consumer subscribes to every rig
  topic and the simulator has matched them (:meth:`Rig.resume_when_connected`);
* lockstep (``plan_rig(lockstep=True)``): the simulator waits for its consumers by itself (``lockstep.consumers``:
  the recorder and the bridge under their node names, plus the names given), and never runs ahead of the slowest
  (docs/rig.md, "Pacing: lockstep").

This package re-exports the names of the three modules.
"""

from __future__ import annotations

from rimd_sim.ros.bringup.plan import (
    COMPOSED,
    REPLAY_NODE,
    PlannedNode,
    RigPlan,
    composed_process,
    plan_replay,
    plan_rig,
)
from rimd_sim.ros.bringup.processes import Rig, StopSignals, stop_process
from rimd_sim.ros.bringup.resume import RIG_TOPICS, resume_once_subscribed

__all__ = ["COMPOSED", "REPLAY_NODE", "RIG_TOPICS", "PlannedNode", "Rig", "RigPlan", "StopSignals",
           "composed_process", "plan_replay", "plan_rig", "resume_once_subscribed", "stop_process"]
