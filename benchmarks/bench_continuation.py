"""Benchmark of the continuation of periodic orbits (docs/analyses.md, "rimd continue").

Prints, in one run, with the load average before each figure (a figure counts only on an idle machine):

1. the branch of the paper's model at gap 0 from 3 Hz upward with its stability, the period doubling located
   and the period-2 branch followed after the switch (``--max-period 2``): wall seconds (target <= 10 s);
2. the same run with the whole cascade (the default ``--max-period 8``), as ``rimd continue`` does it;
3. the same two on the default preset (``config/rimd.yaml``);
4. the cost per period of the shooting kernel, single-threaded and split over the cores (the ratio).

Each figure is the median of ``--repeat`` runs in this process, after one warm-up run (numba's cache loaded).

Run: .venv/bin/python benchmarks/bench_continuation.py [--repeat 3] [--f-end 6]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from rimd_sim.analysis.dynamics.continuation import SHOOTING_TOLERANCES, ContinuationSettings, continuation
from rimd_sim.model import shooting
from rimd_sim.model.rig_model import model_for
from rimd_sim.settings.config import find_config_file, load_config


def _load() -> str:
    la = os.getloadavg()
    return f"load average {la[0]:.2f} {la[1]:.2f} {la[2]:.2f}"


def _median_wall(fn, repeat: int):
    fn()
    walls, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls), walls, result


def _continuation(name: str, f_end: float, max_period: int, repeat: int) -> None:
    config = load_config(find_config_file(name), {"gap": 0.0})
    wall, walls, result = _median_wall(
        lambda: continuation(config, 3.0, f_end, settings=ContinuationSettings(max_period=max_period)), repeat)
    pd = result.of_kind("period_doubling")
    branches = ", ".join(f"period {b.period}: {len(b.points)} orbits" for b in result.branches)
    first = f"{pd[0].frequency_hz:.5f} Hz" if pd else "none"
    verdict = "met" if wall <= 10.0 else "NOT met"
    print(f"{name}, gap 0, 3 -> {f_end:g} Hz, max period {max_period}: {wall:.2f} s wall (median of "
          f"{[round(w, 2) for w in walls]}); first period doubling {first}; {branches}; "
          f"{result.evaluations} periods integrated; target <= 10 s: {verdict} ({_load()})", flush=True)


def _kernel(repeat: int) -> None:
    config = load_config(find_config_file("paper_model.yaml"), {"gap": 0.0}).with_parameters(SHOOTING_TOLERANCES)
    p = model_for(config).params(config)
    starts = np.tile([[-0.0455, -0.0183]], (512, 1))
    shooting.flow_points("rigid", p, 3.0, starts[:4], 1)
    figures = {}
    threads = shooting.THREADS
    for n in (1, threads):
        shooting.THREADS = n
        shooting._pool.cache_clear()
        wall, _, _ = _median_wall(lambda: shooting.flow_points("rigid", p, 3.0, starts, 1), repeat)
        figures[n] = wall / len(starts)
    shooting.THREADS = threads
    print(f"shooting kernel, paper model at 3 Hz (1/1, rtol 1e-10): {figures[1] * 1e3:.3f} ms per period on one "
          f"thread, {figures[threads] * 1e3:.3f} ms on {threads}; ratio {figures[1] / figures[threads]:.2f} "
          f"({_load()})", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--f-end", type=float, default=6.0)
    args = parser.parse_args()
    print(_load(), flush=True)
    for name in ("paper_model.yaml", "rimd.yaml"):
        _continuation(name, args.f_end, 2, args.repeat)
        _continuation(name, args.f_end, 8, args.repeat)
    _kernel(args.repeat)


if __name__ == "__main__":
    main()
