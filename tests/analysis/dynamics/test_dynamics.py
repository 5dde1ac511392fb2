"""Stroboscopic classification of steady motions (p impacts in n cycles), and the period doubling at gap 0."""

from __future__ import annotations

import numpy as np
import pytest

from harness.presets import SINGLE_MASS_SET
from rimd_sim.analysis.dynamics.steady import CHAOTIC, NO_IMPACT, UNSETTLED, classify, steady_orbit
from rimd_sim.errors import ConfigError
from rimd_sim.settings.config import SimConfig, find_config_file, load_config


def test_classify_finds_the_smallest_period_and_counts_impacts():
    """Synthetic windows: a 2-cycle orbit with one impact per cycle is 2/2, not 1/1 nor 4/4; one impact every
    two cycles on a 2-cycle orbit is 1/2; a fixed point with one impact per cycle is 1/1."""
    u2 = np.tile([0.3, -1.2], 12)
    v2 = np.tile([0.5, 0.1], 12)
    assert classify(u2, v2, np.ones(24, int))[:3] == ("2/2", 2, 2)
    assert classify(u2, v2, np.tile([1, 0], 12))[:3] == ("1/2", 2, 1)
    assert classify(np.full(24, 0.7), np.full(24, 0.2), np.ones(24, int))[:3] == ("1/1", 1, 1)


def test_classify_no_impact_and_non_periodic():
    """Points that never repeat (an irrational rotation) with impacts are non-periodic; without impacts the
    class is 'no impact' whatever the points do."""
    k = np.arange(48)
    u, v = np.cos(k * np.sqrt(2.0)), np.sin(k * np.sqrt(2.0))
    label, period, _, spread = classify(u, v, np.ones(48, int))
    assert (label, period) == (CHAOTIC, 0) and spread > 0.1
    assert classify(u, v, np.zeros(48, int))[0] == NO_IMPACT


def test_classify_tolerance_separates_converged_from_drifting():
    """A period-1 point that still drifts by 1e-2 per cycle is not converged at tolerance 1e-3."""
    u = 1.0 + 1e-2 * np.arange(24)
    assert classify(u, np.zeros(24), np.ones(24, int))[0] == CHAOTIC
    assert classify(u, np.zeros(24), np.ones(24, int), tolerance=0.02)[0] == "1/1"


def test_a_slowly_decaying_alternation_is_unsettled_never_2_2():
    """About a period-1 orbit whose Floquet multiplier is -0.998, the points alternate and the alternation
    decays by 0.2 % a cycle: it repeats every two cycles within 1e-3 long before it dies out. The class is
    what the motion converges to (1/1) or unsettled, never 2/2; a converged alternation is 2/2."""
    k = np.arange(48)
    decaying = 1.0 + 0.2 * (-0.998) ** k
    assert classify(decaying, np.zeros(48), np.ones(48, int))[0] == UNSETTLED
    steady = 1.0 + 0.2 * (-1.0) ** k
    assert classify(steady, np.zeros(48), np.ones(48, int))[0] == "2/2"
    growing = 1.0 + 0.01 * np.where(k % 2, -1.0, 1.0) * np.minimum(1.0, 0.5 + k / 40)
    assert classify(growing, np.zeros(48), np.ones(48, int))[0] != "1/1"


def test_the_single_mass_sets_4_95_hz_gap_0_orbit_is_1_1_or_unsettled():
    """The single-mass set (m 0.15 kg, zeta 0.08, A0 1 mm, f_n 1.82 Hz) at gap 0, 4.95 Hz: its period-1 orbit is
    stable with a multiplier of -0.998, and a sweep comes to it on a slowly dying alternation that repeats every two
    cycles to the tolerance. From rest after 100 or 1000 cycles, and on the up, down and from-rest sweeps of
    ``rimd bifurcation``'s grid, it is 1/1 or unsettled, never 2/2; after 5000 cycles, 1/1."""
    from rimd_sim.analysis.dynamics.bifurcation import bifurcation

    single_mass = SimConfig().with_parameters({**SINGLE_MASS_SET, "gap": 0.0})
    for transient in (100, 1000):
        assert steady_orbit(single_mass, 4.95, transient_cycles=transient).label in ("1/1", UNSETTLED)
    assert steady_orbit(single_mass, 4.95, transient_cycles=5000).label == "1/1"
    freqs = [round(4.5 + 0.05 * i, 2) for i in range(13)]
    branches, _, _ = bifurcation(single_mass, freqs, "all", workers=1)
    for b in branches:
        (point,) = [p for p in b.points if p.frequency_hz == 4.95]
        assert point.label in ("1/1", UNSETTLED), (b.direction, point.label)


def test_band_a_at_gap0_is_period_1_and_band_b_period_half():
    """Table 1 with the defaults: 3.75 Hz at gap 0 is one impact per cycle (1/1); 7.25 Hz one impact every
    two cycles (1/2); 1.0 Hz, far below the 1.82 Hz resonance, with gap 2.4 mm, never impacts."""
    cfg = SimConfig()
    assert steady_orbit(cfg, 3.75).label == "1/1"
    assert steady_orbit(cfg, 7.25).label == "1/2"
    assert steady_orbit(cfg.with_parameters({"gap": 2.4e-3}), 1.0).label == NO_IMPACT


def test_steady_orbit_refuses_bad_input():
    with pytest.raises(ConfigError, match="frequency"):
        steady_orbit(SimConfig(), -1.0)
    with pytest.raises(ConfigError, match="cycles"):
        steady_orbit(SimConfig(), 3.0, measure_cycles=1)


@pytest.fixture(scope="module")
def paper_gap0():
    return load_config(find_config_file("paper_model.yaml"), {"gap": 0.0})


def test_period_doubling_window_at_gap0_paper_model(paper_gap0):
    """Paper section 2.1 (docs/interface.md, "What the twin must reproduce"): at gap 0 the paper's model has a period-1
    impact motion with alternating magnitudes from 4.80-4.85 Hz (the experiment: near 4.75 Hz). With the paper-model
    preset the stroboscopic class is 1/1 up to 4.80 Hz and 2/2 (one impact per cycle, period 2, two magnitudes) from
    4.85 Hz. Measured from rest, 100 transient and 48 measured cycles, on a 0.05 Hz grid."""
    labels = {f: steady_orbit(paper_gap0, f) for f in (4.75, 4.8, 4.85, 4.9)}
    assert [labels[f].label for f in (4.75, 4.8)] == ["1/1", "1/1"]
    assert [labels[f].label for f in (4.85, 4.9)] == ["2/2", "2/2"]
    peaks = labels[4.9].peak_forces
    assert abs(peaks[0::2].mean() - peaks[1::2].mean()) > 0.03 * peaks.mean()  # alternating magnitudes


def test_period_doubling_with_the_defaults_near_4_8_hz():
    """The defaults (the paper's rig) double at the end of band A near 4.8 Hz (paper 4.75 Hz; the multiplier
    crosses -1 at 4.805 Hz): 4.75 Hz is still 1/1, 4.85 Hz is 2/2."""
    cfg = SimConfig()
    assert steady_orbit(cfg, 4.75).label == "1/1"
    assert steady_orbit(cfg, 4.85).label == "2/2"


@pytest.mark.parametrize("name", ["paper_model.yaml", "rimd.yaml"])
def test_peterka_finds_the_no_impact_motion_beside_1_1_at_2_4mm_2_548hz(name):
    """docs/analyses.md, "rimd peterka": at gap 2.4 mm, 2.548 Hz (Omega/omega_n = 1.4) ``rimd basins`` finds the
    no-impact motion beside 1/1 (config/rimd.yaml: 33 of 576 initial conditions; config/paper_model.yaml: 1).
    The three named starts all end on 1/1; the default extra start (the no-impact forced response) finds it, and
    so do Halton starts over the basins' region without it (rimd.yaml: the 3rd point)."""
    from rimd_sim.analysis.dynamics.cells import stop_rule
    from rimd_sim.analysis.dynamics.peterka import DEFAULT_EXTRA_STARTS, extra_starts, peterka
    from rimd_sim.model.ensemble import run_cells
    from rimd_sim.model.rig_model import model_for

    cfg = load_config(find_config_file(name), {"gap": 2.4e-3})
    three = peterka(cfg, [2.4e-3], [2.45, 2.548], workers=1, starts=0)
    assert three.classes_found.tolist() == [["1/1", "1/1"]] and not three.coexisting.any()
    assert DEFAULT_EXTRA_STARTS >= 1
    default = peterka(cfg, [2.4e-3], [2.45, 2.548], workers=1)
    assert default.starts == 3 + DEFAULT_EXTRA_STARTS
    assert (default.labels == three.labels).all()   # the named starts are untouched
    assert default.classes_found[0, 1] == "1/1;no impact" and default.coexisting[0, 1]
    assert default.extra_labels[0, 0, 1] == "no impact"
    # The Halton starts alone (start 0, the forced response, left out).
    th, om = extra_starts(cfg, [2.548], 8)
    model = model_for(cfg)
    res = run_cells(model.name, model.params(cfg)[None, :], np.zeros(7, dtype=np.int64), np.full(7, 2.548),
                    th[1:, 0], om[1:, 0], stop_rule(120, 72, True))
    if name == "rimd.yaml":
        assert "no impact" in res.labels()


def test_extra_starts_nest_and_stay_in_the_basins_region():
    from rimd_sim.analysis.dynamics.basins import default_basin_ranges
    from rimd_sim.analysis.dynamics.peterka import extra_starts, free_response

    cfg = load_config(find_config_file("rimd.yaml"), {"gap": 1e-3})
    th, om = extra_starts(cfg, [2.0, 3.0], 16)
    th8, om8 = extra_starts(cfg, [2.0, 3.0], 8)
    assert (th[:8] == th8).all() and (om[:8] == om8).all()
    assert th[0, 1] == free_response(cfg, 3.0)[0] and om[0, 1] == free_response(cfg, 3.0)[1]
    (t_lo, t_hi), (r_lo, r_hi) = default_basin_ranges(cfg)
    assert ((t_lo <= th[1:]) & (th[1:] <= t_hi)).all() and ((r_lo <= om[1:]) & (om[1:] <= r_hi)).all()
    assert len({(a, b) for a, b in zip(th[1:, 0], om[1:, 0], strict=True)}) == 15


def test_cluster_orbits_tells_apart_two_orbits_of_one_class_and_compares_them_as_sets():
    """Synthetic stroboscopic points (u, v): two different 1/2 orbits get two ids, one orbit met at either of
    its two phases (its points in the other order, 1e-4 apart) one id; two different 1/1 orbits two ids;
    non-periodic trajectories of one class share one; a trajectory not run gets -1."""
    from rimd_sim.analysis.dynamics.steady import cluster_orbits, orbit_points, same_orbit

    a = np.array([[0.0, -1.0], [2.0, 1.0]])
    a_shifted = a[::-1] + 1e-4
    b = np.array([[0.0, -1.0], [2.5, 1.0]])          # shares a point with a, not the other
    one, other = np.array([[-3.87, -1.26]]), np.array([[-1.0, 0.5]])
    labels = ["1/2", "1/2", "1/2", "1/1", "1/1", "1/1", CHAOTIC, CHAOTIC, None]
    orbits = [a, a_shifted, b, one, other, one + 5e-4, None, None, None]
    ids, reps = cluster_orbits(labels, orbits)
    assert ids.tolist() == [0, 0, 1, 2, 3, 2, 4, 4, -1] and reps == [0, 2, 3, 4, 6]
    assert same_orbit(a, a_shifted) and not same_orbit(a, b) and not same_orbit(a, one)
    # orbit_points: the last n points of a p/n class; the smallest repeating set of a no-impact motion.
    u = np.array([5.0, 0.0, 2.0, 0.0, 2.0, 0.0, 2.0])
    v = np.array([5.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0])
    assert orbit_points(u, v, "1/2").tolist() == [[0.0, -1.0], [2.0, 1.0]]
    assert orbit_points(u[1:], v[1:], NO_IMPACT).shape == (2, 2) and orbit_points(u, v, NO_IMPACT) is None
    assert orbit_points(u, v, CHAOTIC) is None and orbit_points(np.arange(8.0), np.zeros(8), NO_IMPACT) is None
    assert orbit_points(np.full(3, np.nan), np.zeros(3), "1/1") is None
