"""A run's identity, as the simulator publishes it on ``/rig/session`` (``rimd_msgs/msg/RigSession``).

Each start and each reset opens a run: a new ``run_id``, its reason, a sequence number, the stamp of its first
sample, the seed, the configuration's hash (:func:`config_hash`) and the stamps' time base.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

from rimd_sim.io.cdr_write import encode_session
from rimd_sim.settings.config import SimConfig

__all__ = ["SESSION_FRAME", "Session", "config_hash"]

#: Stamp frame of the run's identity, and the hardware id of the simulator's diagnostics.
SESSION_FRAME = "rimd_virtual_rig"


def config_hash(config: SimConfig) -> str:
    """SHA-256 of the configuration's parameters in canonical JSON (sorted keys): the run's configuration id."""
    text = json.dumps(config.to_parameters(), sort_keys=True, default=list, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class Session:
    """One run's identity, as ``rimd_msgs/msg/RigSession`` carries it (``start_stamp`` in ns)."""

    run_id: str
    reason: str
    sequence: int
    start_stamp: int
    simulation_time: float
    time_base: str
    real_time_factor: float
    lockstep: bool
    seed: int
    config_hash: str
    node: str

    def encode(self) -> bytes:
        """The serialized ``rimd_msgs/msg/RigSession`` (header stamped at the start stamp)."""
        return encode_session(self, SESSION_FRAME)
