"""What the paper publishes of its rig, and the twin's value of each finding (``rimd paper``, ``rimd fit-paper``).

The published findings (the paper's section 2.1, Table 1, Figs. 4, 11 and 12):

* **Table 1**: the impact resonances, the frequency of the largest steady peak force in band A (one impact per
  cycle) and band B (one impact every two cycles), at gaps 0, 1.0 and 2.4 mm, read on the experiment's 0.25 Hz
  grid. The twin reads them as the experiment did: every grid frequency from rest, the steady state over the
  last cycles, band A = the strongest point whose motion is ``1/1``, band B = the strongest ``1/2`` point (by
  class: a ``2/2``, ``3/3`` or chaotic point is in neither band, whatever its impacts per cycle).
* **The gap-0 peak forces** at those resonances: 82.4 N (band A, 3.75 Hz) and 120 N (band B, 7.25 Hz).
* **The gap-0 period doubling** at the end of band A: the experiment shows alternating impact magnitudes at
  4.75 Hz (Fig. 4); the twin's is where the period-1 orbit's Floquet multiplier crosses -1
  (:func:`doubling_frequency`).
* **Chaos in the transition bands at gaps 1.0 and 2.4 mm** (Fig. 11, text): a point of an up, down or
  from-rest sweep (:func:`~rimd_sim.analysis.dynamics.bifurcation.bifurcation`, ``all``) whose motion is
  ``chaotic/non-periodic`` and whose largest Lyapunov exponent, from the sweep's state on that attractor, is
  above :data:`~rimd_sim.analysis.dynamics.lyapunov.CHAOS_THRESHOLD`.
* **Coexisting motions above gap/A0 = 1.5** between the period-1 and the period-1/2 regions of the Peterka map
  (Fig. 12): cells there whose starts end on different motions.

Each finding is a :class:`Check`: the paper's value, the twin's, the tolerance and pass or fail. The
frequencies are compared in hertz (the experiment's grid); the figures put them on the paper's axis
``Omega / omega`` with the paper's ``omega`` (1.82 Hz), so a twin value lands where the experiment's does.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from rimd_sim.analysis.dynamics.bifurcation import BifurcationBranch, bifurcation
from rimd_sim.analysis.dynamics.continuation import fixed_point
from rimd_sim.analysis.dynamics.lyapunov import CHAOS_THRESHOLD, largest_lyapunov
from rimd_sim.analysis.dynamics.peterka import PeterkaResult, peterka
from rimd_sim.analysis.dynamics.steady import CHAOTIC, steady_orbit
from rimd_sim.analysis.dynamics.sweep import SweepPoint, SweepResult, sweep
from rimd_sim.errors import AnalysisError
from rimd_sim.settings.config import SimConfig

__all__ = [
    "BANDS", "Check", "DOUBLING_HZ", "FORCE_TOLERANCE", "FORCES_GAP0_N", "GAPS_MM", "GRID_HZ",
    "PAPER_NATURAL_FREQUENCY_HZ", "TABLE1_HZ", "TargetRun", "Trajectory", "band_of", "check_targets",
    "doubling_frequency", "table_checks", "trajectory",
]

#: The paper's natural frequency without impact (Table 1, modal analysis), the unit of its frequency axes (Hz).
PAPER_NATURAL_FREQUENCY_HZ = 1.82
#: The pin's eccentricity, the cart's nominal amplitude A0 (section 2, m): the unit of the paper's gap axis.
PAPER_AMPLITUDE_M = 1.0e-3
#: Table 1: the impact resonances (Hz) of bands A and B per gap (mm).
TABLE1_HZ = {0.0: (3.75, 7.25), 1.0: (3.00, 6.25), 2.4: (2.50, 5.25)}
GAPS_MM = tuple(TABLE1_HZ)
#: The bands: their class (band A: one impact per cycle; band B: one every two cycles).
BANDS = {"A": "1/1", "B": "1/2"}
#: Section 2.1: the gap-0 peak impact forces at the resonances (N).
FORCES_GAP0_N = {"A": 82.4, "B": 120.0}
#: Relative tolerance of a gap-0 peak force against the paper's.
FORCE_TOLERANCE = 0.05
#: Fig. 4 and section 2.1: the gap-0 period doubling at the end of band A (Hz), and the tolerance (Hz).
DOUBLING_HZ = 4.75
DOUBLING_TOLERANCE_HZ = 0.1
#: Gaps (mm) whose transition bands are chaotic (Fig. 11 and its text).
CHAOS_GAPS_MM = (1.0, 2.4)
#: Fig. 12: coexisting motions above this gap/A0, between the period-1 and period-1/2 regions.
COEXISTENCE_GAP_RATIO = 1.5
#: The experiment's frequency grid (Hz): 0.25 Hz steps over the paper's range (Fig. 6: Omega/omega to ~5).
GRID_HZ = tuple(round(1.5 + 0.25 * k, 2) for k in range(31))   # 1.5 .. 9.0 Hz
#: The bifurcation diagrams' finer grid (Hz): 0.05 Hz steps over the same range, fine enough for the narrow chaotic
#: windows of the transition bands (Fig. 11 is drawn from a simulation, not on the experiment's grid).
DIAGRAM_GRID_HZ = tuple(round(1.5 + 0.05 * k, 2) for k in range(151))


@dataclass(frozen=True)
class Check:
    """One published finding against the twin.

    Attributes:
        key: Short machine name (``table1.gap_1.0.B``, ``force.A``, ``doubling``, ``chaos.gap_2.4``, ...).
        finding: The finding in words.
        source: Where the paper publishes it.
        paper: The paper's value (a number, or words for a qualitative finding).
        twin: The twin's value (a number, words, or None where it has none).
        tolerance: The tolerance in words.
        passed: Whether the twin's value is within it.
        unit: The unit of ``paper`` and ``twin`` when numbers.
        detail: How the twin's value was found (frequencies, exponents...).
    """

    key: str
    finding: str
    source: str
    paper: float | str
    twin: float | str | None
    tolerance: str
    passed: bool
    unit: str = ""
    detail: str = ""

    def row(self) -> dict:
        """A CSV row."""
        return {"key": self.key, "finding": self.finding, "source": self.source, "paper": self.paper,
                "twin": "" if self.twin is None else self.twin, "unit": self.unit, "tolerance": self.tolerance,
                "passed": self.passed, "detail": self.detail}


@dataclass
class TargetRun:
    """What :func:`check_targets` computed, kept for the figures (``rimd paper``)."""

    checks: list[Check] = field(default_factory=list)
    sweeps: dict[float, SweepResult] = field(default_factory=dict)
    branches: dict[float, list[BifurcationBranch]] = field(default_factory=dict)
    lyapunov: dict[float, tuple[float, float, str]] = field(default_factory=dict)
    doubling_hz: float | None = None
    peterka: PeterkaResult | None = None
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def passed(self) -> int:
        """How many checks pass."""
        return sum(c.passed for c in self.checks)


def band_of(points, band: str) -> SweepPoint | None:
    """The valid point of largest peak force among those whose motion is the band's class (``A``: 1/1, ``B``: 1/2)."""
    label = BANDS[band]
    chosen = [p for p in points if p.valid and p.motion_class == label]
    return max(chosen, key=lambda p: p.peak_force_n, default=None)


def table_sweeps(config: SimConfig, *, cycles: int = 150, measure_cycles: int = 50, workers: int | None = None
                 ) -> dict[float, SweepResult]:
    """Every gap of Table 1 swept from rest on the experiment's grid (as the paper measured Table 1)."""
    return {gap: sweep(config.with_parameters({"gap": gap * 1e-3}), list(GRID_HZ), "rest", cycles=cycles,
                       measure_cycles=measure_cycles, workers=workers) for gap in GAPS_MM}


def table_checks(sweeps: dict[float, SweepResult]) -> list[Check]:
    """Table 1's six resonances and the two gap-0 forces, from :func:`table_sweeps`."""
    checks = []
    for gap, resonances in TABLE1_HZ.items():
        for band, paper_hz in zip(BANDS, resonances, strict=True):
            point = band_of(sweeps[gap].points, band)
            twin = None if point is None else point.frequency_hz
            checks.append(Check(
                f"table1.gap_{gap:g}.{band}", f"impact resonance, band {band} ({BANDS[band]}), gap {gap:g} mm",
                "Table 1", paper_hz, twin, "the same 0.25 Hz grid point", twin is not None and
                abs(twin - paper_hz) < 1e-6, "Hz",
                "no valid point of that class on the grid" if point is None else
                f"{point.peak_force_n:.1f} N at {point.frequency_hz:g} Hz, from rest"))
    for band, paper_n in FORCES_GAP0_N.items():
        point = band_of(sweeps[0.0].points, band)
        twin_n = None if point is None else round(point.peak_force_n, 2)
        checks.append(Check(
            f"force.{band}", f"peak impact force at band {band}'s resonance, gap 0", "section 2.1", paper_n, twin_n,
            f"within {FORCE_TOLERANCE:.0%}", twin_n is not None and abs(twin_n / paper_n - 1) <= FORCE_TOLERANCE,
            "N", "" if point is None or twin_n is None else
            f"at {point.frequency_hz:g} Hz ({twin_n / paper_n - 1:+.1%})"))
    return checks


def doubling_frequency(config: SimConfig, *, start_hz: float = 4.0, end_hz: float = 5.8, step_hz: float = 0.05,
                       tolerance_hz: float = 1e-3) -> float | None:
    """The gap-0 period doubling at the end of band A: where the period-1 orbit's multiplier crosses -1 (Hz).

    The period-1 orbit is found from rest at ``start_hz`` (its attractor there) and followed in frequency steps
    by Newton's method on the stroboscopic map (:func:`~rimd_sim.analysis.dynamics.continuation.fixed_point`,
    each step from the last orbit); the first step whose real multiplier is below -1 is bisected to
    ``tolerance_hz``. The continuation (``rimd continue``) locates the same point on its branch; this is its
    cheaper form for a fit, which needs the one number.

    Returns:
        The frequency (Hz), or None when the orbit does not double up to ``end_hz`` (or is lost on the way).
    """
    cfg = config.with_parameters({"gap": 0.0})
    orbit = steady_orbit(cfg, start_hz, transient_cycles=300, measure_cycles=12)
    if orbit.label != "1/1":
        return None

    def lowest_real(f: float, x: np.ndarray) -> tuple[np.ndarray, float]:
        xp, mu = fixed_point(cfg, f, x)
        return xp, min((float(m.real) for m in mu if abs(m.imag) < 1e-9), default=0.0)

    try:
        x, mu = lowest_real(start_hz, np.array(orbit.final_state))
    except AnalysisError:
        return None
    if mu < -1.0:
        return None
    f = start_hz
    while f < end_hz - 1e-12:
        nxt = round(f + step_hz, 9)
        try:
            xn, mn = lowest_real(nxt, x)
        except AnalysisError:
            return None
        if mn < -1.0:
            lo, hi, xlo = f, nxt, x
            while hi - lo > tolerance_hz:
                mid = 0.5 * (lo + hi)
                xm, mm = lowest_real(mid, xlo)
                if mm < -1.0:
                    hi = mid
                else:
                    lo, xlo = mid, xm
            return 0.5 * (lo + hi)
        f, x = nxt, xn
    return None


def doubling_check(doubling_hz: float | None) -> Check:
    return Check("doubling", "period doubling at the end of band A, gap 0 (alternating impact magnitudes)",
                 "Fig. 4, section 2.1", DOUBLING_HZ, None if doubling_hz is None else round(doubling_hz, 4),
                 f"within {DOUBLING_TOLERANCE_HZ:g} Hz",
                 doubling_hz is not None and abs(doubling_hz - DOUBLING_HZ) <= DOUBLING_TOLERANCE_HZ, "Hz",
                 "Floquet multiplier -1 of the period-1 orbit" if doubling_hz is not None else
                 "no period doubling of the period-1 orbit found between 4 and 5.8 Hz")


def chaos(config: SimConfig, gap_mm: float, branches: list[BifurcationBranch], *, cycles: int = 300,
          max_points: int = 24) -> tuple[float, float, str]:
    """The largest Lyapunov exponent among the chaotic-looking points of the sweeps at one gap (up, down, rest).

    Candidates are the valid points classed ``chaotic/non-periodic``, taken alternately from each branch, at
    most ``max_points``; each exponent is measured from the sweep's own state at that point (on the attractor
    the sweep is on). Stops at the first exponent above the threshold.

    Returns:
        ``(exponent 1/s, frequency Hz, direction)`` of the largest exponent found; ``(nan, nan, "")`` without a
        candidate.
    """
    cfg = config.with_parameters({"gap": gap_mm * 1e-3})
    lists = [[(b.direction, p) for p in b.points if p.valid and p.label == CHAOTIC
              and all(math.isfinite(v) for v in p.final_state)] for b in branches]
    candidates = [c for group in _interleave(lists) for c in group][:max_points]
    best = (math.nan, math.nan, "")
    for direction, p in candidates:
        lyap = largest_lyapunov(cfg, p.frequency_hz, theta0=p.final_state[0], theta_dot0=p.final_state[1],
                                transient_cycles=50, cycles=cycles)
        if math.isfinite(lyap.exponent) and not lyap.exponent <= best[0]:
            best = (lyap.exponent, p.frequency_hz, direction)
        if lyap.exponent > CHAOS_THRESHOLD:
            break
    return best


def _interleave(lists):
    longest = max((len(x) for x in lists), default=0)
    return [[x[i] for x in lists if i < len(x)] for i in range(longest)]


def chaos_check(gap_mm: float, found: tuple[float, float, str]) -> Check:
    exponent, f, direction = found
    passed = math.isfinite(exponent) and exponent > CHAOS_THRESHOLD
    return Check(f"chaos.gap_{gap_mm:g}", f"chaos in a transition band, gap {gap_mm:g} mm", "Fig. 11, section 3",
                 "chaos", None if not math.isfinite(exponent) else round(exponent, 3),
                 f"largest Lyapunov exponent > {CHAOS_THRESHOLD:g} 1/s on a chaotic attractor", passed, "1/s",
                 f"at {f:g} Hz, sweep {direction}" if math.isfinite(f) else
                 "no chaotic/non-periodic point on the up and down sweeps")


def coexistence_check(result: PeterkaResult, config: SimConfig) -> Check:
    """Fig. 12: cells with coexisting motions above gap/A0 = 1.5, between the period-1 and period-1/2 regions.

    Per row of the map at or above the ratio: the cells from its last ``1/1`` cell (from rest) to its first ``1/2``
    cell after it, both included; the finding holds when one of them has coexisting motions (its starts end on
    different motions: in the twin, an impacting motion beside a non-impacting one at the regions' borders, the
    experiment's Fig. 12 right) in at least half of those rows.
    """
    coexisting = result.coexisting
    primary = result.primary
    rows = []
    for i, ratio in enumerate(result.gap_ratio):
        if ratio < COEXISTENCE_GAP_RATIO - 1e-9:
            continue
        labels = list(primary[i])
        ones = [j for j, lab in enumerate(labels) if lab == "1/1"]
        if not ones:
            continue
        halves = [j for j, lab in enumerate(labels) if lab == "1/2" and j > ones[-1]]
        if not halves:
            continue
        between = range(ones[-1], halves[0] + 1)   # the two regions' border cells included
        rows.append(any(coexisting[i, j] for j in between))
    n = sum(rows)
    passed = bool(rows) and n >= 0.5 * len(rows)
    return Check("coexistence", "coexisting motions between the period-1 and period-1/2 regions above gap/A0 = 1.5",
                 "Fig. 12, section 3", "present", f"{n} of {len(rows)} rows", "at least half the rows", passed, "",
                 f"gap/A0 >= {COEXISTENCE_GAP_RATIO:g} with A0 = {config.rig.amplitude * 1e3:g} mm")


def peterka_grid(config: SimConfig, *, rows: int = 13, columns: int = 41) -> tuple[list[float], list[float]]:
    """The gaps (m) and frequencies (Hz) of the paper's Fig. 12: gap/A0 0 to 3, Omega/omega 1 to 5 (paper's omega)."""
    a0 = config.rig.amplitude
    gaps = [a0 * 3.0 * k / (rows - 1) for k in range(rows)]
    freqs = [PAPER_NATURAL_FREQUENCY_HZ * (1.0 + 4.0 * k / (columns - 1)) for k in range(columns)]
    return gaps, [f for f in freqs if f <= config.motor.max_frequency]


def check_targets(config: SimConfig, *, workers: int | None = None, peterka_shape: tuple[int, int] = (13, 41),
                  log: Callable[[str], None] | None = None, figures: bool = True) -> TargetRun:
    """Every published finding against the twin of ``config`` (module docstring).

    Args:
        config: The rig (its gap and motor are replaced per analysis).
        workers: Local processes (default: all cores).
        peterka_shape: Rows (gaps) and columns (frequencies) of the map that checks coexistence.
        log: Optional callable told each stage as it starts.
        figures: Also compute what only the figures show: the bifurcation diagrams at the gaps whose chaos is not
            checked (``GAPS_MM`` beyond ``CHAOS_GAPS_MM``). False gives the same checks for less work.

    Returns:
        The checks and what they were computed from.
    """
    import time

    log = log or (lambda text: None)
    run = TargetRun()
    t = time.perf_counter()
    log("Table 1: three gaps from rest on the 0.25 Hz grid")
    run.sweeps = table_sweeps(config, workers=workers)
    run.checks += table_checks(run.sweeps)
    run.seconds["table"] = time.perf_counter() - t
    t = time.perf_counter()
    log("the gap-0 period doubling")
    run.doubling_hz = doubling_frequency(config)
    run.checks.append(doubling_check(run.doubling_hz))
    run.seconds["doubling"] = time.perf_counter() - t
    t = time.perf_counter()
    for gap in GAPS_MM if figures else CHAOS_GAPS_MM:
        log(f"bifurcation diagram, gap {gap:g} mm (up, down and from rest)")
        branches, _, _ = bifurcation(config.with_parameters({"gap": gap * 1e-3}), list(DIAGRAM_GRID_HZ), "all",
                                     workers=workers)
        run.branches[gap] = branches
    run.seconds["bifurcation"] = time.perf_counter() - t
    t = time.perf_counter()
    for gap in CHAOS_GAPS_MM:
        log(f"Lyapunov exponents, gap {gap:g} mm")
        run.lyapunov[gap] = chaos(config, gap, run.branches[gap])
        run.checks.append(chaos_check(gap, run.lyapunov[gap]))
    run.seconds["chaos"] = time.perf_counter() - t
    t = time.perf_counter()
    log("Peterka map (Fig. 12)")
    gaps, freqs = peterka_grid(config, rows=peterka_shape[0], columns=peterka_shape[1])
    run.peterka = peterka(config, gaps, freqs, workers=workers)
    run.checks.append(coexistence_check(run.peterka, config))
    run.seconds["peterka"] = time.perf_counter() - t
    return run


@dataclass(frozen=True)
class Trajectory:
    """A steady motion as the paper's Figs. 9 and 10 show it.

    Attributes:
        gap_mm: Gap (mm).
        frequency_hz: Motor frequency (Hz).
        t: Times of the drawn cycles (s, from their start).
        x_rimd_mm: The hammer's displacement in the inertial frame (mm: the RIMD laser's, without noise).
        x_cart_mm: The cart's (mm).
        u: ``l sin(theta) / A0`` over the drawn cycles.
        v: ``l theta' cos(theta) / (A0 Omega)`` over them.
        strobe_u: ``u`` at each stroboscopic instant of the measured cycles.
        strobe_v: ``v`` at the same instants.
        label: The class of the measured cycles.
    """

    gap_mm: float
    frequency_hz: float
    t: np.ndarray
    x_rimd_mm: np.ndarray
    x_cart_mm: np.ndarray
    u: np.ndarray
    v: np.ndarray
    strobe_u: np.ndarray
    strobe_v: np.ndarray
    label: str


def trajectory(config: SimConfig, gap_mm: float, frequency_hz: float, *, transient_cycles: int = 300,
               shown_cycles: int = 4, measure_cycles: int = 48) -> Trajectory:
    """The steady motion from rest at one gap and frequency: the drawn cycles and the Poincaré points."""
    from rimd_sim.analysis.dynamics.steady import classify, constant_frequency, nondimensional
    from rimd_sim.model.rig_model import TRUTH_FIELDS, RigModel

    f = frequency_hz
    cfg = constant_frequency(config.with_parameters({"gap": gap_mm * 1e-3}), f).with_parameters(
        {"truth.sample_rate": max(1000.0, 400.0 * f)})
    model = RigModel(cfg, channels=False, truth=True, strobe=True)
    model.advance(transient_cycles / f)
    shown = model.advance((transient_cycles + shown_cycles) / f)
    rest = model.advance((transient_cycles + measure_cycles + 1.5) / f)
    assert shown.truth is not None   # built with truth=True
    first, truth = shown.truth
    rows = {name: truth[i] for i, name in enumerate(TRUTH_FIELDS)}
    t = np.arange(truth.shape[1]) / cfg.truth_rate
    rig = cfg.rig
    u, v = nondimensional(rig.length, rig.amplitude, f, rows["theta"], rows["theta_dot"])
    n0 = transient_cycles
    strobe = [s for s in shown.strobe + rest.strobe if n0 < s.cycle_index <= n0 + measure_cycles]
    impacts = [i for i in shown.impacts + rest.impacts if n0 < i.cycle_index <= n0 + measure_cycles]
    su, sv = nondimensional(rig.length, rig.amplitude, f, [s.theta for s in strobe], [s.theta_dot for s in strobe])
    counts = np.bincount([i.cycle_index - n0 - 1 for i in impacts], minlength=len(strobe))[:len(strobe)]
    label = classify(su, sv, counts)[0]
    return Trajectory(gap_mm, f, t, rows["rimd_position"] * 1e3, rows["cart_position"] * 1e3, u, v, su, sv, label)
