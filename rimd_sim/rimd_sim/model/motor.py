"""The motor and the cart it drives, every model's forcing: phase, frequency, ramps, slip and the cart's motion.

The motor runs in *segments* of constant angular acceleration, held in the float state (``F_MT0`` .. ``F_MWSET``,
:mod:`rimd_sim.model.layout`): the phase in turns and the frequency in Hz from the segment's start, so that a
setpoint is reached exactly. Commands and the ends of ramps start a new segment at their time; the driver ends
every step at a segment's end (``F_MTEND``), so the right-hand side is smooth inside a step. The cart follows
``x_c = A0 sin(phi)``.
"""

from __future__ import annotations

import math

import numpy as np

from rimd_sim.model.jit import kernel_jit
from rimd_sim.model.layout import (
    F_MALPHA,
    F_MPHI0,
    F_MT0,
    F_MTEND,
    F_MW0,
    F_MWSET,
    F_SLIP,
    F_SLIPBACK,
    F_SLIPRATE,
    I_CYC,
    I_STRK,
    P_A0,
    SLIP_TIME,
    TWO_PI,
)


@kernel_jit()
def motor_phase(fs, t):
    """Motor phase in turns, relative to the segment base (add ``I_CYC`` for the absolute count)."""
    tau = t - fs[F_MT0]
    return fs[F_MPHI0] + fs[F_MW0] * tau + 0.5 * fs[F_MALPHA] * tau * tau


@kernel_jit()
def motor_freq(fs, t):
    """Motor frequency (Hz)."""
    return fs[F_MW0] + fs[F_MALPHA] * (t - fs[F_MT0])


@kernel_jit(inline=True)
def motor_angles(fs, t):
    """Motor phase (rad, from the segment base), angular frequency (rad/s) and angular acceleration."""
    tau = t - fs[F_MT0]
    phi = TWO_PI * (fs[F_MPHI0] + fs[F_MW0] * tau + 0.5 * fs[F_MALPHA] * tau * tau)
    return phi, TWO_PI * (fs[F_MW0] + fs[F_MALPHA] * tau), TWO_PI * fs[F_MALPHA]


@kernel_jit()
def cart_kinematics(fs, p, t):
    """Cart position, velocity and acceleration ``x_c = A0 sin(phi)`` and its derivatives."""
    phi, w, alpha = motor_angles(fs, t)
    sp = math.sin(phi)
    cp = math.cos(phi)
    a0 = p[P_A0]
    return a0 * sp, a0 * w * cp, a0 * (alpha * cp - w * w * sp)


@kernel_jit(inline=True)
def cart_accel(fs, p, t):
    """Cart acceleration only (the forcing of the embarked pendulum)."""
    phi, w, alpha = motor_angles(fs, t)
    if alpha == 0.0:
        return -p[P_A0] * w * w * math.sin(phi)
    return p[P_A0] * (alpha * math.cos(phi) - w * w * math.sin(phi))


@kernel_jit()
def motor_rebase(fs, ist, t):
    """Start a new motor segment at ``t`` with the phase wrapped to ``[0, 1)`` turn (keeps it precise)."""
    phi = motor_phase(fs, t)
    w = motor_freq(fs, t)
    turns = math.floor(phi)
    ist[I_CYC] += int(turns)
    fs[F_MPHI0] = phi - turns
    fs[F_MW0] = w
    fs[F_MT0] = t


@kernel_jit()
def motor_command(fs, ist, t, w_set, rate):
    """Set a new setpoint ``w_set`` (Hz) at time ``t``, ramping at ``rate`` (Hz/s, > 0)."""
    motor_rebase(fs, ist, t)
    w = fs[F_MW0]
    fs[F_MWSET] = w_set
    if w_set == w:
        fs[F_MALPHA] = 0.0
        fs[F_MTEND] = np.inf
    else:
        fs[F_MALPHA] = rate if w_set > w else -rate
        fs[F_MTEND] = t + abs(w_set - w) / rate
    fs[F_SLIPBACK] = 0.0   # a new setpoint ends a slip's way back (the command wins)


@kernel_jit()
def motor_finish_ramp(fs, ist, t):
    """End of a ramp at ``t``: the frequency sits exactly on the setpoint from now on.

    At the end of a slip's sag, the motor ramps back to the setpoint it had (:func:`motor_slip`).
    """
    motor_rebase(fs, ist, t)
    fs[F_MW0] = fs[F_MWSET]
    fs[F_MALPHA] = 0.0
    fs[F_MTEND] = np.inf
    if fs[F_SLIPBACK] > 0.0:
        motor_command(fs, ist, t, fs[F_SLIPBACK], fs[F_SLIPRATE])


@kernel_jit()
def motor_slip(fs, ist, t):
    """A contact onset at ``t`` under ``motor_slip``: the motor sags, then ramps back.

    The frequency falls by the fraction ``F_SLIP`` of its value over ``SLIP_TIME``, then ramps back to its
    setpoint at ``F_SLIPRATE`` (the load of the impact on an induction motor). A sag during the way back of the
    previous one starts from the frequency reached.
    """
    motor_rebase(fs, ist, t)
    w = fs[F_MW0]
    if w <= 0.0:
        return
    back = fs[F_SLIPBACK] if fs[F_SLIPBACK] > 0.0 else fs[F_MWSET]
    low = w * (1.0 - fs[F_SLIP])
    motor_command(fs, ist, t, low, (w - low) / SLIP_TIME)
    fs[F_SLIPBACK] = back


@kernel_jit(inline=True)
def next_strobe(fs, ist):
    """Time of the next stroboscopic point (the motor phase crossing the next whole turn, cart at 0 moving forward).

    ``inf`` when no crossing is ahead: the motor stopped, or a ramp down stops it before the crossing.
    """
    k = ist[I_STRK] - ist[I_CYC]  # turns ahead of the segment base
    target = k - fs[F_MPHI0]  # turns to go
    w0 = fs[F_MW0]
    alpha = fs[F_MALPHA]
    if alpha == 0.0:
        if w0 <= 0.0:
            return np.inf
        tau = target / w0
    else:
        disc = w0 * w0 + 2.0 * alpha * target
        if disc < 0.0 or w0 + math.sqrt(disc) <= 0.0:
            return np.inf
        tau = 2.0 * target / (w0 + math.sqrt(disc))
    return fs[F_MT0] + tau
