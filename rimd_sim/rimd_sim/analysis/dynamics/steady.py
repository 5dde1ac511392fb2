"""Steady motions at one parameter point: stroboscopic (Poincare) samples and their classification.

The paper's nonlinear tools (section 3, Figs 9-12) all rest on the same reading of a simulated motion: run
the model at a constant motor frequency from an initial state, drop a transient, then sample the state once
per excitation cycle, when the motor phase crosses a multiple of 2 pi (the cart at 0, moving forward), and
count the impacts of each cycle.

Classification (Peterka's notation, "p/n": p impacts in n excitation cycles)
--------------------------------------------------------------------------------
Over the ``measure_cycles`` after the transient:

* no impact in the window: ``no impact``;
* otherwise the smallest period ``n <= max_period`` (in cycles) such that every stroboscopic point repeats
  after ``n`` cycles within ``tolerance`` and the number of impacts of every cycle repeats too:
  ``p/n`` with ``p`` the impacts in ``n`` cycles. The fraction is not reduced: ``2/2`` is the period-1
  motion with alternating impact magnitudes (a period doubling of ``1/1``), distinct from ``1/1``;
* ``unsettled``: the motion has not converged within the window to what it will be, so no class can be given
  yet. Either it repeats after ``n`` cycles while the distance between points ``m`` cycles apart, ``m`` a
  proper divisor of ``n``, shrinks at every step (by 1 % over the window): it converges to a period-``m``
  orbit (the alternation about a period-1 orbit whose multiplier is near -1 repeats every two cycles to the
  tolerance long before it dies out, and would read ``2/2``); or no period repeats, but such distances shrink
  for some ``n``. Run longer to classify it. (A ``p/n`` motion still converging to that same ``p/n`` orbit
  keeps its class: it is what the motion converges to.);
* otherwise ``chaotic/non-periodic``: the Poincare points do not converge to a finite set of at most
  ``max_period`` points. Whether the motion is chaotic is decided by the largest Lyapunov exponent
  (:mod:`rimd_sim.analysis.dynamics.lyapunov`).

Stroboscopic points are compared in non-dimensional coordinates ``u = l sin(theta) / A0`` (the paper's Fig.
11 ordinate) and ``v = l theta_dot cos(theta) / (A0 Omega)``, so one tolerance fits every gap and frequency.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rimd_sim.errors import ConfigError
from rimd_sim.model.rig_model import RigModel
from rimd_sim.model.validity import PointMeasures, domain
from rimd_sim.settings.config import SimConfig

__all__ = [
    "CHAOTIC", "NO_IMPACT", "UNSETTLED", "Orbit", "check_frequencies", "check_frequency", "classify", "class_label",
    "cluster_orbits", "constant_frequency", "orbit_points", "same_orbit", "steady_orbit",
]

NO_IMPACT = "no impact"
CHAOTIC = "chaotic/non-periodic"
UNSETTLED = "unsettled"


@dataclass(frozen=True)
class Orbit:
    """The measured part of a motion at one parameter point.

    Attributes:
        frequency_hz: Motor frequency (Hz).
        gap_mm: Gap (mm).
        u: Non-dimensional displacement ``l sin(theta) / A0`` at each stroboscopic instant.
        v: Non-dimensional relative velocity ``l theta_dot cos(theta) / (A0 Omega)`` at the same instants.
        theta: ``theta`` (rad) at the same instants.
        theta_dot: ``theta_dot`` (rad/s) at the same instants.
        impacts_per_cycle: Impacts started in each measured cycle.
        peak_forces: Peak force of each impact of the window (N), in time order.
        label: The class (see the module docstring).
        period: ``n`` of ``p/n`` (0 for ``no impact`` or ``chaotic/non-periodic``).
        impacts: ``p`` of ``p/n``.
        spread: Largest distance between points ``period`` cycles apart (or 1 cycle apart when non-periodic):
            the measured non-convergence.
        max_abs_theta_rad: Largest ``|theta|`` over the whole run, transient included (rad).
        max_force_n: Largest peak force over the whole run (N).
        valid: Whether the point lies in the model's valid domain (:mod:`rimd_sim.model.validity`).
        invalid_rule: The rules it broke (``;``-separated names), ``""`` when valid.
    """

    frequency_hz: float
    gap_mm: float
    u: np.ndarray
    v: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    impacts_per_cycle: np.ndarray
    peak_forces: np.ndarray
    label: str
    period: int
    impacts: int
    spread: float
    max_abs_theta_rad: float = math.nan
    max_force_n: float = math.nan
    valid: bool = True
    invalid_rule: str = ""

    @property
    def final_state(self) -> tuple[float, float]:
        """``(theta, theta_dot)`` at the last stroboscopic instant: a start for a continuation."""
        return float(self.theta[-1]), float(self.theta_dot[-1])


def class_label(impacts: int, period: int) -> str:
    """``p/n`` label, or ``no impact`` when ``impacts`` is 0."""
    return NO_IMPACT if impacts == 0 else f"{impacts}/{period}"


def classify(u: np.ndarray, v: np.ndarray, impacts_per_cycle: np.ndarray, *, max_period: int = 12,
             tolerance: float = 1e-3) -> tuple[str, int, int, float]:
    """Classify a measured window (see the module docstring).

    Args:
        u: Non-dimensional displacement at the stroboscopic instants (one per cycle).
        v: Non-dimensional velocity at the same instants.
        impacts_per_cycle: Impacts in each cycle of the window (same length as ``u``).
        max_period: Longest period (cycles) looked for; at most a third of the window.
        tolerance: Largest distance (non-dimensional) between points one period apart.

    Returns:
        ``(label, period, impacts, spread)``.
    """
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    counts = np.asarray(impacts_per_cycle, dtype=np.int64)
    total = int(counts.sum())
    max_period = max(1, min(max_period, len(u) // 3))
    for n in range(1, max_period + 1):
        d = np.hypot(u[n:] - u[:-n], v[n:] - v[:-n])
        spread = float(d.max()) if len(d) else 0.0
        if spread <= tolerance and np.array_equal(counts[n:], counts[:-n]):
            impacts = int(counts[-n:].sum())
            if impacts and any(_contracting(u, v, m) for m in range(1, n) if n % m == 0):
                return UNSETTLED, 0, 0, spread
            return class_label(impacts, n), (0 if impacts == 0 else n), impacts, spread
    spread = float(np.hypot(np.diff(u), np.diff(v)).max()) if len(u) > 1 else 0.0
    if total == 0:
        return NO_IMPACT, 0, 0, spread
    if any(_contracting(u, v, n) for n in range(1, max_period + 1)):
        return UNSETTLED, 0, 0, spread
    return CHAOTIC, 0, 0, spread


def _contracting(u: np.ndarray, v: np.ndarray, n: int) -> bool:
    """Whether the distance between points ``n`` cycles apart shrinks at every step, by 1 % over the window.

    A chaotic motion's distances rise and fall; a motion converging to a period-``n`` orbit (slowly, or from
    far) shrinks them cycle after cycle; a converged orbit's stay equal (to 1e-9), and never shrink by 1 %.
    """
    d = np.hypot(u[n:] - u[:-n], v[n:] - v[:-n])
    if len(d) < 6 or not np.isfinite(d).all() or d[0] <= 0.0:
        return False
    return bool(np.all(d[1:] <= d[:-1] + 1e-9) and d[-1] < 0.99 * d[0])


def check_frequency(config: SimConfig, frequency_hz: float) -> float:
    """The motor frequency of an analysis (Hz), as a float.

    Raises:
        ConfigError: Unless finite, > 0 and <= the motor's maximum (``motor.max_frequency``).
    """
    if not (math.isfinite(frequency_hz) and 0 < frequency_hz <= config.motor.max_frequency):
        raise ConfigError("frequency", frequency_hz, f"must be > 0 and <= {_ceiling(config)}")
    return float(frequency_hz)


def check_frequencies(config: SimConfig, frequencies) -> list[float]:
    """The motor frequencies of a sweep or a map (Hz), as floats in the order given.

    Raises:
        ConfigError: Unless non-empty, each > 0 and <= the motor's maximum (``motor.max_frequency``).
    """
    freqs = [float(f) for f in frequencies]
    if not freqs or any(not (0 < f <= config.motor.max_frequency) for f in freqs):
        raise ConfigError("frequencies", freqs, f"must be non-empty, each > 0 and <= {_ceiling(config)}")
    return freqs


def _ceiling(config: SimConfig) -> str:
    """The motor's maximum as a refusal names it: the parameter, its value, and how to raise it."""
    return (f"motor.max_frequency = {config.motor.max_frequency:g} Hz (a parameter of the configuration: raise "
            "it there to go higher)")


def constant_frequency(config: SimConfig, frequency_hz: float, theta0: float = 0.0, theta_dot0: float = 0.0
                       ) -> SimConfig:
    """``config`` with the motor at ``frequency_hz`` from t = 0 (no ramp) and the hammer at the given state."""
    return config.with_parameters({"motor.initial_frequency": frequency_hz, "motor.initial_setpoint": frequency_hz,
                                   "initial.theta": theta0, "initial.theta_dot": theta_dot0})


def steady_orbit(config: SimConfig, frequency_hz: float, *, theta0: float = 0.0, theta_dot0: float = 0.0,
                 transient_cycles: int = 100, measure_cycles: int = 48, max_period: int = 12,
                 tolerance: float = 1e-3) -> Orbit:
    """Run from ``(theta0, theta_dot0)`` at a constant frequency and classify the steady motion.

    Args:
        config: Rig configuration; its motor and initial state are replaced.
        frequency_hz: Motor frequency (Hz), > 0.
        theta0: Initial angle (rad), when the motor phase is 0.
        theta_dot0: Initial rate (rad/s).
        transient_cycles: Cycles dropped before measuring.
        measure_cycles: Cycles measured (stroboscopic points and impacts per cycle).
        max_period: Longest period looked for (cycles).
        tolerance: Non-dimensional distance under which two stroboscopic points are the same.

    Returns:
        The measured window, its class and the valid domain's verdict.

    Raises:
        ConfigError: For a bad frequency or cycle count (and from the configuration).
        ChatteringError: When the integrator's chattering guard fires (the valid domain's ``chattering`` rule).
    """
    f = check_frequency(config, frequency_hz)
    if transient_cycles < 0 or measure_cycles < 3:
        raise ConfigError("cycles", (transient_cycles, measure_cycles),
                          "need transient_cycles >= 0 and measure_cycles >= 3")
    cfg = constant_frequency(config, f, theta0, theta_dot0)
    model = RigModel(cfg, channels=False, truth=False, strobe=True)
    spans = []
    if transient_cycles:
        spans.append(model.advance((transient_cycles + 0.5) / f))
    # The stroboscopic point of cycle c is the state at t = c / f, when cycle c starts. Window: the points of
    # cycles first .. first + N - 1 and the impacts started in those cycles.
    out = model.advance((transient_cycles + measure_cycles + 1.5) / f)
    spans.append(out)
    first = transient_cycles + 1
    strobe = [s for s in out.strobe if first <= s.cycle_index < first + measure_cycles]
    impacts = [i for i in out.impacts if first <= i.cycle_index < first + measure_cycles]
    rig = cfg.rig
    theta = np.array([s.theta for s in strobe])
    theta_dot = np.array([s.theta_dot for s in strobe])
    u, v = nondimensional(rig.length, rig.amplitude, f, theta, theta_dot)
    counts = np.bincount([i.cycle_index - first for i in impacts], minlength=measure_cycles)
    label, period, p, spread = classify(u, v, counts[:measure_cycles], max_period=max_period, tolerance=tolerance)
    max_theta = max(o.max_abs_theta for o in spans)
    max_force = max((i.peak_force for o in spans for i in o.impacts), default=0.0)
    verdict = domain(cfg).check(PointMeasures(max_theta, max_force, float(counts[:measure_cycles].mean())))
    return Orbit(f, rig.gap * 1e3, u, v, theta, theta_dot, counts[:measure_cycles],
                 np.array([i.peak_force for i in impacts]), label, period, p, spread, max_theta, max_force,
                 verdict.valid, verdict.invalid_rule)


def nondimensional(length: float, amplitude: float, frequency_hz: float, theta, theta_dot):
    """``(u, v) = (l sin(theta) / A0, l theta_dot cos(theta) / (A0 Omega))``."""
    theta = np.asarray(theta, dtype=float)
    theta_dot = np.asarray(theta_dot, dtype=float)
    omega = 2.0 * math.pi * frequency_hz
    return length * np.sin(theta) / amplitude, length * theta_dot * np.cos(theta) / (amplitude * omega)


def classes_differ(labels: Sequence[str]) -> bool:
    """Whether a set of classes found from different initial conditions holds more than one class."""
    return len(set(labels)) > 1


def orbit_points(u, v, label: str, tolerance: float = 1e-3, max_period: int | None = None) -> np.ndarray | None:
    """The stroboscopic points of the periodic orbit at the end of ``(u, v)`` (one point per cycle, last last).

    The orbit of a ``p/n`` class is its last ``n`` points; a ``no impact`` motion's is the last ``n`` for the
    smallest ``n`` whose points repeat within ``tolerance`` over the points given (a damped one: 1). None for a
    non-periodic motion (chaotic, an undamped quasi-periodic no-impact motion) or missing points (NaN).

    Returns:
        The points, shape ``(n, 2)``, or None.
    """
    pts = np.column_stack([np.asarray(u, dtype=float), np.asarray(v, dtype=float)])
    if label == NO_IMPACT:
        n_max = len(pts) // 2 if max_period is None else max_period
        for n in range(1, n_max + 1):
            d = pts[n:] - pts[:-n]
            if len(d) and np.isfinite(d).all() and np.hypot(d[:, 0], d[:, 1]).max() <= tolerance:
                return pts[-n:]
        return None
    p, _, n_text = label.partition("/")
    if not (p.isdigit() and n_text.isdigit()):
        return None
    n = int(n_text)
    if n > len(pts) or not np.isfinite(pts[-n:]).all():
        return None
    return pts[-n:]


def same_orbit(a: np.ndarray, b: np.ndarray, tolerance: float = 1e-3) -> bool:
    """Whether two periodic orbits' stroboscopic point sets are the same set within ``tolerance``.

    Compared as sets (whatever cycle each starts at): the same number of points, and every point of each within
    ``tolerance`` (non-dimensional distance) of a point of the other.
    """
    if a.shape != b.shape:
        return False
    d = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
    return bool((d.min(axis=1) <= tolerance).all() and (d.min(axis=0) <= tolerance).all())


def cluster_orbits(labels: Sequence[str], orbits: Sequence[np.ndarray | None], tolerance: float = 1e-3
                   ) -> tuple[np.ndarray, list[int]]:
    """Attractor ids: trajectories ending on the same orbit share one, different orbits get different ones.

    Two trajectories share an id when their classes are equal and their orbits (:func:`orbit_points`) are the
    same set (:func:`same_orbit`) as the first orbit given that id. A trajectory without an orbit (non-periodic)
    shares the id of its class's other non-periodic trajectories: those are told apart by class only. Ids are
    numbered from 0 in order of first appearance; a trajectory whose label is None (not run) gets -1.

    Args:
        labels: The class of each trajectory (None: not run, id -1).
        orbits: Its orbit points (or None), same length.
        tolerance: Non-dimensional distance under which two points are the same (the classification's).

    Returns:
        ``(ids, representatives)``: the id per trajectory, and per id the index of its first trajectory.
    """
    ids = np.full(len(labels), -1, dtype=np.int64)
    reps: list[int] = []
    for i, (label, orbit) in enumerate(zip(labels, orbits, strict=True)):
        if label is None:
            continue
        for a, r in enumerate(reps):
            if labels[r] != label:
                continue
            other = orbits[r]
            if (orbit is None and other is None) or (orbit is not None and other is not None
                                                     and same_orbit(orbit, other, tolerance)):
                ids[i] = a
                break
        else:
            ids[i] = len(reps)
            reps.append(i)
    return ids, reps
