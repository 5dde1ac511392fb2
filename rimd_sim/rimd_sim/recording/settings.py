"""Parameters of the recorder node and their rules, without rclpy (``rimd rig`` checks them before starting)."""

from __future__ import annotations

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

_RULES = {
    "max_duration": lambda v: v >= 0 or "must be >= 0",
    "max_size": lambda v: v >= 0 or "must be >= 0",
    "compression": lambda v: v in COMPRESSIONS or f"must be one of {', '.join(COMPRESSIONS)}",
    "chunk_size": lambda v: v >= 1024 or "must be >= 1024",
    "flush_interval": lambda v: v > 0 or "must be > 0",
    "queue_size": lambda v: v >= 1 or "must be >= 1",
    "discovery_period": lambda v: v > 0 or "must be > 0",
    "output_dir": lambda v: bool(v.strip()) or "must not be empty",
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


def check_parameter(name: str, value: Any) -> None:
    """Raise RecorderConfigError when ``value`` breaks the rule of parameter ``name``."""
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
