"""``rimd fit-table`` on the paper's Table 1 (config/paper_table1.csv).

Hypothesis: starting from config/rimd.yaml (whose resonances already lie within the 0.25 Hz grid step of
Table 1), the fitted set keeps all six resonances within 0.25 Hz of the paper's and states the residual of each
entry, peak forces included (gap 0: 82.4 N and 120 N, paper section 2).
"""

from __future__ import annotations

import contextlib
import csv
import io

import numpy as np
import pytest

from harness.outputs import read_json
from rimd_sim.cli import main


def _run(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(["fit-table", *args])
    return status, out.getvalue(), err.getvalue()


def _residuals(rows: list[dict]) -> np.ndarray:
    """The misfit's residuals recomputed from the CSV: resonances in 0.25 Hz grid steps, peak forces in 5 %."""
    out = []
    for r in rows:
        out.append((float(r["twin_interpolated_hz"]) - float(r["frequency_hz"])) / 0.25)
        if r["peak_force_n"]:
            out.append((float(r["twin_peak_force_n"]) / float(r["peak_force_n"]) - 1.0) / 0.05)
    return np.array(out)


def test_fit_table_on_table_1(tmp_path):
    status, out, err = _run("--out", str(tmp_path), "--max-evaluations", "4")
    assert status == 0, err
    summary = read_json(tmp_path / "summary.json")
    assert summary["natural_frequency_from_table"] == 1.82
    assert summary["all_resonances_within_0.25_hz"]
    with open(tmp_path / "fit_table.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6
    for row in rows:
        assert abs(float(row["twin_grid_hz"]) - float(row["frequency_hz"])) <= 0.25 + 1e-9, row
    forces = {float(r["frequency_hz"]): r for r in rows if r["peak_force_n"]}
    assert sorted(forces) == [3.75, 7.25]
    # Each residual is the twin's peak minus the table's. The table's natural frequency (1.82 Hz) replaces the
    # defaults' identified 1.763 Hz, and 4 evaluations move the set little: the forces stay within 10 %.
    for f, table in {3.75: 82.4, 7.25: 120.0}.items():
        r = forces[f]
        assert float(r["peak_force_n"]) == table
        residual = float(r["peak_force_residual_n"])
        assert residual == pytest.approx(float(r["twin_grid_peak_force_n"]) - table, abs=1e-9), r
        assert abs(residual / table) <= 0.10, (f, residual)
    assert summary["misfit"] == pytest.approx(float(np.sum(_residuals(rows) ** 2)), rel=1e-9)
    # The residuals are those of the fitted set, which loads as a parameter file.
    from rimd_sim.settings.config import load_config
    fitted = load_config(tmp_path / "fitted.yaml")
    assert fitted.rig.damping_ratio == summary["fitted"]["damping_ratio"]
    assert "7.25" in out and "fitted:" in out


def test_fit_table_refuses_a_bad_table(tmp_path):
    table = tmp_path / "t.csv"
    table.write_text("gap_mm,band,frequency_hz\n0.0,C,3.75\n")
    status, _, err = _run(str(table), "--out", str(tmp_path / "o"))
    assert status == 1 and "band 'C' must be A, B or natural" in err.strip().splitlines()[-1]
