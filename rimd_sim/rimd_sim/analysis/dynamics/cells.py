"""What the maps share about their cells, each a trajectory run by the ensemble kernel.

The Peterka map (:mod:`rimd_sim.analysis.dynamics.peterka`), the basins of attraction
(:mod:`rimd_sim.analysis.dynamics.basins`) and the maps over two parameters (:mod:`rimd_sim.analysis.dynamics.maps`)
run their trajectories through :func:`rimd_sim.model.ensemble.run_cells`, one task per row. This module holds the
pieces they have in common: the stop rule with its cap, the valid domain's measures as plain tuples (a task returns
them to the calling process), the class codes of a map's arrays, the valid domain's table columns, and how long the
trajectories ran.
"""

from __future__ import annotations

import math

import numpy as np

from rimd_sim.errors import ConfigError
from rimd_sim.model.ensemble import StopRule

__all__ = ["check_cycles", "class_codes", "cycles_summary", "stop_rule", "trajectory_measures", "validity_columns"]


def check_cycles(transient: int, measure: int) -> None:
    """Refuse a negative transient or fewer than 6 measured cycles (ConfigError)."""
    if transient < 0 or measure < 6:
        raise ConfigError("cycles", (transient, measure), "need transient_cycles >= 0 and measure_cycles >= 6")


def stop_rule(transient_cycles: int, measure_cycles: int, early_stop: bool, method: str = "window") -> StopRule:
    """The rule of :mod:`rimd_sim.model.ensemble` with the cap ``transient + measure`` cycles.

    ``method``: ``window`` (the fixed confirmation window, after at least 30 cycles or the cap if shorter) or
    ``contraction`` (the convergence test on the stroboscopic map, with no floor of cycles but its own blocks).
    An unknown method is refused by :class:`~rimd_sim.model.ensemble.StopRule` (ConfigError).
    """
    cap = transient_cycles + measure_cycles
    return StopRule(max_cycles=cap, measure_cycles=measure_cycles, early=early_stop,
                    min_cycles=0 if method == "contraction" else min(30, cap), method=method)


def trajectory_measures(res) -> list[tuple[float, float, float, bool]]:
    """Per cell of an :class:`~rimd_sim.model.ensemble.EnsembleResult`, the valid domain's measures as a plain tuple.

    ``(max |theta| (rad), peak force of the run (N), impacts per cycle, chattering)``: the fields of
    :class:`~rimd_sim.model.validity.PointMeasures`, in its order, so that ``PointMeasures(*m)`` rebuilds them.
    """
    return [(m.max_abs_theta, m.peak_force, m.impacts_per_cycle, m.chattering) for m in res.measures()]


def class_codes(labels: np.ndarray) -> tuple[list[str], np.ndarray]:
    """The classes of ``labels`` (sorted) and each element's index into them (int16, the shape of ``labels``).

    One dictionary look-up per element, no sort of the elements: linear in their number.
    """
    flat = labels.ravel().tolist()
    names = sorted(set(flat))
    index = {c: i for i, c in enumerate(names)}
    codes = np.fromiter(map(index.__getitem__, flat), dtype=np.int16, count=len(flat))
    return names, codes.reshape(labels.shape)


def validity_columns(max_abs_theta: np.ndarray, max_force: np.ndarray, invalid_rule: np.ndarray) -> dict[str, list]:
    """The valid domain's columns of a table, one value per element of ``invalid_rule`` (row by row).

    ``max_abs_theta`` and ``max_force`` have one more axis in front (a map's starts, or one): the columns hold the
    largest |theta| and impact force along it, NaN where none is finite; then ``valid`` and ``invalid_rule``.
    """
    def largest(values: np.ndarray) -> list[float]:
        values = np.asarray(values, dtype=float)
        top = np.fmax.reduce(values, axis=0)   # NaN ignored, as np.nanmax
        return np.where(np.isfinite(values).any(axis=0), top, math.nan).ravel().tolist()

    return {"max_abs_theta_rad": largest(max_abs_theta), "max_force_n": largest(max_force),
            "valid": (invalid_rule == "").ravel().tolist(), "invalid_rule": invalid_rule.ravel().tolist()}


def cycles_summary(cycles: np.ndarray, cap: int, rest_cap: int | None = None) -> dict:
    """How long the trajectories ran: mean cycles per start, and the fraction stopped before the cap.

    ``cycles``: per start (first axis), the cycles each trajectory ran (the cap + 1 where it ran to the cap).
    ``rest_cap``: the cap of the first start (a Peterka map's ``rest``) when it differs from the others'; then the
    summary also holds ``rest_cap`` and ``rest_ran_to_cap``, the fraction of the cells whose start from rest ran to
    its cap (classified on its last cycles without having settled).
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
