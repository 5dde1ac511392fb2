"""``rimd bifurcation``, ``rimd poincare``, ``rimd peterka`` and ``rimd basins``: files, figures, refusals.

Small grids and few cycles keep these fast; the full sizes run in benchmarks/bench_analysis.py.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest

from harness.outputs import read_json
from harness.presets import SINGLE_MASS_ARGS
from rimd_sim import cli

PNG = b"\x89PNG\r\n\x1a\n"


def _files(out, *names):
    for name in names:
        assert (out / name).is_file(), name
    assert (out / names[0]).read_bytes()[:8] == PNG
    return read_json(out / "summary.json")


def _reference_class(frequency: float) -> str:
    """The class of the default rig's motion at gap 0 from the independent integrator (tests/harness/reference.py,
    scipy's DOP853 written from the paper's equations): impacts per cycle and distinct peak levels over 24 cycles
    after 60 from rest."""
    import numpy as np

    from harness.reference import simulate

    impacts = simulate(frequency=frequency, gap=0.0, duration=84 / frequency)
    last = [i for i in impacts if i.t_start >= 60 / frequency]
    levels = len({round(i.peak_force, 0) for i in last})
    per_cycle = len(last) / 24
    return f"{round(per_cycle * levels)}/{levels}" if per_cycle and np.isclose(per_cycle, 1.0) else "other"


@pytest.mark.process
def test_bifurcation_gap0_shows_the_doubling_window_up_and_down(tmp_path, capsys):
    """Default preset, gap 0: 1/1 at 4.7 Hz and the period-doubled 2/2 motion (alternating peaks) at 4.9 Hz in both
    sweeps, as the independent reference integrator finds from rest (the multiplier crosses -1 at 4.805 Hz)."""
    low, high = _reference_class(4.7), _reference_class(4.9)    # where the expected classes come from
    assert (low, high) == ("1/1", "2/2")
    out = tmp_path / "bif"
    status = cli.main(["bifurcation", "--f-min", "4.7", "--f-max", "4.9", "--f-step", "0.1",
                       "--transient-cycles", "60", "--sample-cycles", "24", "--out", str(out)])
    assert status == 0
    summary = _files(out, "bifurcation.png", "bifurcation.csv", "summary.json")
    for direction in ("up", "down"):
        runs = summary["branches"][direction]
        assert [(r["class"], r["f_from_hz"]) for r in runs][0] == (low, 4.7)
        assert runs[-1]["class"] == high and runs[-1]["f_to_hz"] == 4.9
    rows = list(csv.DictReader(open(out / "bifurcation.csv")))
    at_high = {round(float(r["displacement_ratio"]), 2) for r in rows
               if r["direction"] == "up" and r["frequency_hz"] == "4.9"}
    assert len(at_high) == 2  # two stroboscopic values: period 2
    assert "2/2 (period doubling) at" in capsys.readouterr().out


def test_poincare_reproduces_fig10_period_half(tmp_path):
    """Paper Fig. 10: gap 2.4 mm, Omega/omega_n = 2.7, a period-0.5 motion (one impact every two cycles): two
    Poincare points, class 1/2, negative largest exponent."""
    out = tmp_path / "p"
    assert cli.main(["poincare", "--gap-mm", "2.4", "--ratio", "2.7", "--transient-cycles", "100",
                     "--cycles", "40", "--out", str(out)]) == 0
    summary = _files(out, "poincare.png", "poincare.csv", "trajectory.csv", "summary.json")
    assert summary["class"] == "1/2" and summary["impacts_per_cycle"] == 0.5
    assert summary["lyapunov_exponent_per_s"] < 0 and summary["chaotic"] is False
    assert len(list(csv.DictReader(open(out / "poincare.csv")))) == 40


def test_peterka_small_map_has_period_1_and_half_and_marks_coexistence(tmp_path):
    """A 2 x 3 map of the single-mass set (harness.presets): at gap 0 the 3.75 Hz cell is 1/1 (band A) and 6.75 Hz 1/2
    (band B region); at gap 2.4 mm and 5.25 Hz rest reaches 1/2 while the upward continuation stays without impact
    (the coexisting attractors of the paper's Fig. 12), so that cell is marked."""
    out = tmp_path / "pk"
    assert cli.main(["peterka", "--gap-min-mm", "0", "--gap-max-mm", "2.4", "--gaps", "2", "--f-min", "3.75",
                     "--f-max", "6.75", "--freqs", "3", "--transient-cycles", "60", "--measure-cycles", "24",
                     "--workers", "1", "--out", str(out), *SINGLE_MASS_ARGS]) == 0
    summary = _files(out, "peterka.png", "peterka.csv", "summary.json")
    cells = {(float(r["gap_mm"]), float(r["frequency_hz"])): r for r in csv.DictReader(open(out / "peterka.csv"))}
    assert cells[(0.0, 3.75)]["class_rest"] == "1/1"
    assert cells[(0.0, 6.75)]["class_rest"] == "1/2"
    assert cells[(2.4, 5.25)]["class_rest"] == "1/2"
    assert cells[(2.4, 5.25)]["class_continued"] == "no impact"
    assert cells[(2.4, 5.25)]["coexisting"] == "True"
    assert cells[(2.4, 5.25)]["classes_found"] == "1/2;no impact" and cells[(2.4, 5.25)]["starts"] == "4"
    assert summary["coexisting_cells"] >= 1
    assert summary["coexistence"]["lower_bound"] is True and summary["coexistence"]["starts_per_cell"] == 4
    data = np.load(out / "peterka.npz")
    assert data["starts"].tolist() == ["rest", "kick", "continued", "free"] and data["codes"].shape == (4, 2, 3)
    assert data["valid"].shape == (2, 3) and data["valid"].all() and (data["invalid_rule"] == "").all()


def test_peterka_starts_option_adds_halton_starts_and_0_is_the_three_start_map(tmp_path):
    """``--starts 0`` writes the three named starts only; ``--starts 5`` the forced response and 4 Halton
    points, and the named starts' classes are the same."""
    argv = ["peterka", "--gap-min-mm", "2.4", "--gap-max-mm", "2.4", "--gaps", "1", "--f-min", "2.45",
            "--f-max", "2.548", "--freqs", "2", "--workers", "1"]
    assert cli.main([*argv, "--starts", "0", "--out", str(tmp_path / "a")]) == 0
    assert cli.main([*argv, "--starts", "5", "--out", str(tmp_path / "b")]) == 0
    a = list(csv.DictReader(open(tmp_path / "a" / "peterka.csv")))
    b = list(csv.DictReader(open(tmp_path / "b" / "peterka.csv")))
    assert [r["starts"] for r in a] == ["3", "3"] and [r["starts"] for r in b] == ["8", "8"]
    assert [r["class_rest"] for r in a] == [r["class_rest"] for r in b]
    assert a[1]["classes_found"] == "1/1" and b[1]["classes_found"] == "1/1;no impact"
    starts = np.load(tmp_path / "b" / "peterka.npz")["starts"].tolist()
    assert starts[3:] == ["free", *(f"halton{i}" for i in range(1, 5))]


def test_basins_at_gap_2_4mm_hold_two_attractors(tmp_path):
    """Gap 2.4 mm, 4.0 Hz: some initial conditions end on the 1/2 impact motion, others on the motion without
    impact (coexisting attractors)."""
    out = tmp_path / "b"
    assert cli.main(["basins", "--size", "5", "--transient-cycles", "60", "--measure-cycles", "24",
                     "--workers", "1", "--out", str(out)]) == 0
    summary = _files(out, "basins.png", "basins.csv", "summary.json")
    assert {"1/2", "no impact"} <= set(summary["classes"]) and summary["coexisting_attractors"] is True


def test_basins_give_each_initial_condition_its_attractor(tmp_path, capsys):
    """Gap 2.4 mm, 2.548 Hz (the single-mass set, harness.presets): two attractors, the 1/1 impact motion and the
    motion without impact (33 of 576 initial conditions); each initial condition's attractor id in basins.csv, the
    attractors listed in summary.json with a stroboscopic point and the peak force, their points drawn on the
    plot."""
    out = tmp_path / "b"
    assert cli.main(["basins", "--frequency", "2.548", "--size", "24", "--workers", "1", "--out", str(out),
                     *SINGLE_MASS_ARGS]) == 0
    summary = _files(out, "basins.png", "basins.csv", "summary.json")
    rows = list(csv.DictReader(open(out / "basins.csv")))
    attractors = {a["id"]: a for a in summary["attractors"]}
    assert sorted(a["class"] for a in attractors.values()) == ["1/1", "no impact"]
    for r in rows:   # one id per class here, and every initial condition has the id of its class
        assert attractors[int(r["attractor_id"])]["class"] == r["class"]
    by_class = {a["class"]: a for a in attractors.values()}
    assert by_class["no impact"]["cells"] == 33 and by_class["1/1"]["cells"] == 543
    assert by_class["1/1"]["settled"] and by_class["1/1"]["period"] == 1
    assert by_class["1/1"]["peak_force_n"] > 10 and by_class["no impact"]["peak_force_n"] == 0.0
    assert by_class["1/1"]["theta_rad"] < 0 and abs(by_class["1/1"]["u"] + 3.87) < 0.01
    assert "2 attractor(s)" in capsys.readouterr().out


@pytest.mark.parametrize(("argv", "message"), [
    (["bifurcation", "--f-min", "5", "--f-max", "3"], "--f-min 5 > --f-max 3"),
    (["bifurcation", "--direction", "sideways"], "--direction 'sideways' refused"),
    (["poincare", "--frequency", "30"], "--frequency 30 refused: above motor.max_frequency"),
    (["poincare", "--ratio", "20"], "--frequency 35.26 refused: above motor.max_frequency"),
    (["peterka", "--f-min", "8", "--f-max", "2"], "--f-min 8 > --f-max 2"),
    (["peterka", "--rest-cycles", "100"], "--rest-cycles 100 refused: must be at least the cap of the other starts, "
                                          "--transient-cycles + --measure-cycles = 192"),
    (["basins", "--theta-min", "0.1", "--theta-max", "0.0"], "theta_range"),
])
def test_bad_input_gives_one_line_and_exit_1(tmp_path, capsys, argv, message):
    status = cli.main([*argv, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert status == 1
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize(("argv", "message"), [
    (["bifurcation", "--gap-mm", "-1"], "--gap-mm -1 refused: must be >= 0 and <= 50 mm"),
    (["poincare", "--frequency", "-2"], "--frequency -2 refused: must be > 0 Hz"),
    (["peterka", "--gap-min-mm", "-0.5"], "--gap-min-mm -0.5 refused: must be >= 0 and <= 50 mm"),
    (["basins", "--size", "1"], "--size 1 refused: must be >= 2"),
    (["sweep", "--workers", "0"], "--workers 0 refused: must be >= 1"),
])
def test_a_bad_number_is_a_usage_error_naming_the_option_in_its_unit(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit) as usage:
        cli.main([*argv, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert usage.value.code == 2 and message in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_json_outputs_are_strict_json(tmp_path):
    """Every summary, report and schedule goes through write_json: NaN and infinities (a capture with no
    sample, a step with no impact) become null, NumPy values plain numbers, and the file parses in a strict
    reader (harness.outputs.read_json refuses the bare tokens NaN and Infinity that Python's json writes)."""
    import math

    import numpy as np

    from rimd_sim.cli.verbs._analysis_io import write_json, write_summary

    data = {"nan": math.nan, "pair": (np.float64(np.inf), np.int64(3)), "array": np.array([1.5, np.nan]),
            "minus_inf": -math.inf, "nested": {"x": [np.float32(0.5), None, "text", True]}}
    expected = {"nan": None, "pair": [None, 3], "array": [1.5, None], "minus_inf": None,
                "nested": {"x": [0.5, None, "text", True]}}
    write_summary(tmp_path, data)
    assert read_json(tmp_path / "summary.json") == expected
    write_json(tmp_path / "report.json", data)
    assert read_json(tmp_path / "report.json") == expected
    (tmp_path / "python.json").write_text('{"a": NaN}')
    with pytest.raises(ValueError, match="NaN"):
        read_json(tmp_path / "python.json")


def _finite_where_impacting(rows):
    """Every row has a finite peak force and impact velocity, positive together (an impact) or both 0."""
    assert rows
    for r in rows:
        force, velocity = float(r["peak_force_n"]), float(r["impact_velocity_m_s"])
        assert np.isfinite(force) and np.isfinite(velocity), r
        assert (force > 0) == (velocity > 0), r
    return [r for r in rows if float(r["peak_force_n"]) > 0]


def test_map_writes_its_files_with_force_and_impact_velocity(tmp_path, capsys):
    """``rimd map`` over (natural_frequency, mass) at 3.75 Hz: map.csv with the parameters as columns and the
    figures of every cell, map.npz, map.png, summary.json with the axes and their units."""
    out = tmp_path / "m"
    assert cli.main(["map", "--x", "natural_frequency", "--x-values", "1.7,2.0", "--y", "mass", "--y-range", "0.1",
                     "0.2", "2", "--frequency", "3.75", "--workers", "1", "--out", str(out)]) == 0
    summary = _files(out, "map.png", "map.csv", "summary.json")
    rows = list(csv.DictReader(open(out / "map.csv")))
    assert list(rows[0])[:9] == ["natural_frequency", "mass", "frequency_hz", "frequency_ratio", "class",
                                 "peak_force_n", "force_ratio", "impact_velocity_m_s", "impacts_per_cycle"]
    assert [(float(r["natural_frequency"]), float(r["mass"])) for r in rows] == [(1.7, 0.1), (2.0, 0.1), (1.7, 0.2),
                                                                                (2.0, 0.2)]
    assert len(_finite_where_impacting(rows)) == 4 and all(r["valid"] == "True" for r in rows)
    assert summary["x"]["unit"] == "Hz" and summary["y"] == {"name": "mass", "unit": "kg", "values": [0.1, 0.2]}
    assert summary["frequency_hz"] == 3.75 and summary["cells"] == 4
    data = np.load(out / "map.npz")
    assert data["peak_force_n"].shape == (2, 2) and str(data["x_name"]) == "natural_frequency"
    assert "4 cells" in capsys.readouterr().out


@pytest.mark.parametrize(("argv", "message"), [
    (["--x", "natural_frequency", "--x-values", "1.82,-1"], "parameter 'natural_frequency' = -1.0 refused: must be >"),
    (["--x", "stiffness", "--x-values", "1"], "unknown parameter (known: frequency, gap, mass,"),
    (["--x", "natural_frequency", "--x-range", "1", "2", "two"], "--x-range 1 2 two refused"),
])
def test_map_refuses_a_bad_axis_in_one_line(tmp_path, capsys, argv, message):
    status = cli.main(["map", *argv, "--y", "mass", "--y-values", "0.15", "--frequency", "4",
                       "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert status == 1 and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_every_analysis_csv_has_the_peak_force_and_impact_velocity(tmp_path):
    """The columns appended to sweep.csv (with motion_class), peterka.csv, basins.csv and bifurcation.csv, on
    tiny grids: finite, and positive where the motion impacts."""
    def rows(verb, *argv):
        out = tmp_path / verb
        assert cli.main([verb, *argv, "--out", str(out)]) == 0
        return list(csv.DictReader(open(out / f"{verb}.csv")))

    sweep = rows("sweep", "--f-min", "3.75", "--f-max", "4.0", "--cycles", "60", "--measure-cycles", "20",
                 "--workers", "1")
    assert [r["motion_class"] for r in sweep] == ["1/1", "1/1"] and len(_finite_where_impacting(sweep)) == 2
    peterka = rows("peterka", "--gap-min-mm", "2.4", "--gap-max-mm", "2.4", "--gaps", "1", "--f-min", "3.75",
                   "--f-max", "5.25", "--freqs", "2", "--starts", "0", "--workers", "1")
    assert len(_finite_where_impacting(peterka)) >= 1
    basins = rows("basins", "--size", "3", "--transient-cycles", "60", "--measure-cycles", "24", "--workers", "1")
    run = [r for r in basins if r["class"] != "inside the stop"]
    assert len(_finite_where_impacting(run)) >= 1
    assert all(r["peak_force_n"] == "nan" for r in basins if r["class"] == "inside the stop")
    bifurcation = rows("bifurcation", "--direction", "up", "--f-min", "3.75", "--f-max", "3.85", "--f-step", "0.1",
                       "--transient-cycles", "30", "--sample-cycles", "12")
    assert len(_finite_where_impacting(bifurcation)) == len(bifurcation) == 24


def test_the_gap_is_the_configurations_unless_given_and_a_paper_default_says_so(tmp_path, capsys):
    """``--config`` with a gap: sweep uses it; ``--gap-mm`` replaces it; basins keeps 2.4 mm and says so."""
    from rimd_sim.settings.config import find_config_file

    yaml = tmp_path / "design.yaml"
    yaml.write_text(find_config_file().read_text().replace("    gap: 0.0 ", "    gap: 0.0005 ", 1))
    assert cli.main(["sweep", "--config", str(yaml), "--f-min", "3", "--f-max", "3", "--cycles", "30",
                     "--measure-cycles", "10", "--workers", "1", "--out", str(tmp_path / "a")]) == 0
    assert read_json(tmp_path / "a" / "summary.json")["gap_mm"] == pytest.approx(0.5)
    assert cli.main(["sweep", "--config", str(yaml), "--gap-mm", "1", "--f-min", "3", "--f-max", "3", "--cycles",
                     "30", "--measure-cycles", "10", "--workers", "1", "--out", str(tmp_path / "b")]) == 0
    assert read_json(tmp_path / "b" / "summary.json")["gap_mm"] == pytest.approx(1.0)
    capsys.readouterr()
    assert cli.main(["basins", "--config", str(yaml), "--frequency", "4", "--size", "2", "--transient-cycles",
                     "30", "--measure-cycles", "12", "--workers", "1", "--out", str(tmp_path / "c")]) == 0
    assert "gap 2.4 mm, this verb's default, instead of the configuration's 0.5 mm" in capsys.readouterr().err
    assert read_json(tmp_path / "c" / "summary.json")["gap_mm"] == pytest.approx(2.4)


def test_a_short_pendulums_default_basin_region_is_one_basins_accepts():
    from rimd_sim.analysis.dynamics.basins import MAX_BASIN_ANGLE, default_basin_ranges
    from rimd_sim.settings.config import load_config

    short = load_config(None, {"natural_frequency": 10.5, "gap": 0.25e-3})   # l = 2.25 mm, 3 A0 / l > 1.5
    (lo, hi), (rlo, rhi) = default_basin_ranges(short)
    assert lo == -MAX_BASIN_ANGLE and hi > 0 and rhi == pytest.approx(MAX_BASIN_ANGLE * short.rig.omega_n)


def test_set_reaches_the_model_and_every_analysis_verb_takes_it(tmp_path):
    """``--set natural_frequency=...`` changes the model a sweep runs: the pendulum's resonance without impact moves
    with it (gap 2.4 mm, small amplitude: the sweep's largest response sits at the natural frequency set), and the
    written summary's frequency ratio is the new one. Every analysis verb offers the option."""
    import json

    outs = {}
    for f_n in ("1.6", "2.0"):
        out = tmp_path / f_n
        assert cli.main(["sweep", "--gap-mm", "20", "--f-min", "1.5", "--f-max", "2.1", "--f-step", "0.1",
                         "--set", f"natural_frequency={f_n}", "--set", "amplitude=1e-4",
                         "--set", "damping_ratio=0.05", "--workers", "1", "--out", str(out)]) == 0
        rows = list(csv.DictReader(open(out / "sweep.csv")))
        outs[f_n] = {float(r["frequency_hz"]): float(r["frequency_ratio"]) for r in rows}
    assert outs["1.6"][1.6] == pytest.approx(1.0) and outs["2.0"][2.0] == pytest.approx(1.0)
    summary = json.loads((tmp_path / "2.0" / "summary.json").read_text())
    assert summary["gap_mm"] == 20
    for verb in ("sweep", "bifurcation", "continue", "peterka", "map", "poincare", "basins", "pulse", "paper",
                 "fit-paper", "fit-table"):
        status = cli.main([verb, "--set", "no_such_parameter=1", "--out", str(tmp_path / "x" / verb),
                           *(["--velocity", "1"] if verb == "pulse" else []),
                           *(["--x", "mass", "--x-values", "0.1", "--y", "gap", "--y-values", "0"] if verb == "map"
                             else [])])
        assert status == 1, verb
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(("setting", "message"), [
    ("natural_frequency=-1", "parameter 'natural_frequency' = -1.0 refused: must be > 0"),
    ("natural_frequncy=1.8", "unknown parameter; did you mean natural_frequency"),
    ("contact.model=rubber", "parameter 'contact.model' = 'rubber' refused: must be one of"),
])
def test_set_refuses_a_bad_name_or_value_in_one_line(tmp_path, capsys, setting, message):
    status = cli.main(["sweep", "--set", setting, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert status == 1 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "o").exists()


def test_set_without_a_value_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as usage:
        cli.main(["sweep", "--set", "mass", "--out", str(tmp_path / "o")])
    assert usage.value.code == 2
    assert "--set 'mass' refused: must be NAME=VALUE" in capsys.readouterr().err
