"""Sampling: the channels, the truth block and the stroboscopic points that fall inside the current step.

Every sample is drawn from the current step's dense output at its own time ``n / rate``; samples are indexed by
``n`` from the start of the run, so their values do not depend on how the simulated time is cut into calls.
"""

from __future__ import annotations

import math

from rimd_sim.model.integration import dense_theta
from rimd_sim.model.jit import jit_for
from rimd_sim.model.layout import (
    CONTACT,
    F_MALPHA,
    F_MPHI0,
    F_MT0,
    F_MW0,
    F_TA,
    F_TB,
    I_MODE,
    I_STRK,
    I_STROUT,
    P_A0,
    P_L,
    Q_ACC_CONTACT,
    Q_CART,
    Q_FORCE,
    Q_RIMD,
    S_CYCLE,
    S_MODES,
    S_OMEGA,
    S_T,
    S_THETA,
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
)
from rimd_sim.model.motor import cart_kinematics, motor_freq, motor_phase, next_strobe
from rimd_sim.model.numerics import sincos


def sampling_functions(scope: str, phys, n_modes: int) -> tuple:
    """Compile one model's sampling: ``(emit_samples,)``.

    Args:
        scope: The compiled functions' qualified-name scope (:func:`rimd_sim.model.jit.jit_for`).
        phys: The namespace of the model's physics.
        n_modes: Number of the model's own modes (columns after ``S_MODES`` of a stroboscopic point).
    """
    compiled = jit_for(scope)

    @compiled
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
            n_ = ch_next[c]
            if qty == Q_FORCE and mode != CONTACT and phys.force_free_is_zero(p):
                while n_ < ch_stop[c] and n_ / rate < tb:  # no contact in this step: the force is 0
                    ch_out[c, n_ - ch_base[c]] = 0.0
                    n_ += 1
            elif qty == Q_ACC_CONTACT and mode != CONTACT:
                while n_ < ch_stop[c] and n_ / rate < tb:  # not wanted outside contact
                    ch_out[c, n_ - ch_base[c]] = math.nan
                    n_ += 1
            # Motor phase at the samples: at constant motor speed, sin/cos of the phase are computed exactly at
            # anchor samples (every 16th index, and the segment's first sample) and advanced between them by a
            # rotation through the fixed angle between samples. Anchors depend only on the index, so the values
            # do not depend on how the time was cut into calls.
            alpha_hz = fs[F_MALPHA]
            rot_s = 0.0
            rot_c = 1.0
            sp = 0.0
            cp = 1.0
            if alpha_hz == 0.0 and n_ < ch_stop[c] and n_ / rate < tb:
                rot_s = math.sin(TWO_PI * fs[F_MW0] / rate)
                rot_c = math.cos(TWO_PI * fs[F_MW0] / rate)
                seg_first = int(math.floor(fs[F_MT0] * rate)) - 1
                while seg_first / rate < fs[F_MT0]:
                    seg_first += 1
                anchor = max(n_ - n_ % 16, seg_first)
                tau = anchor / rate - fs[F_MT0]
                phi = TWO_PI * (fs[F_MPHI0] + fs[F_MW0] * tau)
                sp = math.sin(phi)
                cp = math.cos(phi)
                for _ in range(n_ - anchor):
                    sp, cp = sp * rot_c + cp * rot_s, cp * rot_c - sp * rot_s
                seg_first_n = seg_first
            else:
                seg_first_n = -1
            started = False
            while n_ < ch_stop[c]:
                tn = n_ / rate
                if tn >= tb:
                    break
                tau = tn - fs[F_MT0]
                if alpha_hz != 0.0 or (started and (n_ % 16 == 0 or n_ == seg_first_n)):
                    phi = TWO_PI * (fs[F_MPHI0] + fs[F_MW0] * tau + 0.5 * alpha_hz * tau * tau)
                    sp = math.sin(phi)
                    cp = math.cos(phi)
                elif started:
                    sp, cp = sp * rot_c + cp * rot_s, cp * rot_c - sp * rot_s
                started = True
                w = TWO_PI * (fs[F_MW0] + alpha_hz * tau)
                if qty == Q_CART:
                    ch_out[c, n_ - ch_base[c]] = p[P_A0] * sp
                elif qty == Q_RIMD:
                    th, _ = dense_theta(ya, Q, h, (tn - ta) / h)
                    s_, _ = sincos(th)
                    ch_out[c, n_ - ch_base[c]] = p[P_L] * s_ + p[P_A0] * sp
                else:
                    s = phys.dense_point(mode, ya, Q, h, (tn - ta) / h, p)
                    ch_out[c, n_ - ch_base[c]] = phys.sample(qty, mode, s, p, fs, w, TWO_PI * alpha_hz, sp, cp)
                n_ += 1
            ch_next[c] = n_
        n_ = tr_next[0]
        while n_ < tr_stop[0]:
            tn = n_ / tr_rate
            if tn >= tb:
                break
            s = phys.dense_point(mode, ya, Q, h, (tn - ta) / h, p)
            k = n_ - tr_base[0]
            xc, vc, ac = cart_kinematics(fs, p, tn)
            x, v, a, d, force = phys.truth(mode, s, tn, p, fs, xc, vc, ac)
            phi = motor_phase(fs, tn)  # turns
            tr_out[T_THETA, k] = s[0]
            tr_out[T_OMEGA, k] = s[1]
            tr_out[T_XC, k] = xc
            tr_out[T_X, k] = x
            tr_out[T_V, k] = v
            tr_out[T_A, k] = a
            tr_out[T_DELTA, k] = d
            tr_out[T_F, k] = force
            tr_out[T_PHASE, k] = TWO_PI * (phi - math.floor(phi))
            tr_out[T_FREQ, k] = motor_freq(fs, tn)
            tr_out[T_CONTACT, k] = 1.0 if mode == CONTACT else 0.0
            n_ += 1
        tr_next[0] = n_
        # Stroboscopic points: the motor phase crosses a multiple of 2 pi (cart at 0 moving forward).
        if st_out.shape[0] > 0:
            while ist[I_STROUT] < st_out.shape[0]:
                tk = next_strobe(fs, ist)   # inf when the motor stops before it
                if tk < ta:  # already behind the current step (round-off at a rebase): skip it
                    ist[I_STRK] += 1
                    continue
                if tk >= tb or tk >= t_stop:
                    break
                s = phys.dense_point(mode, ya, Q, h, (tk - ta) / h, p)
                j = ist[I_STROUT]
                st_out[j, S_T] = tk
                st_out[j, S_THETA] = s[0]
                st_out[j, S_OMEGA] = s[1]
                st_out[j, S_CYCLE] = ist[I_STRK]
                for m in range(n_modes):
                    st_out[j, S_MODES + m] = s[2 + m]
                ist[I_STROUT] += 1
                ist[I_STRK] += 1

    return (emit_samples,)
