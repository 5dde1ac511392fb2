"""What a frequency sweep gives: its points, the sweep and its bands (data only: no model, no numba).

:func:`rimd_sim.analysis.dynamics.sweep.sweep` computes them (and re-exports these names). They live apart so
that a process that only reads or draws a sweep (the figure worker of :mod:`rimd_sim.analysis.figures`, which
unpickles the result) does not load the model and its compiled kernel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["SweepPoint", "SweepResult", "band_peak"]


@dataclass(frozen=True)
class SweepPoint:
    """Steady state at one frequency.

    Attributes:
        frequency_hz: Motor frequency (Hz).
        frequency_ratio: Omega / omega_n.
        peak_force_n: Largest peak impact force over the measured cycles (N); 0 without impact.
        force_ratio: ``peak_force_n / (m g)``.
        impacts_per_cycle: Impacts per excitation cycle over the measured cycles.
        simulated_seconds: Simulated time spent on this point (s).
        max_abs_theta_rad: Largest ``|theta|`` over the point's whole run (rad).
        max_force_n: Largest peak force over the point's whole run (N), the transient included.
        valid: Whether the point lies in the model's valid domain (:mod:`rimd_sim.model.validity`).
        invalid_rule: The rules it broke (``;``-separated names), ``""`` when valid.
        motion_class: The class of the measured cycles (:mod:`rimd_sim.analysis.dynamics.sweep`).
        impact_velocity_m_s: Largest impact velocity over the measured cycles (m/s, the approach speed at
            contact onset); 0 without impact.
    """

    frequency_hz: float
    frequency_ratio: float
    peak_force_n: float
    force_ratio: float
    impacts_per_cycle: float
    simulated_seconds: float
    max_abs_theta_rad: float = math.nan
    max_force_n: float = math.nan
    valid: bool = True
    invalid_rule: str = ""
    motion_class: str = ""
    impact_velocity_m_s: float = math.nan


@dataclass(frozen=True)
class SweepResult:
    """A sweep and its bands (see :func:`band_peak`, valid points only).

    ``validity`` is the summary's report of the valid domain (:meth:`~rimd_sim.model.validity.ValidityDomain.report`);
    ``restarts`` the frequencies where a continued sweep went on from rest after a chattering point.
    """

    gap_mm: float
    direction: str
    points: tuple[SweepPoint, ...]
    band_a: SweepPoint | None
    band_b: SweepPoint | None
    simulated_seconds: float
    wall_seconds: float
    workers: int
    validity: dict | None = None
    restarts: tuple[float, ...] = ()

    @property
    def invalid(self) -> tuple[SweepPoint, ...]:
        """The points outside the model's valid domain."""
        return tuple(p for p in self.points if not p.valid)

    def summary(self) -> dict:
        """The ``summary.json`` content (its keys: docs/analyses.md, "`rimd sweep`")."""
        def band(p: SweepPoint | None) -> dict | None:
            return None if p is None else {"frequency_hz": p.frequency_hz, "peak_force_n": p.peak_force_n,
                                           "force_ratio": p.force_ratio}
        return {"gap_mm": self.gap_mm, "direction": self.direction, "band_a": band(self.band_a),
                "band_b": band(self.band_b), "points": len(self.points),
                "simulated_seconds": self.simulated_seconds, "wall_seconds": self.wall_seconds,
                "workers": self.workers, "validity": self.validity, "restarts_from_rest_hz": list(self.restarts)}


def band_peak(points: tuple[SweepPoint, ...], impacts_per_cycle: float | str) -> SweepPoint | None:
    """Valid point of largest peak force among those whose motion is the band's class.

    Band A is the ``1/1`` motion (one impact per cycle), band B the ``1/2`` motion (one impact every two
    cycles), as the paper's bands are: a ``2/2``, ``3/3`` or chaotic point whose impacts average one per cycle is
    in neither band, nor is an ``unsettled`` one.

    Args:
        points: The sweep's points.
        impacts_per_cycle: The band: ``1.0`` (band A, class ``1/1``) or ``0.5`` (band B, ``1/2``), or a class
            label such as ``"1/3"``.

    Returns:
        The point, or None when no valid point has that class.
    """
    if isinstance(impacts_per_cycle, str):
        label = impacts_per_cycle
    elif impacts_per_cycle >= 1.0:
        label = f"{round(impacts_per_cycle)}/1"
    else:
        label = f"1/{round(1.0 / impacts_per_cycle)}"
    sel = [p for p in points if p.valid and p.motion_class == label]
    return max(sel, key=lambda p: p.peak_force_n, default=None)
