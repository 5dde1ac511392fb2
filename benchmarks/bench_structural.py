"""Benchmark of the structural contact model (docs/physics.md): real-time factors on one core.

Prints, in one run (same machine state for every figure), per operating point of Table 1, for the
structural preset (config/structural.yaml) and for the paper's model at the same point:
  * integrating: impacts only;
  * with all four channels at the default rates (2, 2, 20, 20 kHz) plus the 1 kHz truth (the simulator node's
    load), noise-free model values;
  * the full instrument chain through RigSimulator in the node's 10 ms blocks;
and the steps per simulated second. Target (set with the model): >= 1,000x real time on one core.

The step stays affordable because the stiff parts are integrated only where they act: in contact the axial
and mount modes are error-controlled (their ~5-15 kHz set the step for ~1 ms per impact); in free flight they
are linear, unforced and decoupled from the pendulum, so they follow their closed form and the free step is
the paper model's (up to 10 ms) however long the ringing lasts.

Run: .venv/bin/python benchmarks/bench_structural.py [--seconds 30] [--config FILE]
The machine is shared: the figures are what it gave under its load at the time (say so when quoting them).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from fractions import Fraction
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "rimd_sim"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _figures import record  # noqa: E402 - benchmarks/_figures.py: the headline figures for report.py
from bench_core import time_simulator  # noqa: E402

from rimd_sim.model.rig_model import RigModel  # noqa: E402
from rimd_sim.settings.config import (  # noqa: E402
    SimConfig,
    find_config_file,  # noqa: E402
    load_config,
)

POINTS = [(0.0, 3.75), (0.0, 5.5), (0.0, 7.25), (1.0e-3, 3.0), (2.4e-3, 5.25)]


def at(cfg: SimConfig, gap: float, freq: float) -> SimConfig:
    return cfg.with_parameters({"gap": gap, "motor.initial_frequency": freq, "motor.initial_setpoint": freq})


def time_model(cfg: SimConfig, seconds: float, **kw) -> tuple[float, int]:
    model = RigModel(cfg, **kw)  # the model cfg selects (structure.model)
    model.advance(0.5)  # warm-up (JIT from cache)
    steps = model.stats["steps"]
    t = time.perf_counter()
    model.advance(0.5 + seconds)
    return time.perf_counter() - t, model.stats["steps"] - steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="simulated seconds per figure")
    parser.add_argument("--config", default=None, help="structural preset (default config/structural.yaml)")
    args = parser.parse_args()
    s = args.seconds
    structural = load_config(args.config or find_config_file("structural.yaml"))
    paper = SimConfig()
    print(f"structural model benchmark, {s:g} simulated s per figure, best of 3, one core, shared machine "
          f"(load average {os.getloadavg()[0]:.2f} at start)")
    print(f"{'gap mm':>7} {'f Hz':>6} {'integrating':>12} {'4 channels':>11} {'steps/s':>8} | "
          f"{'paper integ.':>12} {'paper 4 ch':>11} {'steps/s':>8}")
    integ, chans = [], []
    for gap, freq in POINTS:
        row = []
        for cfg in (structural, paper):
            c = at(cfg, gap, freq)
            ti, steps = min(time_model(c, s, channels=False, truth=False) for _ in range(3))
            tc, _ = min(time_model(c, s, channels=True, truth=True) for _ in range(3))
            row.append((s / ti, s / tc, steps / s))
        integ.append(row[0][0])
        chans.append(row[0][1])
        (a, b, n), (pa, pb, pn) = row
        print(f"{gap * 1e3:7.1f} {freq:6.2f} {a:11.0f}x {b:10.0f}x {n:8.0f} | {pa:11.0f}x {pb:10.0f}x {pn:8.0f}")
    print(f"structural median real-time factor: integrating {statistics.median(integ):.0f}x, with 4 channels "
          f"{statistics.median(chans):.0f}x, worst with channels {min(chans):.0f}x (target >= 1000x)")
    record("core", "structural model, all channels, worst point", min(chans), "×", ">= 1000")
    c = at(structural, 0.0, 3.75)
    t_node = min(time_simulator(c, min(s, 10.0), Fraction(1, 100)) for _ in range(3))
    print(f"instrument chain (noise, filters) through RigSimulator in 10 ms blocks, gap 0 at 3.75 Hz: "
          f"{min(s, 10.0) / t_node:.0f}x real time, i.e. {100 * t_node / min(s, 10.0):.2f} % of one core at real time")
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
