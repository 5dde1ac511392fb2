"""Peterka maps (gap/A0 x Omega/omega) and basins of attraction (theta0 x theta_dot0) of the steady motions.

Peterka map (the paper's Fig. 12 left)
--------------------------------------
Each cell (gap, frequency) is classified (:func:`rimd_sim.analysis.dynamics.steady_orbit`) from three
initial conditions, the motor at phase 0 and constant frequency:

* ``rest``: the hammer at rest (the Table 1 protocol);
* ``kick``: the hammer at rest position with a relative velocity ``omega_n (gap + 2 A0)``, enough to reach
  the stop in free flight (the paper's "energy inserted", Fig. 12 right);
* ``continued``: the final state of the neighbouring cell at the next lower frequency, as an upward sweep.

The cell's class is the one from rest; a cell where the three classes differ is marked as holding coexisting
attractors. One gap row is one task (the ``continued`` start runs along the row); rows run in a process
pool on all cores (points are independent across rows, so the speed-up is the number of cores).

Basins of attraction
--------------------
At one (gap, frequency), a grid of initial conditions ``(theta0, theta_dot0)`` (hammer not inside the stop)
each classified the same way; one grid row per task in the pool.
"""

from __future__ import annotations

import math
import os
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from rimd_sim.core import SimConfig
from rimd_sim.core.errors import ConfigError, IntegrationError

from .dynamics import steady_orbit

__all__ = ["BasinsResult", "PeterkaResult", "START_NAMES", "basins", "peterka"]

START_NAMES = ("rest", "kick", "continued")
FAILED = "integration failed"


@dataclass(frozen=True)
class PeterkaResult:
    """A Peterka map.

    Attributes:
        gaps_mm: Gaps (mm), one per row.
        frequencies_hz: Motor frequencies (Hz), one per column.
        gap_ratio: ``gap / A0`` per row.
        frequency_ratio: ``Omega / omega_n`` per column.
        labels: Class per start, shape ``(len(START_NAMES), rows, columns)`` (strings).
        wall_seconds: Wall time (s).
        workers: Processes used.
        cycles_per_start: Transient + measured cycles of each run.
    """

    gaps_mm: np.ndarray
    frequencies_hz: np.ndarray
    gap_ratio: np.ndarray
    frequency_ratio: np.ndarray
    labels: np.ndarray
    wall_seconds: float
    workers: int
    cycles_per_start: int

    @property
    def primary(self) -> np.ndarray:
        """The class from rest, per cell."""
        return self.labels[0]

    @property
    def coexisting(self) -> np.ndarray:
        """Cells where the starts end on different classes."""
        return np.any(self.labels != self.labels[:1], axis=0)

    def class_counts(self) -> dict[str, int]:
        """Cells per class (from rest)."""
        return dict(Counter(self.primary.ravel().tolist()).most_common())


def _classify(config: SimConfig, f: float, theta0: float, theta_dot0: float, transient: int, measure: int):
    try:
        orbit = steady_orbit(config, f, theta0=theta0, theta_dot0=theta_dot0, transient_cycles=transient,
                             measure_cycles=measure)
    except IntegrationError:
        return FAILED, (0.0, 0.0)
    return orbit.label, orbit.final_state


def _row(args: tuple[SimConfig, float, list[float], int, int, int]) -> list[tuple[str, str, str]]:
    base, gap, freqs, transient, measure, continued_transient = args
    cfg = base.with_parameters({"gap": gap})
    rig = cfg.rig
    kick = rig.omega_n * (gap + 2.0 * rig.amplitude) / rig.length  # rad/s
    out = []
    state = (0.0, 0.0)
    for f in freqs:
        rest, final = _classify(cfg, f, 0.0, 0.0, transient, measure)
        kicked, _ = _classify(cfg, f, 0.0, kick, transient, measure)
        cont, state = _classify(cfg, f, state[0], state[1], continued_transient, measure)
        if cont == FAILED:
            state = final
        out.append((rest, kicked, cont))
    return out


def _pool_map(fn, jobs, workers: int | None, progress):
    n = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
    results = []
    if n == 1:
        for i, job in enumerate(jobs):
            results.append(fn(job))
            if progress:
                progress(i + 1, len(jobs))
    else:
        with ProcessPoolExecutor(n) as pool:
            for i, r in enumerate(pool.map(fn, jobs)):
                results.append(r)
                if progress:
                    progress(i + 1, len(jobs))
    return results, n


def _check_cycles(transient: int, measure: int) -> None:
    if transient < 0 or measure < 6:
        raise ConfigError("cycles", (transient, measure), "need transient_cycles >= 0 and measure_cycles >= 6")


def peterka(config: SimConfig, gaps_m, frequencies_hz, *, transient_cycles: int = 60, measure_cycles: int = 36,
            continued_transient_cycles: int = 30, workers: int | None = None, progress=None) -> PeterkaResult:
    """Classify every (gap, frequency) cell from three starts (module docstring).

    Args:
        config: Rig configuration (mass, damping, contact, ...); gap and motor replaced per cell.
        gaps_m: Gaps (m), each >= 0.
        frequencies_hz: Motor frequencies (Hz), each > 0 and <= the motor maximum; run in increasing order.
        transient_cycles: Cycles dropped before measuring (starts ``rest`` and ``kick``).
        measure_cycles: Cycles classified (periods up to a third of it are found, at most 12).
        continued_transient_cycles: Transient of the ``continued`` start (it begins near an attractor).
        workers: Processes (default: all cores).
        progress: Optional callable ``progress(rows_done, rows)``.

    Raises:
        ConfigError: For a bad gap, frequency or cycle count.
    """
    gaps = [float(g) for g in gaps_m]
    freqs = sorted(float(f) for f in frequencies_hz)
    if not gaps or any(not (math.isfinite(g) and g >= 0) for g in gaps):
        raise ConfigError("gaps", gaps, "must be non-empty, each finite and >= 0 m")
    if not freqs or any(not (0 < f <= config.motor.max_frequency) for f in freqs):
        raise ConfigError("frequencies", freqs, f"must be non-empty, each > 0 and <= {config.motor.max_frequency} Hz")
    _check_cycles(transient_cycles, measure_cycles)
    start = time.perf_counter()
    jobs = [(config, g, freqs, transient_cycles, measure_cycles, continued_transient_cycles) for g in gaps]
    rows, n = _pool_map(_row, jobs, workers, progress)
    labels = np.array(rows, dtype=object).transpose(2, 0, 1)
    rig = config.rig
    return PeterkaResult(np.array(gaps) * 1e3, np.array(freqs), np.array(gaps) / rig.amplitude,
                         np.array(freqs) / rig.natural_frequency, labels, time.perf_counter() - start, n,
                         transient_cycles + measure_cycles)


def peterka_table(result: PeterkaResult) -> list[dict]:
    """CSV rows, one per cell."""
    rows = []
    for i, g in enumerate(result.gaps_mm):
        for j, f in enumerate(result.frequencies_hz):
            row = {"gap_mm": float(g), "gap_ratio": float(result.gap_ratio[i]), "frequency_hz": float(f),
                   "frequency_ratio": float(result.frequency_ratio[j])}
            row.update({f"class_{name}": result.labels[k, i, j] for k, name in enumerate(START_NAMES)})
            row["coexisting"] = bool(result.coexisting[i, j])
            rows.append(row)
    return rows


@dataclass(frozen=True)
class BasinsResult:
    """Classes over a grid of initial conditions at one parameter point.

    Attributes:
        gap_mm: Gap (mm).
        frequency_hz: Motor frequency (Hz).
        theta0: Initial angles (rad), one per column.
        theta_dot0: Initial rates (rad/s), one per row.
        labels: Class per initial condition, shape ``(rows, columns)``; ``inside the stop`` where the
            hammer would start beyond the stop (not run).
        wall_seconds: Wall time (s).
        workers: Processes used.
    """

    gap_mm: float
    frequency_hz: float
    theta0: np.ndarray
    theta_dot0: np.ndarray
    labels: np.ndarray
    wall_seconds: float
    workers: int

    def class_counts(self) -> dict[str, int]:
        """Initial conditions per class."""
        return dict(Counter(self.labels.ravel().tolist()).most_common())


INSIDE = "inside the stop"


def _basin_row(args: tuple[SimConfig, float, np.ndarray, float, int, int]) -> list[str]:
    cfg, f, thetas, theta_dot, transient, measure = args
    limit = math.asin(min(1.0, cfg.rig.gap / cfg.rig.length))
    return [INSIDE if th > limit else _classify(cfg, f, float(th), theta_dot, transient, measure)[0]
            for th in thetas]


def default_basin_ranges(config: SimConfig) -> tuple[tuple[float, float], tuple[float, float]]:
    """Initial angles from ``-3 (gap + A0) / l`` to the stop, rates within ``+-3 omega_n (gap + A0) / l``."""
    rig = config.rig
    span = 3.0 * (rig.gap + rig.amplitude) / rig.length
    return (-span, math.asin(min(1.0, rig.gap / rig.length))), (-span * rig.omega_n, span * rig.omega_n)


def basins(config: SimConfig, frequency_hz: float, theta_range: tuple[float, float],
           theta_dot_range: tuple[float, float], size: tuple[int, int] = (40, 40), *, transient_cycles: int = 80,
           measure_cycles: int = 36, workers: int | None = None, progress=None) -> BasinsResult:
    """Classify the steady motion from each initial condition of a grid (module docstring).

    Args:
        config: Rig configuration with the gap in force.
        frequency_hz: Motor frequency (Hz).
        theta_range: ``(min, max)`` initial angle (rad).
        theta_dot_range: ``(min, max)`` initial rate (rad/s).
        size: Grid points ``(angles, rates)``, each >= 2.
        transient_cycles: Cycles dropped before measuring.
        measure_cycles: Cycles classified.
        workers: Processes (default: all cores).
        progress: Optional callable ``progress(rows_done, rows)``.

    Raises:
        ConfigError: For a bad frequency, range, size or cycle count.
    """
    if not (math.isfinite(frequency_hz) and 0 < frequency_hz <= config.motor.max_frequency):
        raise ConfigError("frequency", frequency_hz, f"must be > 0 and <= {config.motor.max_frequency} Hz")
    for name, (lo, hi) in (("theta_range", theta_range), ("theta_dot_range", theta_dot_range)):
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ConfigError(name, (lo, hi), "must be finite with min < max")
    if abs(theta_range[0]) > 1.5 or abs(theta_range[1]) > 1.5:
        raise ConfigError("theta_range", theta_range, "must stay within +-1.5 rad")
    if min(size) < 2 or max(size) > 2000:
        raise ConfigError("size", size, "each must be in [2, 2000]")
    _check_cycles(transient_cycles, measure_cycles)
    start = time.perf_counter()
    thetas = np.linspace(*theta_range, size[0])
    rates = np.linspace(*theta_dot_range, size[1])
    jobs = [(config, float(frequency_hz), thetas, float(r), transient_cycles, measure_cycles) for r in rates]
    rows, n = _pool_map(_basin_row, jobs, workers, progress)
    return BasinsResult(config.rig.gap * 1e3, float(frequency_hz), thetas, rates, np.array(rows, dtype=object),
                        time.perf_counter() - start, n)


def basins_table(result: BasinsResult) -> list[dict]:
    """CSV rows, one per initial condition."""
    return [{"theta0_rad": float(th), "theta_dot0_rad_s": float(r), "class": result.labels[i, j]}
            for i, r in enumerate(result.theta_dot0) for j, th in enumerate(result.theta0)]
