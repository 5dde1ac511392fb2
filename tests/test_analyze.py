"""``rimd analyze`` on bad input, and the pure routines of ``rimd_sim.analysis.recorded`` on known signals."""

from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from rimd_sim.analysis import recorded as rec


def _rimd(*args: str) -> subprocess.CompletedProcess[str]:
    executable = shutil.which("rimd")
    assert executable is not None, "rimd is not on PATH: source env.sh"
    return subprocess.run([executable, *args], capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)


@pytest.mark.process
def test_garbage_file_is_refused_in_one_line(tmp_path):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"this is not a recording\n" * 100)
    result = _rimd("analyze", str(garbage), "--out", str(tmp_path / "out"))
    assert result.returncode == 1
    assert result.stderr.strip().count("\n") == 0 and "Traceback" not in result.stderr
    assert result.stderr.startswith("rimd analyze: ") and "not an MCAP file" in result.stderr
    assert not (tmp_path / "out" / "summary.json").exists()


@pytest.mark.process
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


def test_onset_fit_recovers_the_spring_dashpot_peak_at_every_sampling_phase():
    import math

    import numpy as np

    from rimd_sim.analysis.recorded import PulseModel, pulse_model

    model = pulse_model({"rimd_rig_parameters": {"contact.model": "spring_dashpot", "mass": "0.15",
                                                 "contact.stiffness": "5.5e6", "contact.damping": "1200.0"}})
    assert model == PulseModel(0.15, 5.5e6, 1200.0)
    assert pulse_model({"rimd_rig_parameters": {"contact.model": "hertz"}}) is None
    assert pulse_model({}) is None
    peak = 1200.0 * 0.066                       # F(0+) = c v0
    amplitude = peak / math.cos(model.phi)
    rng = np.random.default_rng(1)
    dt = 5e-5
    worst_fit, worst_raw = 0.0, 0.0
    for offset in np.linspace(0.0, dt, 40, endpoint=False):
        t = offset + dt * np.arange(20)
        f = amplitude * np.exp(-model.sigma * t) * np.cos(model.omega_d * t - model.phi)
        run = np.flatnonzero(f >= 2.0)
        run = run[: np.argmax(np.diff(np.r_[run, 10**6]) != 1) + 1]    # the first run above threshold
        estimate = model.peak(t[run], f[run] + rng.normal(0.0, 0.01, run.size), dt)
        worst_fit = max(worst_fit, abs(estimate / peak - 1))
        worst_raw = max(worst_raw, 1 - f[run].max() / peak)
    assert worst_fit < 0.002          # the fit: within 0.2 % with the sensor's noise
    assert worst_raw > 0.15           # the largest sample: up to ~18 % low (what the fit removes)


def test_settled_tells_a_steady_window_from_one_still_in_its_transient():
    f = 4.0
    steady = np.arange(0.0, 8.0, 1 / f) + 0.01          # one impact per cycle over 8 s
    assert rec.settled(steady, np.full(steady.size, 76.0), 0.0, 8.0, f) is True
    # Period 2 (one impact every two cycles, alternating magnitudes): still steady.
    period2 = steady[::2]
    assert rec.settled(period2, np.where(np.arange(period2.size) % 2, 60.0, 80.0), 0.0, 8.0, f) is True
    # The 4.0 Hz step of issue 16: no impact for the first 1.7 s of the window, then one per cycle.
    late = steady[steady >= 1.7]
    assert rec.settled(late, np.full(late.size, 76.0), 0.0, 8.0, f) is False
    # Same impacts per cycle, but the peaks still growing by more than 5 % between the halves.
    assert rec.settled(steady, np.linspace(60.0, 76.0, steady.size), 0.0, 8.0, f) is False
    # Halves shorter than two cycles: no verdict.
    assert rec.settled(steady, np.full(steady.size, 76.0), 0.0, 0.9, f) is None


def test_the_last_step_ends_where_every_stream_of_the_recording_ends():
    t = np.arange(0.0, 10.0, 0.01)
    motor = {"time": t, "frequency_setpoint": np.where(t < 5.0, 3.0, 4.0), "frequency": np.where(t < 5.0, 3.0, 4.0)}
    steps = rec.segment_steps(motor, settle=1.0, end=8.0)
    assert [s.setpoint for s in steps] == [3.0, 4.0] and steps[-1].end == pytest.approx(8.0, abs=0.011)
    assert rec.segment_steps(motor, settle=1.0, end=4.0)[-1].setpoint == 3.0   # a step after the end: dropped
    force = _channel(np.zeros(int(7.5 * 20000)))
    data = rec.RecordedData(Path("r"), None, 0, channels={rec.FORCE: force}, motor=motor)
    assert rec.common_end(data) == pytest.approx(7.5, abs=1e-4)
    # The events' stream ended before the force channel: an impact seen by the force sensor after the last
    # event, with no event of its own, ends the common part there.
    data.events = {"time": np.array([1.0, 2.0])}
    detected = {"start": np.array([1.0, 2.0, 3.0, 4.0])}
    assert rec.common_end(data, detected, np.array([0, 1, -1, -1])) == 3.0
    assert rec.common_end(data, detected, np.array([0, 1, 2, 3])) == pytest.approx(7.5, abs=1e-4)
