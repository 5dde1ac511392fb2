"""The local stages of ``rimd identify``: each parameter from the data that show it best, with its error.

Each function takes measured arrays and returns a typed estimate; :mod:`rimd_sim.analysis.identification.identify`
runs them in order and hands the results to the joint fit (:mod:`rimd_sim.analysis.identification.joint_fit`).

* :func:`motor_schedule`: the motor as recorded from a motor cycle start: setpoints, when they were commanded
  (where the linear ramp of the recorded frequency starts) and their ramps; :func:`phase_from_cart` without
  motor states (one constant frequency fitted to the cart laser).
* :func:`fit_amplitude`: A0 from the cart laser against the motor phase (linear least squares).
* :func:`free_stretches`, :func:`fit_free_flight`: ``f_n`` and ``zeta`` from the relative displacement in free
  flight at constant motor frequency (base-excitation response plus a free decay per stretch, variable
  projection).
* :func:`detect_kicks`: jumps of the hammer's velocity without contact force (``/rig/perturb``).
* :func:`impact_samples`, :func:`local_contact`: the contact pulse (the common spring-dashpot shape of all
  impacts, :func:`rimd_sim.analysis.recordings.contact_pulse.fit_pulses`, from the triggered 1 MHz captures when the
  recording has them), each impact's onset and scale ``m v0 / cos(theta)``, the laser's impact velocity
  ``v0`` and relative displacement at the onset: ``k/m``, ``c/m``, then ``m = scale cos(theta) / v0``,
  ``k = m w0^2 / cos``, ``c = 2 m (sigma - zeta w_n) / cos`` and the gap.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from rimd_sim.analysis.recordings import recorded as rec
from rimd_sim.analysis.recordings.contact_pulse import (
    PulseFit,
    PulseSamples,
    fit_onsets,
    fit_pulses,
    onset_scale_errors,
)
from rimd_sim.errors import AnalysisError

__all__ = ["ContactEstimate", "Schedule", "cycle_start", "detect_kicks", "fit_amplitude", "fit_free_flight",
           "free_stretches", "impact_samples", "local_contact", "motor_schedule", "phase_from_cart",
           "unwrapped_phase"]


class LocalError(AnalysisError):
    """A local stage cannot give its estimate from this recording (one line: what, why, what to do)."""


@dataclass
class Schedule:
    """The motor as recorded, in a forward model's time (s since ``t0``, a motor phase zero)."""

    t0: float
    f0: float
    setpoint0: float
    ramp0: float
    commands: list[tuple[float, float, float]]   # (time since t0, setpoint, ramp rate)
    end: float                                   # s since t0
    source: str = "/rig/motor/state"


def unwrapped_phase(motor: dict[str, np.ndarray]) -> np.ndarray:
    """The motor phase ``2 pi cycle_index + phase`` (rad)."""
    return 2.0 * math.pi * motor["cycle_index"] + motor["phase"]


def cycle_start(motor: dict[str, np.ndarray], after: float, avoid: np.ndarray, clear: float = 5e-3,
                before: float | None = None) -> float | None:
    """The first motor phase zero after ``after`` (and before ``before``) at least ``clear`` s from ``avoid``."""
    zeros = rec.poincare_times(motor)
    zeros = zeros[zeros >= after]
    if before is not None:
        zeros = zeros[zeros < before]
    for z in zeros:
        if avoid.size == 0 or np.min(np.abs(avoid - z)) > clear:
            return float(z)
    return None


def motor_schedule(motor: dict[str, np.ndarray], t0: float, end: float) -> Schedule:
    """The motor schedule from ``t0`` to ``end`` (recording times): the frequency at ``t0``, then the commands.

    A setpoint's command time is where the linear ramp of the recorded frequency starts.
    """
    t, sp, f = motor["time"], motor["frequency_setpoint"], motor["frequency"]
    cuts = np.flatnonzero(np.diff(sp) != 0) + 1
    commands: list[tuple[float, float, float]] = []
    for c in cuts:
        f_prev = float(f[c - 1])
        target = float(sp[c])
        nxt = cuts[cuts > c]
        stop = int(nxt[0]) if nxt.size else t.size
        seg_t, seg_f = t[c:stop], f[c:stop]
        inside = (np.abs(seg_f - target) > 1e-9) & (np.abs(seg_f - f_prev) > 1e-9)
        if inside.sum() >= 2:
            slope, icpt = np.polyfit(seg_t[inside], seg_f[inside], 1)
            tc = (f_prev - icpt) / slope
            rate = abs(slope)
        else:   # a ramp shorter than the motor states' period: a step at the change
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
    later = [(tc - t0, s, r) for tc, s, r in commands if t0 < tc < end]
    return Schedule(t0, f0, setpoint0, ramp0, later, end - t0)


def phase_from_cart(cart: rec.Channel) -> tuple[dict[str, np.ndarray], float]:
    """Without motor states: one constant frequency fitted to the cart laser; synthetic motor states."""
    from scipy.optimize import least_squares

    t, x = cart.time, cart.values
    n = x.size
    spec = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(n)))
    freqs = np.fft.rfftfreq(n, 1.0 / cart.rate)
    f_guess = float(freqs[1 + np.argmax(spec[1:])])

    def resid(p: np.ndarray) -> np.ndarray:
        w = 2 * math.pi * p[0]
        basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
        coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
        return basis @ coef - x

    fr = float(least_squares(resid, [f_guess], x_scale=[0.01]).x[0])
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


def fit_amplitude(cart_t: np.ndarray, cart_x: np.ndarray, motor: dict[str, np.ndarray]) -> tuple[float, float]:
    """A0 and its standard error: ``x_c = a sin phi + b cos phi + offset`` at the cart laser's samples."""
    tm = motor["time"]
    inside = (cart_t >= tm[0]) & (cart_t <= tm[-1])
    t, x = cart_t[inside], cart_x[inside]
    phi = np.interp(t, tm, unwrapped_phase(motor))
    basis = np.column_stack([np.sin(phi), np.cos(phi), np.ones_like(phi)])
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    res = x - basis @ coef
    s2 = float(res @ res) / max(x.size - 3, 1)
    cov = s2 * np.linalg.inv(basis.T @ basis)
    return float(math.hypot(coef[0], coef[1])), float(math.sqrt(cov[0, 0]))


def laser_noise(y: np.ndarray) -> float:
    """Noise of a displacement from its second differences (smooth motion cancels)."""
    d2 = np.diff(y, 2)
    d2 = d2[np.isfinite(d2)]
    if d2.size == 0:
        return 1e-5
    return max(float(np.median(np.abs(d2))) * 1.4826 / math.sqrt(6.0), 1e-7)


def free_stretches(y_t: np.ndarray, keep: np.ndarray, motor: dict[str, np.ndarray], t_from: float,
                   onsets: np.ndarray, kicks: list[float], commands: list[float],
                   min_length: float = 0.05) -> list[np.ndarray]:
    """Index arrays of laser samples at constant motor frequency away from contacts, kicks and left-out windows."""
    ok = np.isfinite(y_t) & keep
    tm = motor["time"]
    tt = np.where(np.isfinite(y_t), y_t, 0.0)
    f_rec = np.interp(tt, tm, motor["frequency"])
    sp_rec = motor["frequency_setpoint"][np.clip(np.searchsorted(tm, tt) - 1, 0, tm.size - 1)]
    ok &= np.abs(f_rec - sp_rec) < 1e-9
    ok &= tt >= t_from
    for t_on in onsets:
        ok &= ~((y_t > t_on - 3e-3) & (y_t < t_on + 4e-3))
    for tk in kicks:
        ok &= ~((y_t > tk - 3e-3) & (y_t < tk + 3e-3))
    for tc in commands:
        ok &= ~((y_t > tc - 1e-3) & (y_t < tc + 1e-3))
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return []
    pieces = np.split(idx, np.flatnonzero(np.diff(idx) != 1) + 1)
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
    phi_all = unwrapped_phase(motor)
    data = []
    for p in pieces:
        t = y_t[p]
        data.append((t - t[0], y[p], np.interp(t, tm, phi_all), float(np.interp(t[0], tm, motor["frequency"]))))

    def resid(x: np.ndarray) -> np.ndarray:
        fn, zeta = x[0], x[1] * 0.1
        w = 2 * math.pi * fn
        wd = w * math.sqrt(max(1 - zeta ** 2, 1e-12))
        out = []
        for s, yy, phi, f in data:
            om = 2 * math.pi * f
            h = amplitude * om ** 2 / (w ** 2 - om ** 2 + 2j * zeta * w * om)
            r = yy - np.imag(h * np.exp(1j * phi))
            e = np.exp(-zeta * w * s)
            basis = np.column_stack([e * np.cos(wd * s), e * np.sin(wd * s), np.ones_like(s)])
            coef, *_ = np.linalg.lstsq(basis, r, rcond=None)
            out.append(r - basis @ coef)
        return np.concatenate(out) if out else np.zeros(1)

    best = None
    for f_try in (guess[0], guess[0] * 0.85, guess[0] * 1.15):
        fit = least_squares(resid, [f_try, guess[1] * 10], x_scale=[0.1, 0.1], bounds=([0.05, 0.0], [50.0, 9.9]))
        if best is None or fit.cost < best.cost:
            best = fit
    fit = best
    assert fit is not None   # three tries
    n = fit.fun.size
    s2 = 2 * fit.cost / max(n - 2 - 3 * len(data), 1)
    try:
        cov = s2 * np.linalg.inv(fit.jac.T @ fit.jac)
        se = (math.sqrt(cov[0, 0]), 0.1 * math.sqrt(cov[1, 1]))
    except np.linalg.LinAlgError:
        se = (math.nan, math.nan)
    return (float(fit.x[0]), float(fit.x[1] * 0.1)), se


def _one_sided_filters(n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Weights giving the derivative at the boundary of a quadratic fitted to n samples (left, right)."""
    s = np.arange(n, dtype=float) * dt
    pinv = np.linalg.pinv(np.column_stack([np.ones(n), s, s ** 2]))
    right = pinv[1]
    return -right[::-1], right


def detect_kicks(y_t: np.ndarray, y: np.ndarray, keep: np.ndarray, onsets: np.ndarray,
                 threshold: float = 0.01) -> list[tuple[float, float]]:
    """Jumps of the hammer's velocity without contact force (a ``/rig/perturb``): (time, velocity jump).

    ``keep``: False where the data cannot tell (a laser's or the force sensor's left-out window: an impact in
    a hole of the force channel shows on the lasers as a jump without force).
    """
    finite = np.isfinite(y_t)
    t, x, ok_data = y_t[finite], y[finite], keep[finite]
    if t.size < 100:
        return []
    dt = float(np.median(np.diff(t)))
    n = max(8, int(round(0.02 / dt)))      # 20 ms on either side
    left, right = _one_sided_filters(n, dt)
    v_left = np.full(x.size, np.nan)
    v_right = np.full(x.size, np.nan)
    cl = np.correlate(x, left, mode="valid")
    cr = np.correlate(x, right, mode="valid")
    v_left[n:] = cl[: x.size - n]
    v_right[: x.size - n + 1] = cr
    jump = v_right - v_left
    contiguous = np.r_[np.diff(t) < 1.5 * dt, False]
    ok = np.isfinite(jump)
    for i in np.flatnonzero(~contiguous | ~ok_data):
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


def impact_samples(force: rec.Channel, starts: np.ndarray, durations: np.ndarray, keep: np.ndarray,
                   limit: int | None = None) -> tuple[list[PulseSamples], np.ndarray]:
    """Each complete impact's samples with the bounds of its onset; the indices of the impacts taken.

    From the last sample below 5 times the sensor's noise before the contact to 2 samples after the run above
    the threshold; ``keep`` (per impact) leaves out those a left-out window touches; ``limit``: at most this many,
    evenly spread over the recording.
    """
    dt = 1.0 / force.rate
    quiet = max(5.0 * rec.force_noise(force), 1e-6)
    taken, out = [], []
    for i in np.flatnonzero(keep):
        j = int(np.searchsorted(force.time, starts[i]))
        a = j
        while a > 1 and j - a < 10 and force.values[a - 1] > quiet:
            a -= 1
        b = j + int(round(durations[i] / dt)) + 2
        if a < 1 or b > force.time.size or force.index[b - 1] - force.index[a - 1] != b - a:
            continue
        out.append(PulseSamples(force.time[a - 1:b], force.values[a - 1:b], dt, float(force.time[a - 1]),
                                float(force.time[a])))
        taken.append(i)
    idx = np.array(taken, dtype=int)
    if limit is not None and len(out) > limit:
        pick = np.linspace(0, len(out) - 1, limit).round().astype(int)
        out, idx = [out[k] for k in pick], idx[pick]
    return out, idx


def capture_samples(captures: list[rec.Capture], quiet: float, limit: int = 40,
                    after: float = 2e-3) -> list[PulseSamples]:
    """The triggered captures' samples from just before the contact to ``after`` s past the trigger."""
    out = []
    for cap in captures:
        v, t = cap.values, cap.time
        above = np.flatnonzero(v > quiet)
        if above.size == 0 or above[0] == 0:
            continue
        j = int(above[0])
        # to the end of the first contact (the first run of 20 quiet samples after it) and 20 samples more
        quiet_run = np.flatnonzero(np.convolve(v[j:] <= quiet, np.ones(20), mode="valid") == 20)
        stop = min(v.size, j + int(quiet_run[0]) + 20 if quiet_run.size else int(np.searchsorted(t, cap.trigger
                                                                                                  + after)))
        if stop - j < 5:
            continue
        out.append(PulseSamples(t[j - 1:stop], v[j - 1:stop], 1.0 / cap.rate, float(t[j - 1]), float(t[j])))
    if len(out) > limit:
        out = [out[k] for k in np.linspace(0, len(out) - 1, limit).round().astype(int)]
    return out


@dataclass
class ContactEstimate:
    """What the impacts show locally: the common pulse, per impact onset, scale and the laser's velocity."""

    pulse: PulseFit
    source: str                       # "captures" or the force channel's rate
    onsets: np.ndarray                # per impact (s)
    scales: np.ndarray                # m v0 / cos(theta) (N s... kg m/s)
    onset_se: np.ndarray
    scale_se: np.ndarray
    v0: np.ndarray                    # laser's impact velocity (m/s), NaN where not measurable
    y_onset: np.ndarray               # laser's relative displacement at the onset (m)
    indices: np.ndarray               # rows of the detection
    samples: list[PulseSamples] = field(default_factory=list)   # per impact: its capture, else its channel samples
    values: dict[str, tuple[float, float]] = field(default_factory=dict)   # name -> (value, std error)


def laser_at_onsets(y_t: np.ndarray, y: np.ndarray, onsets: np.ndarray, all_onsets: np.ndarray,
                    keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The relative velocity and displacement at each onset: a quadratic over the free flight just before it.

    At most 20 ms, after the previous impact, laser samples outside left-out windows; NaN when fewer than 8.
    """
    finite = np.isfinite(y_t) & keep
    yt, yy = y_t[finite], y[finite]
    v0, y0 = np.full(onsets.size, np.nan), np.full(onsets.size, np.nan)
    for k, start in enumerate(onsets):
        prev = all_onsets[all_onsets < start - 1e-4]
        lo = max(start - 0.02, (prev.max() + 0.004) if prev.size else -np.inf)
        sel = (yt >= lo) & (yt <= start - 0.5e-3)
        if sel.sum() >= 8:
            cq = np.polyfit(yt[sel] - start, yy[sel], 2)
            v0[k], y0[k] = float(cq[1]), float(cq[2])
    return v0, y0


def robust_mean(x: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of ``x`` without the points beyond 4 robust deviations of the median."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan
    med = float(np.median(x))
    mad = float(np.median(np.abs(x - med))) * 1.4826
    xs = x[np.abs(x - med) <= 4 * mad + 1e-15]
    return float(xs.mean()), float(xs.std(ddof=1) / math.sqrt(xs.size)) if xs.size > 1 else math.nan


#: Most impacts whose samples fit the common pulse shape (evenly spread; every impact then gets its onset
#: and scale with that shape).
MAX_SHAPE_IMPACTS = 80
#: Most triggered captures used (evenly spread): each replaces its impact's channel samples in the joint fit.
MAX_CAPTURES = 200
#: Impacts slower than this fraction of the typical impact velocity are grazing: left out of the joint fit.
GRAZING = 0.25


def local_contact(force: rec.Channel, detected: dict[str, np.ndarray], keep: np.ndarray, captures: list[rec.Capture],
                  y_t: np.ndarray, y: np.ndarray, laser_keep: np.ndarray, accel: Callable[[float], float],
                  length: float, sigma_free: float, free_mass: bool, mass: float | None) -> ContactEstimate | None:
    """The contact's local estimates (see the module doc); None when no complete impact is left.

    ``accel(t)``: the hammer's free acceleration relative to the cart at ``t`` (m/s^2) for ``eps``;
    ``length``: the pendulum's length (m, for ``cos(theta)`` at the gap).
    """
    complete = (detected["complete"] > 0) & keep
    samples, idx = impact_samples(force, detected["start"], detected["duration"], complete)
    if not samples:
        return None
    v0, y0 = laser_at_onsets(y_t, y, detected["start"][idx], detected["start"], laser_keep)
    for p, v, t_on in zip(samples, v0, detected["start"][idx], strict=True):
        if math.isfinite(v) and v > 1e-3:
            p.eps = accel(t_on) / v
            p.eps1 = (accel(t_on + 1e-4) - accel(t_on - 1e-4)) / 2e-4 / v
    quiet = max(5.0 * rec.force_noise(force), 1e-6)
    caps = capture_samples(captures, quiet, limit=MAX_CAPTURES) if captures else []
    joint = list(samples)
    for p in caps:   # the capture of an impact replaces its channel samples; the laser's velocity of that impact
        nearest = int(np.argmin(np.abs(detected["start"][idx] - p.onset_hi))) if idx.size else -1
        if nearest >= 0 and abs(detected["start"][idx][nearest] - p.onset_hi) < 1e-3:
            p.eps, p.eps1 = samples[nearest].eps, samples[nearest].eps1
            joint[nearest] = p
    caps = [p for p in joint if p.dt < 0.5 / force.rate]
    if len(caps) >= 3:
        shape_set = caps if len(caps) <= 40 else [caps[k] for k in
                                                  np.linspace(0, len(caps) - 1, 40).round().astype(int)]
        pulse, source = fit_pulses(shape_set, sigma_free=sigma_free), f"{len(caps)} triggered captures at " \
            f"{1.0 / caps[0].dt / 1e6:g} MHz"
    else:
        shape_set = samples
        if len(samples) > MAX_SHAPE_IMPACTS:
            shape_set = [samples[k] for k in np.linspace(0, len(samples) - 1, MAX_SHAPE_IMPACTS).round().astype(int)]
        pulse, source = fit_pulses(shape_set, sigma_free=sigma_free), \
            f"{len(shape_set)} impacts of the force channel at {force.rate:g} Hz"
    if pulse is None:
        return None
    shape = pulse.pulse()
    onsets, scales = fit_onsets(shape, samples)
    on_se, sc_se, _ = onset_scale_errors(shape, samples, onsets, scales, max(rec.force_noise(force), 1e-4))
    # Grazing impacts (a quarter of the typical impact velocity or less) leave the joint fit: the hammer's free
    # acceleration is then a large part of its motion during the contact, and the pulse model's linear free
    # acceleration no longer describes the motion (their scales err ten times more than the others').
    typical = float(np.nanmedian(v0)) if np.isfinite(v0).any() else math.nan
    strong = ~(v0 < GRAZING * typical)
    keep_idx = np.flatnonzero(strong)
    est = ContactEstimate(pulse, source, onsets[keep_idx], scales[keep_idx], on_se[keep_idx], sc_se[keep_idx],
                          v0[keep_idx], y0[keep_idx], idx[keep_idx], [joint[k] for k in keep_idx])
    gap, gap_se = robust_mean(y0)
    gap = max(gap, 0.0) if math.isfinite(gap) else 0.0
    cos_t = math.sqrt(max(1.0 - (gap / length) ** 2, 0.0))
    if free_mass:
        m, m_se = robust_mean(np.where(v0 > 0.005, scales * cos_t / v0, np.nan))
    else:
        assert mass is not None   # the caller gives the mass it holds fixed
        m, m_se = float(mass), 0.0
    if not math.isfinite(m):
        raise LocalError("the hammer laser shows no impact velocity at the impacts: mass cannot be identified; "
                         "pass --fix mass=VALUE")
    w0, sg = pulse.w0, pulse.sigma
    cov = pulse.cov_shape
    k = m * w0 ** 2 / cos_t
    c = 2 * m * (sg - sigma_free) / cos_t
    rel_m = m_se / m if math.isfinite(m_se) else 0.0
    k_se = k * math.hypot(rel_m, 2 * math.sqrt(max(cov[1, 1], 0.0)) / w0)
    c_se = c * math.hypot(rel_m, math.sqrt(max(cov[0, 0], 0.0)) / max(sg - sigma_free, 1e-12))
    est.values = {"mass": (m, m_se), "contact.stiffness": (k, k_se), "contact.damping": (c, c_se),
                  "gap": (gap, gap_se)}
    return est
