"""A controller in lockstep with the rig, offline: what the rig does with it, in one process, without ROS.

In lockstep a controller that reports its progress and sends its commands with
:class:`rimd_sim.ros.clients.motor.MotorCommander` (docs/control.md) sees the rig block by block: the rig publishes
a block, waits until the controller has finished with its messages, and applies each command the controller sent
meanwhile at the end of that block (stamp zero), or at the stamp it names. :func:`run_closed_loop` does exactly
that with the rig's own core (:class:`~rimd_sim.instruments.rig_simulator.RigSimulator`, the same configuration
and block rate), so a controller's logic can be developed and tested in process, at the core's speed, and gives
the commands and data the running rig gives it, bit for bit (``tests/ros/test_controller_example.py`` checks it
against the rig).

Each block is handed to ``decide(block)``, which answers with the commands to apply (:class:`Command`); the block
carries what the rig publishes in it: its impacts (``/rig/impact/events``), the motor state at its end
(``/rig/motor/state``), the captures (``/rig/capture/*``), the channels. A command stamped at a time already
simulated is late, as on the rig: it applies at the block's end and is marked so.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from fractions import Fraction

from rimd_sim.instruments.rig_simulator import RigSimulator, SimBlock
from rimd_sim.settings.capture import CaptureConfig
from rimd_sim.settings.config import SimConfig

__all__ = ["Applied", "Command", "run_closed_loop"]


@dataclass(frozen=True)
class Command:
    """A motor command as a controller sends it.

    Attributes:
        frequency_hz: The setpoint (Hz).
        ramp_rate: Hz/s; 0 = ``motor.ramp_rate``.
        at: The simulation time at which it applies (s); None: stamp zero, the end of the block it was decided on.
    """

    frequency_hz: float
    ramp_rate: float = 0.0
    at: Fraction | float | None = None


@dataclass(frozen=True)
class Applied:
    """A command as the rig applied it: when (s of simulation time, exact), and whether its stamp was late."""

    time: Fraction
    command: Command
    late: bool = False


def run_closed_loop(config: SimConfig, decide: Callable[[SimBlock], Sequence[Command]], until: float, *,
                    initial: Sequence[Command] = (), capture: CaptureConfig | None = None,
                    stop: Callable[[], bool] | None = None) -> list[Applied]:
    """Run the rig's core block by block up to ``until`` s, applying ``decide``'s commands where the rig would.

    Args:
        config: The rig's configuration (its ``block_rate`` cuts the blocks).
        decide: Called with each block, in order; returns the commands it decided on that block's data.
        until: Simulation time to reach (s): the run ends with the first block end at or after it.
        initial: Commands in force from the start (a controller's commands sent before it joined: the rig applies
            them at time 0, before its first block).
        capture: The triggered capture, as the rig's ``capture.*`` parameters set it (None: none).
        stop: Ends the run after the block it returns true on (a controller that has converged).

    Returns:
        The commands applied, in order.
    """
    sim = RigSimulator(config, capture=capture)
    rate = Fraction(repr(config.block_rate))
    applied = [_apply(sim, c) for c in initial]
    block = 0
    while block == 0 or block / rate < until:
        block += 1
        (out,) = sim.advance_blocks([Fraction(block) / rate])
        applied += [_apply(sim, c) for c in decide(out)]
        if stop is not None and stop():
            break
    return applied


def _apply(sim: RigSimulator, command: Command) -> Applied:
    """Schedule ``command`` where the rig applies one that comes while it waits at ``sim.time``."""
    # A stamp travels in integer nanoseconds: a float time is rounded to one, as the rig reads it.
    at = (None if command.at is None else command.at if isinstance(command.at, Fraction)
          else Fraction(round(command.at * 1e9), 1_000_000_000))
    late = at is not None and at < sim.time
    when = sim.set_motor_frequency(command.frequency_hz, command.ramp_rate, at=None if late else at,
                                   kind="motor_command")
    return Applied(when, command, late)
