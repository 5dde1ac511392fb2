"""The paper's rig: the default configuration against every finding the paper publishes (docs/validation.md).

Hypotheses: with config/rimd.yaml the twin reproduces Table 1's six resonances (from rest, the 0.25 Hz grid, band
by class), both gap-0 forces within 5 %, the gap-0 period doubling within 0.1 Hz of 4.75 Hz (found by the
continuation as well as by the fit's faster tracking), chaos in the transition bands at 1.0 and 2.4 mm (a positive
largest Lyapunov exponent on a chaotic attractor of a sweep) and coexisting motions above gap/A0 = 1.5; ``rimd
paper`` writes that table, the same as docs/validation/validation.csv, and the paper's figures; ``rimd fit-paper``
returns a set that passes, with its evaluations and Pareto front.
"""

from __future__ import annotations

import contextlib
import csv
import io
from pathlib import Path

import pytest

from harness.outputs import read_json
from rimd_sim.analysis.dynamics.continuation import ContinuationSettings, continuation
from rimd_sim.analysis.dynamics.lyapunov import CHAOS_THRESHOLD
from rimd_sim.analysis.dynamics.paper_targets import (
    DOUBLING_HZ,
    FORCES_GAP0_N,
    TABLE1_HZ,
    band_of,
    doubling_frequency,
    table_sweeps,
)
from rimd_sim.analysis.dynamics.sweep import sweep
from rimd_sim.cli import main
from rimd_sim.settings.config import find_config_file, load_config

ROOT = Path(__file__).resolve().parents[3]


def _run(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(list(args))
    return status, out.getvalue(), err.getvalue()


@pytest.mark.process
def test_the_default_reproduces_table_1_and_the_gap_0_forces():
    sweeps = table_sweeps(load_config(), workers=2)
    for gap, (fa, fb) in TABLE1_HZ.items():
        a, b = band_of(sweeps[gap].points, "A"), band_of(sweeps[gap].points, "B")
        assert (a.frequency_hz, b.frequency_hz) == (fa, fb), gap
        if gap == 0.0:
            assert a.peak_force_n == pytest.approx(FORCES_GAP0_N["A"], rel=0.05)
            assert b.peak_force_n == pytest.approx(FORCES_GAP0_N["B"], rel=0.05)
        # The sweep's own bands are the same points: bands go by class.
        assert (sweeps[gap].band_a, sweeps[gap].band_b) == (a, b)


def test_the_default_doubles_at_the_end_of_band_a_within_0_1_hz_of_4_75():
    """The continuation of the gap-0 period-1 orbit locates the multiplier -1 where the fit's tracking does."""
    config = load_config().with_parameters({"gap": 0.0})
    result = continuation(config, 4.0, 5.2, settings=ContinuationSettings(switch=False))
    doublings = [b.frequency_hz for b in result.of_kind("period_doubling") if b.period == 1]
    assert doublings, [b.kind for b in result.bifurcations]
    assert doublings[0] == pytest.approx(DOUBLING_HZ, abs=0.1)
    assert doublings[0] == pytest.approx(doubling_frequency(config), abs=2e-3)


@pytest.mark.process
def test_rimd_paper_reproduces_every_finding_and_writes_the_documented_table(tmp_path):
    out = tmp_path / "paper"
    status, stdout, err = _run("paper", "--out", str(out), "--workers", "2")
    assert status == 0, err
    with open(out / "validation.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 12 and all(r["passed"] == "True" for r in rows), [r for r in rows if r["passed"] != "True"]
    chaos = {r["key"]: float(r["twin"]) for r in rows if r["key"].startswith("chaos.")}
    assert set(chaos) == {"chaos.gap_1", "chaos.gap_2.4"} and min(chaos.values()) > CHAOS_THRESHOLD
    # docs/validation.md's table is this run's (the command regenerates it).
    with open(ROOT / "docs" / "validation" / "validation.csv", newline="") as fh:
        assert list(csv.DictReader(fh)) == rows
    for name in ("fig06_08_forces.png", "fig09_period1.png", "fig10_period_half.png", "fig11_bifurcation.png",
                 "fig12_peterka.png", "continuation_gap0.png"):
        assert (out / name).stat().st_size > 10_000, name
        assert f"]({name})" in (out / "validation.md").read_text()
    summary = read_json(out / "summary.json")
    assert summary["passed"] == 12 and summary["doubling_hz"] == pytest.approx(DOUBLING_HZ, abs=0.1)
    assert "12 of 12 findings reproduced" in stdout


@pytest.mark.process
def test_band_a_of_the_structural_preset_at_gap_0_is_its_1_1_resonance():
    """config/structural.yaml at gap 0 has a 3/3 motion at 9.5 Hz whose impacts average one per cycle and whose peak
    beats the 1/1 points'; band A is chosen by class, so it is the 1/1 resonance at 3.75 Hz."""
    config = load_config(find_config_file("structural.yaml"), {"gap": 0.0})
    result = sweep(config, [3.5, 3.75, 4.0, 9.25, 9.5], "rest", workers=2)
    at = {p.frequency_hz: p for p in result.points}
    assert (at[9.5].motion_class, at[9.5].impacts_per_cycle) == ("3/3", 1.0)
    assert at[9.5].peak_force_n > at[3.75].peak_force_n   # the strongest point with one impact per cycle
    assert result.band_a is not None and result.band_a.frequency_hz == 3.75 and result.band_a.motion_class == "1/1"


@pytest.mark.process
def test_rimd_fit_paper_returns_a_passing_set_and_its_trade_off(tmp_path):
    out = tmp_path / "fit"
    status, stdout, err = _run("fit-paper", "--max-evaluations", "3", "--workers", "2", "--out", str(out))
    assert status == 0, err
    summary = read_json(out / "summary.json")
    assert summary["evaluations"] == 3 and summary["parameters"] == ["damping_ratio", "amplitude", "natural_frequency"]
    assert summary["passed"] and summary["worst_residual"] <= 1.0
    fitted = load_config(out / "fitted.yaml")
    for name, value in summary["fitted"].items():
        assert fitted.to_parameters()[name] == pytest.approx(value, rel=1e-12), name
    with open(out / "evaluations.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 3
    assert (out / "pareto.png").stat().st_size > 10_000 and (out / "pareto.csv").exists()
    assert "every check passes" in stdout
    status, _, err = _run("fit-paper", "--parameters", "colour", "--out", str(tmp_path / "bad"))
    assert status == 1 and "--parameters 'colour' refused" in err.strip().splitlines()[-1]


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_presets_table_of_the_configuration_page_is_what_the_presets_do():
    """docs/configuration.md's presets table comes from docs/validation/presets.csv: a fresh run of the two other
    presets against the paper's findings gives their rows (scripts/validate_presets.py --check, in this process);
    the default's rows are the table `rimd paper` gives
    (test_rimd_paper_reproduces_every_finding_and_writes_the_documented_table)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("validate_presets", ROOT / "scripts" / "validate_presets.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        status = script.main(["--check", "--workers", "1", "--presets", "paper_model.yaml", "structural.yaml"])
    assert status == 0, err.getvalue()
    with open(ROOT / "docs" / "validation" / "presets.csv", newline="") as fh:
        default = [r for r in csv.DictReader(fh) if r["preset"] == "rimd.yaml"]
    with open(ROOT / "docs" / "validation" / "validation.csv", newline="") as fh:
        documented = list(csv.DictReader(fh))
    assert [(r["key"], r["twin"], r["passed"]) for r in default] == [
        (r["key"], r["twin"], r["passed"]) for r in documented]
