"""The paper's model: one rigid hammer, a pendulum embarked on the cart, against a rigid force sensor.

Physics only, in the contract of :mod:`rimd_sim.model.kernel` (which builds the integration driver from it);
the registry :data:`rimd_sim.model.rig_model.MODELS` names it ``rigid``. No modes: the state is
``(theta, theta_dot, J)`` and a point is ``(theta, theta_dot)``.

The two-mass model (:mod:`rimd_sim.model.structural`) writes the same pendulum terms for its hammer's centre of
mass: numba's inlining of a shared helper into the sampled quantities cost more per sample than the terms.
"""

from __future__ import annotations

import math

import numpy as np

from rimd_sim.model.contact import CONTACT_LAWS
from rimd_sim.model.kernel import (
    CONTACT,
    F_VIMP,
    N_PARAM,
    P_A0,
    P_ATOL,
    P_C,
    P_E,
    P_EVTOL,
    P_GAP,
    P_GL,
    P_HCONT0,
    P_HMAX,
    P_K,
    P_KS,
    P_L,
    P_LAW,
    P_M,
    P_N,
    P_RTOL,
    P_VMIN,
    P_WN,
    P_ZETA,
    Q_FORCE,
    cart_accel,
    dense_theta,
    law_force,
    physics_inline,
    sincos,
)

N_MODES = 0
RINGS = False
HAMMER_MODES: tuple[int, ...] = ()


# ---- the pendulum's terms (every model's hammer) ---------------------------------------------------------


# ---- the contract of rimd_sim.model.kernel --------------------------------------------------------------


@physics_inline
def theta_accel(t, th, om, mode, p, fs):
    """Angular acceleration and contact force: the paper's Eqs. 2-3 with the sign erratum fixed.

    ``theta'' = -(a_c / l) cos(theta) - (g / l) sin(theta) - 2 zeta w_n theta' - F / (m l)``, where
    ``a_c = -A0 Omega^2 sin(Omega t)`` at constant motor speed. The contact force pushes the hammer out
    of the stop (the paper prints ``+F/(ml)``). A hammer whose length is set apart from its natural frequency
    (``pendulum_length``) adds its pivot's spring, ``- k_t theta / (m l^2)`` with ``k_t / (m l^2) = w_n^2 - g / l``.
    """
    s, c = sincos(th)
    lg = p[P_L]
    acc = -(cart_accel(fs, p, t) / lg) * c - p[P_GL] * s - 2.0 * p[P_ZETA] * p[P_WN] * om
    if p[P_KS] != 0.0:   # the pivot's spring (no spring: not a term, bit-identical)
        acc -= p[P_KS] * th
    force = 0.0
    if mode == CONTACT:
        force = law_force(lg * s - p[P_GAP], lg * om * c, p, fs[F_VIMP])
        acc -= force / (p[P_M] * lg)
    return acc, force


@physics_inline
def derivs(t, y, mode, p, fs):
    """Right-hand side of ``(theta, theta_dot, J)``."""
    acc, force = theta_accel(t, y[0], y[1], mode, p, fs)
    return y[1], acc, force


@physics_inline
def free_flight(y0, y1, h, p):
    """No mode to advance in closed form."""
    return y1


@physics_inline
def mode_scale(j, p):
    """No mode (never called)."""
    return 0.0


@physics_inline
def point(y):
    """``(theta, theta_dot)``."""
    return y[0], y[1]


@physics_inline
def dense_point(mode, ya, Q, h, x, p):
    """``(theta, theta_dot)`` at fraction ``x`` of the current step."""
    return dense_theta(ya, Q, h, x)


@physics_inline
def penetration(s, p):
    """Penetration ``delta = l sin(theta) - gap`` and its rate ``l theta' cos(theta)``."""
    sn, c = sincos(s[0])
    return p[P_L] * sn - p[P_GAP], p[P_L] * s[1] * c


@physics_inline
def sensor_force(force, s, p):
    """The sensor is rigid: it reads the law's force."""
    return force


@physics_inline
def force_free_is_zero(p):
    """No contact, no force."""
    return True


@physics_inline
def sample(qty, mode, s, p, fs, w, alpha, sp, cp):
    """The force (clipped at 0) or the hammer's inertial acceleration (``Q_FORCE``, ``Q_ACC``)."""
    om = s[1]
    sn, c = sincos(s[0])
    lg = p[P_L]
    if qty == Q_FORCE:
        if mode != CONTACT:
            return 0.0
        return max(law_force(lg * sn - p[P_GAP], lg * om * c, p, fs[F_VIMP]), 0.0)
    # The inertial acceleration x'' = l (theta'' cos - theta'^2 sin) + a_c, theta'' from the cart's a_c.
    ac = p[P_A0] * (alpha * cp - w * w * sp)
    acc = -(ac / lg) * c - p[P_GL] * sn - 2.0 * p[P_ZETA] * p[P_WN] * om
    if p[P_KS] != 0.0:   # the pivot's spring (no spring: not a term, bit-identical)
        acc -= p[P_KS] * s[0]
    if mode == CONTACT:
        acc -= law_force(lg * sn - p[P_GAP], lg * om * c, p, fs[F_VIMP]) / (p[P_M] * lg)
    return lg * (acc * c - om * om * sn) + ac


@physics_inline
def truth(mode, s, t, p, fs, xc, vc, ac):
    """``(x, v, a, delta, force)`` of the truth block: the hammer (inertial) and the contact.

    Written out in one function, sin and cos of theta once (the terms of :func:`theta_accel` and
    :func:`penetration`, in their order of operations), because numba's inlining of those functions here makes each
    truth sample markedly dearer.
    """
    th = s[0]
    om = s[1]
    sn, c = sincos(th)
    lg = p[P_L]
    acc = -(cart_accel(fs, p, t) / lg) * c - p[P_GL] * sn - 2.0 * p[P_ZETA] * p[P_WN] * om
    if p[P_KS] != 0.0:   # the pivot's spring (no spring: not a term, bit-identical)
        acc -= p[P_KS] * th
    d = lg * sn - p[P_GAP]
    force = 0.0
    if mode == CONTACT:
        acc -= law_force(d, lg * om * c, p, fs[F_VIMP]) / (p[P_M] * lg)
        force = max(law_force(d, lg * om * c, p, fs[F_VIMP]), 0.0)
    return lg * sn + xc, lg * om * c + vc, lg * (acc * c - om * om * sn) + ac, d, force


# ---- parameters ------------------------------------------------------------------------------------------


def params(config) -> np.ndarray:
    """The parameter vector (``kernel.P_*``) of a validated :class:`~rimd_sim.settings.config.SimConfig`."""
    rig = config.rig
    p = np.zeros(N_PARAM)
    c = rig.contact
    length = rig.length
    p[P_L] = length
    p[P_M] = rig.mass
    p[P_A0] = rig.amplitude
    p[P_GL] = rig.gravity / length
    p[P_WN] = rig.omega_n
    p[P_KS] = max(rig.omega_n ** 2 - rig.gravity / length, 0.0) if rig.pendulum_length > 0.0 else 0.0
    p[P_ZETA] = rig.damping_ratio
    p[P_GAP] = rig.gap
    p[P_LAW] = CONTACT_LAWS[c.model].code
    p[P_K] = c.stiffness
    p[P_C] = c.damping
    p[P_N] = 1.0 if c.model == "spring_dashpot" else c.exponent
    p[P_E] = c.restitution
    p[P_VMIN] = c.min_impact_velocity
    p[P_RTOL] = config.integrator.rtol
    p[P_ATOL] = config.integrator.atol
    p[P_HMAX] = config.integrator.max_step
    p[P_EVTOL] = config.integrator.event_tolerance
    # First contact step: 1/40 of the period of the linearised contact oscillator at 1 um penetration.
    n = p[P_N]
    k_eff = c.stiffness * n * (1e-6 ** (n - 1.0))
    p[P_HCONT0] = min(config.integrator.max_step, 2.0 * math.pi * math.sqrt(rig.mass / k_eff) / 40.0)
    return p
