"""Largest Lyapunov exponent of the non-smooth rig model, and the chaos criterion.

Method: two trajectories (Benettin et al., 1980) on the full non-smooth flow
-----------------------------------------------------------------------------
The model is a Filippov system with a finite contact stiffness: inside each mode the flow is smooth, and the
switches (contact start when ``delta`` rises through 0, release when the force falls through 0) are located
exactly by the integrator. The largest exponent is measured on the stroboscopic (Poincare) map ``P``, which
advances the state ``(theta, theta_dot)`` by one excitation period ``T = 1 / f``:

1. run the reference trajectory through a transient; let ``x_k`` be its stroboscopic points;
2. at each ``x_k`` start a companion trajectory at ``x_k + d0 w_k`` (``w_k`` a unit vector, norm below),
   integrate it over one period with the same event-located integrator, and measure
   ``d_k = |P(x_k + d0 w_k) - x_{k+1}|``;
3. renormalise: ``w_{k+1} = (P(x_k + d0 w_k) - x_{k+1}) / d_k``;
4. ``lambda = sum_k log(d_k / d0) / (N T)`` (1/s).

Why this method: the companion trajectory crosses the switching surfaces where the dynamics puts it, so the
discontinuities of the linearised flow at the switches (the saltation matrices a tangent-linear method must
add by hand, and which for the force-vanishing release of Filippov's rule need the second switching
function) are included without extra code, with the same integrator the rest of the twin uses. The cost is
one extra period per period. ``d0`` must be small enough for the linear regime and large against the
integration error: here ``d0 = 1e-7`` (rad) with tolerances 1e-10 / 1e-12, so the per-period error of a
ratio is below 1e-4. Renormalising every period keeps the separation in the linear regime even for the
fastest divergence seen (a factor ~10 per period).

The norm: ``|(dtheta, dtheta_dot)| = sqrt(dtheta^2 + (dtheta_dot / Omega)^2)``.

Every model of :data:`rimd_sim.model.rig_model.MODELS` runs. A model with modes of its own (the two-mass hammer's
axial mode and the sensor's mount: ``u, u', s, s'``) has a larger state; its companion starts from the
reference's whole stroboscopic state (the modes carried by the point, :class:`~rimd_sim.model.rig_model.StroboPoint`)
with the perturbation in ``(theta, theta_dot)``, and the separation is measured in the norm above, so what
the modes' deviation is at the end of a period is not carried into the next. The modes are excited only by
the impacts and die out between them (4.5 and 19 kHz at a damping ratio of 0.05 in the preset: their own
exponents are about -1,400 and -6,100 1/s), so the expansion of the map over a period is the pendulum's.

Validation (tests/analysis/dynamics/test_lyapunov.py): the linear damped oscillator (large gap, small amplitude,
no impact), whose exponents are both ``-zeta omega_n``; the undamped linear oscillator (exponent 0); a stable period-1
impacting orbit (negative).

Chaos criterion
---------------
A motion is called chaotic when both hold: the largest exponent is above :data:`CHAOS_THRESHOLD` (1/s), and
its Poincare points do not converge to a finite set of at most ``max_period`` points
(:func:`rimd_sim.analysis.dynamics.steady.classify` gives ``chaotic/non-periodic``). The threshold is well above the
estimator's scatter for periodic and quasi-periodic motions (|lambda| < 0.02 1/s over 300 periods for the
undamped linear oscillator and quasi-periodic motions; periodic orbits are strongly negative) and below
the exponents measured in the chaotic windows (0.1-1.2 1/s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rimd_sim.analysis.dynamics.steady import CHAOTIC, check_frequency, constant_frequency, steady_orbit
from rimd_sim.errors import ConfigError
from rimd_sim.model.rig_model import ChatteringError, RigModel
from rimd_sim.model.validity import PointMeasures, domain
from rimd_sim.settings.config import SimConfig

__all__ = ["CHAOS_THRESHOLD", "LyapunovResult", "is_chaotic", "largest_lyapunov"]

#: Largest exponent (1/s) above which a non-periodic motion is called chaotic.
CHAOS_THRESHOLD = 0.05

#: Tolerances of the Lyapunov runs (tighter than the defaults, see the module docstring).
LYAPUNOV_TOLERANCES = {"integrator.rtol": 1e-10, "integrator.atol": 1e-12}


@dataclass(frozen=True)
class LyapunovResult:
    """Largest Lyapunov exponent at one parameter point.

    Attributes:
        frequency_hz: Motor frequency (Hz).
        exponent: Largest Lyapunov exponent (1/s).
        per_cycle: The same per excitation period (``exponent / f``), the log of the map's growth factor.
        running: Running estimate after each period (1/s): its settling shows convergence.
        cycles: Periods averaged.
        max_abs_theta_rad: Largest ``|theta|`` of the reference trajectory (rad).
        max_force_n: Largest peak force of the reference trajectory (N).
        valid: Whether the point lies in the model's valid domain (:mod:`rimd_sim.model.validity`); where the
            chattering guard fired (reference or companion) the exponent is NaN.
        invalid_rule: The rules it broke (``;``-separated names), ``""`` when valid.
    """

    frequency_hz: float
    exponent: float
    per_cycle: float
    running: np.ndarray
    cycles: int
    max_abs_theta_rad: float = math.nan
    max_force_n: float = math.nan
    valid: bool = True
    invalid_rule: str = ""


def _strobe_after_one_period(config: SimConfig, f: float, theta: float, theta_dot: float,
                             modes: tuple[float, ...]) -> tuple[float, float]:
    model = RigModel(constant_frequency(config, f, theta, theta_dot), channels=False, truth=False, strobe=True,
                     initial_modes=modes)
    out = model.advance(1.5 / f)
    s = next(s for s in out.strobe if s.cycle_index == 1)
    return s.theta, s.theta_dot


def largest_lyapunov(config: SimConfig, frequency_hz: float, *, theta0: float = 0.0, theta_dot0: float = 0.0,
                     transient_cycles: int = 200, cycles: int = 300, d0: float = 1e-7,
                     seed: int = 0) -> LyapunovResult:
    """Largest Lyapunov exponent by the two-trajectory method on the stroboscopic map (module docstring).

    Args:
        config: Rig configuration (its integrator tolerances are tightened to 1e-10 / 1e-12).
        frequency_hz: Constant motor frequency (Hz).
        theta0: Initial angle (rad) of the reference trajectory.
        theta_dot0: Initial rate (rad/s).
        transient_cycles: Periods run before measuring.
        cycles: Periods averaged.
        d0: Separation of the companion trajectory (norm in the module docstring).
        seed: Seed of the initial direction.

    Returns:
        The exponent (1/s), its running estimate and the valid domain's verdict (NaN exponent where the chattering
        guard fired).

    Raises:
        ConfigError: For a bad frequency, cycle count or ``d0``.
    """
    f = check_frequency(config, frequency_hz)
    if cycles < 1 or transient_cycles < 0:
        raise ConfigError("cycles", cycles, "must be >= 1 (and transient_cycles >= 0)")
    if not 0 < d0 < 1e-3:
        raise ConfigError("d0", d0, "must be in (0, 1e-3)")
    omega = 2.0 * math.pi * f
    cfg = config.with_parameters(LYAPUNOV_TOLERANCES)
    rules = domain(config)
    chattering = LyapunovResult(f, math.nan, math.nan, np.full(cycles, math.nan), cycles, valid=False,
                                invalid_rule=rules.check(PointMeasures(chattering=True)).invalid_rule)
    ref = RigModel(constant_frequency(cfg, f, theta0, theta_dot0), channels=False, truth=False, strobe=True)
    try:
        out = ref.advance((transient_cycles + cycles + 0.5) / f)
    except ChatteringError:
        return chattering
    max_force = max((i.peak_force for i in out.impacts), default=0.0)
    rate = sum(transient_cycles <= i.cycle_index < transient_cycles + cycles for i in out.impacts) / cycles
    verdict = rules.check(PointMeasures(out.max_abs_theta, max_force, rate))
    pts = {s.cycle_index: s for s in out.strobe}
    angle = np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi)
    w = np.array([math.cos(angle), math.sin(angle)])
    logs = np.empty(cycles)
    for i in range(cycles):
        s, nxt = pts[transient_cycles + i], pts[transient_cycles + i + 1]
        try:
            pth, pom = _strobe_after_one_period(cfg, f, s.theta + d0 * w[0], s.theta_dot + d0 * w[1] * omega,
                                                s.modes)
        except ChatteringError:
            return chattering
        diff = np.array([pth - nxt.theta, (pom - nxt.theta_dot) / omega])
        d = float(np.hypot(*diff))
        if d == 0.0:  # the companion merged (numerically) with the reference: strongest contraction seen
            d = d0 * 1e-12
            diff = w * d
        logs[i] = math.log(d / d0)
        w = diff / d
    running = np.cumsum(logs) * f / np.arange(1, cycles + 1)
    return LyapunovResult(f, float(running[-1]), float(running[-1] / f), running, cycles, out.max_abs_theta,
                          max_force, verdict.valid, verdict.invalid_rule)


def is_chaotic(config: SimConfig, frequency_hz: float, *, theta0: float = 0.0, theta_dot0: float = 0.0,
               transient_cycles: int = 200, cycles: int = 300) -> tuple[bool, float, str]:
    """The chaos criterion (module docstring) at one point.

    Args:
        config: Rig configuration.
        frequency_hz: Constant motor frequency (Hz).
        theta0: Initial angle (rad).
        theta_dot0: Initial rate (rad/s).
        transient_cycles: Periods run before measuring.
        cycles: Periods averaged (the exponent) and classified (at most 96).

    Returns:
        ``(chaotic, exponent, label)``: the verdict, the largest exponent (1/s) and the Poincare class.
    """
    orbit = steady_orbit(config, frequency_hz, theta0=theta0, theta_dot0=theta_dot0,
                         transient_cycles=transient_cycles, measure_cycles=min(cycles, 96))
    lyap = largest_lyapunov(config, frequency_hz, theta0=theta0, theta_dot0=theta_dot0,
                            transient_cycles=transient_cycles, cycles=cycles)
    return (lyap.exponent > CHAOS_THRESHOLD and orbit.label == CHAOTIC), lyap.exponent, orbit.label
