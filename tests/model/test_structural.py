"""The structural contact model (docs/physics.md): two-mass hammer, force sensor on a compliant mount.

Each test states its hypothesis and where the expected number comes from.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import rimd_sim
from rimd_sim.analysis.dynamics.pulse import LEAD_GAP, force_peaks, pulse, ring_frequency
from rimd_sim.errors import CommandError, ConfigError
from rimd_sim.instruments.rig_simulator import RigSimulator
from rimd_sim.model.rig_model import MODELS, RigModel
from rimd_sim.settings.config import SimConfig, find_config_file, load_config


def at_frequency(cfg: SimConfig, f: float, **params) -> SimConfig:
    return cfg.with_parameters({"motor.initial_frequency": f, "motor.initial_setpoint": f, **params})


@pytest.fixture(scope="module")
def structural() -> SimConfig:
    return load_config(find_config_file("structural.yaml"))


def axial_frequency(cfg: SimConfig) -> float:
    """Damped frequency (Hz) of the hammer's axial mode from the preset's masses and stiffness."""
    st = cfg.rig.structure
    m1, m = st.impactor_mass, cfg.rig.mass
    mu = m1 * (m - m1) / m
    return math.sqrt(st.axial_stiffness / mu) * math.sqrt(1 - st.axial_damping_ratio ** 2) / (2 * math.pi)


# ---- the special case: rigid link and rigid mount are the paper's model ---------------------------------


@pytest.mark.parametrize("freq,gap", [(3.75, 0.0), (7.25, 0.0), (3.0, 1.0e-3), (2.5, 2.4e-3)])
def test_rigid_two_mass_reduces_to_the_paper_model(freq, gap):
    """With axial_stiffness = 0 and mount_stiffness = 0 (rigid, the special case of the two-mass model:
    u and s stay exactly 0 and drop out of the error norm) the structural kernel gives the paper kernel's
    impacts to 1e-6 (every field, 20 s, bands A and B and both gaps of the paper)."""
    cfg = at_frequency(SimConfig(), freq, gap=gap)
    ref = RigModel(cfg, channels=False, truth=False).advance(20.0).impacts
    two = cfg.with_parameters({"structure.model": "two_mass", "structure.axial_stiffness": 0.0,
                               "structure.mount_stiffness": 0.0})
    got = RigModel(two, channels=False, truth=False).advance(20.0).impacts
    assert len(ref) > 30 and len(got) == len(ref)
    np.testing.assert_allclose(np.array(got, dtype=float), np.array(ref, dtype=float), rtol=1e-6, atol=1e-9)


def test_rigid_two_mass_samples_the_paper_models_channels():
    """In the rigid special case the four channels and the truth are the paper model's too (5 s, 3.75 Hz)."""
    cfg = at_frequency(SimConfig(), 3.75)
    ref = RigModel(cfg).advance(5.0)
    got = RigModel(cfg.with_parameters({"structure.model": "two_mass"})).advance(5.0)
    for name, (first, samples) in ref.channels.items():
        assert got.channels[name][0] == first
        np.testing.assert_allclose(got.channels[name][1], samples, rtol=1e-9, atol=1e-9 * np.abs(samples).max())
    np.testing.assert_allclose(got.truth[1], ref.truth[1], rtol=1e-9, atol=1e-9)


def test_reconfigured_to_rigid_while_ringing_runs_on(structural):
    """Changing the link and the mount to rigid right after an impact (modes still ringing) keeps the model
    running, with the axial and mount states at exactly 0 from the next free step on."""
    model = RigModel(at_frequency(structural, 3.75), channels=False, truth=False)
    t = Fraction(0)
    while not model.advance(t := t + Fraction(1, 1000)).impacts:  # stop within 1 ms of the first impact's end
        assert t < 2
    assert np.any(model._ya[3:] != 0.0)
    model.reconfigure(model.config.with_parameters({"structure.axial_stiffness": 0.0,
                                                    "structure.mount_stiffness": 0.0}))
    later = model.advance(t + 2).impacts
    assert len(later) >= 5 and np.all(model._ya[3:] == 0.0)


def test_stiff_link_and_mount_tend_to_the_paper_model():
    """The rigid case is also the limit: with the link and the mount 1e10 N/m the pulse's contact impulse
    and duration come within 2 % of the rigid model's (the peak differs more: in the two-mass model the dashpot's
    jump of c v at first contact accelerates the sensor's mass first)."""
    v = 0.07
    rigid = pulse(SimConfig(), v).summary
    stiff = pulse(SimConfig().with_parameters({
        "structure.model": "two_mass", "structure.axial_stiffness": 1e10, "structure.mount_stiffness": 1e10}),
        v).summary
    assert stiff["impulse_n_s"] == pytest.approx(rigid["impulse_n_s"], rel=0.02)
    assert stiff["duration_s"] == pytest.approx(rigid["duration_s"], rel=0.02)


@pytest.mark.process
def test_pure_python_driver_agrees_with_compiled():
    """RIMD_NO_JIT=1 runs the same driver and two-mass physics as plain Python (STYLE rule 2: both behind one
    interface): a pulse of the preset, its two contacts and the rear mass's ringing, gives the same summary and
    the same acceleration samples to 1e-12 relative."""
    code = textwrap.dedent("""
        import json
        from rimd_sim.analysis.dynamics.pulse import pulse
        from rimd_sim.settings.config import load_config
        from rimd_sim.settings.config import find_config_file
        r = pulse(load_config(find_config_file("structural.yaml")), 0.066, rate=2e5, span=0.003)
        print(json.dumps({"summary": r.summary, "acc": r.acceleration.tolist()}))
    """)
    src = str(Path(rimd_sim.__file__).resolve().parent.parent)
    runs = []
    for jit in ("0", "1"):
        env = {**os.environ, "PYTHONPATH": src + os.pathsep + os.environ.get("PYTHONPATH", "")}
        env.pop("RIMD_NO_JIT", None)
        if jit == "0":
            env["RIMD_NO_JIT"] = "1"
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=240, env=env,
                              check=False)
        assert proc.returncode == 0, proc.stderr
        runs.append(json.loads(proc.stdout))
    pure, compiled = runs
    assert pure["summary"]["contacts"] == compiled["summary"]["contacts"] == 2
    for key in ("peak_force_n", "second_peak_force_n", "duration_s", "impulse_n_s", "ring_frequency_hz"):
        assert pure["summary"][key] == pytest.approx(compiled["summary"][key], rel=1e-12), key
    np.testing.assert_allclose(pure["acc"], compiled["acc"], rtol=1e-12, atol=1e-9)


# ---- the fitted preset at gap 0, 3.75 Hz (paper Fig. 3) -------------------------------------------------


def test_fitted_preset_double_peak_and_ringing_at_3_75_hz(structural):
    """Paper Fig. 3 (gap 0, 3.75 Hz): a first force peak of about 80 N and a second of about 50 N, and an
    accelerometer that rings after each impact. In the rig (steady state, 12 s from rest, force and
    acceleration at 250 kHz, noise-free), the last impact's second force peak is 50-70 % of its first, and
    the rear mass rings at the hammer's axial frequency (within 3 %)."""
    rate = 250_000.0
    cfg = at_frequency(structural, 3.75, **{"channels.impact_force.sample_rate": rate,
                                            "channels.rimd_acceleration.sample_rate": rate})
    model = RigModel(cfg, channels=True, truth=False)
    assert model.physics_model is MODELS["two_mass"]
    model.advance(11.0)
    out = model.advance(12.0)
    imp = out.impacts[-1]
    first, force = out.channels["impact_force"]
    _, acc = out.channels["rimd_acceleration"]
    t = (first + np.arange(force.size)) / rate
    during = (t >= imp.t_start) & (t <= imp.t_start + imp.duration)
    peaks = sorted((force[during][i] for i in force_peaks(force[during])), reverse=True)
    assert len(peaks) >= 2, peaks
    assert 0.50 <= peaks[1] / peaks[0] <= 0.70, peaks
    assert peaks[0] == pytest.approx(imp.peak_force, rel=0.02)
    ring = (t > imp.t_end) & (t <= imp.t_end + 0.005)
    assert ring_frequency(acc[ring], rate) == pytest.approx(axial_frequency(cfg), rel=0.03)
    # The paper's single-mass model shows neither: one peak, no ringing.
    rigid = pulse(SimConfig(), imp.impact_velocity).summary
    assert rigid["second_peak_force_n"] == 0.0 and rigid["ring_frequency_hz"] == 0.0


# ---- Table 1 from rest --------------------------------------------------------------------------------

#: Paper Table 1 (band A, band B) per gap.
TABLE1 = {0.0: (3.75, 7.25), 1.0e-3: (3.00, 6.25), 2.4e-3: (2.50, 5.25)}
#: The fitted preset's resonances: a regression pin (docs/physics.md reports the miss at 1.0 mm).
TABLE1_STRUCTURAL = {0.0: (3.75, 7.25), 1.0e-3: (3.00, 6.50), 2.4e-3: (2.50, 5.25)}


@pytest.mark.parametrize("gap", sorted(TABLE1))
def test_table1_from_rest_with_the_structural_preset(structural, gap):
    """Paper Table 1 with config/structural.yaml, each frequency of the 0.25 Hz grid from rest, steady state
    over the last 50 of 150 cycles (the machinery of the paper model's Table 1 test). The resonances measured
    are within 0.25 Hz (one grid step) of the paper's, and they are the fitted preset's
    (regression pin: five exact, band B at 1.0 mm 6.50 Hz); at gap 0 both peaks within 10 % of 82.4 N and
    120 N (paper)."""
    rows = []
    for f in np.arange(2.0, 9.51, 0.25):
        f = float(f)
        duration = 150 / f
        impacts = RigModel(at_frequency(structural, f, gap=gap), channels=False, truth=False
                           ).advance(duration).impacts
        last = [i for i in impacts if i.t_start >= duration - 50 / f]
        rows.append((f, max((i.peak_force for i in last), default=0.0), len(last) / 50))
    # Period 1 and period 2 strictly: 50 (band A) or 25 (band B) impacts in the 50 cycles. (The paper model's
    # test allows +-0.03 impacts/cycle; with it the preset's irregular motion at 9.0 Hz, 49 impacts in 50
    # cycles with one of 87 N, would be taken for band A.)
    band_a = max((r for r in rows if r[2] == 1.0), key=lambda r: r[1])
    band_b = max((r for r in rows if r[2] == 0.5), key=lambda r: r[1])
    assert abs(band_a[0] - TABLE1[gap][0]) <= 0.25 and abs(band_b[0] - TABLE1[gap][1]) <= 0.25, (band_a, band_b)
    assert (band_a[0], band_b[0]) == TABLE1_STRUCTURAL[gap]
    if gap == 0.0:
        assert band_a[1] == pytest.approx(82.4, rel=0.10) and band_b[1] == pytest.approx(120.0, rel=0.10)


# ---- the model in the simulator, determinism, configuration ---------------------------------------------


def test_simulator_runs_the_selected_model_and_blocks_do_not_matter(structural):
    """The simulator builds the model structure.model selects; the structural model, like the paper's, gives
    bit-identical samples and impacts however time is cut into calls (one call against 1/7 s blocks)."""
    cfg = at_frequency(structural, 3.75, **{"noise.enabled": False})
    one = RigSimulator(cfg)
    assert one.model.physics_model is MODELS["two_mass"]
    a = one.advance(3.0)
    sim = RigSimulator(cfg)
    blocks = []
    t = Fraction(0)
    while t < 3:
        t = min(t + Fraction(1, 7), Fraction(3))
        blocks.append(sim.advance(t))
    for name, ch in a.channels.items():
        np.testing.assert_array_equal(ch.samples, np.concatenate([b.channels[name].samples for b in blocks]))
    assert [i.t_start for i in a.impacts] == [i.t_start for b in blocks for i in b.impacts]
    assert RigSimulator(SimConfig()).model.physics_model is MODELS["rigid"]
    with pytest.raises(CommandError, match="structure.model"):
        one.set_parameters({"structure.model": "rigid"})


@pytest.mark.parametrize("key,value,rule", [
    ("structure.model", "three_mass", "must be one of"),
    ("structure.axial_stiffness", 10.0, "must be 0 (rigid) or >= 1000"),
    ("structure.mount_stiffness", -1.0, "must be 0 (rigid) or >= 1000"),
    ("structure.axial_damping_ratio", 1.0, "must be >= 0 and < 1"),
    ("structure.sensor_mass", 0.0, "must be >= 0.0001"),
])
def test_bad_structure_values_are_refused_naming_the_field(key, value, rule):
    with pytest.raises(ConfigError, match="structure") as err:
        SimConfig().with_parameters({key: value})
    assert rule in str(err.value) and key in str(err.value)


def test_impactor_heavier_than_the_hammer_is_refused():
    with pytest.raises(ConfigError, match="structure.impactor_mass.*must be < mass"):
        SimConfig().with_parameters({"structure.model": "two_mass", "structure.axial_stiffness": 1e6,
                                     "structure.impactor_mass": 0.2})


# ---- rimd pulse ---------------------------------------------------------------------------------------


def reference_impact_duration(cfg: SimConfig, velocity: float, span: float = 3e-3) -> float:
    """The duration of one impact of the two-mass model, from an independent integration.

    Written from the equations of docs/physics.md ("Structural model"), sharing no code with rimd_sim.model: the
    cart at rest, the pendulum (theta), the link's extension u and the sensor's top s, spring-dashpot contact on
    delta = l sin(theta) + (m2/m) u - s - gap; scipy's solve_ivp (DOP853, rtol 1e-11) with the Filippov switches
    as terminal directed events (contact while the law's force is >= 0 and delta > 0; after a release with
    delta > 0, a re-contact when the force rises through 0; the impact ends when delta falls through 0). The
    hammer starts as ``rimd pulse`` starts it: LEAD_GAP before the stop at ``velocity``, the modes at rest.
    Returns the time from the first contact to the last instant the force vanished (``Impact.duration``).
    """
    rig, st = cfg.rig, cfg.rig.structure
    assert rig.contact.model == "spring_dashpot" and st.axial_stiffness > 0 and st.mount_stiffness > 0
    g, length, m, gap = rig.gravity, rig.length, rig.mass, rig.gap
    wn, zeta = 2 * math.pi * rig.natural_frequency, rig.damping_ratio
    k, c = rig.contact.stiffness, rig.contact.damping
    m1 = st.impactor_mass
    m2 = m - m1
    mu = m1 * m2 / m
    ka, ca = st.axial_stiffness, 2 * st.axial_damping_ratio * math.sqrt(st.axial_stiffness * mu)
    ms, km = st.sensor_mass, st.mount_stiffness
    cm = 2 * st.mount_damping_ratio * math.sqrt(km * ms)

    def delta(y):
        th, om, u, up, s, sp = y
        return length * math.sin(th) + m2 / m * u - s - gap, length * om * math.cos(th) + m2 / m * up - sp

    def force(t, y):
        d, dd = delta(y)
        return k * d + c * dd

    def rhs(contact):
        def f(t, y):
            th, om, u, up, s, sp = y
            fc = force(t, y) if contact else 0.0
            return [om, -g / length * math.sin(th) - 2 * zeta * wn * om - fc / (m * length),
                    up, (-ka * u - ca * up - m2 / m * fc) / mu, sp, (fc - km * s - cm * sp) / ms]
        return f

    def event(fn, direction):
        fn.terminal, fn.direction = True, direction
        return fn

    theta0 = math.asin((gap - LEAD_GAP) / length)
    y = [theta0, velocity / (length * math.cos(theta0)), 0.0, 0.0, 0.0, 0.0]
    opts = {"method": "DOP853", "rtol": 1e-11, "atol": 1e-16, "max_step": 2e-6}
    sol = solve_ivp(rhs(False), (0.0, span), y, events=event(lambda t, y: delta(y)[0], 1), **opts)
    t_start, y = sol.t[-1], sol.y[:, -1]
    t, last_release, contact = t_start, t_start, True
    while t < span:
        if contact:  # until the force falls through 0 or delta falls through 0
            sol = solve_ivp(rhs(True), (t, span), y, events=(event(force, -1), event(lambda t, y: delta(y)[0], -1)),
                            **opts)
            t, y = sol.t[-1], sol.y[:, -1]
            last_release, contact = t, False
            if len(sol.t_events[1]) and (not len(sol.t_events[0]) or sol.t_events[1][0] <= sol.t_events[0][0]):
                return last_release - t_start
        else:  # released with delta > 0: a re-contact, or delta back below 0 (the end of the impact)
            sol = solve_ivp(rhs(False), (t, span), y, events=(event(force, 1), event(lambda t, y: delta(y)[0], -1)),
                            **opts)
            t, y = sol.t[-1], sol.y[:, -1]
            if sol.status != 1 or len(sol.t_events[1]):
                return last_release - t_start
            contact = True
    raise AssertionError("the reference impact did not end within the span")



def test_rimd_pulse_writes_plot_samples_and_summary(structural, tmp_path, capsys):
    """`rimd pulse` with the structural preset at the steady-state velocity of 3.75 Hz (0.066 m/s): 1 MHz
    samples, a plot, and a summary whose peaks, duration and ringing agree with the model (the second peak
    50-70 % of the first, the duration that of an independent solve_ivp integration of the model's equations to
    1e-6, ringing at the axial frequency within 1 %)."""
    from harness.outputs import read_json
    from rimd_sim import cli

    out = tmp_path / "pulse"
    assert cli.main(["pulse", "--config", str(find_config_file("structural.yaml")), "--velocity", "0.066",
                     "--out", str(out)]) == 0
    summary = read_json(out / "summary.json")
    assert {"peak_force_n", "second_peak_force_n", "duration_s", "ring_frequency_hz"} <= set(summary)
    assert summary["sample_rate_hz"] == 1e6
    assert 0.50 <= summary["second_peak_force_n"] / summary["peak_force_n"] <= 0.70
    assert summary["duration_s"] == pytest.approx(reference_impact_duration(structural, 0.066), rel=1e-6)
    assert summary["ring_frequency_hz"] == pytest.approx(axial_frequency(structural), rel=0.01)
    assert (out / "pulse.png").stat().st_size > 10_000
    samples = np.loadtxt(out / "pulse.csv", delimiter=",", skiprows=1)
    assert samples.shape[1] == 3 and samples[:, 1].max() == pytest.approx(summary["peak_force_n"])
    assert "second peak" in capsys.readouterr().out


@pytest.mark.parametrize("argv,message", [
    (["--velocity", "-1"], "--velocity -1 refused: must be > 0 and <= 10 m/s"),
    (["--velocity", "nan"], "--velocity nan refused: must be finite; must be > 0 and <= 10 m/s"),
    (["--velocity", "0.1", "--rate", "5e6"], "--rate 5e6 refused: must be >= 1000 and <= 1e+06 Hz"),
])
def test_rimd_pulse_refuses_bad_input_as_a_usage_error(argv, message, tmp_path, capsys):
    """A bad number is refused before anything runs, naming the option as typed and its rule (exit 2)."""
    from rimd_sim import cli

    with pytest.raises(SystemExit) as usage:
        cli.main(["pulse", *argv, "--out", str(tmp_path / "o")])
    assert usage.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].endswith(message)
    assert not (tmp_path / "o").exists()
