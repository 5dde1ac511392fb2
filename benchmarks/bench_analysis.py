"""Benchmark of the analyses (docs/analyses.md): a Table 1 run and a 200 x 200 Peterka map, beside scipy.

Prints, in one run:
  * a Table 1 run: 3 gaps x 31 frequencies (2.0-9.5 Hz, 0.25 Hz steps), 150 cycles each from rest, in the
    process pool of ``rimd sweep`` on all cores (target <= 10 s on 2 cores);
  * a Peterka map of 200 gaps x 200 frequencies (the ``rimd peterka`` defaults otherwise: three starts per
    cell: 60 + 36 cycles from rest and from a kick, 30 + 36 continued) on all cores (target <= 5 min);
  * the time of one point (150 cycles from rest, gap 0, 3.75 Hz) with the compiled core and with the
    independent scipy ``solve_ivp`` (DOP853) reference of tests/harness/reference.py, and the projected times
    of both runs with scipy on the same cores.

The machine is shared: figures are noisy. Run: .venv/bin/python benchmarks/bench_analysis.py [--peterka N]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "rimd_sim"))
sys.path.insert(0, str(ROOT / "tests"))

import numpy as np  # noqa: E402

from rimd_sim.analysis.dynamics.peterka import peterka  # noqa: E402
from rimd_sim.analysis.dynamics.sweep import sweep  # noqa: E402
from rimd_sim.model.rig_model import RigModel  # noqa: E402
from rimd_sim.settings.config import SimConfig  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--peterka", type=int, default=200, help="Peterka grid size per axis (default 200)")
    parser.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    args = parser.parse_args()
    cores = os.cpu_count()
    print(f"RIMD analysis benchmark on {cores} core(s), load average {os.getloadavg()[0]:.2f}")

    freqs = np.arange(2.0, 9.51, 0.25)
    t0 = time.perf_counter()
    for gap in (0.0, 1.0e-3, 2.4e-3):
        res = sweep(SimConfig().with_parameters({"gap": gap}), freqs, "rest", cycles=150, workers=args.workers)
        print(f"  gap {gap * 1e3:.1f} mm: band A {res.band_a.frequency_hz:g} Hz, band B {res.band_b.frequency_hz:g} Hz,"
              f" {res.wall_seconds:.2f} s on {res.workers} processes")
    table1 = time.perf_counter() - t0
    print(f"Table 1 run (3 gaps x {len(freqs)} frequencies x 150 cycles): {table1:.2f} s   (target <= 10 s)")
    from _figures import record  # the headline figures for report.py

    record("analyses", f"Table 1: 3 gaps × {len(freqs)} frequencies", table1, "s", "<= 10")

    n = args.peterka
    t0 = time.perf_counter()
    res = peterka(SimConfig(), np.linspace(0, 3e-3, n), np.linspace(1.82, 9.1, n), workers=args.workers,
                  progress=lambda d, t: print(f"\r  Peterka rows {d}/{t}", end="", file=sys.stderr, flush=True))
    print(file=sys.stderr)
    pk = time.perf_counter() - t0
    scale = 40000 / (n * n)
    print(f"Peterka map {n} x {n} (3 starts per cell, {res.cycles_per_start} cycles each): {pk:.1f} s on "
          f"{res.workers} processes" + (f" (x{scale:.1f} for 200 x 200: {pk * scale:.0f} s)" if n != 200 else "")
          + "   (target <= 300 s)")

    cfg = SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
    RigModel(cfg, channels=False, truth=False).advance(1.0)  # JIT from cache
    t0 = time.perf_counter()
    for _ in range(20):
        RigModel(cfg, channels=False, truth=False).advance(150 / 3.75)
    ours = (time.perf_counter() - t0) / 20
    from harness import reference

    t0 = time.perf_counter()
    reference.simulate(frequency=3.75, gap=0.0, duration=150 / 3.75, rtol=1e-7, atol=1e-9)
    scipy_point = time.perf_counter() - t0
    workers = res.workers
    print(f"One point (gap 0, 3.75 Hz, 150 cycles from rest): core {ours * 1e3:.1f} ms, scipy solve_ivp DOP853 "
          f"(rtol 1e-7, as the core) {scipy_point:.2f} s: {scipy_point / ours:.0f}x slower")
    print(f"  projected with scipy on {workers} processes: Table 1 run {93 * scipy_point / workers:.0f} s, "
          f"Peterka 200 x 200 {40000 * 3 * scipy_point * (res.cycles_per_start / 150) / workers / 3600:.1f} h")


if __name__ == "__main__":
    main()
