"""The ``rimd_rig`` fixture's settings: the ROS domain range it leases from and how long it waits for a rig.

Each setting comes from its environment variable, which wins, else from its ini key in the pytest configuration,
else from its default:

* the domain range: ``RIMD_DOMAIN_RANGE``, the ini key ``rimd_domain_range`` (``FIRST-LAST``, ``51-80``), default
  1-100 (:func:`configured_domain_range`);
* the ready timeout (s): ``RIMD_READY_TIMEOUT``, the ini key ``rimd_ready_timeout``, default
  :data:`DEFAULT_READY_TIMEOUT_S` (:func:`configured_ready_timeout`).

A refused value raises :class:`rimd_sim.errors.InputError` naming where it came from. This module needs no pytest
at run time: it reads the configuration through ``config.getini`` alone, and the plugin
(:mod:`rimd_sim.ros.testing`) registers the two ini keys.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from rimd_sim.errors import InputError

if TYPE_CHECKING:
    import pytest

__all__ = ["DEFAULT_READY_TIMEOUT_S", "DOMAIN_ID_MAX", "DOMAIN_ID_MIN", "DOMAIN_RANGE_ENV", "DOMAIN_RANGE_INI",
           "READY_TIMEOUT_ENV", "READY_TIMEOUT_INI", "ROS_DOMAIN_ID_LIMIT", "configured_domain_range",
           "configured_ready_timeout", "parse_domain_range", "parse_ready_timeout"]

#: The domain ids leased when no range is configured (0 is left to people).
DOMAIN_ID_MIN = 1
DOMAIN_ID_MAX = 100
#: The largest ROS domain id: with Fast DDS's default ports (7400 + 250 x id + offsets) a larger one has no UDP port.
ROS_DOMAIN_ID_LIMIT = 232
#: The domain range's environment variable (wins) and ini key (``FIRST-LAST``).
DOMAIN_RANGE_ENV = "RIMD_DOMAIN_RANGE"
DOMAIN_RANGE_INI = "rimd_domain_range"
#: The ready timeout's environment variable (wins) and ini key (seconds).
READY_TIMEOUT_ENV = "RIMD_READY_TIMEOUT"
READY_TIMEOUT_INI = "rimd_ready_timeout"
#: Default of the ready timeout (s). It covers a first run on an empty numba cache on a slow 2-core machine, when
#: the simulator compiles its kernels before it is ready, with a margin (docs/testing.md).
DEFAULT_READY_TIMEOUT_S = 120.0

#: ``FIRST-LAST`` or ``ID``, blanks allowed around each part.
_RANGE = re.compile(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?")


def parse_domain_range(text: str, source: str = DOMAIN_RANGE_ENV) -> tuple[int, int]:
    """A domain range as written (``51-80``; ``7``: that id alone): (first, last), both leased.

    Args:
        text: The range.
        source: Where it was given, for the message (``RIMD_DOMAIN_RANGE``, ``rimd_domain_range in pytest.ini``).

    Raises:
        InputError: Not ``FIRST-LAST`` with ``0 <= FIRST <= LAST <= 232``; the message names the source and the rule.
    """
    rule = (f"must be FIRST-LAST (for example 51-80), ROS domain ids with 0 <= FIRST <= LAST <= "
            f"{ROS_DOMAIN_ID_LIMIT}")
    match = _RANGE.fullmatch(text)
    if match is None:
        raise InputError(f"{source} = {text!r} refused: {rule}")
    first = int(match.group(1))
    last = int(match.group(2)) if match.group(2) is not None else first
    if first > last:
        raise InputError(f"{source} = {text!r} refused: reversed ({first} > {last}); {rule}")
    if last > ROS_DOMAIN_ID_LIMIT:
        raise InputError(f"{source} = {text!r} refused: {last} is beyond the largest ROS domain id, "
                         f"{ROS_DOMAIN_ID_LIMIT} (Fast DDS's default ports); {rule}")
    return first, last


def parse_ready_timeout(text: str, source: str = READY_TIMEOUT_ENV) -> float:
    """A ready timeout as written (seconds, > 0).

    Raises:
        InputError: Not a finite number > 0; the message names the source.
    """
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{source} = {text!r} refused: must be a number of seconds > 0 "
                         f"(default {DEFAULT_READY_TIMEOUT_S:g})")
    return value


def _ini(config: pytest.Config | None, name: str) -> tuple[str, str]:
    """The ini key ``name``'s value ('' when unset, or when this plugin's keys are not registered) and its source."""
    if config is None:
        return "", name
    try:
        value = config.getini(name)
    except ValueError:   # the keys are not registered: the plugin is not loaded (-p no:rimd_sim)
        return "", name
    where = config.inipath.name if config.inipath is not None else "the ini file"
    return str(value or "").strip(), f"{name} in {where}"


def _configured(config: pytest.Config | None, environ: Mapping[str, str] | None, env_name: str, ini_name: str,
                parse: Callable[[str, str], Any], default: Any) -> Any:
    """A setting: ``parse`` of the environment variable (wins), else of the ini key, else ``default``."""
    environ = os.environ if environ is None else environ
    text = environ.get(env_name, "").strip()
    if text:
        return parse(text, env_name)
    text, source = _ini(config, ini_name)
    return parse(text, source) if text else default


def configured_domain_range(config: pytest.Config | None = None,
                            environ: Mapping[str, str] | None = None) -> tuple[int, int]:
    """The domain ids to lease: ``RIMD_DOMAIN_RANGE`` (wins), else the ini key ``rimd_domain_range``, else 1..100.

    Args:
        config: The pytest configuration (its ini file); None: the environment only.
        environ: The environment (default ``os.environ``).

    Raises:
        InputError: The range given is refused (:func:`parse_domain_range`).
    """
    return _configured(config, environ, DOMAIN_RANGE_ENV, DOMAIN_RANGE_INI, parse_domain_range,
                       (DOMAIN_ID_MIN, DOMAIN_ID_MAX))


def configured_ready_timeout(config: pytest.Config | None = None, environ: Mapping[str, str] | None = None) -> float:
    """The default ready timeout (s): ``RIMD_READY_TIMEOUT`` (wins), else the ini key ``rimd_ready_timeout``, else 120.

    Raises:
        InputError: The value given is refused (:func:`parse_ready_timeout`).
    """
    return _configured(config, environ, READY_TIMEOUT_ENV, READY_TIMEOUT_INI, parse_ready_timeout,
                       DEFAULT_READY_TIMEOUT_S)
