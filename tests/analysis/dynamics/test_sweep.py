"""``rimd sweep`` and the sweep analysis (docs/analyses.md)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from harness import reference
from harness.outputs import read_json
from harness.presets import SINGLE_MASS_SET
from rimd_sim import cli
from rimd_sim.analysis.dynamics.sweep import sweep
from rimd_sim.settings.config import SimConfig


@pytest.mark.process
def test_rimd_sweep_writes_summary_csv_and_png(tmp_path, capsys):
    """`rimd sweep` from rest at gap 0, 3.5-4 Hz: band A at 3.75 Hz (paper Table 1) with the steady peak force of
    the independent solve_ivp integration of the paper's model (tests/harness/reference.py, from rest at 3.75 Hz,
    its last 20 cycles of 16 s: 79.16 N), to 1e-4."""
    ref_peak, ref_rate = reference.steady_peak(reference.simulate(frequency=3.75, gap=0.0, duration=16.0), 3.75,
                                               16.0 - 20 / 3.75, 16.0)
    assert ref_rate == pytest.approx(1.0)
    out = tmp_path / "sw"
    status = cli.main(["sweep", "--gap-mm", "0", "--f-min", "3.5", "--f-max", "4.0", "--f-step", "0.25",
                       "--direction", "rest", "--out", str(out)])
    assert status == 0
    summary = read_json(out / "summary.json")
    assert summary["gap_mm"] == 0.0
    assert summary["band_a"]["frequency_hz"] == 3.75
    assert summary["band_a"]["peak_force_n"] == pytest.approx(ref_peak, rel=1e-4)
    assert summary["band_b"] is None
    assert summary["simulated_seconds"] > 0 and summary["wall_seconds"] > 0
    rows = list(csv.DictReader(open(out / "sweep.csv")))
    assert [float(r["frequency_hz"]) for r in rows] == [3.5, 3.75, 4.0]
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "band A 3.75 Hz" in capsys.readouterr().out


def test_rimd_sweep_refuses_bad_ranges(tmp_path, capsys):
    with pytest.raises(SystemExit) as usage:
        cli.main(["sweep", "--f-step", "0", "--out", str(tmp_path)])
    assert usage.value.code == 2 and "--f-step 0 refused: must be > 0 Hz" in capsys.readouterr().err
    assert cli.main(["sweep", "--f-min", "5", "--f-max", "3", "--out", str(tmp_path)]) == 1
    assert "--f-min 5 > --f-max 3" in capsys.readouterr().err
    assert cli.main(["sweep", "--f-max", "50", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    # The refusal names the parameter that sets the ceiling, and its value.
    assert "parameter 'frequencies'" in err and "<= motor.max_frequency = 12 Hz" in err, err
    for verb in (["bifurcation", "--f-max", "50"], ["peterka", "--f-max", "50", "--gap-max-mm", "0"]):
        assert cli.main([*verb, "--out", str(tmp_path)]) == 1
        assert "motor.max_frequency = 12 Hz" in capsys.readouterr().err, verb


def test_coexisting_attractors_at_gap_2_4mm():
    """Paper Fig. 12 (right), docs/interface.md, "What the twin must reproduce": at gap 2.4 mm an upward sweep falls off
    band A onto the non-impacting motion and stays there through band B's frequency, while a start from rest reaches
    band B (5.25 Hz, one impact every two cycles)."""
    cfg = SimConfig().with_parameters({"gap": 2.4e-3})
    freqs = np.arange(2.0, 5.51, 0.25)
    up = sweep(cfg, freqs, "up")
    rest = sweep(cfg, freqs, "rest", workers=1)
    up_at = {p.frequency_hz: p for p in up.points}
    rest_at = {p.frequency_hz: p for p in rest.points}
    assert up_at[2.5].impacts_per_cycle == 1.0
    assert all(up_at[f].impacts_per_cycle == 0.0 for f in (3.0, 4.0, 5.0, 5.25))
    assert up.band_b is None
    assert rest.band_b is not None and rest.band_b.frequency_hz == 5.25
    assert rest_at[5.25].impacts_per_cycle == 0.5


@pytest.mark.parametrize("name, gap, up, down", [
    # config/rimd.yaml with the single-mass set's values (harness.presets): a 1/1 point of the up sweep read 0.98 (its
    # time window cut the impact in progress at its end); 5/6 and 2/3 points read 0.84, 0.64 (50 cycles hold no
    # whole number of their periods).
    ("rimd.yaml", 0.0, *[{4.5: 1.0, 4.75: 1.0, 6.5: 0.5, 9.0: 5 / 6, 9.25: 2 / 3}] * 2),
    # config/paper_model.yaml at 2.4 mm: 1/1 below 3.25 Hz; down, 5/8 at 4.5 Hz and 1/3 up high (read 0.62, 0.32,
    # 0.34). Up, the sweep falls onto the coexisting non-impacting motion at 3.25 Hz and stays there (which of the
    # two it meets there turns on the last bits of the arithmetic, so this pin holds the integrator's exact
    # operations).
    ("paper_model.yaml", 2.4e-3, {2.5: 1.0, 3.0: 1.0, 4.5: 0.0},
     {2.5: 1.0, 4.5: 5 / 8, 8.5: 1 / 3, 9.0: 1 / 3, 9.5: 1 / 3}),
])
def test_impacts_per_cycle_of_a_steady_motion_is_exactly_p_over_n(name, gap, up, down):
    """docs/analyses.md, "`rimd sweep`": a steady p/n point of an up and of a down sweep reads exactly
    p / n (the classification of its last measured whole cycles), not a count over a window of time."""
    from rimd_sim.settings.config import find_config_file, load_config

    cfg = load_config(find_config_file(name), {"gap": gap, **(SINGLE_MASS_SET if name == "rimd.yaml" else {})})
    freqs = np.round(np.arange(2.0, 9.51, 0.25), 6)
    for direction, expected in (("up", up), ("down", down)):
        at = {p.frequency_hz: p.impacts_per_cycle for p in sweep(cfg, freqs, direction).points}
        assert {f: at[f] for f in expected} == expected, direction
