"""Every analysis runs every model (docs/physics.md): the structural preset through sweep, orbit, bifurcation, Poincare,
the Peterka and basins maps (their ensemble path) and the Lyapunov exponent.

Hypotheses, and where the expected values come from:

* The analyses integrate the model the configuration selects (``structure.model``, the registry
  ``rimd_sim.model.rig_model.MODELS``), not the paper's: their numbers are the two-mass model's, which differ from the
  rigid model's (the force sensor reads the force through its mount), and every path gives the same trajectory
  as ``RigModel`` with that configuration (the ensemble integrates it with the same driver, bit for bit).
* Classes from rest are the structural preset's Table 1 (tests/model/test_structural.py, impacts per cycle
  counted over 50 cycles): one impact per cycle at 3.75 Hz and one every two cycles at 7.25 Hz (gap 0) and at
  5.25 Hz (gap 2.4 mm).
* At gap 2.4 mm, 5.25 Hz, coexisting attractors (paper Fig. 12 right; docs/interface.md): an upward sweep stays on
  the non-impacting motion while a start from rest reaches band B.
* Lyapunov exponents: without impact the model is the base-excited linear oscillator (the modes are never
  excited), exponent -zeta omega_n (closed form); a stable period-1 impacting orbit (band A) contracts faster.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from harness.outputs import read_json
from rimd_sim import cli
from rimd_sim.analysis.dynamics.basins import basins
from rimd_sim.analysis.dynamics.bifurcation import bifurcation
from rimd_sim.analysis.dynamics.lyapunov import largest_lyapunov
from rimd_sim.analysis.dynamics.peterka import peterka
from rimd_sim.analysis.dynamics.steady import steady_orbit
from rimd_sim.analysis.dynamics.sweep import sweep
from rimd_sim.model.ensemble import StopRule, run_cells
from rimd_sim.model.rig_model import model_for
from rimd_sim.settings.config import find_config_file, load_config


@pytest.fixture(scope="module")
def structural(repo_root):
    return load_config(repo_root / "config" / "structural.yaml")


@pytest.fixture(scope="module")
def rigid(repo_root):
    return load_config(repo_root / "config" / "rimd.yaml")


def test_sweep_and_orbit_run_the_structural_model(structural, rigid):
    """Sweep and orbit from rest at 3.75 Hz, gap 0: band A (1/1), the same steady peak force through both paths
    (the same trajectory), and not the rigid model's."""
    two_mass = sweep(structural, [3.75], "rest", cycles=60, measure_cycles=20, workers=1).points[0]
    paper = sweep(rigid, [3.75], "rest", cycles=60, measure_cycles=20, workers=1).points[0]
    assert two_mass.impacts_per_cycle == 1.0 and paper.impacts_per_cycle == 1.0
    assert abs(two_mass.peak_force_n - paper.peak_force_n) > 0.5, (two_mass.peak_force_n, paper.peak_force_n)
    orbit = steady_orbit(structural, 3.75, transient_cycles=40, measure_cycles=12)
    assert orbit.label == "1/1"
    assert orbit.peak_forces.max() == pytest.approx(two_mass.peak_force_n, rel=1e-6)


def test_bifurcation_and_poincare_run_the_structural_model(structural, rigid, tmp_path):
    """The first point of an upward bifurcation sweep starts from rest: after 40 cycles its 12 stroboscopic
    points are those of ``steady_orbit`` over the same cycles, bit for bit (1/1), and differ from the rigid
    model's. ``rimd poincare`` with the preset: the same class and points, and a negative Lyapunov exponent."""
    orbit = steady_orbit(structural, 3.75, transient_cycles=40, measure_cycles=12)
    (branch,), _, _ = bifurcation(structural, [3.75, 4.0], "up", transient_cycles=40, sample_cycles=12, workers=1)
    (paper,), _, _ = bifurcation(rigid, [3.75, 4.0], "up", transient_cycles=40, sample_cycles=12, workers=1)
    assert branch.points[0].label == "1/1"
    np.testing.assert_array_equal(branch.points[0].u, orbit.u)
    assert np.abs(branch.points[0].u - paper.points[0].u).min() > 1e-3

    out = tmp_path / "pc"
    assert cli.main(["poincare", "--config", str(find_config_file("structural.yaml")), "--gap-mm", "0",
                     "--frequency", "3.75", "--transient-cycles", "40", "--cycles", "12", "--out", str(out)]) == 0
    summary = read_json(out / "summary.json")
    assert summary["class"] == "1/1" and summary["lyapunov_exponent_per_s"] < 0 and not summary["chaotic"]
    rows = np.loadtxt(out / "poincare.csv", delimiter=",", skiprows=1, usecols=4)
    np.testing.assert_allclose(rows, orbit.u, rtol=1e-12)


def test_the_ensemble_is_the_fixed_length_run_of_the_two_mass_model(structural):
    """Three cells of the preset at gap 0 (bands A and B, and the irregular 5.25 Hz) through the ensemble without
    early stopping: the class and the final stroboscopic state of ``steady_orbit`` (``RigModel``), bit for bit."""
    freqs = [3.75, 5.25, 7.25]
    model = model_for(structural)
    assert model.name == "two_mass"
    res = run_cells(model.name, model.params(structural)[None, :], np.zeros(3, dtype=np.int64), freqs, np.zeros(3),
                    np.zeros(3), StopRule(early=False, max_cycles=60 + 36, measure_cycles=36))
    for i, f in enumerate(freqs):
        orbit = steady_orbit(structural, f, transient_cycles=60, measure_cycles=36)
        assert res.labels()[i] == orbit.label and tuple(res.final[i]) == orbit.final_state, f


def test_peterka_runs_the_structural_model_through_the_ensemble(structural):
    """A 2 x 3 map of the preset, fixed length (60 + 36 cycles): the class from rest of every cell is
    ``steady_orbit``'s with the same cycles (``RigModel``), the Table 1 cells are band A and band B, and at
    2.4 mm, 5.25 Hz the upward continuation stays on the non-impacting motion while rest and kick reach band B."""
    gaps, freqs = [0.0, 2.4e-3], [3.75, 5.25, 7.25]
    result = peterka(structural, gaps, freqs, transient_cycles=60, measure_cycles=36, early_stop=False, workers=1)
    for i, g in enumerate(gaps):
        for j, f in enumerate(freqs):
            orbit = steady_orbit(structural.with_parameters({"gap": g}), f, transient_cycles=60, measure_cycles=36)
            assert result.primary[i, j] == orbit.label, (g, f)
    assert result.primary[0, 0] == "1/1" and result.primary[0, 2] == "1/2" and result.primary[1, 1] == "1/2"
    assert list(result.labels[:, 1, 1]) == ["1/2", "1/2", "no impact"] and result.coexisting[1, 1]


@pytest.mark.parametrize(("gap", "frequency"), [(2.4e-3, 5.25), (0.0, 9.0)])
def test_basins_run_the_structural_model_through_the_ensemble(structural, gap, frequency):
    """A 3 x 3 grid of starts (fixed length): every cell's class is ``steady_orbit``'s from that start. At 2.4 mm,
    5.25 Hz the start from rest (the centre) reaches band B (1/2) and another start stays without impact (the
    rigid model gives the same map there); at gap 0, 9.0 Hz the two-mass model's motion is not the rigid model's
    (6/6 against 5/6), so this grid tells the models apart."""
    cfg = structural.with_parameters({"gap": gap})
    grid = {"size": (3, 3), "transient_cycles": 60, "measure_cycles": 36, "early_stop": False, "workers": 1}
    result = basins(cfg, frequency, (-0.03, 0.03), (-1.0, 1.0), **grid)
    for i, rate in enumerate(result.theta_dot0):
        for j, theta in enumerate(result.theta0):
            if result.labels[i, j] != "inside the stop":
                orbit = steady_orbit(cfg, frequency, theta0=theta, theta_dot0=rate, transient_cycles=60,
                                     measure_cycles=36)
                assert result.labels[i, j] == orbit.label, (theta, rate)
    if gap > 0:
        assert result.labels[1, 1] == "1/2" and "no impact" in result.labels
    else:
        paper = basins(cfg.with_parameters({"structure.model": "rigid"}), frequency, (-0.03, 0.03), (-1.0, 1.0),
                       **grid)
        assert (paper.labels != result.labels).any()


def test_lyapunov_of_the_structural_preset(structural):
    """Without impact (gap 30 mm, A0 0.1 mm): -zeta omega_n = -0.915 1/s within 3 % (the modes are never
    excited). Band A at gap 0 (3.75 Hz), a stable period-1 impacting orbit: more negative than the damping alone.
    The two-mass model with a rigid link and mount is the paper's model: the same exponent, bit for bit."""
    linear = structural.with_parameters({"gap": 0.03, "amplitude": 1e-4})
    zeta_wn = structural.rig.damping_ratio * 2 * math.pi * structural.rig.natural_frequency
    assert largest_lyapunov(linear, 2.5, transient_cycles=20, cycles=100).exponent == pytest.approx(-zeta_wn, rel=0.03)
    band_a = largest_lyapunov(structural, 3.75, transient_cycles=100, cycles=100)
    assert band_a.exponent < -zeta_wn
    stiff = {"structure.axial_stiffness": 0.0, "structure.mount_stiffness": 0.0}
    special = largest_lyapunov(structural.with_parameters(stiff), 3.75, transient_cycles=60, cycles=30)
    paper = largest_lyapunov(structural.with_parameters({**stiff, "structure.model": "rigid"}), 3.75,
                             transient_cycles=60, cycles=30)
    assert special.exponent == paper.exponent
