"""The one integration driver of every model: event-exact Dormand-Prince with Filippov contact switching.

This module is the hot loop, written in the subset of Python that numba compiles; with the environment
variable ``RIMD_NO_JIT=1`` the very same functions run as plain Python (slow, for debugging and for the test
that both paths agree). The public, typed interface is :class:`rimd_sim.model.rig_model.RigModel`; the models are
chosen in its registry (:data:`rimd_sim.model.rig_model.MODELS`); the arrays and integer codes here are an
implementation detail.

The model is data: :func:`build_driver` compiles the driver once per model from that model's *physics*, a
module that follows the contract below (:mod:`rimd_sim.model.rigid`, the paper's pendulum;
:mod:`rimd_sim.model.structural`, the two-mass hammer on a compliant sensor mount), in the manner of scipy's
``integrate/_ivp``: one solver with a written contract, methods in a registry, validation in one place.

Method
------
* State ``y = (theta, theta_dot, J, m_1 .. m_k)``: embarked pendulum angle, its rate, the impulse of the
  current contact (``J' = F``), then the model's own *modes* (none for the paper's model). A *point* is the
  state without ``J``: ``(theta, theta_dot, m_1 .. m_k)``. Integrated by the explicit Dormand-Prince 5(4)
  pair with local extrapolation, standard step control on ``(theta, theta_dot)`` (and, in contact, on the
  modes the model weighs) and its 4th-order continuous extension (the coefficients of
  ``scipy.integrate.RK45``). Global error O(h^5).
* The right-hand side is smooth inside each *mode* (FREE or CONTACT) and within a motor segment (constant
  angular acceleration of the motor). Every step ends at a motor breakpoint (ramp start/end).
* Events (switches) are located on the dense output by the Illinois method to ``event_tolerance``; the
  step is then recomputed from its start to the event time, so the state at the switch carries the
  method's full order. Modes change only at located events, never by testing the sign of a state inside
  the right-hand side, so a switch can neither be missed by an oscillating sign nor be applied twice.
* FREE mode watches ``delta`` crossing 0 upwards (contact starts, Filippov surface Sigma_alpha), a double
  crossing of ``delta`` inside one step (found from the cubic Hermite of delta and its rate), and, while
  the hammer is separated but still beyond the stop position (``delta > 0`` after a dashpot release), the
  law's force crossing 0 upwards (re-contact) and ``delta`` returning to 0 (the impact is over).
  CONTACT mode watches the force crossing 0 downwards (Sigma_beta) and ``delta`` crossing 0 downwards.
* A model whose modes *ring* in free flight (``RINGS``) advances them by their closed form there (so the free
  step is the pendulum's however long they ring), and while they ring near the stop the onset test samples
  ``delta`` eight times per ringing period, so a re-contact on the ring is not stepped over.
* An *impact* is the interval from ``delta`` rising through 0 to ``delta`` falling back through 0; it
  may hold several contact intervals. Its duration runs to the last instant the force vanished.
* A chattering guard stops with a status code when more than ``ZENO_MAX_EVENTS`` switches happen within
  ``ZENO_WINDOW`` seconds, instead of stalling.

Chunk independence: an ``advance`` call never shortens a step to land on its stop time. The current
step (with its dense output) persists between calls and samples are drawn from it, so the trajectory and
every sample are bit-identical however the simulated time is cut into calls. Only commands (see
``truncate``) end a step early, at the command's time.

The physics contract
--------------------
A model's physics module defines, compiled with :func:`physics_inline` or :func:`physics_jit` (``p`` is the
parameter vector, ``fs`` the float state, ``y`` a state tuple, ``s`` a point tuple, ``mode`` FREE or CONTACT):

=========================================== =================================================================
``N_MODES``                                 number of modes ``k`` (the state has ``3 + k`` components)
``RINGS``                                   True when the modes ring in free flight (then the ``ring_*``
                                            functions and ``settle`` below are used)
``HAMMER_MODES``                            state indices (>= 3) a reset of the hammer puts at rest
``derivs(t, y, mode, p, fs)``               the right-hand side, a tuple of ``3 + k``
``free_flight(y0, y1, h, p)``               the state at the end of a free step from ``y0`` (``y1``: as the
                                            Runge-Kutta stages computed it; closed-form modes replace theirs)
``mode_scale(j, p)``                        in contact, the absolute-tolerance scale of mode ``j`` in the error
                                            norm (0: not error-controlled)
``point(y)``, ``dense_point(mode, ya, Q,    the point at a step end, and at fraction ``x`` of the current step
h, x, p)``                                  (from :func:`dense_theta`, :func:`dense_comp` or a closed form)
``penetration(s, p)``                       ``(delta, delta_dot)``
``sensor_force(force, s, p)``               what the force sensor reads in contact when the law gives
                                            ``force`` (unclipped): the impact record's peak is taken on it
``force_free_is_zero(p)``                   the sensor reads exactly 0 outside contact
``sample(qty, mode, s, p, fs, w, alpha,     the force or the acceleration (``Q_FORCE``, ``Q_ACC``; the driver
sp, cp)``                                   samples the displacements) from the point and the motor's angular
                                            frequency, acceleration and the sine and cosine of its phase
``truth(mode, s, t, p, fs, xc, vc, ac)``    ``(x, v, a, delta, force)`` of the truth block
``ring_amplitude(y, p)``                    a bound on how far the modes can move ``delta`` from the
                                            pendulum's ``l sin(theta) - gap`` from now on (free flight)
``ring_period(p, y)``                       the shortest period of a mode still ringing, or inf
``settle(y, p)``                            set modes that have died out to exactly 0 (start of a free step)
``params(config)``                          (Python) the parameter vector: the ``P_*`` layout of this module
                                            first, the model's own after it
=========================================== =================================================================

:func:`check_physics` checks a module against this table (``CONTRACT``, ``RING_HOOKS``) before a driver is built.
"""

from __future__ import annotations

import hashlib
import math
import os
import sys
import types
from typing import Any

import numpy as np

if os.environ.get("RIMD_NO_JIT") == "1":  # pragma: no cover - exercised by a subprocess test

    def _jit(func):
        return func

    _jit_alloc = _jit
    _jit_fused = _jit
    _jit_inline = _jit
    physics_jit = _jit
    physics_inline = _jit
    JIT = False

    def to_tuple(array, length):
        """The first ``length`` entries of ``array`` as a tuple."""
        return tuple(array[:length])

    def tuple_set(tup, index, value):
        """``tup`` with entry ``index`` replaced by ``value``."""
        return tup[:index] + (value,) + tup[index + 1:]
else:
    from numba import njit

    # numba types an @intrinsic by its typing function (with the typing context first), not by its call in
    # jitted code, which is what the pure-Python versions above give.
    from numba.cpython.unsafe.tuple import tuple_setitem as tuple_set  # type: ignore[assignment]
    from numba.np.unsafe.ndarray import to_fixed_tuple as to_tuple  # type: ignore[assignment]

    # Compiled functions *borrow* their arrays: numba's reference counting (NRT) is off in them (``_nrt=False``),
    # because with it every call of a compiled function incremented and decremented the count of each array it
    # was given, atomically, on entry and exit: measured, half of a Peterka map's time went into those two
    # instructions (the driver's steps pass six arrays to each of their calls, the ensemble's cycles more). A
    # borrowing function cannot create an array (numba refuses to compile one that does) and must not return
    # one; the few that allocate their workspace are compiled with ``_jit_alloc``, which keeps the counting, set
    # explicitly: a function left at numba's default inherits its caller's setting. ``_nrt`` is numba's own
    # (underscored) option; tests/model/test_driver.py checks that every compiled function has the one meant.
    def _jit(func):
        return njit(cache=True, fastmath=False, nogil=True, _nrt=False)(func)  # type: ignore[call-overload]  # _nrt: numba's option

    def _jit_alloc(func):
        """A compiled function that creates arrays (its workspace, its results): with reference counting."""
        return njit(cache=True, fastmath=False, nogil=True, _nrt=True)(func)  # type: ignore[call-overload]  # _nrt: numba's option

    def _jit_fused(func):
        """The Runge-Kutta step: borrowing, with ``a * b + c`` fused into one rounding (FMA, LLVM's ``contract``).

        Only the step, a function of its own that every path calls: a physics function inlined into several
        callers would be fused in one and not in another, and a trajectory would then depend on where a run is
        cut (tests/instruments/test_streaming.py fails so). The fused step's last bits depend on the CPU having FMA
        (every x86-64 since 2013, every ARM64): bit-identical runs are bit-identical on one kind of machine.
        """
        return njit(cache=True, fastmath={"contract"}, nogil=True, _nrt=False)(func)  # type: ignore[call-overload]  # _nrt: numba's option

    def _jit_inline(func):
        # Small functions of the hot loop, inlined at the numba IR level (measured: +20 % steps/s).
        return njit(cache=True, fastmath=False, nogil=True, inline="always")(func)

    def physics_jit(func):
        """A model's physics function, not cached on its own.

        It is compiled into the driver built from it, whose cache entry is keyed by the physics sources
        (:func:`build_driver`), so an edit to the physics is never served stale.
        """
        return njit(cache=False, fastmath=False, nogil=True, _nrt=False)(func)  # type: ignore[call-overload]  # _nrt: numba's option

    def physics_inline(func):
        """A small physics function of the hot loop, inlined into the driver (see :func:`physics_jit`)."""
        return njit(cache=False, fastmath=False, nogil=True, inline="always")(func)

    JIT = True

# ---- parameter vector ------------------------------------------------------------------------------
P_L, P_M, P_A0, P_GL, P_WN, P_ZETA, P_GAP, P_LAW, P_K, P_C, P_N, P_E, P_VMIN = range(13)
P_RTOL, P_ATOL, P_HMAX, P_EVTOL, P_HCONT0 = range(13, 18)
# The pivot's spring of a hammer whose length is set apart from its natural frequency, per unit m l^2:
# k_t / (m l^2) = omega_n^2 - g / l (1/s^2); 0 for the gravity pendulum (no term at all then).
P_KS = 18
N_PARAM = 19

# ---- float state -----------------------------------------------------------------------------------
F_TA, F_TB, F_H, F_HFREE, F_HCONT = range(5)
# Motor segment: start time (s), phase at start (turns), frequency at start (Hz), its rate (Hz/s),
# end of the ramp (s), setpoint (Hz). Phase in turns and frequency in Hz keep setpoints exact.
F_MT0, F_MPHI0, F_MW0, F_MALPHA, F_MTEND, F_MWSET = range(5, 11)
F_VIMP = 11
F_RT0, F_RPEAK, F_RJ, F_RV, F_RPEN, F_RFREQ, F_RPHASE, F_RLAST = range(12, 20)
F_ZT0 = 20
# Motor slip (fault ``motor_slip``, rimd_sim.instruments.faults): the fraction of its frequency the motor loses at each
# contact onset (0 = none), the rate (Hz/s) at which it then ramps back, and the setpoint it ramps back to once
# the sag is over (> 0 while a sag is in progress). See :func:`motor_slip`.
F_SLIP, F_SLIPRATE, F_SLIPBACK = 21, 22, 23
# Largest |theta| at the ends of the steps taken since the caller last set it (the valid domain's pendulum_angle
# rule, rimd_sim.model.validity): the driver only raises it, so it changes no other quantity.
F_THMAX = 24
N_FSTATE = 25
#: Duration (s) of the motor's sag at a contact onset under ``motor_slip``: the frequency falls linearly (a
#: motor cannot jump: the cart's velocity stays continuous), then ramps back at ``F_SLIPRATE``.
SLIP_TIME = 0.002

# ---- integer state ---------------------------------------------------------------------------------
I_MODE, I_PEND, I_REC, I_CYC, I_NIMP, I_NSTEP, I_NREJ, I_NEV = range(8)
I_RCYC, I_RSUB, I_ZCNT, I_NEEDF, I_IMPOUT, I_STRK, I_STROUT, I_STATUS = range(8, 16)
N_ISTATE = 16

# ---- codes -----------------------------------------------------------------------------------------
FREE, CONTACT = 0, 1
EV_NONE, EV_ENTER, EV_REENTER, EV_EXIT, EV_EXIT_CLOSE, EV_CLOSE, EV_MOTOR = range(7)
ST_OK, ST_IMPACTS_FULL, ST_STROBE_FULL, ST_STEP_UNDERFLOW, ST_ZENO, ST_NONFINITE = range(6)

# Channel quantities.
Q_CART, Q_RIMD, Q_ACC, Q_FORCE = range(4)
# The acceleration only in contact (NaN outside): the triggered capture's fast channel (rimd_sim.instruments.capture).
Q_ACC_CONTACT = 4
# Rows of the truth block.
T_THETA, T_OMEGA, T_XC, T_X, T_V, T_A, T_DELTA, T_F, T_PHASE, T_FREQ, T_CONTACT = range(11)
N_TRUTH = 11
# Columns of an impact record.
(R_T0, R_DURATION, R_PEAK, R_IMPULSE, R_VELOCITY, R_PENETRATION, R_FREQ, R_PHASE, R_CYCLE, R_INDEX, R_TEND,
 R_NCONTACT) = range(12)
N_RECORD = 12
# Columns of a stroboscopic (Poincare) point; a model with modes adds them after these (S_MODES on).
S_T, S_THETA, S_OMEGA, S_CYCLE = range(4)
N_STROBE = 4
S_MODES = N_STROBE

ZENO_WINDOW = 1e-3
ZENO_MAX_EVENTS = 400
TWO_PI = 2.0 * math.pi

# Dormand-Prince 5(4) (scipy.integrate.RK45): the error weights and the dense-output matrix; the stages of
# :func:`build_driver`'s ``rk_step`` are its Butcher tableau written out (the zeros skipped).
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



# Models whose modes ring in free flight (RINGS): most samples of delta per free step (8 per ringing period); a
# longer free step is cut to this many samples.
RING_SAMPLES_MAX = 512
# A ring that moves delta by less than this (m) is not scanned for re-contacts: one it could cause would carry
# less than k x 1e-10 m = 0.55 mN with the paper's contact stiffness.
RING_NEGLIGIBLE = 1e-10


# ======================================================================================================
# Shared physics: contact laws and the motor (every model's)
# ======================================================================================================


@_jit_inline
def sincos(x):
    """``(sin x, cos x)``, fast for the pendulum's small angles.

    For ``|x| < 0.25`` by Taylor polynomials of degree 11 and 12, accurate to about one ulp and several
    times faster than the library calls.
    """
    if abs(x) < 0.25:
        x2 = x * x
        s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (
            1.0 / 362880.0 + x2 * (-1.0 / 39916800.0))))))
        c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0 + x2 * (
            -1.0 / 3628800.0 + x2 * (1.0 / 479001600.0))))))
        return s, c
    return math.sin(x), math.cos(x)


#: ``2^(-r/5)`` for r = 0..4: the fractional part of ``2^(-e/5)`` in :func:`inv_fifth_root`.
_TWO_POW_MINUS_FIFTHS = (1.0, 2.0 ** -0.2, 2.0 ** -0.4, 2.0 ** -0.6, 2.0 ** -0.8)


@_jit_inline
def inv_fifth_root(x):
    """``x ** -0.2`` to 1e-5 relative for ``x > 0``: the step control's factor, which needs two digits.

    ``x = m 2^e`` with ``m`` in [0.5, 1) (``frexp``); ``2^(-e/5) = 2^-q 2^(-r/5)`` for ``e = 5 q + r`` from a table
    and an exact ``ldexp``; ``m^(-1/5)`` from a quadratic fit on [0.5, 1] (within 2e-3) and one Newton step on
    ``y^5 m = 1``. ``pow`` here was 7.5 % of a Peterka map's time (one call per step, 12 million in a 40 x 40 map).
    An infinite ``x`` (a step that overflowed) gives 0, as ``pow`` does: the step is then cut by the most allowed.
    """
    if not x < math.inf:
        return 0.0
    m, e = math.frexp(x)
    q = e // 5
    r = e - 5 * q
    y = (0.2395284269767007 * m - 0.6505206630934096) * m + 1.4122927588697187
    y2 = y * y
    y = y + 0.2 * y * (1.0 - m * (y2 * y2 * y))
    return math.ldexp(y * _TWO_POW_MINUS_FIFTHS[r], -q)


@_jit_inline
def spow(x, n):
    """Signed power ``sign(x) |x|^n``."""
    if x >= 0.0:
        return x**n
    return -((-x) ** n)


@_jit_inline
def law_force(delta, ddelta, p, vimp):
    """Force of the configured contact law, unclipped (may be negative near a switch)."""
    code = int(p[P_LAW])
    if code == 0:
        return p[P_K] * delta + p[P_C] * ddelta
    dn = spow(delta, p[P_N])
    if code == 1:
        return p[P_K] * dn
    if code == 2:
        return dn * (p[P_K] + p[P_C] * ddelta)
    e = p[P_E]
    return p[P_K] * dn * (1.0 + 0.75 * (1.0 - e * e) * ddelta / vimp)


@_jit
def motor_phase(fs, t):
    """Motor phase in turns, relative to the segment base (add ``I_CYC`` for the absolute count)."""
    tau = t - fs[F_MT0]
    return fs[F_MPHI0] + fs[F_MW0] * tau + 0.5 * fs[F_MALPHA] * tau * tau


@_jit
def motor_freq(fs, t):
    """Motor frequency (Hz)."""
    return fs[F_MW0] + fs[F_MALPHA] * (t - fs[F_MT0])


@_jit_inline
def motor_angles(fs, t):
    """Motor phase (rad, from the segment base), angular frequency (rad/s) and angular acceleration."""
    tau = t - fs[F_MT0]
    phi = TWO_PI * (fs[F_MPHI0] + fs[F_MW0] * tau + 0.5 * fs[F_MALPHA] * tau * tau)
    return phi, TWO_PI * (fs[F_MW0] + fs[F_MALPHA] * tau), TWO_PI * fs[F_MALPHA]


@_jit
def cart_kinematics(fs, p, t):
    """Cart position, velocity and acceleration ``x_c = A0 sin(phi)`` and its derivatives."""
    phi, w, alpha = motor_angles(fs, t)
    sp = math.sin(phi)
    cp = math.cos(phi)
    a0 = p[P_A0]
    return a0 * sp, a0 * w * cp, a0 * (alpha * cp - w * w * sp)


@_jit_inline
def cart_accel(fs, p, t):
    """Cart acceleration only (the forcing of the embarked pendulum)."""
    phi, w, alpha = motor_angles(fs, t)
    if alpha == 0.0:
        return -p[P_A0] * w * w * math.sin(phi)
    return p[P_A0] * (alpha * math.cos(phi) - w * w * math.sin(phi))




# ======================================================================================================
# State tuples: the Runge-Kutta stages on tuples, so that they stay in registers whatever the model's size
# ======================================================================================================


@_jit_inline
def _comb1(y, a, ka):
    """``y + a ka``, component by component, in this order of operations."""
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i])
    return out


@_jit_inline
def _comb2(y, a, ka, b, kb):
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i] + b * kb[i])
    return out


@_jit_inline
def _comb3(y, a, ka, b, kb, c, kc):
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i] + b * kb[i] + c * kc[i])
    return out


@_jit_inline
def _comb4(y, a, ka, b, kb, c, kc, d, kd):
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i] + b * kb[i] + c * kc[i] + d * kd[i])
    return out


@_jit_inline
def _comb5(y, a, ka, b, kb, c, kc, d, kd, e, ke):
    out = y
    for i in range(len(y)):
        out = tuple_set(out, i, y[i] + a * ka[i] + b * kb[i] + c * kc[i] + d * kd[i] + e * ke[i])
    return out


@_jit_inline
def _store(rows, j, values):
    """``rows[j, :] = values`` (a tuple)."""
    for i in range(len(values)):
        rows[j, i] = values[i]


@_jit_inline
def _error_term(h, k0, k2, k3, k4, k5, k6, i):
    """The embedded error estimate of component ``i``."""
    E = _E
    return h * (E[0] * k0[i] + E[2] * k2[i] + E[3] * k3[i] + E[4] * k4[i] + E[5] * k5[i] + E[6] * k6[i])


# ======================================================================================================
# Dense output
# ======================================================================================================


@_jit_inline
def dense_theta(ya, Q, h, x):
    """Angle and rate at fraction ``x`` of the current step."""
    x2 = x * x
    x3 = x2 * x
    x4 = x3 * x
    th = ya[0] + h * (Q[0, 0] * x + Q[0, 1] * x2 + Q[0, 2] * x3 + Q[0, 3] * x4)
    om = ya[1] + h * (Q[1, 0] * x + Q[1, 1] * x2 + Q[1, 2] * x3 + Q[1, 3] * x4)
    return th, om


@_jit_inline
def dense_comp(ya, Q, h, x, i):
    """Component ``i`` at fraction ``x`` of the current step."""
    x2 = x * x
    return ya[i] + h * (Q[i, 0] * x + Q[i, 1] * x2 + Q[i, 2] * x2 * x + Q[i, 3] * x2 * x2)


# ======================================================================================================
# Events and records (model-independent parts)
# ======================================================================================================


@_jit
def hermite_peak(d0, d1, s0, s1):
    """Location in ``(0, 1)`` of the maximum of the cubic Hermite with values d0, d1 and slopes s0, s1.

    The slopes are per unit step fraction. Returns -1 when the cubic has no interior maximum.
    """
    # p(x) = d0 + s0 x + a x^2 + b x^3
    a = 3.0 * (d1 - d0) - 2.0 * s0 - s1
    b = 2.0 * (d0 - d1) + s0 + s1
    # p'(x) = s0 + 2 a x + 3 b x^2 = 0
    if b == 0.0:
        if a >= 0.0:
            return -1.0
        x = -s0 / (2.0 * a)
        return x if 0.0 < x < 1.0 else -1.0
    disc = a * a - 3.0 * b * s0
    if disc < 0.0:
        return -1.0
    r = math.sqrt(disc)
    for x in ((-a - r) / (3.0 * b), (-a + r) / (3.0 * b)):
        if 0.0 < x < 1.0 and 2.0 * a + 6.0 * b * x < 0.0:
            return x
    return -1.0


@_jit
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



# ======================================================================================================
# Motor
# ======================================================================================================


@_jit
def motor_rebase(fs, ist, t):
    """Start a new motor segment at ``t`` with the phase wrapped to ``[0, 1)`` turn (keeps it precise)."""
    phi = motor_phase(fs, t)
    w = motor_freq(fs, t)
    turns = math.floor(phi)
    ist[I_CYC] += int(turns)
    fs[F_MPHI0] = phi - turns
    fs[F_MW0] = w
    fs[F_MT0] = t


@_jit
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


@_jit
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


@_jit
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


@_jit_inline
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


# ======================================================================================================
# The driver, built once per model
# ======================================================================================================


#: What a physics module must define (the contract of the module docstring); ``RINGS`` adds :data:`RING_HOOKS`.
CONTRACT = ("N_MODES", "RINGS", "HAMMER_MODES", "derivs", "free_flight", "mode_scale", "point", "dense_point",
            "penetration", "sensor_force", "force_free_is_zero", "sample", "truth", "params")
RING_HOOKS = ("ring_amplitude", "ring_period", "settle")


def source_key(*modules) -> str:
    """A digest of the source files of ``modules``: part of the compiled driver's cache key."""
    digest = hashlib.sha256()
    for module in modules:
        with open(module.__file__, "rb") as f:
            digest.update(f.read())
    return digest.hexdigest()[:12]


def jit_for(scope: str, *, allocates: bool = False, fused: bool = False):
    """The decorator of the functions a factory compiles for one model: ``_jit`` under the name ``scope.fn``.

    ``allocates``: the functions create arrays (``_jit_alloc``, with numba's reference counting); by default they
    borrow the arrays they are given (``_jit``). ``fused``: the Runge-Kutta step's (``_jit_fused``).

    Functions built by one factory share their Python qualified name; numba names the compiled symbols and the
    cache files after it, and two models' functions loaded from the cache into one process must not share a
    symbol (the second would call the first's code). ``scope`` holds the model's name.
    """
    jit = _jit_alloc if allocates else _jit_fused if fused else _jit

    def compiled(func):
        func.__qualname__ = f"{scope}.{func.__name__}"
        return jit(func)

    return compiled


def _namespace(name: str, doc: str) -> Any:
    """A module registered in ``sys.modules`` (so numba's cache key pickles it by its name).

    Typed ``Any``: its attributes (the compiled functions, ...) are set after it is made.
    """
    ns = types.ModuleType(name, doc)
    sys.modules[name] = ns
    return ns


def check_physics(physics) -> None:
    """Raise ``TypeError`` naming what ``physics`` lacks of the contract (:data:`CONTRACT`)."""
    missing = [a for a in CONTRACT + (RING_HOOKS if getattr(physics, "RINGS", False) else ())
               if not hasattr(physics, a)]
    if missing:
        raise TypeError(f"{physics.__name__} is not a physics module of rimd_sim.model.kernel: it lacks "
                        f"{', '.join(missing)}")


def build_driver(physics, name: str, sources=()) -> types.ModuleType:
    """Compile the driver for one model from its physics module (the contract of the module docstring).

    Args:
        physics: The model's physics module.
        name: The model's name (registry key).
        sources: Further modules whose source the physics compiles in (for the cache key).

    Returns:
        A namespace with ``advance``, ``truncate`` and ``resync`` (their contracts are their docstrings),
        ``N_STATE``, ``N_MODES`` and ``physics``.

    Raises:
        TypeError: For a physics module that lacks part of the contract.

    numba compiles each function at its first call and caches it on disk (``cache=True``) under a key made of
    the closure's cells. The functions reach the physics and one another through namespaces (modules registered
    in ``sys.modules``) whose names hold the digest of the physics sources: a module is pickled by its name into
    that key (a compiled function would be pickled with an id of its process, and never hit the cache), and an
    edit to the physics (or to this module: a cached caller holds its code) changes the name, so it is never
    served stale.
    """
    check_physics(physics)
    # This module's own source is in the key too: a cached caller (the ensemble loop, ...) holds the driver's
    # compiled code, and numba checks only the caller's file, so an edit here would otherwise be served stale.
    key = source_key(sys.modules[__name__], physics, *sources)
    phys = _namespace(f"{__name__}.physics_{name}_{key}", f"The physics of the {name!r} model ({physics.__name__}).")
    for attr in CONTRACT + (RING_HOOKS if physics.RINGS else ()):
        setattr(phys, attr, getattr(physics, attr))
    n = 3 + physics.N_MODES
    n_modes = physics.N_MODES
    rings = bool(physics.RINGS)
    ns = _namespace(f"{__name__}.driver_{name}_{key}",
                    f"The integration driver of the {name!r} model, built by rimd_sim.model.kernel.build_driver.")
    drv = ns
    compiled = jit_for(f"build_driver.{name}")
    allocating = jit_for(f"build_driver.{name}", allocates=True)   # the two entry points make their workspace
    fused = jit_for(f"build_driver.{name}", fused=True)               # the step (``_jit_fused``)

    # ---- Runge-Kutta step ------------------------------------------------------------------------

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

    # ---- events --------------------------------------------------------------------------------

    @compiled
    def event_value(kind, mode, ya, Q, h, x, p, fs):
        """Value of event function ``kind`` (0: delta, 1: law force) at fraction ``x`` of the step."""
        d, dd = phys.penetration(phys.dense_point(mode, ya, Q, h, x, p), p)
        if kind == 0:
            return d
        return law_force(d, dd, p, fs[F_VIMP])

    @compiled
    def find_root(kind, mode, ya, Q, h, lo, glo, hi, ghi, p, fs):
        """Illinois regula falsi for a sign change of event ``kind`` in ``[lo, hi]`` (fractions of the step).

        Returns the end of the final bracket on the far side of the crossing, so the event state is on the
        new side of the switching surface (or on it).
        """
        tol = p[P_EVTOL] / h
        side = 0
        for _ in range(200):
            if hi - lo <= tol:
                break
            x = (lo * ghi - hi * glo) / (ghi - glo)
            if not (lo < x < hi):
                x = 0.5 * (lo + hi)
            g = drv.event_value(kind, mode, ya, Q, h, x, p, fs)
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

    @compiled
    def ring_scan(ya, yb, Q, h, p):
        """Samples of ``delta`` the free step needs while the modes ring near the stop (0: none); the bound.

        The pendulum's part of ``delta`` over the step is bounded by its ends, middle and spread; the ring's by
        ``ring_amplitude``. Eight samples per ringing period, at most ``RING_SAMPLES_MAX``.
        """
        amp = phys.ring_amplitude(ya, p)
        if not amp > RING_NEGLIGIBLE:
            return 0, amp
        th, _ = dense_theta(ya, Q, h, 0.5)
        s0, _ = sincos(ya[0])
        s1, _ = sincos(yb[0])
        sh, _ = sincos(th)
        lg = p[P_L]
        p0 = lg * s0 - p[P_GAP]
        p1 = lg * s1 - p[P_GAP]
        pm = lg * sh - p[P_GAP]
        if max(p0, p1, pm) + 0.5 * abs(p1 - p0) + amp >= 0.0:
            return min(RING_SAMPLES_MAX, int(math.ceil(8.0 * h / phys.ring_period(p, ya))) + 1), amp
        return 0, amp

    @compiled
    def scan_onset(ya, Q, h, p, fs, scan, amp, da):
        """Contact onset while the modes ring: ``delta`` sampled eight times per ringing period.

        Chunks of one ringing period; only a chunk the ring can reach from the pendulum's ``delta`` (bounded
        by its ends and their spread) is sampled. Returns ``(fraction, event code)``.
        """
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
                glo = drv.event_value(0, FREE, ya, Q, h, xa, p, fs) if j > 0 else da
                if glo > 0.0:
                    return xa, EV_ENTER
                for i in range(1, 9):
                    x = xa + (xb - xa) * i / 8.0
                    g = drv.event_value(0, FREE, ya, Q, h, x, p, fs)
                    if g > 0.0:
                        return drv.find_root(0, FREE, ya, Q, h, xa + (xb - xa) * (i - 1) / 8.0, glo, x, g, p,
                                             fs), EV_ENTER
                    glo = g
            q0 = q1
        return 2.0, EV_NONE

    @compiled
    def scan_release(ya, Q, h, p, fs, scan, da, dda):
        """After a release with ``delta > 0`` while the modes ring: the end of the impact or a re-contact.

        ``delta`` and the law's force sampled ``scan`` times over the step. Returns ``(fraction, event code)``.
        """
        best = 2.0
        code = EV_NONE
        xlo = 0.0
        glo = da
        flo = law_force(da, dda, p, fs[F_VIMP])
        for j in range(1, scan + 1):
            x = j / scan
            g, gd = phys.penetration(phys.dense_point(FREE, ya, Q, h, x, p), p)
            fx = law_force(g, gd, p, fs[F_VIMP])
            if g <= 0.0:
                best = drv.find_root(0, FREE, ya, Q, h, xlo, glo, x, g, p, fs)
                code = EV_CLOSE
            if flo < 0.0 and fx >= 0.0:
                xr = drv.find_root(1, FREE, ya, Q, h, xlo, flo, x, fx, p, fs)
                if xr < best:
                    best = xr
                    code = EV_REENTER
            if code != EV_NONE:
                break
            xlo = x
            glo = g
            flo = fx
        return best, code

    @compiled
    def onset(ya, h, K, Q, q_ok, p, fs, da, dda, db, ddb):
        """A free step with no impact open: ``delta`` rising through 0 inside it (``da``, ``db``: its ends).

        Returns ``(fraction, event code, q_ok)``; ``Q`` is computed from the stages ``K`` (unless ``q_ok``) only
        where the search needs the dense output: ``delta`` ending the step beyond the stop from below it, or
        peaking inside the step. Most free steps need neither (a map's asks for ``Q`` once a cycle, for its
        stroboscopic point).
        """
        if db > 0.0:
            if da < 0.0:
                if not q_ok:
                    drv.dense_coeffs(K, Q)
                return drv.find_root(0, FREE, ya, Q, h, 0.0, da, 1.0, db, p, fs), EV_ENTER, True
            return min(1.0, p[P_EVTOL] / h), EV_ENTER, q_ok   # starts on the surface and moves in
        if da < 0.0 and dda > 0.0 and ddb < 0.0:
            xm = hermite_peak(da, db, dda * h, ddb * h)
            if xm > 0.0:
                if not q_ok:
                    drv.dense_coeffs(K, Q)
                gm = drv.event_value(0, FREE, ya, Q, h, xm, p, fs)
                if gm > 0.0:
                    return drv.find_root(0, FREE, ya, Q, h, 0.0, da, xm, gm, p, fs), EV_ENTER, True
                return 2.0, EV_NONE, True
        return 2.0, EV_NONE, q_ok

    @compiled
    def detect_event(mode, rec, ya, yb, h, K, Q, p, fs):
        """Earliest switch inside the step ``[0, 1]``: ``(fraction, event code, q_ok)``, or ``(2, EV_NONE, q_ok)``.

        The step's dense coefficients ``Q`` are computed from its stages ``K`` when the search needs them (always
        but in the free steps of :func:`onset`); ``q_ok`` says whether they were.

        ``rec`` tells whether an impact is open. In FREE mode it selects what to watch: with no impact open,
        ``delta`` rising through 0 (a state a rounding error beyond the surface counts as on it); with an
        impact open (released by a vanishing force while ``delta > 0``), re-contact and ``delta`` returning
        below 0. Choosing by the record rather than by the sign of ``delta`` keeps a state that lies a
        rounding error off the surface from switching again and again.
        """
        best = 2.0
        code = EV_NONE
        da, dda = phys.penetration(phys.point(ya), p)
        db, ddb = phys.penetration(phys.point(yb), p)
        if mode == FREE and rec == 0 and not rings:
            return drv.onset(ya, h, K, Q, False, p, fs, da, dda, db, ddb)
        drv.dense_coeffs(K, Q)
        if mode == FREE:
            scan = 0
            amp = 0.0
            if rings:
                scan, amp = drv.ring_scan(ya, yb, Q, h, p)
            if rec == 0:
                if rings and scan > 0:
                    if da > 0.0 and dda > 0.0:  # on the surface (rounding) and moving in
                        return min(1.0, p[P_EVTOL] / h), EV_ENTER, True
                    # On the surface (rounding) but moving out: not a contact.
                    x, c = drv.scan_onset(ya, Q, h, p, fs, scan, amp, min(da, 0.0))
                    return x, c, True
                return drv.onset(ya, h, K, Q, True, p, fs, da, dda, db, ddb)
            # Separated by a vanishing force while still beyond the stop position.
            if da <= 0.0:  # already back at the surface (rounding): the impact is over
                return min(1.0, p[P_EVTOL] / h), EV_CLOSE, True
            if rings and scan > 0:
                x, c = drv.scan_release(ya, Q, h, p, fs, scan, da, dda)
                return x, c, True
            if db <= 0.0:
                best = drv.find_root(0, mode, ya, Q, h, 0.0, da, 1.0, db, p, fs)
                code = EV_CLOSE
            fa = law_force(da, dda, p, fs[F_VIMP])
            fb = law_force(db, ddb, p, fs[F_VIMP])
            if fa < 0.0 and fb >= 0.0:
                x = drv.find_root(1, mode, ya, Q, h, 0.0, fa, 1.0, fb, p, fs)
                if x < best:
                    best = x
                    code = EV_REENTER
        else:
            fa = law_force(da, dda, p, fs[F_VIMP])
            fb = law_force(db, ddb, p, fs[F_VIMP])
            if fa >= 0.0 and fb < 0.0:
                best = drv.find_root(1, mode, ya, Q, h, 0.0, fa, 1.0, fb, p, fs)
                code = EV_EXIT
            if da >= 0.0 and db < 0.0:
                x = drv.find_root(0, mode, ya, Q, h, 0.0, da, 1.0, db, p, fs)
                if x < best:
                    best = x
                    code = EV_EXIT_CLOSE
        return best, code, True

    # ---- sampling ------------------------------------------------------------------------------

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

    # ---- records and switches ------------------------------------------------------------------

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

    # ---- the driver ----------------------------------------------------------------------------

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
            # emit_samples only when something falls in the step: a call per step cost a third of a free step.
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

    for fn in (rk_step, dense_coeffs, rhs, event_value, find_root, ring_scan, scan_onset, scan_release, onset,
               detect_event,
               emit_samples, open_record, apply_event, force_and_delta, refine_max, track_contact_extremes,
               advance, truncate, resync):
        setattr(ns, getattr(fn, "py_func", fn).__name__, fn)
    ns.N_STATE = n
    ns.N_MODES = n_modes
    ns.physics = physics
    return ns
