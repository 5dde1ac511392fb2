"""Exception family of the RIMD core.

Every error the core raises derives from :class:`RimdError`, so a node or a command can catch the whole
family at its boundary and turn it into a refusal (``success = false`` with the message) or one clear line
on stderr, without catching unrelated bugs.
"""

from __future__ import annotations

__all__ = ["CommandError", "ConfigError", "IntegrationError", "RimdError"]


class RimdError(Exception):
    """Base class of every error raised by :mod:`rimd_sim.core`."""


class ConfigError(RimdError, ValueError):
    """A configuration value was refused.

    Attributes:
        key: The parameter name (ROS form, for example ``contact.stiffness``).
        value: The value that was refused.
        rule: The rule it broke, in words (for example ``must be finite and > 0``).
    """

    def __init__(self, key: str, value: object, rule: str) -> None:
        self.key = key
        self.value = value
        self.rule = rule
        super().__init__(f"parameter '{key}' = {value!r} refused: {rule}")


class CommandError(RimdError, ValueError):
    """A command to the running model (motor setpoint, perturbation, ...) was refused."""


class IntegrationError(RimdError, RuntimeError):
    """The integrator could not continue (step size underflow, chattering contact, non-finite state)."""
