"""Benchmark of the physics core: real-time factors on one core, and the ratio to a scipy reference.

Prints, in one run (same machine state for every figure):
  * integrating: impacts only (integration + switch location + impact records), per operating point;
  * with all four channels sampled at the default rates (2 kHz, 2 kHz, 20 kHz, 20 kHz) plus the 1 kHz truth,
    noise-free model values;
  * the full instrument chain (noise, filters, quantisation) through RigSimulator, in 1 s blocks and in the
    node's 10 ms blocks;
  * the independent scipy solve_ivp (DOP853) reference on the same trajectory, and the speed ratio.
Targets (docs/benchmarks.md, Physics core): >= 10,000x integrating, >= 1,000x with all channels.

Run: .venv/bin/python benchmarks/bench_core.py [--seconds 60]
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
sys.path.insert(0, str(ROOT / "tests"))

from _figures import record  # noqa: E402 - benchmarks/_figures.py: the headline figures for report.py

from rimd_sim.instruments.rig_simulator import RigSimulator  # noqa: E402
from rimd_sim.model.rig_model import RigModel  # noqa: E402
from rimd_sim.settings.config import SimConfig  # noqa: E402

POINTS = [(0.0, 3.75), (0.0, 5.5), (0.0, 7.25), (1.0e-3, 3.0), (2.4e-3, 5.25)]


def config(gap: float, freq: float) -> SimConfig:
    return SimConfig().with_parameters({"gap": gap, "motor.initial_frequency": freq, "motor.initial_setpoint": freq})


def best_of(fn, repeats: int = 3) -> float:
    return min(fn() for _ in range(repeats))


def time_model(cfg: SimConfig, seconds: float, **kw) -> float:
    model = RigModel(cfg, **kw)
    model.advance(0.5)  # warm-up (JIT from cache)
    t = time.perf_counter()
    model.advance(0.5 + seconds)
    return time.perf_counter() - t


def time_simulator(cfg: SimConfig, seconds: float, block: Fraction) -> float:
    sim = RigSimulator(cfg)
    sim.advance(block)
    t0 = time.perf_counter()
    t = sim.time
    end = t + Fraction(seconds)
    while t < end:
        t += block
        sim.advance(t)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds per figure")
    args = parser.parse_args()
    s = args.seconds
    print(f"RIMD core benchmark, {s:g} simulated s per figure, best of 3, one core")
    print(f"{'gap mm':>7} {'f Hz':>6} {'integrating':>13} {'4 channels':>12} {'steps/s':>9}")
    integ, chans = [], []
    for gap, freq in POINTS:
        cfg = config(gap, freq)
        ti = best_of(lambda cfg=cfg: time_model(cfg, s, channels=False, truth=False))
        tc = best_of(lambda cfg=cfg: time_model(cfg, s / 4, channels=True, truth=True)) * 4
        m = RigModel(cfg, channels=False, truth=False)
        m.advance(s)
        integ.append(s / ti)
        chans.append(s / tc)
        print(f"{gap * 1e3:7.1f} {freq:6.2f} {s / ti:12.0f}x {s / tc:11.0f}x {m.stats['steps'] / s:9.0f}")
    print(f"median real-time factor: integrating {statistics.median(integ):.0f}x (target >= 10000x), "
          f"with all channels {statistics.median(chans):.0f}x (target >= 1000x)")
    record("core", "integrating, median of 5 points", statistics.median(integ), "×", ">= 10000")
    record("core", "with all channels, median", statistics.median(chans), "×", ">= 1000")
    cfg = config(0.0, 3.75)
    t1 = best_of(lambda: time_simulator(cfg, s / 4, Fraction(1))) * 4
    t2 = best_of(lambda: time_simulator(cfg, s / 4, Fraction(1, 100))) * 4
    print(f"instrument chain (noise, filters, quantisation), gap 0 at 3.75 Hz: {s / t1:.0f}x in 1 s blocks, "
          f"{s / t2:.0f}x in 10 ms blocks")
    tight = {"integrator.rtol": 1e-10, "integrator.atol": 1e-12, "integrator.max_step": 2e-3}
    diffs = []
    for gap, freq in POINTS:
        a = RigModel(config(gap, freq), channels=False, truth=False).advance(20.0).impacts
        b = RigModel(config(gap, freq).with_parameters(tight), channels=False, truth=False).advance(20.0).impacts
        pa = max(i.peak_force for i in a if i.t_start > 16.0)
        pb = max(i.peak_force for i in b if i.t_start > 16.0)
        diffs.append(f"{gap * 1e3:g} mm/{freq:g} Hz {abs(pa / pb - 1):.0e}")
    print("accuracy of the default tolerances (steady peak force vs rtol 1e-10): " + ", ".join(diffs))
    from harness import reference

    ref_s = min(s, 20.0)
    t = time.perf_counter()
    reference.simulate(frequency=3.75, gap=0.0, duration=ref_s)
    tr = time.perf_counter() - t
    tm = best_of(lambda: time_model(cfg, ref_s, channels=False, truth=False))
    print(f"scipy solve_ivp reference (DOP853, rtol 1e-10), gap 0 at 3.75 Hz: {ref_s / tr:.0f}x real time; "
          f"core is {tr / tm:.0f}x faster")


if __name__ == "__main__":
    main()
