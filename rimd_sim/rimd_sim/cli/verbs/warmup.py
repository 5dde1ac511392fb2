"""``rimd warmup``: compile the physics once, ahead, into numba's on-disk cache.

numba compiles the integration driver of each model, the instruments' filters and the ensembles of the maps at
their first call and keeps the machine code in its cache (``__pycache__`` beside the sources, or
``NUMBA_CACHE_DIR``). On a fresh install that first call takes tens of seconds, paid by whatever runs first: a
rig's simulator before it says ``rig ready``, a test, a sweep. ``rimd warmup`` pays it at set-up time instead
(``scripts/setup.sh`` runs ``rimd warmup --all`` after the build); later processes load the compiled code in about
a second.

By default it compiles what a rig of the default configuration runs: the rigid model through the simulator, its
sensors and the composed rig's loop of DDS writes (what a DAQ test against the rig needs). ``--all`` adds the
maps' ensembles and the two-mass model (``config/structural.yaml``: its simulator and its ensemble), in two
processes at once with two cores or more (numba writes each cache file whole, so two writers of one file do no
harm); without it they compile at their first use. Each step is timed.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

#: The groups of steps: (group, [step names]) in the order they start (``--all``: two at a time).
GROUPS = {"rig": ("rigid model and instruments", "the composed rig's DDS batch writer"),
          "two-mass": ("two-mass model and instruments", "two-mass ensemble", "two-mass shooting"),
          "maps": ("rigid ensemble", "rigid shooting")}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``rimd warmup [--all]``."""
    parser.add_argument("--all", action="store_true",
                        help="also the maps' ensembles and the two-mass model (default: only what a rig of the default "
                             "configuration runs: the rigid model, its sensors, the composed rig's writer)")
    parser.add_argument("--rig", action="store_true", help="what a rig runs (the default)")


def _step(name: str) -> None:
    import numpy as np

    from rimd_sim.analysis.dynamics.peterka import peterka
    from rimd_sim.instruments.rig_simulator import RigSimulator
    from rimd_sim.model.rig_model import model_for
    from rimd_sim.model.shooting import flow_points
    from rimd_sim.ros.nodes.outbox import compile_batch_writer
    from rimd_sim.settings.config import SimConfig, find_config_file, load_config

    if name.startswith("two-mass"):
        config = load_config(find_config_file("structural.yaml"))
    else:
        config = SimConfig()
    if name.endswith("model and instruments"):
        running = config.with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
        RigSimulator(running, strobe=True).advance(0.2)
    elif name.endswith("ensemble"):
        peterka(config, [0.0], [3.75], transient_cycles=2, measure_cycles=6, workers=1)
    elif name.endswith("shooting"):   # the stroboscopic map of continuation and steady orbits
        model = model_for(config)
        start = np.zeros((1, 2 + model.physics.N_MODES))
        flow_points(model.name, model.params(config)[None, :], np.array([3.75]), start, 1)
    else:
        compile_batch_writer()


def run_group(group: str) -> list[tuple[str, float]]:
    """Run one group's steps in this process; each step's name and seconds."""
    times = []
    for name in GROUPS[group]:
        start = time.perf_counter()
        _step(name)
        times.append((name, time.perf_counter() - start))
    return times


def main(args: argparse.Namespace) -> int:
    """Compile (or load from the cache) every compiled function of the simulator and the maps."""
    where = os.environ.get("NUMBA_CACHE_DIR") or "__pycache__ beside the sources"
    total = time.perf_counter()
    groups = list(GROUPS) if args.all else ["rig"]
    if len(groups) > 1 and (os.cpu_count() or 1) >= 2:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=min(len(groups), 2), mp_context=context) as pool:
            results = list(pool.map(run_group, groups))
    else:
        results = [run_group(g) for g in groups]
    for group, times in zip(groups, results, strict=True):
        for name, seconds in times:
            print(f"rimd warmup: {name}: {seconds:.1f} s ({group})", file=sys.stderr, flush=True)
    print(f"rimd warmup: compiled code cached in {where} ({time.perf_counter() - total:.1f} s)")
    return 0
