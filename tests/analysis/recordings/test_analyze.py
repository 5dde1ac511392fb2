"""``rimd analyze`` on bad input, and the pure routines of rimd_sim.analysis.recordings.recorded on known signals."""

from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from rimd_sim.analysis.recordings import recorded as rec


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


def test_a_recording_of_several_runs_is_refused_naming_each_run_and_its_file(tmp_path):
    """A directory recorded into twice holds two runs that each count their samples from 0: mixed, the first
    run's channels would be kept and both runs' impacts counted (hundreds of blocks read as "late" and impacts
    as "not covered"). The reader refuses it, naming each run and its file; each file alone is analysed,
    and a reset within a run (its samples go on counting) is no second run."""
    import contextlib
    import io

    from harness.rig_mcap import write_rig_mcap
    from rimd_sim import cli
    from rimd_sim.errors import AnalysisError

    runs = tmp_path / "recordings"
    runs.mkdir()
    first, second = runs / "rimd_a_0.mcap", runs / "rimd_b_0.mcap"
    write_rig_mcap(first, 1.5, sessions=(("aaaa1111" * 4, "start"), ("cccc3333" * 4, "reset")))
    write_rig_mcap(second, 1.0, sessions=(("bbbb2222" * 4, "start"),))
    with pytest.raises(AnalysisError) as refused:
        rec.load(runs)
    message = str(refused.value)
    assert message.startswith(f"{runs} holds 2 runs of the rig, each counting its samples from 0: "), message
    assert "run 1 aaaa1111 (start, from log time 0.000 s, in rimd_a_0.mcap)" in message
    assert "run 2 bbbb2222 (start, from log time 0.000 s, in rimd_b_0.mcap)" in message
    assert "cccc3333" not in message and "rimd rig --output-dir DIR" in message
    # Each file alone: one run (the reset included), its channel whole from sample 0.
    for path, seconds in ((first, 1.5), (second, 1.0)):
        force = rec.load(path).channels[rec.FORCE]
        assert force.index[0] == 0 and force.index.size == round(seconds * 20000) and force.lost_samples == 0
    # rimd analyze and rimd identify say it in one line and write nothing.
    for verb in ("analyze", "identify"):
        err = io.StringIO()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            assert cli.main([verb, str(runs), "--out", str(tmp_path / verb)]) == 1
        assert err.getvalue().strip() == f"rimd {verb}: {message}"
        assert not any((tmp_path / verb).glob("*.json"))


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
    assert m["matches"] + m["misses"] + m["not_covered"] == 4          # every event counted once
    assert math.isclose(m["peak_difference_max"], 2 / 52)
    # An event whose contact starts in a hole of the force channel but peaks after it: matched, so not also
    # "not covered" (the counts must add up).
    hole = _channel(np.r_[np.zeros(1000), [30, 20, 10, 5], np.zeros(996)], first=0)
    hole.index[1000:] += 10          # 10 samples lost just before the run
    hole.time[1000:] += 10 / 20000.0
    det = rec.detect_impacts(hole)
    events = {"time": np.array([1005 / 20000.0]), "duration": np.full(1, 3e-4), "peak_force": np.array([31.0])}
    m = rec.match_impacts(det, events, hole)
    assert (m["matches"], m["misses"], m["not_covered"]) == (1, 0, 0)


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
    from rimd_sim.analysis.recordings.contact_pulse import PulseSamples, pulse_of, pulse_peaks
    from rimd_sim.analysis.recordings.recorded import pulse_model

    model = pulse_model({"rimd_rig_parameters": {"contact.model": "spring_dashpot", "mass": "0.15",
                                                 "contact.stiffness": "5.5e6", "contact.damping": "1200.0"}})
    assert model == pulse_of(0.15, 5.5e6, 1200.0)   # no gap, f_n or zeta given: cos(theta) 1, no wires' damping
    assert pulse_model({"rimd_rig_parameters": {"contact.model": "hertz"}}) is None
    assert pulse_model({}) is None
    peak = 1200.0 * 0.066                       # F(0+) = c v0 (damping ratio 0.66 > 1/2: the largest force)
    scale = 0.15 * 0.066
    rng = np.random.default_rng(1)
    dt = 5e-5
    worst_fit, worst_raw = 0.0, 0.0
    for offset in np.linspace(0.0, dt, 40, endpoint=False):
        t = offset - dt + dt * np.arange(20)    # the onset at t = 0, between samples 0 and 1
        f = model.force(t, scale)
        run = np.flatnonzero(f >= 2.0)
        run = run[: np.argmax(np.diff(np.r_[run, 10**6]) != 1) + 1]    # the first run above threshold
        j = int(run[0])
        noisy = f + rng.normal(0.0, 0.01, t.size)
        (estimate,) = pulse_peaks(model, [PulseSamples(t[j - 1:], noisy[j - 1:], dt, float(t[j - 1]), float(t[j]))])
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
    # The 4.0 Hz step of the loaded experiment (docs/analyses.md, Reproducibility): no impact for the first 1.7 s of
    # the window, then one per cycle.
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


# ---- the report of rimd analyze: counts that add up, a warning, the figures a lab asks for ----------

@pytest.fixture(scope="module")
def faulted(tmp_path_factory):
    """The default rig, two steady steps (3.5 then 3.75 Hz, 5 s each), a 0.8 s dropout of the force channel from
    10.2 s (three impacts of the second step's steady window) and a stuck cart laser from 8.0 s, as the recorder
    writes it (with /rig/faults); analysed once."""
    from harness.ident_rigs import Schedule, write_core_recording
    from rimd_sim import cli

    work = tmp_path_factory.mktemp("analyze")
    path = work / "faulted.mcap"
    faults = [{"channel": "impact_force", "kind": "dropout", "start": 10.2, "duration": 0.8},
              {"channel": "cart_displacement", "kind": "stuck", "start": 8.0, "duration": 0.2}]
    write_core_recording(path, {}, Schedule([3.5, 3.75], dwell=5.0, faults=faults))
    out = work / "out"
    import contextlib
    import io

    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(io.StringIO()):
        assert cli.main(["analyze", str(path), "--out", str(out)]) == 0
    from harness.outputs import read_json

    return path, out, read_json(out / "summary.json"), stdout.getvalue()


def test_the_printed_counts_add_up_and_a_hiding_threshold_is_warned(faulted, tmp_path):
    import contextlib
    import io
    import re

    from rimd_sim import cli

    path, _, summary, text = faulted
    imp = summary["impacts"]
    line = next(li for li in text.splitlines() if li.startswith("impacts: "))
    numbers = [int(n) for n in re.findall(r"(\d+) (?:events|matched|missed|not covered|detected|extras)", line)]
    events, matched, missed, not_covered, detected, matched2, extras = numbers
    assert events == matched + missed + not_covered == imp["events"] and not_covered > 0   # the dropout's impacts
    assert detected == matched2 + extras + (imp.get("detected_after_events_end") or 0) == imp["detected"]
    assert "WARNING" not in text
    # --threshold 2000 once exited 0 with "0 detected ... 117 misses" and no warning
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(io.StringIO()):
        assert cli.main(["analyze", str(path), "--out", str(tmp_path / "t"), "--threshold", "2000"]) == 0
    out = stdout.getvalue()
    warning = next((li for li in out.splitlines() if li.startswith("WARNING: --threshold 2000 N")), None)
    assert warning is not None and "lower --threshold" in warning, out
    line = next(li for li in out.splitlines() if li.startswith("impacts: "))
    assert re.search(rf"{imp['events']} events = 0 matched \+ (\d+) missed \(\1 below the threshold\) \+ "
                     rf"{imp['not_covered']} not covered", line), line


def test_fault_and_gap_windows_are_left_out_said_and_drawn_on_every_time_plot(faulted):
    _, out, summary, text = faulted
    windows = summary["excluded_windows"]
    force = [w for w in windows if w["topic"] == "/rig/impact/force"]
    # the rig's word (/rig/faults) and the data's (the hole in first_index), both over 10.2-11.0 s
    assert {w["source"] for w in force} == {"/rig/faults", "data"}
    assert all(10.19 <= w["start_s"] and w["end_s"] <= 11.01 for w in force), force
    cart = [w for w in windows if w["topic"] == "/rig/cart/displacement"]
    assert any(w["kind"] == "stuck" and w["source"] == "data" for w in cart), cart
    assert summary["figure_windows"]["impacts.png"] == len(windows)
    assert summary["figure_windows"]["channels.png"] >= len(force) + len(cart)
    assert any(li.startswith(f"left out ({len(windows)} windows, s from the recording's first stamp): ")
               for li in text.splitlines())
    # the force channel's impacts per cycle count only the cycles the sensor saw: the 3.75 Hz step holds the
    # dropout (3 of its ~26 cycles) and still reads one impact per cycle, as its events do
    row = next(r for r in summary["steps"] if r["frequency_hz"] == 3.75)
    seen = (row["end_s"] - row["steady_from_s"] - 0.8) * 3.75        # cycles outside the dropout
    assert abs(row["impacts_per_cycle_channel"] - 1.0) <= 1.0 / seen + 0.01, row   # one impact of window edge
    assert abs(row["impacts_per_cycle_events"] - 1.0) <= 1.0 / (seen + 3) + 0.01, row


@pytest.mark.process
def test_no_plot_writes_the_same_tables_and_summary_without_figures_or_matplotlib(faulted, tmp_path):
    import json
    import sys

    from harness.outputs import read_json

    path, out, summary, _ = faulted
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(out / "impacts.png", bare / "impacts.png")   # an earlier run's figure: not this run's
    script = ("import sys; from rimd_sim.cli import main; status = main(sys.argv[1:]); "
              "print('matplotlib' in sys.modules); sys.exit(status)")
    done = subprocess.run([sys.executable, "-c", script, "analyze", str(path), "--out", str(bare), "--no-plot"],
                          capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "False", "--no-plot loaded matplotlib"
    assert not list(bare.glob("*.png"))
    for table in sorted(out.glob("*.csv")):
        assert (bare / table.name).read_bytes() == table.read_bytes(), table.name
    plain = read_json(bare / "summary.json")
    assert plain["figures"] == [] and plain["figure_windows"] == {}
    same = ("figures", "figure_windows", "wall_seconds")
    assert json.dumps({k: v for k, v in plain.items() if k not in same}, sort_keys=True) == json.dumps(
        {k: v for k, v in summary.items() if k not in same}, sort_keys=True)


def test_spread_per_step_pulse_zoom_and_acceleration_spectrum(faulted):
    import csv

    _, out, summary, _ = faulted
    for name in ("peak_force_vs_frequency.png", "impacts.png", "channels.png", "pulse_zoom.png",
                 "acceleration_spectrum.png", "phase_planes.png"):
        assert (out / name).stat().st_size > 10_000, name
    detected = list(csv.DictReader(open(out / "impacts_detected.csv")))
    for r in summary["steps"]:
        if r["steady_from_s"] is None:
            continue
        peaks = np.array([float(d["peak_force_n"]) for d in detected
                          if r["steady_from_s"] <= float(d["start_s"]) < r["end_s"]])
        peaks = peaks[peaks > 0]
        # the error bars: mean and standard deviation of the steady window's peaks (computed here from the CSV)
        assert r["peak_force_events_mean_n"] <= r["peak_force_events_n"]
        assert r["peak_force_channel_std_n"] == pytest.approx(np.std(peaks, ddof=1), rel=0.05, abs=0.05)
    zoom = summary["pulse_zoom"]
    # "typical": the impact of the steady windows whose peak is their median (closest to it)
    steady = np.array([float(d["peak_force_n"]) for d in detected if d["complete"] == "True" and any(
        r["steady_from_s"] is not None and r["steady_from_s"] <= float(d["start_s"]) < r["end_s"]
        for r in summary["steps"])])
    assert np.min(np.abs(steady - zoom["peak"])) < 1e-9
    assert abs(zoom["peak"] - np.median(steady)) <= np.min(np.abs(steady - np.median(steady))) + 1e-9
    assert zoom["captured"] is False
    rows = list(csv.DictReader(open(out / "spectrum.csv")))
    for spec in summary["spectra"]:
        f0 = spec["motor_hz"]
        sel = [(float(r["frequency_hz"]), float(r["psd_m2_s4_hz"])) for r in rows
               if int(r["step"]) == spec["step"] and 0.5 < float(r["frequency_hz"]) < 30.0]
        fr, psd = np.array(sel).T
        top = fr[np.argsort(psd)[-3:]]
        df = float(np.median(np.diff(fr)))   # the resolution: 1 / the stretch's length (the dropout shortens it)
        # a steady motion of one impact per cycle is periodic at f0: its power sits on the harmonics
        assert np.all(np.abs(top / f0 - np.round(top / f0)) * f0 <= df + 1e-9), (f0, df, top)
