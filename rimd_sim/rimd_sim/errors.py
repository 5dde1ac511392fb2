"""Exception family of the RIMD core: one tree, documented here.

Every exception class the package defines derives from :class:`RimdError`: a reason a user can act on (the core,
the recording and analysis libraries, the bring-up, the nodes, the verbs). A node or the command line catches
the whole family at its boundary and turns it into a refusal (``success = false`` with the message) or one
clear line on stderr (``rimd_sim.cli.main``, the one place: ``rimd VERB: message``, exit status 1), without
catching unrelated bugs. A library's exception (mcap, mcap_ros2, rerun, the Foxglove SDK, Dask, PyYAML) is
translated into the family where the package calls the library, so a user sees only this family.

The tree: the general kinds are defined here; module-specific classes stay in their modules (named in the
tree, with their module) and derive from one of these kinds::

    RimdError
    ├── ConfigError(key, value, rule)    a configuration value refused
    │   └── InputError(message)          a file or an option a user gave cannot be used
    │       ├── analysis.outputs.FileFormatError            a YAML file the analyses read is not what it must be
    │       ├── analysis.dynamics.fit_table.TableError      the resonance table cannot be read or holds a bad row
    │       └── ros.nodes.replay.ReplayError                the replay node cannot start as configured
    ├── CommandError                     a command (to the running model, or a verb's) refused or not carried out
    ├── IntegrationError                 the integrator cannot continue
    │   └── model.rig_model.ChatteringError                 the chattering guard fired (the valid domain's rule)
    ├── RecordingError                   a recording cannot be read, or made, as asked
    │   ├── io.crop.CropError                               a crop cannot be done as asked
    │   └── viz.mcap_source.McapError                       no rig message can be read from the file
    ├── AnalysisError                    an analysis cannot give its result from this input
    │   ├── analysis.recordings.report.ReportError          the recording holds nothing to analyse
    │   ├── analysis.identification.design.DesignError      no identification schedule fits the rig
    │   ├── analysis.identification.identify.IdentificationError   the recording cannot give what was asked
    │   └── analysis.identification.local.LocalError        a local stage cannot give its estimate
    └── UnavailableError                 something outside the package is missing, not running or not answering
        ├── io.msgdefs.MessageDefinitionError               a message or service type is not installed
        ├── analysis.executor.SchedulerError                the Dask scheduler cannot be used
        ├── runtime.playback_control.ReplayUnavailable      the replay's services did not answer
        ├── viz.sinks.SinkError                             the Rerun sink cannot be opened
        ├── viz.foxglove_sink.FoxgloveError                 the Foxglove server cannot be set up as asked
        └── viz.foxglove_sink.ServiceCallError              a service call forwarded from Foxglove failed

``tests/test_errors.py`` imports every module of the package and fails naming any exception class outside the
family. Not in the family: the operating system's own errors (``OSError``: a directory that cannot be made, a
full disk), which ``rimd_sim.cli.main`` renders in the same one line naming the file; plain ``ValueError`` and
``TypeError`` for a caller's programming mistake (a bad argument to a function, not a user's input); and
``KeyboardInterrupt``.

No mixin with a built-in exception: the family's classes derive from ``Exception`` only, through
:class:`RimdError`, so that an ``except ValueError`` (around ``float(text)``, or a library's own failure) never
swallows a configuration refusal by accident. Nothing outside the package needs a built-in base: argparse's
``type=`` callables of ``rimd_sim.cli`` raise ``argparse.ArgumentTypeError`` themselves and call nothing that
raises the family, and the ROS parameter callbacks catch ``ConfigError``/``CommandError`` by name. Catch the
family's class, not a built-in one.

Every error of the family pickles whatever its constructor's signature (:meth:`RimdError.__reduce__`), so one
raised in a worker process (the sweeps' process pools, Dask) reaches the caller as itself. Python's default
pickling calls the constructor with the message alone, which fails for :class:`ConfigError` (three arguments)
and would break the pool instead.
"""

from __future__ import annotations

from typing import Any

__all__ = ["AnalysisError", "CommandError", "ConfigError", "InputError", "IntegrationError", "RecordingError",
           "RimdError", "UnavailableError"]


def _restore(cls: type[RimdError], args: tuple, state: dict[str, Any]) -> RimdError:
    """An error of ``cls`` with ``args`` and attributes ``state``, without calling its constructor (unpickling)."""
    error = cls.__new__(cls, *args)
    error.args = args
    error.__dict__.update(state)
    return error


class RimdError(Exception):
    """Base class of every error raised by the package (the CLI prints it as one line and exits 1)."""

    def __reduce__(self) -> tuple:
        """Pickle as the message and the attributes, whatever the constructor takes (see the module docstring)."""
        return _restore, (type(self), self.args, dict(self.__dict__))


class ConfigError(RimdError):
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


class CommandError(RimdError):
    """A command was refused or could not be carried out.

    A command to the running model (motor setpoint, perturbation, ...), or a ``rimd`` verb's (the CLI prints
    the message as one line and exits 1).
    """


class IntegrationError(RimdError):
    """The integrator could not continue (step size underflow, chattering contact, non-finite state)."""


class RecordingError(RimdError):
    """A recording cannot be read at all, or made as asked; the message names the file and the reason."""


class AnalysisError(RimdError):
    """An analysis cannot give its result from this input; the message says what is missing and what to do."""


class UnavailableError(RimdError):
    """Something outside the package cannot be used: not installed, not running, not answering, or refused.

    A message definition not installed, a scheduler out of reach, a viewer or server that does not start, a
    node's service that does not answer; the message names it and the reason.
    """
