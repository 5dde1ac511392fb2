"""The joint fit of ``rimd identify``: every parameter at once, with the core's integrator as forward model.

:class:`JointFit` holds the measured data (:class:`Observations`), the segments the recording is cut into
(:class:`Segment`) and the packing of the unknowns; it computes the forward model
(:class:`~rimd_sim.model.rig_model.RigModel`, the simulator's own event-exact Filippov integrator, under the recorded
motor schedule), the residuals, their Jacobian, the least-squares solution and two covariances of it.

**Multiple shooting.** The recording is cut into segments (one per motor step, at most ~10 s), each starting at
a motor cycle start in free flight, each with its own initial state ``(theta, theta_dot)`` among the unknowns
(Bock 1981; Baake et al. 1992, "Fitting ordinary differential equations to chaotic data", Phys. Rev. A 45:
a long single shot turns small parameter errors into late impacts far off, and its misfit has many local
minima). The Jacobian is computed column by column by forward differences, each segment's state and kick
columns re-running that segment only.

**Residuals**, each scaled by its measured spread (so the sum of squares is a chi-square):

* the relative displacement (RIMD laser minus cart laser) and the cart laser at their samples (decimated to
  :data:`FIT_RATE`), by the lasers' noise measured from the data;
* per impact, its force samples (the 20 kHz channel, or the 1 MHz capture when the recording has one for it)
  against the spring-dashpot pulse of the model's parameters
  (:class:`~rimd_sim.analysis.recordings.contact_pulse.SpringDashpotPulse`), its onset and scale fitted to the samples
  (variable projection), by the sensor's noise and the pulse model's accuracy (:data:`PULSE_MODEL_FLOOR`): the
  oscilloscope's equivalent-time sampling pins ``k/m`` and ``c/m``;
* per impact, the onset time of the model's impact against that onset, and ``m v0 / cos(theta)`` with the model's
  impact velocity against that scale, by their standard errors with floors for what the model cannot be asked
  to match (:data:`POSITION_FLOOR`: the hammer's position at the onset; :data:`SCALE_FLOOR`), with Huber's loss
  beyond 3 (:func:`huber`): an impact the model cannot follow counts linearly.

Unknowns: the free parameters (scaled by :data:`SCALES`), per segment ``theta`` and ``theta_dot`` at its start,
per velocity kick its time and size. ``scipy.optimize.least_squares`` (trust-region reflective, bounds: every
parameter positive, the gap >= 0) runs until its tolerances say it converged (``ftol``, ``xtol``, ``gtol`` of
1e-10), not for a fixed number of evaluations; the result says whether it converged.

**Covariance.** :meth:`JointFit.covariance`: ``s^2 (J^T J)^-1`` at the solution. :meth:`JointFit.bootstrap`: a
cluster bootstrap (each cluster one excitation cycle: its laser samples and its impacts), linearised at the
solution (one Gauss-Newton step per resample, Efron and Tibshirani 1993, ch. 9 and 10; the "cluster" or block
resampling of Cameron and Miller 2015, J. Human Resources 50: 317): errors that grow when the misfit has
structure (residuals correlated within cycles) instead of assuming white noise. Both (and the jackknife) take the
Jacobian at the solution from both sides (:meth:`JointFit.two_sided_jacobian`, the entries' minmod): a residual
that jumps within the step (an impact's onset fit switching branch) is not read as a slope.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from fractions import Fraction
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from rimd_sim.analysis.identification.local import Schedule
from rimd_sim.analysis.recordings.contact_pulse import (
    PulseSamples,
    fit_onsets,
    onset_scale_errors,
    pulse_of,
    pulse_residuals,
)
from rimd_sim.settings.config import SimConfig

if TYPE_CHECKING:   # the model (and numba) is imported when a fit runs
    from rimd_sim.model.rig_model import Impact, ModelOutput

__all__ = ["CART_RATE", "FIT_RATE", "JointFit", "JointResult", "Observations", "Segment", "SegmentRun", "run_schedule"]

#: Scale of each parameter in the optimiser's unknowns (the unknowns are value / scale, all of order 1).
SCALES = {"amplitude": 1e-3, "natural_frequency": 1.0, "damping_ratio": 0.1, "gap": 1e-3, "mass": 0.1,
          "contact.stiffness": 1e6, "contact.damping": 1e3}
#: Rate (Hz) at which the lasers' samples enter the fit.
FIT_RATE = 250.0
#: Smallest spread of the hammer's position at an onset (m; the onset's spread is this over the impact velocity)
#: and, relative, of an impact's scale: the forward model's own accuracy (a simulated rig integrates at its
#: configured tolerance: its impacts wander by a few micrometres from the exact solution after a ramp).
POSITION_FLOOR = 2e-6
SCALE_FLOOR = 2e-4
#: Convergence: ``least_squares``' ftol, xtol and gtol (a relative change of the misfit of 1e-8 is ~1e-4 in
#: chi-square units for a recording of ~10^4 samples: far below what moves an estimate).
TOLERANCE = 1e-8
#: Rate (Hz) at which the cart laser's samples enter the fit (it mainly pins A0).
CART_RATE = 50.0
#: The pulse model's accuracy, as a fraction of an impact's peak force: what its constant-shape contact leaves out
#: (the free acceleration's curvature over the contact, the hammer's small rotation): ~1e-4 against the core's
#: integrator at rest (tests/analysis/recordings/test_contact_pulse.py), up to ~1e-3 on a driven, strongly damped
#: contact.
PULSE_MODEL_FLOOR = 1e-3
#: Forward-difference step of the Jacobian (in the unknowns' scaled units): above the integrator's relative tolerance
#: (1e-7 by default: the columns at 1e-6 and 1e-7 agree), and within the residuals' linear range. A slow impact's
#: scale residual moves by about its spread per 1e-6 of ``f_n`` (its impact velocity is that sensitive to the
#: trajectory): a step of 1e-5 crossed Huber's kink at 3 (the difference then understates the slope by a quarter,
#: and the large columns of ``f_n``, A0 and the shot's state no longer cancel along the valley the data allow) and
#: one impact's onset fit switched branch within it (a jump read as a slope of 10^5); the covariance then pinned
#: A0, ``f_n`` and the mass far tighter than the data do, and the fit stopped (``xtol``) on the valley's side
#: (docs/identification.md, "Judging the result").
FD_STEP = 1e-6
#: Huber's threshold for the impacts' residuals (in their standard errors).
HUBER = 3.0
#: A model impact further than this from a measured onset (s) does not match it.
MATCH = 5e-3


def huber(r: np.ndarray, c: float = HUBER) -> np.ndarray:
    """Residuals whose squares are Huber's loss: ``r`` within ``c``, ``sign(r) sqrt(2 c |r| - c^2)`` beyond.

    An impact the model cannot follow (a transient that sensitive dependence makes the rig's own integration
    wander through, a grazing contact) then counts linearly, not quadratically (Huber 1964).
    """
    a = np.abs(r)
    return np.where(a <= c, r, np.sign(r) * np.sqrt(np.maximum(2 * c * a - c * c, 0.0)))


def minmod(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Entry by entry: the one of ``a``, ``b`` of smaller magnitude when they have the same sign, else 0."""
    return np.where(np.sign(a) == np.sign(b), np.where(np.abs(a) <= np.abs(b), a, b), 0.0)


@dataclass
class Segment:
    """One shot of the forward model: from ``t0`` (recording time, a motor phase zero) to ``t1``."""

    t0: float
    t1: float
    schedule: Schedule
    initial: tuple[float, float]                    # theta (rad), theta_dot (rad/s): the first guess
    kicks: list[tuple[float, float]] = field(default_factory=list)   # (recording time, m/s): first guesses


@dataclass
class Observations:
    """What the joint fit compares the model with (times in s from the recording's origin)."""

    y_t: np.ndarray
    y: np.ndarray
    sigma_y: float
    c_t: np.ndarray
    c_x: np.ndarray
    sigma_c: float
    impacts: list[PulseSamples]                     # per impact: its samples (channel or capture)
    onsets: np.ndarray                              # per impact: a first onset (s), to assign it to a segment
    force_noise: float                              # the force sensor's noise (N)
    phase: np.ndarray | None = None                 # per impact: the motor phase at its onset (rad)
    omega: np.ndarray | None = None                 # per impact: the motor's angular frequency there (rad/s)

    def __post_init__(self) -> None:
        """Without the motor at the impacts, no free acceleration (each impact keeps its laser ``eps``)."""
        if self.phase is None:
            self.phase = np.zeros(self.onsets.size)
        if self.omega is None:
            self.omega = np.zeros(self.onsets.size)

    def cycle_ids(self, times: np.ndarray, motor_t: np.ndarray, motor_phase: np.ndarray) -> np.ndarray:
        """The excitation cycle (motor turn) in which each time falls."""
        return np.floor(np.interp(times, motor_t, motor_phase) / (2 * math.pi)).astype(np.int64)


@dataclass
class SegmentRun:
    """The forward model over one segment, in recording time."""

    t: np.ndarray            # the model's displacement sample times (recording time)
    y: np.ndarray            # relative displacement l sin(theta) (m)
    cart: np.ndarray         # cart displacement (m)
    onsets: np.ndarray       # impact starts (recording time)
    v0: np.ndarray           # impact velocities (m/s)
    peaks: np.ndarray        # peak forces (N)
    impacts: list[Impact]    # model time


def model_config(base: SimConfig, params: dict[str, float], schedule: Schedule, initial: tuple[float, float],
                 force_rate: float = 100.0) -> SimConfig:
    """The configuration a segment runs: the parameters, the recorded motor at its start, the initial state.

    The integrator's settings are the base file's, those the twin runs with (``identified.yaml``): the twin that
    reproduces a recording is the simulator as it integrates. (A simulated rig integrates at its configured
    tolerance; its impacts then differ from the exact solution's by a few micrometres, consistently from impact
    to impact, and a forward model at another tolerance would take that for a gap or a mass ~1 % off.)
    """
    max_f = max([base.motor.max_frequency, schedule.f0, schedule.setpoint0] + [c[1] for c in schedule.commands])
    return base.with_parameters({
        **params,
        "motor.max_frequency": max_f,
        "motor.initial_frequency": schedule.f0,
        "motor.initial_setpoint": schedule.setpoint0,
        "motor.ramp_rate": min(max(schedule.ramp0, 1e-3), 1e4),
        "initial.theta": initial[0],
        "initial.theta_dot": initial[1],
        "channels.rimd_acceleration.sample_rate": 100.0,
        "channels.impact_force.sample_rate": force_rate,
        "channels.rimd_acceleration.highpass": 0.0,
    })


def run_schedule(config: SimConfig, schedule: Schedule, kicks: list[tuple[float, float]], t_end: float,
                 force: bool = False) -> tuple[SegmentRun, tuple[np.ndarray, np.ndarray] | None]:
    """Run the core's integrator under ``schedule`` (commands and kicks at their model times) to ``t_end``.

    With ``force``, also the force channel's samples (model time, values) at its configured rate.
    """
    from rimd_sim.model.rig_model import RigModel

    model = RigModel(config, channels=True, truth=False)
    # (model time, the command): motor commands, then kicks, in time order (a stable sort).
    events: list[tuple[float, Callable[[], list[Impact]]]] = sorted(
        [(tc, partial(model.set_motor_frequency, f, r)) for tc, f, r in schedule.commands if tc < t_end]
        + [(tk, partial(model.perturb, v)) for tk, v in kicks if 0 < tk < t_end], key=lambda e: e[0])
    parts: list[ModelOutput] = []
    impacts: list[Impact] = []
    for when, command in events:
        parts.append(model.advance(Fraction(repr(float(when)))))
        impacts += command()
    parts.append(model.advance(Fraction(repr(float(t_end)))))
    rate = config.channel("rimd_displacement").sample_rate
    first = parts[0].channels["rimd_displacement"][0]
    x = np.concatenate([p.channels["rimd_displacement"][1] for p in parts])
    xc = np.concatenate([p.channels["cart_displacement"][1] for p in parts])
    impacts = sorted(impacts + [i for p in parts for i in p.impacts], key=lambda i: i.t_start)
    t = schedule.t0 + (first + np.arange(x.size)) / rate
    run = SegmentRun(t, x - xc, xc, np.array([i.t_start for i in impacts]) + schedule.t0,
                     np.array([i.impact_velocity for i in impacts]), np.array([i.peak_force for i in impacts]),
                     impacts)
    if not force:
        return run, None
    frate = config.channel("impact_force").sample_rate
    ff = parts[0].channels["impact_force"][0]
    fv = np.concatenate([p.channels["impact_force"][1] for p in parts])
    return run, (schedule.t0 + (ff + np.arange(fv.size)) / frate, fv)


@dataclass
class JointResult:
    """The solution of :meth:`JointFit.solve`."""

    x: np.ndarray
    values: dict[str, float]
    states: list[tuple[float, float]]
    kicks: list[tuple[float, float]]
    cost: float
    evaluations: int
    jacobians: int
    converged: bool
    message: str
    chi2: dict[str, float | None]   # per part: mean square of the scaled residuals (None: the part is empty)
    counts: dict[str, int]
    starts: int = 1


class JointFit:
    """The joint least-squares problem of ``rimd identify`` (see the module doc).

    Args:
        base: The base configuration (the values not identified).
        names: The parameters identified, in order.
        fixed: Values held (``--fix``), over the base.
        segments: The shots, in time order.
        obs: The measured data.
    """

    def __init__(self, base: SimConfig, names: list[str], fixed: dict[str, float], segments: list[Segment],
                 obs: Observations) -> None:
        self.base = base
        self.names = list(names)
        self.fixed = dict(fixed)
        self.segments = segments
        self.obs = obs
        self.kick_owner = [s for s, seg in enumerate(segments) for _ in seg.kicks]
        self.n_par = len(self.names)
        self.n = self.n_par + 2 * len(segments) + 2 * len(self.kick_owner)
        # which observations each segment explains
        self._y_sel = [(obs.y_t >= s.t0) & (obs.y_t < s.t1) for s in segments]
        self._c_sel = [(obs.c_t >= s.t0) & (obs.c_t < s.t1) for s in segments]
        self._i_sel = [(obs.onsets >= s.t0 + 1e-3) & (obs.onsets < s.t1 - 1e-2) for s in segments]
        #: the impacts some segment explains (an impact in no segment, one left out, has no model to compare with)
        self._in_fit = np.flatnonzero(np.any(self._i_sel, axis=0)) if segments and obs.onsets.size else \
            np.zeros(0, dtype=int)
        self.evaluations = 0
        self.jacobians = 0
        self._pulse_cache: tuple | None = None
        self._onsets: np.ndarray | None = None
        #: Threads for the Jacobian's forward runs (one per core).
        self.workers = max(1, min(4, os.cpu_count() or 1))

    # ---- packing -----------------------------------------------------------------------------------------

    def pack(self, values: dict[str, float], states: list[tuple[float, float]],
             kicks: list[tuple[float, float]]) -> np.ndarray:
        """The unknowns' vector.

        Parameters / scale, per segment (theta / 0.01, theta_dot / 0.1), per kick ((time - guess) / 1 ms,
        velocity / 0.01 m/s).
        """
        guesses = [k for s in self.segments for k in s.kicks]
        return np.concatenate([[values[p] / SCALES[p] for p in self.names],
                               [v for th, thd in states for v in (th / 0.01, thd / 0.1)],
                               [v for (t, dv), (tg, _) in zip(kicks, guesses, strict=True)
                                for v in ((t - tg) / 1e-3, dv / 0.01)]])

    def unpack(self, x: np.ndarray) -> tuple[dict[str, float], list[tuple[float, float]], list[tuple[float, float]]]:
        """Parameters (the free ones over the fixed), per segment initial state, per kick (time, velocity)."""
        values = dict(self.fixed)
        for i, p in enumerate(self.names):
            values[p] = float(x[i] * SCALES[p])
        o = self.n_par
        states = [(float(x[o + 2 * s] * 0.01), float(x[o + 2 * s + 1] * 0.1)) for s in range(len(self.segments))]
        o += 2 * len(self.segments)
        guesses = [k for s in self.segments for k in s.kicks]
        kicks = [(guesses[j][0] + float(x[o + 2 * j]) * 1e-3, float(x[o + 2 * j + 1]) * 0.01)
                 for j in range(len(guesses))]
        return values, states, kicks

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Every parameter positive (the gap and the damping ratio may be 0); states and kicks free."""
        lo = np.full(self.n, -np.inf)
        hi = np.full(self.n, np.inf)
        for i, p in enumerate(self.names):
            lo[i] = 0.0 if p in ("gap", "damping_ratio") else 1e-6
        return lo, hi

    # ---- forward model -----------------------------------------------------------------------------------

    def run(self, x: np.ndarray, which: list[int] | None = None) -> list[SegmentRun | None]:
        """The forward model over each segment (``which``: only those; the others None)."""
        values, states, kicks = self.unpack(x)
        runs: list[SegmentRun | None] = []
        for s, seg in enumerate(self.segments):
            if which is not None and s not in which:
                runs.append(None)
                continue
            ks = [(t - seg.t0, v) for (t, v), owner in zip(kicks, self.kick_owner, strict=True) if owner == s]
            try:
                config = model_config(self.base, values, seg.schedule, states[s])
                runs.append(run_schedule(config, seg.schedule, ks, seg.t1 - seg.t0)[0])
            except Exception:  # a trial point where the core refuses or fails: a large residual
                runs.append(None)
        return runs

    def _geometry(self, values: dict[str, float]) -> tuple[float, float, float]:
        """``cos(theta)`` at the gap, the mass, ``zeta w_n`` of the parameters."""
        rig = self.base.rig
        wn = 2 * math.pi * values.get("natural_frequency", rig.natural_frequency)
        length = rig.length_at(wn / (2 * math.pi))
        gap = values.get("gap", rig.gap)
        cos_t = math.sqrt(max(1.0 - (gap / length) ** 2, 0.0))
        return cos_t, values.get("mass", rig.mass), values.get("damping_ratio", rig.damping_ratio) * wn

    def _match(self, runs: list[SegmentRun | None]) -> tuple[np.ndarray, np.ndarray]:
        """Per measured impact, the onset and impact velocity of the nearest model impact of its segment.

        NaN when none lies within :data:`MATCH`.
        """
        obs = self.obs
        on_m = np.full(obs.onsets.size, np.nan)
        v0_m = np.full(obs.onsets.size, np.nan)
        for s, run in enumerate(runs):
            idx = np.flatnonzero(self._i_sel[s])
            if run is None or not idx.size or not run.onsets.size:
                continue
            on = obs.onsets[idx]
            j = np.zeros(idx.size, dtype=int)
            if run.onsets.size > 1:
                j = np.clip(np.searchsorted(run.onsets, on), 1, run.onsets.size - 1)
                j = np.where(np.abs(run.onsets[j - 1] - on) < np.abs(run.onsets[j] - on), j - 1, j)
            near = np.abs(run.onsets[j] - on) < MATCH
            on_m[idx] = np.where(near, run.onsets[j], np.nan)
            v0_m[idx] = np.where(near, run.v0[j], np.nan)
        return on_m, v0_m

    def pulse_part(self, values: dict[str, float], v0_model: np.ndarray | None = None) -> tuple[
            np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each impact's samples against the parameters' pulse, its onset and scale fitted (variable projection).

        Each impact's ``eps`` (its free acceleration over its impact velocity) is the parameters' free acceleration
        at its motor phase, ``A0 Omega^2 sin(phi) - w_n^2 gap``, over the model's impact velocity (``v0_model``;
        where there is none, the laser's estimate the samples came with), and ``eps1`` its rate of change,
        ``A0 Omega^3 cos(phi)``, over the same velocity. Returns the scaled sample residuals
        (impacts' samples in order), per impact onset, scale and their standard errors.
        """
        obs = self.obs
        if not obs.impacts:
            empty = np.zeros(0)
            return empty, empty, empty, empty, empty
        n = obs.onsets.size
        use = self._in_fit
        rig = self.base.rig
        cos_t, m, sigma_free = self._geometry(values)
        wn = 2 * math.pi * values.get("natural_frequency", rig.natural_frequency)
        phase, omega = obs.phase, obs.omega
        assert phase is not None and omega is not None   # filled by Observations.__post_init__
        accel = (values.get("amplitude", rig.amplitude) * omega ** 2 * np.sin(phase)
                 - wn ** 2 * values.get("gap", rig.gap))
        jerk = values.get("amplitude", rig.amplitude) * omega ** 3 * np.cos(phase)
        fallback = np.array([p.eps for p in obs.impacts])
        fallback1 = np.array([p.eps1 for p in obs.impacts])
        if v0_model is None:
            eps, eps1 = fallback, fallback1
        else:
            ok = np.isfinite(v0_model) & (np.abs(np.nan_to_num(v0_model)) > 1e-3)
            v = np.where(ok, v0_model, 1.0)
            eps, eps1 = np.where(ok, accel / v, fallback), np.where(ok, jerk / v, fallback1)
        key = (tuple(sorted(values.items())), eps.tobytes(), eps1.tobytes())
        if self._pulse_cache is not None and self._pulse_cache[0] == key:
            return self._pulse_cache[1]
        impacts = [PulseSamples(obs.impacts[i].t, obs.impacts[i].f, obs.impacts[i].dt, obs.impacts[i].onset_lo,
                                obs.impacts[i].onset_hi, float(eps[i]), float(eps1[i])) for i in use]
        pulse = pulse_of(m, values.get("contact.stiffness", rig.contact.stiffness),
                         values.get("contact.damping", rig.contact.damping), cos_theta=cos_t, sigma_free=sigma_free)
        onset, scale = np.full(n, np.nan), np.full(n, np.nan)
        on_se, sc_se = np.full(n, np.nan), np.full(n, np.nan)
        if impacts:
            o, sc = fit_onsets(pulse, impacts, self._onsets)
            if self._onsets is None:   # the first search is global; later ones stay near it (continuity)
                self._onsets = o
            noise = max(obs.force_noise, 1e-6)
            ose, sse, _ = onset_scale_errors(pulse, impacts, o, sc, noise)
            onset[use], scale[use], on_se[use], sc_se[use] = o, sc, ose, sse
            # each impact's samples by the sensor's noise and the pulse model's own accuracy (a fraction of the
            # impact's largest sample: the data's, so that the weights do not move with the parameters): the
            # samples resolve the force to 1e-4 of its peak, finer than the model is exact
            peak = np.array([float(np.max(p.f)) for p in impacts])
            spread = np.sqrt(noise ** 2 + (PULSE_MODEL_FLOOR * peak) ** 2)
            samples = pulse_residuals(pulse, impacts, o, sc) / np.repeat(spread, [p.t.size for p in impacts])
        else:
            samples = np.zeros(0)
        out = (samples, onset, scale, on_se, sc_se)
        self._pulse_cache = (key, out)
        return out

    def _segment_residuals(self, s: int, run: SegmentRun | None, values: dict[str, float],
                           pulse: tuple) -> list[np.ndarray]:
        """The scaled residuals of segment ``s``: displacement, cart, onsets, scales.

        ``pulse``: :meth:`pulse_part` with the matches of :meth:`_match` in ``pulse[5:]``.
        """
        obs = self.obs
        ysel, csel, isel = self._y_sel[s], self._c_sel[s], self._i_sel[s]
        n_imp = int(isel.sum())
        if run is None:
            return [np.full(int(ysel.sum()), 1e3), np.full(int(csel.sum()), 1e3), np.full(n_imp, 1e3),
                    np.full(n_imp, 1e3)]
        ry = (np.interp(obs.y_t[ysel], run.t, run.y) - obs.y[ysel]) / obs.sigma_y
        rc = (np.interp(obs.c_t[csel], run.t, run.cart) - obs.c_x[csel]) / obs.sigma_c
        _, onsets, scales, on_se, sc_se, on_m, v0_m = pulse
        on, sc = onsets[isel], scales[isel]
        sc_sd = np.maximum(sc_se[isel], SCALE_FLOOR * np.abs(sc))
        near = np.isfinite(on_m[isel])
        v0 = np.maximum(np.abs(np.nan_to_num(v0_m[isel], nan=1.0)), 1e-3)
        on_sd = np.sqrt(on_se[isel] ** 2 + (POSITION_FLOOR / v0) ** 2)
        cos_t, m, _ = self._geometry(values)
        dt = np.nan_to_num(on_m[isel] - on)
        rt = huber(np.where(near, dt / on_sd, 1e3))
        rs = huber(np.where(near, (m * np.nan_to_num(v0_m[isel]) / cos_t - sc) / sc_sd, 1e3))
        return [ry, rc, rt, rs]

    def _all(self, x: np.ndarray, runs: list[SegmentRun | None]) -> tuple[dict[str, float], list[list[np.ndarray]],
                                                                           np.ndarray]:
        values, _, _ = self.unpack(x)
        on_m, v0_m = self._match(runs)
        pulse = (*self.pulse_part(values, v0_m), on_m, v0_m)
        segs = [self._segment_residuals(s, run, values, pulse) for s, run in enumerate(runs)]
        return values, segs, pulse[0]

    def residuals(self, x: np.ndarray, runs: list[SegmentRun | None] | None = None) -> np.ndarray:
        """All scaled residuals, in a fixed order.

        Per segment (displacement, cart, onsets, scales), then the impacts' samples.
        """
        self.evaluations += 1
        runs = self.run(x) if runs is None else runs
        _, segs, samples = self._all(x, runs)
        r = np.concatenate([r for seg in segs for r in seg] + [samples])
        return np.nan_to_num(r, nan=1e3, posinf=1e3, neginf=-1e3)   # a trial point the model cannot evaluate

    def parts(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """The residuals by kind (each scaled): ``displacement``, ``cart``, ``onset``, ``scale``, ``samples``."""
        _, segs, samples = self._all(x, self.run(x))
        res = {k: np.concatenate([seg[i] for seg in segs]) if segs else np.zeros(0)
               for i, k in enumerate(("displacement", "cart", "onset", "scale"))}
        res["samples"] = samples
        return res

    def segment_chi2(self, x: np.ndarray) -> list[float]:
        """Per segment, the mean square of its scaled displacement residuals (inf where the model failed)."""
        runs = self.run(x)
        _, segs, _ = self._all(x, runs)
        return [float(np.mean(seg[0] ** 2)) if run is not None and seg[0].size else (0.0 if run is not None
                                                                                       else math.inf)
                for seg, run in zip(segs, runs, strict=True)]

    def jacobian(self, x: np.ndarray, base_runs: list[SegmentRun | None] | None = None,
                 f0: np.ndarray | None = None, *, backward: bool = False) -> np.ndarray:
        """Forward differences (``backward``: backward); a segment's state and kick columns re-run that segment only.

        The forward runs of the columns go to :attr:`workers` threads (the compiled kernel releases the GIL);
        the residuals are computed in this thread.
        """
        from concurrent.futures import ThreadPoolExecutor

        self.jacobians += 1
        base_runs = self.run(x) if base_runs is None else base_runs
        f0 = self.residuals(x, base_runs) if f0 is None else f0
        jac = np.zeros((f0.size, x.size))

        def column(i: int) -> tuple[int, float, np.ndarray, list]:
            h = (-FD_STEP if backward else FD_STEP) * max(1.0, abs(x[i]))
            xp = x.copy()
            xp[i] += h
            if i < self.n_par:
                return i, h, xp, self.run(xp)
            o = i - self.n_par
            seg = o // 2 if o < 2 * len(self.segments) else self.kick_owner[(o - 2 * len(self.segments)) // 2]
            runs = list(base_runs)
            runs[seg] = self.run(xp, [seg])[seg]
            return i, h, xp, runs

        chunk = max(1, 2 * self.workers)
        with ThreadPoolExecutor(max_workers=self.workers) as pool:
            for start in range(0, x.size, chunk):
                for i, h, xp, runs in pool.map(column, range(start, min(x.size, start + chunk))):
                    jac[:, i] = (self.residuals(xp, runs) - f0) / h
        return jac

    def solve(self, x0: np.ndarray, *, max_iterations: int = 60, loss: str = "linear", f_scale: float = 3.0,
              log: Callable[[str], None] | None = None) -> JointResult:
        """Least squares from ``x0`` until converged (or ``max_iterations`` Jacobians: then not converged).

        ``loss``: ``linear`` (least squares) or a robust loss of ``least_squares`` (``soft_l1``, ``cauchy``) with
        ``f_scale`` (in units of the residuals' spread): a first stage that keeps a segment the model does not
        follow yet (a step the trial parameters put on another motion) from steering the fit.
        """
        from scipy.optimize import least_squares

        cache: dict[bytes, tuple[np.ndarray, list]] = {}

        def fun(x: np.ndarray) -> np.ndarray:
            runs = self.run(x)
            r = self.residuals(x, runs)
            cache.clear()
            cache[x.tobytes()] = (r, runs)
            return r

        def jac(x: np.ndarray) -> np.ndarray:
            hit = cache.get(x.tobytes())
            r, runs = hit if hit else (None, None)
            j = self.jacobian(x, runs, r)
            if log is not None and r is not None:
                log(f"joint fit: iteration {self.jacobians}, misfit {0.5 * float(r @ r):.6g}")
            return j

        lo, hi = self.bounds()
        x0 = np.clip(x0, lo + 1e-9, hi)
        self._onsets = None   # each solve searches the impacts' onsets afresh at its start, then follows them
        fit = least_squares(fun, x0, jac=jac, bounds=(lo, hi), x_scale="jac", method="trf", ftol=TOLERANCE,
                            xtol=TOLERANCE, gtol=TOLERANCE, max_nfev=max_iterations, loss=loss, f_scale=f_scale)
        values, states, kicks = self.unpack(fit.x)
        parts = self.parts(fit.x)
        chi2 = {k: float(np.mean(v ** 2)) if v.size else None for k, v in parts.items()}
        cost = 0.5 * float(sum(float(v @ v) for v in parts.values()))
        return JointResult(fit.x, values, states, kicks, cost, self.evaluations, self.jacobians,
                           fit.status > 0, fit.message, chi2, {k: int(v.size) for k, v in parts.items()})

    # ---- uncertainty ---------------------------------------------------------------------------------------

    def clusters(self, motor_t: np.ndarray, motor_phase: np.ndarray) -> np.ndarray:
        """Per residual (order of :meth:`residuals`): its excitation cycle (an impact's samples: the impact's)."""
        obs = self.obs
        ids = []
        for s in range(len(self.segments)):
            for times in (obs.y_t[self._y_sel[s]], obs.c_t[self._c_sel[s]], obs.onsets[self._i_sel[s]],
                          obs.onsets[self._i_sel[s]]):
                ids.append(obs.cycle_ids(times, motor_t, motor_phase))
        for i in self._in_fit:
            ids.append(np.full(obs.impacts[i].t.size, obs.cycle_ids(obs.onsets[i:i + 1], motor_t, motor_phase)[0]))
        return np.concatenate(ids) if ids else np.zeros(0, dtype=np.int64)

    def segment_ids(self) -> np.ndarray:
        """Per residual (order of :meth:`residuals`): the segment it belongs to (an impact's samples: its own)."""
        ids = []
        for s in range(len(self.segments)):
            n = int(self._y_sel[s].sum() + self._c_sel[s].sum() + 2 * self._i_sel[s].sum())
            ids.append(np.full(n, s, dtype=np.int64))
        for i in self._in_fit:
            owner = next(s for s in range(len(self.segments)) if self._i_sel[s][i])
            ids.append(np.full(self.obs.impacts[i].t.size, owner, dtype=np.int64))
        return np.concatenate(ids) if ids else np.zeros(0, dtype=np.int64)

    def two_sided_jacobian(self, x: np.ndarray, base_runs: list[SegmentRun | None] | None = None,
                           f0: np.ndarray | None = None) -> np.ndarray:
        """The Jacobian the covariances use: forward and backward differences, entry by entry their minmod.

        Where the residual is smooth over the step the two agree (to the step's first order) and this is either;
        where one side jumps (an impact's onset fit switching branch, a residual crossing Huber's kink) that side
        reads a jump as a slope, often orders of magnitude too steep, and a covariance from it pins the parameter
        far tighter than the data do. The minmod (the one of smaller magnitude when both have the same sign, 0 when
        they disagree in sign: van Leer's slope limiter) keeps the slope both sides support; it never exceeds
        either in magnitude.
        """
        base_runs = self.run(x) if base_runs is None else base_runs
        f0 = self.residuals(x, base_runs) if f0 is None else f0
        fwd = self.jacobian(x, base_runs, f0)
        bwd = self.jacobian(x, base_runs, f0, backward=True)
        return minmod(fwd, bwd)

    def jackknife(self, jac: np.ndarray, r: np.ndarray, groups: np.ndarray) -> np.ndarray:
        """Delete-a-group jackknife covariance, linearised at the solution (Efron and Tibshirani 1993, ch. 11).

        Each group (a segment) left out in turn: one Gauss-Newton step from the solution without it. The spread of
        those estimates says how far the segments disagree, which the cycles' bootstrap cannot see when the
        misfit is correlated over a whole segment (the model's error over a transient).
        """
        ids = np.unique(groups)
        n = jac.shape[1]
        a_all, g_all = jac.T @ jac, jac.T @ r
        dxs = []
        for g in ids:
            sel = groups == g
            jg = jac[sel]
            a = a_all - jg.T @ jg
            b = g_all - jg.T @ r[sel]
            dxs.append(-np.linalg.lstsq(a, b, rcond=None)[0])
        if len(dxs) < 3:
            return np.zeros((n, n))
        d = np.array(dxs)
        d -= d.mean(axis=0)
        return (len(dxs) - 1) / len(dxs) * (d.T @ d)

    def covariance(self, jac: np.ndarray, r: np.ndarray) -> np.ndarray:
        """``s^2 (J^T J)^-1``, ``s^2`` the residuals' mean square per degree of freedom."""
        dof = max(r.size - jac.shape[1], 1)
        s2 = float(r @ r) / dof
        return np.linalg.pinv(jac.T @ jac) * s2

    def bootstrap(self, jac: np.ndarray, r: np.ndarray, clusters: np.ndarray, *, resamples: int = 400,
                  seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Cluster bootstrap linearised at the solution: the covariance and the resampled unknowns' offsets.

        Each resample draws the clusters with replacement (weights from a multinomial); one Gauss-Newton step
        from the solution gives its unknowns: ``dx = -(sum w_c J_c^T J_c)^-1 sum w_c J_c^T r_c``.
        """
        rng = np.random.default_rng(seed)
        ids = np.unique(clusters[clusters >= 0])
        index = {c: i for i, c in enumerate(ids)}
        n = jac.shape[1]
        g_mats = np.zeros((ids.size, n, n))
        g_vecs = np.zeros((ids.size, n))
        for c in ids:
            sel = clusters == c
            jc = jac[sel]
            g_mats[index[c]] = jc.T @ jc
            g_vecs[index[c]] = jc.T @ r[sel]
        dxs = np.zeros((resamples, n))
        for b in range(resamples):
            w = rng.multinomial(ids.size, np.full(ids.size, 1.0 / ids.size)).astype(float)
            dxs[b] = -np.linalg.lstsq(np.tensordot(w, g_mats, axes=1), np.tensordot(w, g_vecs, axes=1),
                                      rcond=None)[0]
        return np.cov(dxs, rowvar=False), dxs
