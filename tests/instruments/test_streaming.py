"""The streaming simulator: exact sample grids, determinism, commands at stated times, instruments."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from rimd_sim.errors import CommandError, ConfigError
from rimd_sim.instruments.rig_simulator import RigSimulator
from rimd_sim.model.rig_model import RigModel
from rimd_sim.settings.config import SimConfig

CORE_SRC = str(Path(__file__).resolve().parents[2] / "rimd_sim")


def run_blocks(sim: RigSimulator, t_end: Fraction, block: Fraction):
    """Advance in blocks and concatenate what came out."""
    chans: dict[str, list[np.ndarray]] = {}
    firsts: dict[str, list[int]] = {}
    impacts, truth = [], []
    t = sim.time
    while t < t_end:
        t = min(t + block, t_end)
        out = sim.advance(t)
        for name, blk in out.channels.items():
            chans.setdefault(name, []).append(blk.samples)
            firsts.setdefault(name, []).append(blk.first_index)
        impacts.extend(out.impacts)
        truth.append(out.truth[1])
    return ({n: np.concatenate(v) for n, v in chans.items()}, firsts, impacts, np.concatenate(truth, axis=1))


def scheduled(seed: int = 7) -> RigSimulator:
    sim = RigSimulator(SimConfig().with_parameters({"seed": seed}))
    sim.set_motor_frequency(7.25, 4.0, at=Fraction(1, 2))
    sim.perturb(0.05, at=Fraction(13, 10))
    sim.set_parameters({"gap": 0.5e-3}, at=2)
    return sim


def test_same_seed_and_schedule_give_bit_identical_data_however_time_is_cut():
    """Hypothesis: the integrator never shortens a step to land on a block boundary and the instruments
    carry their filter and noise state, so blocks of 10 ms, blocks of 1/7 s and one call give the same
    bytes.
    """
    a = run_blocks(scheduled(), Fraction(3), Fraction(1, 100))
    b = run_blocks(scheduled(), Fraction(3), Fraction(1, 7))
    c = run_blocks(scheduled(), Fraction(3), Fraction(3))
    for other in (b, c):
        for name in a[0]:
            assert np.array_equal(a[0][name], other[0][name]), name
        assert a[2] == other[2]
        assert np.array_equal(a[3], other[3])
    assert len(a[2]) > 5  # the run does impact


def test_different_seed_changes_only_the_noise():
    a = run_blocks(scheduled(1), Fraction(1), Fraction(1, 100))
    b = run_blocks(scheduled(2), Fraction(1), Fraction(1, 100))
    assert not np.array_equal(a[0]["rimd_displacement"], b[0]["rimd_displacement"])
    assert np.array_equal(a[3], b[3])  # same physics


def test_sample_grid_is_exact_and_contiguous():
    """Over 2 s in 100 blocks/s: each channel has exactly rate x 2 s samples, first_index contiguous."""
    sim = RigSimulator(SimConfig())
    chans, firsts, _, truth = run_blocks(sim, Fraction(2), Fraction(1, 100))
    for name, rate in (("cart_displacement", 2000), ("rimd_displacement", 2000), ("rimd_acceleration", 20000),
                       ("impact_force", 20000)):
        assert len(chans[name]) == 2 * rate
        per_block = rate // 100
        assert firsts[name] == list(range(0, 2 * rate, per_block))
    assert truth.shape == (11, 2000)


def test_odd_rate_grid_has_no_drift():
    """A rate that does not divide the block (3 kHz at 7 blocks/s) still gives floor-free exact counts:
    sample n is at n / rate, the number of samples before t is ceil(t * rate).
    """
    cfg = SimConfig().with_parameters({"channels.cart_displacement.sample_rate": 3001.0})
    sim = RigSimulator(cfg)
    chans, firsts, _, _ = run_blocks(sim, Fraction(5), Fraction(1, 7))
    assert len(chans["cart_displacement"]) == 5 * 3001
    counts = np.diff(firsts["cart_displacement"] + [5 * 3001])
    assert set(counts) <= {428, 429}


def test_truth_matches_cart_kinematics_and_phase_is_continuous_through_a_ramp():
    """The cart follows x_c = A0 sin(phase): no jump when the setpoint changes (phase continuous), the
    frequency ramps at the commanded rate and sits on the setpoint afterwards; 0 Hz stops the cart.
    """
    cfg = SimConfig().with_parameters({"motor.initial_frequency": 3.0, "motor.initial_setpoint": 3.0,
                                       "truth.sample_rate": 10000.0})
    sim = RigSimulator(cfg)
    sim.set_motor_frequency(5.0, 2.0, at=1)
    sim.set_motor_frequency(0.0, 10.0, at=3)
    out = sim.advance(4)
    tr = out.truth[1]
    t = np.arange(tr.shape[1]) / 10000.0
    freq, xc, phase = tr[9], tr[2], tr[8]
    np.testing.assert_allclose(freq[t < 1.0], 3.0)
    ramp = (t > 1.0) & (t < 2.0)
    np.testing.assert_allclose(freq[ramp], 3.0 + 2.0 * (t[ramp] - 1.0), atol=1e-12)
    np.testing.assert_allclose(freq[(t >= 2.0) & (t < 3.0)], 5.0)
    a0 = cfg.rig.amplitude
    assert np.max(np.abs(np.diff(xc))) < a0 * 2 * np.pi * 5.0 / 10000.0 * 1.01
    np.testing.assert_allclose(xc, a0 * np.sin(phase), atol=1e-12)
    stopped = t > 3.5  # 5 Hz at 10 Hz/s: stopped at 3.5 s
    assert np.ptp(xc[stopped]) == 0.0 and np.all(freq[stopped] == 0.0)
    assert out.motor.frequency == 0.0 and out.motor.frequency_setpoint == 0.0


def test_perturbation_acts_at_its_stated_time():
    """Two identical runs, one with a velocity kick at t = 1.5 s: the truth is identical before 1.5 s and
    differs right after; the kick is logged with its time.
    """
    cfg = SimConfig().with_parameters({"gap": 2.4e-3, "motor.initial_frequency": 5.25,
                                       "motor.initial_setpoint": 5.25, "noise.enabled": False})
    a, b = RigSimulator(cfg), RigSimulator(cfg)
    b.perturb(0.2, at=Fraction(3, 2))
    ta, tb = a.advance(3).truth[1], b.advance(3).truth[1]
    assert np.array_equal(ta[:, :1500], tb[:, :1500])
    # Inertial velocity jumps by the kick at sample 1500 (t = 1.5 s exactly).
    assert tb[4, 1500] - ta[4, 1500] == pytest.approx(0.2, rel=1e-3)


def test_reset_puts_the_hammer_back_at_rest():
    cfg = SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
    sim = RigSimulator(cfg)
    sim.advance(5)
    sim.reset()
    out = sim.advance(Fraction(5001, 1000))
    assert out.truth[1][0, 0] == 0.0 and out.truth[1][1, 0] == 0.0
    assert [c.kind for c in out.commands] == ["reset"]


def test_a_resting_contact_is_not_reported_as_an_impact_and_the_impacts_count_from_zero():
    """At gap 0 with the motor at speed from t = 0, the hammer starts on the stop: the model's first contact, at
    t = 0 with no closing velocity, is the cart pressing it away, no collision. The rig leaves it out (after a reset
    too) and numbers the impacts it reports from 0; the model itself keeps it."""
    cfg = SimConfig().with_parameters({"gap": 0.0, "motor.initial_frequency": 7.25, "motor.initial_setpoint": 7.25})
    model = RigModel(cfg, channels=False)
    model_impacts = model.advance(2.0)
    assert model_impacts.impacts[0].t_start < 1e-9 and model_impacts.impacts[0].impact_velocity < 1e-9
    sim = RigSimulator(cfg)
    impacts = run_blocks(sim, Fraction(2), Fraction(1, 100))[2]
    assert [i.t_start for i in impacts] == [i.t_start for i in model_impacts.impacts[1:]]
    assert [i.index for i in impacts] == list(range(len(impacts))) and impacts[0].impact_velocity > 0.01
    sim.reset(at=Fraction(2))
    after = run_blocks(sim, Fraction(4), Fraction(1, 100))[2]
    assert all(i.impact_velocity > 1e-6 for i in after)
    assert [i.index for i in after] == list(range(len(impacts), len(impacts) + len(after)))


@pytest.mark.parametrize(
    ("freq", "rate", "message"),
    [(float("nan"), 0.0, "finite"), (float("inf"), 0.0, "finite"), (-1.0, 0.0, ">= 0"), (13.0, 0.0, "max_frequency"),
     (3.0, -1.0, ">= 0"), (3.0, float("nan"), "finite")],
)
def test_bad_motor_commands_refused_and_nothing_scheduled(freq, rate, message):
    sim = RigSimulator(SimConfig())
    with pytest.raises(CommandError, match=message):
        sim.set_motor_frequency(freq, rate)
    assert sim.pending_commands() == 0


def test_bad_parameter_commands_refused():
    sim = RigSimulator(SimConfig())
    with pytest.raises(ConfigError, match="gap"):
        sim.set_parameters({"gap": -1.0})
    with pytest.raises(CommandError, match="sample_rate"):
        sim.set_parameters({"channels.impact_force.sample_rate": 10000.0})
    with pytest.raises(CommandError, match="in the past"):
        sim.advance(1)
        sim.perturb(0.1, at=0.5)
    assert sim.pending_commands() == 0


def test_instruments_without_noise_read_the_truth_quantised_and_clipped():
    cfg = SimConfig().with_parameters({
        "noise.enabled": False, "motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75,
        "channels.rimd_displacement.range_max": 1e-3, "channels.rimd_displacement.range_min": -1e-3,
        "truth.sample_rate": 2000.0, "channels.rimd_acceleration.highpass": 0.0})
    out = RigSimulator(cfg).advance(4)
    rimd = out.channels["rimd_displacement"]
    truth_x = out.truth[1][3]
    expected = np.clip(np.round(truth_x / 1.5e-6) * 1.5e-6, -1e-3, 1e-3)
    np.testing.assert_array_equal(rimd.samples, expected)
    assert rimd.saturated == np.count_nonzero(np.abs(np.round(truth_x / 1.5e-6) * 1.5e-6) > 1e-3) > 0
    force = out.channels["impact_force"].samples
    assert force.max() > 50 and force.min() == 0.0


def test_noise_has_the_configured_standard_deviation():
    cfg = SimConfig().with_parameters({"motor.initial_setpoint": 0.0, "channels.impact_force.noise_std": 0.5})
    out = RigSimulator(cfg).advance(1)
    assert np.std(out.channels["impact_force"].samples) == pytest.approx(0.5, rel=0.03)


def test_impacts_are_not_lost_across_blocks():
    """Impacts completed in each block are reported once, with consecutive indices."""
    cfg = SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
    _, _, impacts, _ = run_blocks(RigSimulator(cfg), Fraction(10), Fraction(1, 100))
    assert [i.index for i in impacts] == list(range(len(impacts)))
    one = RigModel(cfg, channels=False, truth=False).advance(10).impacts
    assert one[0].t_start < 1e-9 and one[0].impact_velocity < 1e-9   # the resting contact at gap 0, left out
    assert impacts == [i._replace(index=i.index - 1) for i in one[1:]]


def _run_python(code: str, **env) -> subprocess.CompletedProcess:
    environment = {**os.environ, "PYTHONPATH": CORE_SRC + os.pathsep + os.environ.get("PYTHONPATH", ""), **env}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=240, env=environment, check=False)


@pytest.mark.process
def test_core_never_imports_rclpy():
    """The core runs with rclpy made unimportable (STYLE rule 1)."""
    proc = _run_python("""
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in ('rclpy', 'rimd_msgs', 'std_msgs'):
                    raise ImportError('blocked: ' + name)
        sys.meta_path.insert(0, Block())
        from rimd_sim.settings.config import SimConfig
        from rimd_sim.instruments.rig_simulator import RigSimulator
        out = RigSimulator(SimConfig()).advance(0.1)
        assert 'rclpy' not in sys.modules
        print('ok', len(out.channels['impact_force'].samples))
    """)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["ok", "2000"]


@pytest.mark.process
def test_pure_python_kernel_agrees_with_compiled():
    """RIMD_NO_JIT=1 runs the same kernel source as plain Python: same impacts to 1e-12 relative."""
    code = """
        import json
        from rimd_sim.model.rig_model import RigModel, SimConfig
        cfg = SimConfig().with_parameters({'motor.initial_frequency': 3.75, 'motor.initial_setpoint': 3.75,
                                           'initial.theta': -0.05})
        out = RigModel(cfg, channels=False, truth=False).advance(0.6)
        print(json.dumps([list(i) for i in out.impacts]))
    """
    pure = _run_python(code, RIMD_NO_JIT="1")
    jit = _run_python(code)
    assert pure.returncode == 0 and jit.returncode == 0, pure.stderr + jit.stderr
    a, b = json.loads(pure.stdout), json.loads(jit.stdout)
    assert len(a) == len(b) >= 2
    np.testing.assert_allclose(np.array(a), np.array(b), rtol=1e-12, atol=1e-15)


def test_instrument_filter_equals_scipy_sosfilt_across_blocks():
    """The compiled biquad cascade gives scipy.signal.sosfilt's output, block after block."""
    from scipy import signal

    from rimd_sim.instruments.sensors import _sos_filter

    sos = np.vstack([signal.butter(2, 3000, fs=20000, output="sos"),
                     signal.butter(1, 0.5, "highpass", fs=20000, output="sos")])
    x = np.random.default_rng(1).standard_normal(5000)
    expected = signal.sosfilt(sos, x)
    zi = np.zeros((sos.shape[0], 2))
    parts = [x[:1234].copy(), x[1234:3000].copy(), x[3000:].copy()]
    for part in parts:
        _sos_filter(sos, part, zi)
    np.testing.assert_allclose(np.concatenate(parts), expected, rtol=0, atol=1e-12)


def test_advance_blocks_equals_block_by_block():
    """One pass over many blocks (the node's fast mode) gives bit for bit the blocks of per-block calls:
    samples, saturation counts, truth, impacts, Poincare points, motor state at each boundary (through a
    ramp end) and the commands applied."""
    def make() -> RigSimulator:
        cfg = SimConfig().with_parameters({"seed": 3, "channels.rimd_displacement.range_max": 2e-3,
                                           "channels.rimd_displacement.range_min": -2e-3})
        sim = RigSimulator(cfg, strobe=True)
        sim.set_motor_frequency(7.25, 4.0, at=Fraction(1, 2))
        sim.perturb(0.05, at=Fraction(13, 10))
        return sim

    bounds = [Fraction(i, 100) for i in range(1, 301)]
    a, b = make(), make()
    one = [a.advance(t) for t in bounds]
    many = b.advance_blocks(bounds[:7]) + b.advance_blocks(bounds[7:150]) + b.advance_blocks(bounds[150:])
    assert len(one) == len(many) == 300
    for x, y in zip(one, many, strict=True):
        assert (x.t_start, x.t_stop) == (y.t_start, y.t_stop)
        for name in x.channels:
            cx, cy = x.channels[name], y.channels[name]
            assert cx.first_index == cy.first_index and cx.saturated == cy.saturated, name
            assert np.array_equal(cx.samples, cy.samples), name
        assert x.truth[0] == y.truth[0] and np.array_equal(x.truth[1], y.truth[1])
        assert x.impacts == y.impacts and x.strobe == y.strobe
        assert x.motor == y.motor, (x.t_stop, x.motor, y.motor)
        assert [(c.time, c.kind) for c in x.commands] == [(c.time, c.kind) for c in y.commands]
    assert sum(x.channels["rimd_displacement"].saturated for x in one) > 0
    assert sum(len(x.impacts) for x in one) > 5
