"""The analyses and the structural model (issue 15): which run it, and which refuse it with a reason.

Hypothesis: ``rimd sweep``, ``bifurcation`` and ``poincare`` build their model with
:func:`rimd_sim.core.structural.make_model`, so ``structure.model: two_mass`` changes their results (the force
sensor reads the force through its mount: the peak force differs from the rigid model's); the Peterka and
basins maps (the ensemble kernel of the paper's model) and the Lyapunov exponent (a two-dimensional
stroboscopic map) refuse it naming ``structure.model``, instead of silently computing the rigid model.
"""

from __future__ import annotations

import pytest

from rimd_sim.analysis.dynamics import steady_orbit
from rimd_sim.analysis.lyapunov import largest_lyapunov
from rimd_sim.analysis.peterka import basins, peterka
from rimd_sim.analysis.sweep import sweep
from rimd_sim.core import ConfigError, load_config


@pytest.fixture(scope="module")
def structural(repo_root):
    return load_config(repo_root / "config" / "structural.yaml")


def test_sweep_and_orbit_run_the_structural_model(structural, repo_root):
    rigid = load_config(repo_root / "config" / "rimd.yaml")
    two_mass = sweep(structural, [3.75], "rest", cycles=60, measure_cycles=20, workers=1).points[0]
    paper = sweep(rigid, [3.75], "rest", cycles=60, measure_cycles=20, workers=1).points[0]
    assert two_mass.peak_force_n > 0 and paper.peak_force_n > 0
    assert abs(two_mass.peak_force_n - paper.peak_force_n) > 0.5, (two_mass.peak_force_n, paper.peak_force_n)
    orbit = steady_orbit(structural, 3.75, transient_cycles=40, measure_cycles=12)
    assert orbit.label


def test_maps_and_lyapunov_refuse_the_structural_model(structural):
    with pytest.raises(ConfigError, match=r"structure.model.*not supported by the Peterka map"):
        peterka(structural, [0.0], [3.75], workers=1)
    with pytest.raises(ConfigError, match=r"structure.model.*not supported by the basins map"):
        basins(structural, 3.75, (-0.1, 0.1), (-1.0, 1.0), size=(2, 2), workers=1)
    with pytest.raises(ConfigError, match=r"structure.model.*not supported by the Lyapunov exponent"):
        largest_lyapunov(structural, 3.75, transient_cycles=1, cycles=1)
