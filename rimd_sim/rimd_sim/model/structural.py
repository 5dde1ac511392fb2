"""Structural contact model: the impact as the sensors see it (docs/physics.md, "Structural model").

The paper's model (:mod:`rimd_sim.model.rigid`) is one rigid hammer against a rigid force sensor. Its own
measurements show more (section 2.1, Fig. 3): a first force peak of about 80 N, then a second of about 50 N
as the impacted structure gives an impulse back, and an accelerometer that rings after each impact (the
authors' hypothesis: an axial vibration of the hammer). This model adds the two missing structures:

* the hammer as two masses along the impact line, the impact device in front (``m1``) and the aluminium
  coupling that carries the accelerometer behind (``m2 = m - m1``), joined by the hammer's axial stiffness
  ``ka`` and damping ``ca``. The pendulum angle ``theta`` describes the hammer's centre of mass
  ``X = l sin(theta)``; ``u`` is the extension of the link, so ``x1 = X + (m2/m) u`` and
  ``x2 = X - (m1/m) u``. Gravity, the wires and the cart's acceleration act on each mass in proportion to
  it, so they cancel in ``u``; only the contact force excites the axial mode:
  ``m theta'' l = (the paper's Eq. 2 terms) - F`` and ``mu u'' = -ka u - ca u' - (m2/m) F``
  (``mu = m1 m2 / m``);
* the force sensor's top (mass ``ms``) on a compliant mount (``km``, ``cm``) fixed to the cart:
  ``ms s'' = F - km s - cm s'``; the sensor reads the force through its mount, ``km s + cm s'``. (The
  cart's acceleration on ``ms`` is left out: its reading ``ms a_c`` is below 0.05 N at the rig's
  frequencies.)

The penetration is ``delta = x1 - s - gap = l sin(theta) + (m2/m) u - s - gap`` and the contact law is the
configured one (paper Eq. 1). The accelerometer reads the rear mass, ``x2''`` (inertial).

Physics only, in the contract of :mod:`rimd_sim.model.kernel` (the one driver, built from this module; the
registry :data:`rimd_sim.model.rig_model.MODELS` names it ``two_mass``). Four modes, ``(u, u', s, s')``: the state
is ``(theta, theta', J, u, u', s, s')``. **How the step stays affordable:** in contact every component is
integrated and the modes are error-controlled (scaled by ``1 / l`` into the pendulum's units; the fast modes
set the step, ~1 ms per impact); in free flight the axial mode and the sensor mode are linear, unforced and
decoupled from the pendulum, so they follow their exact closed form (damped oscillators, :func:`ring`) and the
free step is the paper model's (up to 10 ms), however long the ringing lasts (``RINGS``: the driver then
samples ``delta`` eight times per ringing period near the stop, so a re-contact on the ring is not stepped
over).

A stiffness of 0 means a rigid link or mount: the component stays exactly 0 and drops out of the error
norm. With both rigid, every floating-point operation of a step is that of the paper's model, so the
two-mass model *is* the paper's model in that special case (tested: bit-identical impacts).
"""

from __future__ import annotations

import math

import numpy as np

import rimd_sim.model.rigid as rigid
from rimd_sim.model.kernel import (
    CONTACT,
    F_VIMP,
    N_PARAM,
    P_A0,
    P_GAP,
    P_GL,
    P_HCONT0,
    P_KS,
    P_L,
    P_M,
    P_WN,
    P_ZETA,
    Q_FORCE,
    RING_NEGLIGIBLE,
    TWO_PI,
    cart_accel,
    dense_comp,
    dense_theta,
    law_force,
    physics_inline,
    sincos,
)

# ---- parameters (after the paper model's) ------------------------------------------------------------------
(P_AX, P_R1, P_R2, P_M1, P_MU, P_KA, P_CA, P_WA, P_ZA,
 P_MT, P_MS, P_KM, P_CM, P_WM, P_ZM) = range(N_PARAM, N_PARAM + 15)
N_SPARAM = N_PARAM + 15

N_MODES = 4  # u, u', s, s'
RINGS = True
#: A reset of the hammer puts its axial mode at rest (the sensor keeps ringing).
HAMMER_MODES = (3, 4)

# A mode whose amplitude has decayed below this (m) is set to exactly 0 at the start of a free step (its
# reading: < 1e-6 N through the mount, < 1e-5 m/s^2 on the accelerometer), so that it costs nothing more.
RING_SNAP = 1e-15


# ---- the modes in free flight ----------------------------------------------------------------------------


@physics_inline
def ring(x0, v0, tau, w0, z):
    """Free damped oscillator ``x'' + 2 z w0 x' + w0^2 x = 0`` (``z < 1``) after ``tau``: ``(x, x')``."""
    sigma = z * w0
    wd = w0 * math.sqrt(1.0 - z * z)
    e = math.exp(-sigma * tau)
    c = math.cos(wd * tau)
    s = math.sin(wd * tau)
    b = (v0 + sigma * x0) / wd
    return e * (x0 * c + b * s), e * (v0 * c - (w0 * w0 * x0 + sigma * v0) / wd * s)


@physics_inline
def ring_envelope(x0, v0, w0, z):
    """Bound on ``|x|`` of the free oscillator from ``(x0, v0)`` on (it only decays from there)."""
    sigma = z * w0
    wd = w0 * math.sqrt(1.0 - z * z)
    b = (v0 + sigma * x0) / wd
    return math.sqrt(x0 * x0 + b * b)


@physics_inline
def free_modes(y, tau, p):
    """Axial and mount states ``(u, u', s, s')`` a time ``tau`` after ``y`` in free flight (exact)."""
    u = 0.0
    up = 0.0
    sm = 0.0
    smp = 0.0
    if p[P_AX] != 0.0 and (y[3] != 0.0 or y[4] != 0.0):
        u, up = ring(y[3], y[4], tau, p[P_WA], p[P_ZA])
    if p[P_MT] != 0.0 and (y[5] != 0.0 or y[6] != 0.0):
        sm, smp = ring(y[5], y[6], tau, p[P_WM], p[P_ZM])
    return u, up, sm, smp


@physics_inline
def ring_amplitude(y, p):
    """Bound on how far the ringing modes can move ``delta`` from now on (m)."""
    a = 0.0
    if p[P_AX] != 0.0:
        a += abs(p[P_R2]) * ring_envelope(y[3], y[4], p[P_WA], p[P_ZA])
    if p[P_MT] != 0.0:
        a += ring_envelope(y[5], y[6], p[P_WM], p[P_ZM])
    return a


@physics_inline
def ring_period(p, y):
    """Shortest period (s) of the modes still ringing by more than ``kernel.RING_NEGLIGIBLE``, or inf."""
    w = 0.0
    if p[P_AX] != 0.0 and abs(p[P_R2]) * ring_envelope(y[3], y[4], p[P_WA], p[P_ZA]) > RING_NEGLIGIBLE:
        w = p[P_WA]
    if p[P_MT] != 0.0 and ring_envelope(y[5], y[6], p[P_WM], p[P_ZM]) > RING_NEGLIGIBLE:
        w = max(w, p[P_WM])
    if w == 0.0:
        return np.inf
    return TWO_PI / w


@physics_inline
def settle(y, p):
    """Set a mode that has decayed below :data:`RING_SNAP` to exactly 0 (free flight only).

    A rigid link or mount (after a reconfiguration) has its component at 0 too.
    """
    if (y[3] != 0.0 or y[4] != 0.0) and (p[P_AX] == 0.0 or ring_envelope(y[3], y[4], p[P_WA], p[P_ZA]) < RING_SNAP):
        y[3] = 0.0
        y[4] = 0.0
    if (y[5] != 0.0 or y[6] != 0.0) and (p[P_MT] == 0.0 or ring_envelope(y[5], y[6], p[P_WM], p[P_ZM]) < RING_SNAP):
        y[5] = 0.0
        y[6] = 0.0


# ---- the contract of rimd_sim.model.kernel --------------------------------------------------------------


@physics_inline
def penetration(s, p):
    """Penetration ``delta = l sin(theta) + (m2/m) u - s - gap`` and its rate."""
    sn, c = sincos(s[0])
    lg = p[P_L]
    return lg * sn + p[P_R2] * s[2] - s[4] - p[P_GAP], lg * s[1] * c + p[P_R2] * s[3] - s[5]


@physics_inline
def rates(t, th, om, u, up, sm, smp, mode, p, fs):
    """``(theta', theta'', F, u', u'', s', s'')``; in free flight only the pendulum's (the modes are exact)."""
    sn, c = sincos(th)
    lg = p[P_L]
    # The pendulum's terms, as rimd_sim.model.rigid.theta_accel writes them.
    acc = -(cart_accel(fs, p, t) / lg) * c - p[P_GL] * sn - 2.0 * p[P_ZETA] * p[P_WN] * om
    if p[P_KS] != 0.0:   # the pivot's spring (no spring: not a term, bit-identical)
        acc -= p[P_KS] * th
    if mode != CONTACT:
        return om, acc, 0.0, 0.0, 0.0, 0.0, 0.0
    force = law_force(lg * sn + p[P_R2] * u - sm - p[P_GAP], lg * om * c + p[P_R2] * up - smp, p, fs[F_VIMP])
    acc -= force / (p[P_M] * lg)
    upp = 0.0
    if p[P_AX] != 0.0:
        upp = -(p[P_KA] * u + p[P_CA] * up) / p[P_MU] - force / p[P_M1]
    spp = 0.0
    if p[P_MT] != 0.0:
        spp = (force - p[P_KM] * sm - p[P_CM] * smp) / p[P_MS]
    return om, acc, force, up, upp, smp, spp


@physics_inline
def derivs(t, y, mode, p, fs):
    """Right-hand side of ``(theta, theta', J, u, u', s, s')``."""
    return rates(t, y[0], y[1], y[3], y[4], y[5], y[6], mode, p, fs)


@physics_inline
def free_flight(y0, y1, h, p):
    """The pendulum as the stages computed it, the modes by their closed form."""
    u, up, sm, smp = free_modes(y0, h, p)
    return y1[0], y1[1], y1[2], u, up, sm, smp


@physics_inline
def mode_scale(j, p):
    """The error weight of mode ``j`` in contact: ``l`` where controlled, 0 where not.

    ``u`` and ``u'`` (``j`` 0, 1) of a compliant link and ``s``, ``s'`` of a compliant mount are error-controlled,
    their absolute tolerance scaled by ``l`` (from the pendulum's radians into metres).
    """
    if (j < 2 and p[P_AX] != 0.0) or (j >= 2 and p[P_MT] != 0.0):
        return p[P_L]
    return 0.0


@physics_inline
def point(y):
    """``(theta, theta', u, u', s, s')``."""
    return y[0], y[1], y[3], y[4], y[5], y[6]


@physics_inline
def dense_point(mode, ya, Q, h, x, p):
    """The point at fraction ``x`` of the current step.

    The modes come from the dense output in contact, from their closed form in free flight.
    """
    th, om = dense_theta(ya, Q, h, x)
    if mode == CONTACT:
        return (th, om, dense_comp(ya, Q, h, x, 3), dense_comp(ya, Q, h, x, 4), dense_comp(ya, Q, h, x, 5),
                dense_comp(ya, Q, h, x, 6))
    u, up, sm, smp = free_modes(ya, x * h, p)
    return th, om, u, up, sm, smp


@physics_inline
def sensor_force(force, s, p):
    """The force through the mount, ``km s + cm s'`` (the law's force, clipped at 0, if the mount is rigid)."""
    if p[P_MT] != 0.0:
        return p[P_KM] * s[4] + p[P_CM] * s[5]
    return max(force, 0.0)


@physics_inline
def force_free_is_zero(p):
    """Only a rigid mount reads exactly 0 outside contact (a compliant one rings)."""
    return p[P_MT] == 0.0


@physics_inline
def rear_accel(xdd, u, up, force, mode, p):
    """The rear mass's inertial acceleration (the accelerometer's), ``X'' - (m1/m) u''``, from ``X''``."""
    if p[P_AX] == 0.0:
        return xdd
    upp = -(p[P_KA] * u + p[P_CA] * up) / p[P_MU]
    if mode == CONTACT:
        upp -= force / p[P_M1]
    return xdd - p[P_R1] * upp


@physics_inline
def sample(qty, mode, s, p, fs, w, alpha, sp, cp):
    """The force through the mount (``Q_FORCE``) or the rear mass's acceleration (``Q_ACC``)."""
    if qty == Q_FORCE:
        if p[P_MT] != 0.0:
            return sensor_force(0.0, s, p)  # through the mount: the law's force is not needed
        if mode != CONTACT:
            return 0.0
        d, dd = penetration(s, p)
        return sensor_force(law_force(d, dd, p, fs[F_VIMP]), s, p)
    om = s[1]
    sn, c = sincos(s[0])
    lg = p[P_L]
    force = 0.0
    if mode == CONTACT:
        force = law_force(lg * sn + p[P_R2] * s[2] - s[4] - p[P_GAP], lg * om * c + p[P_R2] * s[3] - s[5], p,
                          fs[F_VIMP])
    ac = p[P_A0] * (alpha * cp - w * w * sp)  # the centre of mass's x'', as rimd_sim.model.rigid.sample writes it
    acc = -(ac / lg) * c - p[P_GL] * sn - 2.0 * p[P_ZETA] * p[P_WN] * om
    if p[P_KS] != 0.0:   # the pivot's spring (no spring: not a term, bit-identical)
        acc -= p[P_KS] * s[0]
    if mode == CONTACT:
        acc -= force / (p[P_M] * lg)
    return rear_accel(lg * (acc * c - om * om * sn) + ac, s[2], s[3], force, mode, p)


@physics_inline
def truth(mode, s, t, p, fs, xc, vc, ac):
    """``(x, v, a, delta, force)`` of the truth block.

    The centre of mass's position and velocity, the rear mass's acceleration, the law's force (not the mount's).
    Written out, sin and cos of theta once (the terms of :func:`rates`, in their order of operations), as
    :func:`rimd_sim.model.rigid.truth` is.
    """
    th, om, u, up, sm, smp = s
    sn, c = sincos(th)
    lg = p[P_L]
    xdd = -(cart_accel(fs, p, t) / lg) * c - p[P_GL] * sn - 2.0 * p[P_ZETA] * p[P_WN] * om
    if p[P_KS] != 0.0:   # the pivot's spring (no spring: not a term, bit-identical)
        xdd -= p[P_KS] * th
    delta = lg * sn + p[P_R2] * u - sm - p[P_GAP]
    force = 0.0
    if mode == CONTACT:
        force = law_force(delta, lg * om * c + p[P_R2] * up - smp, p, fs[F_VIMP])
        xdd -= force / (p[P_M] * lg)
    xdd = lg * (xdd * c - om * om * sn) + ac
    return lg * sn + xc, lg * om * c + vc, rear_accel(xdd, u, up, force, mode, p), delta, max(force, 0.0)


# ---- parameters ------------------------------------------------------------------------------------------


def params(config) -> np.ndarray:
    """The parameter vector: the paper model's (:func:`rimd_sim.model.rigid.params`), then the structure's."""
    rig = config.rig
    st = rig.structure
    p = np.zeros(N_SPARAM)
    p[:N_PARAM] = rigid.params(config)
    m = rig.mass
    periods = []
    if st.axial_stiffness > 0.0:
        m1 = st.impactor_mass
        m2 = m - m1
        mu = m1 * m2 / m
        wa = math.sqrt(st.axial_stiffness / mu)
        p[P_AX] = 1.0
        p[P_R1] = m1 / m
        p[P_R2] = m2 / m
        p[P_M1] = m1
        p[P_MU] = mu
        p[P_KA] = st.axial_stiffness
        p[P_CA] = 2.0 * st.axial_damping_ratio * wa * mu
        p[P_WA] = wa
        p[P_ZA] = st.axial_damping_ratio
        periods += [2.0 * math.pi / wa, 2.0 * math.pi * math.sqrt(m1 / rig.contact.stiffness)]
    if st.mount_stiffness > 0.0:
        ms = st.sensor_mass
        wm = math.sqrt(st.mount_stiffness / ms)
        p[P_MT] = 1.0
        p[P_MS] = ms
        p[P_KM] = st.mount_stiffness
        p[P_CM] = 2.0 * st.mount_damping_ratio * wm * ms
        p[P_WM] = wm
        p[P_ZM] = st.mount_damping_ratio
        periods.append(2.0 * math.pi * math.sqrt(ms / (st.mount_stiffness + rig.contact.stiffness)))
    if periods:
        p[P_HCONT0] = min([p[P_HCONT0]] + [t / 40.0 for t in periods])
    return p
