"""What the simulator's runtime hands its caller: answers, diagnostic statuses, pacing steps.

A service's :class:`Answer`, a diagnostic :class:`Status`, and the :class:`Step` one pass of the pacing loop asks
for: plain data, which the node maps onto ROS messages.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["ERROR", "OK", "WARN", "Answer", "Status", "Step"]

#: Diagnostic levels (diagnostic_msgs/DiagnosticStatus).
OK, WARN, ERROR = 0, 1, 2


@dataclass(frozen=True)
class Answer:
    """A service's answer: ``stamp_ns`` when it takes effect (None: no stamp), ``frequency_hz`` the setpoint."""

    success: bool
    message: str
    stamp_ns: int | None = None
    frequency_hz: float | None = None


@dataclass(frozen=True)
class Status:
    """One ``diagnostic_msgs/DiagnosticStatus``: level (:data:`OK`, :data:`WARN`, :data:`ERROR`), texts, values."""

    name: str
    level: int
    message: str
    hardware_id: str
    values: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Step:
    """What one pass of the pacing loop asks of its caller.

    Attributes:
        wait: Seconds to wait before the next pass (0: go on at once); the runtime's ``wake`` event ends it sooner.
        report: Publish the diagnostics now (a lockstep hold to report).
        stopped: The loop is over (the model cannot continue, or the caller is no longer alive).
    """

    wait: float = 0.0
    report: bool = False
    stopped: bool = False
