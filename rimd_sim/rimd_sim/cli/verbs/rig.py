"""``rimd rig``: bring up the rig from a configuration file, like a launch file (library: rimd_sim.ros.bringup).

The rig is the simulator, the recorder and the Rerun bridge (each when its config section has
``enabled: true``), by default in one process: the recorder and the bridge are fed the simulator's messages in
the process, DDS carries them only to the other processes (docs/rig.md, "The composed rig"); ``--separate``
starts each node in a process of its own. Open loop (default), the simulator starts paused and is resumed
once every consumer subscribes; with ``--lockstep`` it waits for its consumers by itself and never runs ahead
of the slowest. Ctrl-C (or ``--duration``) stops the nodes in reverse order (simulator first, recorder last).
``--set NAME=VALUE`` (or ROS's ``-p NAME:=VALUE``) sets a simulator parameter over the file's, checked before
anything starts.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from rimd_sim.cli import nonnegative_float, real_time_factor
from rimd_sim.settings import paths


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd rig``."""
    parser.add_argument("--config", type=Path, default=None,
                        help="ROS parameter YAML of the rig (default: config/rimd.yaml); a relative path is looked "
                             "up in the working directory, then in the shipped config directory")
    parser.add_argument("--duration", type=nonnegative_float("--duration", "s"), default=0.0,
                        help="stop after this many seconds of wall time (default 0: run until Ctrl-C)")
    parser.add_argument("--output-dir", type=Path, default=None,
                        help="record into this directory (default: the recorder's output_dir in the config)")
    parser.add_argument("--no-record", action="store_true", help="do not start the recorder")
    parser.add_argument("--no-rerun", action="store_true", help="do not start the Rerun bridge")
    parser.add_argument("--rerun-full-rate", action="store_true",
                        help="send every sample of every channel to Rerun (the bridge's display_interval 0); by "
                             "default the live view gets each channel's min and max sample per 5 ms, which keeps "
                             "every peak exact at a rate a browser keeps up with. The recording keeps every sample "
                             "either way")
    parser.add_argument("--foxglove", action="store_true",
                        help="serve the rig to Foxglove (ws://127.0.0.1:8765 by default; the bridge's foxglove.* "
                             "parameters); with --no-rerun the bridge serves Foxglove only")
    parser.add_argument("--lockstep", action="store_true",
                        help="lockstep: the simulator publishes time t only once the recorder, the bridge and every "
                             "--consumer have finished with t - lockstep.window (nothing lost, whatever the load)")
    parser.add_argument("--consumer", action="append", default=[], metavar="NAME",
                        help="with --lockstep: one more consumer to wait for (the name your node reports progress "
                             "under; repeatable)")
    parser.add_argument("--separate", action="store_true",
                        help="each node in a process of its own (default: the recorder and the bridge run in the "
                             "simulator's process, fed without DDS)")
    parser.add_argument("--real-time-factor", type=real_time_factor, default=None, metavar="F",
                        help="the simulator's real_time_factor (0 = as fast as possible; in lockstep: a speed cap)")
    parser.add_argument("--set", dest="settings", action="append", type=_setting, default=[], metavar="NAME=VALUE",
                        help="a simulator parameter over the config file's, named as in the file with dots "
                             "(motor.initial_setpoint=3.0, gap=1e-3); repeatable; checked as the file is, before "
                             "anything starts")
    parser.add_argument("-p", dest="settings", action="append", type=_ros_setting, metavar="NAME:=VALUE",
                        help="the same, in ROS's --ros-args form (-p gap:=0.001)")


def _setting(text: str) -> tuple[str, Any, str]:
    """``--set NAME=VALUE``: the name, the value typed (as the analysis verbs' ``--set``) and the option as typed."""
    from rimd_sim.cli.verbs._analysis_io import parameter_setting

    name, value = parameter_setting(text)
    return name, value, f"--set {text}"


def _ros_setting(text: str) -> tuple[str, Any, str]:
    """``-p NAME:=VALUE`` (ROS's parameter form): as ``--set``."""
    from rimd_sim.cli.verbs._analysis_io import parameter_setting

    name, sep, value = text.partition(":=")
    if not sep or not name.strip() or not value.strip():
        raise argparse.ArgumentTypeError(f"-p {text!r} refused: must be NAME:=VALUE, for example gap:=0.001")
    name, typed = parameter_setting(f"{name}={value}")
    return name, typed, f"-p {text}"


def simulator_settings(settings: list[tuple[str, Any, str]], config: Path | None) -> dict[str, Any]:
    """The ``--set``/``-p`` values by name (the last given wins), checked as the config file's values are.

    Each name and value on its own, then with the file's other values (``motor.initial_setpoint <=
    motor.max_frequency``); a refusal of the file's own values is left to the plan, which names the file.

    Raises:
        CommandError: An unknown name (with the closest ones) or a refused value, naming the option as typed.
    """
    from rimd_sim.cli import CommandError
    from rimd_sim.errors import ConfigError
    from rimd_sim.settings.config import (
        NODE_PARAMETERS,
        PARAMETERS,
        check_simulator_section,
        find_config_file,
        read_ros_parameters,
    )
    from rimd_sim.settings.params import unknown_name
    from rimd_sim.settings.yaml_file import resolve_config

    known = {**PARAMETERS, **NODE_PARAMETERS}
    out: dict[str, Any] = {}
    typed: dict[str, str] = {}
    for name, value, given in settings:
        declared = known.get(name)
        if declared is None:
            raise CommandError(f"{given} refused: {unknown_name(name, known)}")
        try:
            declared.validate(value)
        except ConfigError as exc:
            raise CommandError(f"{given} refused: {exc.rule}") from None
        out[name], typed[name] = value, given
    if not out:
        return out
    try:
        path = resolve_config(config) if config is not None else find_config_file("rimd.yaml")
        section = read_ros_parameters(path, node="rimd_simulator")
    except ConfigError:
        return out   # the file itself is refused: the plan says why, naming it
    try:
        check_simulator_section({**section, **out})
    except ConfigError as exc:
        if exc.key in typed:
            raise CommandError(f"{typed[exc.key]} refused: {exc.rule} (with {path}'s other values)") from None
    return out


def main(args: argparse.Namespace) -> int:
    """Start the rig's nodes and wait; return non-zero if a node failed."""
    from rimd_sim.cli import CommandError
    from rimd_sim.ros.bringup.plan import plan_rig
    from rimd_sim.ros.bringup.processes import Rig

    if args.consumer and not args.lockstep:
        raise CommandError("--consumer is for --lockstep (the names the lockstep rig waits for)")
    if args.rerun_full_rate and args.no_rerun:
        raise CommandError("--rerun-full-rate is for the Rerun view: not with --no-rerun")
    if args.foxglove:   # the extra foxglove (Rerun's, rerun-sdk, is refused by the plan when the bridge streams)
        from rimd_sim.viz.foxglove_sink import require_sdk

        require_sdk("or run without --foxglove")
    parameters: dict[str, dict[str, Any]] = {"rimd_simulator": simulator_settings(args.settings, args.config)}
    if args.rerun_full_rate:
        parameters["rimd_rerun"] = {"display_interval": 0.0}
    plan = plan_rig(args.config, output_dir=args.output_dir, record=not args.no_record, rerun=not args.no_rerun,
                    foxglove=args.foxglove, lockstep=args.lockstep, consumers=args.consumer,
                    real_time_factor=args.real_time_factor, separate=args.separate, parameters=parameters)
    rig = Rig(plan)
    config = plan.config
    assert config is not None   # plan_rig reads one (only a replay's plan has none)

    def announce() -> None:
        if plan.foxglove_address:
            print(f"rimd rig: Foxglove: open {plan.foxglove_address} in Foxglove (Open connection > Foxglove "
                  f"WebSocket; layout: {paths.config_dir() / 'foxglove' / 'rig_layout.json'})", flush=True)
        print(f"rimd rig: running {', '.join(plan.names)}"
              + ("" if plan.separate or len(plan.names) < 2 else " in one process") + f" with {plan.config_path} "
              f"(gap {config.rig.gap * 1e3:g} mm, motor setpoint {config.motor.initial_setpoint:g} Hz, "
              f"ROS_DOMAIN_ID {os.environ.get('ROS_DOMAIN_ID', '0')}); topics under /rig. "
              + (f"Recording into {plan.recording_dir}. " if plan.recording_dir else "Not recording. ")
              + "Ctrl-C stops.", flush=True)
        if plan.lockstep_consumers:
            print(f"rimd rig: lockstep with {', '.join(plan.lockstep_consumers)} (window "
                  f"{plan.lockstep_window:g} s of simulation time, speed cap {config.real_time_factor:g}x, "
                  "0 = none): the rig waits for each of them from sample 0 and goes as fast as the slowest",
                  flush=True)
        elif any(n.consumer for n in plan.nodes):
            if rig.resume_when_connected():
                print("rimd rig: every consumer is connected; the rig runs from sample 0", flush=True)
            elif rig.failed() is None:
                print("rimd rig: the consumers did not all connect within 20 s; the rig runs anyway",
                      file=sys.stderr, flush=True)

    status = rig.run("rig", announce, duration=args.duration)
    if plan.recording_dir:
        print(f"rimd rig: stopped; the recording is in {plan.recording_dir} "
              f"(replay: rimd replay {plan.recording_dir}, add --foxglove to drive it from Foxglove)", flush=True)
    else:
        print("rimd rig: stopped", flush=True)
    return status

