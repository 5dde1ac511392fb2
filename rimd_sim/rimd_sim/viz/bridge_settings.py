"""Parameters of the Rerun bridge node (``rimd_rerun``), declared once (:mod:`rimd_sim.settings.params`), without rclpy.

Every parameter is read at start (the sinks are opened once). ``rimd rig`` reads ``enabled`` and the
``foxglove.*`` keys of the bridge's section to plan the bring-up.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from rimd_sim.settings.params import Param, param, parameters
from rimd_sim.viz.foxglove_sink import DEFAULT_HOST, DEFAULT_PORT
from rimd_sim.viz.sinks import BAD_MEMORY_LIMITS, MEMORY_LIMIT_RULE, SERVER_HISTORY, SINKS, memory_limit_problem

__all__ = ["PARAMETERS", "BridgeSettings"]

#: A fully qualified ROS node name: ``/name`` or ``/namespace/name`` (tokens of letters, digits and underscores,
#: not starting with a digit).
_NODE_NAME = re.compile(r"(/[A-Za-z_][A-Za-z0-9_]*)+")


def _node_name_or_empty(value: str) -> bool:
    return value == "" or _NODE_NAME.fullmatch(value) is not None


@dataclass(frozen=True)
class BridgeSettings:
    """The bridge's parameters."""

    enabled: bool = param(True, "read by `rimd rig`: whether the bring-up starts this node (the node ignores it)",
                          read_only=True)
    sink: str = param("serve_web", "where the Rerun stream goes", choices=tuple(SINKS), read_only=True)
    save_path: str = param("", "sink save: .rrd file to write ('' = ./rimd_<UTC timestamp>.rrd)", read_only=True)
    url: str = param("rerun+http://127.0.0.1:9876/proxy", "sink connect: gRPC URL of a running viewer or server",
                     read_only=True)
    grpc_port: int = param(0, "sinks spawn/serve_web: gRPC port of the viewer/server started (0 = a free port)",
                           ge=0, le=65535, read_only=True)
    web_port: int = param(0, "sink serve_web: HTTP port of the web viewer on 127.0.0.1 (0 = a free port)", ge=0,
                          le=65535, read_only=True)
    memory_limit: str = param("1GiB", "sink spawn: the viewer's memory limit (oldest data dropped)",
                              rule=MEMORY_LIMIT_RULE, check=memory_limit_problem, breaks=BAD_MEMORY_LIMITS,
                              read_only=True)
    server_memory_limit: str = param(SERVER_HISTORY, "sink serve_web: data kept for a viewer opened later "
                                                     "(oldest dropped; 0 = none)",
                                     rule=MEMORY_LIMIT_RULE, check=memory_limit_problem, breaks=BAD_MEMORY_LIMITS,
                                     read_only=True)
    analytics: bool = param(False, "let Rerun report usage per the user's Rerun configuration (default: off)",
                            read_only=True)
    natural_frequency: float = param(1.82, "the phase plane's velocity axis is v_rel / (2 pi f)", unit="Hz",
                                     ge=0.01, le=1000, read_only=True)
    window: float = param(2.0, "channel data the time-series views show", unit="s", ge=0.01, le=3600,
                          read_only=True)
    trail: float = param(1.0, "phase-plane trajectory shown (trailing line)", unit="s", ge=0.01, le=3600,
                         read_only=True)
    display_interval: float = param(0.005, "the channels' display stream: per interval of this length, its "
                                           "smallest and largest sample at their own times (peaks exact, at most 2 "
                                           "points per interval and channel whatever the sample rate); 0 = full "
                                           "rate, every sample (rimd rig --rerun-full-rate). The recording keeps "
                                           "every sample either way", unit="s", ge=0.0001, le=10,
                                    zero="full rate: every sample", read_only=True)
    batch_blocks: int = param(50, "blocks of a channel sent per send_columns call (1 = one call per block; more = "
                                  "less CPU, up to that many block periods of latency)", ge=1, le=1000,
                              read_only=True)
    batch_interval: float = param(0.5, "shortest wall time between two sends of a channel, and the period of the "
                                       "flush of what is pending (0 = every batch_blocks blocks)", unit="s", ge=0,
                                  le=10, read_only=True)
    reliable: bool = param(True, "reliable subscriptions (false: best effort, matches best-effort channels)",
                           read_only=True)
    status_period: float = param(10.0, "time between status lines (0 = none)", unit="s", ge=0, le=3600,
                                 read_only=True)
    rerun: bool = param(True, "stream to Rerun (false: the Foxglove server only, which foxglove.enabled must then "
                              "turn on)", read_only=True)
    foxglove_enabled: bool = param(False, "serve the Foxglove WebSocket protocol: the rig topics (cdr, ros2msg "
                                          "schemas), the rig's services, the parameters of foxglove.parameter_nodes, "
                                          "the rig clock", read_only=True, name="foxglove.enabled")
    foxglove_host: str = param(DEFAULT_HOST, "IP address the Foxglove server binds (127.0.0.1 = this machine only)",
                               read_only=True, name="foxglove.host")
    foxglove_port: int = param(DEFAULT_PORT, "TCP port of the Foxglove server (0 = a free port, logged)", ge=0,
                               le=65535, read_only=True, name="foxglove.port")
    foxglove_topics: tuple[str, ...] = param(("/rig/.*", "/clock", "/diagnostics"), "topics offered to Foxglove: "
                                             "regular expressions (full match)", read_only=True,
                                             name="foxglove.topics")
    foxglove_parameter_nodes: tuple[str, ...] = param(("/rig/rimd_simulator",), "nodes whose parameters Foxglove "
                                                      "reads and sets, through their own parameter services",
                                                      read_only=True, name="foxglove.parameter_nodes")
    foxglove_call_timeout: float = param(3.0, "time to wait for the answer of a forwarded service call or "
                                              "parameter request", unit="s", ge=0.1, le=60, read_only=True,
                                         name="foxglove.call_timeout")
    foxglove_playback_node: str = param("", "with foxglove.enabled, a replay that Foxglove's timeline drives, by "
                                            "its fully qualified node name (/rimd_replay): playback control over the "
                                            "part it plays, through its services, which are offered instead of the "
                                            "rig's ('' = the live rig)",
                                        rule="empty or a fully qualified node name such as /rimd_replay",
                                        check=_node_name_or_empty, breaks=("rimd_replay", "/rimd replay", "/",
                                                                           "/a//b", "/2nd"),
                                        read_only=True, name="foxglove.playback_node")


#: The bridge's parameters by name.
PARAMETERS: dict[str, Param] = parameters(BridgeSettings)
