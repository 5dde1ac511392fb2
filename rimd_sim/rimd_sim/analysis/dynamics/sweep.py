"""Stepped frequency sweeps of the model: steady peak impact force and impacts per cycle versus frequency.

The paper's protocol (section 2.1, Table 1) steps the motor frequency on a 0.25 Hz grid and reads the
steady impact force at each step. Three directions:

* ``rest``: every frequency starts from rest (the hammer at rest, the motor at that frequency from
  t = 0), as in Table 1. Points are independent, so they run in a process pool on all cores.
* ``up`` / ``down``: one continuous run; at each step the motor ramps to the next frequency (at
  ``ramp_rate``) and the motion continues from the previous state, so hysteresis and coexisting
  attractors show (the paper's Fig. 12 right). Sequential by nature.

At each point the model runs ``cycles`` excitation cycles (after the ramp) and the steady state is read
over the last ``measure_cycles``: the largest peak force, the largest impact velocity (the approach speed at
contact onset, ``Impact.impact_velocity``) and the number of impacts per cycle; and the class of the motion.

Impacts per cycle: the last ``measure_cycles`` whole motor cycles (stroboscopic point to stroboscopic point)
that ended at least half a cycle before the point's end are classified as in
:func:`rimd_sim.analysis.dynamics.steady.classify`; a periodic ``p/n`` motion reads exactly ``p / n``. A
window of ``measure_cycles`` periods of time ending at the point's end would miss the impact in progress at
its end (its record closes with the contact) and, for a period that does not divide ``measure_cycles``,
could not hold a whole number of periods (a steady 1/1 would read 0.98). Where the window
is not periodic (chaotic, or not yet settled to the classification tolerance) the impacts per cycle are still
that count over the time window. The class (``motion_class``: ``p/n``, ``no impact``, ``chaotic/non-periodic``)
is that classification's label; ``integration failed`` where the chattering guard stopped the run, and empty
where the run holds fewer than ``measure_cycles`` whole cycles before its last half cycle.

Every point is checked against the model's valid domain (:mod:`rimd_sim.model.validity`) over its whole run
(the ramp and the transient included): the largest ``|theta|``, the largest contact force, the impacts per
cycle and whether the chattering guard fired. A point outside it is marked (``valid``, ``invalid_rule``); a
point where the guard fired has no measures (NaN), and a continued sweep goes on from rest at the next
frequency (``SweepResult.restarts``).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict
from typing import Literal

import numpy as np

from rimd_sim.analysis.dynamics.steady import check_frequencies, classify, nondimensional
from rimd_sim.analysis.dynamics.sweep_result import SweepPoint, SweepResult, band_peak
from rimd_sim.analysis.executor import run_tasks, scheduler_address
from rimd_sim.errors import ConfigError
from rimd_sim.model.rig_model import ChatteringError, RigModel
from rimd_sim.model.validity import PointMeasures, Verdict, domain
from rimd_sim.settings.config import SimConfig

__all__ = ["SweepPoint", "SweepResult", "band_peak", "sweep"]

Direction = Literal["up", "down", "rest"]


def _measure(impacts, t_end: float, f: float, measure_cycles: int) -> tuple[float, float, float]:
    """Largest peak force, impacts per cycle and largest impact velocity of the impacts of the last cycles."""
    t_from = t_end - measure_cycles / f
    last = [i for i in impacts if i.t_start >= t_from]
    return (max((i.peak_force for i in last), default=0.0), len(last) / measure_cycles,
            max((i.impact_velocity for i in last), default=0.0))


def _steady(out, t_end: float, f: float, measure_cycles: int, rig) -> tuple[str, float | None]:
    """The class of the last ``measure_cycles`` whole cycles of ``out`` and, when periodic, ``p / n`` (else None).

    The cycles are those whose stroboscopic points (start and end) lie in ``out`` and that ended at least half
    a cycle before ``t_end``, so that every impact started in them has closed its record. ``("", None)`` when
    ``out`` holds fewer such cycles.
    """
    ends = [s for s in out.strobe if s.t <= t_end - 0.5 / f]
    if len(ends) < measure_cycles + 1:
        return "", None
    window = ends[-measure_cycles - 1:-1]
    first = window[0].cycle_index
    if window[-1].cycle_index - first != measure_cycles - 1:
        return "", None
    counts = np.zeros(measure_cycles, dtype=np.int64)
    for i in out.impacts:
        if first <= i.cycle_index < first + measure_cycles:
            counts[i.cycle_index - first] += 1
    u, v = nondimensional(rig.length, rig.amplitude, f, [s.theta for s in window], [s.theta_dot for s in window])
    label, period, impacts, _ = classify(u, v, counts)
    return label, (impacts / period if period > 0 else None)


def _read(out, t_end: float, f: float, measure_cycles: int, rig) -> tuple[float, float, str, float]:
    """What a point reads of its measured cycles (module docstring).

    Returns ``(peak force, impacts per cycle, class, impact velocity)``; the impacts per cycle are ``p / n`` of a
    periodic motion, else the count over the time window.
    """
    peak, time_rate, velocity = _measure(out.impacts, t_end, f, measure_cycles)
    label, steady = _steady(out, t_end, f, measure_cycles, rig)
    return peak, time_rate if steady is None else steady, label, velocity


def _point(cfg: SimConfig, f: float, read: tuple[float, float, str, float], seconds: float, max_theta: float,
           max_force: float) -> SweepPoint:
    rig = cfg.rig
    peak, rate, label, velocity = read
    verdict = domain(cfg).check(PointMeasures(max_theta, max_force, rate))
    return SweepPoint(f, f / rig.natural_frequency, peak, peak / (rig.mass * rig.gravity), rate, seconds,
                      max_theta, max_force, verdict.valid, verdict.invalid_rule, label, velocity)


#: The class of a point whose run the chattering guard stopped (the maps' label of a failed trajectory).
FAILED = "integration failed"


def _chattering(cfg: SimConfig, f: float, seconds: float) -> SweepPoint:
    """A point where the chattering guard stopped the run: no measures."""
    nan = math.nan
    verdict = domain(cfg).check(PointMeasures(chattering=True))
    return SweepPoint(f, f / cfg.rig.natural_frequency, nan, nan, nan, seconds, nan, nan, False, verdict.invalid_rule,
                      FAILED, nan)


def _from_rest(args: tuple[SimConfig, float, int, int]) -> SweepPoint:
    base, f, cycles, measure_cycles = args
    cfg = base.with_parameters({"motor.initial_frequency": f, "motor.initial_setpoint": f})
    duration = cycles / f
    try:
        out = RigModel(cfg, channels=False, truth=False, strobe=True).advance(duration)
    except ChatteringError as error:
        return _chattering(cfg, f, math.nan if error.t is None else error.t)
    return _point(cfg, f, _read(out, duration, f, measure_cycles, cfg.rig), duration, out.max_abs_theta,
                  max((i.peak_force for i in out.impacts), default=0.0))


def _rest_chunk(jobs: list[tuple[SimConfig, float, int, int]]) -> list[SweepPoint]:
    return [_from_rest(job) for job in jobs]


def _continuous(job: tuple[SimConfig, list[float], int, int, float], progress=None
                ) -> tuple[list[SweepPoint], list[float]]:
    """An up or down sweep: one run, the motor ramped from point to point.

    Returns the points and the frequencies where the run went on from rest after a chattering point.
    """
    config, order, cycles, measure_cycles, ramp_rate = job

    def start(f: float) -> RigModel:
        return RigModel(config.with_parameters({"motor.initial_frequency": f, "motor.initial_setpoint": f}),
                        channels=False, truth=False, strobe=True)

    cfg = config.with_parameters({"motor.initial_frequency": order[0], "motor.initial_setpoint": order[0]})
    model: RigModel | None = start(order[0])
    points = []
    restarts: list[float] = []
    fresh = True
    for i, f in enumerate(order):
        if model is None:
            model, fresh = start(f), True
            restarts.append(f)
        t0 = model.time
        if not fresh:
            model.set_motor_frequency(f, ramp_rate)
        ramp = 0.0 if fresh else abs(f - order[i - 1]) / ramp_rate
        fresh = False
        try:
            out = model.advance(t0 + ramp + cycles / f)
        except ChatteringError as error:
            # The state where the guard fired is no start for the next point: the sweep goes on from rest.
            points.append(_chattering(cfg, f, math.nan if error.t is None else error.t - float(t0)))
            model = None
        else:
            t_end = float(model.time)
            points.append(_point(cfg, f, _read(out, t_end, f, measure_cycles, cfg.rig), t_end - float(t0),
                                 out.max_abs_theta, max((i.peak_force for i in out.impacts), default=0.0)))
        if progress:
            progress(i + 1, len(order))
    points.sort(key=lambda p: p.frequency_hz)
    return points, restarts


def sweep(config: SimConfig, frequencies: np.ndarray | list[float], direction: Direction = "rest", *,
          cycles: int = 150, measure_cycles: int = 50, ramp_rate: float = 2.0, workers: int | None = None,
          scheduler: str | None = None, progress=None) -> SweepResult:
    """Run a stepped sweep.

    Args:
        config: Rig configuration (gap, mass, contact, ...); its motor settings are replaced per point.
        frequencies: Motor frequencies (Hz), in sweep order for ``up``/``down``.
        direction: ``rest``, ``up`` or ``down``.
        cycles: Excitation cycles simulated per point (after the ramp).
        measure_cycles: Last cycles over which the steady state is read.
        ramp_rate: Ramp between steps of an ``up``/``down`` sweep (Hz/s).
        workers: Local processes for ``rest`` sweeps (default: all cores).
        scheduler: Dask scheduler address (default ``$RIMD_DASK_SCHEDULER``, else local): ``rest`` points run
            there as tasks, an ``up``/``down`` sweep as one task.
        progress: Optional callable ``progress(done, total)``.

    Returns:
        The points in frequency order, the bands A and B, the valid domain's report and the costs.

    Raises:
        ConfigError: For a bad direction, frequency or cycle count.
        SchedulerError: For an unusable scheduler.
    """
    if direction not in ("up", "down", "rest"):
        raise ConfigError("direction", direction, "must be up, down or rest")
    freqs = check_frequencies(config, frequencies)
    if not 0 < measure_cycles <= cycles:
        raise ConfigError("measure_cycles", measure_cycles, f"must be > 0 and <= cycles = {cycles}")
    start = time.perf_counter()
    points: list[SweepPoint] = []
    restarts: list[float] = []
    n_workers = 1
    if direction == "rest":
        # Chunks of points per task (interleaved, so each holds low and high frequencies): few enough that
        # submitting them costs little, enough to balance the workers. On a cluster, one point per task.
        local = scheduler_address(scheduler) is None
        n_chunks = min(len(freqs), 4 * max(1, workers or os.cpu_count() or 1)) if local else len(freqs)
        chunks = [list(range(len(freqs)))[i::n_chunks] for i in range(n_chunks)]
        jobs = [[(config, freqs[i], cycles, measure_cycles) for i in chunk] for chunk in chunks]

        def chunk_progress(done: int, total: int) -> None:
            progress(min(len(freqs), round(done * len(freqs) / total)), len(freqs))

        results, n_workers, _ = run_tasks(_rest_chunk, jobs, workers=workers, scheduler=scheduler,
                                          progress=chunk_progress if progress else None)
        by_index = {i: p for chunk, res in zip(chunks, results, strict=True) for i, p in zip(chunk, res, strict=True)}
        points = [by_index[i] for i in range(len(freqs))]
    else:
        order = sorted(freqs) if direction == "up" else sorted(freqs, reverse=True)
        job = (config, order, cycles, measure_cycles, ramp_rate)
        if scheduler_address(scheduler) is None:
            points, restarts = _continuous(job, progress)
        else:
            points, restarts = run_tasks(_continuous, [job], scheduler=scheduler, progress=progress and (
                lambda d, t: progress(len(order), len(order))))[0][0]
    pts = tuple(points)
    return SweepResult(
        gap_mm=config.rig.gap * 1e3, direction=direction, points=pts, band_a=band_peak(pts, 1.0),
        band_b=band_peak(pts, 0.5), simulated_seconds=math.fsum(p.simulated_seconds for p in pts),
        wall_seconds=time.perf_counter() - start, workers=n_workers,
        validity=domain(config).report(Verdict.of(p.invalid_rule) for p in pts), restarts=tuple(restarts))


def points_table(result: SweepResult) -> list[dict]:
    """Rows for a CSV file."""
    return [asdict(p) for p in result.points]
