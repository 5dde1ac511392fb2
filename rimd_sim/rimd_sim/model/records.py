"""Impact records and mode switches: applying a located event, keeping the open record, resyncing after commands.

An *impact* is the interval from ``delta`` rising through 0 to ``delta`` falling back through 0; it may hold
several contact intervals. Its record (``F_R*`` of the float state while open, a row of ``R_*`` columns once
closed, :mod:`rimd_sim.model.layout`) holds its start, the peak of the force the sensor reads, the impulse, the
impact velocity, the largest penetration and the motor's frequency and phase at the start; its duration runs to
the last instant the force vanished. A chattering guard stops the run (``apply_event`` returns False) when more
than ``ZENO_MAX_EVENTS`` switches happen within ``ZENO_WINDOW`` seconds, instead of stalling.
"""

from __future__ import annotations

import math

import numpy as np

from rimd_sim.model.contact import law_force
from rimd_sim.model.jit import jit_for, kernel_jit
from rimd_sim.model.layout import (
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
    F_RFREQ,
    F_RJ,
    F_RLAST,
    F_RPEAK,
    F_RPEN,
    F_RPHASE,
    F_RT0,
    F_RV,
    F_SLIP,
    F_TA,
    F_TB,
    F_VIMP,
    F_ZT0,
    FREE,
    I_CYC,
    I_IMPOUT,
    I_MODE,
    I_NEEDF,
    I_NEV,
    I_NIMP,
    I_PEND,
    I_RCYC,
    I_REC,
    I_RSUB,
    I_ZCNT,
    P_VMIN,
    R_CYCLE,
    R_DURATION,
    R_FREQ,
    R_IMPULSE,
    R_INDEX,
    R_NCONTACT,
    R_PEAK,
    R_PENETRATION,
    R_PHASE,
    R_T0,
    R_TEND,
    R_VELOCITY,
    TWO_PI,
    ZENO_MAX_EVENTS,
    ZENO_WINDOW,
)
from rimd_sim.model.motor import motor_finish_ramp, motor_freq, motor_phase, motor_slip


@kernel_jit()
def close_record(fs, ist, imp_out, t):
    """Write the open impact record to ``imp_out`` (the caller guarantees room)."""
    j = ist[I_IMPOUT]
    imp_out[j, R_T0] = fs[F_RT0]
    imp_out[j, R_DURATION] = fs[F_RLAST] - fs[F_RT0]
    imp_out[j, R_PEAK] = fs[F_RPEAK]
    imp_out[j, R_IMPULSE] = fs[F_RJ]
    imp_out[j, R_VELOCITY] = fs[F_RV]
    imp_out[j, R_PENETRATION] = fs[F_RPEN]
    imp_out[j, R_FREQ] = fs[F_RFREQ]
    imp_out[j, R_PHASE] = fs[F_RPHASE]
    imp_out[j, R_CYCLE] = ist[I_RCYC]
    imp_out[j, R_INDEX] = ist[I_NIMP]
    imp_out[j, R_TEND] = t
    imp_out[j, R_NCONTACT] = ist[I_RSUB]
    ist[I_IMPOUT] += 1
    ist[I_NIMP] += 1
    ist[I_REC] = 0


def record_functions(scope: str, phys, drv, n: int) -> tuple:
    """Compile one model's records and switches, the functions ``open_record`` .. ``resync`` below.

    Returns ``(open_record, apply_event, force_and_delta, refine_max, track_contact_extremes, resync)``.

    Args:
        scope: The compiled functions' qualified-name scope (:func:`rimd_sim.model.jit.jit_for`).
        phys: The namespace of the model's physics.
        drv: The driver's namespace (the compiled functions reach one another through it).
        n: Number of state components.
    """
    compiled = jit_for(scope)

    @compiled
    def open_record(fs, ist, p, t, y):
        """Start an impact record at ``t`` (contact begins with ``delta`` rising through 0)."""
        d, dd = phys.penetration(phys.point(y), p)
        phi = motor_phase(fs, t)
        turns = math.floor(phi)
        ist[I_REC] = 1
        ist[I_RSUB] = 1
        ist[I_RCYC] = ist[I_CYC] + int(turns)
        fs[F_RT0] = t
        fs[F_RLAST] = t
        fs[F_RV] = dd
        fs[F_VIMP] = max(dd, p[P_VMIN])
        fs[F_RPEAK] = 0.0
        fs[F_RJ] = 0.0
        fs[F_RPEN] = max(d, 0.0)
        fs[F_RFREQ] = motor_freq(fs, t)
        fs[F_RPHASE] = TWO_PI * (phi - turns)

    @compiled
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
            if ist[I_REC] == 1:  # defensive: a record can only be open here after a command changed the state
                close_record(fs, ist, imp_out, t)
            drv.open_record(fs, ist, p, t, yb)
            ist[I_MODE] = CONTACT
            if fs[F_SLIP] > 0.0:
                motor_slip(fs, ist, t)
            fs[F_HFREE] = fs[F_H]
            fs[F_H] = min(fs[F_HCONT], fs[F_H])
            yb[2] = 0.0
            # The force may jump at first contact (dashpot): count it in the peak.
            s = phys.point(yb)
            d, dd = phys.penetration(s, p)
            fs[F_RPEAK] = max(fs[F_RPEAK], phys.sensor_force(law_force(d, dd, p, fs[F_VIMP]), s, p))
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
            d, _ = phys.penetration(phys.point(yb), p)
            if ev == EV_EXIT_CLOSE or d <= 0.0:
                close_record(fs, ist, imp_out, t)
        elif ev == EV_CLOSE:
            if ist[I_REC] == 1:
                close_record(fs, ist, imp_out, t)
        ist[I_NEEDF] = 1
        return True

    @compiled
    def force_and_delta(fs, p, ya, Q, h, x):
        """The sensor's force and the penetration at fraction ``x`` of the current (contact) step."""
        s = phys.dense_point(CONTACT, ya, Q, h, x, p)
        d, dd = phys.penetration(s, p)
        return phys.sensor_force(law_force(d, dd, p, fs[F_VIMP]), s, p), d

    @compiled
    def refine_max(fs, p, ya, Q, h, which):
        """Maximum of the force (``which`` 0) or penetration (1) inside the step.

        Nine samples, then a parabola through the largest and its neighbours.
        """
        best = -np.inf
        best_i = 0
        prev = -np.inf
        left = -np.inf
        right = -np.inf
        for i in range(9):
            v = drv.force_and_delta(fs, p, ya, Q, h, i / 8.0)[which]
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

    @compiled
    def track_contact_extremes(fs, p, ya, Q, h):
        """Update the open record's peak force and penetration over the current (contact) step.

        The ends and the middle of the step are evaluated; a maximum is searched inside the step only when
        the middle exceeds both ends (the step is short against the contact, so each quantity is unimodal).
        """
        f0, d0 = drv.force_and_delta(fs, p, ya, Q, h, 0.0)
        f1, d1 = drv.force_and_delta(fs, p, ya, Q, h, 0.5)
        f2, d2 = drv.force_and_delta(fs, p, ya, Q, h, 1.0)
        peak = max(f0, f2)
        if f1 > peak:
            peak = max(f1, drv.refine_max(fs, p, ya, Q, h, 0))
        pen = max(d0, d2)
        if d1 > pen:
            pen = max(d1, drv.refine_max(fs, p, ya, Q, h, 1))
        if peak > fs[F_RPEAK]:
            fs[F_RPEAK] = peak
        if pen > fs[F_RPEN]:
            fs[F_RPEN] = pen

    @compiled
    def resync(p, fs, ist, ya, yb, imp_out):
        """Make the mode agree with the Filippov sets after a command changed the state or the parameters.

        Call on an empty current step (after :func:`truncate`). ``imp_out`` must have room for one record.
        """
        t = fs[F_TA]
        s = phys.point(ya)
        d, dd = phys.penetration(s, p)
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
                    drv.open_record(fs, ist, p, t, ya)
                    force = law_force(d, dd, p, fs[F_VIMP])
                if force >= 0.0:
                    ist[I_MODE] = CONTACT
                    ya[2] = 0.0
                    fs[F_RPEAK] = max(fs[F_RPEAK], phys.sensor_force(force, s, p))
            elif ist[I_REC] == 1:
                close_record(fs, ist, imp_out, t)
        for i in range(n):
            yb[i] = ya[i]
        ist[I_NEEDF] = 1

    return open_record, apply_event, force_and_delta, refine_max, track_contact_extremes, resync
