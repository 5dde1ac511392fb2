"""Experiment design for identification: the motor steps that make every parameter identifiable for a rig.

``rimd identify`` needs impacts it can read (the contact pulse, the onsets, the impact velocity: the mass, ``k``,
``c``, the gap) and the hammer's free flight between them (``f_n``, ``zeta``), every step steady (a step still in
its transient, or chaotic, gives impacts the schedule cannot be aligned with). Which motor frequencies give that
depends on the rig: band A (one impact per cycle) lies around 1.6-2.5 times the natural frequency, shifted by
gap/A0 and the damping, and at gap/A0 above ~1.5 an upward sweep can stay on the motion without impact while a
start from rest impacts (the paper's Fig. 12; docs/interface.md, "What the twin must reproduce").

:func:`identification_steps` finds the steps for the rig as the user believes it is (a parameter file):

1. every candidate frequency on a grid from ``1.1 f_n`` to ``3.5 f_n`` is run from rest by the core (the
   simulator's integrator): impacts per cycle and peak force over the last cycles, and whether the two halves
   of that window agree (:func:`rimd_sim.analysis.recordings.recorded.settled`);
2. the longest run of consecutive candidates with one impact per cycle, steady, is band A; ``steps`` frequencies
   are spread evenly across it, so the impact velocities (and the pulses' scales) differ from step to step,
   which separates the mass from the contact law;
3. the schedule is built step by step as ``rimd experiment`` runs it: the first step from rest at the band's
   largest impact, then upward and downward to the spread targets, each continued from the state the step
   before left (the ramp, the dwell); a target where the continued run leaves band A (another attractor) is
   replaced by the nearest candidate that stays in it.

The result says, per step, what the core predicts. Band A keeps the hammer in free flight for most of each
cycle, which is what ``f_n`` and ``zeta`` are identified from (docs/identification.md; the battery of
``benchmarks/bench_identify.py`` shows the schedule identifies each parameter within its target, or says which
it cannot: a contact too short for the 20 kHz channel needs the triggered captures).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np

from rimd_sim.analysis.recordings.recorded import settled
from rimd_sim.errors import AnalysisError
from rimd_sim.settings.config import SimConfig

if TYPE_CHECKING:   # the model (and numba) is imported when a prediction runs
    from rimd_sim.model.rig_model import Impact

__all__ = ["Design", "DesignError", "StepPrediction", "identification_steps", "predict", "steps_for_identification"]

#: Cycles each candidate runs from rest, and the last ones it is read over.
CANDIDATE_CYCLES = 60
MEASURE_CYCLES = 20


class DesignError(AnalysisError):
    """No schedule fits the rig (one line: what was found, what to change)."""


@dataclass(frozen=True)
class StepPrediction:
    """What the core predicts for one step: impacts per cycle, peak force, impact velocity, steady or not."""

    frequency_hz: float
    impacts_per_cycle: float
    peak_force_n: float
    impact_velocity_m_s: float
    steady: bool


@dataclass
class Design:
    """The chosen steps, the core's prediction for each (as the experiment runs them), and the candidates."""

    frequencies: list[float]
    predictions: list[StepPrediction]
    band: tuple[float, float]
    candidates: list[StepPrediction] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def describe(self) -> str:
        """One line: the steps and why."""
        return (f"{len(self.frequencies)} steps in band A ({self.band[0]:g}-{self.band[1]:g} Hz, one steady impact "
                "per cycle for this rig): " + ", ".join(
                    f"{p.frequency_hz:g} Hz ({p.peak_force_n:.0f} N, {p.impact_velocity_m_s * 1e3:.0f} mm/s)"
                    for p in self.predictions) + ("; " + "; ".join(self.notes) if self.notes else ""))


def _read(impacts: Sequence[Impact], t_from: float, t_end: float, f: float) -> StepPrediction:
    times = np.array([i.t_start for i in impacts if t_from <= i.t_start < t_end])
    peaks = np.array([i.peak_force for i in impacts if t_from <= i.t_start < t_end])
    v0 = np.array([i.impact_velocity for i in impacts if t_from <= i.t_start < t_end])
    cycles = (t_end - t_from) * f
    ipc = times.size / cycles if cycles > 0 else 0.0
    steady = bool(times.size and settled(times, peaks, t_from, t_end, f))
    return StepPrediction(f, ipc, float(peaks.max()) if peaks.size else 0.0,
                          float(v0.mean()) if v0.size else 0.0, steady)


def _candidate(config: SimConfig, f: float) -> StepPrediction:
    from rimd_sim.model.rig_model import RigModel

    cfg = config.with_parameters({"motor.initial_frequency": f, "motor.initial_setpoint": f,
                                  "motor.max_frequency": max(config.motor.max_frequency, f)})
    duration = CANDIDATE_CYCLES / f
    impacts = RigModel(cfg, channels=False, truth=False).advance(duration).impacts
    return _read(impacts, duration - MEASURE_CYCLES / f, duration, f)


def predict(config: SimConfig, frequencies: list[float], *, dwell: float, settle: float, ramp_rate: float,
            start: float = 2.0) -> list[StepPrediction]:
    """The core's run of ``rimd experiment``'s timeline; per step, what its steady window holds.

    From rest at the first frequency, step ``k`` at ``start + k * dwell`` with its ramp; the steady window is the
    step after the ramp and ``settle``.
    """
    from rimd_sim.model.rig_model import RigModel

    f0 = frequencies[0]
    cfg = config.with_parameters({"motor.initial_frequency": f0, "motor.initial_setpoint": f0,
                                  "motor.max_frequency": max([config.motor.max_frequency, *frequencies])})
    model = RigModel(cfg, channels=False, truth=False)
    impacts = list(model.advance(Fraction(repr(start))).impacts)
    out = []
    prev = f0
    for k, f in enumerate(frequencies):
        t0 = start + k * dwell
        if k:
            impacts += model.set_motor_frequency(f, ramp_rate)
        impacts += model.advance(Fraction(repr(t0 + dwell))).impacts
        ramp = abs(f - prev) / ramp_rate if ramp_rate > 0 else 0.0
        out.append(_read(impacts, t0 + ramp + settle, t0 + dwell, f))
        prev = f
    return out


def _band_a(c: StepPrediction) -> bool:
    return c.steady and abs(c.impacts_per_cycle - 1.0) <= 0.03


def identification_steps(config: SimConfig, *, steps: int = 6, dwell: float = 10.0, settle: float = 3.0,
                         ramp_rate: float = 2.0, grid: float = 0.125, start: float = 2.0) -> Design:
    """The steps for identifying ``config``'s rig (see the module doc).

    Raises:
        DesignError: No run of candidates with one steady impact per cycle, or none of them reachable in the
            experiment's continued run.
    """
    import copy

    from rimd_sim.model.rig_model import RigModel

    if steps < 1:
        raise DesignError(f"steps {steps} refused: must be >= 1")
    fn = config.rig.natural_frequency
    lo = math.ceil(1.1 * fn / grid) * grid
    hi = min(3.5 * fn, config.motor.max_frequency)
    grid_f = [round(lo + i * grid, 9) for i in range(int((hi - lo) / grid) + 1)]
    candidates = [_candidate(config, f) for f in grid_f]
    runs: list[list[StepPrediction]] = []
    for c in candidates:
        if _band_a(c):
            if runs and abs(c.frequency_hz - runs[-1][-1].frequency_hz - grid) < 1e-9:
                runs[-1].append(c)
            else:
                runs.append([c])
    if not runs:
        raise DesignError(f"no motor frequency from {lo:g} to {hi:g} Hz gives this rig one steady impact per cycle "
                          f"(gap {config.rig.gap * 1e3:g} mm, A0 {config.rig.amplitude * 1e3:g} mm): check the rig's "
                          "parameter file, or choose the steps with --frequencies")
    band = max(runs, key=len)
    pool = [c.frequency_hz for c in band]
    # The first step: the band's largest impact among those that settle from rest within the first step (the
    # experiment starts the rig from rest there).
    first = None
    for c in sorted(band, key=lambda c: -c.peak_force_n):
        head = predict(config, [c.frequency_hz], dwell=dwell, settle=settle, ramp_rate=ramp_rate, start=start)[0]
        if _band_a(head):
            first = c.frequency_hz
            break
    if first is None:
        raise DesignError(f"this rig does not settle to one impact per cycle from rest within {dwell:g} s anywhere in "
                          f"band A ({pool[0]:g}-{pool[-1]:g} Hz): a longer --dwell, or choose the steps with "
                          "--frequencies")
    n = min(steps, len(pool))
    targets = [pool[i] for i in np.linspace(0, len(pool) - 1, n).round().astype(int)]
    if first in targets:
        targets.remove(first)
    else:
        targets.remove(min(targets, key=lambda f: abs(f - first)))
    # Visit upward from the first step, then downward: each step continued from the one before, as the
    # experiment runs; a target that leaves band A there is replaced by the nearest unused candidate that stays.
    order = sorted(f for f in targets if f > first) + sorted((f for f in targets if f < first), reverse=True)
    cfg = config.with_parameters({"motor.initial_frequency": first, "motor.initial_setpoint": first,
                                  "motor.max_frequency": max([config.motor.max_frequency, *pool])})
    model = RigModel(cfg, channels=False, truth=False)
    impacts = list(model.advance(Fraction(repr(start + dwell))).impacts)
    chosen, preds = [first], [_read(impacts, start + settle, start + dwell, first)]
    notes = []
    used = {first}
    for target in order:
        t0 = start + len(chosen) * dwell
        for f in sorted((f for f in pool if f not in used), key=lambda f: abs(f - target))[:4]:
            trial = copy.deepcopy(model)
            got = trial.set_motor_frequency(f, ramp_rate)
            got += trial.advance(Fraction(repr(t0 + dwell))).impacts
            ramp = abs(f - chosen[-1]) / ramp_rate if ramp_rate > 0 else 0.0
            pred = _read(got, t0 + ramp + settle, t0 + dwell, f)
            if _band_a(pred):
                model, used = trial, used | {f}
                chosen.append(f)
                preds.append(pred)
                if f != target:
                    notes.append(f"{f:g} Hz instead of {target:g} Hz (the continued run leaves band A there)")
                break
        else:
            notes.append(f"no step near {target:g} Hz stays in band A in the continued run: left out")
    if len(chosen) < steps:
        notes.append(f"{len(chosen)} steps (band A: {len(pool)} grid frequencies {grid:g} Hz apart)")
    return Design(chosen, preds, (pool[0], pool[-1]), candidates, notes)


def steps_for_identification(config_path: str, *, frequencies: list[float] | None, dwell: float, settle: float,
                             ramp_rate: float) -> list[float]:
    """``rimd experiment --for-identification CONFIG``: the steps for the rig of ``CONFIG`` (empty: the default).

    The design is said on stderr. Raises :class:`DesignError` (one line) for --frequencies given as well, a
    parameter file that does not load, or no schedule for the rig.
    """
    import sys

    from rimd_sim.errors import ConfigError
    from rimd_sim.settings.config import find_config_file, load_config

    if frequencies:
        raise DesignError("--for-identification chooses the frequencies: leave out --frequencies")
    path = config_path or find_config_file()
    try:
        config = load_config(path)
    except ConfigError as exc:
        raise DesignError(f"--for-identification {path}: {exc}") from None
    rate = ramp_rate if ramp_rate > 0 else config.motor.ramp_rate
    design = identification_steps(config, dwell=dwell, settle=settle, ramp_rate=rate)
    print(f"rimd experiment: for identification of the rig of {path}: {design.describe()}", file=sys.stderr,
          flush=True)
    return design.frequencies
