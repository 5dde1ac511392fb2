"""The layout of the arrays the compiled driver shares with its callers, and the driver's integer codes.

The driver (:mod:`rimd_sim.model.kernel`) keeps its whole state in flat arrays, so that compiled code and Python
share it without copies: the parameter vector ``p`` (``P_*``), the float state ``fs`` (``F_*``) and the integer
state ``ist`` (``I_*``). Its outputs are rows and columns of arrays too: the truth block (``T_*``), impact records
(``R_*``) and stroboscopic points (``S_*``). A model's physics module appends its own parameters after
``N_PARAM``. The names are re-exported by :mod:`rimd_sim.model.kernel`, where the rest of the package reads them.
"""

from __future__ import annotations

import math

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
# the sag is over (> 0 while a sag is in progress). See :func:`rimd_sim.model.motor.motor_slip`.
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

# The chattering guard: more than ZENO_MAX_EVENTS switches within ZENO_WINDOW seconds stop the run (ST_ZENO).
ZENO_WINDOW = 1e-3
ZENO_MAX_EVENTS = 400
TWO_PI = 2.0 * math.pi

# Models whose modes ring in free flight (RINGS): most samples of delta per free step (8 per ringing period); a
# longer free step is cut to this many samples.
RING_SAMPLES_MAX = 512
# A ring that moves delta by less than this (m) is not scanned for re-contacts: one it could cause would carry
# less than k x 1e-10 m = 0.55 mN with the paper's contact stiffness.
RING_NEGLIGIBLE = 1e-10
