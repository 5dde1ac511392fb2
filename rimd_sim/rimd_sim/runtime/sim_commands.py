"""The rules of the simulator's commands: when a request's stamp is taken, and the book of the topic's commands.

A service request (``set_motor_frequency``, ``perturb``) names a ``start_stamp``: zero for the next block
boundary, else a stamp from now to :data:`MAX_SCHEDULE_AHEAD_S` ahead (:func:`request_time`). A command from
``/rig/motor/command`` is applied at its stamp, or at the next block boundary when the stamp is zero or already
simulated (:func:`command_time`); :class:`CommandBook` counts them for the diagnostics and for a summary line at
most every :data:`COMMAND_SUMMARY_S` (docs/control.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction

from rimd_sim.errors import CommandError
from rimd_sim.runtime.stamps import show_stamp, stamp_ns, stamp_time
from rimd_sim.settings.config import MAX_RAMP_RATE

__all__ = ["COMMAND_SUMMARY_S", "MAX_SCHEDULE_AHEAD_S", "CommandBook", "command_time", "request_time"]

#: Longest a command may be scheduled ahead of the simulation (s of simulation time).
MAX_SCHEDULE_AHEAD_S = 86_400
#: Motor commands from the topic are summed up in one log line at most this often (s of wall time), while they come.
COMMAND_SUMMARY_S = 10.0


def request_time(stamp: tuple[int, int], t0_ns: int, now: Fraction) -> Fraction | None:
    """Simulation time of a request's ``start_stamp`` ``(sec, nanosec)`` (None for zero: the next boundary).

    ``t0_ns`` is the stamp of simulation time 0, ``now`` the simulation time the rig has reached.

    Raises:
        CommandError: A stamp before the rig's start, already passed, or more than a day ahead.
    """
    sec, nanosec = stamp
    if nanosec >= 1_000_000_000:  # builtin_interfaces/Time: nanosec in [0, 1e9)
        raise CommandError(f"start_stamp.nanosec = {nanosec} refused: must be < 1000000000 "
                           "(the seconds go in start_stamp.sec)")
    ns = int(sec) * 1_000_000_000 + int(nanosec)
    if ns == 0:
        return None
    t = stamp_time(t0_ns, ns)
    rule = "must be zero (next block boundary) or a stamp from now to one day ahead in the rig's time base"
    if t < now:
        raise CommandError(f"start_stamp {sec}.{nanosec:09d} refused: already passed "
                           f"(the rig is at stamp {show_stamp(stamp_ns(t0_ns, now))}, simulation time "
                           f"{float(now):.6f} s); {rule}")
    if t - now > MAX_SCHEDULE_AHEAD_S:
        raise CommandError(f"start_stamp {sec}.{nanosec:09d} refused: {float(t - now):.6g} s "
                           f"ahead of the rig; {rule}")
    return t


def command_time(stamp: tuple[int, int], ramp_rate: float, t0_ns: int, now: Fraction) -> Fraction | None:
    """Simulation time of a topic command's ``header.stamp`` ``(sec, nanosec)`` (None for zero).

    A time before ``now`` is late: the caller applies it at the next block boundary.

    Raises:
        CommandError: A ``nanosec`` out of its range, a stamp more than a day ahead, or a ramp rate above the
            rig's bound (NaN included).
    """
    sec, nanosec = stamp
    ns = int(sec) * 1_000_000_000 + int(nanosec)
    t = None if ns == 0 else stamp_time(t0_ns, ns)
    if not 0 <= int(nanosec) < 1_000_000_000:
        raise CommandError(f"header.stamp.nanosec = {nanosec} refused: must be in [0, 1000000000)")
    if t is not None and t - now > MAX_SCHEDULE_AHEAD_S:
        raise CommandError(f"stamp {show_stamp(ns)} refused: {float(t - now):.6g} s ahead of the rig "
                           "(at most one day)")
    if not ramp_rate <= MAX_RAMP_RATE:
        raise CommandError(f"ramp_rate = {ramp_rate!r} refused: must be <= {MAX_RAMP_RATE:g} Hz/s "
                           "(0 = motor.ramp_rate)")
    return t


@dataclass
class CommandBook:
    """The counts of the motor commands taken from the topic, for the diagnostics and the periodic summary.

    Attributes:
        received: Commands taken (valid or not).
        applied: Commands the core applied (at their stamp, or at the next block boundary).
        late: Commands whose stamp was already simulated when they came (applied at the next block boundary).
        refused: Commands refused (a value out of its range, a stamp more than a day ahead).
        worst_late_s: The largest lateness (s of simulation time from the stamp to where the rig stood).
        last: The last applied command, in words.
        last_refusal: Why the last refused one was refused.
        since_summary: Commands applied since the last summary line.
        summary_at: Monotonic time of the last summary line (0: none yet).
    """

    received: int = 0
    applied: int = 0
    late: int = 0
    refused: int = 0
    worst_late_s: float = 0.0
    last: str = ""
    last_refusal: str = ""
    since_summary: int = 0
    summary_at: float = 0.0

    def took(self, detail: str) -> None:
        """The core applied a command: ``detail`` says what, and when."""
        self.applied += 1
        self.since_summary += 1
        self.last = detail

    def summary(self, clock: Callable[[], float]) -> str | None:
        """The summary line of the commands applied since the last one, at most every COMMAND_SUMMARY_S (else None).

        ``clock``: monotonic seconds, read only when commands have been applied since the last line.
        """
        if not self.since_summary:
            return None
        now = clock()
        if self.summary_at and now - self.summary_at < COMMAND_SUMMARY_S:
            return None
        span = f"in the last {now - self.summary_at:.1f} s" if self.summary_at else "since the start"
        self.summary_at = now
        line = (f"motor commands: {self.since_summary} applied {span} ({self.applied} in all; "
                f"{self.late} late, worst {self.worst_late_s * 1e3:.3f} ms; {self.refused} refused); "
                f"last: {self.last}")
        self.since_summary = 0
        return line

    def values(self) -> dict[str, str]:
        """The counts as the diagnostics' key-value pairs."""
        return {
            "motor_commands_received": str(self.received),
            "motor_commands_applied": str(self.applied),
            "motor_commands_late": str(self.late),
            "motor_commands_worst_late_ms": f"{self.worst_late_s * 1e3:.3f}",
            "motor_commands_refused": str(self.refused),
            "motor_command_last": self.last,
            "motor_command_last_refusal": self.last_refusal,
        }
