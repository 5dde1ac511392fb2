"""Structural contact model: the impact as the sensors see it (issue 15).

The paper's model (:mod:`rimd_sim.core.kernel`) is one rigid hammer against a rigid force sensor. Its own
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

Method (same class as :mod:`~rimd_sim.core.kernel`, which this module reuses for the motor, records and
constants): state ``(theta, theta', J, u, u', s, s')``, Dormand-Prince 5(4) with event-exact Filippov
switching (contact onset when ``delta`` rises through 0, release when the law's force falls through 0 or
``delta`` through 0, re-contact when the force rises again), switches located on the dense output by the
Illinois method. **How the step stays affordable:** in contact all seven components are integrated and
error-controlled (the fast modes set the step, ~1 ms per impact); in free flight the axial mode and the
sensor mode are linear, unforced and decoupled from the pendulum, so they are advanced by their exact
closed-form solution (damped oscillators) and the free step is the paper model's (up to 10 ms), however
long the ringing lasts. While a mode still rings near the stop, the contact-onset test samples
``delta`` at eight points per ringing period, so a re-contact on the ring is not stepped over.

A stiffness of 0 means a rigid link or mount: the component stays exactly 0 and drops out of the error
norm. With both rigid, every floating-point operation of a step is that of the paper's kernel, so the
two-mass model *is* the paper's model in that special case (tested to 1e-6, in fact bit-identical impacts).
"""

from __future__ import annotations

import math

import numpy as np

from . import kernel as k
from .kernel import (
    _E,
    _P,
    CONTACT,
    EV_CLOSE,
    EV_ENTER,
    EV_EXIT,
    EV_EXIT_CLOSE,
    EV_MOTOR,
    EV_NONE,
    EV_REENTER,
    F_H,
    F_HCONT,
    F_HFREE,
    F_MALPHA,
    F_MPHI0,
    F_MT0,
    F_MTEND,
    F_MW0,
    F_RJ,
    F_RLAST,
    F_RPEAK,
    F_RPEN,
    F_TA,
    F_TB,
    F_VIMP,
    F_ZT0,
    FREE,
    I_CYC,
    I_MODE,
    I_NEEDF,
    I_NEV,
    I_NREJ,
    I_NSTEP,
    I_PEND,
    I_REC,
    I_RSUB,
    I_STRK,
    I_STROUT,
    I_ZCNT,
    N_ISTATE,
    N_RECORD,
    N_TRUTH,
    P_A0,
    P_ATOL,
    P_EVTOL,
    P_GAP,
    P_GL,
    P_HMAX,
    P_L,
    P_M,
    P_RTOL,
    P_WN,
    P_ZETA,
    Q_CART,
    Q_FORCE,
    Q_RIMD,
    S_CYCLE,
    S_OMEGA,
    S_T,
    S_THETA,
    ST_IMPACTS_FULL,
    ST_NONFINITE,
    ST_OK,
    ST_STEP_UNDERFLOW,
    ST_STROBE_FULL,
    ST_ZENO,
    T_A,
    T_CONTACT,
    T_DELTA,
    T_F,
    T_FREQ,
    T_OMEGA,
    T_PHASE,
    T_THETA,
    T_V,
    T_X,
    T_XC,
    TWO_PI,
    ZENO_MAX_EVENTS,
    ZENO_WINDOW,
    _jit,
    _jit_inline,
    cart_accel,
    cart_kinematics,
    close_record,
    dense_theta,
    hermite_peak,
    law_force,
    motor_finish_ramp,
    motor_freq,
    motor_phase,
    motor_rebase,
    sincos,
)

__all__ = ["N_STATE", "StructuralModel", "make_model", "structural_params"]

# ---- extra parameters (after the paper kernel's 18) --------------------------------------------------
(P_AX, P_R1, P_R2, P_M1, P_MU, P_KA, P_CA, P_WA, P_ZA,
 P_MT, P_MS, P_KM, P_CM, P_WM, P_ZM) = range(k.N_PARAM, k.N_PARAM + 15)
N_SPARAM = k.N_PARAM + 15

N_STATE = 7  # theta, theta', J, u, u', s, s'
N_FSTATE = k.N_FSTATE

# Most samples of delta per step while a mode rings near the stop (8 per ringing period); a longer free
# step is cut to this many samples.
RING_SAMPLES_MAX = 512
# A ring that moves delta by less than this (m) is not scanned for re-contacts: one it could cause would carry
# less than k x 1e-10 m = 0.55 mN with the paper's contact stiffness.
RING_NEGLIGIBLE = 1e-10
# A mode whose amplitude has decayed below this (m) is set to exactly 0 at the start of a free step (its
# reading: < 1e-6 N through the mount, < 1e-5 m/s^2 on the accelerometer), so that it costs nothing more.
RING_SNAP = 1e-15


# ======================================================================================================
# Physics
# ======================================================================================================


@_jit_inline
def ring(x0, v0, tau, w0, z):
    """Free damped oscillator ``x'' + 2 z w0 x' + w0^2 x = 0`` (``z < 1``) after ``tau``: ``(x, x')``."""
    sigma = z * w0
    wd = w0 * math.sqrt(1.0 - z * z)
    e = math.exp(-sigma * tau)
    c = math.cos(wd * tau)
    s = math.sin(wd * tau)
    b = (v0 + sigma * x0) / wd
    return e * (x0 * c + b * s), e * (v0 * c - (w0 * w0 * x0 + sigma * v0) / wd * s)


@_jit_inline
def ring_envelope(x0, v0, w0, z):
    """Bound on ``|x|`` of the free oscillator from ``(x0, v0)`` on (it only decays from there)."""
    sigma = z * w0
    wd = w0 * math.sqrt(1.0 - z * z)
    b = (v0 + sigma * x0) / wd
    return math.sqrt(x0 * x0 + b * b)


@_jit_inline
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


@_jit_inline
def pen(th, om, u, up, sm, smp, p):
    """Penetration ``delta = l sin(theta) + (m2/m) u - s - gap`` and its rate."""
    s, c = sincos(th)
    lg = p[P_L]
    return lg * s + p[P_R2] * u - sm - p[P_GAP], lg * om * c + p[P_R2] * up - smp


@_jit_inline
def sensor_force(mode, force, sm, smp, p):
    """What the force sensor reads: the force through its mount (the contact force if the mount is rigid)."""
    if p[P_MT] != 0.0:
        return p[P_KM] * sm + p[P_CM] * smp
    if mode == CONTACT:
        return max(force, 0.0)
    return 0.0


@_jit_inline
def derivs(t, th, om, u, up, sm, smp, mode, p, fs):
    """Right-hand side: ``(theta', theta'', F, u', u'', s', s'')``.

    In free flight only the pendulum is integrated here (``u``, ``s`` follow their closed form).
    The pendulum terms are evaluated in the order of :func:`rimd_sim.core.kernel.theta_accel`.
    """
    s, c = sincos(th)
    lg = p[P_L]
    acc = -(cart_accel(fs, p, t) / lg) * c - p[P_GL] * s - 2.0 * p[P_ZETA] * p[P_WN] * om
    if mode != CONTACT:
        return om, acc, 0.0, 0.0, 0.0, 0.0, 0.0
    force = law_force(lg * s + p[P_R2] * u - sm - p[P_GAP], lg * om * c + p[P_R2] * up - smp, p, fs[F_VIMP])
    acc -= force / (p[P_M] * lg)
    upp = 0.0
    if p[P_AX] != 0.0:
        upp = -(p[P_KA] * u + p[P_CA] * up) / p[P_MU] - force / p[P_M1]
    spp = 0.0
    if p[P_MT] != 0.0:
        spp = (force - p[P_KM] * sm - p[P_CM] * smp) / p[P_MS]
    return om, acc, force, up, upp, smp, spp


@_jit_inline
def accel_rear(th, om, acc, u, up, force, mode, p, ac):
    """Inertial acceleration of the rear mass (the accelerometer's): ``X'' - (m1/m) u''``."""
    s, c = sincos(th)
    lg = p[P_L]
    xdd = lg * (acc * c - om * om * s) + ac
    if p[P_AX] == 0.0:
        return xdd
    upp = -(p[P_KA] * u + p[P_CA] * up) / p[P_MU]
    if mode == CONTACT:
        upp -= force / p[P_M1]
    return xdd - p[P_R1] * upp


@_jit
def rhs(t, y, mode, p, fs, out):
    """Derivative of the state into ``out``."""
    d = derivs(t, y[0], y[1], y[3], y[4], y[5], y[6], mode, p, fs)
    for i in range(N_STATE):
        out[i] = d[i]


# ======================================================================================================
# Runge-Kutta step and dense output
# ======================================================================================================


@_jit_inline
def _stage(t, ytmp, mode, p, fs, K, j):
    d = derivs(t, ytmp[0], ytmp[1], ytmp[3], ytmp[4], ytmp[5], ytmp[6], mode, p, fs)
    for i in range(N_STATE):
        K[j, i] = d[i]


@_jit
def rk_step(t, y, f, h, mode, p, fs, K, ynew, ytmp):
    """One Dormand-Prince step (the tableau and the arithmetic of :func:`rimd_sim.core.kernel.rk_step`).

    Returns the RMS error norm over the integrated components: ``(theta, theta')``, and in contact the
    axial and mount states of a compliant link/mount, scaled by ``1 / l`` into the same units. In free
    flight ``u`` and ``s`` are replaced by their exact closed form.
    """
    n = N_STATE
    for i in range(n):
        K[0, i] = f[i]
    c0 = h / 5.0
    for i in range(n):
        ytmp[i] = y[i] + c0 * K[0, i]
    _stage(t + c0, ytmp, mode, p, fs, K, 1)
    c0 = 3.0 / 40.0 * h
    c1 = 9.0 / 40.0 * h
    for i in range(n):
        ytmp[i] = y[i] + c0 * K[0, i] + c1 * K[1, i]
    _stage(t + 0.3 * h, ytmp, mode, p, fs, K, 2)
    c0 = 44.0 / 45.0 * h
    c1 = -56.0 / 15.0 * h
    c2 = 32.0 / 9.0 * h
    for i in range(n):
        ytmp[i] = y[i] + c0 * K[0, i] + c1 * K[1, i] + c2 * K[2, i]
    _stage(t + 0.8 * h, ytmp, mode, p, fs, K, 3)
    c0 = 19372.0 / 6561.0 * h
    c1 = -25360.0 / 2187.0 * h
    c2 = 64448.0 / 6561.0 * h
    c3 = -212.0 / 729.0 * h
    for i in range(n):
        ytmp[i] = y[i] + c0 * K[0, i] + c1 * K[1, i] + c2 * K[2, i] + c3 * K[3, i]
    _stage(t + 8.0 / 9.0 * h, ytmp, mode, p, fs, K, 4)
    c0 = 9017.0 / 3168.0 * h
    c1 = -355.0 / 33.0 * h
    c2 = 46732.0 / 5247.0 * h
    c3 = 49.0 / 176.0 * h
    c4 = -5103.0 / 18656.0 * h
    for i in range(n):
        ytmp[i] = y[i] + c0 * K[0, i] + c1 * K[1, i] + c2 * K[2, i] + c3 * K[3, i] + c4 * K[4, i]
    _stage(t + h, ytmp, mode, p, fs, K, 5)
    b0 = 35.0 / 384.0 * h
    b2 = 500.0 / 1113.0 * h
    b3 = 125.0 / 192.0 * h
    b4 = -2187.0 / 6784.0 * h
    b5 = 11.0 / 84.0 * h
    for i in range(n):
        ynew[i] = y[i] + b0 * K[0, i] + b2 * K[2, i] + b3 * K[3, i] + b4 * K[4, i] + b5 * K[5, i]
    if mode != CONTACT:
        ynew[3], ynew[4], ynew[5], ynew[6] = free_modes(y, h, p)
    _stage(t + h, ynew, mode, p, fs, K, 6)
    E = _E
    rtol = p[P_RTOL]
    atol = p[P_ATOL]
    total = 0.0
    count = 0
    for i in range(n):
        if i == 2:
            continue
        if i >= 3:
            if mode != CONTACT or (i < 5 and p[P_AX] == 0.0) or (i >= 5 and p[P_MT] == 0.0):
                continue
        e = h * (E[0] * K[0, i] + E[2] * K[2, i] + E[3] * K[3, i] + E[4] * K[4, i] + E[5] * K[5, i]
                 + E[6] * K[6, i])
        if i < 2:
            r = e / (atol + rtol * max(abs(y[i]), abs(ynew[i])))
        else:
            lg = p[P_L]
            r = e / (atol * lg + rtol * max(abs(y[i]), abs(ynew[i])))
        total += r * r
        count += 1
    return math.sqrt(total / count)


@_jit
def dense_coeffs(K, Q):
    """``Q = K.T @ P``: coefficients of the 4th-order continuous extension."""
    P = _P
    for i in range(N_STATE):
        for j in range(4):
            acc = 0.0
            for s in range(7):
                acc += K[s, i] * P[s, j]
            Q[i, j] = acc


@_jit_inline
def dense_comp(ya, Q, h, x, i):
    x2 = x * x
    return ya[i] + h * (Q[i, 0] * x + Q[i, 1] * x2 + Q[i, 2] * x2 * x + Q[i, 3] * x2 * x2)


@_jit_inline
def state_at(mode, ya, Q, h, x, p):
    """``(theta, theta', u, u', s, s')`` at fraction ``x`` of the current step."""
    th, om = dense_theta(ya, Q, h, x)
    if mode == CONTACT:
        return (th, om, dense_comp(ya, Q, h, x, 3), dense_comp(ya, Q, h, x, 4), dense_comp(ya, Q, h, x, 5),
                dense_comp(ya, Q, h, x, 6))
    u, up, sm, smp = free_modes(ya, x * h, p)
    return th, om, u, up, sm, smp


@_jit
def event_value(kind, mode, ya, Q, h, x, p, fs):
    """Event ``kind`` (0: delta, 1: law force) at fraction ``x`` of the step."""
    th, om, u, up, sm, smp = state_at(mode, ya, Q, h, x, p)
    d, dd = pen(th, om, u, up, sm, smp, p)
    if kind == 0:
        return d
    return law_force(d, dd, p, fs[F_VIMP])


@_jit
def find_root(kind, mode, ya, Q, h, lo, glo, hi, ghi, p, fs):
    """Illinois regula falsi (as :func:`rimd_sim.core.kernel.find_root`); returns the far end of the bracket."""
    tol = p[P_EVTOL] / h
    side = 0
    for _ in range(200):
        if hi - lo <= tol:
            break
        x = (lo * ghi - hi * glo) / (ghi - glo)
        if not (lo < x < hi):
            x = 0.5 * (lo + hi)
        g = event_value(kind, mode, ya, Q, h, x, p, fs)
        if (g > 0.0) == (glo > 0.0) and g != 0.0:
            lo = x
            glo = g
            if side == -1:
                ghi *= 0.5
            side = -1
        else:
            hi = x
            ghi = g
            if side == 1:
                glo *= 0.5
            side = 1
    return hi


@_jit_inline
def ring_amplitude(y, p):
    """Bound on how far the ringing modes can move ``delta`` from now on (m)."""
    a = 0.0
    if p[P_AX] != 0.0:
        a += abs(p[P_R2]) * ring_envelope(y[3], y[4], p[P_WA], p[P_ZA])
    if p[P_MT] != 0.0:
        a += ring_envelope(y[5], y[6], p[P_WM], p[P_ZM])
    return a


@_jit_inline
def ring_period(p, y):
    """Shortest period (s) of the modes still ringing by more than :data:`RING_NEGLIGIBLE`, or inf."""
    w = 0.0
    if p[P_AX] != 0.0 and abs(p[P_R2]) * ring_envelope(y[3], y[4], p[P_WA], p[P_ZA]) > RING_NEGLIGIBLE:
        w = p[P_WA]
    if p[P_MT] != 0.0 and ring_envelope(y[5], y[6], p[P_WM], p[P_ZM]) > RING_NEGLIGIBLE:
        w = max(w, p[P_WM])
    if w == 0.0:
        return np.inf
    return TWO_PI / w


@_jit_inline
def snap_quiet_modes(y, p):
    """Set a mode that has decayed below :data:`RING_SNAP` to exactly 0 (free flight only).

    A rigid link or mount (after a reconfiguration) has its component at 0 too.
    """
    if (y[3] != 0.0 or y[4] != 0.0) and (p[P_AX] == 0.0 or ring_envelope(y[3], y[4], p[P_WA], p[P_ZA]) < RING_SNAP):
        y[3] = 0.0
        y[4] = 0.0
    if (y[5] != 0.0 or y[6] != 0.0) and (p[P_MT] == 0.0 or ring_envelope(y[5], y[6], p[P_WM], p[P_ZM]) < RING_SNAP):
        y[5] = 0.0
        y[6] = 0.0


@_jit
def detect_event(mode, rec, ya, yb, h, Q, p, fs):
    """Earliest switch inside the step: ``(fraction, event code)`` or ``(2, EV_NONE)``.

    The logic of :func:`rimd_sim.core.kernel.detect_event` on the full penetration, plus, in free flight
    while a mode rings near the stop, a scan of ``delta`` at eight samples per ringing period.
    """
    best = 2.0
    code = EV_NONE
    da, dda = pen(ya[0], ya[1], ya[3], ya[4], ya[5], ya[6], p)
    db, ddb = pen(yb[0], yb[1], yb[3], yb[4], yb[5], yb[6], p)
    if mode == FREE:
        amp = ring_amplitude(ya, p)
        scan = 0
        if amp > RING_NEGLIGIBLE:
            # The pendulum part of delta over the step, bounded by its ends, middle and spread.
            th, om = dense_theta(ya, Q, h, 0.5)
            s0, _ = sincos(ya[0])
            s1, _ = sincos(yb[0])
            sh, _ = sincos(th)
            lg = p[P_L]
            p0 = lg * s0 - p[P_GAP]
            p1 = lg * s1 - p[P_GAP]
            pm = lg * sh - p[P_GAP]
            if max(p0, p1, pm) + 0.5 * abs(p1 - p0) + amp >= 0.0:
                scan = min(RING_SAMPLES_MAX, int(math.ceil(8.0 * h / ring_period(p, ya))) + 1)
        if rec == 0:
            if scan > 0:
                if da > 0.0 and dda > 0.0:  # on the surface (rounding) and moving in
                    return min(1.0, p[P_EVTOL] / h), EV_ENTER
                da = min(da, 0.0)  # on the surface (rounding) but moving out: not a contact
                # Chunks of one ringing period; only a chunk the ring can reach from the pendulum's delta
                # (bounded by its ends and their spread) is sampled, eight times.
                nchunk = max(1, (scan + 7) // 8)
                lg = p[P_L]
                s0, _ = sincos(ya[0])
                q0 = lg * s0 - p[P_GAP]
                for j in range(nchunk):
                    xa = j / nchunk
                    xb = (j + 1) / nchunk
                    thb, _ = dense_theta(ya, Q, h, xb)
                    sb, _ = sincos(thb)
                    q1 = lg * sb - p[P_GAP]
                    if max(q0, q1) + 0.5 * abs(q1 - q0) + amp >= 0.0:
                        glo = event_value(0, mode, ya, Q, h, xa, p, fs) if j > 0 else da
                        if glo > 0.0:
                            return xa, EV_ENTER
                        for i in range(1, 9):
                            x = xa + (xb - xa) * i / 8.0
                            g = event_value(0, mode, ya, Q, h, x, p, fs)
                            if g > 0.0:
                                return find_root(0, mode, ya, Q, h, xa + (xb - xa) * (i - 1) / 8.0, glo, x, g,
                                                 p, fs), EV_ENTER
                            glo = g
                    q0 = q1
                return best, code
            if db > 0.0:
                if da < 0.0:
                    best = find_root(0, mode, ya, Q, h, 0.0, da, 1.0, db, p, fs)
                else:
                    best = min(1.0, p[P_EVTOL] / h)
                code = EV_ENTER
            elif da < 0.0 and dda > 0.0 and ddb < 0.0:
                xm = hermite_peak(da, db, dda * h, ddb * h)
                if xm > 0.0:
                    gm = event_value(0, mode, ya, Q, h, xm, p, fs)
                    if gm > 0.0:
                        best = find_root(0, mode, ya, Q, h, 0.0, da, xm, gm, p, fs)
                        code = EV_ENTER
        else:
            if da <= 0.0:
                return min(1.0, p[P_EVTOL] / h), EV_CLOSE
            if scan == 0:
                if db <= 0.0:
                    best = find_root(0, mode, ya, Q, h, 0.0, da, 1.0, db, p, fs)
                    code = EV_CLOSE
                fa = law_force(da, dda, p, fs[F_VIMP])
                fb = law_force(db, ddb, p, fs[F_VIMP])
                if fa < 0.0 and fb >= 0.0:
                    x = find_root(1, mode, ya, Q, h, 0.0, fa, 1.0, fb, p, fs)
                    if x < best:
                        best = x
                        code = EV_REENTER
                return best, code
            xlo = 0.0
            glo = da
            flo = law_force(da, dda, p, fs[F_VIMP])
            for j in range(1, scan + 1):
                x = j / scan
                th, om, u, up, sm, smp = state_at(mode, ya, Q, h, x, p)
                g, gd = pen(th, om, u, up, sm, smp, p)
                fx = law_force(g, gd, p, fs[F_VIMP])
                if g <= 0.0:
                    best = find_root(0, mode, ya, Q, h, xlo, glo, x, g, p, fs)
                    code = EV_CLOSE
                if flo < 0.0 and fx >= 0.0:
                    xr = find_root(1, mode, ya, Q, h, xlo, flo, x, fx, p, fs)
                    if xr < best:
                        best = xr
                        code = EV_REENTER
                if code != EV_NONE:
                    break
                xlo = x
                glo = g
                flo = fx
    else:
        fa = law_force(da, dda, p, fs[F_VIMP])
        fb = law_force(db, ddb, p, fs[F_VIMP])
        if fa >= 0.0 and fb < 0.0:
            best = find_root(1, mode, ya, Q, h, 0.0, fa, 1.0, fb, p, fs)
            code = EV_EXIT
        if da >= 0.0 and db < 0.0:
            x = find_root(0, mode, ya, Q, h, 0.0, da, 1.0, db, p, fs)
            if x < best:
                best = x
                code = EV_EXIT_CLOSE
    return best, code


# ======================================================================================================
# Sampling
# ======================================================================================================


@_jit_inline
def sample_quantity(qty, mode, th, om, u, up, sm, smp, p, fs, t, w, alpha, sp, cp):
    """Noise-free value of a channel quantity (accelerometer: the rear mass; force: through the mount)."""
    a0 = p[P_A0]
    if qty == Q_CART:
        return a0 * sp
    s, c = sincos(th)
    lg = p[P_L]
    if qty == Q_RIMD:
        return lg * s + a0 * sp
    force = 0.0
    if mode == CONTACT:
        force = law_force(lg * s + p[P_R2] * u - sm - p[P_GAP], lg * om * c + p[P_R2] * up - smp, p, fs[F_VIMP])
    if qty == Q_FORCE:
        return sensor_force(mode, force, sm, smp, p)
    ac = a0 * (alpha * cp - w * w * sp)
    acc = -(ac / lg) * c - p[P_GL] * s - 2.0 * p[P_ZETA] * p[P_WN] * om
    if mode == CONTACT:
        acc -= force / (p[P_M] * lg)
    return accel_rear(th, om, acc, u, up, force, mode, p, ac)


@_jit
def emit_samples(fs, ist, p, ya, Q, ch_rate, ch_qty, ch_next, ch_stop, ch_base, ch_out,
                 tr_rate, tr_next, tr_stop, tr_base, tr_out, st_out, t_stop):
    """Emit every channel sample, truth sample and stroboscopic point that falls in the current step."""
    ta = fs[F_TA]
    tb = fs[F_TB]
    h = tb - ta
    if h <= 0.0:
        return
    mode = ist[I_MODE]
    for c in range(ch_rate.shape[0]):
        rate = ch_rate[c]
        qty = ch_qty[c]
        n = ch_next[c]
        if qty == Q_FORCE and mode != CONTACT and p[P_MT] == 0.0:
            while n < ch_stop[c] and n / rate < tb:
                ch_out[c, n - ch_base[c]] = 0.0
                n += 1
        # Motor phase at the samples as in the paper kernel: exact sin/cos at anchor samples (every 16th index
        # and the segment's first), a rotation by the fixed angle between samples in between.
        alpha_hz = fs[F_MALPHA]
        rot_s = 0.0
        rot_c = 1.0
        sp = 0.0
        cp = 1.0
        if alpha_hz == 0.0 and n < ch_stop[c] and n / rate < tb:
            rot_s = math.sin(TWO_PI * fs[F_MW0] / rate)
            rot_c = math.cos(TWO_PI * fs[F_MW0] / rate)
            seg_first = int(math.floor(fs[F_MT0] * rate)) - 1
            while seg_first / rate < fs[F_MT0]:
                seg_first += 1
            anchor = max(n - n % 16, seg_first)
            tau = anchor / rate - fs[F_MT0]
            phi = TWO_PI * (fs[F_MPHI0] + fs[F_MW0] * tau)
            sp = math.sin(phi)
            cp = math.cos(phi)
            for _ in range(n - anchor):
                sp, cp = sp * rot_c + cp * rot_s, cp * rot_c - sp * rot_s
            seg_first_n = seg_first
        else:
            seg_first_n = -1
        started = False
        while n < ch_stop[c]:
            tn = n / rate
            if tn >= tb:
                break
            tau = tn - fs[F_MT0]
            if alpha_hz != 0.0 or (started and (n % 16 == 0 or n == seg_first_n)):
                phi = TWO_PI * (fs[F_MPHI0] + fs[F_MW0] * tau + 0.5 * alpha_hz * tau * tau)
                sp = math.sin(phi)
                cp = math.cos(phi)
            elif started:
                sp, cp = sp * rot_c + cp * rot_s, cp * rot_c - sp * rot_s
            started = True
            w = TWO_PI * (fs[F_MW0] + alpha_hz * tau)
            if qty == Q_CART:
                ch_out[c, n - ch_base[c]] = p[P_A0] * sp
            elif qty == Q_RIMD:
                th, om = dense_theta(ya, Q, h, (tn - ta) / h)
                s_, _ = sincos(th)
                ch_out[c, n - ch_base[c]] = p[P_L] * s_ + p[P_A0] * sp
            else:
                th, om, u, up, sm, smp = state_at(mode, ya, Q, h, (tn - ta) / h, p)
                ch_out[c, n - ch_base[c]] = sample_quantity(qty, mode, th, om, u, up, sm, smp, p, fs, tn, w,
                                                            TWO_PI * alpha_hz, sp, cp)
            n += 1
        ch_next[c] = n
    n = tr_next[0]
    while n < tr_stop[0]:
        tn = n / tr_rate
        if tn >= tb:
            break
        th, om, u, up, sm, smp = state_at(mode, ya, Q, h, (tn - ta) / h, p)
        k_ = n - tr_base[0]
        xc, vc, ac = cart_kinematics(fs, p, tn)
        d = derivs(tn, th, om, u, up, sm, smp, mode, p, fs)
        s, c_ = sincos(th)
        dl, _ = pen(th, om, u, up, sm, smp, p)
        phi = motor_phase(fs, tn)
        tr_out[T_THETA, k_] = th
        tr_out[T_OMEGA, k_] = om
        tr_out[T_XC, k_] = xc
        tr_out[T_X, k_] = p[P_L] * s + xc
        tr_out[T_V, k_] = p[P_L] * om * c_ + vc
        tr_out[T_A, k_] = accel_rear(th, om, d[1], u, up, d[2], mode, p, ac)
        tr_out[T_DELTA, k_] = dl
        tr_out[T_F, k_] = max(d[2], 0.0)
        tr_out[T_PHASE, k_] = TWO_PI * (phi - math.floor(phi))
        tr_out[T_FREQ, k_] = motor_freq(fs, tn)
        tr_out[T_CONTACT, k_] = 1.0 if mode == CONTACT else 0.0
        n += 1
    tr_next[0] = n
    if st_out.shape[0] > 0:
        while ist[I_STROUT] < st_out.shape[0]:
            kk = ist[I_STRK] - ist[I_CYC]
            target = kk - fs[F_MPHI0]
            w0 = fs[F_MW0]
            alpha = fs[F_MALPHA]
            if alpha == 0.0:
                if w0 <= 0.0:
                    break
                tau = target / w0
            else:
                disc = w0 * w0 + 2.0 * alpha * target
                if disc < 0.0 or w0 + math.sqrt(disc) <= 0.0:
                    break
                tau = 2.0 * target / (w0 + math.sqrt(disc))
            tk = fs[F_MT0] + tau
            if tk < ta:
                ist[I_STRK] += 1
                continue
            if tk >= tb or tk >= t_stop:
                break
            th, om = dense_theta(ya, Q, h, (tk - ta) / h)
            j = ist[I_STROUT]
            st_out[j, S_T] = tk
            st_out[j, S_THETA] = th
            st_out[j, S_OMEGA] = om
            st_out[j, S_CYCLE] = ist[I_STRK]
            ist[I_STROUT] += 1
            ist[I_STRK] += 1


# ======================================================================================================
# Events and records
# ======================================================================================================


@_jit
def open_record(fs, ist, p, t, y):
    """Start an impact record at ``t`` (as :func:`rimd_sim.core.kernel.open_record`, full penetration)."""
    d, dd = pen(y[0], y[1], y[3], y[4], y[5], y[6], p)
    phi = motor_phase(fs, t)
    turns = math.floor(phi)
    ist[I_REC] = 1
    ist[I_RSUB] = 1
    ist[k.I_RCYC] = ist[I_CYC] + int(turns)
    fs[k.F_RT0] = t
    fs[F_RLAST] = t
    fs[k.F_RV] = dd
    fs[F_VIMP] = max(dd, p[k.P_VMIN])
    fs[F_RPEAK] = 0.0
    fs[F_RJ] = 0.0
    fs[F_RPEN] = max(d, 0.0)
    fs[k.F_RFREQ] = motor_freq(fs, t)
    fs[k.F_RPHASE] = TWO_PI * (phi - turns)


@_jit
def apply_event(fs, ist, p, yb, imp_out):
    """Apply the pending switch at the end of the current step. Returns False on a chattering contact."""
    ev = ist[I_PEND]
    ist[I_PEND] = EV_NONE
    if ev == EV_NONE:
        return True
    t = fs[F_TB]
    if ev == EV_MOTOR:
        motor_finish_ramp(fs, ist, t)
        ist[I_NEEDF] = 1
        return True
    ist[I_NEV] += 1
    if t - fs[F_ZT0] > ZENO_WINDOW:
        fs[F_ZT0] = t
        ist[I_ZCNT] = 0
    ist[I_ZCNT] += 1
    if ist[I_ZCNT] > ZENO_MAX_EVENTS:
        return False
    if ev == EV_ENTER:
        if ist[I_REC] == 1:
            close_record(fs, ist, imp_out, t)
        open_record(fs, ist, p, t, yb)
        ist[I_MODE] = CONTACT
        fs[F_HFREE] = fs[F_H]
        fs[F_H] = min(fs[F_HCONT], fs[F_H])
        yb[2] = 0.0
        d, dd = pen(yb[0], yb[1], yb[3], yb[4], yb[5], yb[6], p)
        fs[F_RPEAK] = max(fs[F_RPEAK], sensor_force(CONTACT, law_force(d, dd, p, fs[F_VIMP]), yb[5], yb[6], p))
    elif ev == EV_REENTER:
        ist[I_MODE] = CONTACT
        ist[I_RSUB] += 1
        fs[F_H] = min(fs[F_HCONT], fs[F_H])
        yb[2] = 0.0
    elif ev == EV_EXIT or ev == EV_EXIT_CLOSE:
        fs[F_RJ] += yb[2]
        yb[2] = 0.0
        fs[F_RLAST] = t
        ist[I_MODE] = FREE
        fs[F_HCONT] = fs[F_H]
        fs[F_H] = max(fs[F_H], fs[F_HFREE])
        d, _ = pen(yb[0], yb[1], yb[3], yb[4], yb[5], yb[6], p)
        if ev == EV_EXIT_CLOSE or d <= 0.0:
            close_record(fs, ist, imp_out, t)
    elif ev == EV_CLOSE:
        if ist[I_REC] == 1:
            close_record(fs, ist, imp_out, t)
    ist[I_NEEDF] = 1
    return True


@_jit
def _force_and_delta(p, fs, ya, Q, h, x):
    th, om, u, up, sm, smp = state_at(CONTACT, ya, Q, h, x, p)
    d, dd = pen(th, om, u, up, sm, smp, p)
    return sensor_force(CONTACT, law_force(d, dd, p, fs[F_VIMP]), sm, smp, p), d


@_jit
def _refine_max(fs, p, ya, Q, h, which):
    """Maximum of the sensor force (``which`` 0) or penetration (1) inside the step (as the paper kernel)."""
    best = -np.inf
    best_i = 0
    prev = -np.inf
    left = -np.inf
    right = -np.inf
    for i in range(9):
        v = _force_and_delta(p, fs, ya, Q, h, i / 8.0)[which]
        if v > best:
            best = v
            best_i = i
            left = prev
            right = -np.inf
        elif i == best_i + 1:
            right = v
        prev = v
    if 0 < best_i < 8:
        den = left - 2.0 * best + right
        if den < 0.0:
            return best - 0.125 * (right - left) * (right - left) / den
    return best


@_jit
def track_contact_extremes(fs, p, ya, Q, h):
    """Update the open record's peak (sensor) force and penetration over the current contact step."""
    f0, d0 = _force_and_delta(p, fs, ya, Q, h, 0.0)
    f1, d1 = _force_and_delta(p, fs, ya, Q, h, 0.5)
    f2, d2 = _force_and_delta(p, fs, ya, Q, h, 1.0)
    peak = max(f0, f2)
    if f1 > peak:
        peak = max(f1, _refine_max(fs, p, ya, Q, h, 0))
    pe = max(d0, d2)
    if d1 > pe:
        pe = max(d1, _refine_max(fs, p, ya, Q, h, 1))
    if peak > fs[F_RPEAK]:
        fs[F_RPEAK] = peak
    if pe > fs[F_RPEN]:
        fs[F_RPEN] = pe


# ======================================================================================================
# Driver (the paper kernel's, on the seven-component state)
# ======================================================================================================


@_jit
def advance(p, fs, ist, ya, yb, fa, Q, t_stop,
            ch_rate, ch_qty, ch_next, ch_stop, ch_base, ch_out,
            tr_rate, tr_next, tr_stop, tr_base, tr_out,
            imp_out, st_out):
    """Integrate until the current step reaches ``t_stop`` (contract of :func:`rimd_sim.core.kernel.advance`)."""
    K = np.empty((7, N_STATE))
    ynew = np.empty(N_STATE)
    ytmp = np.empty(N_STATE)
    hmax = p[P_HMAX]
    n_ch = ch_rate.shape[0]
    strobe = st_out.shape[0] > 0
    while True:
        t_next = np.inf
        for c in range(n_ch):
            if ch_next[c] < ch_stop[c]:
                t_next = min(t_next, ch_next[c] / ch_rate[c])
        if tr_next[0] < tr_stop[0]:
            t_next = min(t_next, tr_next[0] / tr_rate)
        if strobe or t_next < fs[F_TB]:
            emit_samples(fs, ist, p, ya, Q, ch_rate, ch_qty, ch_next, ch_stop, ch_base, ch_out,
                         tr_rate, tr_next, tr_stop, tr_base, tr_out, st_out, t_stop)
        if st_out.shape[0] > 0 and ist[I_STROUT] >= st_out.shape[0]:
            return ST_STROBE_FULL
        if fs[F_TB] >= t_stop and tr_next[0] >= tr_stop[0]:
            done = True
            for c in range(ch_next.shape[0]):
                if ch_next[c] < ch_stop[c]:
                    done = False
            if done:
                return ST_OK
        if ist[k.I_IMPOUT] >= imp_out.shape[0]:
            return ST_IMPACTS_FULL
        for i in range(N_STATE):
            ya[i] = yb[i]
        t = fs[F_TB]
        fs[F_TA] = t
        if not apply_event(fs, ist, p, ya, imp_out):
            return ST_ZENO
        if fs[F_MTEND] <= t + 1e-12 * max(1.0, abs(t)):
            motor_finish_ramp(fs, ist, t)
            ist[I_NEEDF] = 1
        if motor_phase(fs, t) > 2048.0:
            motor_rebase(fs, ist, t)
        mode = ist[I_MODE]
        if mode == FREE:
            snap_quiet_modes(ya, p)
        if ist[I_NEEDF] == 1:
            rhs(t, ya, mode, p, fs, fa)
            ist[I_NEEDF] = 0
        h = min(fs[F_H], hmax)
        if mode == FREE and ring_amplitude(ya, p) > RING_NEGLIGIBLE:
            h = min(h, RING_SAMPLES_MAX / 8.0 * ring_period(p, ya))
        while True:
            limit = fs[F_MTEND] - t
            at_break = False
            if h >= limit:
                h = limit
                at_break = True
            if h < 1e-14 * max(1.0, abs(t)):
                return ST_STEP_UNDERFLOW
            err = rk_step(t, ya, fa, h, mode, p, fs, K, ynew, ytmp)
            if not (err == err):
                return ST_NONFINITE
            if err <= 1.0:
                factor = 10.0 if err == 0.0 else min(10.0, 0.9 * err ** -0.2)
                break
            ist[I_NREJ] += 1
            h *= max(0.2, 0.9 * err ** -0.2)
        ist[I_NSTEP] += 1
        dense_coeffs(K, Q)
        x, code = detect_event(mode, ist[I_REC], ya, ynew, h, Q, p, fs)
        if code != EV_NONE and x < 1.0:
            h_full = h
            h = x * h
            rk_step(t, ya, fa, h, mode, p, fs, K, ynew, ytmp)
            dense_coeffs(K, Q)
            fs[F_H] = min(h_full * factor, hmax)
            at_break = False
        else:
            code = EV_MOTOR if at_break else EV_NONE
            fs[F_H] = min(h * factor, hmax)
        for i in range(N_STATE):
            yb[i] = ynew[i]
            fa[i] = K[6, i]
        if not (math.isfinite(yb[0]) and math.isfinite(yb[1])):
            return ST_NONFINITE
        fs[F_TB] = t + h
        ist[I_PEND] = code
        if mode == CONTACT:
            track_contact_extremes(fs, p, ya, Q, h)


@_jit
def truncate(p, fs, ist, ya, yb, fa, Q, t, imp_out):
    """End the current step at ``t`` (contract of :func:`rimd_sim.core.kernel.truncate`)."""
    K = np.empty((7, N_STATE))
    ynew = np.empty(N_STATE)
    ytmp = np.empty(N_STATE)
    ta = fs[F_TA]
    tb = fs[F_TB]
    if t < tb and t > ta:
        h = t - ta
        rk_step(ta, ya, fa, h, ist[I_MODE], p, fs, K, ynew, ytmp)
        for i in range(N_STATE):
            yb[i] = ynew[i]
        ist[I_PEND] = EV_NONE
        if ist[I_MODE] == CONTACT:
            dense_coeffs(K, Q)
            track_contact_extremes(fs, p, ya, Q, h)
    fs[F_TB] = t
    for i in range(N_STATE):
        ya[i] = yb[i]
    fs[F_TA] = t
    ok = apply_event(fs, ist, p, ya, imp_out)
    for i in range(N_STATE):
        yb[i] = ya[i]
    ist[I_NEEDF] = 1
    return ok


@_jit
def resync(p, fs, ist, ya, yb, imp_out):
    """Make the mode agree with the Filippov sets after a command (contract of the paper kernel's)."""
    t = fs[F_TA]
    d, dd = pen(ya[0], ya[1], ya[3], ya[4], ya[5], ya[6], p)
    force = law_force(d, dd, p, fs[F_VIMP])
    if ist[I_MODE] == CONTACT:
        if d <= 0.0 or force < 0.0:
            fs[F_RJ] += ya[2]
            ya[2] = 0.0
            fs[F_RLAST] = t
            ist[I_MODE] = FREE
            if d <= 0.0:
                close_record(fs, ist, imp_out, t)
    else:
        if d > 0.0:
            if ist[I_REC] == 0:
                open_record(fs, ist, p, t, ya)
                force = law_force(d, dd, p, fs[F_VIMP])
            if force >= 0.0:
                ist[I_MODE] = CONTACT
                ya[2] = 0.0
                fs[F_RPEAK] = max(fs[F_RPEAK], sensor_force(CONTACT, force, ya[5], ya[6], p))
        elif ist[I_REC] == 1:
            close_record(fs, ist, imp_out, t)
    for i in range(N_STATE):
        yb[i] = ya[i]
    ist[I_NEEDF] = 1


# ======================================================================================================
# Python side
# ======================================================================================================


def structural_params(config) -> np.ndarray:
    """Parameter vector of the structural kernel: the paper kernel's plus the structure's."""
    from .model import _params_vector

    rig = config.rig
    st = rig.structure
    p = np.zeros(N_SPARAM)
    p[: k.N_PARAM] = _params_vector(rig, config)
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
        p[k.P_HCONT0] = min([p[k.P_HCONT0]] + [t / 40.0 for t in periods])
    return p


def _model_base():
    from .model import RigModel

    return RigModel


class StructuralModel(_model_base()):
    """:class:`~rimd_sim.core.model.RigModel` with the structural contact model (same API).

    ``rimd_acceleration`` is the rear mass (the coupling that carries the accelerometer); ``impact_force``
    and :attr:`~rimd_sim.core.model.Impact.peak_force` are the force through the sensor's mount.
    """

    _kernel = None  # set below (the module itself)
    _n_state = N_STATE
    _n_fstate = N_FSTATE

    def _params(self, config) -> np.ndarray:
        return structural_params(config)

    def reset_hammer(self):
        """Put the hammer back to its initial state now, its axial mode at rest (the sensor keeps ringing)."""
        done = self._truncate()
        self._ya[0] = self._config.initial_theta
        self._ya[1] = self._config.initial_theta_dot
        self._ya[3] = 0.0
        self._ya[4] = 0.0
        return done + self._resync()


def _self_module():
    import sys

    return sys.modules[__name__]


StructuralModel._kernel = _self_module()

assert N_ISTATE == k.N_ISTATE and N_RECORD == k.N_RECORD and N_TRUTH == k.N_TRUTH


def make_model(config, **kwargs):
    """The model ``structure.model`` selects.

    :class:`~rimd_sim.core.model.RigModel` for ``rigid`` (the paper's), :class:`StructuralModel` for
    ``two_mass``; keyword arguments go to the model.
    """
    if config.rig.structure.model == "two_mass":
        return StructuralModel(config, **kwargs)
    return _model_base()(config, **kwargs)
