"""Bifurcation diagrams: the stroboscopic non-dimensional displacement ``l sin(theta) / A0`` versus Omega/omega.

The paper's Fig. 11. A sweep is one continuous run: at each frequency the motor ramps to it (at
``ramp_rate``) and the motion continues from the previous state, so the up and down sweeps can end on
different attractors (hysteresis, coexisting motions). After ``transient_cycles`` at the new frequency the
state is sampled once per cycle (motor phase a multiple of 2 pi) over ``sample_cycles`` cycles, and the
samples are classified (:func:`rimd_sim.analysis.dynamics.steady.classify`). The impacts started in the
sampled cycles (those the classification counts) give the point's steady peak force and impact velocity (the
approach speed at contact onset).

A third reading, ``rest``, starts every frequency from rest (the hammer at rest, the motor at that frequency
from t = 0), as Table 1 was measured: it finds the attractors a continued sweep never reaches (at gap 2.4 mm,
band B lies on an attractor the up and down sweeps pass by, the paper's coexisting motions). The directions
are independent runs: ``both`` (up and down) and ``all`` (up, down and rest) run them in parallel processes.

Every frequency is checked against the model's valid domain (:mod:`rimd_sim.model.validity`) over its ramp,
transient and samples; a point outside it is marked (``valid``, ``invalid_rule``). Where the chattering guard
fires, the point has no samples and the sweep goes on from rest at the next frequency
(``BifurcationBranch.restarts``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from rimd_sim.analysis.dynamics.steady import check_frequencies, classify, nondimensional
from rimd_sim.analysis.executor import run_tasks
from rimd_sim.errors import ConfigError
from rimd_sim.model.rig_model import ChatteringError, RigModel
from rimd_sim.model.validity import PointMeasures, Verdict, domain
from rimd_sim.settings.config import SimConfig

__all__ = ["DIRECTIONS", "BifurcationBranch", "BifurcationPoint", "bifurcation"]

#: The readings :func:`bifurcation` takes: one sweep, ``both`` (up and down) or ``all`` (up, down and rest).
DIRECTIONS = ("up", "down", "rest", "both", "all")


@dataclass(frozen=True)
class BifurcationPoint:
    """The stroboscopic samples at one frequency of a sweep.

    Attributes:
        frequency_hz: Motor frequency (Hz).
        frequency_ratio: Omega / omega_n.
        u: ``l sin(theta) / A0`` at each sampled cycle.
        label: The class of the sampled motion (``p/n``, ``no impact``, ``chaotic/non-periodic``).
        impacts_per_cycle: Mean impacts per cycle over the samples.
        max_abs_theta_rad: Largest ``|theta|`` over the point's ramp, transient and samples (rad).
        max_force_n: Largest peak force over the same (N).
        valid: Whether the point lies in the model's valid domain (:mod:`rimd_sim.model.validity`).
        invalid_rule: The rules it broke (``;``-separated names), ``""`` when valid.
        peak_force_n: Largest peak force of the impacts started in the sampled cycles (N); 0 without impact,
            NaN where the chattering guard fired.
        impact_velocity_m_s: Largest impact velocity of the same impacts (m/s); 0 without impact.
        final_state: ``(theta, theta_dot)`` (rad, rad/s) at the last sampled stroboscopic instant (motor phase
            0): a start on the attractor the sweep is on, for :func:`~rimd_sim.analysis.dynamics.lyapunov.
            largest_lyapunov` or a continuation; NaN where the chattering guard fired.
    """

    frequency_hz: float
    frequency_ratio: float
    u: np.ndarray
    label: str
    impacts_per_cycle: float
    max_abs_theta_rad: float = math.nan
    max_force_n: float = math.nan
    valid: bool = True
    invalid_rule: str = ""
    peak_force_n: float = math.nan
    impact_velocity_m_s: float = math.nan
    final_state: tuple[float, float] = (math.nan, math.nan)


@dataclass(frozen=True)
class BifurcationBranch:
    """One sweep direction."""

    direction: str
    points: tuple[BifurcationPoint, ...]
    simulated_seconds: float
    restarts: tuple[float, ...] = field(default=())

    @property
    def verdicts(self) -> list[Verdict]:
        """The valid domain's verdict of each point."""
        return [Verdict.of(p.invalid_rule) for p in self.points]


def _branch(args: tuple[SimConfig, list[float], str, int, int, float]) -> BifurcationBranch:
    config, freqs, direction, transient_cycles, sample_cycles, ramp_rate = args
    order = sorted(freqs, reverse=direction == "down")
    from_rest = direction == "rest"   # every frequency from rest: the attractors a sweep may never reach
    cfg = config.with_parameters({"motor.initial_frequency": order[0], "motor.initial_setpoint": order[0]})
    rig = cfg.rig
    rules = domain(cfg)

    def start(f: float) -> RigModel:
        return RigModel(config.with_parameters({"motor.initial_frequency": f, "motor.initial_setpoint": f}),
                        channels=False, truth=False, strobe=True)

    model: RigModel | None = start(order[0])
    points = []
    restarts = []
    simulated = 0.0
    fresh = True
    for i, f in enumerate(order):
        if from_rest and i:
            simulated += float(model.time) if model is not None else 0.0
            model, fresh = start(f), True
        elif model is None:
            model, fresh = start(f), True
            restarts.append(f)
        spans = []
        try:
            if not fresh:
                model.set_motor_frequency(f, ramp_rate)
                spans.append(model.advance(model.time + abs(f - order[i - 1]) / ramp_rate))
            fresh = False
            if transient_cycles:
                spans.append(model.advance(model.time + transient_cycles / f))
            # Window: the stroboscopic points closing cycles c0 + 1 .. c0 + N (c0: the cycle running now, after a
            # ramp at an arbitrary phase) and the impacts of the cycle each point opens.
            c0 = model.motor_state().cycle_index
            out = model.advance(model.time + (sample_cycles + 1.5) / f)
        except ChatteringError as error:
            # The state where the guard fired is no start for the next point: the sweep goes on from rest.
            simulated += error.t or 0.0
            verdict = rules.check(PointMeasures(chattering=True))
            points.append(BifurcationPoint(f, f / rig.natural_frequency, np.zeros(0), "", math.nan, math.nan,
                                           math.nan, False, verdict.invalid_rule))
            model = None
            continue
        spans.append(out)
        strobe = [s for s in out.strobe if c0 < s.cycle_index <= c0 + sample_cycles]
        sampled = [i for i in out.impacts if c0 < i.cycle_index <= c0 + sample_cycles]
        counts = np.bincount([i.cycle_index - c0 - 1 for i in sampled], minlength=sample_cycles)[:sample_cycles]
        u, v = nondimensional(rig.length, rig.amplitude, f, [s.theta for s in strobe], [s.theta_dot for s in strobe])
        n = min(len(u), len(counts))
        label = classify(u[:n], v[:n], counts[:n])[0]
        rate = float(counts.mean())
        max_theta = max(o.max_abs_theta for o in spans)
        max_force = max((imp.peak_force for o in spans for imp in o.impacts), default=0.0)
        verdict = rules.check(PointMeasures(max_theta, max_force, rate))
        points.append(BifurcationPoint(f, f / rig.natural_frequency, u, label, rate, max_theta, max_force,
                                       verdict.valid, verdict.invalid_rule,
                                       max((i.peak_force for i in sampled), default=0.0),
                                       max((i.impact_velocity for i in sampled), default=0.0),
                                       (float(strobe[-1].theta), float(strobe[-1].theta_dot)) if strobe
                                       else (math.nan, math.nan)))
    points.sort(key=lambda p: p.frequency_hz)
    if model is not None:
        simulated += float(model.time)
    return BifurcationBranch(direction, tuple(points), simulated, tuple(restarts))


def bifurcation(config: SimConfig, frequencies, direction: str = "both", *, transient_cycles: int = 100,
                sample_cycles: int = 48, ramp_rate: float = 2.0, workers: int | None = None,
                scheduler: str | None = None) -> tuple[list[BifurcationBranch], float, int]:
    """Run the up and/or down sweeps.

    Args:
        config: Rig configuration (gap, mass, ...).
        frequencies: Motor frequencies (Hz).
        direction: ``up``, ``down``, ``rest`` (each frequency from rest), ``both`` (up and down) or ``all``.
        transient_cycles: Cycles run at each frequency before sampling.
        sample_cycles: Cycles sampled at each frequency.
        ramp_rate: Motor ramp between frequencies (Hz/s).
        workers: Local processes for ``both`` and ``all`` (default 2).
        scheduler: Dask scheduler address (default ``$RIMD_DASK_SCHEDULER``, else local): each branch is a task.

    Returns:
        ``(branches, wall_seconds, processes)``.

    Raises:
        ConfigError: For a bad direction, frequency or cycle count.
    """
    if direction not in DIRECTIONS:
        raise ConfigError("direction", direction, f"must be one of {', '.join(DIRECTIONS)}")
    freqs = check_frequencies(config, frequencies)
    if transient_cycles < 0 or sample_cycles < 3:
        raise ConfigError("cycles", (transient_cycles, sample_cycles),
                          "need transient_cycles >= 0 and sample_cycles >= 3")
    if not ramp_rate > 0:
        raise ConfigError("ramp_rate", ramp_rate, "must be > 0 Hz/s")
    start = time.perf_counter()
    dirs = {"both": ["up", "down"], "all": ["up", "down", "rest"]}.get(direction, [direction])
    jobs = [(config, freqs, d, transient_cycles, sample_cycles, ramp_rate) for d in dirs]
    branches, n, _ = run_tasks(_branch, jobs, workers=workers or 2, scheduler=scheduler)
    return branches, time.perf_counter() - start, n


def branch_table(branches: list[BifurcationBranch]) -> list[dict]:
    """CSV rows: one per stroboscopic sample; the point's steady peak force and impact velocity on each of its rows."""
    rows = []
    for b in branches:
        for p in b.points:
            for k, u in enumerate(p.u):
                rows.append({"direction": b.direction, "frequency_hz": p.frequency_hz,
                             "frequency_ratio": p.frequency_ratio, "sample": k, "displacement_ratio": float(u),
                             "class": p.label, "impacts_per_cycle": p.impacts_per_cycle, "valid": p.valid,
                             "invalid_rule": p.invalid_rule, "peak_force_n": p.peak_force_n,
                             "impact_velocity_m_s": p.impact_velocity_m_s})
            if not len(p.u):   # no sample (the chattering guard fired): the point still has its row
                rows.append({"direction": b.direction, "frequency_hz": p.frequency_hz,
                             "frequency_ratio": p.frequency_ratio, "sample": "", "displacement_ratio": "",
                             "class": p.label, "impacts_per_cycle": p.impacts_per_cycle, "valid": p.valid,
                             "invalid_rule": p.invalid_rule, "peak_force_n": p.peak_force_n,
                             "impact_velocity_m_s": p.impact_velocity_m_s})
    return rows
