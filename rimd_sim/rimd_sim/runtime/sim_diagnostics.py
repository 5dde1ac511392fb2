"""The pieces of the simulator's ``/diagnostics`` that stand on their own: lateness, lockstep holders, faults.

:meth:`rimd_sim.runtime.simulator.SimulatorRuntime.diagnostics` assembles them with the pacing state into its two
statuses, ``<node>: pacing`` and ``<node>: faults``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Sequence
from typing import Any

from rimd_sim.runtime.session import SESSION_FRAME
from rimd_sim.runtime.sim_answers import OK, WARN, Status

__all__ = ["Lateness", "faults_status", "holders_text", "lockstep_values"]


class Lateness:
    """How late the last ``size`` blocks left (s), and the overruns: blocks later than one block period."""

    def __init__(self, size: int = 1000) -> None:
        self.recent: deque[float] = deque(maxlen=size)
        self.overruns = 0

    def add(self, late: float, period: float) -> None:
        """One block left ``late`` s after it was due; ``period``: the block period (s)."""
        self.recent.append(late)
        if late > period:
            self.overruns += 1

    def percentiles(self) -> tuple[float, float]:
        """The median and the 99th percentile of the recent lateness (s; 0 before the first block)."""
        lat = sorted(self.recent)
        p50 = lat[len(lat) // 2] if lat else 0.0
        p99 = lat[min(len(lat) - 1, int(0.99 * len(lat)))] if lat else 0.0
        return p50, p99


def holders_text(holders: Iterable[Any], now: float) -> str:
    """The lockstep consumers that hold the run, in words: how far each is done, when it was last heard.

    ``holders``: the pacer's consumer states (:meth:`rimd_sim.runtime.pacing.Lockstep.holders`); ``now``: the
    monotonic clock (s).
    """
    parts = []
    for c in holders:
        heard = "never heard" if c.last_heard is None else f"last heard {now - c.last_heard:.1f} s ago"
        done = "not joined" if c.done_ns is None else f"done through {c.done_ns / 1e9:.6f} s"
        if c.awaiting is not None:   # a controller's report counts commands that have not come
            done += f", its report counts {c.awaiting[0]} commands, {c.awaiting[1]} received"
        parts.append(f"{c.name} ({done}, {heard}" + (", timed out" if c.timed_out else "") + ")")
    return ", ".join(parts) or "nobody"


def lockstep_values(consumers: Iterable[Any]) -> dict[str, str]:
    """Each lockstep consumer's progress and state, as the diagnostics' key-value pairs."""
    values = {}
    for c in consumers:
        values[f"lockstep {c.name} done_through_s"] = "" if c.done_ns is None else f"{c.done_ns / 1e9:.6f}"
        values[f"lockstep {c.name} state"] = (
            "left" if c.left else "dropped" if c.dropped else "timed out" if c.timed_out
            else "not joined" if c.done_ns is None else "joined")
    return values


def faults_status(name: str, active: Sequence[Any], events_published: int) -> Status:
    """The ``<name>: faults`` status: the faults in force (``active``), and the fault events published."""
    faults = {f"fault_{f.number}": (
        f"{f.kind} on {f.channel} from simulation time {float(f.start):.6f} s, "
        + (f"duration {float(f.duration):g} s" if f.duration else "until cleared")
        + f", magnitude {f.magnitude:g}") for f in active}
    faults["fault_events_published"] = str(events_published)
    return Status(f"{name}: faults", WARN if active else OK,
                  (f"{len(active)} fault(s) active: " + ", ".join(f"{f.kind} on {f.channel}" for f in active))
                  if active else "no fault active", SESSION_FRAME, faults)
