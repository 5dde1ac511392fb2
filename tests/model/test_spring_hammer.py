"""The hammer with its own spring: a pendulum length set apart from the natural frequency.

Without a spring (``pendulum_length: 0``, the default) the model is the gravity pendulum, bit for bit.
``REFERENCE`` holds the SHA-256 of the public calls' outputs computed by :func:`public_hashes` (numba and numpy of
the lock), so that the test catches any change of those outputs that nobody meant. A change meant to alter the
outputs' last bits (the integrator's order of operations, a default cap) re-takes the hashes in the same commit.
``python tests/model/test_spring_hammer.py`` prints them (run it against another tree by putting that tree's
``rimd_sim`` first on ``PYTHONPATH``).

With a spring: a hammer at f_n 10 Hz with l = 23 mm (a gravity pendulum would be 2.48 mm) keeps g = 9.81, runs in
a sweep, a map and the streaming simulator, and its linear resonance without impact lies at f_n.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config"

#: The expected ``public_hashes()`` (see the module docstring).
REFERENCE = {
    'model.paper': 'e1f0789457969179324a6d9acb98d7d058751876fef791c2d0a7907a1eb36c80',
    'model.rimd': '800833b9f812b7c22d90cbee789e3d18add7c1bc7e24b07f222485569ebbaea9',
    'model.structural': 'fd2e2ef1f6ed0587cad209eea139a03bc43eead640f0e7bb009a71f8b79c8c9c',
    'simulator.rimd': '60091acb58413bdd77422190ee151ec1601fbc27776a102f476063b5530eae83',
    'sweep.rimd': 'b96d8838569c6f0b3c23e68556ad83715842ce9663bf1324571c2c629d455970',
    'peterka.paper': '1638536971fd36b80493fe6f11b7baf3283069be69513d7268be1134bde569fe',
}

#: The fields of a sweep point the reference hashed (points may gain fields after them).
SWEEP_FIELDS = ("frequency_hz", "frequency_ratio", "peak_force_n", "force_ratio", "impacts_per_cycle",
                "simulated_seconds", "max_abs_theta_rad", "max_force_n", "valid", "invalid_rule")


def _digest(*parts) -> str:
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(str(part.dtype).encode())
            h.update(np.ascontiguousarray(part).tobytes())
        else:
            h.update(repr(part).encode())
    return h.hexdigest()


def _model_run(config) -> str:
    from rimd_sim.model.rig_model import RigModel

    out = RigModel(config, channels=True, truth=True, strobe=True).advance(2.0)
    parts = []
    for name in sorted(out.channels):
        first, samples = out.channels[name]
        parts += [name, first, np.asarray(samples)]
    parts += [out.truth[0], np.asarray(out.truth[1])]
    parts += [tuple(float(x).hex() if isinstance(x, float) else x for x in i) for i in out.impacts]
    parts += [(s.t.hex(), s.theta.hex(), s.theta_dot.hex(), s.cycle_index) for s in out.strobe]
    parts.append(float(out.max_abs_theta).hex())
    return _digest(*parts)


def _simulator_run(config) -> str:
    from rimd_sim.instruments.rig_simulator import RigSimulator

    sim = RigSimulator(config, truth=True)
    parts = []
    for block in sim.advance_blocks([0.25 * (i + 1) for i in range(4)]):
        for name in sorted(block.channels):
            ch = block.channels[name]
            parts += [name, np.asarray(ch.samples)]
        parts.append(np.asarray(block.truth[1]))
    return _digest(*parts)


def public_hashes() -> dict[str, str]:
    """SHA-256 of the outputs of the public calls on the presets (a few seconds)."""
    from rimd_sim.analysis.dynamics.peterka import peterka
    from rimd_sim.analysis.dynamics.sweep import sweep
    from rimd_sim.settings.config import load_config

    paper = load_config(CONFIG / "paper_model.yaml")
    from harness.presets import SINGLE_MASS_SET

    rimd = load_config(CONFIG / "rimd.yaml", SINGLE_MASS_SET)   # the mechanics the reference hashes are of
    structural = load_config(CONFIG / "structural.yaml")
    const = {"motor.initial_frequency": 4.9, "motor.initial_setpoint": 4.9}
    out = {
        "model.paper": _model_run(paper.with_parameters(const)),
        "model.rimd": _model_run(rimd.with_parameters({**const, "gap": 1e-3})),
        "model.structural": _model_run(structural.with_parameters(const)),
        "simulator.rimd": _simulator_run(rimd),
    }
    pts = sweep(rimd, [3.75, 7.25], "rest", cycles=60, measure_cycles=20, workers=1).points
    out["sweep.rimd"] = _digest([tuple(repr(asdict(p)[k]) for k in SWEEP_FIELDS) for p in pts])
    m = peterka(paper, [0.0, 1e-3], [3.0, 4.5], starts=0, stop="window", workers=1)
    out["peterka.paper"] = _digest(m.labels.tolist(), m.cycles, m.max_force, m.max_abs_theta)
    return out


def test_without_a_spring_the_model_is_bit_identical_to_the_gravity_pendulum_before_it():
    assert REFERENCE, "no reference hashes"
    assert public_hashes() == REFERENCE


def _spring_config(**extra):
    from rimd_sim.settings.config import load_config

    return load_config(CONFIG / "rimd.yaml", {"natural_frequency": 10.0, "pendulum_length": 0.023, "gap": 0.0,
                                              "motor.max_frequency": 30.0, **extra})


def test_the_spring_supplies_what_the_length_leaves_and_a_shorter_pendulum_is_refused():
    from rimd_sim.errors import ConfigError
    from rimd_sim.settings.config import load_config

    cfg = _spring_config()
    rig = cfg.rig
    assert rig.gravity == 9.81 and rig.length == 0.023
    omega = 2 * math.pi * 10.0
    assert rig.spring_stiffness == pytest.approx(rig.mass * 0.023 ** 2 * omega ** 2 - rig.mass * 9.81 * 0.023,
                                                 rel=1e-12)
    assert rig.gravity_length == pytest.approx(9.81 / omega ** 2)
    with pytest.raises(ConfigError) as info:   # shorter than the gravity pendulum: a negative spring
        load_config(CONFIG / "rimd.yaml", {"natural_frequency": 10.0, "pendulum_length": 0.002})
    assert "pendulum_length" in str(info.value) and "negative stiffness" in str(info.value)
    with pytest.raises(ConfigError) as info:   # the gap rule follows the declared length
        _spring_config(gap=0.0116)
    assert "'gap'" in str(info.value) and "l/2 = 0.0115" in str(info.value)


def _theta(cfg, seconds):
    from rimd_sim.model.rig_model import RigModel

    out = RigModel(cfg, channels=False, truth=True).advance(seconds)
    assert not out.impacts
    truth = np.asarray(out.truth[1])
    return (out.truth[0] + np.arange(truth.shape[1])) / cfg.truth_rate, truth[0]


def test_its_linear_resonance_without_impact_lies_at_the_natural_frequency():
    """Free and forced, far from the stop and at small angles: the linear resonance at f_n within 0.1 %."""
    far = {"gap": 0.01, "damping_ratio": 0.0}
    # Free, undamped, from 1 mrad: the frequency of the oscillation is f_n itself.
    t, theta = _theta(_spring_config(**far, **{"amplitude": 0.0, "initial.theta": 1e-3,
                                              "motor.initial_setpoint": 0.0}), 3.0)
    i = np.flatnonzero((theta[:-1] < 0) & (theta[1:] >= 0))
    tz = t[i] - theta[i] * (t[i + 1] - t[i]) / (theta[i + 1] - theta[i])
    assert (len(tz) - 1) / (tz[-1] - tz[0]) == pytest.approx(10.0, rel=1e-4)
    # Forced by the cart (A0 = 10 um), damped (zeta 0.02): the steady amplitude of theta at each frequency by
    # a lock-in over the last 2 s of an 8 s run, a parabola through the five amplitudes; the vertex is the
    # resonance (of the relative angle under base acceleration: omega_n / sqrt(1 - 2 zeta^2), 0.04 % above).
    freqs = np.array([9.9, 9.95, 10.0, 10.05, 10.1])
    amps = []
    for f in freqs:
        cfg = _spring_config(**{**far, "damping_ratio": 0.02, "amplitude": 1e-5, "motor.initial_frequency": f,
                                "motor.initial_setpoint": f})
        t, theta = _theta(cfg, 8.0)
        keep = t >= 6.0
        phase = 2 * np.pi * f * t[keep]
        amps.append(2 * abs(np.mean(theta[keep] * np.exp(-1j * phase))))
    a, b, _ = np.polyfit(freqs, amps, 2)
    assert -b / (2 * a) == pytest.approx(10.0, rel=1e-3)


def test_a_spring_restored_hammer_runs_in_a_sweep_a_map_and_the_simulator():
    from rimd_sim.analysis.dynamics.peterka import peterka
    from rimd_sim.analysis.dynamics.sweep import sweep
    from rimd_sim.instruments.rig_simulator import RigSimulator

    cfg = _spring_config(**{"gap": 0.25e-3, "mass": 1.0, "damping_ratio": 0.02})
    res = sweep(cfg, [18.0, 20.0, 22.0], "rest", cycles=80, measure_cycles=20, workers=1)
    for p in res.points:
        assert p.impacts_per_cycle == 1.0 and p.valid, p
        assert p.force_ratio == pytest.approx(p.peak_force_n / (1.0 * 9.81))   # F/mg against the real g
        assert 100.0 < p.peak_force_n < 10000.0
    m = peterka(cfg, [0.25e-3], [18.0, 22.0], starts=0, workers=1)
    assert set(m.primary.ravel().tolist()) == {"1/1"}
    sim = RigSimulator(cfg.with_parameters({"motor.initial_frequency": 20.0, "motor.initial_setpoint": 20.0}))
    block = sim.advance(1.0)
    force = np.asarray(block.channels["impact_force"].samples)
    assert len(block.impacts) >= 15 and force.max() > 100.0


def test_a_spring_restored_hammer_is_identified_from_its_recording(tmp_path):
    """A 5 s recording of the design at 19 and 21 Hz (1/1 impacts, no free flight: f_n and zeta fixed)."""
    from harness.ident_rigs import Schedule, write_core_recording
    from rimd_sim.analysis.identification.identify import identify
    from rimd_sim.settings.config import SimConfig

    rig = {"pendulum_length": 0.023, "natural_frequency": 10.0, "mass": 1.0, "gap": 0.25e-3, "damping_ratio": 0.02,
           "motor.max_frequency": 30.0}
    path = tmp_path / "spring.mcap"
    write_core_recording(path, rig, Schedule([19.0, 21.0], dwell=2.5, start=1.0, seed=3))
    fixed = {"natural_frequency": 10.0, "damping_ratio": 0.02}
    base = SimConfig().with_parameters({"pendulum_length": 0.023, "motor.max_frequency": 30.0, **fixed})
    result = identify(path, base, fixed)
    truth = {**rig, "amplitude": SimConfig().rig.amplitude, "contact.stiffness": 5.5e6, "contact.damping": 1.2e3}
    assert set(result.estimates) >= {"mass", "contact.stiffness", "contact.damping", "gap"}
    for name, estimate in result.estimates.items():
        assert estimate.value == pytest.approx(truth[name], rel=0.01), name


def test_identification_geometry_follows_the_declared_length():
    cfg = _spring_config()
    assert cfg.rig.length_at(12.0) == 0.023   # the length stays; the spring takes the change
    gravity = cfg.with_parameters({"pendulum_length": 0.0})
    assert gravity.rig.length_at(10.0) == pytest.approx(9.81 / (2 * math.pi * 10.0) ** 2)


if __name__ == "__main__":
    for key, value in public_hashes().items():
        print(f"    {key!r}: {value!r},")
