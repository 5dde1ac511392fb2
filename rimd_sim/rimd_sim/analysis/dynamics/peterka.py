"""Peterka maps (gap/A0 x Omega/omega) and basins of attraction (theta0 x theta_dot0) of the steady motions.

Peterka map (the paper's Fig. 12 left)
--------------------------------------
Each cell (gap, frequency) is classified (:func:`rimd_sim.analysis.dynamics.steady.steady_orbit`) from three
initial conditions, the motor at phase 0 and constant frequency:

* ``rest``: the hammer at rest (the Table 1 protocol);
* ``kick``: the hammer at rest position with a relative velocity ``omega_n (gap + 2 A0)``, enough to reach
  the stop in free flight (the paper's "energy inserted", Fig. 12 right);
* ``continued``: the final state of the neighbouring cell at the next lower frequency, as an upward sweep.

The cell's class is the one from rest. More starts look for the other attractors (``starts`` extra per cell,
default 1, ``rimd peterka --starts N``), run in the same compiled call per row:

* the first, ``free``: the hammer on the no-impact forced response of the linearised pendulum (its state at
  phase 0, clipped to the stop), so the no-impact motion is found wherever it coexists with impacting ones
  (at gap 2.4 mm, 2.548 Hz, Omega/omega_n = 1.4: with 1/1 for both configurations; its basin from the region
  below is 33 of 576 initial conditions in config/rimd.yaml, 1 of 576 in config/paper_model.yaml);
* the others: the points of a Halton sequence (bases 2, 3; the first N - 1 points after the origin) over the
  region of ``rimd basins`` (:func:`default_basin_ranges`: angles from ``-3 (gap + A0) / l`` to the stop,
  rates within ``+-3 omega_n (gap + A0) / l``); the sequence nests, so raising N only adds starts.

A cell is marked as holding coexisting attractors when its starts end on more than one class
(``classes_found``). The mark is a lower bound: an attractor whose basin misses every start is not found;
with N - 1 Halton points, a basin that covers less than about 1 / (N - 1) of the region can be missed.
``starts=0`` is the three-start map. Each trajectory stops as soon as its motion is known or at the cap,
``transient_cycles + measure_cycles`` (default 120 + 72, twice the fixed length the map used before early
stopping), where its last ``measure_cycles`` are classified. Known means, by default (``stop="contraction"``, the
rule of :mod:`rimd_sim.model.ensemble`), that its stroboscopic points repeat with a period n <= 12 and that their
repetition shrinks between two blocks of max(4, 2 n) cycles so that they are within 1e-4 of their limit (a
no-impact motion: shrinking, and clear of the stop by more than it can still change); ``stop="window"`` is the
former rule (a period repeated to 1e-4 over max(24, 4 n) cycles, after at least 30 cycles), which reproduces the
maps made before it bit for bit. :func:`rest_classes` is a fixed-length reference. One gap row is one task:
its 3 x frequencies trajectories run in one compiled call (the ``continued`` start runs along the row); the
tasks go through the executor seam (:mod:`rimd_sim.analysis.executor`): a local process pool on all cores,
or a Dask cluster.

Long transients
---------------
Only the ``rest`` start gives the cell its class, and it has a cap of its own, ``rest_cycles`` (default 640, the
others' cap 192). A trajectory from rest still unsettled at the common cap runs on, the same trajectory bit for bit,
until the stop rule finds its motion known or it reaches ``rest_cycles``, where its last ``measure_cycles`` are
classified as a fixed run of that length classifies them: with ``rest_cycles=1920`` every class is that of
:func:`rest_classes` at 1920 cycles but for the trajectories the stop rule stopped earlier. On 100 x 100 cells of
the default rig, against that 1920-cycle reference: 99.52 % of the cells alike at the default 640, 96.62 % with the
common cap (``rest_cycles=192``), 99.8 % with 1920 (docs/analyses.md). The cells whose start from rest settled
before the common cap, and the other starts, do not depend on ``rest_cycles``.

Basins of attraction
--------------------
At one (gap, frequency), a grid of initial conditions ``(theta0, theta_dot0)`` (hammer not inside the stop)
each classified the same way; one grid row per task in the pool.

Each initial condition also gets an attractor id: the orbit it ends on, its stroboscopic points (the last
``n`` of the classified window for a ``p/n`` class, or the smallest repeating set of a no-impact motion) in
the non-dimensional ``(u, v)`` of :mod:`rimd_sim.analysis.dynamics.steady`, compared as a set with the
orbits met before to the classification tolerance (:func:`~rimd_sim.analysis.dynamics.steady.cluster_orbits`):
the same orbit shares an id, another orbit of the same class (another 1/1, a 1/2 shifted by one cycle) gets
its own. Only settled motions are told apart by their orbit: a trajectory that ran to the cap without
settling (a non-periodic motion, or a slow transient: near a period doubling a 2/4 read at the cap is still
converging to 1/2, its points spread by 1e-2 from one initial condition to the next) has no orbit to compare,
and those of one class share one id (``settled`` false in the list of attractors).

The model's valid domain
------------------------
Every trajectory is checked against :mod:`rimd_sim.model.validity` over its whole run: the compiled loop
returns its largest ``|theta|``, its largest impact force, its impacts per cycle over the classified window and
whether the chattering guard stopped it (:mod:`rimd_sim.model.ensemble`); the verdicts are made here, in the
calling process, from those plain numbers (they travel back from the tasks with the classes). A Peterka cell is
outside the domain when any of its starts is (its rules: the union over the starts, in the domain's
order); a basin's initial condition when its trajectory is. The classes are reported as before, and marked.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from rimd_sim.analysis.dynamics.steady import (
    check_frequencies,
    check_frequency,
    cluster_orbits,
    orbit_points,
    steady_orbit,
)
from rimd_sim.analysis.executor import run_tasks
from rimd_sim.analysis.outputs import rows_of
from rimd_sim.errors import ConfigError, IntegrationError
from rimd_sim.model import validity
from rimd_sim.model.ensemble import StopRule, run_cells
from rimd_sim.model.rig_model import model_for
from rimd_sim.model.validity import (
    PointMeasures,
    ValidityDomain,
    Verdict,
    domain,
)
from rimd_sim.settings.config import SimConfig

__all__ = ["BasinsResult", "DEFAULT_EXTRA_STARTS", "DEFAULT_STOP", "PeterkaResult", "START_NAMES", "basins",
           "basins_columns", "class_codes", "extra_starts", "peterka", "peterka_columns", "rest_classes"]

START_NAMES = ("rest", "kick", "continued")
#: How a Peterka map's trajectories are judged settled by default (module docstring; ``window``: the former rule).
DEFAULT_STOP = "contraction"
#: Extra starts per Peterka cell by default: the no-impact forced response (module docstring).
DEFAULT_EXTRA_STARTS = 1
FAILED = "integration failed"
#: Largest initial angle (rad) of a basins grid: short of the horizontal, where the model's domain ends.
MAX_BASIN_ANGLE = 1.5


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
        invalid_rules: The rules of the model's valid domain each trajectory broke (``;``-separated, ``""``
            when valid), same shape as ``labels``.
        max_abs_theta: Largest ``|theta|`` (rad) of each trajectory's run, same shape (NaN where chattering).
        max_force: Largest impact force (N) of each trajectory's run, same shape (NaN where chattering).
        validity: The summary's report of the valid domain, one point per cell.
        extra_labels: Class per extra start (module docstring), shape ``(starts, rows, columns)``.
        extra_invalid_rules: The valid domain's rules per extra start, same shape.
        extra_max_abs_theta: Largest ``|theta|`` per extra start, same shape.
        extra_max_force: Largest impact force per extra start, same shape.
        peak_force: Largest impact force (N) of the classified window of the ``rest`` start, per cell (rows,
            columns): the steady force of the cell's motion from rest; 0 without impact, NaN where it failed.
        impact_velocity: Largest impact velocity (m/s, the approach speed at contact onset) of the same window.
        stop: How trajectories were judged settled when stopping early (``contraction`` or ``window``).
        rest_cycles: The cap of the ``rest`` start (0: ``cycles_per_start``, as for the other starts); its
            ``cycles`` are ``rest_cycles + 1`` where it ran to that cap.
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

    def _all(self, named, extra):
        return named if named is None or extra is None else np.concatenate([named, extra])

    @property
    def invalid_rule(self) -> np.ndarray:
        """Per cell, the rules its starts broke (the union, in the domain's order), ``""`` when valid."""
        if self.invalid_rules is None:
            return np.full(self.primary.shape, "", dtype=object)
        rules = self._all(self.invalid_rules, self.extra_invalid_rules)
        return _rule_fields(np.bitwise_or.reduce(_rule_masks(rules), axis=0))

    @property
    def valid(self) -> np.ndarray:
        """Per cell, whether every start stayed in the model's valid domain."""
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


def class_codes(labels: np.ndarray) -> tuple[list[str], np.ndarray]:
    """The classes of ``labels`` (sorted) and each element's index into them (int16, the shape of ``labels``).

    One dictionary look-up per element, no sort of the elements: linear in their number.
    """
    flat = labels.ravel().tolist()
    names = sorted(set(flat))
    index = {c: i for i, c in enumerate(names)}
    codes = np.fromiter(map(index.__getitem__, flat), dtype=np.int16, count=len(flat))
    return names, codes.reshape(labels.shape)


def _class_sets(names: list[str], codes: np.ndarray) -> np.ndarray:
    """Per element of ``codes[0]``, the classes ``codes`` hold along the first axis: names sorted, ``;``-joined.

    ``names`` sorted (:func:`class_codes`), so that increasing codes are sorted names. The distinct sets are found
    once (a map has few) and each element takes its own: no per-element join.
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


def _rule_fields(masks: np.ndarray) -> np.ndarray:
    """The ``invalid_rule`` field of each rule mask (``""``: none broken), an object array of the same shape."""
    return _MASK_FIELDS[masks]


def _measures(res) -> list[tuple[float, float, float, bool]]:
    """Per cell of an :class:`~rimd_sim.model.ensemble.EnsembleResult`, its measures as plain tuples (for a task)."""
    return [(m.max_abs_theta, m.peak_force, m.impacts_per_cycle, m.chattering) for m in res.measures()]


def _verdicts(dom: ValidityDomain, measures) -> list[str]:
    return [dom.check(PointMeasures(*m)).invalid_rule for m in measures]


def _classify(config: SimConfig, f: float, theta0: float, theta_dot0: float, transient: int, measure: int):
    try:
        orbit = steady_orbit(config, f, theta0=theta0, theta_dot0=theta_dot0, transient_cycles=transient,
                             measure_cycles=measure)
    except IntegrationError:
        return FAILED, (0.0, 0.0)
    return orbit.label, orbit.final_state


def _row(args: tuple[SimConfig, float, list[float], int, int, int]) -> list[tuple[str, str, str]]:
    """One gap row through :func:`steady_orbit`: one ``RigModel`` per trajectory, a fixed length.

    The path before the ensemble kernel, kept as the reference of the benchmark.
    """
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


def _row_ensemble(args):
    """One gap row in three compiled calls: the rest starts, the kick starts, then the continuation along the row.

    ``args``: ``(model, params, kick, freqs, rule, continued_rule, extra, rest_rule)``; ``extra`` (None or the
    ``(theta0, theta_dot0)`` arrays of shape ``(starts, frequencies)``) runs in a fourth call; ``rest_rule`` is
    the rest start's (its cap ``rest_cycles``; the others' rule but for the cap).

    Returns ``(labels, cycles, measures, window)``: per start, the class, the cycles run and the valid domain's
    measures (:func:`_measures`) of each frequency, the extra starts after the three named ones; and per
    frequency, the ``rest`` start's ``(peak force, impact velocity)`` of its classified window.
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
           [_measures(rest), _measures(kicked), _measures(cont)],
           _window(rest, nf))
    if extra is not None and extra[0].size:
        th0, om0 = extra
        ns = th0.shape[0]
        res = run_cells(model, p[None, :], np.zeros(ns * nf, dtype=np.int64), np.tile(freqs, ns), th0.ravel(),
                        om0.ravel(), rule)
        labels, cycles, measures = res.labels(), res.cycles.tolist(), _measures(res)
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
    """The extra starts of a Peterka row (module docstring): ``(theta0, theta_dot0)``, each ``(starts, freqs)``.

    Start 0 is :func:`free_response` at each frequency; start ``s >= 1`` is Halton point ``s`` (bases 2 and 3)
    over :func:`default_basin_ranges`, the same at every frequency.
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


#: Largest ``rest_cycles`` of a Peterka map (a run from rest of a million cycles is hours per cell).
MAX_REST_CYCLES = 1_000_000
#: The default cap of the start from rest with early stopping: the class of 99.5 % of the cells is that of a run ten
#: times as long (docs/analyses.md, "Long transients").
DEFAULT_REST_CYCLES = 640


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


def _check_cycles(transient: int, measure: int) -> None:
    if transient < 0 or measure < 6:
        raise ConfigError("cycles", (transient, measure), "need transient_cycles >= 0 and measure_cycles >= 6")


def stop_rule(transient_cycles: int, measure_cycles: int, early_stop: bool, method: str = "window") -> StopRule:
    """The rule of :mod:`rimd_sim.model.ensemble` with the cap ``transient + measure`` cycles.

    ``method`` ``window`` (the fixed confirmation window, at least 30 cycles) or ``contraction`` (the convergence
    test on the stroboscopic map, no floor but its own blocks).
    """
    cap = transient_cycles + measure_cycles
    return StopRule(max_cycles=cap, measure_cycles=measure_cycles, early=early_stop,
                    min_cycles=0 if method == "contraction" else min(30, cap), method=method)


def peterka(config: SimConfig, gaps_m, frequencies_hz, *, transient_cycles: int = 120, measure_cycles: int = 72,
            continued_transient_cycles: int = 60, early_stop: bool = True, starts: int = DEFAULT_EXTRA_STARTS,
            stop: str = DEFAULT_STOP, rest_cycles: int | None = None, workers: int | None = None,
            scheduler: str | None = None, progress=None) -> PeterkaResult:
    """Classify every (gap, frequency) cell from three starts (module docstring).

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
        starts: Extra starts per cell looking for coexisting attractors (module docstring), >= 0; 0 is the
            three-start map.
        stop: How a trajectory is judged settled when stopping early (module docstring): ``contraction`` (the
            default, the convergence test on the stroboscopic map) or ``window`` (the former fixed confirmation
            window: the maps made before, bit for bit).
        rest_cycles: The cap of the start from rest, which gives the cell its class (module docstring, "Long
            transients"): a trajectory from rest still unsettled at the other starts' cap runs on until it settles
            or reaches this many cycles, its last ``measure_cycles`` then classified. At least the other starts'
            cap, ``transient_cycles + measure_cycles``. Default (None): :data:`DEFAULT_REST_CYCLES` (640), or that
            cap if larger; without ``early_stop``, that cap.
        workers: Local processes (default: all cores).
        scheduler: Dask scheduler address (default ``$RIMD_DASK_SCHEDULER``, else the local pool).
        progress: Optional callable ``progress(rows_done, rows)``.

    Returns:
        The classes per start and cell, the cycles run, the valid domain's verdicts and the costs.

    Raises:
        ConfigError: For a bad gap, frequency, cycle count or stop method.
        SchedulerError: For an unusable scheduler.
    """
    gaps = [float(g) for g in gaps_m]
    if not gaps or any(not (math.isfinite(g) and g >= 0) for g in gaps):
        raise ConfigError("gaps", gaps, "must be non-empty, each finite and >= 0 m")
    freqs = sorted(check_frequencies(config, frequencies_hz))
    _check_cycles(transient_cycles, measure_cycles)
    _check_cycles(continued_transient_cycles, measure_cycles)
    if not (isinstance(starts, int | np.integer) and 0 <= starts <= 4096):
        raise ConfigError("starts", starts, "must be an integer in [0, 4096]")
    cap = transient_cycles + measure_cycles
    rest_cycles = check_rest_cycles(rest_cycles, cap, early_stop)
    start = time.perf_counter()
    rule = stop_rule(transient_cycles, measure_cycles, early_stop, stop)   # refuses an unknown method
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
    all_labels = np.array([r[0] for r in rows], dtype=object).transpose(1, 0, 2)
    labels = all_labels[:len(START_NAMES)]
    cycles = np.array([r[1] for r in rows], dtype=np.int64).transpose(1, 0, 2)[:len(START_NAMES)]
    # The domain does not depend on the gap (its force bound is the sensor's range): one for the whole map.
    dom = domain(config)
    measures = [r[2] for r in rows]   # row, start, frequency -> (max |theta|, peak force, rate, chattering)
    all_rules = np.array([[_verdicts(dom, per_start) for per_start in row] for row in measures],
                         dtype=object).transpose(1, 0, 2)
    named = len(START_NAMES)
    nan = math.nan

    def take(index: int) -> np.ndarray:
        return np.array([[[nan if m[3] else m[index] for m in per_start] for per_start in row] for row in measures],
                        dtype=float).transpose(1, 0, 2)

    theta, force = take(0), take(1)
    window = np.array([r[3] for r in rows], dtype=float)   # row, frequency, (peak, velocity)
    result = PeterkaResult(np.array(gaps) * 1e3, np.array(freqs), np.array(gaps) / rig.amplitude,
                           np.array(freqs) / rig.natural_frequency, labels, time.perf_counter() - start, n,
                           transient_cycles + measure_cycles, cycles, early_stop, where, all_rules[:named],
                           theta[:named], force[:named],
                           extra_labels=all_labels[named:] if starts else None,
                           extra_invalid_rules=all_rules[named:] if starts else None,
                           extra_max_abs_theta=theta[named:] if starts else None,
                           extra_max_force=force[named:] if starts else None,
                           peak_force=window[..., 0], impact_velocity=window[..., 1], stop=stop,
                           rest_cycles=rest_cycles)
    return _with_validity(result, dom)


def _with_validity(result, dom: ValidityDomain):
    from dataclasses import replace

    return replace(result, validity=dom.report(Verdict.of(r) for r in result.invalid_rule.ravel().tolist()))


def peterka_columns(result: PeterkaResult) -> dict[str, list]:
    """The columns of ``peterka.csv``, one value per cell, row by row (gap, then frequency within a gap).

    The gap and frequency and their ratios, the class from each named start, ``coexisting``, ``classes_found`` and
    ``starts``; then the valid domain's columns (the largest |theta| and impact force over every start, ``valid``,
    ``invalid_rule``: the union over the starts); then the ``rest`` start's steady peak force and impact velocity
    (its classified window): ``peak_force_n``, ``impact_velocity_m_s``.

    ``coexisting`` and ``classes_found`` are over every start (``starts``: the three named ones and the extra
    ones), a lower bound (module docstring). Whole-array operations: linear in the cells. Python values, as
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
    if result.max_abs_theta is not None:
        out.update(_validity_arrays(result._all(result.max_abs_theta, result.extra_max_abs_theta),
                                    result._all(result.max_force, result.extra_max_force), result.invalid_rule))
    if result.peak_force is not None and result.impact_velocity is not None:
        out["peak_force_n"] = np.asarray(result.peak_force, dtype=float).ravel().tolist()
        out["impact_velocity_m_s"] = np.asarray(result.impact_velocity, dtype=float).ravel().tolist()
    return out


def peterka_table(result: PeterkaResult) -> list[dict]:
    """CSV rows, one per cell: :func:`peterka_columns` as one dict per row."""
    return rows_of(peterka_columns(result))


def _validity_arrays(max_abs_theta: np.ndarray, max_force: np.ndarray, invalid_rule: np.ndarray) -> dict[str, list]:
    """The valid domain's columns of a table, one value per element of ``invalid_rule`` (row by row).

    ``max_abs_theta`` and ``max_force`` have one more axis in front (the starts, or one): the largest |theta| and
    impact force over it, NaN where none is finite; then ``valid`` and ``invalid_rule``.
    """
    def largest(values: np.ndarray) -> list[float]:
        values = np.asarray(values, dtype=float)
        top = np.fmax.reduce(values, axis=0)   # NaN ignored, as np.nanmax
        return np.where(np.isfinite(values).any(axis=0), top, math.nan).ravel().tolist()

    return {"max_abs_theta_rad": largest(max_abs_theta), "max_force_n": largest(max_force),
            "valid": (invalid_rule == "").ravel().tolist(), "invalid_rule": invalid_rule.ravel().tolist()}


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
    _check_cycles(cycles - measure_cycles, measure_cycles)
    rule = StopRule(early=False, max_cycles=cycles, measure_cycles=measure_cycles)
    jobs = []
    for g in gaps_m:
        cfg = config.with_parameters({"gap": float(g)})
        model = model_for(cfg)
        jobs.append((model.name, model.params(cfg), freqs, rule))
    rows, _, _ = run_tasks(_rest_row, jobs, workers=workers, scheduler=scheduler, progress=progress)
    return np.array(rows, dtype=object)


def cycles_summary(cycles: np.ndarray, cap: int, rest_cap: int | None = None) -> dict:
    """How long the trajectories ran: mean cycles per start, and the fraction stopped before the cap.

    ``rest_cap``: the cap of the first start (a Peterka map's ``rest``, :attr:`PeterkaResult.rest_cap`) when it
    differs from the others'; then also ``rest_cap`` and ``rest_ran_to_cap``, the fraction of the cells whose start
    from rest ran to its cap (classified on its last cycles without having settled).
    """
    if cycles.size == 0:
        return {}
    caps = np.full(len(cycles), cap)
    if rest_cap is not None:
        caps[0] = rest_cap
    early = cycles <= caps.reshape((-1,) + (1,) * (cycles.ndim - 1))
    out = {"mean": float(cycles.mean()), "cap": int(cap), "stopped_early": float(early.mean()),
           "mean_per_start": [float(c.mean()) for c in cycles]}
    if rest_cap is not None:
        out.update(rest_cap=int(rest_cap), rest_ran_to_cap=float((cycles[0] > rest_cap).mean()))
    return out


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
    rules = result.invalid_rule
    window: dict[str, np.ndarray] = {}
    if result.peak_force is not None and result.impact_velocity is not None:
        window = {"peak_force_n": result.peak_force, "impact_velocity_m_s": result.impact_velocity}
    np.savez_compressed(path, classes=np.array(names), codes=codes, starts=np.array(start_names),
                        coexisting=result.coexisting, cycles=result.cycles.astype(np.int32),
                        gaps_mm=result.gaps_mm, frequencies_hz=result.frequencies_hz, gap_ratio=result.gap_ratio,
                        frequency_ratio=result.frequency_ratio, valid=rules == "",
                        invalid_rule=rules.astype(str), **window)  # type: ignore[arg-type]


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


INSIDE = "inside the stop"


def _basin_row(args: tuple[str, np.ndarray, float, np.ndarray, float, float, StopRule]
               ) -> tuple[list[str], list[int], list, list, list, list]:
    """One row of initial conditions (one rate, every angle) in one compiled call.

    Returns ``(labels, cycles, measures, points, window_peaks, window_velocities)``; the measures
    (:func:`_measures`), the last stroboscopic points ``(u, v)``, the largest impact force and impact velocity of
    the classified window are None where not run.
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
        for j, label, c, m, pts, pk, vel in zip(run.tolist(), res.labels(), res.cycles.tolist(), _measures(res),
                                                res.points, res.window_peak.tolist(), res.window_velocity.tolist(),
                                                strict=True):
            labels[j] = label
            cycles[j] = c
            measures[j] = m
            points[j] = pts
            peaks[j] = pk
            vels[j] = vel
    return labels, cycles, measures, points, peaks, vels


def default_basin_ranges(config: SimConfig) -> tuple[tuple[float, float], tuple[float, float]]:
    """Initial angles from ``-3 (gap + A0) / l`` to the stop, rates within ``+-3 omega_n (gap + A0) / l``.

    The angles no wider than the +-1.5 rad :func:`basins` accepts (a short pendulum, 3 A0 / l > 1.5, had a default
    region the function refused); the rates then as wide as the angles, ``+-omega_n`` times the span.
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
    _check_cycles(transient_cycles, measure_cycles)
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
        out.update(_validity_arrays(result.max_abs_theta[None], result.max_force[None], result.invalid_rule))
    if result.peak_force is not None and result.impact_velocity is not None:
        out["peak_force_n"] = np.asarray(result.peak_force, dtype=float).ravel().tolist()
        out["impact_velocity_m_s"] = np.asarray(result.impact_velocity, dtype=float).ravel().tolist()
    return out


def basins_table(result: BasinsResult) -> list[dict]:
    """CSV rows, one per initial condition: :func:`basins_columns` as one dict per row."""
    return rows_of(basins_columns(result))
