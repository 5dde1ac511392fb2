"""Basins of attraction: the steady motion reached from each initial condition ``(theta0, theta_dot0)`` of a grid.

At one (gap, frequency), each initial condition of the grid (the hammer not inside the stop) runs from motor phase
0 at constant frequency through the ensemble kernel (:func:`rimd_sim.model.ensemble.run_cells`, the ``window``
stop rule of :func:`~rimd_sim.analysis.dynamics.cells.stop_rule`) and its motion is classified as
:func:`~rimd_sim.analysis.dynamics.steady.classify` does. One grid row (one rate, every angle) is one task of
:func:`rimd_sim.analysis.executor.run_tasks`.

Each initial condition also gets an attractor id, the orbit it ends on. The orbit is its stroboscopic points in
the non-dimensional ``(u, v)`` of :mod:`rimd_sim.analysis.dynamics.steady`: the last ``n`` of the classified window
for a ``p/n`` class, or the smallest repeating set of a no-impact motion. Orbits are compared as sets, to the
classification tolerance, with the orbits met before (:func:`~rimd_sim.analysis.dynamics.steady.cluster_orbits`):
the same orbit shares an id, and another orbit of the same class (another 1/1, a 1/2 shifted by one cycle) gets its
own. Only settled motions are told apart by their orbit. A trajectory that ran to the cap without settling (a
non-periodic motion, or a slow transient such as a 2/4 read near a period doubling while it still converges to
1/2) has no orbit to compare, and those of one class share one id (``settled`` false in the list of attractors).

Every trajectory is checked against the model's valid domain (:mod:`rimd_sim.model.validity`) over its whole run:
the compiled loop returns its largest ``|theta|``, its largest impact force, its impacts per cycle over the
classified window and whether the chattering guard stopped it; the verdicts are made in the calling process from
those numbers, and an initial condition is marked with the rules its trajectory broke.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from rimd_sim.analysis.dynamics.cells import check_cycles, stop_rule, trajectory_measures, validity_columns
from rimd_sim.analysis.dynamics.steady import check_frequency, cluster_orbits, orbit_points
from rimd_sim.analysis.executor import run_tasks
from rimd_sim.analysis.outputs import rows_of
from rimd_sim.errors import ConfigError
from rimd_sim.model.ensemble import StopRule, run_cells
from rimd_sim.model.rig_model import model_for
from rimd_sim.model.validity import PointMeasures, Verdict, domain
from rimd_sim.settings.config import SimConfig

__all__ = ["INSIDE", "MAX_BASIN_ANGLE", "BasinsResult", "basins", "basins_columns", "basins_table",
           "default_basin_ranges"]

#: Largest initial angle (rad) of a basins grid: short of the horizontal, where the model's domain ends.
MAX_BASIN_ANGLE = 1.5
#: The class of an initial condition beyond the stop (not run).
INSIDE = "inside the stop"
#: The class of a trajectory the chattering guard stopped (:meth:`rimd_sim.model.ensemble.EnsembleResult.labels`).
FAILED = "integration failed"


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
        workers: Processes (or Dask worker threads) used.
        cycles: Cycles each trajectory ran (0 where not run).
        where: ``local`` or the Dask scheduler's address.
        invalid_rule: The rules of the model's valid domain each trajectory broke, same shape as ``labels``
            (``""`` when valid or not run).
        max_abs_theta: Largest ``|theta|`` (rad) of each run (NaN where not run or chattering).
        max_force: Largest impact force (N) of each run (NaN where not run or chattering).
        validity: The summary's report of the valid domain, one point per initial condition run.
        attractor_id: The attractor each initial condition ends on (module docstring), same shape as
            ``labels``; -1 where not run or failed.
        attractors: Per id, a dict: ``id``, ``class``, ``settled``, ``period`` (points of its orbit; 0 when not
            settled), ``u``, ``v`` and ``theta_rad``, ``theta_dot_rad_s`` (its stroboscopic points; the last one
            of its first initial condition when not settled), ``peak_force_n`` (the largest impact of the
            classified window of its first initial condition), ``cells`` (initial conditions ending on it).
        peak_force: Largest impact force (N) of each initial condition's classified window, same shape as
            ``labels`` (0 without impact; NaN where not run or failed).
        impact_velocity: Largest impact velocity (m/s, the approach speed at contact onset) of the same window.
    """

    gap_mm: float
    frequency_hz: float
    theta0: np.ndarray
    theta_dot0: np.ndarray
    labels: np.ndarray
    wall_seconds: float
    workers: int
    cycles: np.ndarray = field(default_factory=lambda: np.zeros((0,)))
    where: str = "local"
    invalid_rule: np.ndarray | None = None
    max_abs_theta: np.ndarray | None = None
    max_force: np.ndarray | None = None
    validity: dict | None = None
    attractor_id: np.ndarray | None = None
    attractors: list | None = None
    peak_force: np.ndarray | None = None
    impact_velocity: np.ndarray | None = None

    @property
    def valid(self) -> np.ndarray:
        """Per initial condition, whether its run stayed in the model's valid domain (True where not run)."""
        if self.invalid_rule is None:
            return np.ones(self.labels.shape, dtype=bool)
        return self.invalid_rule == ""

    def class_counts(self) -> dict[str, int]:
        """Initial conditions per class."""
        return dict(Counter(self.labels.ravel().tolist()).most_common())


def _basin_row(args: tuple[str, np.ndarray, float, np.ndarray, float, float, StopRule]
               ) -> tuple[list[str], list[int], list, list, list, list]:
    """One row of initial conditions (one rate, every angle) in one compiled call.

    Returns ``(labels, cycles, measures, points, window_peaks, window_velocities)``; the measures
    (:func:`~rimd_sim.analysis.dynamics.cells.trajectory_measures`), the last stroboscopic points ``(u, v)``, the
    largest impact force and impact velocity of the classified window are None where not run.
    """
    model, p, f, thetas, theta_dot, limit, rule = args
    run = np.flatnonzero(thetas <= limit)
    labels = [INSIDE] * len(thetas)
    cycles = [0] * len(thetas)
    measures: list = [None] * len(thetas)
    points: list = [None] * len(thetas)
    peaks: list = [None] * len(thetas)
    vels: list = [None] * len(thetas)
    if len(run):
        res = run_cells(model, p[None, :], np.zeros(len(run), dtype=np.int64), np.full(len(run), f), thetas[run],
                        np.full(len(run), theta_dot), rule)
        assert res.points is not None and res.window_peak is not None  # run_cells fills them
        assert res.window_velocity is not None
        for j, label, c, m, pts, pk, vel in zip(run.tolist(), res.labels(), res.cycles.tolist(),
                                                trajectory_measures(res), res.points, res.window_peak.tolist(),
                                                res.window_velocity.tolist(), strict=True):
            labels[j] = label
            cycles[j] = c
            measures[j] = m
            points[j] = pts
            peaks[j] = pk
            vels[j] = vel
    return labels, cycles, measures, points, peaks, vels


def default_basin_ranges(config: SimConfig) -> tuple[tuple[float, float], tuple[float, float]]:
    """Initial angles from ``-3 (gap + A0) / l`` to the stop, rates within ``+-3 omega_n (gap + A0) / l``.

    The angles reach no further than the +-1.5 rad :func:`basins` accepts (:data:`MAX_BASIN_ANGLE`), so that a short
    pendulum, whose ``3 A0 / l`` exceeds it, still has a region; the rates are then ``+-omega_n`` times that span.
    """
    rig = config.rig
    span = min(3.0 * (rig.gap + rig.amplitude) / rig.length, MAX_BASIN_ANGLE)
    return (-span, math.asin(min(1.0, rig.gap / rig.length))), (-span * rig.omega_n, span * rig.omega_n)


def basins(config: SimConfig, frequency_hz: float, theta_range: tuple[float, float],
           theta_dot_range: tuple[float, float], size: tuple[int, int] = (40, 40), *, transient_cycles: int = 160,
           measure_cycles: int = 72, early_stop: bool = True, workers: int | None = None,
           scheduler: str | None = None, progress=None) -> BasinsResult:
    """Classify the steady motion from each initial condition of a grid (module docstring).

    Args:
        config: Rig configuration with the gap in force.
        frequency_hz: Motor frequency (Hz).
        theta_range: ``(min, max)`` initial angle (rad).
        theta_dot_range: ``(min, max)`` initial rate (rad/s).
        size: Grid points ``(angles, rates)``, each >= 2.
        transient_cycles: Cycles dropped before measuring at the cap.
        measure_cycles: Cycles classified at the cap.
        early_stop: Stop each trajectory when its motion is known (:mod:`rimd_sim.model.ensemble`).
        workers: Local processes (default: all cores).
        scheduler: Dask scheduler address (default ``$RIMD_DASK_SCHEDULER``, else the local pool).
        progress: Optional callable ``progress(rows_done, rows)``.

    Returns:
        The class and attractor of each initial condition, the attractors, the valid domain's verdicts.

    Raises:
        ConfigError: For a bad frequency, range, size or cycle count.
        SchedulerError: For an unusable scheduler.
    """
    frequency_hz = check_frequency(config, frequency_hz)
    for name, (lo, hi) in (("theta_range", theta_range), ("theta_dot_range", theta_dot_range)):
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ConfigError(name, (lo, hi), "must be finite with min < max")
    if abs(theta_range[0]) > MAX_BASIN_ANGLE or abs(theta_range[1]) > MAX_BASIN_ANGLE:
        raise ConfigError("theta_range", theta_range, f"must stay within +-{MAX_BASIN_ANGLE:g} rad")
    if min(size) < 2 or max(size) > 2000:
        raise ConfigError("size", size, "each must be in [2, 2000]")
    check_cycles(transient_cycles, measure_cycles)
    start = time.perf_counter()
    thetas = np.linspace(*theta_range, size[0])
    rates = np.linspace(*theta_dot_range, size[1])
    model = model_for(config)
    p = model.params(config)
    limit = math.asin(min(1.0, config.rig.gap / config.rig.length))
    rule = stop_rule(transient_cycles, measure_cycles, early_stop)
    jobs = [(model.name, p, frequency_hz, thetas, float(r), limit, rule) for r in rates]
    rows, n, where = run_tasks(_basin_row, jobs, workers=workers, scheduler=scheduler, progress=progress)
    dom = domain(config)
    measures = [m for r in rows for m in r[2]]
    rules = ["" if m is None else dom.check(PointMeasures(*m)).invalid_rule for m in measures]
    shape = (len(rows), len(thetas))
    nan = math.nan

    def take(index: int) -> np.ndarray:
        return np.array([nan if m is None or m[3] else m[index] for m in measures], dtype=float).reshape(shape)

    labels = np.array([r[0] for r in rows], dtype=object)
    cycles = np.array([r[1] for r in rows], dtype=np.int64)
    settled = (cycles.ravel() <= rule.max_cycles).tolist()
    ids, attractors = _attractors(config, float(frequency_hz), labels.ravel().tolist(),
                                  [pt for r in rows for pt in r[3]], [pk for r in rows for pk in r[4]], settled,
                                  rule.tolerance)
    window = np.array([[nan if x is None else x for x in r[k]] for r in rows for k in (4, 5)],
                      dtype=float).reshape(len(rows), 2, len(thetas))
    return BasinsResult(config.rig.gap * 1e3, float(frequency_hz), thetas, rates, labels,
                        time.perf_counter() - start, n, cycles, where,
                        np.array(rules, dtype=object).reshape(shape), take(0), take(1),
                        dom.report(Verdict.of(r) for r, m in zip(rules, measures, strict=True) if m is not None),
                        ids.reshape(shape), attractors, window[:, 0], window[:, 1])


def _attractors(config: SimConfig, frequency_hz: float, labels: list[str], points: list, peaks: list,
                settled: list[bool], tolerance: float) -> tuple[np.ndarray, list[dict]]:
    """Attractor ids of the basins' initial conditions and the list of attractors (module docstring)."""
    rig = config.rig
    keep: list = [None if pts is None or label == FAILED else label
                  for label, pts in zip(labels, points, strict=True)]
    orbits = [None if label is None or not done else orbit_points(pts[:, 0], pts[:, 1], label, tolerance)
              for label, pts, done in zip(keep, points, settled, strict=True)]
    ids, reps = cluster_orbits(keep, orbits, tolerance)
    cells = np.bincount(ids[ids >= 0], minlength=len(reps))   # initial conditions per attractor
    omega = 2.0 * math.pi * frequency_hz
    out = []
    for a, r in enumerate(reps):
        found = orbits[r]
        orbit: np.ndarray = found if found is not None else points[r][-1:]
        u, v = orbit[:, 0], orbit[:, 1]
        theta = np.arcsin(np.clip(u * rig.amplitude / rig.length, -1.0, 1.0))
        theta_dot = v * rig.amplitude * omega / (rig.length * np.cos(theta))
        out.append({"id": a, "class": labels[r], "settled": orbits[r] is not None,
                    "period": 0 if orbits[r] is None else len(orbit),
                    "u": u.tolist(), "v": v.tolist(), "theta_rad": theta.tolist(),
                    "theta_dot_rad_s": theta_dot.tolist(),
                    "peak_force_n": float(peaks[r]), "cells": int(cells[a])})
    return ids, out


def basins_columns(result: BasinsResult) -> dict[str, list]:
    """The columns of ``basins.csv``, one value per initial condition, row by row (rate, then angle within a rate).

    The initial angle and rate, the class, the attractor id, then the valid domain's columns, then the peak force
    and impact velocity of its classified window (``peak_force_n``, ``impact_velocity_m_s``; NaN where not run).
    Whole-array operations: linear in the initial conditions.
    """
    rows, cols = result.labels.shape
    out: dict[str, list] = {
        "theta0_rad": np.tile(np.asarray(result.theta0, dtype=float), rows).tolist(),
        "theta_dot0_rad_s": np.repeat(np.asarray(result.theta_dot0, dtype=float), cols).tolist(),
        "class": result.labels.ravel().tolist(),
    }
    if result.attractor_id is not None:
        out["attractor_id"] = np.asarray(result.attractor_id, dtype=np.int64).ravel().tolist()
    if result.invalid_rule is not None and result.max_abs_theta is not None and result.max_force is not None:
        out.update(validity_columns(result.max_abs_theta[None], result.max_force[None], result.invalid_rule))
    if result.peak_force is not None and result.impact_velocity is not None:
        out["peak_force_n"] = np.asarray(result.peak_force, dtype=float).ravel().tolist()
        out["impact_velocity_m_s"] = np.asarray(result.impact_velocity, dtype=float).ravel().tolist()
    return out


def basins_table(result: BasinsResult) -> list[dict]:
    """CSV rows, one per initial condition: :func:`basins_columns` as one dict per row."""
    return rows_of(basins_columns(result))
