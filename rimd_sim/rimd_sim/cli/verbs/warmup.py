"""``rimd warmup``: compile the physics once, ahead, into numba's on-disk cache.

numba compiles the integration driver of each model, the instruments' filters and the ensembles of the maps at
their first call and keeps the machine code in its cache (``__pycache__`` beside the sources, or
``NUMBA_CACHE_DIR``). On a fresh install that first call takes tens of seconds, paid by whatever runs first: a
rig's simulator before it says ``rig ready``, a test, a sweep. ``rimd warmup`` pays it at set-up time instead
(``scripts/setup.sh`` runs it after the build); later processes load the compiled code in about a second. It
runs the rigid and the two-mass model through the simulator (the drivers and the sensors) and one cell of a
Peterka map for each (the ensembles), compiles the composed rig's loop of DDS writes, and prints how long each
took: a few tenths of a second each when the cache already held them.
"""

from __future__ import annotations

import argparse
import os
import sys
import time


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``rimd warmup`` takes no option."""


def main(args: argparse.Namespace) -> int:
    """Compile (or load from the cache) every compiled function of the simulator and the maps."""
    from rimd_sim.analysis.dynamics.peterka import peterka
    from rimd_sim.instruments.rig_simulator import RigSimulator
    from rimd_sim.ros.nodes.outbox import compile_batch_writer
    from rimd_sim.settings.config import SimConfig, find_config_file, load_config

    rigid = SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
    two_mass = load_config(find_config_file("structural.yaml"))
    steps = (
        ("rigid model and instruments", lambda: RigSimulator(rigid, strobe=True).advance(0.2)),
        ("two-mass model and instruments", lambda: RigSimulator(two_mass, strobe=True).advance(0.2)),
        ("rigid ensemble", lambda: peterka(SimConfig(), [0.0], [3.75], transient_cycles=2, measure_cycles=6,
                                           workers=1)),
        ("two-mass ensemble", lambda: peterka(two_mass, [0.0], [3.75], transient_cycles=2, measure_cycles=6,
                                              workers=1)),
        ("the composed rig's DDS batch writer", compile_batch_writer),
    )
    where = os.environ.get("NUMBA_CACHE_DIR") or "__pycache__ beside the sources"
    total = time.perf_counter()
    for name, step in steps:
        start = time.perf_counter()
        step()
        print(f"rimd warmup: {name}: {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)
    print(f"rimd warmup: compiled code cached in {where} ({time.perf_counter() - total:.1f} s)")
    return 0
