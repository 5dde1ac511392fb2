"""One exception family: every exception class of the package derives from RimdError, and crosses processes whole.

The tree is documented in ``rimd_sim/rimd_sim/errors.py``; the CLI renders the family in one place
(``rimd_sim.cli.main``; the sweep of every verb with bad files is in tests/cli/test_cli.py).
"""

from __future__ import annotations

import importlib
import inspect
import pickle
import pkgutil

import pytest

import rimd_sim
from rimd_sim import cli
from rimd_sim.errors import ConfigError, InputError, RimdError

#: The built-in bases a class of the family may have: none but Exception (no ValueError/RuntimeError mixin).
PLAIN_BASES = {Exception, BaseException, object}


def _package_exceptions() -> dict[str, type[BaseException]]:
    """Every exception class defined in the package (``module.Class``), after importing every module."""
    found: dict[str, type[BaseException]] = {}
    failed = []
    for info in pkgutil.walk_packages(rimd_sim.__path__, "rimd_sim."):
        try:
            module = importlib.import_module(info.name)
        except Exception as exc:  # noqa: BLE001 - reported below: an unimportable module hides its classes
            failed.append(f"{info.name}: {type(exc).__name__}: {exc}")
            continue
        for name, value in vars(module).items():
            if inspect.isclass(value) and issubclass(value, BaseException) and value.__module__ == module.__name__:
                found[f"{module.__name__}.{name}"] = value
    assert not failed, "modules that cannot be imported (their exception classes cannot be checked):\n" + \
        "\n".join(failed)
    return found


EXCEPTIONS = _package_exceptions()


def test_the_walk_finds_the_package_s_exceptions():
    """The walk reaches every layer (a walk that found nothing would pass the tests below)."""
    layers = {name.split(".")[1] for name in EXCEPTIONS}
    assert {"errors", "io", "analysis", "runtime", "viz", "ros"} <= layers, sorted(EXCEPTIONS)
    assert len(EXCEPTIONS) >= 20, sorted(EXCEPTIONS)


def test_every_exception_class_of_the_package_is_in_the_family():
    offenders = sorted(f"{name} ({', '.join(b.__name__ for b in cls.__mro__[1:])})"
                       for name, cls in EXCEPTIONS.items() if not issubclass(cls, RimdError))
    assert not offenders, "exception classes outside rimd_sim.errors.RimdError:\n" + "\n".join(offenders)


def test_no_class_of_the_family_is_also_a_builtin_exception():
    """``except ValueError`` (around ``float(text)``, or a library call) must not swallow a configuration refusal."""
    def builtin_bases(cls: type) -> list[str]:
        return [b.__name__ for b in cls.__mro__ if b not in PLAIN_BASES and not issubclass(b, RimdError)]

    mixed = sorted(f"{name}: also {', '.join(builtin_bases(cls))}" for name, cls in EXCEPTIONS.items()
                   if issubclass(cls, RimdError) and builtin_bases(cls))
    assert not mixed, "family classes with a built-in exception as a base:\n" + "\n".join(mixed)
    with pytest.raises(ConfigError):
        try:
            raise ConfigError("gap", -1.0, "must be >= 0")
        except ValueError:
            pytest.fail("a ConfigError was caught as a ValueError")


def _instance(cls: type[RimdError]) -> RimdError:
    try:
        return cls("the message, one line")
    except TypeError:
        return cls("contact.stiffness", -1.0, "must be > 0")


@pytest.mark.parametrize("name", sorted(n for n, c in EXCEPTIONS.items() if issubclass(c, RimdError)))
def test_every_error_of_the_family_pickles_as_itself(name):
    """A worker process (the sweeps' pools, Dask) sends its error back pickled: an error that failed to unpickle
    (a ConfigError has three constructor arguments) would break the pool instead of reaching the user."""
    error = _instance(EXCEPTIONS[name])
    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is type(error) and str(copy) == str(error) and vars(copy) == vars(error)


def test_a_config_error_keeps_its_key_value_and_rule_across_processes():
    copy = pickle.loads(pickle.dumps(ConfigError("gap", -1.0, "must be >= 0")))
    assert (copy.key, copy.value, copy.rule, str(copy)) == ("gap", -1.0, "must be >= 0",
                                                            "parameter 'gap' = -1.0 refused: must be >= 0")
    copy = pickle.loads(pickle.dumps(InputError("x.yaml cannot be read")))
    assert isinstance(copy, ConfigError) and copy.rule == "x.yaml cannot be read"


def test_the_cli_renders_the_family_and_os_errors_in_one_line():
    assert cli.error_line("crop", ConfigError("gap", -1.0, "must be >= 0")) == \
        "rimd crop: parameter 'gap' = -1.0 refused: must be >= 0"
    assert cli.error_line("sweep", NotADirectoryError(20, "Not a directory", "/tmp/f/out")) == \
        "rimd sweep: /tmp/f/out: Not a directory"
    assert cli.error_line("crop", OSError(28, "No space left on device")) == "rimd crop: No space left on device"
    assert cli.error_line("analyze", RimdError("first line\n  second line\n")) == \
        "rimd analyze: first line; second line"


@pytest.mark.parametrize("error", [RimdError("refused"), FileNotFoundError(2, "No such file or directory", "x")])
def test_main_prints_one_line_and_exits_1_for_the_family_and_os_errors(monkeypatch, capsys, error):
    def failing_main(args):
        raise error

    monkeypatch.setattr("rimd_sim.cli.verbs.info.main", failing_main)
    assert cli.main(["info"]) == 1
    err = capsys.readouterr().err
    assert err == cli.error_line("info", error) + "\n" and err.count("\n") == 1


def test_main_lets_a_bug_through():
    """Not a user's error: the traceback is what a developer needs."""
    def buggy_main(args):
        raise ZeroDivisionError("a bug")

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("rimd_sim.cli.verbs.info.main", buggy_main)
        with pytest.raises(ZeroDivisionError):
            cli.main(["info"])
