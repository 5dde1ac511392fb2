"""Integration: the Dormand-Prince 5(4) step, its dense output, and the driver's loop over the steps.

The module-level functions work on state tuples and arrays of any length; the factories :func:`step_functions`
and :func:`loop_functions` compile, for one model, the step (``rk_step``, ``dense_coeffs``, ``rhs``) and the loop
that calls it (``advance``, ``truncate``), as closures over the model's state size and its physics namespace.
:func:`rimd_sim.model.kernel.build_driver` composes them with the events (:mod:`rimd_sim.model.events`), the
records and switches (:mod:`rimd_sim.model.records`) and the sampling (:mod:`rimd_sim.model.sampling`); the
functions call one another through the driver's namespace ``drv``.

The method (the coefficients of ``scipy.integrate.RK45``): the explicit Dormand-Prince 5(4) pair with local
extrapolation, standard step control on ``(theta, theta_dot)`` (and, in contact, on the modes the model weighs)
and its 4th-order continuous extension. The stages work on tuples, so that the state stays in registers whatever
the model's size.
"""

from __future__ import annotations

import math

import numpy as np

from rimd_sim.model.jit import jit_for, kernel_jit, to_tuple, tuple_set
from rimd_sim.model.layout import (
    CONTACT,
    EV_MOTOR,
    EV_NONE,
    F_H,
    F_MTEND,
    F_TA,
    F_TB,
    F_THMAX,
    FREE,
    I_IMPOUT,
    I_MODE,
    I_NEEDF,
    I_NREJ,
    I_NSTEP,
    I_PEND,
    I_REC,
    I_STROUT,
    P_ATOL,
    P_HMAX,
    P_RTOL,
    RING_NEGLIGIBLE,
    RING_SAMPLES_MAX,
    ST_IMPACTS_FULL,
    ST_NONFINITE,
    ST_OK,
    ST_STEP_UNDERFLOW,
    ST_STROBE_FULL,
    ST_ZENO,
)
from rimd_sim.model.motor import motor_finish_ramp, motor_phase, motor_rebase, next_strobe
from rimd_sim.model.numerics import inv_fifth_root

# Dormand-Prince 5(4) (scipy.integrate.RK45): the error weights and the dense-output matrix; the stages of
# ``rk_step`` (:func:`step_functions`) are its Butcher tableau written out (the zeros skipped).
_E = np.array([-71 / 57600, 0.0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40])
_P = np.array([
    [1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
    [0.0, 0.0, 0.0, 0.0],
    [0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799],
    [0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072],
    [0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632],
    [0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
    [0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423],
])


# ---- state tuples: the Runge-Kutta stages on tuples, so that they stay in registers whatever the model's size ----


@kernel_jit(inline=True)
def _comb1(y, a, ka):
    """``y + a ka``, component by component, in this order of operations."""
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i])
    return out


@kernel_jit(inline=True)
def _comb2(y, a, ka, b, kb):
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i] + b * kb[i])
    return out


@kernel_jit(inline=True)
def _comb3(y, a, ka, b, kb, c, kc):
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i] + b * kb[i] + c * kc[i])
    return out


@kernel_jit(inline=True)
def _comb4(y, a, ka, b, kb, c, kc, d, kd):
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i] + b * kb[i] + c * kc[i] + d * kd[i])
    return out


@kernel_jit(inline=True)
def _comb5(y, a, ka, b, kb, c, kc, d, kd, e, ke):
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i] + b * kb[i] + c * kc[i] + d * kd[i] + e * ke[i])
    return out


@kernel_jit(inline=True)
def _store(rows, j, values):
    """``rows[j, :] = values`` (a tuple)."""
    for i in range(len(values)):
        rows[j, i] = values[i]


@kernel_jit(inline=True)
def _error_term(h, k0, k2, k3, k4, k5, k6, i):
    """The embedded error estimate of component ``i``."""
    E = _E
    return h * (E[0] * k0[i] + E[2] * k2[i] + E[3] * k3[i] + E[4] * k4[i] + E[5] * k5[i] + E[6] * k6[i])


# ---- dense output --------------------------------------------------------------------------------------------


@kernel_jit(inline=True)
def dense_theta(ya, Q, h, x):
    """Angle and rate at fraction ``x`` of the current step."""
    x2 = x * x
    x3 = x2 * x
    x4 = x3 * x
    th = ya[0] + h * (Q[0, 0] * x + Q[0, 1] * x2 + Q[0, 2] * x3 + Q[0, 3] * x4)
    om = ya[1] + h * (Q[1, 0] * x + Q[1, 1] * x2 + Q[1, 2] * x3 + Q[1, 3] * x4)
    return th, om


@kernel_jit(inline=True)
def dense_comp(ya, Q, h, x, i):
    """Component ``i`` at fraction ``x`` of the current step."""
    x2 = x * x
    return ya[i] + h * (Q[i, 0] * x + Q[i, 1] * x2 + Q[i, 2] * x2 * x + Q[i, 3] * x2 * x2)


# ---- the step and the loop, compiled per model -----------------------------------------------------------------


def step_functions(scope: str, phys, drv, n: int, n_modes: int) -> tuple:
    """Compile the Dormand-Prince step of one model: ``(rk_step, dense_coeffs, rhs)``.

    Args:
        scope: The compiled functions' qualified-name scope (:func:`rimd_sim.model.jit.jit_for`).
        phys: The namespace of the model's physics.
        drv: The driver's namespace (the compiled functions reach one another through it).
        n: Number of state components, ``3 + n_modes``.
        n_modes: Number of the model's own modes.
    """
    compiled = jit_for(scope)
    fused = jit_for(scope, fused=True)   # the step (``_jit_fused``)

    @fused
    def rk_step(t, y, f, h, mode, p, fs, K, ynew):
        """One Dormand-Prince step from ``(t, y)`` with ``f = rhs(t, y)``; fills ``K`` (7 stages), ``ynew``.

        Returns the RMS error norm over ``(theta, theta_dot)`` scaled by ``atol + rtol * |y|``, and in contact
        over the modes the physics weighs (``mode_scale``).
        """
        y0 = to_tuple(y, n)
        k0 = to_tuple(f, n)
        c0 = h / 5.0
        k1 = phys.derivs(t + c0, _comb1(y0, c0, k0), mode, p, fs)
        c0 = 3.0 / 40.0 * h
        c1 = 9.0 / 40.0 * h
        k2 = phys.derivs(t + 0.3 * h, _comb2(y0, c0, k0, c1, k1), mode, p, fs)
        c0 = 44.0 / 45.0 * h
        c1 = -56.0 / 15.0 * h
        c2 = 32.0 / 9.0 * h
        k3 = phys.derivs(t + 0.8 * h, _comb3(y0, c0, k0, c1, k1, c2, k2), mode, p, fs)
        c0 = 19372.0 / 6561.0 * h
        c1 = -25360.0 / 2187.0 * h
        c2 = 64448.0 / 6561.0 * h
        c3 = -212.0 / 729.0 * h
        k4 = phys.derivs(t + 8.0 / 9.0 * h, _comb4(y0, c0, k0, c1, k1, c2, k2, c3, k3), mode, p, fs)
        c0 = 9017.0 / 3168.0 * h
        c1 = -355.0 / 33.0 * h
        c2 = 46732.0 / 5247.0 * h
        c3 = 49.0 / 176.0 * h
        c4 = -5103.0 / 18656.0 * h
        k5 = phys.derivs(t + h, _comb5(y0, c0, k0, c1, k1, c2, k2, c3, k3, c4, k4), mode, p, fs)
        b0 = 35.0 / 384.0 * h
        b2 = 500.0 / 1113.0 * h
        b3 = 125.0 / 192.0 * h
        b4 = -2187.0 / 6784.0 * h
        b5 = 11.0 / 84.0 * h
        y1 = _comb5(y0, b0, k0, b2, k2, b3, k3, b4, k4, b5, k5)
        if mode != CONTACT:
            y1 = phys.free_flight(y0, y1, h, p)
        k6 = phys.derivs(t + h, y1, mode, p, fs)
        _store(K, 0, k0)
        _store(K, 1, k1)
        _store(K, 2, k2)
        _store(K, 3, k3)
        _store(K, 4, k4)
        _store(K, 5, k5)
        _store(K, 6, k6)
        for i in range(n):
            ynew[i] = y1[i]
        rtol = p[P_RTOL]
        atol = p[P_ATOL]
        total = 0.0
        count = 0
        for i in range(2):
            r = _error_term(h, k0, k2, k3, k4, k5, k6, i) / (atol + rtol * max(abs(y0[i]), abs(y1[i])))
            total += r * r
            count += 1
        if mode == CONTACT:
            for j in range(n_modes):
                scale = phys.mode_scale(j, p)
                if scale > 0.0:
                    i = 3 + j
                    r = _error_term(h, k0, k2, k3, k4, k5, k6, i) / (atol * scale + rtol * max(abs(y0[i]),
                                                                                                abs(y1[i])))
                    total += r * r
                    count += 1
        return math.sqrt(total / count)

    @compiled
    def dense_coeffs(K, Q):
        """``Q = K.T @ P``: coefficients of the 4th-order continuous extension of every component."""
        P = _P
        for i in range(n):
            for j in range(4):
                acc = 0.0
                for s in range(7):
                    acc += K[s, i] * P[s, j]
                Q[i, j] = acc

    @compiled
    def rhs(t, y, mode, p, fs, out):
        """Derivative of the state array ``y`` into ``out``."""
        d = phys.derivs(t, to_tuple(y, n), mode, p, fs)
        for i in range(n):
            out[i] = d[i]

    return rk_step, dense_coeffs, rhs


def loop_functions(scope: str, phys, drv, n: int, rings: bool) -> tuple:
    """Compile the driver's loop of one model: ``(advance, truncate)``, the two entry points that make a workspace.

    Args:
        scope: The compiled functions' qualified-name scope (:func:`rimd_sim.model.jit.jit_for`).
        phys: The namespace of the model's physics.
        drv: The driver's namespace (the compiled functions reach one another through it).
        n: Number of state components.
        rings: Whether the model's modes ring in free flight (its physics' ``RINGS``).
    """
    allocating = jit_for(scope, allocates=True)

    @allocating
    def advance(p, fs, ist, ya, yb, fa, Q, t_stop,
                ch_rate, ch_qty, ch_next, ch_stop, ch_base, ch_out,
                tr_rate, tr_next, tr_stop, tr_base, tr_out,
                imp_out, st_out):
        """Integrate until the current step reaches ``t_stop`` and every requested sample is emitted.

        Channel ``c`` gets samples ``ch_next[c] .. ch_stop[c] - 1`` (sample ``n`` at ``n / ch_rate[c]``),
        sample ``n`` written to column ``n - ch_base[c]`` of ``ch_out[c]``; likewise the truth block.
        Completed impacts are written to ``imp_out`` and stroboscopic points to ``st_out`` (``N_STROBE`` columns
        and the model's modes; counts in ``ist[I_IMPOUT]``, ``ist[I_STROUT]``; the caller resets them). Returns
        a status code; on ``ST_IMPACTS_FULL`` / ``ST_STROBE_FULL`` the caller drains the buffers and calls again
        with the same stop.

        The current step's dense coefficients ``Q`` are computed from its stages when something needs them (a
        sample, a stroboscopic point, an event search, a contact's extremes) and before returning, so that the
        caller's ``Q`` always holds the current step's on return, as if computed at every step; after a failure
        status (``ST_STEP_UNDERFLOW``, ``ST_NONFINITE``) they may be those of an earlier step.
        """
        K = np.empty((7, n))
        q_ok = True   # Q holds the current step's coefficients (the caller's, on entry)
        ynew = np.empty(n)
        hmax = p[P_HMAX]
        n_ch = ch_rate.shape[0]
        strobe = st_out.shape[0] > 0
        while True:
            # Emit what falls in the current step (a cheap test first: most steps of a fast run have none).
            t_next = np.inf
            for c in range(n_ch):
                if ch_next[c] < ch_stop[c]:
                    t_next = min(t_next, ch_next[c] / ch_rate[c])
            if tr_next[0] < tr_stop[0]:
                t_next = min(t_next, tr_next[0] / tr_rate)
            # Call emit_samples only when something falls in the step: most free steps have nothing to emit, and
            # the call is costly against a free step's own work.
            if t_next < fs[F_TB] or (strobe and next_strobe(fs, ist) < fs[F_TB]):
                if not q_ok:
                    drv.dense_coeffs(K, Q)
                    q_ok = True
                drv.emit_samples(fs, ist, p, ya, Q, ch_rate, ch_qty, ch_next, ch_stop, ch_base, ch_out,
                                 tr_rate, tr_next, tr_stop, tr_base, tr_out, st_out, t_stop)
            if not q_ok and (ist[I_IMPOUT] >= imp_out.shape[0] or fs[F_TB] >= t_stop
                             or (st_out.shape[0] > 0 and ist[I_STROUT] >= st_out.shape[0])):
                drv.dense_coeffs(K, Q)   # it may return below: the caller's Q is the current step's
                q_ok = True
            if st_out.shape[0] > 0 and ist[I_STROUT] >= st_out.shape[0]:
                return ST_STROBE_FULL
            if fs[F_TB] >= t_stop and tr_next[0] >= tr_stop[0]:
                done = True
                for c in range(ch_next.shape[0]):
                    if ch_next[c] < ch_stop[c]:
                        done = False
                if done:
                    return ST_OK
            if ist[I_IMPOUT] >= imp_out.shape[0]:
                return ST_IMPACTS_FULL
            # Move to the end of the current step and apply its switch.
            for i in range(n):
                ya[i] = yb[i]
            t = fs[F_TB]
            fs[F_TA] = t
            if ist[I_PEND] != EV_NONE and not drv.apply_event(fs, ist, p, ya, imp_out):   # most steps: none
                if not q_ok:
                    drv.dense_coeffs(K, Q)   # K still holds the last step's stages
                return ST_ZENO
            if fs[F_MTEND] <= t + 1e-12 * max(1.0, abs(t)):
                motor_finish_ramp(fs, ist, t)
                ist[I_NEEDF] = 1
            if motor_phase(fs, t) > 2048.0:
                motor_rebase(fs, ist, t)
            mode = ist[I_MODE]
            if rings and mode == FREE:
                phys.settle(ya, p)
            if ist[I_NEEDF] == 1:
                drv.rhs(t, ya, mode, p, fs, fa)
                ist[I_NEEDF] = 0
            # Adaptive step, never across a motor breakpoint (nor, while the modes ring, over more than
            # RING_SAMPLES_MAX / 8 ringing periods).
            h = min(fs[F_H], hmax)
            if rings and mode == FREE and phys.ring_amplitude(ya, p) > RING_NEGLIGIBLE:
                h = min(h, RING_SAMPLES_MAX / 8.0 * phys.ring_period(p, ya))
            while True:
                limit = fs[F_MTEND] - t
                at_break = False
                if h >= limit:
                    h = limit
                    at_break = True
                if h < 1e-14 * max(1.0, abs(t)):
                    return ST_STEP_UNDERFLOW
                err = drv.rk_step(t, ya, fa, h, mode, p, fs, K, ynew)
                if not (err == err):  # NaN
                    return ST_NONFINITE
                if err <= 1.0:
                    factor = 10.0 if err == 0.0 else min(10.0, 0.9 * inv_fifth_root(err))
                    break
                ist[I_NREJ] += 1
                h *= max(0.2, 0.9 * inv_fifth_root(err))
            ist[I_NSTEP] += 1
            x, code, q_ok = drv.detect_event(mode, ist[I_REC], ya, ynew, h, K, Q, p, fs)
            if code != EV_NONE and x < 1.0:
                # Recompute the step exactly up to the switch.
                h_full = h
                h = x * h
                drv.rk_step(t, ya, fa, h, mode, p, fs, K, ynew)
                q_ok = False
                fs[F_H] = min(h_full * factor, hmax)
                at_break = False
            else:
                code = EV_MOTOR if at_break else EV_NONE
                fs[F_H] = min(h * factor, hmax)
            for i in range(n):
                yb[i] = ynew[i]
                fa[i] = K[6, i]
            if not (math.isfinite(yb[0]) and math.isfinite(yb[1])):
                return ST_NONFINITE
            fs[F_TB] = t + h
            if abs(yb[0]) > fs[F_THMAX]:
                fs[F_THMAX] = abs(yb[0])
            ist[I_PEND] = code
            if mode == CONTACT:
                if not q_ok:
                    drv.dense_coeffs(K, Q)
                    q_ok = True
                drv.track_contact_extremes(fs, p, ya, Q, h)

    @allocating
    def truncate(p, fs, ist, ya, yb, fa, Q, t, imp_out):
        """End the current step at ``t`` (``F_TA <= t <= F_TB``), discarding what lies beyond.

        Used before a command so that it acts at exactly ``t``. A switch pending at exactly ``t`` is applied
        first (``imp_out`` must have room for one record). Afterwards the current step is empty at ``t`` and
        the right-hand side is marked stale. Returns False on a chattering contact.
        """
        K = np.empty((7, n))
        ynew = np.empty(n)
        ta = fs[F_TA]
        tb = fs[F_TB]
        if t < tb and t > ta:
            h = t - ta
            drv.rk_step(ta, ya, fa, h, ist[I_MODE], p, fs, K, ynew)
            for i in range(n):
                yb[i] = ynew[i]
            ist[I_PEND] = EV_NONE
            if ist[I_MODE] == CONTACT:
                drv.dense_coeffs(K, Q)
                drv.track_contact_extremes(fs, p, ya, Q, h)
        fs[F_TB] = t
        for i in range(n):
            ya[i] = yb[i]
        fs[F_TA] = t
        ok = drv.apply_event(fs, ist, p, ya, imp_out)
        for i in range(n):
            yb[i] = ya[i]
        ist[I_NEEDF] = 1
        return ok

    return advance, truncate
