"""Maps over two declared parameters (``rimd_sim.analysis.dynamics.maps``): the same runs as the sweep and the
Peterka map they generalise, and refusals that name the parameter before any work."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimd_sim.analysis.dynamics import maps
from rimd_sim.analysis.dynamics.maps import parameter_map
from rimd_sim.analysis.dynamics.peterka import peterka
from rimd_sim.analysis.dynamics.sweep import sweep
from rimd_sim.errors import ConfigError
from rimd_sim.settings.config import load_config

CYCLES, MEASURE = 100, 30


@pytest.fixture(scope="module")
def paper():
    return load_config("config/paper_model.yaml", {"gap": 0.0})


def test_map_cells_are_the_sweep_points_of_their_parameters(paper):
    """(natural_frequency x mass) at 2 Hz, gap 0, run to a fixed length: every cell's class, peak force, F/(m g)
    and impact velocity equal, bit for bit, those of a sweep from rest of that cell's configuration (the ensemble
    is bit-identical to RigModel runs). The sweep of C cycles reads cycles C - M .. C - 1; the map's capped window
    is transient + 1 .. transient + M (as steady_orbit and the Peterka map read it), so the same cycles are
    transient = C - M - 1. With transient = C - M the window is one cycle later, and the largest of M per-cycle
    peaks of a settled motion, equal only to rounding, then differs in its last bits in some cells (2 of 24 in a
    scan of natural_frequency 1.7-2 Hz x mass 0.1-0.15 kg at 3-6.75 Hz)."""
    xs, ys = [1.5, 1.82, 2.5], [0.1, 0.2]
    m = parameter_map(paper, "natural_frequency", xs, "mass", ys, frequency_hz=2.0, early_stop=False,
                      transient_cycles=CYCLES - MEASURE - 1, measure_cycles=MEASURE, workers=1)
    assert m.labels.shape == (2, 3) and m.x == "natural_frequency" and m.y == "mass"
    assert len(set(m.labels.ravel().tolist())) > 1   # the grid holds different motions
    for i, mass in enumerate(ys):
        for j, fn in enumerate(xs):
            cfg = paper.with_parameters({"natural_frequency": fn, "mass": mass})
            point = sweep(cfg, [2.0], "rest", cycles=CYCLES, measure_cycles=MEASURE, workers=1).points[0]
            assert m.labels[i, j] == point.motion_class, (fn, mass)
            assert m.peak_force[i, j] == point.peak_force_n, (fn, mass)
            assert m.impact_velocity[i, j] == point.impact_velocity_m_s, (fn, mass)
            assert m.force_ratio[i, j] == point.force_ratio, (fn, mass)
            assert m.impacts_per_cycle[i, j] == point.impacts_per_cycle, (fn, mass)
            assert point.peak_force_n > 0 and 0 < point.impact_velocity_m_s < 1   # m/s, the approach speed
            assert m.valid[i, j] == point.valid and m.cycles[i, j] == CYCLES   # ran to the cap (cap + 1 = C)
            assert m.frequency_ratio[i, j] == 2.0 / fn


def test_a_frequency_gap_map_is_the_peterka_maps_rest_start(paper):
    """With frequency along x and gap along y: the classes, peak force and impact velocity of the Peterka map's
    ``rest`` start (the same stop rule, the same compiled runs), with the no-impact cell at 0 N."""
    gaps, freqs = [0.0, 2.4e-3], [3.75, 5.25, 6.75]
    m = parameter_map(paper, "frequency", freqs, "gap", gaps, workers=1)
    p = peterka(paper, gaps, freqs, starts=0, stop="window", rest_cycles=192, workers=1)   # the map's rule and cap
    assert m.labels.tolist() == p.primary.tolist()
    np.testing.assert_array_equal(m.peak_force, p.peak_force)
    np.testing.assert_array_equal(m.impact_velocity, p.impact_velocity)
    assert m.frequency_hz.tolist() == [freqs, freqs]
    impacting = m.peak_force > 0
    assert impacting.any() and (m.impact_velocity[impacting] > 0).all()
    assert (m.impact_velocity[~impacting] == 0).all() and (m.labels[~impacting] == "no impact").all()
    rows = m.table()
    assert list(rows[0])[:5] == ["frequency", "gap", "frequency_hz", "frequency_ratio", "class"]
    summary = m.summary()
    assert summary["x"] == {"name": "frequency", "unit": "Hz", "values": freqs}
    assert summary["y"]["unit"] == "m" and summary["frequency_hz"] is None and summary["start"] == "rest"


def test_a_refused_value_names_the_parameter_before_any_work(paper, monkeypatch):
    def no_work(*args, **kwargs):
        raise AssertionError("the map started work before refusing")

    monkeypatch.setattr(maps, "run_tasks", no_work)
    with pytest.raises(ConfigError, match=r"natural_frequency.*must be > 0"):
        parameter_map(paper, "natural_frequency", [1.82, -1.0], "mass", [0.15], frequency_hz=4.0)
    with pytest.raises(ConfigError, match=r"mass.*must be >= 0.001"):
        parameter_map(paper, "natural_frequency", [1.82], "mass", [0.15, 0.0], frequency_hz=4.0)


@pytest.mark.parametrize(("x", "kwargs", "message"), [
    ("stifness", {"frequency_hz": 4.0}, r"stifness.*unknown parameter \(known: frequency, gap, mass, .*natural_"),
    ("structure.model", {"frequency_hz": 4.0}, r"structure.model.*selects the model"),
    ("motor.ramp_rate", {"frequency_hz": 4.0}, r"motor.ramp_rate.*protocol sets it"),
    ("seed", {"frequency_hz": 4.0}, r"seed.*does not enter the model"),
    ("natural_frequency", {}, r"frequency.*is needed"),
    ("natural_frequency", {"frequency_hz": 40.0}, r"frequency.*<= motor.max_frequency = 12 Hz"),
    ("frequency", {"frequency_hz": 4.0}, r"frequency.*axis of this map"),
    ("mass", {"frequency_hz": 4.0}, r"y.*must differ from x"),
])
def test_an_unmappable_axis_is_refused_naming_it(paper, x, kwargs, message):
    with pytest.raises(ConfigError, match=message):
        parameter_map(paper, x, [1.0], "mass", [0.15], **kwargs)


def test_axis_values_are_in_the_declared_unit(paper):
    """Values in the declared unit: a gap axis in m, one row; the cell's force ratio uses its own mass."""
    m = parameter_map(paper, "gap", [0.0, 1e-3], "mass", [0.1], frequency_hz=3.75, workers=1)
    assert m.x_values.tolist() == [0.0, 1e-3] and m.x_unit == "m" and m.y_unit == "kg"
    assert math.isclose(m.force_ratio[0, 0], m.peak_force[0, 0] / (0.1 * paper.rig.gravity))
