"""The parameter set that best reproduces a table of impact resonances and peak forces per gap (``rimd fit-table``).

A table such as the paper's Table 1 (``config/paper_table1.csv``) gives, per gap, the frequency of the largest
steady peak force in band A (one impact per cycle) and band B (one impact every two cycles), read on a
0.25 Hz grid with each frequency started from rest, and possibly those peak forces, plus the natural frequency.
What such a table can determine: the resonances depend on the natural frequency (given by the table), the
ratio gap/A0, the structural damping ratio and the restitution of the contact; the peak forces scale with the
hammer's mass for a given contact law. So a table fixes at most the damping ratio and the mass (with A0, the
gaps and the contact law taken as given); it cannot separate the contact stiffness from the damping (the
pulse shape is not in the table), A0 from the gaps (only their ratio enters), nor anything without impacts.

Each table entry is computed as the paper measured it: the twin from rest at the entry's frequency and its
0.25 Hz neighbours (two on each side), steady peak force over the last cycles, the band's resonance = the grid
frequency of the largest peak among the points in that band; a parabola through the largest peak and its
neighbours gives the optimiser a continuous resonance. ``scipy.optimize.least_squares`` adjusts the free
parameters (default ``damping_ratio`` and ``mass``) to the resonances (scale 0.25 Hz) and the peak forces
(scale 5 %); of every set it evaluated, the one with the smallest misfit whose grid resonances all lie within
0.25 Hz of the table is returned (the starting set when none does better).

Every grid point run is checked against the model's valid domain (:mod:`rimd_sim.model.validity`, the whole
run as a sweep point). A point outside it is not the twin's rig: it is never taken as a band's resonance (as
:func:`rimd_sim.analysis.dynamics.sweep.band_peak`), each row is marked with the rules its grid points broke
(``valid``, ``invalid_rule``), and a parameter set with a marked row is chosen only when no set without one is
as good a candidate (all resonances within 0.25 Hz first): a fit must not be won on physics the model does
not hold.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rimd_sim.errors import ConfigError, InputError
from rimd_sim.model import validity
from rimd_sim.model.rig_model import ChatteringError, RigModel
from rimd_sim.model.validity import PointMeasures, Verdict, domain
from rimd_sim.settings.config import SimConfig

__all__ = ["TableEntry", "TableError", "evaluate", "fit_table", "read_table"]

GRID = 0.25                  # Hz, the paper's frequency grid
OFFSETS = (-2, -1, 0, 1, 2)  # grid points evaluated around each entry
IMPACTS = {"A": 1.0, "B": 0.5}
FIT_PARAMETERS = ("damping_ratio", "mass")
SCALES = {"damping_ratio": 0.1, "mass": 0.1, "natural_frequency": 1.0, "amplitude": 1e-3,
          "contact.stiffness": 1e6, "contact.damping": 1e3}


class TableError(InputError):
    """The table cannot be read or holds a bad entry (one line naming the row and the column)."""


@dataclass(frozen=True)
class TableEntry:
    """One row: band A or B at a gap, its resonance frequency and, when known, its peak force."""

    gap_mm: float
    band: str
    frequency_hz: float
    peak_force_n: float | None


def read_table(path: Path) -> tuple[list[TableEntry], float | None]:
    """Entries and the natural frequency (a row with band ``natural``) of a table CSV.

    Columns: ``gap_mm``, ``band`` (``A``, ``B`` or ``natural``), ``frequency_hz``, optional ``peak_force_n``.
    """
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise TableError(f"{path}: cannot be read: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise TableError(f"{path}: not text (UTF-8): {exc.reason} at byte {exc.start}") from None
    need = {"gap_mm", "band", "frequency_hz"}
    if not rows or not need <= set(rows[0]):
        raise TableError(f"{path}: needs the columns {', '.join(sorted(need))} (optional peak_force_n)")
    entries, natural = [], None
    for n, row in enumerate(rows, start=2):
        band = (row.get("band") or "").strip()
        try:
            f = float(row["frequency_hz"])
        except (TypeError, ValueError):
            raise TableError(f"{path} line {n}: frequency_hz {row['frequency_hz']!r} must be a number") from None
        if not (math.isfinite(f) and f > 0):
            raise TableError(f"{path} line {n}: frequency_hz {f!r} must be > 0")
        if band == "natural":
            natural = f
            continue
        if band not in IMPACTS:
            raise TableError(f"{path} line {n}: band {band!r} must be A, B or natural")
        try:
            gap = float(row["gap_mm"])
        except (TypeError, ValueError):
            raise TableError(f"{path} line {n}: gap_mm {row['gap_mm']!r} must be a number") from None
        if not (math.isfinite(gap) and gap >= 0):
            raise TableError(f"{path} line {n}: gap_mm {gap!r} must be >= 0")
        peak_text = (row.get("peak_force_n") or "").strip()
        peak = None
        if peak_text:
            try:
                peak = float(peak_text)
            except ValueError:
                raise TableError(f"{path} line {n}: peak_force_n {peak_text!r} must be a number or empty") from None
            if not (math.isfinite(peak) and peak > 0):
                raise TableError(f"{path} line {n}: peak_force_n {peak!r} must be > 0")
        entries.append(TableEntry(gap, band, f, peak))
    if not entries:
        raise TableError(f"{path}: no band A or B entry")
    return entries, natural


def _steady(config: SimConfig, gap_mm: float, f: float, cycles: int, measure: int) -> tuple[float, float, str]:
    """Steady peak force, impacts per cycle and the valid domain's ``invalid_rule`` of one grid point."""
    cfg = config.with_parameters({"gap": gap_mm * 1e-3, "motor.initial_frequency": f, "motor.initial_setpoint": f,
                                  "motor.max_frequency": max(config.motor.max_frequency, f)})
    duration = cycles / f
    try:
        out = RigModel(cfg, channels=False, truth=False).advance(duration)
    except ChatteringError:
        return math.nan, math.nan, domain(cfg).check(PointMeasures(chattering=True)).invalid_rule
    impacts = out.impacts
    last = [i for i in impacts if i.t_start >= duration - measure / f]
    peak, rate = max((i.peak_force for i in last), default=0.0), len(last) / measure
    verdict = domain(cfg).check(PointMeasures(out.max_abs_theta, max((i.peak_force for i in impacts), default=0.0),
                                              rate))
    return peak, rate, verdict.invalid_rule


def evaluate(config: SimConfig, entries: list[TableEntry], cycles: int = 150, measure: int = 50) -> list[dict]:
    """Per entry: the twin's resonance on the grid, the interpolated resonance and the peak force there."""
    out = []
    for e in entries:
        freqs = [round(e.frequency_hz + k * GRID, 6) for k in OFFSETS]
        points = [(f, *_steady(config, e.gap_mm, f, cycles, measure)) for f in freqs if f > 0]
        target = IMPACTS[e.band]
        # Only points in the model's valid domain can be the band's resonance.
        inband = [i for i, p in enumerate(points) if not p[3] and abs(p[2] - target) <= 0.03 * target]
        rules = validity.joined(name for p in points for name in p[3].split(";") if name)
        marks = {"valid": not rules, "invalid_rule": rules}
        if not inband:
            out.append({"gap_mm": e.gap_mm, "band": e.band, "frequency_hz": e.frequency_hz, "twin_grid_hz": None,
                        "twin_interpolated_hz": None, "twin_peak_force_n": None, "peak_force_n": e.peak_force_n,
                        **marks})
            continue
        k = max(inband, key=lambda i: points[i][1])
        f_grid, peak = points[k][0], points[k][1]
        f_int, p_int = f_grid, peak
        if 0 < k < len(points) - 1 and k - 1 in inband and k + 1 in inband:
            y0, y1, y2 = points[k - 1][1], peak, points[k + 1][1]
            denom = y0 - 2 * y1 + y2
            if denom < 0:
                shift = max(-0.5, min(0.5, 0.5 * (y0 - y2) / denom))
                f_int = f_grid + shift * GRID
                p_int = y1 - 0.25 * (y0 - y2) * shift
        out.append({"gap_mm": e.gap_mm, "band": e.band, "frequency_hz": e.frequency_hz, "twin_grid_hz": f_grid,
                    "twin_interpolated_hz": f_int, "twin_peak_force_n": p_int, "twin_grid_peak_force_n": peak,
                    "peak_force_n": e.peak_force_n, **marks})
    return out


def _residuals(rows: list[dict]) -> np.ndarray:
    r = []
    for row in rows:
        if row["twin_interpolated_hz"] is None:
            r.append(4.0)
        else:
            r.append((row["twin_interpolated_hz"] - row["frequency_hz"]) / GRID)
        if row["peak_force_n"]:
            twin = row["twin_peak_force_n"] or 0.0
            r.append((twin / row["peak_force_n"] - 1.0) / 0.05)
    return np.array(r)


def _within(rows: list[dict]) -> bool:
    return all(r["twin_grid_hz"] is not None and abs(r["twin_grid_hz"] - r["frequency_hz"]) <= GRID + 1e-9
               for r in rows)


def fit_table(base: SimConfig, entries: list[TableEntry], parameters: tuple[str, ...] = FIT_PARAMETERS, *,
              max_evaluations: int = 20, cycles: int = 150, measure: int = 50,
              log: Callable[[str], None] | None = None) -> dict:
    """Fit ``parameters`` of ``base`` to the table; returns the fitted config, the rows and the evaluations."""
    from scipy.optimize import least_squares

    log = log or (lambda text: None)
    x0 = np.array([base.to_parameters()[p] / SCALES[p] for p in parameters])
    seen: list[tuple[float, bool, dict, list[dict]]] = []

    def config_of(x: np.ndarray) -> SimConfig:
        return base.with_parameters({p: float(max(v, 1e-6) * SCALES[p]) for p, v in zip(parameters, x, strict=True)})

    cache: dict[tuple, np.ndarray] = {}

    def fun(x: np.ndarray) -> np.ndarray:
        key = tuple(np.round(x, 12))
        if key in cache:
            return cache[key]
        cfg = config_of(x)
        rows = evaluate(cfg, entries, cycles, measure)
        r = _residuals(rows)
        values = {p: cfg.to_parameters()[p] for p in parameters}
        seen.append((float(r @ r), _within(rows), values, rows))
        log(f"evaluation {len(seen)}: " + ", ".join(f"{p} = {v:.5g}" for p, v in values.items())
            + f"; misfit {float(r @ r):.3f}" + ("" if _within(rows) else " (a resonance off by more than 0.25 Hz)"))
        cache[key] = r
        return r

    fun(x0)
    if len(seen) < max_evaluations:
        try:
            least_squares(fun, x0, diff_step=0.03, max_nfev=max(1, (max_evaluations - 1) // (len(x0) + 1)),
                          bounds=(0.3 * x0, 3.0 * x0))   # within a factor 3 of the base: the map is not smooth
        except (ValueError, ConfigError):   # ConfigError: a step beyond a parameter's bounds ends the search
            pass
    def valid(s) -> bool:
        return all(r["valid"] for r in s[3])

    # Sets whose rows all lie in the model's valid domain first, then those within the grid step.
    candidates = ([s for s in seen if s[1] and valid(s)] or [s for s in seen if valid(s)]
                  or [s for s in seen if s[1]] or seen)
    best = min(candidates, key=lambda s: s[0])
    start = seen[0]
    return {"config": base.with_parameters(best[2]), "values": best[2], "rows": best[3], "misfit": best[0],
            "start": {"values": start[2], "misfit": start[0], "rows": start[3]}, "evaluations": len(seen),
            "all_within_grid_step": best[1], "invalid_sets": sum(not valid(s) for s in seen),
            "validity": domain(base).report(Verdict.of(r["invalid_rule"]) for r in best[3])}
