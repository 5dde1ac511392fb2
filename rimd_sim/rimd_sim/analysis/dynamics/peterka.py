"""Peterka maps: the class of the steady motion over gap/A0 x Omega/omega_n (the paper's Fig. 12 left).

Each cell (gap, frequency) runs from several starts, the motor at phase 0 and constant frequency, through the
ensemble kernel (:func:`rimd_sim.model.ensemble.run_cells`); each trajectory's motion is classified as
:func:`~rimd_sim.analysis.dynamics.steady.classify` does. The starts (:data:`START_NAMES`, then the extra ones):

* ``rest``: the hammer at rest (the paper's Table 1 protocol); its class is the cell's class;
* ``kick``: the hammer at its rest position with the relative velocity ``omega_n (gap + 2 A0)``, enough to reach
  the stop in free flight (the paper's "energy inserted", Fig. 12 right);
* ``continued``: the final state of the neighbouring cell at the next lower frequency, as an upward sweep;
* ``starts`` extra ones (:func:`extra_starts`): the no-impact forced response of the linearised pendulum, so that
  the no-impact motion is found wherever it coexists with impacting ones, then Halton points over the region of
  ``rimd basins``.

A cell whose starts end on more than one class holds coexisting attractors (``coexisting``, ``classes_found``).
The mark is a lower bound: an attractor whose basin holds no start is not found, and with ``starts - 1`` Halton
points a basin smaller than about ``1 / (starts - 1)`` of the region can be missed.

Each trajectory stops when the rule ``stop`` (:mod:`rimd_sim.model.ensemble`) finds its motion known, or at its cap
``transient_cycles + measure_cycles``, where its last ``measure_cycles`` are classified. The ``rest`` start has a
cap of its own, ``rest_cycles``: a trajectory from rest still unsettled at the common cap runs on, the same
trajectory, until the rule finds its motion known or it reaches ``rest_cycles``. :func:`rest_classes` is the
fixed-length reference such a map is checked against (docs/analyses.md, "Maps at scale").

Every trajectory is checked against the model's valid domain (:mod:`rimd_sim.model.validity`) over its whole run;
a cell is outside the domain when any of its starts is, with the union of their rules in the domain's order. One
gap row is one task of :func:`rimd_sim.analysis.executor.run_tasks`: its trajectories run in a few compiled calls.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from rimd_sim.analysis.dynamics.basins import default_basin_ranges
from rimd_sim.analysis.dynamics.cells import (
    check_cycles,
    class_codes,
    stop_rule,
    trajectory_measures,
    validity_columns,
)
from rimd_sim.analysis.dynamics.steady import check_frequencies
from rimd_sim.analysis.executor import run_tasks
from rimd_sim.analysis.outputs import rows_of
from rimd_sim.errors import ConfigError
from rimd_sim.model import validity
from rimd_sim.model.ensemble import StopRule, run_cells
from rimd_sim.model.rig_model import model_for
from rimd_sim.model.validity import PointMeasures, Verdict, domain
from rimd_sim.settings.config import SimConfig

__all__ = ["DEFAULT_EXTRA_STARTS", "DEFAULT_REST_CYCLES", "DEFAULT_STOP", "MAX_REST_CYCLES", "START_NAMES",
           "PeterkaResult", "cell_rules", "check_rest_cycles", "compare_maps", "extra_starts", "free_response",
           "peterka", "peterka_columns", "peterka_table", "rest_classes", "save_peterka_npz"]

START_NAMES = ("rest", "kick", "continued")
#: How a Peterka map's trajectories are judged settled by default: the ``contraction`` rule of
#: :mod:`rimd_sim.model.ensemble`. ``window`` is the rule of ``rimd basins`` and ``rimd map``.
DEFAULT_STOP = "contraction"
#: Extra starts per Peterka cell by default: the no-impact forced response (:func:`extra_starts`).
DEFAULT_EXTRA_STARTS = 1
#: Largest ``rest_cycles`` of a Peterka map (a run from rest of a million cycles is hours per cell).
MAX_REST_CYCLES = 1_000_000
#: The default cap of the start from rest with early stopping, a third of the reference of :func:`rest_classes`;
#: docs/analyses.md ("Maps at scale", "A cap of its own for the start from rest") gives how often the two agree.
DEFAULT_REST_CYCLES = 640


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
        workers: Processes (or Dask worker threads) used.
        cycles_per_start: Transient + measured cycles of each run: the cap when stopping early.
        cycles: Cycles each trajectory ran, same shape as ``labels`` (cap + 1 where it ran to the cap).
        early_stop: Whether trajectories stopped when their motion was known.
        where: ``local`` or the Dask scheduler's address.
        invalid_rules: The rules of the model's valid domain each trajectory of a named start broke
            (``;``-separated, ``""`` when valid), same shape as ``labels``.
        max_abs_theta: Largest ``|theta|`` (rad) of each trajectory's run, same shape (NaN where chattering).
        max_force: Largest impact force (N) of each trajectory's run, same shape (NaN where chattering).
        validity: The summary's report of the valid domain, one point per cell.
        extra_labels: Class per extra start (:func:`extra_starts`), shape ``(starts, rows, columns)``.
        extra_invalid_rules: The valid domain's rules per extra start, same shape.
        extra_max_abs_theta: Largest ``|theta|`` per extra start, same shape.
        extra_max_force: Largest impact force per extra start, same shape.
        peak_force: Largest impact force (N) of the classified window of the ``rest`` start, per cell (rows,
            columns): the steady force of the cell's motion from rest; 0 without impact, NaN where it failed.
        impact_velocity: Largest impact velocity (m/s, the approach speed at contact onset) of the same window.
        stop: The rule that judged trajectories settled when stopping early (``contraction`` or ``window``).
        rest_cycles: The cap of the ``rest`` start (0: ``cycles_per_start``, as for the other starts); its
            ``cycles`` are ``rest_cycles + 1`` where it ran to that cap.
        invalid_rule: Per cell, the rules its starts broke (:func:`cell_rules`: their union, in the domain's
            order), ``""`` when valid; shape ``(rows, columns)``.
    """

    gaps_mm: np.ndarray
    frequencies_hz: np.ndarray
    gap_ratio: np.ndarray
    frequency_ratio: np.ndarray
    labels: np.ndarray
    wall_seconds: float
    workers: int
    cycles_per_start: int
    cycles: np.ndarray = field(default_factory=lambda: np.zeros((0,)))
    early_stop: bool = False
    where: str = "local"
    invalid_rules: np.ndarray | None = None
    max_abs_theta: np.ndarray | None = None
    max_force: np.ndarray | None = None
    validity: dict | None = None
    extra_labels: np.ndarray | None = None
    extra_invalid_rules: np.ndarray | None = None
    extra_max_abs_theta: np.ndarray | None = None
    extra_max_force: np.ndarray | None = None
    peak_force: np.ndarray | None = None
    impact_velocity: np.ndarray | None = None
    stop: str = "window"
    rest_cycles: int = 0
    invalid_rule: np.ndarray | None = None

    @property
    def rest_cap(self) -> int:
        """The cap of the ``rest`` start (cycles): ``rest_cycles``, or the other starts' cap."""
        return self.rest_cycles or self.cycles_per_start

    @property
    def starts(self) -> int:
        """Starts per cell: the three named ones and the extra ones."""
        return len(START_NAMES) + (0 if self.extra_labels is None else len(self.extra_labels))

    @property
    def all_labels(self) -> np.ndarray:
        """Class per start, the named ones then the extra ones, shape ``(starts, rows, columns)``."""
        return self.labels if self.extra_labels is None else np.concatenate([self.labels, self.extra_labels])

    @property
    def valid(self) -> np.ndarray:
        """Per cell, whether every start stayed in the model's valid domain (True without verdicts)."""
        if self.invalid_rule is None:
            return np.ones(self.primary.shape, dtype=bool)
        return self.invalid_rule == ""

    @property
    def primary(self) -> np.ndarray:
        """The class from rest, per cell."""
        return self.labels[0]

    @property
    def coexisting(self) -> np.ndarray:
        """Cells where the starts end on different classes (a lower bound: module docstring)."""
        labels = self.all_labels
        return np.any(labels != labels[:1], axis=0)

    @property
    def classes_found(self) -> np.ndarray:
        """Per cell, the classes its starts ended on, sorted, ``;``-joined."""
        return _class_sets(*class_codes(self.all_labels))

    def class_counts(self) -> dict[str, int]:
        """Cells per class (from rest)."""
        return dict(Counter(self.primary.ravel().tolist()).most_common())


def _class_sets(names: list[str], codes: np.ndarray) -> np.ndarray:
    """Per element of ``codes[0]``, the classes ``codes`` hold along the first axis: names sorted, ``;``-joined.

    ``names`` sorted (:func:`~rimd_sim.analysis.dynamics.cells.class_codes`), so that increasing codes are sorted
    names. The distinct sets are found once (a map has few) and each element takes its own: no per-element join.
    """
    starts, cells = codes.shape[0], codes[0].size
    present = np.zeros((len(names), cells), dtype=bool)
    present[codes.reshape(starts, cells), np.arange(cells)] = True
    packed = np.ascontiguousarray(np.packbits(present, axis=0).T)   # per element, one bit per class
    keys = packed.view(np.dtype((np.void, packed.shape[1]))).ravel()
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    sets = np.array([";".join(names[c] for c in np.flatnonzero(present[:, k]).tolist()) for k in first.tolist()],
                    dtype=object)
    return sets[inverse.ravel()].reshape(codes.shape[1:])


#: The ``invalid_rule`` field of each rule mask (:func:`_rule_masks`; bit k: ``RULE_NAMES[k]``), in the domain's order.
_MASK_FIELDS = np.array([validity.joined(name for k, name in enumerate(validity.RULE_NAMES) if mask >> k & 1)
                         for mask in range(1 << len(validity.RULE_NAMES))], dtype=object)


def _rule_masks(fields: np.ndarray) -> np.ndarray:
    """Each ``invalid_rule`` field as a mask of the rules it names (bit k: ``RULE_NAMES[k]``), the same shape.

    A name outside the domain's counts for nothing, as in :func:`rimd_sim.model.validity.joined`; each distinct
    field is read once.
    """
    flat = fields.ravel().tolist()
    masks = {f: sum(1 << k for k, name in enumerate(validity.RULE_NAMES) if name in f.split(";")) for f in set(flat)}
    return np.fromiter(map(masks.__getitem__, flat), dtype=np.uint8, count=len(flat)).reshape(fields.shape)


def cell_rules(rules: np.ndarray) -> np.ndarray:
    """Per cell, the union of its starts' ``invalid_rule`` fields, in the domain's order (``""``: none broken).

    ``rules``: the fields per start, shape ``(starts, rows, columns)``; returns an object array ``(rows, columns)``.
    """
    return _MASK_FIELDS[np.bitwise_or.reduce(_rule_masks(rules), axis=0)]


def _row_ensemble(args):
    """One gap row in three compiled calls: the rest starts, the kick starts, then the continuation along the row.

    ``args``: ``(model, params, kick, freqs, rule, continued_rule, extra, rest_rule)``; ``extra`` (None or the
    ``(theta0, theta_dot0)`` arrays of shape ``(starts, frequencies)``) runs in a fourth call; ``rest_rule`` is
    the rest start's (its cap ``rest_cycles``; the others' rule but for the cap).

    Returns ``(labels, cycles, measures, window)``: per start, the class, the cycles run and the valid domain's
    measures (:func:`~rimd_sim.analysis.dynamics.cells.trajectory_measures`) of each frequency, the extra starts
    after the three named ones; and per frequency, the ``rest`` start's ``(peak force, impact velocity)`` of its
    classified window.
    """
    model, p, kick, freqs, rule, continued_rule, extra, rest_rule = args
    nf = len(freqs)
    zeros = np.zeros(nf)
    gi = np.zeros(nf, dtype=np.int64)
    rest = run_cells(model, p[None, :], gi, freqs, zeros, zeros, rest_rule)
    kicked = run_cells(model, p[None, :], gi, freqs, zeros, np.full(nf, kick), rule)
    chain = np.ones(nf, dtype=bool)
    chain[0] = False
    cont = run_cells(model, p[None, :], gi, freqs, zeros, zeros, continued_rule, chain=chain,
                     fallback=(rest.final[:, 0].copy(), rest.final[:, 1].copy()))
    out = ([rest.labels(), kicked.labels(), cont.labels()],
           [rest.cycles.tolist(), kicked.cycles.tolist(), cont.cycles.tolist()],
           [trajectory_measures(rest), trajectory_measures(kicked), trajectory_measures(cont)],
           _window(rest, nf))
    if extra is not None and extra[0].size:
        th0, om0 = extra
        ns = th0.shape[0]
        res = run_cells(model, p[None, :], np.zeros(ns * nf, dtype=np.int64), np.tile(freqs, ns), th0.ravel(),
                        om0.ravel(), rule)
        labels, cycles, measures = res.labels(), res.cycles.tolist(), trajectory_measures(res)
        for s in range(ns):
            out[0].append(labels[s * nf:(s + 1) * nf])
            out[1].append(cycles[s * nf:(s + 1) * nf])
            out[2].append(measures[s * nf:(s + 1) * nf])
    return out


def _window(res, n: int) -> list[tuple[float, float]]:
    """The first ``n`` cells' ``(window_peak, window_velocity)`` of an ensemble result (plain floats, for a task)."""
    assert res.window_peak is not None and res.window_velocity is not None  # run_cells fills them
    return list(zip(res.window_peak[:n].tolist(), res.window_velocity[:n].tolist(), strict=True))


def _halton(index: int, base: int) -> float:
    """Point ``index`` of the van der Corput sequence in ``base`` (in [0, 1))."""
    f, r = 1.0, 0.0
    while index > 0:
        f /= base
        r += f * (index % base)
        index //= base
    return r


def free_response(config: SimConfig, frequency_hz: float) -> tuple[float, float]:
    """``(theta, theta_dot)`` at phase 0 of the no-impact forced response of the linearised pendulum.

    ``theta'' + 2 zeta omega_n theta' + omega_n^2 theta = (A0 Omega^2 / l) sin(Omega t)`` (docs/physics.md without
    contact, small angles); the angle clipped to the stop. ``(0, 0)`` at an undamped resonance.
    """
    rig = config.rig
    w = 2.0 * math.pi * float(frequency_hz)
    den = complex(rig.omega_n ** 2 - w * w, 2.0 * rig.damping_ratio * rig.omega_n * w)
    if den == 0:
        return 0.0, 0.0
    amp = rig.amplitude * w * w / rig.length / den
    limit = math.asin(min(1.0, rig.gap / rig.length))
    return min(amp.imag, limit), w * amp.real


def extra_starts(config: SimConfig, frequencies_hz, starts: int) -> tuple[np.ndarray, np.ndarray]:
    """The extra starts of a Peterka row: ``(theta0, theta_dot0)``, each of shape ``(starts, frequencies)``.

    Start 0 is :func:`free_response` at each frequency: the no-impact motion, found so wherever it coexists with
    impacting ones. Start ``s >= 1`` is point ``s`` of the Halton sequence in bases 2 and 3 (the origin is point 0)
    over :func:`~rimd_sim.analysis.dynamics.basins.default_basin_ranges`, the same at every frequency; the sequence
    nests, so that more starts only add points.
    """
    freqs = np.asarray(frequencies_hz, dtype=float)
    th = np.zeros((starts, len(freqs)))
    om = np.zeros((starts, len(freqs)))
    if starts:
        free = [free_response(config, f) for f in freqs]
        th[0] = [t for t, _ in free]
        om[0] = [o for _, o in free]
    (t_lo, t_hi), (r_lo, r_hi) = default_basin_ranges(config)
    for s in range(1, starts):
        th[s] = t_lo + (t_hi - t_lo) * _halton(s, 2)
        om[s] = r_lo + (r_hi - r_lo) * _halton(s, 3)
    return th, om


def check_rest_cycles(rest_cycles, cap: int, early_stop: bool = True) -> int:
    """``rest_cycles`` of :func:`peterka` as an int, refused below the cap or past the maximum.

    None gives the default: :data:`DEFAULT_REST_CYCLES` (or ``cap`` if larger) with early stopping, else ``cap``
    (a fixed-length run is as long from every start).
    """
    if rest_cycles is None:
        return max(DEFAULT_REST_CYCLES, cap) if early_stop else cap
    if not (isinstance(rest_cycles, int | np.integer) and not isinstance(rest_cycles, bool)
            and cap <= rest_cycles <= MAX_REST_CYCLES):
        raise ConfigError("rest_cycles", rest_cycles,
                          f"must be an integer from the cap transient_cycles + measure_cycles = {cap} to "
                          f"{MAX_REST_CYCLES}")
    return int(rest_cycles)


def peterka(config: SimConfig, gaps_m, frequencies_hz, *, transient_cycles: int = 120, measure_cycles: int = 72,
            continued_transient_cycles: int = 60, early_stop: bool = True, starts: int = DEFAULT_EXTRA_STARTS,
            stop: str = DEFAULT_STOP, rest_cycles: int | None = None, workers: int | None = None,
            scheduler: str | None = None, progress=None) -> PeterkaResult:
    """Classify every (gap, frequency) cell from its starts (module docstring).

    Args:
        config: Rig configuration (mass, damping, contact, ...); gap and motor replaced per cell.
        gaps_m: Gaps (m), each >= 0.
        frequencies_hz: Motor frequencies (Hz), each > 0 and <= the motor maximum; run in increasing order.
        transient_cycles: Cycles dropped before measuring at the cap (starts ``rest`` and ``kick``).
        measure_cycles: Cycles classified at the cap (periods up to a third of it are found, at most 12).
        continued_transient_cycles: Transient of the ``continued`` start at its cap (it begins near an
            attractor).
        early_stop: Stop each trajectory when its motion is known (False: every one runs to the cap, the
            fixed-length run).
        starts: Extra starts per cell looking for coexisting attractors (:func:`extra_starts`), >= 0; 0 is the
            three-start map.
        stop: The early-stopping rule of :mod:`rimd_sim.model.ensemble`: ``contraction`` (the default, the
            convergence test on the stroboscopic map) or ``window`` (the fixed confirmation window, the rule of
            :func:`~rimd_sim.analysis.dynamics.basins.basins` and :func:`~rimd_sim.analysis.dynamics.maps.
            parameter_map`, so that the ``rest`` start can be compared with their cells run for run).
        rest_cycles: The cap of the start from rest, which gives the cell its class (module docstring): a
            trajectory from rest still unsettled at the other starts' cap runs on until it settles or reaches this
            many cycles, its last ``measure_cycles`` then classified. At least the other starts' cap,
            ``transient_cycles + measure_cycles``. Default (None): :data:`DEFAULT_REST_CYCLES`, or that cap if
            larger; without ``early_stop``, that cap.
        workers: Local processes (default: all cores).
        scheduler: Dask scheduler address (default ``$RIMD_DASK_SCHEDULER``, else the local pool).
        progress: Optional callable ``progress(rows_done, rows)``.

    Returns:
        The classes per start and cell, the cycles run, the valid domain's verdicts per trajectory and per cell
        with their report, and the costs.

    Raises:
        ConfigError: For a bad gap, frequency, cycle count or stop rule.
        SchedulerError: For an unusable scheduler.
    """
    gaps = [float(g) for g in gaps_m]
    if not gaps or any(not (math.isfinite(g) and g >= 0) for g in gaps):
        raise ConfigError("gaps", gaps, "must be non-empty, each finite and >= 0 m")
    freqs = sorted(check_frequencies(config, frequencies_hz))
    check_cycles(transient_cycles, measure_cycles)
    check_cycles(continued_transient_cycles, measure_cycles)
    if not (isinstance(starts, int | np.integer) and 0 <= starts <= 4096):
        raise ConfigError("starts", starts, "must be an integer in [0, 4096]")
    cap = transient_cycles + measure_cycles
    rest_cycles = check_rest_cycles(rest_cycles, cap, early_stop)
    start = time.perf_counter()
    rule = stop_rule(transient_cycles, measure_cycles, early_stop, stop)   # refuses an unknown rule
    continued_rule = stop_rule(continued_transient_cycles, measure_cycles, early_stop, stop)
    rest_rule = stop_rule(rest_cycles - measure_cycles, measure_cycles, early_stop, stop)
    rig = config.rig
    jobs = []
    for g in gaps:
        cfg = config.with_parameters({"gap": g})
        kick = rig.omega_n * (g + 2.0 * rig.amplitude) / rig.length  # rad/s
        model = model_for(cfg)
        jobs.append((model.name, model.params(cfg), kick, np.array(freqs), rule, continued_rule,
                     extra_starts(cfg, freqs, starts) if starts else None, rest_rule))
    rows, n, where = run_tasks(_row_ensemble, jobs, workers=workers, scheduler=scheduler, progress=progress)
    named = len(START_NAMES)
    # Arrays of shape (start, gap, frequency): the named starts, then the extra ones.
    labels = np.array([r[0] for r in rows], dtype=object).transpose(1, 0, 2)
    cycles = np.array([r[1] for r in rows], dtype=np.int64).transpose(1, 0, 2)[:named]
    measures = [r[2] for r in rows]   # gap, start, frequency -> (max |theta|, peak force, rate, chattering)
    # The domain does not depend on the gap (its force bound is the sensor's range): one for the whole map.
    dom = domain(config)
    rules = np.array([[[dom.check(PointMeasures(*m)).invalid_rule for m in per_start] for per_start in row]
                      for row in measures], dtype=object).transpose(1, 0, 2)
    per_cell = cell_rules(rules)
    nan = math.nan

    def take(index: int) -> np.ndarray:
        return np.array([[[nan if m[3] else m[index] for m in per_start] for per_start in row] for row in measures],
                        dtype=float).transpose(1, 0, 2)

    theta, force = take(0), take(1)
    window = np.array([r[3] for r in rows], dtype=float)   # gap, frequency, (peak, velocity)
    extra = slice(named, None) if starts else None
    return PeterkaResult(np.array(gaps) * 1e3, np.array(freqs), np.array(gaps) / rig.amplitude,
                         np.array(freqs) / rig.natural_frequency, labels[:named], time.perf_counter() - start, n,
                         cap, cycles, early_stop, where, rules[:named], theta[:named], force[:named],
                         dom.report(Verdict.of(r) for r in per_cell.ravel().tolist()),
                         extra_labels=None if extra is None else labels[extra],
                         extra_invalid_rules=None if extra is None else rules[extra],
                         extra_max_abs_theta=None if extra is None else theta[extra],
                         extra_max_force=None if extra is None else force[extra],
                         peak_force=window[..., 0], impact_velocity=window[..., 1], stop=stop,
                         rest_cycles=rest_cycles, invalid_rule=per_cell)


def _stacked(named: np.ndarray | None, extra: np.ndarray | None) -> np.ndarray | None:
    """A per-start array of the named starts followed by that of the extra ones (if any)."""
    return named if named is None or extra is None else np.concatenate([named, extra])


def peterka_columns(result: PeterkaResult) -> dict[str, list]:
    """The columns of ``peterka.csv``, one value per cell, row by row (gap, then frequency within a gap).

    The gap and frequency and their ratios, the class from each named start, ``coexisting``, ``classes_found`` and
    ``starts``; then the valid domain's columns (the largest |theta| and impact force over every start, ``valid``,
    ``invalid_rule``: the union over the starts); then the ``rest`` start's steady peak force and impact velocity
    (its classified window): ``peak_force_n``, ``impact_velocity_m_s``.

    ``coexisting`` and ``classes_found`` are over every start (``starts``: the three named ones and the extra
    ones), a lower bound (module docstring). Whole-array operations: linear in the cells; the valid domain's
    columns read the verdicts :func:`peterka` made, once per cell. Python values, as
    :func:`rimd_sim.analysis.outputs.write_columns` wants them.
    """
    rows, cols = result.primary.shape
    cells = rows * cols
    out: dict[str, list] = {
        "gap_mm": np.repeat(np.asarray(result.gaps_mm, dtype=float), cols).tolist(),
        "gap_ratio": np.repeat(np.asarray(result.gap_ratio, dtype=float), cols).tolist(),
        "frequency_hz": np.tile(np.asarray(result.frequencies_hz, dtype=float), rows).tolist(),
        "frequency_ratio": np.tile(np.asarray(result.frequency_ratio, dtype=float), rows).tolist(),
    }
    out.update({f"class_{name}": result.labels[k].ravel().tolist() for k, name in enumerate(START_NAMES)})
    out["coexisting"] = result.coexisting.ravel().tolist()
    out["classes_found"] = result.classes_found.ravel().tolist()
    out["starts"] = [result.starts] * cells
    theta = _stacked(result.max_abs_theta, result.extra_max_abs_theta)
    force = _stacked(result.max_force, result.extra_max_force)
    if theta is not None and force is not None and result.invalid_rule is not None:
        out.update(validity_columns(theta, force, result.invalid_rule))
    if result.peak_force is not None and result.impact_velocity is not None:
        out["peak_force_n"] = np.asarray(result.peak_force, dtype=float).ravel().tolist()
        out["impact_velocity_m_s"] = np.asarray(result.impact_velocity, dtype=float).ravel().tolist()
    return out


def peterka_table(result: PeterkaResult) -> list[dict]:
    """CSV rows, one per cell: :func:`peterka_columns` as one dict per row."""
    return rows_of(peterka_columns(result))


def save_peterka_npz(result: PeterkaResult, path) -> None:
    """Write the map as arrays (compact for big maps), NumPy ``.npz``.

    Arrays: ``classes`` (names), ``codes`` (start x gap x frequency, indices into ``classes``; the named starts
    then the extra ones), ``starts`` (their names: ``rest``, ``kick``, ``continued``, ``free``, ``halton1``,
    ...), ``coexisting`` (over every start, a lower bound), ``cycles`` (the named starts), ``gaps_mm``,
    ``frequencies_hz``, ``gap_ratio``, ``frequency_ratio``, ``valid`` and ``invalid_rule`` (per cell, the
    model's valid domain over every start), ``peak_force_n`` and ``impact_velocity_m_s`` (per cell, the classified
    window of the ``rest`` start).
    """
    names, codes = class_codes(result.all_labels)
    extra = result.starts - len(START_NAMES)
    start_names = [*START_NAMES, *(["free"] if extra else []), *(f"halton{s}" for s in range(1, extra))]
    rules = (np.full(result.primary.shape, "", dtype=object) if result.invalid_rule is None
             else result.invalid_rule)
    window: dict[str, np.ndarray] = {}
    if result.peak_force is not None and result.impact_velocity is not None:
        window = {"peak_force_n": result.peak_force, "impact_velocity_m_s": result.impact_velocity}
    np.savez_compressed(path, classes=np.array(names), codes=codes, starts=np.array(start_names),
                        coexisting=result.coexisting, cycles=result.cycles.astype(np.int32),
                        gaps_mm=result.gaps_mm, frequencies_hz=result.frequencies_hz, gap_ratio=result.gap_ratio,
                        frequency_ratio=result.frequency_ratio, valid=rules == "",
                        invalid_rule=rules.astype(str), **window)  # type: ignore[arg-type]


def compare_maps(early: PeterkaResult, fixed: PeterkaResult, config: SimConfig, measure_cycles: int, *,
                 long_factor: int = 10) -> dict:
    """Where an early-stopped map and a fixed-length map (same grid) disagree, and which is right.

    Returns the agreement per start and every differing cell with both classes; for the ``rest`` and ``kick``
    starts, also the class of a run ``long_factor`` times the start's cap (its last ``measure`` cycles), the verdict.
    The ``continued`` start depends on its neighbour's final state, which differs between the two maps, so it
    gets no long run.
    """
    rig = config.rig
    cells = []
    agreement = []
    for k, name in enumerate(START_NAMES):
        differ = early.labels[k] != fixed.labels[k]
        agreement.append(float(1.0 - differ.mean()))
        for i, j in zip(*np.nonzero(differ), strict=True):
            cell = {"start": name, "gap_mm": float(early.gaps_mm[i]), "frequency_hz": float(early.frequencies_hz[j]),
                    "early_stop": early.labels[k, i, j], "fixed_length": fixed.labels[k, i, j],
                    "early_stop_cycles": int(early.cycles[k, i, j]), "long_run": None}
            if name != "continued":
                cfg = config.with_parameters({"gap": early.gaps_mm[i] * 1e-3})
                kick = rig.omega_n * (cfg.rig.gap + 2.0 * rig.amplitude) / rig.length if name == "kick" else 0.0
                cap = long_factor * (fixed.rest_cap if name == "rest" else fixed.cycles_per_start)
                model = model_for(cfg)
                res = run_cells(model.name, model.params(cfg)[None, :], np.zeros(1, dtype=np.int64),
                                np.array([early.frequencies_hz[j]]), np.zeros(1), np.array([kick]),
                                StopRule(early=False, max_cycles=cap, measure_cycles=measure_cycles))
                cell["long_run"] = res.labels()[0]
                cell["long_run_cycles"] = cap
            cells.append(cell)
    return {"fixed_cycles": int(fixed.cycles_per_start), "agreement_from_rest": agreement[0],
            "agreement_per_start": dict(zip(START_NAMES, agreement, strict=True)),
            "fixed_wall_seconds": fixed.wall_seconds, "differing_cells": cells}


def _rest_row(args) -> list[str]:
    """One gap row of :func:`rest_classes`: every frequency from rest, at fixed length, in one compiled call."""
    model, p, freqs, rule = args
    n = len(freqs)
    return run_cells(model, p[None, :], np.zeros(n, dtype=np.int64), freqs, np.zeros(n), np.zeros(n),
                     rule).labels()


def rest_classes(config: SimConfig, gaps_m, frequencies_hz, *, cycles: int = 1920, measure_cycles: int = 72,
                 workers: int | None = None, scheduler: str | None = None, progress=None) -> np.ndarray:
    """The class from rest of every (gap, frequency) cell after a fixed number of cycles: a map's reference.

    Each trajectory runs ``cycles`` cycles (no early stop) and its last ``measure_cycles`` are classified, as the
    ``rest`` start of :func:`peterka` at its cap; default ten times the default cap (192). Returns the labels,
    shape ``(gaps, frequencies)``.
    """
    freqs = np.array(sorted(check_frequencies(config, frequencies_hz)))
    check_cycles(cycles - measure_cycles, measure_cycles)
    rule = StopRule(early=False, max_cycles=cycles, measure_cycles=measure_cycles)
    jobs = []
    for g in gaps_m:
        cfg = config.with_parameters({"gap": float(g)})
        model = model_for(cfg)
        jobs.append((model.name, model.params(cfg), freqs, rule))
    rows, _, _ = run_tasks(_rest_row, jobs, workers=workers, scheduler=scheduler, progress=progress)
    return np.array(rows, dtype=object)
