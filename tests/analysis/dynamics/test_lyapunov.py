"""Largest Lyapunov exponent of the non-smooth model: validated on known cases, then the chaotic windows."""

from __future__ import annotations

import math

import pytest

from rimd_sim.analysis.dynamics.lyapunov import CHAOS_THRESHOLD, is_chaotic, largest_lyapunov
from rimd_sim.errors import ConfigError
from rimd_sim.settings.config import SimConfig, find_config_file, load_config

LINEAR = {"gap": 0.03, "amplitude": 1e-4}  # the hammer never reaches the stop; theta ~ 1e-3: linear


def test_linear_damped_oscillator_gives_minus_zeta_omega_n():
    """Without impact and at small amplitude the model is the base-excited linear oscillator; the variational
    equation is x'' + 2 zeta w_n x' + w_n^2 x = 0, whose two exponents are both -zeta w_n (underdamped), so
    lambda_max = -zeta w_n = -0.088 * 2 pi * 1.763 = -0.975 1/s with the defaults."""
    cfg = SimConfig().with_parameters(LINEAR)
    lyap = largest_lyapunov(cfg, 2.5, transient_cycles=20, cycles=100)
    assert lyap.exponent == pytest.approx(-cfg.rig.damping_ratio * 2 * math.pi * cfg.rig.natural_frequency, rel=0.03)


def test_undamped_linear_oscillator_gives_zero():
    """Same without damping: a centre, exponent 0 (the estimator's scatter is below the chaos threshold)."""
    cfg = SimConfig().with_parameters({**LINEAR, "damping_ratio": 0.0})
    lyap = largest_lyapunov(cfg, 2.5, transient_cycles=20, cycles=100)
    assert abs(lyap.exponent) < 0.02 < CHAOS_THRESHOLD


def test_stable_period_1_impact_orbit_is_negative():
    """Band A at gap 0 (3.75 Hz): a stable period-1 impacting orbit, every perturbation decays; the
    companion trajectory crosses the switching surfaces on its own, so the contraction by the impacts
    (restitution ~0.3) makes the exponent far more negative than the structural damping alone."""
    cfg = SimConfig()
    lyap = largest_lyapunov(cfg, 3.75)
    assert lyap.exponent < -cfg.rig.damping_ratio * 2 * math.pi * cfg.rig.natural_frequency


def test_bad_input_is_refused():
    with pytest.raises(ConfigError, match="d0"):
        largest_lyapunov(SimConfig(), 3.0, d0=0.0)
    with pytest.raises(ConfigError, match="frequency"):
        largest_lyapunov(SimConfig(), 0.0)


@pytest.mark.parametrize(("frequency", "chaotic"), [(4.3, False), (4.4, False), (4.45, True), (4.6, True),
                                                    (4.75, True), (4.9, False)])
def test_chaotic_window_at_gap_1mm_defaults(frequency, chaotic):
    """The paper (Fig. 11, text): chaos in the transition band at gap 1.0 mm. With the defaults, measured from rest on
    a 0.05 Hz grid (200 + 300 cycles): chaotic at 4.45-4.75 Hz (lambda 0.34-0.93 1/s); 4.3 Hz is 4/4, 4.4 Hz 2/2,
    4.9 Hz 1/2. Criterion: lambda_max > CHAOS_THRESHOLD and the Poincare points not converging."""
    cfg = SimConfig().with_parameters({"gap": 1.0e-3})
    verdict, exponent, label = is_chaotic(cfg, frequency)
    assert verdict is chaotic, (exponent, label)


@pytest.mark.parametrize(("frequency", "chaotic"), [(3.1, False), (3.15, True), (3.3, True), (3.45, True),
                                                    (3.6, True), (3.7, False)])
def test_chaotic_window_at_gap_2_4mm_paper_model(frequency, chaotic):
    """docs/interface.md, "What the twin must reproduce": the paper-model preset (m = 1 kg, no structural damping) is
    chaotic at gap 2.4 mm at about 3.15-3.6 Hz. Measured from rest on a 0.05 Hz grid: period 1 (1/1) up to 3.10 Hz,
    chaotic from 3.15 to 3.65 Hz (lambda 0.12-1.27 1/s), a periodic window at 3.70 Hz (6/10); above it chaos and
    periodic windows alternate (chaotic again at 3.75, 3.9, 3.95 Hz)."""
    cfg = load_config(find_config_file("paper_model.yaml"), {"gap": 2.4e-3})
    verdict, exponent, label = is_chaotic(cfg, frequency)
    assert verdict is chaotic, (exponent, label)
