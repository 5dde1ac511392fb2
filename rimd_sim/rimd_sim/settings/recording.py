"""Parameters of the recorder node, declared once (:mod:`rimd_sim.settings.params`), without rclpy.

``rimd rig`` checks a configuration's recorder section with :func:`check_recorder_parameters` before starting
anything; the node declares :data:`PARAMETERS` and builds :class:`RecorderSettings` from its values. Part of the
interface (docs/interface.md): ``output_dir``, ``topics``, ``max_duration``, ``max_size``, ``compression``,
``start_paused``; the others are additions. Every parameter is read at start; ``stop_at`` may also be set while
the recorder runs (``rimd experiment`` sets it once it knows when its last step ends).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rimd_sim.errors import ConfigError
from rimd_sim.settings.params import BAD_REGEX_LISTS, Param, build, param, parameters, regex_list_problem

__all__ = ["COMPRESSIONS", "PARAMETERS", "LOSS_METADATA", "PROGRESS_STAMP_KEY", "STOP_METADATA", "RecorderConfigError",
           "RecorderSettings", "check_parameter", "check_recorder_parameters", "compile_patterns"]

#: The key suffix of the recorder's /diagnostics values that say how far each topic is written: the value of
#: ``"<topic>" + PROGRESS_STAMP_KEY`` is the header stamp (integer ns) of the last message of that topic written.
#: ``rimd experiment`` waits on it before stopping its recorder (a declared interface, not a convention).
PROGRESS_STAMP_KEY = " last_stamp_ns"

#: The MCAP metadata record that says where a recording stops (``stop_at``): key ``stop_at_ns``, integer ns, the
#: first stamp left out. The recorder writes it into the current and every later file when ``stop_at`` is set;
#: the analysis of a recording ends its last step there (docs/recording.md).
STOP_METADATA = "rimd_stop"

#: The MCAP metadata record in which the recorder says, when it finishes, what it knows was lost that the file
#: itself cannot show: per topic, ``<topic> transport_lost`` (messages the transport declared lost, DDS's
#: sample-lost status) and ``<topic> missing_at_start`` (samples a lockstep consumer should have had before its
#: first block of that topic). Only topics with a loss appear; the record is absent when nothing was lost.
LOSS_METADATA = "rimd_loss"

#: The MCAP chunk compressions the recorder writes (``recorder.compression``).
COMPRESSIONS = ("zstd", "lz4", "none")

#: A recorder parameter refused (the same exception as every configuration refusal).
RecorderConfigError = ConfigError

#: A ROS node name, relative or absolute (what ``rig_node`` must be when not empty).
_NODE_NAME = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


def compile_patterns(key: str, patterns: tuple[str, ...] | list[str]) -> list[re.Pattern[str]]:
    """The non-empty regular expressions of parameter ``key``, compiled (ConfigError for a bad one)."""
    parameters(RecorderSettings)[key].validate(patterns)
    return [re.compile(p) for p in patterns if p]


# The durations have upper bounds and must be finite: an infinite max_duration or discovery_period stopped the
# recorder at start with a traceback (OverflowError), an infinite flush_interval never closed a chunk by time.
@dataclass(frozen=True)
class RecorderSettings:
    """The recorder's parameters (node ``rimd_recorder``)."""

    enabled: bool = param(True, "whether `rimd rig` starts the recorder (the node itself ignores it)",
                          read_only=True)
    output_dir: str = param("recordings", "directory of the recording (created if needed); files are "
                                          "<prefix>_<UTC timestamp>_<n>.mcap, plus a rosbag2 metadata.yaml",
                            rule="a non-empty path", check=lambda v: bool(v.strip()), breaks=("", "   "),
                            read_only=True)
    # A prefix is part of a file name in output_dir: '../x' would write outside it.
    prefix: str = param("rimd", "file name prefix", rule="a file name prefix: no '/', '\\' or NUL",
                        check=lambda v: not any(c in v for c in "/\\\0"), breaks=("../escaped", "a/b", "nul\0"),
                        read_only=True)
    topics: tuple[str, ...] = param(("/rig/.*", "/diagnostics", "/clock"),
                                    "topics to record: regular expressions (full match)",
                                    rule="a list of regular expressions", check=regex_list_problem,
                                    breaks=BAD_REGEX_LISTS, read_only=True)
    exclude: tuple[str, ...] = param(("/rig/progress",), "topics never recorded: regular expressions (full "
                                                         "match); empty entries are ignored (default: the lockstep "
                                                         "consumers' progress reports)",
                                     rule="a list of regular expressions", check=regex_list_problem,
                                    breaks=BAD_REGEX_LISTS, read_only=True)
    max_duration: float = param(0.0, "start a new file when the current one spans this long (0 = no split)",
                                unit="s", ge=0, le=1e9, read_only=True)
    max_size: int = param(0, "start a new file when the current one reaches this size (0 = no split)",
                          unit="bytes", ge=0, read_only=True)
    compression: str = param("zstd", "chunk compression", choices=COMPRESSIONS, read_only=True)
    chunk_size: int = param(786432, "bytes of messages per chunk (a crash loses at most the chunk in progress)",
                            unit="bytes", ge=1024, read_only=True)
    flush_interval: float = param(1.0, "close the chunk in progress at least this often (bounds a crash's loss "
                                       "in time)", unit="s", gt=0, le=3600, read_only=True)
    start_paused: bool = param(False, "start with recording paused (~/resume starts it)", read_only=True)
    queue_size: int = param(200000, "messages waiting for the writer before new ones are dropped (and counted)",
                            ge=1, read_only=True)
    # At least 10 ms: 1e-300 s is a timer of period 0 ns, always due, that never lets the executor rest.
    discovery_period: float = param(0.25, "how often the graph is searched for new topics", unit="s", ge=0.01,
                                    le=3600, read_only=True)
    # An invalid name stopped the recorder at start with a traceback (its parameter client's service names).
    rig_node: str = param("/rig/rimd_simulator", "node whose parameters are stored in the recording's metadata",
                          rule="empty or a ROS node name such as /rig/rimd_simulator",
                          check=lambda v: v == "" or _NODE_NAME.fullmatch(v) is not None,
                          breaks=("bad name", "/rig/", "1abc", "a//b"), read_only=True)
    # Settable at run time: the end of an experiment is known once its first step is scheduled.
    stop_at: int = param(0, "leave out every message whose header stamp is at or after this stamp (integer ns in "
                            "the rig's time base; sample blocks that straddle it are cut to their samples before "
                            "it); 0 = no stop. May be set while recording: refused when a topic is already "
                            "written at or past it", unit="ns", ge=0)


#: The recorder's parameters by name.
PARAMETERS: dict[str, Param] = parameters(RecorderSettings)


def check_parameter(name: str, value: Any) -> Any:
    """The value of recorder parameter ``name``, checked (ConfigError naming the key, the value and the rule)."""
    return PARAMETERS[name].validate(value)


def check_recorder_parameters(values: Mapping[str, Any]) -> RecorderSettings:
    """The recorder's settings from a configuration section (unknown keys are refused by name)."""
    return build(RecorderSettings, values)
