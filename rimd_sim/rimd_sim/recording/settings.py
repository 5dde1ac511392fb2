"""Parameters of the recorder node and their rules, without rclpy (``rimd rig`` checks them before starting)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

from rimd_sim.recording.bag import COMPRESSIONS

#: name -> (default, description). Fixed by SPEC section 6: output_dir, topics, max_duration, max_size,
#: compression, start_paused; the others are additions.
PARAMETERS: dict[str, tuple[Any, str]] = {
    "enabled": (True, "whether `rimd rig` starts the recorder (the node itself ignores it)"),
    "output_dir": ("recordings", "directory of the recording (created if needed); files are "
                                 "<prefix>_<UTC timestamp>_<n>.mcap, plus a rosbag2 metadata.yaml"),
    "prefix": ("rimd", "file name prefix"),
    "topics": (["/rig/.*", "/diagnostics", "/clock"], "topics to record: regular expressions (full match)"),
    "exclude": ([""], "topics never recorded: regular expressions (full match); empty entries are ignored"),
    "max_duration": (0.0, "s, start a new file when the current one spans this long (0 = no split)"),
    "max_size": (0, "bytes, start a new file when the current one reaches this size (0 = no split)"),
    "compression": ("zstd", "chunk compression: zstd, lz4 or none"),
    "chunk_size": (786432, "bytes of messages per chunk (a crash loses at most the chunk in progress)"),
    "flush_interval": (1.0, "s, close the chunk in progress at least this often (bounds a crash's loss in time)"),
    "start_paused": (False, "start with recording paused (~/resume starts it)"),
    "queue_size": (200000, "messages waiting for the writer before new ones are dropped (and counted)"),
    "discovery_period": (0.25, "s, how often the graph is searched for new topics"),
    "rig_node": ("/rig/rimd_simulator", "node whose parameters are stored in the recording's metadata"),
}

#: A ROS node name, relative or absolute (what ``rig_node`` must be when not empty).
_NODE_NAME = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")

# The durations have upper bounds and must be finite: an infinite max_duration or discovery_period stopped the
# recorder at start with a traceback (OverflowError), an infinite flush_interval never closed a chunk by time.
_RULES = {
    "max_duration": lambda v: (math.isfinite(v) and 0 <= v <= 1e9) or "must be >= 0 and <= 1e9 s",
    "max_size": lambda v: v >= 0 or "must be >= 0",
    "compression": lambda v: v in COMPRESSIONS or f"must be one of {', '.join(COMPRESSIONS)}",
    "chunk_size": lambda v: v >= 1024 or "must be >= 1024",
    "flush_interval": lambda v: (math.isfinite(v) and 0 < v <= 3600) or "must be > 0 and <= 3600 s",
    "queue_size": lambda v: v >= 1 or "must be >= 1",
    # At least 10 ms: 1e-300 s is a timer of period 0 ns, always due, that never lets the executor rest.
    "discovery_period": lambda v: (math.isfinite(v) and 0.01 <= v <= 3600) or "must be >= 0.01 and <= 3600 s",
    "output_dir": lambda v: bool(v.strip()) or "must not be empty",
    # A prefix is part of a file name in output_dir: '../x' wrote outside it.
    "prefix": lambda v: not any(c in v for c in "/\\\0") or "must be a file name prefix: no '/', '\\' or NUL",
    # An invalid name stopped the recorder at start with a traceback (its parameter client's service names).
    "rig_node": lambda v: (v == "" or _NODE_NAME.fullmatch(v) is not None)
                          or "must be empty or a ROS node name such as /rig/rimd_simulator",
}


class RecorderConfigError(ValueError):
    """A recorder parameter is invalid; the message names the key, the value and the rule."""


def compile_patterns(key: str, patterns: list[str]) -> list[re.Pattern[str]]:
    """Compile the non-empty regular expressions of parameter ``key``; a bad one raises RecorderConfigError."""
    compiled = []
    for pattern in patterns:
        if not pattern:
            continue
        try:
            compiled.append(re.compile(pattern))
        except re.error as exc:
            raise RecorderConfigError(f"{key}: '{pattern}' is not a regular expression ({exc})") from None
    return compiled


def _type_rule(default: Any, value: Any) -> str | None:
    """The type rule that ``value`` breaks for a parameter with ``default``, or None."""
    if isinstance(default, bool):
        return None if isinstance(value, bool) else "must be true or false"
    if isinstance(default, int):
        return None if isinstance(value, int) and not isinstance(value, bool) else "must be an integer"
    if isinstance(default, float):
        return None if isinstance(value, (int, float)) and not isinstance(value, bool) else "must be a number"
    if isinstance(default, str):
        return None if isinstance(value, str) else "must be a string"
    if isinstance(value, (list, tuple)) and all(isinstance(x, str) for x in value):
        return None
    return "must be a list of strings"


def check_parameter(name: str, value: Any) -> None:
    """Raise RecorderConfigError when ``value`` breaks the rule of parameter ``name``."""
    # The type first: a value of the wrong type in a YAML file (`rimd rig` checks it before starting) made
    # the rules below raise TypeError instead of a refusal.
    if name in PARAMETERS:
        wrong = _type_rule(PARAMETERS[name][0], value)
        if wrong is not None:
            raise RecorderConfigError(f"{name}: {value!r} refused: {wrong}")
    rule = _RULES.get(name)
    if rule is not None:
        verdict = rule(value)
        if verdict is not True:
            raise RecorderConfigError(f"{name}: {value!r} refused: {verdict}")
    if name in ("topics", "exclude"):
        compile_patterns(name, list(value))




def check_recorder_parameters(values: Mapping[str, Any]) -> None:
    """Check every known recorder parameter in ``values`` (unknown keys such as ``enabled`` are skipped)."""
    for name, value in values.items():
        if name in PARAMETERS:
            check_parameter(name, value)
