"""Exception family of the RIMD core.

Every error the product raises for a reason a user can act on derives from :class:`RimdError` (the core, the
recording and analysis libraries, the bring-up, the verbs), so a node or the command line catches the whole
family at its boundary and turns it into a refusal (``success = false`` with the message) or one clear line on
stderr (``rimd_sim.cli.main``, the one place), without catching unrelated bugs.
"""

from __future__ import annotations

__all__ = ["CommandError", "ConfigError", "InputError", "IntegrationError", "RimdError"]


class RimdError(Exception):
    """Base class of every error raised by the package."""


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


class InputError(ConfigError):
    """A file or an option given by a user cannot be used (a missing file, bad YAML with its line and column).

    A :class:`ConfigError` whose message is given whole (it is not about one parameter's value).
    """

    def __init__(self, message: str) -> None:
        self.key, self.value, self.rule = "", None, message
        Exception.__init__(self, message)


class CommandError(RimdError, ValueError):
    """A command was refused or could not be carried out.

    A command to the running model (motor setpoint, perturbation, ...), or a ``rimd`` verb's (the CLI prints
    the message as one line and exits 1).
    """


class IntegrationError(RimdError, RuntimeError):
    """The integrator could not continue (step size underflow, chattering contact, non-finite state)."""
