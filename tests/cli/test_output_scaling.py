"""The map verbs write their files in time linear in the cells: ``rimd peterka``, ``rimd map``, ``rimd basins``.

What a verb does once its computation is over (the CSV, the arrays, the summary, the validity report and its last
lines) is timed on an N x N result and on a 2N x 2N one (four times the cells), in this process, the computation
replaced by a synthetic result of that size (classes, coexisting cells, cells outside the valid domain, NaN
measures: every column path). Linear work gives a ratio about 4; work quadratic in the cells (an array of the whole
map rebuilt per cell) about 16. The ratio is asserted, never a duration: each time is the fastest of a few runs in
this one test, alternating the sizes, and it is this process's CPU time (the work is this process's alone: no pool,
no figure worker), which other processes on a loaded machine change far less than they change its wall time.

The figure is left out (a stub writes the PNG): matplotlib's drawing costs about as much at both sizes, which
would hide the ratio of the rest; benchmarks/bench_wall.py times the whole verbs, figures included.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from rimd_sim import cli

#: Cells per axis of the smaller map: its files take tens of milliseconds or more, well above the timer's noise.
N = 100
#: Runs of each size; the fastest counts.
REPEATS = 3
#: Largest ratio of the 2N x 2N map's time to the N x N one's: linear gives about 4, quadratic about 16.
MAX_RATIO = 6.0

CLASSES = np.array(["1/1", "1/2", "no impact", "chaotic/non-periodic", "2/2", "3/7"], dtype=object)


def _pattern(n: int, shift: int = 0) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.mgrid[0:n, 0:n]
    return i, (j + shift)


def _classes(n: int, shift: int = 0) -> np.ndarray:
    i, j = _pattern(n, shift)
    return CLASSES[(i // 7 + j // 5) % len(CLASSES)]


def _rules(n: int, shift: int = 0) -> np.ndarray:
    """Every third cell outside the valid domain, by one rule or two."""
    i, j = _pattern(n, shift)
    names = np.array(["", "contact_force", "", "pendulum_angle;contact_force", "", "chattering"], dtype=object)
    return names[(i + 2 * j) % len(names)]


def _measure(n: int, seed: int) -> np.ndarray:
    """Figures of 0.1 resolution (short to write: the CSV's linear part stays small beside a quadratic one)."""
    values = np.round(np.random.default_rng(seed).random((n, n)) * 100.0, 1)
    values[::9, ::4] = np.nan   # a run the chattering guard stopped: no measure
    return values


def _peterka_result(n: int):
    from rimd_sim.analysis.dynamics.peterka import PeterkaResult, cell_rules

    named = np.stack([_classes(n), _classes(n), _classes(n, 3)])
    rules = np.stack([_rules(n), _rules(n, 1), _rules(n, 2)])
    gaps = np.linspace(0.0, 3.0, n)
    freqs = np.linspace(1.82, 9.1, n)
    return PeterkaResult(
        gaps, freqs, gaps / 2.0, freqs / 1.82, named, 1.0, 2, 192, np.full(named.shape, 100), True, "local",
        rules, np.stack([_measure(n, s) for s in range(3)]),
        np.stack([_measure(n, s) for s in range(3, 6)]), {"points": n * n},
        extra_labels=_classes(n, 7)[None], extra_invalid_rules=_rules(n, 4)[None],
        extra_max_abs_theta=_measure(n, 6)[None], extra_max_force=_measure(n, 7)[None],
        peak_force=_measure(n, 8), impact_velocity=_measure(n, 9), stop="contraction", rest_cycles=640,
        invalid_rule=cell_rules(np.concatenate([rules, _rules(n, 4)[None]])))


def _map_result(n: int):
    from rimd_sim.analysis.dynamics.maps import ParameterMap

    freqs = np.tile(np.linspace(3.0, 8.0, n), (n, 1))
    return ParameterMap(
        "frequency", "mass", np.linspace(3.0, 8.0, n), np.linspace(0.1, 0.2, n), freqs, freqs / 1.82, _classes(n),
        _measure(n, 0), _measure(n, 1), _measure(n, 2), _measure(n, 3), np.full((n, n), 100), _measure(n, 4),
        _measure(n, 5), _rules(n), 120, 72, True, 1.0, 2, "local", {"points": n * n})


def _basins_result(n: int):
    from rimd_sim.analysis.dynamics.basins import BasinsResult

    labels = _classes(n)
    ids = np.searchsorted(np.sort(CLASSES), labels)
    attractors = [{"id": a, "class": c, "settled": True, "period": 1, "u": [0.1], "v": [0.2], "theta_rad": [0.01],
                   "theta_dot_rad_s": [0.1], "peak_force_n": 50.0, "cells": int((ids == a).sum())}
                  for a, c in enumerate(np.sort(CLASSES))]
    return BasinsResult(2.4, 4.0, np.linspace(-0.1, 0.05, n), np.linspace(-3.0, 3.0, n), labels, 1.0, 2,
                        np.full((n, n), 100), "local", _rules(n), _measure(n, 0), _measure(n, 1), {"points": n * n},
                        ids, attractors, _measure(n, 2), _measure(n, 3))


#: Per verb: its arguments for an n x n map, the analysis it calls (module, name), the synthetic result, the figure.
VERBS = {
    "peterka": (lambda n: ["peterka", "--gaps", str(n), "--freqs", str(n)],
                ("rimd_sim.analysis.dynamics.peterka", "peterka"), _peterka_result, "plot_peterka"),
    "map": (lambda n: ["map", "--x", "frequency", "--x-range", "3", "8", str(n), "--y", "mass", "--y-range", "0.1",
                       "0.2", str(n)],
            ("rimd_sim.analysis.dynamics.maps", "parameter_map"), _map_result, "plot_map"),
    "basins": (lambda n: ["basins", "--size", str(n)],
               ("rimd_sim.analysis.dynamics.basins", "basins"), _basins_result, "plot_basins"),
}


def _stub_figure(result, path: Path, *args, **kwargs) -> Path:
    path.write_bytes(b"\x89PNG\r\n\x1a\n")
    return path


@pytest.mark.parametrize("verb", list(VERBS))
def test_writing_a_maps_files_is_linear_in_its_cells(verb, tmp_path, monkeypatch, capsys):
    import importlib

    import rimd_sim.analysis.plots as plots

    argv, (module, name), make, figure = VERBS[verb]
    monkeypatch.setattr(plots, figure, _stub_figure)
    results = {n: make(n) for n in (N // 4, N, 2 * N)}

    def files_seconds(n: int) -> float:
        """CPU seconds of the verb's main with the computation replaced by the n x n result (its files' writing)."""
        monkeypatch.setattr(importlib.import_module(module), name, lambda *a, **k: results[n])
        out = tmp_path / f"{verb}{n}"
        start = time.process_time()
        status = cli.main([*argv(n), "--out", str(out), "--accept-invalid"])
        seconds = time.process_time() - start
        assert status == 0 and (out / "summary.json").is_file()
        return seconds

    files_seconds(N // 4)   # imports and first calls, untimed
    times: dict[int, list[float]] = {N: [], 2 * N: []}
    for _ in range(REPEATS):
        for n in times:
            times[n].append(files_seconds(n))
    small, big = min(times[N]), min(times[2 * N])
    ratio = big / small
    capsys.readouterr()
    assert ratio <= MAX_RATIO, (f"rimd {verb}: {2 * N}x{2 * N} cells' files in {big:.3f} CPU s against {small:.3f} s "
                                f"for {N}x{N}: x{ratio:.1f} for 4x the cells (linear: about 4)")
