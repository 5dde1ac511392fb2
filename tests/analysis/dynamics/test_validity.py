"""The model's valid domain (rimd_sim.model.validity): every analysis point checked, marked, and said.

The researcher's points: natural frequency 11 Hz (l = 2.05 mm), motor.max_frequency raised to 30 Hz; at gap 1 mm,
22-23 Hz the pendulum spins over its pivot (|theta| grows to 1e5-1e6 rad) with MN contact forces and ~70 impacts
per cycle; at gap 0.5 mm, 21 Hz it swings to |theta| = 1.80-2.4 rad (past 90 deg) with ordinary forces; at gap
1 mm, 22-23 Hz with the Lyapunov run's tolerances (rtol 1e-10, atol 1e-12) the chattering guard fires. Few cycles
keep the runs short (they show the excursion within 20 cycles).
"""

from __future__ import annotations

import csv
import math

import pytest

from harness.outputs import read_json
from harness.presets import SINGLE_MASS_ARGS, SINGLE_MASS_SET
from rimd_sim import cli
from rimd_sim.analysis.dynamics.bifurcation import bifurcation
from rimd_sim.analysis.dynamics.sweep import sweep
from rimd_sim.model import validity
from rimd_sim.model.rig_model import ChatteringError, RigModel
from rimd_sim.settings.config import SimConfig, find_config_file, load_config

FN11 = """/**/rimd_simulator:
  ros__parameters:
    natural_frequency: 11.0
    motor:
      max_frequency: 30.0
"""


@pytest.fixture
def fn11(tmp_path):
    path = tmp_path / "fn11.yaml"
    path.write_text(FN11)
    return path


def _rows(path):
    return list(csv.DictReader(open(path)))


def test_the_domain_declares_each_rule_with_its_bound_unit_and_reason():
    config = SimConfig()
    dom = validity.domain(config)
    assert [r.name for r in dom.rules] == ["pendulum_angle", "contact_force", "chattering", "impacts_per_cycle"]
    assert dom.rule("pendulum_angle").bound == math.pi / 2 and dom.rule("pendulum_angle").unit == "rad"
    # The force bound is the force sensor's compression range, and follows it.
    assert dom.rule("contact_force").bound == 2224.0 and dom.rule("contact_force").unit == "N"
    moved = config.with_parameters({"channels.impact_force.range_max": 500.0})
    assert validity.domain(moved).rule("contact_force").bound == 500.0
    assert all(r.why for r in dom.rules)
    assert dom.check(validity.PointMeasures(0.1, 100.0, 1.0)).valid
    v = dom.check(validity.PointMeasures(1.6, 3000.0, 11.0))
    assert v.invalid_rule == "pendulum_angle;contact_force;impacts_per_cycle"
    assert dom.check(validity.PointMeasures(chattering=True)).rules == ("chattering",)
    assert validity.Verdict.of(v.invalid_rule) == v


def test_the_driver_tracks_the_largest_angle_of_each_call():
    cfg = SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
    model = RigModel(cfg, channels=False, truth=True)
    out = model.advance(4.0)
    truth_max = abs(out.truth[1][0]).max()  # sampled at 1 kHz: at most the step ends' largest, and close to it
    assert truth_max * 0.98 <= out.max_abs_theta <= truth_max * 1.02
    assert out.max_abs_theta < validity.MAX_ANGLE


def test_researchers_sweep_is_marked_and_the_verb_exits_3(fn11, tmp_path, capsys):
    out = tmp_path / "sweep"
    status = cli.main(["sweep", "--config", str(fn11), "--gap-mm", "1", "--f-min", "22", "--f-max", "23",
                       "--f-step", "1", "--cycles", "20", "--measure-cycles", "10", "--workers", "1",
                       "--out", str(out)])
    assert status == cli.EXIT_INVALID == 3
    rows = _rows(out / "sweep.csv")
    assert [r["valid"] for r in rows] == ["False", "False"]
    for r in rows:
        assert {"pendulum_angle", "contact_force", "impacts_per_cycle"} <= set(r["invalid_rule"].split(";"))
        assert float(r["peak_force_n"]) > 1e5    # still reported, but marked
    summary = read_json(out / "summary.json")
    assert summary["validity"]["invalid"] == 2 and summary["validity"]["by_rule"]["contact_force"] == 2
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("rimd sweep: 2 of 2 points outside the model's valid domain (")
    assert "contact_force > 2224 N: 2" in last and "invalid_rule column" in last
    assert (out / "sweep.png").read_bytes()[:4] == b"\x89PNG"


def test_accept_invalid_exits_0_and_keeps_the_marks(fn11, tmp_path, capsys):
    out = tmp_path / "sweep"
    status = cli.main(["sweep", "--config", str(fn11), "--gap-mm", "1", "--f-min", "22", "--f-max", "22",
                       "--cycles", "20", "--measure-cycles", "10", "--workers", "1", "--out", str(out),
                       "--accept-invalid"])
    assert status == 0
    assert _rows(out / "sweep.csv")[0]["valid"] == "False"
    assert "accepted: --accept-invalid" in capsys.readouterr().out.strip().splitlines()[-1]


def test_a_swing_past_90_degrees_is_marked_pendulum_angle_alone(fn11):
    config = load_config(fn11, {"gap": 0.5e-3})
    point = sweep(config, [21.0], "rest", cycles=20, measure_cycles=10, workers=1).points[0]
    assert point.max_abs_theta_rad > math.pi / 2 and point.max_force_n < 2224.0
    assert (point.valid, point.invalid_rule) == (False, "pendulum_angle")


def test_chattering_is_a_mark_not_a_crash_and_a_continued_sweep_goes_on_from_rest(fn11):
    config = load_config(fn11, {"gap": 1e-3, "integrator.rtol": 1e-10, "integrator.atol": 1e-12})
    with pytest.raises(ChatteringError):   # what stopped the analyses before
        RigModel(config.with_parameters({"motor.initial_frequency": 22.0, "motor.initial_setpoint": 22.0}),
                 channels=False, truth=False).advance(1.0)
    result = sweep(config, [22.0, 23.0], "up", cycles=20, measure_cycles=10)
    assert [p.invalid_rule for p in result.points] == ["chattering", "chattering"]
    assert all(math.isnan(p.peak_force_n) for p in result.points)
    assert result.restarts == (23.0,) and result.band_a is None
    assert result.summary()["validity"]["by_rule"] == {"chattering": 2}


def test_poincare_marks_a_chattering_lyapunov_run(fn11, tmp_path, capsys):
    out = tmp_path / "po"
    status = cli.main(["poincare", "--config", str(fn11), "--gap-mm", "1", "--frequency", "23",
                       "--transient-cycles", "20", "--cycles", "12", "--out", str(out)])
    assert status == 3
    summary = read_json(out / "summary.json")
    assert summary["valid"] is False and "chattering" in summary["invalid_rule"].split(";")
    assert summary["lyapunov_exponent_per_s"] is None
    assert "chattering" in capsys.readouterr().out.strip().splitlines()[-1]


def test_bifurcation_marks_its_points(fn11):
    config = load_config(fn11, {"gap": 1e-3})
    (branch,), _, _ = bifurcation(config, [22.0], "up", transient_cycles=5, sample_cycles=6, workers=1)
    point = branch.points[0]
    assert not point.valid and "pendulum_angle" in point.invalid_rule.split(";")
    assert branch.verdicts[0].rules == tuple(point.invalid_rule.split(";"))


def test_a_paper_point_is_valid_and_its_outputs_unchanged(tmp_path, capsys):
    """config/paper_model.yaml, gap 0, 4 Hz: the validity checks leave the result alone (the peak force, 170.19 N,
    pinned bit for bit), the point is valid, and the verb exits 0 with no validity line."""
    config = load_config(find_config_file("paper_model.yaml"))
    point = sweep(config, [4.0], "rest", cycles=40, measure_cycles=10, workers=1).points[0]
    assert point.peak_force_n.hex() == "0x1.545fde93befb8p+7"
    assert (point.impacts_per_cycle, point.simulated_seconds) == (1.0, 10.0)
    assert point.valid and point.invalid_rule == ""
    out = tmp_path / "sweep"
    status = cli.main(["sweep", "--config", str(find_config_file("paper_model.yaml")), "--f-min", "4",
                       "--f-max", "4", "--cycles", "40", "--measure-cycles", "10", "--workers", "1",
                       "--out", str(out)])
    assert status == 0
    assert _rows(out / "sweep.csv")[0]["valid"] == "True"
    assert "valid domain" not in capsys.readouterr().out
    assert read_json(out / "summary.json")["validity"]["invalid"] == 0


# ---- the maps (rimd peterka, rimd basins): each cell checked by the compiled ensemble's measures ----------------


def test_researchers_peterka_cells_are_marked_and_the_verb_exits_3(fn11, tmp_path, capsys):
    out = tmp_path / "pk"
    argv = ["peterka", "--config", str(fn11), "--gap-min-mm", "1", "--gap-max-mm", "1", "--gaps", "1",
            "--f-min", "22", "--f-max", "23", "--freqs", "2", "--transient-cycles", "20", "--measure-cycles", "12",
            "--workers", "1", "--out", str(out)]
    assert cli.main(argv) == cli.EXIT_INVALID
    rows = _rows(out / "peterka.csv")
    assert [r["valid"] for r in rows] == ["False", "False"]
    for r in rows:
        assert {"pendulum_angle", "contact_force", "impacts_per_cycle"} <= set(r["invalid_rule"].split(";"))
        assert float(r["max_force_n"]) > 1e5 and float(r["max_abs_theta_rad"]) > math.pi / 2
        assert r["class_rest"]    # still classified, but marked
    summary = read_json(out / "summary.json")
    assert summary["validity"]["points"] == 2 and summary["validity"]["by_rule"]["contact_force"] == 2
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("rimd peterka: 2 of 2 cells outside the model's valid domain (")
    assert "invalid_rule column" in last
    assert (out / "peterka.png").read_bytes()[:4] == b"\x89PNG"
    assert cli.main([*argv, "--accept-invalid"]) == 0
    assert "accepted: --accept-invalid" in capsys.readouterr().out.strip().splitlines()[-1]


def test_a_map_cell_swinging_past_90_degrees_is_marked_pendulum_angle_alone(fn11):
    """Gap 0.5 mm, 21 Hz from rest: the ensemble sees the swing past 90 deg the sweep sees (same trajectory)."""
    from rimd_sim.analysis.dynamics.peterka import peterka

    result = peterka(load_config(fn11), [0.5e-3], [21.0], transient_cycles=20, measure_cycles=12, workers=1)
    assert result.invalid_rules[0, 0, 0] == "pendulum_angle"
    assert result.max_abs_theta[0, 0, 0] > math.pi / 2 and result.max_force[0, 0, 0] < 2224.0


def test_the_ensemble_reports_chattering_as_its_own_status():
    """A cell the chattering guard stops is KIND_FAILED with status ST_ZENO, and its verdict is chattering."""
    import numpy as np

    import rimd_sim.model.kernel as k
    from rimd_sim.model.ensemble import KIND_FAILED, StopRule, run_cells
    from rimd_sim.model.rig_model import model_for

    config = load_config(find_config_file("rimd.yaml"), {"natural_frequency": 11.0, "motor.max_frequency": 30.0,
                                                          "gap": 1e-3, "integrator.rtol": 1e-10,
                                                          "integrator.atol": 1e-12})
    model = model_for(config)
    res = run_cells(model.name, model.params(config)[None, :], np.zeros(1, dtype=np.int64), np.array([22.0]),
                    np.zeros(1), np.zeros(1), StopRule(max_cycles=20, measure_cycles=10, min_cycles=20))
    assert res.kind[0] == KIND_FAILED and res.status[0] == k.ST_ZENO
    assert validity.domain(config).check(res.measures()[0]).rules == ("chattering",)


def test_researchers_basins_are_marked_and_the_verb_exits_3(fn11, tmp_path, capsys):
    out = tmp_path / "bs"
    status = cli.main(["basins", "--config", str(fn11), "--gap-mm", "1", "--frequency", "22", "--size", "2",
                       "--theta-min", "-0.2", "--theta-max", "0.0", "--theta-dot-min", "-1", "--theta-dot-max", "1",
                       "--transient-cycles", "20", "--measure-cycles", "12", "--workers", "1", "--out", str(out)])
    assert status == 3
    rows = _rows(out / "basins.csv")
    assert rows and all(r["valid"] == "False" and "pendulum_angle" in r["invalid_rule"] for r in rows)
    assert read_json(out / "summary.json")["validity"]["invalid"] == len(rows)
    assert "initial conditions outside the model's valid domain" in capsys.readouterr().out.strip().splitlines()[-1]


def test_paper_map_cells_are_valid_and_their_classes_unchanged(tmp_path, capsys):
    """The single-mass set's map at gap 0 and 2.4 mm: every cell valid, the verb exits 0 with no validity line,
    and the validity checks leave the classes and cycles alone (pinned, with the ``window`` stop rule and its
    common cap from rest)."""
    from rimd_sim.analysis.dynamics.peterka import peterka

    result = peterka(SimConfig().with_parameters(SINGLE_MASS_SET), [0.0, 2.4e-3], [3.0, 5.5, 8.0], transient_cycles=30,
                     measure_cycles=24,
                     stop="window", rest_cycles=54, workers=1)   # the common cap from rest of the pinned map
    assert result.labels.tolist() == [[["1/1", "3/2", "1/2"], ["no impact", "no impact", "1/3"]],
                                      [["1/1", "3/2", "1/2"], ["no impact", "no impact", "1/3"]],
                                      [["1/1", "3/2", "1/2"], ["no impact", "no impact", "no impact"]]]
    assert result.cycles.tolist() == [[[31, 30, 39], [55, 55, 54]], [[31, 30, 42], [55, 55, 55]],
                                      [[31, 30, 39], [60, 81, 85]]]
    assert result.valid.all() and result.validity["invalid"] == 0 and result.validity["points"] == 6
    out = tmp_path / "pk"
    status = cli.main(["peterka", "--gap-min-mm", "0", "--gap-max-mm", "2.4", "--gaps", "2", "--f-min", "3",
                       "--f-max", "8", "--freqs", "3", "--transient-cycles", "30", "--measure-cycles", "24",
                       "--workers", "1", "--out", str(out), *SINGLE_MASS_ARGS])
    assert status == 0
    assert {r["valid"] for r in _rows(out / "peterka.csv")} == {"True"}
    assert "valid domain" not in capsys.readouterr().out


def test_a_pulse_past_the_sensors_range_is_marked_and_exits_3(tmp_path, capsys):
    out = tmp_path / "pulse"
    assert cli.main(["pulse", "--velocity", "3", "--rate", "1e5", "--out", str(out)]) == 3
    summary = read_json(out / "summary.json")
    assert (summary["valid"], summary["invalid_rule"]) == (False, "contact_force")
    assert summary["max_force_n"] > 2224.0 and summary["validity"]["invalid"] == 1
    assert "contact_force > 2224 N: 1" in capsys.readouterr().out.strip().splitlines()[-1]
    assert cli.main(["pulse", "--velocity", "3", "--rate", "1e5", "--out", str(out), "--accept-invalid"]) == 0
    assert cli.main(["pulse", "--velocity", "0.07", "--rate", "1e5", "--out", str(out)]) == 0
    assert read_json(out / "summary.json")["valid"] is True


def test_fit_table_marks_and_counts_its_invalid_rows(fn11, tmp_path, capsys, monkeypatch):
    """An entry at gap 1 mm, band B, 22 Hz: its grid points (21.5-23 Hz) leave the domain; none is taken as the
    band's resonance, the row is marked and counted, and the verb exits 3."""
    from rimd_sim.analysis.dynamics.fit_table import TableEntry, evaluate

    config = load_config(fn11)
    (row,) = evaluate(config, [TableEntry(1.0, "B", 22.0, None)], cycles=20, measure=10)
    assert row["valid"] is False and "pendulum_angle" in row["invalid_rule"].split(";")
    table = tmp_path / "table.csv"
    table.write_text("gap_mm,band,frequency_hz\n1.0,B,22.0\n,natural,11.0\n")
    out = tmp_path / "fit"
    import rimd_sim.analysis.dynamics.fit_table as ft

    monkeypatch.setattr(ft, "evaluate", lambda cfg, entries, cycles, measure: evaluate(cfg, entries, 20, 10))
    status = cli.main(["fit-table", str(table), "--config", str(fn11), "--max-evaluations", "1", "--out", str(out)])
    assert status == 3
    assert _rows(out / "fit_table.csv")[0]["valid"] == "False"
    summary = read_json(out / "summary.json")
    assert summary["validity"]["invalid"] == 1 and summary["invalid_sets"] == 1
    assert "1 of 1 entries outside the model's valid domain" in capsys.readouterr().out.strip().splitlines()[-1]


def test_rule_names_are_the_domains_order_and_fields_join_in_it():
    config = load_config(find_config_file("rimd.yaml"))
    assert validity.RULE_NAMES == tuple(r.name for r in validity.domain(config).rules)
    assert validity.joined(["impacts_per_cycle", "pendulum_angle", "pendulum_angle"]) == \
        "pendulum_angle;impacts_per_cycle"
    assert validity.joined([]) == ""
