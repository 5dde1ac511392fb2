"""Identification of the rig's physical parameters from a recording alone (``rimd identify``).

What a recording of the SPEC's topics determines, and from what (see docs/identification.md):

* ``amplitude`` A0: the cart laser against the motor phase (linear least squares, ``x_c = A0 sin phi``); the
  motor frequency and its schedule from ``/rig/motor/state`` (or, without it, a sine fitted to the cart laser).
* ``natural_frequency`` and ``damping_ratio``: the hammer's motion relative to the cart (RIMD laser minus cart
  laser) over the stretches of constant motor frequency without contact: the base-excitation response plus a
  free decay per stretch (variable projection: the free part's two coefficients per stretch are solved
  linearly, ``f_n`` and ``zeta`` by ``scipy.optimize.least_squares``).
* The contact pulse (spring-dashpot law): each impact's force samples are fitted with the pulse of
  ``m delta'' + c delta' + k delta = 0`` from ``delta = 0``, ``F(s) = m v0 e^{-sigma s} [2 sigma cos w s +
  (w^2 - sigma^2)/w sin w s]`` up to the release (``F = 0``): the pulse's shape gives ``sigma = c/2m`` and
  ``w^2 = k/m - sigma^2`` (duration ~ sqrt(m/k)), its scale ``m v0``. The hammer laser gives the impact
  velocity ``v0`` (the slope of the relative displacement just before the onset), so ``m = scale / v0``
  (the impulse against the change of velocity says the same thing), then ``k = m (w^2 + sigma^2)``,
  ``c = 2 m sigma``. Without the laser only ``k/m`` and ``c/m`` are determined; without the force channel
  none of the three.
* ``gap``: the relative displacement at each contact onset.

A final joint refinement fits everything at once with the core's own integrator
(:class:`~rimd_sim.core.model.RigModel`) as the forward model, under the motor schedule read from the
recording and with the hammer's initial state and any velocity kick (a jump of the hammer's velocity without
contact force, such as ``/rig/perturb``) as nuisance parameters: residuals are the relative displacement at
the laser's samples and, per impact, onset time, peak force, duration and impulse
(``scipy.optimize.least_squares``). Standard errors come from the Jacobian at the solution, scaled by the
residuals' spread.

The recording's metadata (the twin writes its own parameters there) is never read: the identification uses
the measured channels only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from rimd_sim.analysis import recorded as rec
from rimd_sim.core.config import SimConfig

__all__ = ["IDENTIFIABLE", "IdentificationError", "Identification", "identify", "simulate"]

#: Parameters ``rimd identify`` estimates (spring-dashpot law), in report order.
IDENTIFIABLE = ("amplitude", "natural_frequency", "damping_ratio", "gap", "mass", "contact.stiffness",
                "contact.damping")

#: Channels each parameter needs (``/rig/motor/state`` or the cart laser gives the schedule).
NEEDS = {
    "amplitude": (rec.CART_X,),
    "natural_frequency": (rec.RIMD_X, rec.CART_X),
    "damping_ratio": (rec.RIMD_X, rec.CART_X),
    "gap": (rec.RIMD_X, rec.CART_X, rec.FORCE),
    "mass": (rec.RIMD_X, rec.CART_X, rec.FORCE),
    "contact.stiffness": (rec.RIMD_X, rec.CART_X, rec.FORCE),
    "contact.damping": (rec.RIMD_X, rec.CART_X, rec.FORCE),
}
CONTACT_PARAMETERS = ("gap", "mass", "contact.stiffness", "contact.damping")

#: Scale of each parameter in the optimiser's unknowns (the unknowns are value / scale, all of order 1).
SCALES = {"amplitude": 1e-3, "natural_frequency": 1.0, "damping_ratio": 0.1, "gap": 1e-3, "mass": 0.1,
          "contact.stiffness": 1e6, "contact.damping": 1e3}

#: A priori spreads of the impact features in the joint fit (scaled afterwards by the residuals' spread).
SIGMA_ONSET = 20e-6          # s
SIGMA_DURATION = 2e-6        # s
SIGMA_PEAK_FRACTION = 2e-3   # of the median peak
SIGMA_IMPULSE_FRACTION = 2e-3

#: Rate (Hz) at which the relative displacement enters the joint fit (the laser's samples, decimated).
FIT_RATE = 250.0


class IdentificationError(Exception):
    """The recording cannot give what was asked (one line: which parameter, which channel, what to do)."""


@dataclass
class Schedule:
    """The motor as recorded, in the forward model's time (s since ``t0``, a motor phase zero)."""

    t0: float
    f0: float
    setpoint0: float
    ramp0: float
    commands: list[tuple[float, float, float]]   # (time, setpoint, ramp rate)
    end: float
    source: str


@dataclass
class Impacts:
    """Impacts measured in the force channel: the fitted pulse per impact and the laser's impact velocity."""

    onset: np.ndarray
    peak: np.ndarray
    duration: np.ndarray
    impulse: np.ndarray
    scale: np.ndarray        # m v0 (N)
    sigma: np.ndarray        # 1/s
    omega: np.ndarray        # rad/s
    v0: np.ndarray           # m/s, from the laser (NaN where not measurable)
    y_onset: np.ndarray      # m, relative displacement at the onset (NaN where not measurable)
    runs: int                # runs of samples above the threshold (impacts seen)


@dataclass
class Estimate:
    """One estimated parameter: value, standard error and where it came from."""

    value: float
    std_error: float | None
    source: str
    local_value: float | None = None
    local_std_error: float | None = None

    def as_dict(self) -> dict:
        """JSON-ready."""
        return {"value": self.value, "std_error": self.std_error, "source": self.source,
                "local_value": self.local_value, "local_std_error": self.local_std_error}


@dataclass
class Identification:
    """What :func:`identify` found."""

    config: SimConfig
    estimates: dict[str, Estimate]
    fixed: dict[str, float]
    schedule: Schedule
    kicks: list[tuple[float, float]]            # (recording time, velocity m/s)
    initial: tuple[float, float]                # theta, theta_dot at t0
    data: dict
    residuals: dict
    validation: list[dict] = field(default_factory=list)
    series: dict = field(default_factory=dict)
    log: list[str] = field(default_factory=list)


# ---- schedule ------------------------------------------------------------------------------------------------

def _unwrapped_phase(motor: dict[str, np.ndarray]) -> np.ndarray:
    return 2.0 * math.pi * motor["cycle_index"] + motor["phase"]


def motor_schedule(motor: dict[str, np.ndarray], t_first: float, avoid: np.ndarray) -> Schedule:
    """The motor schedule of the recording: setpoints, the times they were commanded and their ramps.

    ``t0`` is the first motor phase zero after ``t_first`` at least 5 ms away from an impact (``avoid``: onset
    times). A setpoint's command time is where the linear ramp of the recorded frequency starts.
    """
    t, sp, f = motor["time"], motor["frequency_setpoint"], motor["frequency"]
    zeros = rec.poincare_times(motor)
    zeros = zeros[zeros >= t_first + 0.01]
    for z in zeros:
        if avoid.size == 0 or np.min(np.abs(avoid - z)) > 5e-3:
            t0 = float(z)
            break
    else:
        raise IdentificationError("the recording has no motor cycle start clear of impacts (/rig/motor/state)")
    cuts = np.flatnonzero(np.diff(sp) != 0) + 1
    commands: list[tuple[float, float, float]] = []
    for c in cuts:
        f_prev = float(f[c - 1])
        target = float(sp[c])
        nxt = cuts[cuts > c]
        stop = int(nxt[0]) if nxt.size else t.size
        seg_t, seg_f = t[c:stop], f[c:stop]
        inside = np.abs(seg_f - target) > 1e-9
        inside &= np.abs(seg_f - f_prev) > 1e-9
        if inside.sum() >= 2:
            slope, icpt = np.polyfit(seg_t[inside], seg_f[inside], 1)
            tc = (f_prev - icpt) / slope
            rate = abs(slope)
        else:   # a ramp shorter than the motor states' period: take it as a step at the change
            tc, rate = float(t[c - 1]) + 0.5 * float(t[c] - t[c - 1]), 1e4
        commands.append((float(tc), target, float(min(rate, 1e4))))
    i0 = int(np.searchsorted(t, t0, side="right")) - 1
    f0 = float(np.interp(t0, t, f))
    setpoint0, ramp0 = float(sp[max(i0, 0)]), 2.0
    before = [c for c in commands if c[0] <= t0]
    if before:
        setpoint0, ramp0 = before[-1][1], before[-1][2]
    if abs(f0 - setpoint0) < 1e-9:
        f0 = setpoint0
    later = [(tc - t0, s, r) for tc, s, r in commands if tc > t0]
    return Schedule(t0, f0, setpoint0, ramp0, later, float(t[-1]) - t0, "/rig/motor/state")


def phase_from_cart(cart: rec.Channel) -> tuple[dict[str, np.ndarray], float]:
    """Without motor states: one constant frequency fitted to the cart laser; synthetic motor states."""
    from scipy.optimize import least_squares

    t, x = cart.time, cart.values
    n = x.size
    spec = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(n)))
    freqs = np.fft.rfftfreq(n, 1.0 / cart.rate)
    f_guess = float(freqs[1 + np.argmax(spec[1:])])

    def resid(p):  # noqa: ANN001, ANN202
        w = 2 * math.pi * p[0]
        basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
        coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
        return basis @ coef - x

    fit = least_squares(resid, [f_guess], x_scale=[0.01])
    fr = float(fit.x[0])
    w = 2 * math.pi * fr
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    (a, b, _), *_ = np.linalg.lstsq(basis, x, rcond=None)
    psi = math.atan2(b, a)              # x = A sin(w t + psi)
    tm = np.arange(t[0], t[-1], 0.01)
    phi = w * tm + psi
    cycles = np.floor(phi / (2 * math.pi))
    motor = {"time": tm, "frequency_setpoint": np.full(tm.size, fr), "frequency": np.full(tm.size, fr),
             "phase": phi - 2 * math.pi * cycles, "cycle_index": cycles}
    return motor, fr


# ---- local estimates -----------------------------------------------------------------------------------------

def fit_amplitude(cart: rec.Channel, motor: dict[str, np.ndarray]) -> tuple[float, float]:
    """A0 and its standard error: ``x_c = a sin phi + b cos phi + offset`` at the cart laser's samples."""
    tm = motor["time"]
    inside = (cart.time >= tm[0]) & (cart.time <= tm[-1])
    t, x = cart.time[inside], cart.values[inside]
    phi = np.interp(t, tm, _unwrapped_phase(motor))
    basis = np.column_stack([np.sin(phi), np.cos(phi), np.ones_like(phi)])
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    res = x - basis @ coef
    s2 = float(res @ res) / max(x.size - 3, 1)
    cov = s2 * np.linalg.inv(basis.T @ basis)
    return float(math.hypot(coef[0], coef[1])), float(math.sqrt(cov[0, 0]))


def _pulse_shape(s: np.ndarray, sigma: float, omega: float, eps: float) -> np.ndarray:
    """Contact force per unit ``m v0`` of ``delta'' + 2 sigma delta' + w0^2 delta = eps v0`` from ``delta = 0``.

    ``eps v0`` is the (constant) acceleration of the hammer relative to the cart that the excitation, gravity
    and the wires give during the ~0.4 ms contact: a 0.1-0.2 % effect on the force that, left out, biases the
    fitted pulse by about 1 %.
    """
    w0sq = omega ** 2 + sigma ** 2
    a_ = -eps / w0sq
    b_ = (1.0 + sigma * a_) / omega
    e = np.exp(-sigma * s)
    c, sn = np.cos(omega * s), np.sin(omega * s)
    delta = eps / w0sq + e * (a_ * c + b_ * sn)
    ddelta = e * ((-sigma * a_ + omega * b_) * c + (-sigma * b_ - omega * a_) * sn)
    return w0sq * delta + 2 * sigma * ddelta


def _release(sigma: float, omega: float, eps: float = 0.0) -> float:
    """Time from the onset to the release (the force falls through 0): closed form without ``eps``, then Newton."""
    s = (math.pi - math.atan2(2 * sigma * omega, omega ** 2 - sigma ** 2)) / omega
    if eps == 0.0:
        return s
    w0sq = omega ** 2 + sigma ** 2
    a_ = -eps / w0sq
    b_ = (1.0 + sigma * a_) / omega
    for _ in range(4):
        e, c, sn = math.exp(-sigma * s), math.cos(omega * s), math.sin(omega * s)
        d = eps / w0sq + e * (a_ * c + b_ * sn)
        dd = e * ((-sigma * a_ + omega * b_) * c + (-sigma * b_ - omega * a_) * sn)
        g = w0sq * d + 2 * sigma * dd
        dg = w0sq * dd + 2 * sigma * (eps - 2 * sigma * dd - w0sq * d)
        if dg == 0:
            break
        s -= g / dg
    return s


def _pulse(s: np.ndarray, scale: float, sigma: float, omega: float, eps: float = 0.0) -> np.ndarray:
    """Spring-dashpot contact force from the onset (``s = 0``) to the release, 0 outside."""
    release = _release(sigma, omega, eps)
    inside = (s >= 0) & (s <= release)
    return np.where(inside, scale * _pulse_shape(np.where(inside, s, 0.0), sigma, omega, eps), 0.0)


def _pulse_features(scale: float, sigma: float, omega: float, eps: float = 0.0) -> tuple[float, float, float]:
    """Peak, duration (onset to release) and impulse of the pulse."""
    release = _release(sigma, omega, eps)
    s = np.linspace(0.0, release, 801)
    f = _pulse(s, scale, sigma, omega, eps)
    return float(f.max()), release, float(np.trapezoid(f, s))


def _fit_one_pulse(t: np.ndarray, v: np.ndarray, start: float, dt: float, sigma: float, omega: float,
                   eps: float = 0.0):  # noqa: ANN202
    """Least-squares fit of one pulse from a first guess of (sigma, omega); returns the fit result."""
    from scipy.optimize import least_squares

    shape_peak = _pulse_features(1.0, sigma, omega, eps)[0]
    p0 = [(start - t[0]) / dt - 0.5, float(v.max()) / shape_peak, sigma / omega, 1.0]

    def resid(p):  # noqa: ANN001, ANN202
        return _pulse(t - (t[0] + p[0] * dt), p[1], p[2] * omega, p[3] * omega, eps) - v

    return least_squares(resid, p0, x_scale=[1.0, max(p0[1], 1e-12), 0.1, 0.1], max_nfev=300), omega


#: Most impacts whose pulses are fitted (evenly spread over the recording when there are more).
MAX_PULSES = 100

#: Damping ratios of the contact tried as first guesses of the pulse fit (the shape has local minima).
PULSE_ZETA_STARTS = (0.05, 0.2, 0.4, 0.6, 0.8, 0.95)


def fit_pulses(force: rec.Channel, detected: dict[str, np.ndarray], y_t: np.ndarray, y: np.ndarray,
               accel=None) -> Impacts:  # noqa: ANN001
    """Fit the spring-dashpot pulse to each complete impact; the laser's velocity and position at its onset.

    ``accel(t, v0)``: the hammer's acceleration relative to the cart, without contact force, at time ``t``
    with velocity ``v0`` (see :func:`_pulse_shape`); None: 0. The first impacts are fitted from several first
    guesses (contact damping ratios
    :data:`PULSE_ZETA_STARTS`, the frequency from the duration above threshold); the median of their best
    fits starts every impact's fit.
    """
    dt = 1.0 / force.rate
    finite = np.isfinite(y_t)
    yt, yy = y_t[finite], y[finite]
    onsets_all = detected["start"]
    windows = []
    for i in np.flatnonzero(detected["complete"] > 0):
        start = detected["start"][i]
        j = int(np.searchsorted(force.time, start))
        a, b = j - 3, j + int(round(detected["duration"][i] / dt)) + 3
        if a < 0 or b > force.time.size or force.index[b - 1] - force.index[a] != b - 1 - a:
            continue
        windows.append((start, force.time[a:b], force.values[a:b], detected["duration"][i]))
    if len(windows) > MAX_PULSES:   # evenly over the recording: enough for the estimates, bounded time
        windows = [windows[i] for i in np.linspace(0, len(windows) - 1, MAX_PULSES).round().astype(int)]
    # First guess from the strongest impacts, several starts each.
    order = sorted(range(len(windows)), key=lambda w: -float(windows[w][2].max()))[:4]
    guesses = []
    for w in order:
        start, t, v, dur = windows[w]
        best = None
        for zeta in PULSE_ZETA_STARTS:
            wd_over_w0 = math.sqrt(1 - zeta ** 2)
            w0 = _release(zeta, wd_over_w0) / (dur + 0.5 * dt)       # release time = duration above threshold
            fit, om = _fit_one_pulse(t, v, start, dt, zeta * w0, wd_over_w0 * w0)
            if best is None or fit.cost < best[0]:
                best = (fit.cost, fit.x[2] * om, fit.x[3] * om)
        guesses.append(best[1:])
    sigma0, omega0 = (float(np.median([g[0] for g in guesses])), float(np.median([g[1] for g in guesses]))) \
        if guesses else (1.0, 1.0)
    rows = []
    noise = float(np.median(np.abs(force.values[force.values < 1.0]))) * 1.4826 if force.values.size else 0.01
    firsts = []
    for start, t, v, _dur in windows:
        # Laser: quadratic over the free flight just before the onset (at most 20 ms, after the last impact).
        prev = onsets_all[onsets_all < start - 1e-4]
        lo = max(start - 0.02, (prev.max() + 0.004) if prev.size else -np.inf)
        sel = (yt >= lo) & (yt <= start - 0.5e-3)
        v_in = y_on = math.nan
        if sel.sum() >= 8:
            cq = np.polyfit(yt[sel] - start, yy[sel], 2)
            v_in, y_on = float(cq[1]), float(cq[2])
        eps = accel(start, v_in) / v_in if (accel is not None and v_in > 1e-3) else 0.0
        fit, om = _fit_one_pulse(t, v, start, dt, sigma0, omega0, eps)
        firsts.append((start, t, v, v_in, y_on, eps, fit, om))
    # A fit whose residual is well above the sensor noise may be caught in a local minimum: try the other starts
    # and keep the best (a relative criterion, against the typical fit, let some through: 19 % on zeta).
    for k, (start, t, v, v_in, y_on, eps, fit, om) in enumerate(firsts):
        good = 25 * 0.5 * t.size * max(noise, 1e-6) ** 2
        if fit.cost > good:
            for zeta in PULSE_ZETA_STARTS:
                w0 = math.hypot(sigma0, omega0)
                trial, om2 = _fit_one_pulse(t, v, start, dt, zeta * w0, math.sqrt(1 - zeta ** 2) * w0, eps)
                if trial.cost < fit.cost:
                    fit, om = trial, om2
                if fit.cost <= good:
                    break
            firsts[k] = (start, t, v, v_in, y_on, eps, fit, om)
    for _start, t, _v, v_in, y_on, eps, fit, om in firsts:
        onset = t[0] + fit.x[0] * dt
        scale, sg, omega = fit.x[1], fit.x[2] * om, fit.x[3] * om
        if not (scale > 0 and omega > 0 and sg >= 0):
            continue
        peak, duration, impulse = _pulse_features(scale, sg, omega, eps)
        rows.append((onset, peak, duration, impulse, scale, sg, omega, v_in, y_on))
    arr = np.array(rows, dtype=float).reshape(-1, 9)
    return Impacts(*(arr[:, k] for k in range(9)), runs=int(detected["start"].size))


def _robust_mean(x: np.ndarray) -> tuple[float, float]:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan
    med = float(np.median(x))
    mad = float(np.median(np.abs(x - med))) * 1.4826
    keep = np.abs(x - med) <= 4 * mad + 1e-15
    xs = x[keep]
    return float(xs.mean()), float(xs.std(ddof=1) / math.sqrt(xs.size)) if xs.size > 1 else math.nan


def free_stretches(y_t: np.ndarray, y: np.ndarray, motor: dict[str, np.ndarray], schedule: Schedule,
                   onsets: np.ndarray, kicks: list[float], min_length: float = 0.05) -> list[np.ndarray]:
    """Index arrays of laser samples at constant motor frequency away from contacts and kicks."""
    ok = np.isfinite(y_t)
    tm = motor["time"]
    # Constant frequency: between a command's ramp end and the next command.
    f_rec = np.interp(np.where(ok, y_t, 0.0), tm, motor["frequency"])
    sp_rec = motor["frequency_setpoint"][np.clip(np.searchsorted(tm, np.where(ok, y_t, 0.0)) - 1, 0, tm.size - 1)]
    ok &= np.abs(f_rec - sp_rec) < 1e-9
    ok &= np.where(np.isfinite(y_t), y_t, -1) >= schedule.t0
    for t_on in onsets:
        ok &= ~((y_t > t_on - 3e-3) & (y_t < t_on + 4e-3))
    for tk in kicks:
        ok &= ~((y_t > tk - 3e-3) & (y_t < tk + 3e-3))
    for tc, _, _ in schedule.commands:
        ok &= ~((y_t > schedule.t0 + tc - 1e-3) & (y_t < schedule.t0 + tc + 1e-3))
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(idx) != 1) + 1
    pieces = np.split(idx, cuts)
    dt = float(np.median(np.diff(y_t[ok]))) if ok.sum() > 1 else 1.0
    return [p for p in pieces if p.size * dt >= min_length]


def fit_free_flight(y_t: np.ndarray, y: np.ndarray, pieces: list[np.ndarray], motor: dict[str, np.ndarray],
                    amplitude: float, guess: tuple[float, float]) -> tuple[tuple[float, float], tuple[float, float]]:
    """``f_n`` and ``zeta`` from the free stretches (variable projection); values and standard errors.

    Linearised model of the relative displacement: ``y'' + 2 zeta w y' + w^2 y = A0 Omega^2 sin phi``; per
    stretch the base-excitation response plus ``e^{-zeta w s}(C1 cos w_d s + C2 sin w_d s)``.
    """
    from scipy.optimize import least_squares

    tm = motor["time"]
    phi_all = _unwrapped_phase(motor)
    data = []
    for p in pieces:
        t = y_t[p]
        data.append((t - t[0], y[p], np.interp(t, tm, phi_all), float(np.interp(t[0], tm, motor["frequency"]))))

    def resid(x):  # noqa: ANN001, ANN202
        fn, zeta = x[0], x[1] * 0.1
        w = 2 * math.pi * fn
        wd = w * math.sqrt(max(1 - zeta ** 2, 1e-12))
        out = []
        for s, yy, phi, f in data:
            om = 2 * math.pi * f
            h = amplitude * om ** 2 / (w ** 2 - om ** 2 + 2j * zeta * w * om)
            yp = np.imag(h * np.exp(1j * phi))
            e = np.exp(-zeta * w * s)
            basis = np.column_stack([e * np.cos(wd * s), e * np.sin(wd * s)])
            r = yy - yp
            coef, *_ = np.linalg.lstsq(basis, r, rcond=None)
            out.append(r - basis @ coef)
        return np.concatenate(out) if out else np.zeros(1)

    fit = least_squares(resid, [guess[0], guess[1] * 10], x_scale=[0.1, 0.1])
    n = fit.fun.size
    s2 = 2 * fit.cost / max(n - 2 - 2 * len(data), 1)
    try:
        cov = s2 * np.linalg.inv(fit.jac.T @ fit.jac)
        se = (math.sqrt(cov[0, 0]), 0.1 * math.sqrt(cov[1, 1]))
    except np.linalg.LinAlgError:
        se = (math.nan, math.nan)
    return (float(fit.x[0]), float(fit.x[1] * 0.1)), se


def _one_sided_filters(n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Weights giving the derivative at the boundary of a quadratic fitted to n samples (left, right)."""
    s = np.arange(n, dtype=float) * dt
    basis = np.column_stack([np.ones(n), s, s ** 2])
    pinv = np.linalg.pinv(basis)
    right = pinv[1]                 # samples at s = 0..(n-1)dt after the point: derivative at 0
    left = -right[::-1]             # samples before: mirrored
    return left, right


def detect_kicks(y_t: np.ndarray, y: np.ndarray, onsets: np.ndarray,
                 threshold: float = 0.01) -> list[tuple[float, float]]:
    """Jumps of the hammer's velocity without contact force (a ``/rig/perturb``): (time, velocity jump)."""
    finite = np.isfinite(y_t)
    t, x = y_t[finite], y[finite]
    if t.size < 100:
        return []
    dt = float(np.median(np.diff(t)))
    n = max(8, int(round(0.02 / dt)))      # 20 ms on either side
    left, right = _one_sided_filters(n, dt)
    v_left = np.full(x.size, np.nan)
    v_right = np.full(x.size, np.nan)
    # v_left[i]: fit over x[i-n:i] (ending one sample before i); v_right[i]: over x[i:i+n].
    cl = np.correlate(x, left, mode="valid")     # cl[k] uses x[k:k+n]
    cr = np.correlate(x, right, mode="valid")
    v_left[n:] = cl[: x.size - n]
    v_right[: x.size - n + 1] = cr
    # The left fit's derivative is at its last sample's time + dt: correct for the acceleration over one step.
    jump = v_right - v_left
    contiguous = np.r_[np.diff(t) < 1.5 * dt, False]
    ok = np.isfinite(jump)
    for i in np.flatnonzero(~contiguous):
        ok[max(i - n, 0): i + n + 1] = False
    for t_on in onsets:
        ok &= ~((t > t_on - 0.025) & (t < t_on + 0.025))
    noise = float(np.nanmedian(np.abs(jump[ok]))) * 1.4826 if ok.any() else 0.0
    level = max(threshold, 7 * noise)
    cand = np.flatnonzero(ok & (np.abs(jump) > level))
    kicks = []
    for group in np.split(cand, np.flatnonzero(np.diff(cand) > n) + 1) if cand.size else []:
        k = group[np.argmax(np.abs(jump[group]))]
        kicks.append((float(t[k] - 0.5 * dt), float(jump[k])))
    return kicks


# ---- forward model -------------------------------------------------------------------------------------------

def model_config(base: SimConfig, params: dict[str, float], schedule: Schedule, initial: tuple[float, float],
                 rtol: float = 1e-9) -> SimConfig:
    """The configuration the forward model runs: the parameters, the recorded motor start, the initial state."""
    max_f = max([base.motor.max_frequency, schedule.f0, schedule.setpoint0] + [c[1] for c in schedule.commands])
    return base.with_parameters({
        **params,
        "motor.max_frequency": max_f,
        "motor.initial_frequency": schedule.f0,
        "motor.initial_setpoint": schedule.setpoint0,
        "motor.ramp_rate": min(max(schedule.ramp0, 1e-3), 1e4),
        "initial.theta": initial[0],
        "initial.theta_dot": initial[1],
        "integrator.rtol": min(base.integrator.rtol, rtol),
        "integrator.atol": min(base.integrator.atol, rtol * 1e-2),
        "channels.rimd_acceleration.sample_rate": 100.0,
        "channels.impact_force.sample_rate": 100.0,
        "channels.rimd_acceleration.highpass": 0.0,
    })


@dataclass
class Simulation:
    """The forward model's output in recording time."""

    t: np.ndarray            # times of the displacement samples (recording time)
    y: np.ndarray            # relative displacement l sin theta (m)
    cart: np.ndarray         # cart displacement (m)
    impacts: list            # rimd_sim.core.model.Impact, times in model time
    t0: float


def simulate(config: SimConfig, schedule: Schedule, kicks: list[tuple[float, float]], t_end: float) -> Simulation:
    """Run the core's integrator under the recorded schedule (commands and kicks at their times, model time)."""
    from rimd_sim.core.model import RigModel

    model = RigModel(config, channels=True, truth=False)
    events = sorted([(tc, "motor", (f, r)) for tc, f, r in schedule.commands if tc < t_end]
                    + [(tk, "kick", v) for tk, v in kicks if 0 < tk < t_end], key=lambda e: e[0])
    parts = []
    impacts = []
    for when, kind, arg in events:
        out = model.advance(Fraction(repr(float(when))))
        parts.append(out)
        if kind == "motor":
            impacts += model.set_motor_frequency(arg[0], arg[1])
        else:
            impacts += model.perturb(arg)
    parts.append(model.advance(Fraction(repr(float(t_end)))))
    rate = config.channel("rimd_displacement").sample_rate
    first = parts[0].channels["rimd_displacement"][0]
    x = np.concatenate([p.channels["rimd_displacement"][1] for p in parts])
    xc = np.concatenate([p.channels["cart_displacement"][1] for p in parts])
    impacts = sorted(impacts + [i for p in parts for i in p.impacts], key=lambda i: i.t_start)
    t = schedule.t0 + (first + np.arange(x.size)) / rate
    return Simulation(t, x - xc, xc, impacts, schedule.t0)


# ---- the identification --------------------------------------------------------------------------------------

def _initial_state(y_t: np.ndarray, y: np.ndarray, t0: float, length: float) -> tuple[float, float]:
    finite = np.isfinite(y_t)
    t, x = y_t[finite], y[finite]
    sel = (t >= t0 - 0.01) & (t <= t0 + 0.01)
    if sel.sum() < 5:
        return 0.0, 0.0
    c = np.polyfit(t[sel] - t0, x[sel], 2)
    y0, v0 = float(c[2]), float(c[1])
    th = math.asin(max(-0.99, min(0.99, y0 / length)))
    return th, v0 / (length * math.cos(th))


def identify(path, base: SimConfig, fixed: dict[str, float], *, threshold: float = rec.DEFAULT_THRESHOLD,
             log=None) -> Identification:  # noqa: ANN001
    """Identify the free parameters of ``base`` from the recording at ``path`` (see the module doc).

    Raises:
        IdentificationError: A channel a parameter needs is missing, or no impact when contact parameters are
            asked for.
        rimd_sim.recording.reader.RecordingError: Not a recording.
    """
    from scipy.optimize import least_squares

    log = log or (lambda text: None)
    notes: list[str] = []

    def say(text: str) -> None:
        notes.append(text)
        log(text)

    data = rec.load(path)
    free = [p for p in IDENTIFIABLE if p not in fixed]
    if base.rig.contact.model != "spring_dashpot":
        raise IdentificationError(
            f"contact.model {base.rig.contact.model!r}: rimd identify fits the spring_dashpot law only; use a base "
            "config with contact.model: spring_dashpot, or --fix the contact parameters")
    missing: dict[str, list[str]] = {}
    for p in free:
        for topic in NEEDS[p]:
            if not data.counts.get(topic):
                missing.setdefault(topic, []).append(p)
    if missing:
        what = "; ".join(f"{', '.join(ps)} need {topic}" for topic, ps in missing.items())
        raise IdentificationError(f"the recording lacks channels: {what}; record them or pass --fix NAME=VALUE")
    cart = data.channels.get(rec.CART_X)
    motor = data.motor
    if not motor.get("time", np.empty(0)).size:
        if cart is None:
            raise IdentificationError("no /rig/motor/state and no /rig/cart/displacement: the motor frequency is "
                                      "unknown")
        motor, fr = phase_from_cart(cart)
        say(f"no /rig/motor/state: one constant motor frequency fitted to the cart laser, {fr:.5f} Hz")
    force = data.channels.get(rec.FORCE)
    rimd = data.channels.get(rec.RIMD_X)
    if rimd is not None and cart is not None:
        y_t, y, _ = rec.phase_plane(rimd, cart)
    else:
        y_t = y = np.empty(0)
    empty = np.empty(0)
    detected = rec.detect_impacts(force, threshold) if force is not None else {
        k: empty for k in ("start", "duration", "complete", "peak_force")}
    contact_free = [p for p in free if p in CONTACT_PARAMETERS]
    if contact_free and detected["start"].size == 0:
        raise IdentificationError(
            f"no impact in the recording (the force channel never reaches {threshold:g} N): {', '.join(contact_free)} "
            "cannot be identified; record impacts (a step in band A) or pass --fix " +
            " ".join(f"{p}=VALUE" for p in contact_free))

    # 1. schedule and amplitude.
    t_first = max(c.time[0] for c in data.channels.values()) if data.channels else motor["time"][0]
    schedule = motor_schedule(motor, float(t_first), detected["start"])
    if data.counts.get(rec.MOTOR):
        schedule.source = "/rig/motor/state"
    else:
        schedule.source = "cart laser (constant frequency)"
    estimates: dict[str, Estimate] = {}
    params = {k: float(v) for k, v in fixed.items()}
    base_rig = base.rig
    if "amplitude" in free:
        a0, se = fit_amplitude(cart, motor)
        estimates["amplitude"] = Estimate(a0, se, f"cart laser against the motor phase ({cart.values.size} samples)",
                                          a0, se)
        params["amplitude"] = a0
    amplitude = params.get("amplitude", base_rig.amplitude)
    say(f"motor: {len(schedule.commands)} setpoint change(s) after t0 = {schedule.t0:.4f} s; "
        f"A0 = {amplitude * 1e3:.5f} mm")

    # 2. impacts: pulses, impact velocity, gap, contact law, mass.
    imp = None
    kicks = detect_kicks(y_t, y, detected["start"]) if y.size else []
    if kicks:
        say("velocity kicks without contact: " + ", ".join(f"{v:+.4f} m/s at {t:.4f} s" for t, v in kicks))
    # 3. natural frequency and damping ratio from the free stretches.
    if "natural_frequency" in free or "damping_ratio" in free:
        pieces = free_stretches(y_t, y, motor, schedule, detected["start"], [k[0] for k in kicks])
        if not pieces:
            raise IdentificationError("no stretch of constant motor frequency without contact (50 ms or more): "
                                      "natural_frequency and damping_ratio cannot be identified; pass --fix")
        guess = (params.get("natural_frequency", base_rig.natural_frequency),
                 params.get("damping_ratio", base_rig.damping_ratio))
        (fn, zeta), (fn_se, z_se) = fit_free_flight(y_t, y, pieces, motor, amplitude, guess)
        seconds = sum(p.size for p in pieces) / rimd.rate
        src = f"free flight at constant motor frequency ({len(pieces)} stretches, {seconds:.1f} s)"
        if "natural_frequency" in free:
            estimates["natural_frequency"] = Estimate(fn, fn_se, src, fn, fn_se)
            params["natural_frequency"] = fn
        if "damping_ratio" in free:
            estimates["damping_ratio"] = Estimate(max(zeta, 0.0), z_se, src, zeta, z_se)
            params["damping_ratio"] = max(zeta, 0.0)
    # The hammer's acceleration relative to the cart without contact force, for the pulse fits (a small term).
    phase_all = _unwrapped_phase(motor)
    wn = 2 * math.pi * params.get("natural_frequency", base_rig.natural_frequency)
    zeta_ = params.get("damping_ratio", base_rig.damping_ratio)
    gap_guess = float(np.nanmedian(np.interp(detected["start"], y_t[np.isfinite(y_t)], y[np.isfinite(y_t)]))) \
        if detected["start"].size and y.size else 0.0

    def accel(t: float, v0: float) -> float:
        om = 2 * math.pi * float(np.interp(t, motor["time"], motor["frequency"]))
        ph = float(np.interp(t, motor["time"], phase_all))
        return amplitude * om ** 2 * math.sin(ph) - wn ** 2 * gap_guess - 2 * zeta_ * wn * v0

    if force is not None and detected["start"].size and y.size:
        imp = fit_pulses(force, detected, y_t, y, accel)
        say(f"impacts: {imp.runs} seen in the force channel, {imp.onset.size} pulses fitted")
        if imp.onset.size == 0 and contact_free:
            raise IdentificationError("no complete impact pulse in the force channel: " + ", ".join(contact_free)
                                      + " cannot be identified; pass --fix")
    if imp is not None and imp.onset.size:
        sg, sg_se = _robust_mean(imp.sigma)
        om, om_se = _robust_mean(imp.omega)
        ratio = imp.scale / imp.v0
        m_loc, m_se = _robust_mean(np.where(imp.v0 > 0.005, ratio, np.nan))
        if "mass" not in free:
            m_loc, m_se = params["mass"], 0.0
        if not math.isfinite(m_loc):
            raise IdentificationError("the hammer laser shows no impact velocity at the impacts: mass cannot be "
                                      "identified; pass --fix mass=VALUE")
        k_loc = m_loc * (om ** 2 + sg ** 2)
        c_loc = 2 * m_loc * sg
        rel_m = m_se / m_loc if m_se == m_se else 0.0
        k_se = k_loc * math.hypot(rel_m, 2 * (om * om_se + sg * sg_se) / (om ** 2 + sg ** 2))
        c_se = c_loc * math.hypot(rel_m, sg_se / sg if sg > 0 else 0.0)
        n_imp = int(np.isfinite(imp.v0).sum())
        local = {"mass": (m_loc, m_se, f"pulse scale m v0 over the laser's impact velocity v0 ({n_imp} impacts)"),
                 "contact.stiffness": (k_loc, k_se, f"pulse frequency k/m and decay c/2m ({imp.onset.size} pulses) "
                                                    "times the mass"),
                 "contact.damping": (c_loc, c_se, f"pulse decay c/2m ({imp.onset.size} pulses) times the mass")}
        g_loc, g_se = _robust_mean(imp.y_onset)
        local["gap"] = (max(g_loc, 0.0), g_se, f"relative displacement at the contact onsets ({n_imp} impacts)")
        for p, (v, se, src) in local.items():
            if p in free:
                estimates[p] = Estimate(v, se, src, v, se)
                params[p] = v

    say("local estimates: " + ", ".join(f"{k} = {v.value:.6g}" for k, v in estimates.items()))

    # 4. joint refinement with the core's integrator.
    config0 = base.with_parameters(params)
    length = config0.rig.length
    initial = _initial_state(y_t, y, schedule.t0, length)
    t_end = schedule.end
    if y.size:
        t_end = min(t_end, float(np.nanmax(y_t)) - schedule.t0)
    fin = np.isfinite(y_t)
    sel_t = y_t[fin]
    sel_y = y[fin]
    keep = (sel_t >= schedule.t0) & (sel_t <= schedule.t0 + t_end)
    step = max(1, int(round(rimd.rate / FIT_RATE))) if rimd is not None else 1
    fit_t, fit_y = sel_t[keep][::step], sel_y[keep][::step]
    sigma_y = _laser_noise(sel_y)
    # The cart laser too (it pins A0 in the joint fit), at the same decimated rate.
    if cart is not None:
        ck = (cart.time >= schedule.t0) & (cart.time <= schedule.t0 + t_end)
        cstep = max(1, int(round(cart.rate / FIT_RATE)))
        cart_t, cart_x = cart.time[ck][::cstep], cart.values[ck][::cstep]
        sigma_c = _laser_noise(cart.values)
    else:
        cart_t = cart_x = np.empty(0)
        sigma_c = 1.0
    feat_on = imp.onset if imp is not None else np.empty(0)
    feat_ok = (feat_on >= schedule.t0 + 1e-3) & (feat_on <= schedule.t0 + t_end - 0.01)
    f_on = feat_on[feat_ok]
    f_peak = imp.peak[feat_ok] if imp is not None else np.empty(0)
    f_dur = imp.duration[feat_ok] if imp is not None else np.empty(0)
    f_imp = imp.impulse[feat_ok] if imp is not None else np.empty(0)
    peak_sigma = SIGMA_PEAK_FRACTION * (float(np.median(f_peak)) if f_peak.size else 1.0)
    imp_sigma = SIGMA_IMPULSE_FRACTION * (float(np.median(f_imp)) if f_imp.size else 1.0)

    names = list(estimates)
    x0_params = np.array([estimates[p].value / SCALES[p] for p in names])
    n_kick = len(kicks)

    def unpack(x):  # noqa: ANN001, ANN202
        values = dict(params)
        for i, p in enumerate(names):
            values[p] = float(x[i] * SCALES[p])
        values["gap"] = max(values.get("gap", base_rig.gap), 0.0)
        th0, thd0 = x[len(names)] * 0.01, x[len(names) + 1] * 0.1
        ks = [(kicks[j][0] - schedule.t0 + x[len(names) + 2 + 2 * j] * 1e-3, x[len(names) + 3 + 2 * j] * 0.01)
              for j in range(n_kick)]
        return values, (th0, thd0), ks

    def forward(x):  # noqa: ANN001, ANN202
        values, init, ks = unpack(x)
        cfg = model_config(base, values, schedule, init)
        return simulate(cfg, schedule, ks, t_end), cfg

    def residuals(x, parts: bool = False):  # noqa: ANN001, ANN202
        try:
            sim, _ = forward(x)
        except Exception:  # noqa: BLE001 - a trial point where the integrator fails: a large residual
            r = np.full(fit_y.size + cart_x.size + 4 * f_on.size, 1e3)
            return (r, {}) if parts else r
        ry = (np.interp(fit_t, sim.t, sim.y) - fit_y) / sigma_y
        rc = (np.interp(cart_t, sim.t, sim.cart) - cart_x) / sigma_c
        m_on = np.array([i.t_start for i in sim.impacts]) + schedule.t0
        rt = np.zeros(f_on.size)
        rp = np.zeros(f_on.size)
        rd = np.zeros(f_on.size)
        ri = np.zeros(f_on.size)
        if f_on.size:
            if m_on.size:
                j = np.zeros(f_on.size, int)
                if m_on.size > 1:
                    j = np.clip(np.searchsorted(m_on, f_on), 1, m_on.size - 1)
                    j = np.where(np.abs(m_on[j - 1] - f_on) < np.abs(m_on[j] - f_on), j - 1, j)
                dtm = m_on[j] - f_on
                near = np.abs(dtm) < 5e-3
                mp = np.array([sim.impacts[k].peak_force for k in j])
                md = np.array([sim.impacts[k].duration for k in j])
                mi = np.array([sim.impacts[k].impulse for k in j])
                rt = np.where(near, dtm, np.sign(dtm) * 5e-3) / SIGMA_ONSET
                rp = np.where(near, mp - f_peak, -f_peak) / peak_sigma
                rd = np.where(near, md - f_dur, -f_dur) / SIGMA_DURATION
                ri = np.where(near, mi - f_imp, -f_imp) / imp_sigma
            else:
                rt = np.full(f_on.size, 5e-3 / SIGMA_ONSET)
                rp, rd, ri = -f_peak / peak_sigma, -f_dur / SIGMA_DURATION, -f_imp / imp_sigma
        r = np.concatenate([ry, rc, rt, rp, rd, ri])
        if parts:
            return r, {"sim": sim, "ry": ry, "rc": rc, "rt": rt, "rp": rp, "rd": rd, "ri": ri}
        return r

    x0 = np.concatenate([x0_params, [initial[0] / 0.01, initial[1] / 0.1]]
                        + [[0.0, v / 0.01] for _, v in kicks])
    say(f"joint refinement: {len(x0)} unknowns ({len(names)} parameters, initial state, {n_kick} kick(s)), "
        f"{fit_y.size} displacement samples, {f_on.size} impacts")
    fit = least_squares(residuals, x0, diff_step=1e-5, x_scale="jac", max_nfev=60 * len(x0), xtol=1e-10, ftol=1e-10)
    dof = max(fit.fun.size - fit.x.size, 1)
    s2 = 2 * fit.cost / dof
    try:
        cov = np.linalg.pinv(fit.jac.T @ fit.jac) * s2
        std = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        std = np.full(fit.x.size, np.nan)
    values, init, ks = unpack(fit.x)
    for i, p in enumerate(names):
        e = estimates[p]
        at_bound = p == "gap" and values[p] == 0.0
        estimates[p] = Estimate(values[p], None if at_bound else float(std[i] * SCALES[p]),
                                "joint refinement with the core's integrator (starting from: " + e.source + ")",
                                e.local_value, e.local_std_error)
    final = base.with_parameters(values)
    _, parts = residuals(fit.x, parts=True)
    sim = parts.get("sim")
    resid = {
        "displacement_rms_um": float(np.sqrt(np.mean((parts["ry"] * sigma_y) ** 2)) * 1e6) if sim else None,
        "laser_noise_um": sigma_y * 1e6,
        "cart_rms_um": float(np.sqrt(np.mean((parts["rc"] * sigma_c) ** 2)) * 1e6) if sim and cart_x.size else None,
        "onset_rms_us": float(np.sqrt(np.mean((parts["rt"] * SIGMA_ONSET) ** 2)) * 1e6) if f_on.size and sim else None,
        "peak_rms_n": float(np.sqrt(np.mean((parts["rp"] * peak_sigma) ** 2))) if f_on.size and sim else None,
        "duration_rms_us": float(np.sqrt(np.mean((parts["rd"] * SIGMA_DURATION) ** 2)) * 1e6)
        if f_on.size and sim else None,
        "impulse_rms_ns": float(np.sqrt(np.mean((parts["ri"] * imp_sigma) ** 2))) if f_on.size and sim else None,
        "reduced_chi2": s2,
        "evaluations": int(fit.nfev),
        "status": fit.message,
    }
    say(f"joint refinement: {fit.nfev} evaluations, displacement residual {resid['displacement_rms_um']:.2f} um rms "
        f"(laser noise {sigma_y * 1e6:.2f} um)")
    info = {
        "samples_displacement": int(fit_y.size), "impacts_seen": int(detected["start"].size),
        "impacts_fitted": int(f_on.size), "kicks": [{"time_s": t, "velocity_m_s": v} for t, v in kicks],
        "schedule": {"t0_s": schedule.t0, "initial_frequency_hz": schedule.f0, "source": schedule.source,
                     "commands": [{"time_s": schedule.t0 + t, "setpoint_hz": f, "ramp_rate_hz_s": r}
                                  for t, f, r in schedule.commands]},
        "recording_loss": data.loss(),
    }
    ident = Identification(final, estimates, dict(fixed), schedule,
                           [(schedule.t0 + t, v) for t, v in ks], init, info, resid, log=notes)
    ident.validation, ident.series = validate(data, ident, sim, imp, motor, y_t, y, threshold)
    return ident


def _steady_peak(peaks: np.ndarray) -> float:
    """Largest peak of a steady window, ignoring a lone outlier (a pulse fit caught in a local minimum).

    Peaks further than 5 median absolute deviations plus 0.5 % from the median are left out; the two levels
    of a period-doubled motion (alternating magnitudes) both stay.
    """
    if peaks.size == 0:
        return 0.0
    med = float(np.median(peaks))
    mad = float(np.median(np.abs(peaks - med)))
    keep = np.abs(peaks - med) <= 5 * mad + 0.005 * med
    return float(peaks[keep].max())


def _laser_noise(y: np.ndarray) -> float:
    """Noise of the relative displacement from its second differences (smooth motion cancels)."""
    d2 = np.diff(y, 2)
    d2 = d2[np.isfinite(d2)]
    if d2.size == 0:
        return 1e-5
    return max(float(np.median(np.abs(d2))) * 1.4826 / math.sqrt(6.0), 1e-7)


def validate(data: rec.RecordedData, ident: Identification, sim: Simulation | None, imp: Impacts | None,
             motor: dict, y_t: np.ndarray, y: np.ndarray, threshold: float) -> tuple[list[dict], dict]:
    """Per motor step: the recording against the twin re-simulated with the identified parameters."""
    rows: list[dict] = []
    if sim is None:
        return rows, {}
    steps = rec.segment_steps(motor, 2.0, end=float(sim.t[-1]))
    m_on = np.array([i.t_start for i in sim.impacts]) + sim.t0
    m_peak = np.array([i.peak_force for i in sim.impacts])
    r_on = imp.onset if imp is not None else np.empty(0)
    r_peak = imp.peak if imp is not None else np.empty(0)
    phase_all = _unwrapped_phase(motor)
    fin = np.isfinite(y_t)
    ty, yy = y_t[fin], y[fin]
    ym = np.interp(ty, sim.t, sim.y)
    for s in steps:
        if s.steady_from is None or s.steady_from < sim.t0:
            continue
        lo, hi = s.steady_from, s.end
        rsel = (r_on >= lo) & (r_on < hi)
        msel = (m_on >= lo) & (m_on < hi)
        ysel = (ty >= lo) & (ty < hi)
        cycles = (hi - lo) * s.setpoint

        def phase(times):  # noqa: ANN001, ANN202
            if times.size == 0:
                return None
            ph = np.interp(times, motor["time"], phase_all)
            return float(np.angle(np.mean(np.exp(1j * ph))) % (2 * math.pi))

        rp, mp = _steady_peak(r_peak[rsel]), _steady_peak(m_peak[msel])
        rows.append({
            "step": s.number, "frequency_hz": s.setpoint, "steady_from_s": lo, "end_s": hi,
            "peak_force_recorded_n": rp, "peak_force_twin_n": mp,
            "peak_force_difference": (mp / rp - 1.0) if rp > 0 else None,
            "impacts_per_cycle_recorded": float(rsel.sum() / cycles) if cycles else None,
            "impacts_per_cycle_twin": float(msel.sum() / cycles) if cycles else None,
            "impact_phase_recorded_rad": phase(r_on[rsel]), "impact_phase_twin_rad": phase(m_on[msel]),
            "displacement_rms_difference_um": float(np.sqrt(np.mean((ym[ysel] - yy[ysel]) ** 2)) * 1e6)
            if ysel.any() else None,
        })
    series = {"t": ty, "y": yy, "y_twin": ym, "r_on": r_on, "r_peak": r_peak, "m_on": m_on, "m_peak": m_peak,
              "steps": steps}
    return rows, series
