"""The simulator's settings: read from the parameter values at start, and the changes a running rig takes.

The values come as ROS holds them (flat names, :data:`~rimd_sim.settings.config.PARAMETERS` for the rig and
:data:`~rimd_sim.settings.config.NODE_PARAMETERS` for the node); every refusal is a
:class:`~rimd_sim.errors.ConfigError` naming the parameter and its rule, or a sentence saying why.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from rimd_sim.errors import ConfigError
from rimd_sim.settings.config import NODE_PARAMETERS, PARAMETERS, SimConfig, SimulatorNodeSettings
from rimd_sim.settings.params import build

__all__ = ["check_time_base", "load_settings", "running_changes", "wall_clock_stamps"]


def load_settings(values: Mapping[str, Any]) -> tuple[SimConfig, SimulatorNodeSettings]:
    """The configuration and the node's settings from the node's parameter values (as ROS holds them).

    Raises:
        ConfigError: Naming the first refused parameter and its rule.
    """
    config = SimConfig.from_parameters({k: values[k] for k in PARAMETERS if k in values})
    settings = build(SimulatorNodeSettings, {k: values[k] for k in NODE_PARAMETERS if k in values})
    lockstep = settings.lockstep
    if lockstep.enabled and lockstep.window < 2.0 / config.block_rate:
        raise ConfigError("lockstep.window", lockstep.window,
                          f"must be >= two block periods (2 / block_rate = {2.0 / config.block_rate:g} s): "
                          "a consumer reports the stamp of the last block it took, which is a block behind")
    return config, settings


def wall_clock_stamps(config: SimConfig, settings: SimulatorNodeSettings) -> bool:
    """Whether the stamps are wall-clock: only at real time without lockstep."""
    return config.real_time_factor == 1.0 and not settings.lockstep.enabled


def running_changes(changes: Sequence[tuple[str, Any]]) -> tuple[dict[str, Any], str | None]:
    """The parameter changes ``(name, value)`` a running rig may take, or why they are refused (then None).

    The node's own parameters, ``use_sim_time`` and the channels' QoS are read at start only. The node refuses
    the names it does not declare and its own parameters (read-only) before they get here, so a name outside the
    rig's parameters is ``use_sim_time``: the rig's stamps follow its own clock, always. The publishers' QoS is
    set when they are created, so a change of a channel's ``reliable`` would have no effect.
    """
    accepted = {}
    for name, value in changes:
        if name not in PARAMETERS:
            return {}, (f"parameter '{name}' = {value!r} refused: read at start only, it cannot change while the "
                        "rig runs")
        if name.endswith(".reliable"):
            return {}, (f"parameter '{name}' = {value!r} refused: read at start only, the channel's QoS cannot "
                        "change while the rig runs")
        accepted[name] = value
    return accepted, None


def check_time_base(config: SimConfig, wall_clock: bool, lockstep: bool) -> None:
    """Refuse a ``real_time_factor`` that would switch the stamps' time base of a running rig.

    Raises:
        ConfigError: From 1 while the stamps are wall-clock, or to 1 without lockstep while they are simulation
            time.
    """
    if wall_clock and config.real_time_factor != 1.0:
        raise ConfigError("real_time_factor", config.real_time_factor,
                          "cannot switch from 1 while running: the stamps are wall-clock at real time "
                          "(restart the rig with another factor)")
    if not wall_clock and config.real_time_factor == 1.0 and not lockstep:
        raise ConfigError("real_time_factor", config.real_time_factor,
                          "cannot switch to 1 while running: the stamps are simulation time (restart "
                          "the rig at real time for wall-clock stamps)")
