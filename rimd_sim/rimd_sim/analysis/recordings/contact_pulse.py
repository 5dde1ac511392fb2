"""The spring-dashpot contact pulse, for every damping of the contact: one model for the analyses and the fits.

During a contact the hammer's penetration ``delta = l sin(theta) - gap`` obeys (the kernel's equation of
motion, :func:`rimd_sim.model.kernel.theta_accel`, written for ``delta``)::

    delta'' + 2 sigma delta' + w0^2 delta = a,      delta(0) = 0,  delta'(0) = v0,
    sigma = c cos(theta) / 2m + zeta w_n,   w0^2 = k cos(theta) / m,

with ``a`` the hammer's acceleration relative to the cart without contact force (the excitation, gravity and
the wires: a few m/s^2 against the contact's ~10^3, taken constant over the ~0.3 ms of the contact) and
``cos(theta) = sqrt(1 - (gap / l)^2)`` (0.9996 at a 2 mm gap). The force the sensor reads is
``F = k delta + c delta' = (m / cos theta) (w0^2 delta + 2 sigma_c delta')`` with ``sigma_c = sigma - zeta w_n``
(the wires' damping slows the hammer, the sensor does not read it), from the onset until it falls through 0
(the release; the force never pulls), so

    F(s) = scale * shape(s),   scale = m v0 / cos(theta),   eps = a / v0.

The solution is written with ``D = w0^2 - sigma^2``, ``C(s) = cos(sqrt(D) s)`` and ``S(s) = sin(sqrt(D) s) /
sqrt(D)`` (``cosh``, ``sinh`` when ``D < 0``, ``1`` and ``s`` when ``D = 0``): one formula for the underdamped,
critically damped and overdamped contact. The lab's contacts span all three: over the battery's ranges
``c / 2 sqrt(k m)`` runs from ~0.09 to ~5; a light hammer on a soft, well damped contact releases within a
quarter of a millisecond, its force falling from ``c v0`` within one 50 us sample.

The release has a closed form without ``eps`` (underdamped: ``w s = pi - atan2(2 sigma_c w, w0^2 - 2 sigma
sigma_c)``; overdamped: ``s = ln(g2 / g1) / (r1 - r2)`` with ``r = -sigma +- sqrt(-D)``, ``g = w0^2 + 2 sigma_c
r``); with it, Newton's method from the closed form where it finds the first fall through 0, else that fall
bracketed on a grid and bisected (a grazing impact), so that it moves continuously with the parameters
(:func:`_release`).

:func:`fit_pulses` fits one shape common to many impacts, each with its own onset and scale, to their
samples: the oscilloscope's equivalent-time sampling (each impact falls at another phase of the 20 kHz grid,
so together they sample the shape densely even when each contact spans three samples). The same function
fits the 1 MHz triggered captures, which resolve each contact on their own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rimd_sim.analysis.peaks import sampled_peak

__all__ = ["PulseFit", "PulseSamples", "SpringDashpotPulse", "fit_onsets", "fit_pulses", "onset_scale_errors",
           "pulse_residuals", "pulse_of", "pulse_peaks"]

# The trapezoidal rule: np.trapezoid (NumPy 2); on NumPy 1.26 (the apt NumPy under Ubuntu 24.04's ROS 2 Jazzy,
# docs/ros-install.md) the same computation is named np.trapz.
if hasattr(np, "trapezoid"):
    _trapezoid = np.trapezoid
else:  # pragma: no cover - NumPy 1.26
    _trapezoid = np.trapz  # type: ignore[attr-defined]


def _state(s: np.ndarray, sigma: float, w0: float, eps: float | np.ndarray,
           eps1: float | np.ndarray = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``delta`` and ``delta'`` per unit ``v0`` at ``s`` (``eps``, ``eps1`` broadcast against ``s``).

    The free acceleration is ``v0 (eps + eps1 s)``: particular solution ``p0 + p1 s``, ``p1 = eps1 / w0^2``,
    ``p0 = (eps - 2 sigma p1) / w0^2``; homogeneous part from ``delta(0) = 0``, ``delta'(0) = 1``.
    """
    w0sq = w0 * w0
    d = w0sq - sigma * sigma
    # e^{-sigma s} C(s) and e^{-sigma s} S(s), written so that nothing overflows (0 < q < sigma when overdamped)
    if d > 0:
        w = math.sqrt(d)
        e = np.exp(-sigma * s)
        ec, es = e * np.cos(w * s), e * np.sin(w * s) / w
    elif d < 0:
        q = math.sqrt(-d)
        slow, fast = np.exp((q - sigma) * s), np.exp(-(q + sigma) * s)
        ec, es = 0.5 * (slow + fast), (slow - fast) / (2.0 * q)
    else:
        e = np.exp(-sigma * s)
        ec, es = e, e * s
    p1 = eps1 / w0sq
    p0 = (eps - 2.0 * sigma * p1) / w0sq
    a_ = -p0
    b_ = 1.0 - p1 + sigma * a_
    delta = p0 + p1 * s + a_ * ec + b_ * es
    ddelta = p1 + (b_ - sigma * a_) * ec - (sigma * b_ + a_ * d) * es
    return delta, ddelta


def _shape(s: np.ndarray, sigma: float, w0: float, eps: float | np.ndarray, sigma_free: float,
           eps1: float | np.ndarray = 0.0) -> np.ndarray:
    delta, ddelta = _state(s, sigma, w0, eps, eps1)
    return w0 * w0 * delta + 2.0 * (sigma - sigma_free) * ddelta


#: Where :func:`_release` looks for the release when Newton's iteration does not give it, in units of the release
#: without free acceleration: densely up to twice it, then geometrically to :data:`RELEASE_HORIZON` times it (a
#: grazing impact, pushed on by its free acceleration).
RELEASE_GRID = np.concatenate([np.linspace(0.0, 2.0, 257)[1:], 2.0 * np.geomspace(1.0, 50.0, 129)[1:]])
RELEASE_HORIZON = float(RELEASE_GRID[-1])
#: Points (fractions of Newton's root) where the force must be positive for that root to be the first fall.
RELEASE_CHECK = np.linspace(0.0, 1.0, 33)[1:-1]


def _release(sigma: float, w0: float, eps: float | np.ndarray, sigma_free: float,
             eps1: float | np.ndarray = 0.0) -> np.ndarray:
    """Time from the onset to the release (the force's first fall through 0), per ``eps`` and ``eps1`` (arrays).

    Without free acceleration, the closed form (module doc). With it, Newton's method from the closed form, kept
    where it converged to a fall through 0 with the force positive before it; elsewhere (the free acceleration a
    large part of the motion: a grazing impact) the first sign change on :data:`RELEASE_GRID`, bisected. Either way
    the first root, which moves continuously with the parameters. Newton's iterate alone does not: it can stop
    where the force is far from 0, or land on a later root, and the joint fit's misfit would then jump between two
    nearby parameter sets. No fall through 0 within :data:`RELEASE_HORIZON` times the closed form: that horizon (the
    contact outlasts any recorded window).
    """
    sc = sigma - sigma_free
    w0sq = w0 * w0
    d = w0sq - sigma * sigma
    if d > 1e-9 * w0sq:
        w = math.sqrt(d)
        s0 = (math.pi - math.atan2(2 * sc * w, w0sq - 2 * sigma * sc)) / w
    elif d < -1e-9 * w0sq:
        q = math.sqrt(-d)
        r1, r2 = -sigma + q, -sigma - q
        g1, g2 = w0sq + 2 * sc * r1, w0sq + 2 * sc * r2
        s0 = math.log(g2 / g1) / (r1 - r2) if g2 / g1 > 0 else 2.0 / sigma
    else:
        s0 = 2.0 / sigma
    eps = np.asarray(eps, dtype=float)
    if not np.any(eps) and not np.any(eps1) and abs(d) > 1e-9 * w0sq:
        return np.full(eps.shape, s0)
    e = eps.reshape(-1)
    e1 = np.broadcast_to(np.asarray(eps1, dtype=float), eps.shape).reshape(-1)

    def force(s: np.ndarray, ea: np.ndarray, e1a: np.ndarray) -> np.ndarray:
        delta, ddelta = _state(s, sigma, w0, ea, e1a)
        return w0sq * delta + 2 * sc * ddelta

    s = np.full(e.shape, s0)
    step = np.zeros(e.shape)
    for _ in range(12):   # Newton on F(s) = 0; dF/ds = w0^2 delta' + 2 sigma_c delta''
        delta, ddelta = _state(s, sigma, w0, e, e1)
        f = w0sq * delta + 2 * sc * ddelta
        acc = e + e1 * s - 2 * sigma * ddelta - w0sq * delta
        df = w0sq * ddelta + 2 * sc * acc
        step = np.where(df < 0, f / np.where(df < 0, df, -1.0), np.inf)   # a fall through 0 has dF/ds < 0
        s = np.where(np.isfinite(step), np.maximum(s - step, 0.5 * s), s)
        if np.all(np.abs(step) < 1e-14 + 1e-10 * s):
            break
    ok = np.abs(step) < 1e-12 + 1e-8 * s
    if ok.any():   # the force positive before the root: it is the first fall
        ok[ok] = (force(s[ok] * RELEASE_CHECK[:, None], e[ok], e1[ok]) > 0).all(axis=0)
    bad = ~ok
    if bad.any():
        eb, e1b = e[bad], e1[bad]
        grid = s0 * RELEASE_GRID
        below = force(grid[:, None], eb, e1b) <= 0.0                 # (grid, impacts)
        found = below.any(axis=0)
        first = np.argmax(below, axis=0)
        hi = np.where(found, grid[first], grid[-1])
        lo = np.where(found & (first > 0), grid[np.maximum(first - 1, 0)], 0.0)
        for _ in range(48):   # bisection: the bracket shrinks to 2^-48 of a grid step
            mid = 0.5 * (lo + hi)
            down = force(mid, eb, e1b) <= 0.0
            lo, hi = np.where(down, lo, mid), np.where(down, mid, hi)
        s[bad] = np.where(found, hi, grid[-1])
    return s.reshape(eps.shape)


@dataclass(frozen=True)
class SpringDashpotPulse:
    """The contact pulse of a spring-dashpot law (see the module doc).

    Attributes:
        sigma: Decay rate of the penetration (1/s): ``c cos(theta) / 2m + zeta w_n``.
        w0: Undamped angular frequency (rad/s): ``sqrt(k cos(theta) / m)``.
        eps: Free acceleration over the impact velocity (1/s): ``a / v0``.
        sigma_free: The part of ``sigma`` that is not the contact's (``zeta w_n``, 1/s).
        eps1: Its rate of change over the impact velocity (1/s^2): the free acceleration is ``v0 (eps + eps1 s)``.
    """

    sigma: float
    w0: float
    eps: float = 0.0
    sigma_free: float = 0.0
    eps1: float = 0.0

    @property
    def damping_ratio(self) -> float:
        """``sigma / w0``: below 1 the contact rings, above 1 it is overdamped."""
        return self.sigma / self.w0

    def shape(self, s: np.ndarray) -> np.ndarray:
        """Force per unit ``scale`` at ``s`` seconds after the onset (valid up to the release)."""
        return _shape(np.asarray(s, dtype=float), self.sigma, self.w0, self.eps, self.sigma_free, self.eps1)

    def release(self) -> float:
        """Time from the onset to the release (the force falls through 0), s."""
        return float(_release(self.sigma, self.w0, self.eps, self.sigma_free, self.eps1))

    def force(self, s: np.ndarray, scale: float) -> np.ndarray:
        """``scale * shape`` from the onset (``s = 0``) to the release, 0 outside."""
        s = np.asarray(s, dtype=float)
        inside = (s >= 0) & (s <= self.release())
        return np.where(inside, scale * self.shape(np.where(inside, s, 0.0)), 0.0)

    def features(self, scale: float = 1.0) -> tuple[float, float, float]:
        """Peak force, duration (onset to release) and impulse of the pulse of ``scale``."""
        release = self.release()
        s = np.linspace(0.0, release, 2001)
        f = scale * self.shape(s)
        return sampled_peak(f), release, float(_trapezoid(f, s))


def pulse_of(mass: float, stiffness: float, damping: float, *, cos_theta: float = 1.0,
             sigma_free: float = 0.0, eps: float = 0.0) -> SpringDashpotPulse:
    """The pulse of a hammer of ``mass`` on a contact of ``stiffness`` and ``damping`` (see the module doc)."""
    return SpringDashpotPulse(damping * cos_theta / (2.0 * mass) + sigma_free,
                              math.sqrt(stiffness * cos_theta / mass), eps, sigma_free)


@dataclass
class PulseSamples:
    """One impact's samples: times (s), forces (N), the sample period, and where its onset can lie.

    ``onset_lo`` < onset <= ``onset_hi``: the last sample before the contact and the first in it.
    ``eps``: the free acceleration over the impact velocity, ``a / v0`` (1/s); 0 when unknown; ``eps1`` its rate
    of change over the impact velocity (1/s^2).
    """

    t: np.ndarray
    f: np.ndarray
    dt: float
    onset_lo: float
    onset_hi: float
    eps: float = 0.0
    eps1: float = 0.0


def _stack(impacts: list[PulseSamples]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = max(p.t.size for p in impacts)
    t = np.zeros((len(impacts), n))
    f = np.zeros((len(impacts), n))
    mask = np.zeros((len(impacts), n), dtype=bool)
    for i, p in enumerate(impacts):
        t[i, : p.t.size], f[i, : p.t.size], mask[i, : p.t.size] = p.t, p.f, True
    return t, f, mask


def _model(shape: SpringDashpotPulse, t: np.ndarray, onset: np.ndarray, scale: np.ndarray,
           eps: np.ndarray, release: np.ndarray | None = None, eps1: np.ndarray | None = None) -> np.ndarray:
    """Forces at ``t`` (impacts x samples) for per impact onset, scale, ``eps`` and ``eps1``."""
    eps = np.asarray(eps, dtype=float)[:, None]
    eps1 = np.zeros_like(eps) if eps1 is None else np.asarray(eps1, dtype=float)[:, None]
    if release is None:
        release = _release(shape.sigma, shape.w0, eps, shape.sigma_free, eps1)
    s = t - onset[:, None]
    inside = (s >= 0) & (s <= release)
    g = _shape(np.where(inside, s, 0.0), shape.sigma, shape.w0, eps, shape.sigma_free, eps1)
    return np.where(inside, scale[:, None] * g, 0.0)


def _best_onset(shape: SpringDashpotPulse, impacts: list[PulseSamples], grid: int = 25,
                guess: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per impact, the onset (grid then golden section within its bounds) and scale that fit ``shape`` best.

    With ``guess`` (per impact onsets), no grid: Newton's method from it, so that the result moves continuously
    with the shape (a fit's Jacobian by finite differences needs that: an impact whose misfit has two near-equal
    minima, a sample crossing the release's corner, must not jump between them).
    """
    t, f, mask = _stack(impacts)
    lo = np.array([p.onset_lo for p in impacts])
    hi = np.array([p.onset_hi for p in impacts])
    eps = np.array([p.eps for p in impacts])
    eps1 = np.array([p.eps1 for p in impacts])
    release = _release(shape.sigma, shape.w0, eps[:, None], shape.sigma_free, eps1[:, None])
    ones = np.ones(lo.size)

    def cost(onset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g = _model(shape, t, onset, ones, eps, release, eps1) * mask
        gg = (g * g).sum(axis=1)
        scale = np.where(gg > 0, (g * f).sum(axis=1) / np.where(gg > 0, gg, 1.0), 0.0)
        r = (scale[:, None] * g - f) * mask
        return (r * r).sum(axis=1), scale

    best_c = np.full(lo.size, np.inf)
    best_x = hi.copy()
    if guess is None:
        for u in np.linspace(0.0, 1.0, grid):
            x = lo + u * (hi - lo)
            c, _ = cost(x)
            better = c < best_c
            best_c, best_x = np.where(better, c, best_c), np.where(better, x, best_x)
        step = (hi - lo) / (grid - 1)
    else:
        # Newton's method on the misfit from the guess (numerical first and second derivatives, steps bounded):
        # it stays in the guess's basin, so the onset moves continuously with the shape.
        x = np.clip(guess, lo, hi)
        h = 1e-4 * (hi - lo)
        limit = 0.1 * (hi - lo)
        for _ in range(20):
            xm, xp = np.maximum(x - h, lo), np.minimum(x + h, hi)
            c0, cm, cp = cost(x)[0], cost(xm)[0], cost(xp)[0]
            d1 = (cp - cm) / np.maximum(xp - xm, 1e-30)
            d2 = (cp - 2 * c0 + cm) / np.maximum(0.25 * (xp - xm) ** 2, 1e-30)
            move = np.where(d2 > 0, -d1 / np.where(d2 > 0, d2, 1.0), -np.sign(d1) * limit)
            x = np.clip(x + np.clip(move, -limit, limit), lo, hi)
            if np.all(np.abs(move) < 1e-7 * (hi - lo)):
                break
        final_c, final_s = cost(x)
        return x, final_s, final_c
    a, b = np.maximum(lo, best_x - step), np.minimum(hi, best_x + step)
    ratio = (math.sqrt(5) - 1) / 2
    c1, c2 = b - ratio * (b - a), a + ratio * (b - a)
    f1, f2 = cost(c1)[0], cost(c2)[0]
    for _ in range(30):   # golden section: the bracket shrinks to 0.618^30 ~ 5e-7 of a grid step
        left = f1 < f2
        b = np.where(left, c2, b)
        a = np.where(left, a, c1)
        new1 = np.where(left, b - ratio * (b - a), c2)
        new2 = np.where(left, c1, a + ratio * (b - a))
        f_new = cost(np.where(left, new1, new2))[0]
        f1, f2 = np.where(left, f_new, f2), np.where(left, f1, f_new)
        c1, c2 = new1, new2
    x = 0.5 * (a + b)
    c, _ = cost(x)
    onset = np.where(c < best_c, x, best_x)
    final_c, final_s = cost(onset)
    return onset, final_s, final_c


def pulse_peaks(pulse: SpringDashpotPulse, impacts: list[PulseSamples]) -> np.ndarray:
    """The peak of each impact read off ``pulse`` fitted to its samples (onset within its bounds, scale linear).

    The analysis's peak at the contact onset: a spring-dashpot force jumps to ``c v0`` at the onset and may fall
    within one sample, so the largest sample can be well below the peak. NaN where no onset within the bounds
    gives a positive scale.
    """
    if not impacts:
        return np.zeros(0)
    _, scale = fit_onsets(pulse, impacts)
    unit = pulse.features(1.0)[0]
    return np.where(scale > 0, scale * unit, np.nan)


def fit_onsets(pulse: SpringDashpotPulse, impacts: list[PulseSamples],
               guess: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per impact, the onset (within its bounds) and the scale with which ``pulse`` fits its samples best.

    ``guess``: onsets found before (the search stays near them, see :func:`_best_onset`).
    """
    if not impacts:
        return np.zeros(0), np.zeros(0)
    onset, scale, _ = _best_onset(pulse, impacts, guess=guess)
    return onset, scale


def pulse_residuals(pulse: SpringDashpotPulse, impacts: list[PulseSamples], onset: np.ndarray,
                    scale: np.ndarray) -> np.ndarray:
    """The pulse's forces minus the samples, every impact's samples in order (N)."""
    if not impacts:
        return np.zeros(0)
    t, f, mask = _stack(impacts)
    eps = np.array([p.eps for p in impacts])
    eps1 = np.array([p.eps1 for p in impacts])
    return (_model(pulse, t, onset, scale, eps, eps1=eps1) - f)[mask]


def onset_scale_errors(pulse: SpringDashpotPulse, impacts: list[PulseSamples], onset: np.ndarray,
                       scale: np.ndarray, noise: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Standard errors of each impact's onset and scale for a known shape, and the residual rms per impact.

    From the 2 x 2 Gauss-Newton matrix of the impact's samples, with the force sensor's ``noise`` (N).
    """
    t, f, mask = _stack(impacts)
    eps = np.array([p.eps for p in impacts])
    eps1 = np.array([p.eps1 for p in impacts])
    base = _model(pulse, t, onset, scale, eps, eps1=eps1)
    h = np.array([max(p.dt * 1e-4, 1e-12) for p in impacts])
    # one-sided, inward, at a bound of the onset (beyond it a sample would cross the onset's jump)
    lo = np.array([p.onset_lo for p in impacts])
    hi = np.array([p.onset_hi for p in impacts])
    up = np.where(onset + h <= hi, onset + h, onset)
    down = np.where(onset - h >= lo, onset - h, onset)
    d_on = ((_model(pulse, t, up, scale, eps, eps1=eps1) - _model(pulse, t, down, scale, eps, eps1=eps1))
            / np.maximum(up - down, 1e-15)[:, None]) * mask
    d_sc = _model(pulse, t, onset, np.ones_like(scale), eps, eps1=eps1) * mask
    a11, a12, a22 = (d_on * d_on).sum(1), (d_on * d_sc).sum(1), (d_sc * d_sc).sum(1)
    det = a11 * a22 - a12 * a12
    ok = det > 0
    on_se = np.where(ok, np.sqrt(np.where(ok, a22 / np.where(ok, det, 1.0), 0.0)) * noise, np.nan)
    sc_se = np.where(ok, np.sqrt(np.where(ok, a11 / np.where(ok, det, 1.0), 0.0)) * noise, np.nan)
    r = (base - f) * mask
    rms = np.sqrt((r * r).sum(1) / np.maximum(mask.sum(1), 1))
    return on_se, sc_se, rms


@dataclass
class PulseFit:
    """One shape common to many impacts, per impact its onset and scale, and their standard errors."""

    sigma: float
    w0: float
    onsets: np.ndarray
    scales: np.ndarray
    noise: float                   # residual rms (N)
    samples: int
    cov_shape: np.ndarray          # covariance of (sigma, w0)
    onset_se: np.ndarray
    scale_se: np.ndarray
    rms: np.ndarray                # per impact residual rms (N)
    sigma_free: float = 0.0
    evaluations: int = 0

    def pulse(self, eps: float = 0.0) -> SpringDashpotPulse:
        """The fitted pulse."""
        return SpringDashpotPulse(self.sigma, self.w0, eps, self.sigma_free)


#: Contact damping ratios ``sigma / w0`` from which the common shape is fitted (the shape has local minima).
ZETA_STARTS = (0.1, 0.25, 0.5, 0.8, 1.2, 2.0, 3.5, 6.0)


def fit_pulses(impacts: list[PulseSamples], *, sigma_free: float = 0.0, zeta_starts: tuple[float, ...] = ZETA_STARTS,
               w0_guess: float | None = None) -> PulseFit | None:
    """Fit one spring-dashpot shape to every impact's samples, each impact with its own onset and scale.

    Variable projection (Golub and Pereyra 1973): for a trial shape ``(sigma, w0)`` each impact's scale is
    linear and its onset a 1-D search within its bounds, so ``scipy.optimize.least_squares`` adjusts only
    ``(log w0, log(sigma / w0))``, from each of ``zeta_starts``. The standard errors come from the Jacobian of
    the full problem (shape, onsets, scales) at the solution, scaled by the residuals' spread; the shape's by
    the Schur complement over the per-impact unknowns.
    """
    from scipy.optimize import least_squares

    if not impacts:
        return None
    t, f, mask = _stack(impacts)
    eps = np.array([p.eps for p in impacts])
    eps1 = np.array([p.eps1 for p in impacts])
    n_samples = int(mask.sum())
    if w0_guess is None:   # the typical time above 2 % of the peak ~ the contact's duration ~ pi / w0
        durs = [float(np.ptp(p.t[p.f > 0.02 * max(float(p.f.max()), 1e-9)])) + p.dt for p in impacts]
        w0_guess = math.pi / max(float(np.median(durs)), 1e-7)
    evaluations = 0

    def unpack(x: np.ndarray) -> SpringDashpotPulse:
        w0 = math.exp(x[0])
        return SpringDashpotPulse(w0 * math.exp(x[1]) + sigma_free, w0, 0.0, sigma_free)

    def residuals(x: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += 1
        shape = unpack(x)
        onset, scale, _ = _best_onset(shape, impacts)
        return ((_model(shape, t, onset, scale, eps, eps1=eps1) - f) * mask)[mask]

    best = None
    for zeta in zeta_starts:
        # At a given duration, a more damped contact has a higher w0 (overdamped: duration ~ ln(4 zeta^2)/sigma).
        w0 = w0_guess if zeta < 1 else w0_guess * math.log(4 * zeta * zeta + 1) / (zeta * math.pi) * math.pi / 2
        x0 = np.array([math.log(w0), math.log(zeta)])
        try:
            fit = least_squares(residuals, x0, x_scale=[0.1, 0.1], diff_step=1e-6, max_nfev=40)
        except (ValueError, FloatingPointError, ZeroDivisionError):
            continue
        if best is None or fit.cost < best.cost:
            best = fit
    if best is None:
        return None
    fit = least_squares(residuals, best.x, x_scale=[0.1, 0.1], diff_step=1e-7, xtol=1e-12, ftol=1e-12,
                        gtol=1e-12, max_nfev=100)
    shape = unpack(fit.x)
    onset, scale, costs = _best_onset(shape, impacts)
    r = ((_model(shape, t, onset, scale, eps, eps1=eps1) - f) * mask)
    dof = max(n_samples - 2 - 2 * len(impacts), 1)
    s2 = float((r * r).sum()) / dof
    # Full-problem Jacobian: shape columns (all impacts), per impact (onset, scale) columns.
    base = _model(shape, t, onset, scale, eps, eps1=eps1)
    cols = []
    for j in range(2):
        xp = fit.x.copy()
        xp[j] += 1e-6
        cols.append(((_model(unpack(xp), t, onset, scale, eps, eps1=eps1) - base) / 1e-6) * mask)
    h = np.array([max(p.dt * 1e-4, 1e-12) for p in impacts])
    d_on = (_model(shape, t, onset + h, scale, eps, eps1=eps1)
            - _model(shape, t, onset - h, scale, eps, eps1=eps1)) / (2 * h[:, None])
    d_sc = (_model(shape, t, onset, scale * (1 + 1e-6), eps, eps1=eps1) - base) / (scale[:, None] * 1e-6)
    d_on, d_sc = d_on * mask, d_sc * mask
    a_mat = np.array([[float((cols[i] * cols[j]).sum()) for j in range(2)] for i in range(2)])
    schur = a_mat.copy()
    onset_se, scale_se = np.full(len(impacts), math.nan), np.full(len(impacts), math.nan)
    for i in range(len(impacts)):
        jl = np.column_stack([d_on[i], d_sc[i]])
        js = np.column_stack([cols[0][i], cols[1][i]])
        cc = jl.T @ jl
        try:
            inv = np.linalg.inv(cc)
        except np.linalg.LinAlgError:
            continue
        bb = js.T @ jl
        schur -= bb @ inv @ bb.T
        onset_se[i] = math.sqrt(max(inv[0, 0] * s2, 0.0))
        scale_se[i] = math.sqrt(max(inv[1, 1] * s2, 0.0))
    try:
        cov_log = np.linalg.inv(schur) * s2
    except np.linalg.LinAlgError:
        cov_log = np.full((2, 2), np.nan)
    # (log w0, log zeta_c) -> (sigma, w0): w0 = e^x0, sigma = e^(x0 + x1) + sigma_free
    w0 = shape.w0
    sc = shape.sigma - sigma_free
    jac = np.array([[sc, sc], [w0, 0.0]])
    counts = mask.sum(axis=1)
    return PulseFit(shape.sigma, shape.w0, onset, scale, math.sqrt(s2), n_samples, jac @ cov_log @ jac.T,
                    onset_se, scale_se, np.sqrt(costs / np.maximum(counts, 1)), sigma_free, evaluations)
