"""The lockstep's settings: parameters ``lockstep.*`` of the simulator and the replay.

The lockstep itself (:class:`~rimd_sim.runtime.pacing.Lockstep`) is part of the runtime.
"""

from __future__ import annotations

from dataclasses import dataclass

from rimd_sim.errors import ConfigError
from rimd_sim.settings.params import group, param

__all__ = ["ON_TIMEOUT", "LockstepGroup", "LockstepSettings"]

#: The policies of a consumer that has held the run ``timeout`` seconds without progress.
ON_TIMEOUT = ("wait", "drop")


def _names(values: tuple[str, ...]) -> bool:
    return all(v.strip() == v and v for v in values) and len(set(values)) == len(values)


@dataclass(frozen=True)
class LockstepSettings:
    """The lockstep of a publisher: parameters ``lockstep.*`` of the simulator and the replay (read at start)."""

    enabled: bool = param(False, "lockstep: publish data time t only once every consumer has finished with the "
                                 "data up to t - lockstep.window (the run goes as fast as its slowest consumer)",
                          read_only=True)
    consumers: tuple[str, ...] = param((), "names of the consumers waited for, before the first block and all "
                                           "along (the `consumer` of their /rig/progress reports)",
                                       rule="a list of distinct non-empty names without surrounding spaces",
                                       check=_names, breaks=(("a", "a"), (" a",)), read_only=True,
                                       relation="at least one when lockstep.enabled is true")
    window: float = param(1.0, "how far a consumer may lag behind the publisher (data time)", unit="s", gt=0,
                          le=3600, read_only=True)
    timeout: float = param(10.0, "seconds a consumer may hold the run without progress before lockstep.on_timeout "
                                 "applies", unit="s", ge=0, le=1e6, read_only=True)
    on_timeout: str = param("wait", "what a consumer silent for lockstep.timeout gets: wait (keep holding; the "
                                    "debugger case) or drop (go on without it until it reports again)",
                            choices=ON_TIMEOUT, read_only=True)

    def __post_init__(self) -> None:
        """Rules between the fields."""
        if self.enabled and not self.consumers:
            raise ConfigError("lockstep.consumers", list(self.consumers),
                              "must name at least one consumer when lockstep.enabled is true")

    @property
    def window_ns(self) -> int:
        """The window in integer nanoseconds."""
        return round(self.window * 1e9)


@dataclass(frozen=True)
class LockstepGroup:
    """The lockstep as a group of a node's parameters (``lockstep.*``)."""

    lockstep: LockstepSettings = group(LockstepSettings, "lockstep.")
