"""``rimd analyze`` on bad input, and the pure routines of ``rimd_sim.analysis.recorded`` on known signals."""

from __future__ import annotations

import math
import shutil
import subprocess

import numpy as np

from rimd_sim.analysis import recorded as rec


def _rimd(*args: str) -> subprocess.CompletedProcess[str]:
    executable = shutil.which("rimd")
    assert executable is not None, "rimd is not on PATH: source env.sh"
    return subprocess.run([executable, *args], capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)


def test_garbage_file_is_refused_in_one_line(tmp_path):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"this is not a recording\n" * 100)
    result = _rimd("analyze", str(garbage), "--out", str(tmp_path / "out"))
    assert result.returncode == 1
    assert result.stderr.strip().count("\n") == 0 and "Traceback" not in result.stderr
    assert result.stderr.startswith("rimd analyze: ") and "not an MCAP file" in result.stderr
    assert not (tmp_path / "out" / "summary.json").exists()


def test_missing_recording_is_refused_in_one_line(tmp_path):
    result = _rimd("analyze", str(tmp_path / "nothing"), "--out", str(tmp_path / "out"))
    assert result.returncode == 1 and result.stderr.strip() == f"rimd analyze: {tmp_path / 'nothing'} does not exist"


def _channel(values, rate=20000.0, first=0):
    index = np.arange(first, first + len(values))
    return rec.Channel("/rig/impact/force", rate, index, index / rate, np.asarray(values, dtype=float))


def test_detection_finds_each_run_above_threshold_and_its_largest_sample():
    values = np.zeros(2000)
    values[100:108] = [60, 55, 48, 40, 30, 20, 9, 1]     # a spring-dashpot-like pulse: largest at contact start
    values[900:905] = [1, 5, 12, 7, 1.5]                  # a smaller one, interior peak
    values[1500] = 1.9                                     # below the 2 N threshold: not an impact
    det = rec.detect_impacts(_channel(values))
    assert det["peak_force"].tolist() == [60.0, 12.0]
    assert det["peak_time"].tolist() == [100 / 20000.0, 902 / 20000.0]
    assert det["complete"].tolist() == [1.0, 1.0]
    # The crossing of the second pulse is interpolated between 1 N and 5 N: a quarter of a sample after 900.
    assert math.isclose(det["start"][1], 900.25 / 20000.0)


def test_cross_check_counts_matches_misses_and_extras():
    values = np.zeros(4000)
    values[100:105] = [50, 40, 30, 20, 10]
    values[2000:2003] = [8, 6, 3]
    force = _channel(values)
    det = rec.detect_impacts(force)
    events = {"time": np.array([100 / 20000.0, 3000 / 20000.0, 3500 / 20000.0, 9.0]),
              "duration": np.full(4, 3e-4), "peak_force": np.array([52.0, 40.0, 1.0, 30.0])}
    m = rec.match_impacts(det, events, force)
    assert m["event_match"].tolist() == [0, -1, -1, -1]
    assert (m["matches"], m["misses"], m["misses_below_threshold"], m["not_covered"], m["extras"]) == (1, 2, 1, 1, 1)
    assert math.isclose(m["peak_difference_max"], 2 / 52)


def test_steps_discard_ramp_and_settle_and_poincare_times_are_phase_zero():
    t = np.arange(0, 10, 0.01)
    setpoint = np.where(t < 4, 3.0, 3.5)
    freq = np.where(t < 4, 3.0, np.minimum(3.5, 3.0 + 2.0 * (t - 4)))   # 0.25 s ramp at 2 Hz/s
    phase_total = 2 * math.pi * np.cumsum(freq) * 0.01
    motor = {"time": t, "frequency_setpoint": setpoint, "frequency": freq,
             "phase": np.mod(phase_total, 2 * math.pi), "cycle_index": np.floor(phase_total / (2 * math.pi))}
    steps = rec.segment_steps(motor, settle=1.0)
    assert [(s.setpoint, s.start, s.ramp_end) for s in steps] == [(3.0, 0.0, 0.0), (3.5, 4.0, 4.25)]
    assert math.isclose(steps[1].steady_from, 5.25) and math.isclose(steps[1].end, t[-1])
    times = rec.poincare_times(motor)
    assert np.allclose(np.interp(times, t, phase_total) / (2 * math.pi), np.round(np.interp(times, t, phase_total)
                                                                                  / (2 * math.pi)), atol=1e-9)
    assert len(times) == int(phase_total[-1] / (2 * math.pi))
