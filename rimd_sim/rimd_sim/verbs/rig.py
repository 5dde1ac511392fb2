"""``rimd rig``: bring up the rig from a configuration file, like a launch file.

Today the rig is the simulator node; the recorder and the Rerun bridge join it when their issues land
(5 and 6). The nodes run as separate processes; Ctrl-C (or ``--duration``) stops them in reverse order,
each with SIGINT first, then SIGTERM, then SIGKILL after bounded waits.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from rimd_sim.core import ConfigError, load_config
from rimd_sim.core.config import find_config_file

#: (name, module) of the nodes of the rig, started in this order and stopped in the reverse order.
RIG_NODES = (("rimd_simulator", "rimd_sim.nodes.simulator"),)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd rig``."""
    parser.add_argument("--config", type=Path, default=None,
                        help="ROS parameter YAML of the rig (default: config/rimd.yaml)")
    parser.add_argument("--duration", type=float, default=0.0,
                        help="stop after this many seconds of wall time (default: run until Ctrl-C)")


def _stop(proc: subprocess.Popen, name: str) -> int | None:
    for sig, wait in ((signal.SIGINT, 10.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait)
        except subprocess.TimeoutExpired:
            print(f"rimd rig: {name} did not stop on {signal.Signals(sig).name}", file=sys.stderr)
    return proc.returncode


def main(args: argparse.Namespace) -> int:
    """Start the rig's nodes and wait; return non-zero if a node failed."""
    try:
        config_path = args.config if args.config is not None else find_config_file("rimd.yaml")
        config = load_config(config_path)  # refuse a bad file before starting anything
    except ConfigError as exc:
        print(f"rimd rig: {exc}", file=sys.stderr)
        return 1
    procs: list[tuple[str, subprocess.Popen]] = []
    stopping = False

    def on_signal(signum, frame):  # noqa: ARG001
        nonlocal stopping
        stopping = True

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    status = 0
    try:
        for name, module in RIG_NODES:
            cmd = [sys.executable, "-m", module, "--ros-args", "--params-file", str(config_path)]
            procs.append((name, subprocess.Popen(cmd, start_new_session=True)))
        print(f"rimd rig: running {', '.join(n for n, _ in procs)} with {config_path} "
              f"(gap {config.rig.gap * 1e3:g} mm, motor setpoint {config.motor.initial_setpoint:g} Hz, "
              f"ROS_DOMAIN_ID {os.environ.get('ROS_DOMAIN_ID', '0')}); topics under /rig. "
              "Recorder and Rerun bridge: not implemented yet (issues 5, 6). Ctrl-C stops.", flush=True)
        deadline = time.monotonic() + args.duration if args.duration > 0 else None
        while not stopping and (deadline is None or time.monotonic() < deadline):
            for name, proc in procs:
                if proc.poll() is not None:
                    print(f"rimd rig: {name} exited with status {proc.returncode}", file=sys.stderr)
                    stopping = True
                    status = 1
            time.sleep(0.1)
    finally:
        for name, proc in reversed(procs):
            code = _stop(proc, name)
            if code not in (0, None) and status == 0 and code != -signal.SIGINT:
                status = 1
        for s, handler in previous.items():
            signal.signal(s, handler)
    print("rimd rig: stopped", flush=True)
    return status
