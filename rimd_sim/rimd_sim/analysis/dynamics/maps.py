"""Maps over any two declared parameters: the steady motion, its peak force and impact velocity per cell.

A Peterka map (:mod:`rimd_sim.analysis.dynamics.peterka`) varies the gap and the motor frequency. Designing a new
RIMD asks other questions: which (natural frequency, mass) gives one impact per cycle at the motor's frequency,
and with what force. :func:`parameter_map` varies any two numeric parameters of :class:`SimConfig`, by their
flat ROS names (``natural_frequency``, ``mass``, ``damping_ratio``, ``gap``, ``contact.stiffness``, ...), or
the motor frequency (``"frequency"``, Hz), and reads per cell:

* the class of the steady motion (``p/n``, ``no impact``, ``chaotic/non-periodic``; ``integration failed``),
* the peak impact force (N) and the largest impact velocity (m/s, the approach speed at contact onset) of the
  classified window, and the force ratio ``F / (m g)`` with that cell's ``m`` and ``g``,
* the impacts per cycle of that window, the cycles run, and the model's valid domain's verdict
  (:mod:`rimd_sim.model.validity`, over the cell's whole run, as the Peterka map checks each start).

Protocol: every cell runs from rest (the hammer at rest, the motor at the cell's frequency from t = 0, phase 0:
the paper's Table 1 protocol, the ``rest`` start of a Peterka map), through the compiled ensemble
(:func:`rimd_sim.model.ensemble.run_cells`, bit-identical to a ``RigModel`` run): each trajectory stops when its
motion is known, or at the cap ``transient_cycles + measure_cycles``, whose last ``measure_cycles`` are
classified (cycles ``transient + 1 .. transient + measure``, as :func:`~rimd_sim.analysis.dynamics.steady.
steady_orbit` reads them). ``early_stop=False`` runs every cell to the cap. A stepped sweep of ``cycles`` per
point reads the cycles ``cycles - measure .. cycles - 1`` instead (:mod:`rimd_sim.analysis.dynamics.sweep`):
the same run as a fixed-length map cell with ``transient_cycles = cycles - measure - 1``.

Every cell's configuration is built with :meth:`SimConfig.with_parameters` in the calling process before any
work starts, so a refused value is one :class:`~rimd_sim.errors.ConfigError` naming the parameter and its rule.
The model must be the same in every cell (only its parameter vector changes): ``structure.model`` and
``contact.model`` cannot be mapped (run one map per model), nor a parameter that is not a number; nor the
``motor.*`` and ``initial.*`` parameters, which the protocol sets (map ``"frequency"`` instead); nor those of
the instruments, the pacing or the seed, which do not enter the model: the mappable ones are the numbers of
the rig (``gap``, ``mass``, ..., ``contact.*``, ``structure.*``) and of the integrator (``integrator.*``). One row of
cells (one ``y`` value, every ``x``) is one task of :func:`rimd_sim.analysis.executor.run_tasks`: inline, a
local process pool, or a Dask cluster, as the other maps.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass

import numpy as np

from rimd_sim.analysis.dynamics.cells import class_codes, cycles_summary, stop_rule
from rimd_sim.analysis.dynamics.steady import check_frequencies, check_frequency
from rimd_sim.analysis.executor import run_tasks
from rimd_sim.analysis.outputs import rows_of
from rimd_sim.errors import ConfigError
from rimd_sim.model.ensemble import run_cells
from rimd_sim.model.rig_model import model_for
from rimd_sim.model.validity import PointMeasures, Verdict, domain
from rimd_sim.settings.config import PARAMETERS, SimConfig

__all__ = ["FREQUENCY", "ParameterMap", "axis_unit", "mappable_parameters", "parameter_map", "save_map_npz"]

#: The axis name of the motor frequency (Hz): not a parameter of :class:`SimConfig` but of the protocol.
FREQUENCY = "frequency"
#: Parameter prefixes the protocol sets itself (the motor at the cell's frequency from t = 0, from rest).
_PROTOCOL = ("motor.", "initial.")
#: The settings groups that make the model's parameter vector: the rig's and the integrator's.
_MODEL_GROUPS = ("rig", "integrator")


def mappable_parameters() -> list[str]:
    """The names an axis may take: ``frequency`` and every numeric parameter of the rig and the integrator."""
    return [FREQUENCY, *(name for name, p in PARAMETERS.items()
                         if p.kind in ("float", "int") and p.attr[:1] in {(g,) for g in _MODEL_GROUPS})]


def axis_unit(name: str) -> str:
    """The unit of an axis, from the parameter's declaration (``Hz`` for ``frequency``; ``""`` when none)."""
    return "Hz" if name == FREQUENCY else PARAMETERS[name].unit


def _check_axis(name: str, values) -> list[float | int]:
    """The axis values as numbers of the parameter's kind, or ConfigError naming the axis (module docstring)."""
    if not isinstance(name, str) or (name != FREQUENCY and name not in PARAMETERS):
        raise ConfigError(str(name), values, "unknown parameter (known: " + ", ".join(mappable_parameters()) + ")")
    if name != FREQUENCY:
        p = PARAMETERS[name]
        if p.kind not in ("float", "int"):
            raise ConfigError(name, values, "cannot be mapped: a map varies numbers, and " + (
                "it selects the model (run one map per model)" if name in ("structure.model", "contact.model")
                else f"this parameter is {p.kind}"))
        if name.startswith(_PROTOCOL):
            raise ConfigError(name, values, "cannot be mapped: the map's protocol sets it (the motor at each "
                                            f"cell's frequency from t = 0, from rest); map '{FREQUENCY}' instead")
        if name not in mappable_parameters():
            raise ConfigError(name, values, "cannot be mapped: it does not enter the model (mappable: "
                                            + ", ".join(mappable_parameters()) + ")")
    try:
        out = [float(v) for v in values]
    except (TypeError, ValueError):
        raise ConfigError(name, values, "axis values must be numbers") from None
    if not out or len(out) > 10000 or not all(math.isfinite(v) for v in out):
        raise ConfigError(name, out, "axis values must be 1 to 10000 finite numbers")
    if name != FREQUENCY and PARAMETERS[name].kind == "int":
        return [int(v) if v.is_integer() else v for v in out]   # with_parameters refuses a fraction, naming it
    return out


@dataclass(frozen=True)
class ParameterMap:
    """A map over two parameters (module docstring); every array has rows along ``y``, columns along ``x``.

    Attributes:
        x: The parameter of the columns (flat ROS name, or ``frequency``).
        y: The parameter of the rows.
        x_values: Its values (in its declared unit), one per column.
        y_values: Its values, one per row.
        frequency_hz: Motor frequency (Hz) per cell.
        frequency_ratio: ``Omega / omega_n`` per cell (its own natural frequency).
        labels: Class of the steady motion from rest, per cell (strings).
        peak_force: Largest impact force of the classified window (N); 0 without impact, NaN where it failed.
        force_ratio: ``peak_force / (m g)`` with the cell's mass and gravity.
        impact_velocity: Largest impact velocity of the classified window (m/s, the approach speed at contact
            onset); 0 without impact, NaN where it failed.
        impacts_per_cycle: Impacts per cycle of the classified window (NaN where it failed).
        cycles: Cycles each trajectory ran (the cap + 1 where it ran to the cap).
        max_abs_theta: Largest ``|theta|`` of the run (rad; NaN where the chattering guard fired).
        max_force: Largest impact force of the whole run (N; NaN where the chattering guard fired).
        invalid_rule: The rules of the model's valid domain the cell broke (``;``-separated), ``""`` when valid.
        transient_cycles: Cycles dropped before measuring at the cap.
        measure_cycles: Cycles classified at the cap.
        early_stop: Whether trajectories stopped when their motion was known.
        wall_seconds: Wall time (s).
        workers: Processes (or Dask worker threads) used.
        where: ``local`` or the Dask scheduler's address.
        validity: The summary's report of the valid domain, one point per cell.
    """

    x: str
    y: str
    x_values: np.ndarray
    y_values: np.ndarray
    frequency_hz: np.ndarray
    frequency_ratio: np.ndarray
    labels: np.ndarray
    peak_force: np.ndarray
    force_ratio: np.ndarray
    impact_velocity: np.ndarray
    impacts_per_cycle: np.ndarray
    cycles: np.ndarray
    max_abs_theta: np.ndarray
    max_force: np.ndarray
    invalid_rule: np.ndarray
    transient_cycles: int
    measure_cycles: int
    early_stop: bool
    wall_seconds: float
    workers: int
    where: str
    validity: dict

    @property
    def x_unit(self) -> str:
        """The unit of ``x`` (its declaration's)."""
        return axis_unit(self.x)

    @property
    def y_unit(self) -> str:
        """The unit of ``y``."""
        return axis_unit(self.y)

    @property
    def valid(self) -> np.ndarray:
        """Per cell, whether its run stayed in the model's valid domain."""
        return self.invalid_rule == ""

    def class_counts(self) -> dict[str, int]:
        """Cells per class."""
        return dict(Counter(self.labels.ravel().tolist()).most_common())

    def columns(self) -> dict[str, list]:
        """The columns of ``map.csv``, one value per cell, row by row.

        The two parameters (named as given), then the cell's figures. Whole-array operations: linear in the cells;
        Python values (an int parameter's stay integers).
        """
        rows, cols = self.labels.shape

        def flat(values: np.ndarray, dtype: type = float) -> list:
            return np.asarray(values, dtype=dtype).ravel().tolist()

        xs, ys = [_plain(v) for v in self.x_values], [_plain(v) for v in self.y_values]
        out: dict[str, list] = {self.x: xs * rows}
        out[self.y] = [v for v in ys for _ in range(cols)]
        out.update({"frequency_hz": flat(self.frequency_hz), "frequency_ratio": flat(self.frequency_ratio),
                    "class": self.labels.ravel().tolist(), "peak_force_n": flat(self.peak_force),
                    "force_ratio": flat(self.force_ratio), "impact_velocity_m_s": flat(self.impact_velocity),
                    "impacts_per_cycle": flat(self.impacts_per_cycle), "cycles": flat(self.cycles, np.int64),
                    "max_abs_theta_rad": flat(self.max_abs_theta), "max_force_n": flat(self.max_force),
                    "valid": self.valid.ravel().tolist(), "invalid_rule": self.invalid_rule.ravel().tolist()})
        return out

    def table(self) -> list[dict]:
        """CSV rows, one per cell: :meth:`columns` as one dict per row."""
        return rows_of(self.columns())

    def summary(self) -> dict:
        """The ``summary.json`` content of ``rimd map`` (docs/analyses.md)."""
        force = np.where(np.isfinite(self.peak_force) & self.valid, self.peak_force, -np.inf)
        top = None
        if np.isfinite(force).any() and force.max() > 0:
            i, j = np.unravel_index(int(np.argmax(force)), force.shape)
            top = {self.x: _plain(self.x_values[j]), self.y: _plain(self.y_values[i]), "class": self.labels[i, j],
                   "peak_force_n": float(self.peak_force[i, j]), "force_ratio": float(self.force_ratio[i, j]),
                   "impact_velocity_m_s": float(self.impact_velocity[i, j])}
        frequencies = np.unique(self.frequency_hz)
        return {
            "x": {"name": self.x, "unit": self.x_unit, "values": [_plain(v) for v in self.x_values]},
            "y": {"name": self.y, "unit": self.y_unit, "values": [_plain(v) for v in self.y_values]},
            "frequency_hz": float(frequencies[0]) if len(frequencies) == 1 else None,
            "start": "rest", "cells": int(self.labels.size), "classes": self.class_counts(),
            "impacting_cells": int(((self.peak_force > 0) & np.isfinite(self.peak_force)).sum()),
            "largest_peak_force": top, "transient_cycles": self.transient_cycles,
            "measure_cycles": self.measure_cycles, "early_stop": self.early_stop,
            "cycles_run": cycles_summary(self.cycles[None], self.transient_cycles + self.measure_cycles),
            "wall_seconds": self.wall_seconds, "workers": self.workers, "where": self.where,
            "validity": self.validity,
        }


def _plain(v) -> float | int:
    """An axis value as a plain number (an int parameter's values stay integers)."""
    return v.item() if isinstance(v, np.generic) else v


def _map_row(args) -> tuple[list[str], list[int], list, list[float], list[float], list[float]]:
    """One row of cells in one compiled call: per cell its own parameter vector and frequency, from rest.

    Returns plain lists (they travel back from a task): the classes, the cycles run, the valid domain's measures
    ``(max |theta|, peak force of the run, impacts per cycle, chattering)``, and the classified window's peak
    force, impact velocity and impacts per cycle.
    """
    model, params, freqs, rule = args
    n = len(freqs)
    zeros = np.zeros(n)
    res = run_cells(model, params, np.arange(n, dtype=np.int64), freqs, zeros, zeros, rule)
    assert res.window_peak is not None and res.window_velocity is not None and res.impacts_per_cycle is not None
    measures = [(m.max_abs_theta, m.peak_force, m.impacts_per_cycle, m.chattering) for m in res.measures()]
    return (res.labels(), res.cycles.tolist(), measures, res.window_peak.tolist(), res.window_velocity.tolist(),
            res.impacts_per_cycle.tolist())


def parameter_map(config: SimConfig, x: str, x_values, y: str, y_values, *, frequency_hz: float | None = None,
                  transient_cycles: int = 120, measure_cycles: int = 72, early_stop: bool = True,
                  workers: int | None = None, scheduler: str | None = None, progress=None) -> ParameterMap:
    """Classify the steady motion from rest in every cell of ``x`` x ``y`` and read its force (module docstring).

    Args:
        config: Rig configuration; each cell is ``config.with_parameters({x: xv, y: yv})``.
        x: The parameter of the columns: a flat ROS name (``natural_frequency``, ``mass``, ``gap``,
            ``contact.stiffness``, ...) or ``frequency`` (the motor frequency, Hz).
        x_values: Its values, in its declared unit (SI: ``gap`` in m).
        y: The parameter of the rows (another one).
        y_values: Its values.
        frequency_hz: The motor frequency (Hz) of every cell when neither axis is ``frequency``; None otherwise.
        transient_cycles: Cycles dropped before measuring at the cap.
        measure_cycles: Cycles classified at the cap (periods up to a third of it are found, at most 12).
        early_stop: Stop each trajectory when its motion is known (False: every one runs to the cap).
        workers: Local processes (default: all cores).
        scheduler: Dask scheduler address (default ``$RIMD_DASK_SCHEDULER``, else the local pool).
        progress: Optional callable ``progress(rows_done, rows)``.

    Raises:
        ConfigError: For an unknown or unmappable axis, a value the parameter refuses (naming it and its rule),
            a bad frequency or cycle count; before any cell runs.
        SchedulerError: For an unusable scheduler.
    """
    xs, ys = _check_axis(x, x_values), _check_axis(y, y_values)
    if x == y:
        raise ConfigError("y", y, f"must differ from x = {x}")
    mapped_frequency = FREQUENCY in (x, y)
    if mapped_frequency and frequency_hz is not None:
        raise ConfigError("frequency", frequency_hz, f"is an axis of this map ({FREQUENCY}): give no frequency_hz")
    if not mapped_frequency:
        if frequency_hz is None:
            raise ConfigError("frequency", frequency_hz, f"is needed unless an axis is '{FREQUENCY}'")
        frequency_hz = check_frequency(config, frequency_hz)
    else:
        check_frequencies(config, xs if x == FREQUENCY else ys)
    if transient_cycles < 0 or measure_cycles < 6:
        raise ConfigError("cycles", (transient_cycles, measure_cycles),
                          "need transient_cycles >= 0 and measure_cycles >= 6")
    start = time.perf_counter()
    # Every cell's configuration first: a refused value stops the map before any work.
    configs, freqs = [], np.zeros((len(ys), len(xs)))
    for i, yv in enumerate(ys):
        row = []
        for j, xv in enumerate(xs):
            values = {x: xv, y: yv}
            freqs[i, j] = float(values.pop(FREQUENCY, frequency_hz))   # type: ignore[arg-type]
            row.append(config.with_parameters(values))
        configs.append(row)
    model = model_for(config)
    rule = stop_rule(transient_cycles, measure_cycles, early_stop)
    jobs = [(model.name, np.array([model.params(c) for c in row]), freqs[i], rule) for i, row in enumerate(configs)]
    rows, n, where = run_tasks(_map_row, jobs, workers=workers, scheduler=scheduler, progress=progress)
    shape = freqs.shape
    nan = math.nan
    labels = np.array([r[0] for r in rows], dtype=object).reshape(shape)
    cycles = np.array([r[1] for r in rows], dtype=np.int64).reshape(shape)
    peak = np.array([r[3] for r in rows], dtype=float).reshape(shape)
    velocity = np.array([r[4] for r in rows], dtype=float).reshape(shape)
    rate = np.array([r[5] for r in rows], dtype=float).reshape(shape)
    theta, force = np.full(shape, nan), np.full(shape, nan)
    rules = np.full(shape, "", dtype=object)
    ratio, weight = np.zeros(shape), np.zeros(shape)
    for i, row in enumerate(configs):
        for j, cfg in enumerate(row):
            m = rows[i][2][j]
            rules[i, j] = domain(cfg).check(PointMeasures(*m)).invalid_rule
            if not m[3]:
                theta[i, j], force[i, j] = m[0], m[1]
            ratio[i, j] = freqs[i, j] / cfg.rig.natural_frequency
            weight[i, j] = cfg.rig.mass * cfg.rig.gravity
    report = domain(config).report(Verdict.of(r) for r in rules.ravel().tolist())
    return ParameterMap(x, y, np.array(xs), np.array(ys), freqs, ratio, labels, peak, peak / weight, velocity, rate,
                        cycles, theta, force, rules, transient_cycles, measure_cycles, early_stop,
                        time.perf_counter() - start, n, where, report)


def save_map_npz(result: ParameterMap, path) -> None:
    """Write the map as arrays, NumPy ``.npz`` (rows along ``y``, columns along ``x``).

    Arrays: ``x_name``, ``y_name``, ``x_values``, ``y_values``, ``classes`` (names) and ``codes`` (indices into
    them), ``frequency_hz``, ``peak_force_n``, ``force_ratio``, ``impact_velocity_m_s``, ``impacts_per_cycle``,
    ``cycles``, ``valid`` and ``invalid_rule``.
    """
    names, codes = class_codes(result.labels)
    np.savez_compressed(path, x_name=np.array(result.x), y_name=np.array(result.y), x_values=result.x_values,
                        y_values=result.y_values, classes=np.array(names), codes=codes,
                        frequency_hz=result.frequency_hz, peak_force_n=result.peak_force,
                        force_ratio=result.force_ratio, impact_velocity_m_s=result.impact_velocity,
                        impacts_per_cycle=result.impacts_per_cycle, cycles=result.cycles.astype(np.int32),
                        valid=result.valid, invalid_rule=result.invalid_rule.astype(str))
