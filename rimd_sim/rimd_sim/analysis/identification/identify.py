"""Identification of the rig's physical parameters from a recording alone (``rimd identify``).

:func:`identify` runs stages, each returning typed estimates (docs/identification.md says what determines
what, and the references):

1. **Reading** (:func:`rimd_sim.analysis.recordings.reading.read`): the impacts in the force channel, the motor's
   steps and the windows to leave out: holes in ``first_index``, faults seen in the data, faults named on
   ``/rig/faults``.
   Every later stage leaves those windows out and the result says which.
2. **Motor and amplitude** (:mod:`rimd_sim.analysis.identification.local`): the recorded schedule, A0 from the
   cart laser.
3. **Free flight**: ``f_n`` and ``zeta`` from the relative displacement between impacts; velocity kicks.
4. **Contact**: the common spring-dashpot pulse of all impacts (any damping; from the 1 MHz triggered
   captures when the recording has them), each impact's onset and scale ``m v0 / cos(theta)``; with the laser's
   impact velocity: the mass, ``k``, ``c`` and the gap.
5. **Joint fit** (:class:`rimd_sim.analysis.identification.joint_fit.JointFit`): everything at once with the
   core's integrator, multiple shooting, until converged; when the local estimates are uncertain or the fit does
   not reach the lasers' noise, more starts across the local estimates' uncertainty (:data:`STARTS`), the best
   kept.
6. **Uncertainty and verdict**: a cluster bootstrap over the excitation cycles (impacts and laser samples
   together) linearised at the solution; 95 % intervals; the verdict: identified, or which parameters are
   poorly determined, why, and what experiment would determine them.
7. **Validation**: the twin re-run under the recorded schedule, read by the same reading as the recording (the
   table ``rimd analyze`` prints), step by step.

The recording's metadata (the twin writes its own parameters there) never enters an estimate: only the
measured channels. (The validation's recorded column is ``rimd analyze``'s reading of the recording, which
reads the peaks with the contact law the metadata names when there is one; see docs/identification.md.)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from rimd_sim.analysis.identification import local as loc
from rimd_sim.analysis.identification.joint_fit import (
    CART_RATE,
    FIT_RATE,
    SCALES,
    JointFit,
    JointResult,
    Observations,
    Segment,
    model_config,
    run_schedule,
)
from rimd_sim.analysis.recordings import recorded as rec
from rimd_sim.analysis.recordings.reading import Reading, Window, keep_mask, read, step_rows
from rimd_sim.errors import AnalysisError
from rimd_sim.settings.config import SimConfig

__all__ = ["IDENTIFIABLE", "TARGETS", "Estimate", "Identification", "IdentificationError", "Prepared", "Verdict",
           "identify", "local_stages", "uncertainty"]

#: Parameters ``rimd identify`` estimates (spring-dashpot law), in report order.
IDENTIFIABLE = ("amplitude", "natural_frequency", "damping_ratio", "gap", "mass", "contact.stiffness",
                "contact.damping")
CONTACT_PARAMETERS = ("gap", "mass", "contact.stiffness", "contact.damping")
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
#: What "identified" means: the 95 % interval's half-width within 1 % (the gap: 0.02 mm); docs/identification.md.
TARGETS = {p: ("relative", 0.01) for p in IDENTIFIABLE} | {"gap": ("absolute", 0.02e-3)}
#: Longest segment of the multiple shooting (s).
MAX_SEGMENT = 10.0
#: Extra starts of the joint fit, in local standard errors of each uncertain parameter (see identify()).
STARTS = ((-3.0,), (3.0,))
#: The joint fit reaches the data when the displacement's scaled residuals have a mean square below this.
GOOD_FIT_CHI2 = 2.0
#: A segment whose displacement residuals' mean square exceeds this (and three times the segments' median) at the
#: solution is cut in two ...
SEGMENT_CHI2 = 4.0
#: ... into shots of about this length (s) ...
SHORT_SEGMENT = 1.0
#: ... unless its halves would be shorter than this (s): then it is left out (the model cannot follow it).
MIN_SEGMENT = 0.75


class IdentificationError(AnalysisError):
    """The recording cannot give what was asked (one line: which parameter, which channel, what to do)."""


@dataclass
class Estimate:
    """One estimated parameter: value, standard error, 95 % interval and where it came from."""

    value: float
    std_error: float | None
    source: str
    local_value: float | None = None
    local_std_error: float | None = None
    jacobian_std_error: float | None = None
    bootstrap_std_error: float | None = None
    numerical_error: float | None = None
    jackknife_std_error: float | None = None

    @property
    def half_width_95(self) -> float | None:
        """Half-width of the 95 % interval (1.96 standard errors), or None."""
        return None if self.std_error is None else 1.96 * self.std_error

    def as_dict(self) -> dict:
        """JSON-ready."""
        return {"value": self.value, "std_error": self.std_error, "interval_95": self.half_width_95,
                "source": self.source, "local_value": self.local_value, "local_std_error": self.local_std_error,
                "jacobian_std_error": self.jacobian_std_error, "bootstrap_std_error": self.bootstrap_std_error,
                "numerical_error": self.numerical_error, "jackknife_std_error": self.jackknife_std_error}


@dataclass
class Verdict:
    """Identified, or which parameters are poorly determined, why, and what would determine them."""

    poorly: list[tuple[str, str, str]] = field(default_factory=list)   # (parameter, why, experiment)
    notes: list[str] = field(default_factory=list)

    @property
    def identified(self) -> bool:
        """Every parameter within its target at 95 %."""
        return not self.poorly

    def line(self) -> str:
        """The verdict as one line."""
        if self.identified:
            return "VERDICT: identified: every parameter's 95 % interval within its target (1 %; gap 0.02 mm)" + (
                "; " + "; ".join(self.notes) if self.notes else "")
        return "VERDICT: poorly determined: " + "; ".join(f"{p} ({why}; {what})" for p, why, what in self.poorly)

    def as_dict(self) -> dict:
        """JSON-ready."""
        return {"identified": self.identified, "line": self.line(), "notes": self.notes,
                "poorly_determined": [{"parameter": p, "why": w, "experiment": e} for p, w, e in self.poorly]}


@dataclass
class Identification:
    """What :func:`identify` found."""

    config: SimConfig
    estimates: dict[str, Estimate]
    fixed: dict[str, float]
    kicks: list[tuple[float, float]]              # (recording time, velocity m/s)
    initial: tuple[float, float]                  # theta, theta_dot at the first segment's start
    data: dict
    residuals: dict
    verdict: Verdict
    windows: list[Window]
    validation: list[dict] = field(default_factory=list)
    series: dict = field(default_factory=dict)
    log: list[str] = field(default_factory=list)


# ---- stages ------------------------------------------------------------------------------------------------

def _check(data: rec.RecordedData, base: SimConfig, free: list[str]) -> None:
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


@dataclass
class Lasers:
    """The relative displacement (RIMD laser minus cart laser) and the cart laser, with what to keep."""

    y_t: np.ndarray
    y: np.ndarray
    keep: np.ndarray
    c_t: np.ndarray
    c_x: np.ndarray
    c_keep: np.ndarray
    rate: float


def _lasers(data: rec.RecordedData, windows: list[Window]) -> Lasers:
    rimd, cart = data.channels.get(rec.RIMD_X), data.channels.get(rec.CART_X)
    if rimd is not None and cart is not None:
        y_t, y, _ = rec.phase_plane(rimd, cart)
    else:
        y_t = y = np.empty(0)
    keep = keep_mask(np.where(np.isfinite(y_t), y_t, -1e9), windows, (rec.RIMD_X, rec.CART_X), 0.01)
    c_t = cart.time if cart is not None else np.empty(0)
    c_x = cart.values if cart is not None else np.empty(0)
    c_keep = keep_mask(c_t, windows, (rec.CART_X,), 0.01)
    return Lasers(y_t, y, keep, c_t, c_x, c_keep, rimd.rate if rimd is not None else FIT_RATE)


def _segments(motor: dict, t_first: float, t_end: float, avoid: np.ndarray, lasers: Lasers,
              windows: list[Window], kicks: list[tuple[float, float]], length: float) -> list[Segment]:
    """The shots of the joint fit.

    A motor cycle start clear of impacts before each command, at most :data:`MAX_SEGMENT` s each, none across a
    motor fault.
    """
    motor_windows = [w for w in windows if w.topic == "motor"]
    bad = [(w.start, w.end) for w in windows if w.topic in (rec.RIMD_X, rec.CART_X)]
    full = loc.motor_schedule(motor, t_first, t_end)
    wanted = [t_first] + [full.t0 + tc - 0.3 for tc, _, _ in full.commands]
    starts: list[float] = []
    z: float | None
    for target in sorted(wanted):
        z = target
        while True:
            z = loc.cycle_start(motor, z, np.r_[avoid, [k for k, _ in kicks]], clear=0.02, before=t_end - 1.0)
            if z is None or not any(a - 0.02 <= z <= b + 0.02 for a, b in bad + [(w.start, w.end)
                                                                             for w in motor_windows]):
                break
            z += 1e-3
        if z is not None and (not starts or z - starts[-1] > 1.0):
            starts.append(z)
    for w in motor_windows:   # a new shot after every motor fault
        z = loc.cycle_start(motor, w.end + 0.05, avoid, clear=0.02, before=t_end - 1.0)
        if z is not None and all(abs(z - s) > 0.5 for s in starts):
            starts.append(z)
    starts.sort()
    if not starts:
        raise IdentificationError("the recording has no motor cycle start clear of impacts (/rig/motor/state)")
    # split long shots
    bounds: list[float] = []
    for a, b in zip(starts, [*starts[1:], t_end], strict=True):
        bounds.append(a)
        n = int(math.ceil((b - a) / MAX_SEGMENT))
        for k in range(1, n):
            z = loc.cycle_start(motor, a + k * (b - a) / n, avoid, clear=0.02, before=b - 0.5)
            if z is not None:
                bounds.append(z)
    bounds = sorted(set(bounds))
    segments = []
    for a, b in zip(bounds, [*bounds[1:], t_end], strict=True):
        for w in motor_windows:   # a shot ends where a motor fault starts
            if a < w.start < b:
                b = w.start
        if b - a < 0.2:
            continue
        sched = loc.motor_schedule(motor, a, b)
        ks = [(t, v) for t, v in kicks if a + 0.02 < t < b - 0.02]
        segments.append(Segment(a, b, sched, _initial_state(lasers, a, length), ks))
    return segments


def _initial_state(lasers: Lasers, t0: float, length: float) -> tuple[float, float]:
    ok = np.isfinite(lasers.y_t) & lasers.keep
    t, x = lasers.y_t[ok], lasers.y[ok]
    sel = (t >= t0 - 0.01) & (t <= t0 + 0.01)
    if sel.sum() < 5:
        return 0.0, 0.0
    c = np.polyfit(t[sel] - t0, x[sel], 2)
    th = math.asin(max(-0.99, min(0.99, float(c[2]) / length)))
    return th, float(c[1]) / (length * math.cos(th))


def _value_of(config: SimConfig, name: str) -> float:
    return float(config.to_parameters()[name])


# ---- the identification ------------------------------------------------------------------------------------

@dataclass
class Prepared:
    """What the local stages give the joint fit: the recording read, the local estimates, the fit's data."""

    data: rec.RecordedData
    reading: Reading
    windows: list[Window]
    motor: dict[str, np.ndarray]
    schedule_source: str
    lasers: Lasers
    estimates: dict[str, Estimate]
    params: dict[str, float]
    contact: loc.ContactEstimate | None
    kicks: list[tuple[float, float]]
    obs: Observations
    segments: list[Segment]
    length: float


def local_stages(data: rec.RecordedData, base: SimConfig, fixed: dict[str, float], *,
                 threshold: float = rec.DEFAULT_THRESHOLD, settle: float = 2.0,
                 say: Callable[[str], None] | None = None) -> Prepared:
    """Stages 1-4 (see the module doc): the reading, the motor, the local estimates, the joint fit's data.

    Raises:
        IdentificationError: See :func:`identify`.
    """
    say = say or (lambda text: None)
    free = [p for p in IDENTIFIABLE if p not in fixed]
    _check(data, base, free)
    # 1. the reading of the recording (shared with rimd analyze), the windows to leave out
    reading = read(data, threshold=threshold, settle=settle, pulse=rec.pulse_model(data.recording.metadata)
                   if data.recording is not None else None, scan=data.recording is not None)
    windows = list(reading.windows)
    if windows:
        say(f"left out (s from the recording's first stamp): {reading.windows_text()}")
    detected = reading.detected
    force = data.channels.get(rec.FORCE)
    contact_free = [p for p in free if p in CONTACT_PARAMETERS]
    if contact_free and detected["start"].size == 0:
        raise IdentificationError(
            f"no impact in the recording (the force channel never reaches {threshold:g} N): {', '.join(contact_free)} "
            "cannot be identified; record impacts (a step in band A) or pass --fix " +
            " ".join(f"{p}=VALUE" for p in contact_free))
    force_keep = keep_mask(detected["start"], windows, (rec.FORCE,), 2e-3) if detected["start"].size else \
        np.zeros(0, dtype=bool)

    # 2. motor and amplitude
    cart = data.channels.get(rec.CART_X)
    motor = data.motor
    schedule_source = "/rig/motor/state"
    if not motor.get("time", np.empty(0)).size:
        if cart is None:
            raise IdentificationError("no /rig/motor/state and no /rig/cart/displacement: the motor frequency is "
                                      "unknown")
        motor, fr = loc.phase_from_cart(cart)
        schedule_source = "cart laser (constant frequency)"
        say(f"no /rig/motor/state: one constant motor frequency fitted to the cart laser, {fr:.5f} Hz")
    lasers = _lasers(data, windows)
    estimates: dict[str, Estimate] = {}
    params = {k: float(v) for k, v in fixed.items()}
    rig = base.rig
    if "amplitude" in free:
        a0, se = loc.fit_amplitude(lasers.c_t[lasers.c_keep], lasers.c_x[lasers.c_keep], motor)
        estimates["amplitude"] = Estimate(a0, se, f"cart laser against the motor phase ({int(lasers.c_keep.sum())} "
                                          "samples)", a0, se)
        params["amplitude"] = a0
    amplitude = params.get("amplitude", rig.amplitude)

    # 3. kicks, free flight
    onsets_all = detected["start"]
    kick_keep = lasers.keep & keep_mask(np.where(np.isfinite(lasers.y_t), lasers.y_t, -1e9), windows, (rec.FORCE,),
                                        0.03)
    kicks = loc.detect_kicks(lasers.y_t, lasers.y, kick_keep, onsets_all) if lasers.y.size else []
    if kicks:
        say("velocity kicks without contact: " + ", ".join(f"{v:+.4f} m/s at {t:.4f} s" for t, v in kicks))
    t_first = max(c.time[0] for c in data.channels.values()) if data.channels else float(motor["time"][0])
    full = loc.motor_schedule(motor, float(t_first), float(motor["time"][-1]))
    commands = [full.t0 + tc for tc, _, _ in full.commands]
    if "natural_frequency" in free or "damping_ratio" in free:
        # free flight needs the force channel too: a hole in it may hide an impact
        pieces = loc.free_stretches(lasers.y_t, kick_keep, motor, float(t_first), onsets_all,
                                    [k for k, _ in kicks], commands)
        if not pieces:
            raise IdentificationError("no stretch of constant motor frequency without contact (50 ms or more): "
                                      "natural_frequency and damping_ratio cannot be identified; pass --fix")
        guess = (params.get("natural_frequency", rig.natural_frequency), params.get("damping_ratio", rig.damping_ratio))
        (fn, zeta), (fn_se, z_se) = loc.fit_free_flight(lasers.y_t, lasers.y, pieces, motor, amplitude, guess)
        seconds = sum(p.size for p in pieces) / lasers.rate
        src = f"free flight at constant motor frequency ({len(pieces)} stretches, {seconds:.1f} s)"
        if "natural_frequency" in free:
            estimates["natural_frequency"] = Estimate(fn, fn_se, src, fn, fn_se)
            params["natural_frequency"] = fn
        if "damping_ratio" in free:
            estimates["damping_ratio"] = Estimate(max(zeta, 0.0), z_se, src, zeta, z_se)
            params["damping_ratio"] = max(zeta, 0.0)
    wn = 2 * math.pi * params.get("natural_frequency", rig.natural_frequency)
    zeta_ = params.get("damping_ratio", rig.damping_ratio)
    length = rig.length_at(wn / (2 * math.pi))

    # 4. contact
    contact = None
    if force is not None and detected["start"].size and lasers.y.size:
        phase_all = loc.unwrapped_phase(motor)
        fin = np.isfinite(lasers.y_t)
        gap_guess = params.get("gap", float(np.nanmedian(np.interp(detected["start"], lasers.y_t[fin], lasers.y[fin]))))

        def accel(t: float) -> float:
            om = 2 * math.pi * float(np.interp(t, motor["time"], motor["frequency"]))
            return amplitude * om ** 2 * math.sin(float(np.interp(t, motor["time"], phase_all))) - wn ** 2 * gap_guess

        try:
            contact = loc.local_contact(force, detected, force_keep, data.captures, lasers.y_t, lasers.y, lasers.keep,
                                        accel, length, zeta_ * wn, "mass" in free, params.get("mass"))
        except loc.LocalError as exc:
            raise IdentificationError(str(exc)) from None
        if contact is None and contact_free:
            raise IdentificationError("no complete impact pulse in the force channel outside the left-out windows: "
                                      + ", ".join(contact_free) + " cannot be identified; pass --fix")
    if contact is not None:
        say(f"contact pulse: {contact.source}; contact damping ratio {contact.pulse.sigma / contact.pulse.w0:.3g}, "
            f"{contact.onsets.size} impacts with onset and scale")
        n_v = int(np.isfinite(contact.v0).sum())
        sources = {"mass": f"pulse scale m v0 / cos(theta) over the laser's impact velocity ({n_v} impacts)",
                   "contact.stiffness": f"pulse shape w0^2 = k cos(theta)/m ({contact.source}) times the mass",
                   "contact.damping": f"pulse shape sigma = c cos(theta)/2m + zeta w_n ({contact.source}) times the "
                                      "mass",
                   "gap": f"relative displacement at the contact onsets ({n_v} impacts)"}
        for p, (v, se) in contact.values.items():
            if p in free:
                estimates[p] = Estimate(v, se, sources[p], v, se)
                params[p] = v
    say("local estimates: " + ", ".join(f"{k} = {v.value:.6g}" for k, v in estimates.items()))

    # the joint fit's data and shots
    t_end = float(min(motor["time"][-1], np.nanmax(lasers.y_t) if lasers.y.size else motor["time"][-1]))
    end = rec.common_end(data)
    if end is not None:
        t_end = min(t_end, end)
    if reading.stop is not None:   # a recording cut at the schedule's end: the fit reads it up to there
        t_end = reading.stop
    segments = _segments(motor, float(t_first) + 0.01, t_end, onsets_all, lasers, windows, kicks, length)
    step = max(1, int(round(lasers.rate / FIT_RATE)))
    yk = np.isfinite(lasers.y_t) & lasers.keep
    c_step = max(1, int(round((cart.rate if cart is not None else CART_RATE) / CART_RATE)))
    obs = Observations(lasers.y_t[yk][::step], lasers.y[yk][::step],
                       loc.laser_noise(lasers.y[np.isfinite(lasers.y)]) if lasers.y.size else 1.0,
                       lasers.c_t[lasers.c_keep][::c_step], lasers.c_x[lasers.c_keep][::c_step],
                       loc.laser_noise(lasers.c_x) if lasers.c_x.size else 1.0,
                       contact.samples if contact else [], contact.onsets if contact else np.empty(0),
                       rec.force_noise(force) if force is not None else 1.0,
                       np.interp(contact.onsets, motor["time"], loc.unwrapped_phase(motor)) if contact else None,
                       2 * math.pi * np.interp(contact.onsets, motor["time"], motor["frequency"]) if contact else None)
    return Prepared(data, reading, windows, motor, schedule_source, lasers, estimates, params, contact, kicks, obs,
                    segments, length)


def identify(path, base: SimConfig, fixed: dict[str, float], *, threshold: float = rec.DEFAULT_THRESHOLD,
             settle: float = 2.0, resamples: int = 400, log: Callable[[str], None] | None = None) -> Identification:
    """Identify the free parameters of ``base`` from the recording at ``path`` (see the module doc).

    Args:
        path: The recording (MCAP file or rosbag2 directory).
        base: The configuration the estimates start from and the fixed parameters are taken from.
        fixed: Parameters held at these values (flat names, ``--fix``); the others of :data:`IDENTIFIABLE` are
            estimated.
        threshold: Impact detection threshold on the force (N).
        settle: Seconds after each motor step before its steady state is read.
        resamples: Draws of the cluster bootstrap.
        log: Optional callable receiving each stage's line.

    Returns:
        The identified configuration, the estimates with their uncertainty, the verdict and the validation.

    Raises:
        IdentificationError: A channel a parameter needs is missing, no impact when contact parameters are
            asked for, no free flight for ``f_n`` and ``zeta``.
        rimd_sim.io.reader.RecordingError: Not a recording.
    """
    log = log or (lambda text: None)
    notes: list[str] = []

    def say(text: str) -> None:
        notes.append(text)
        log(text)

    prep = local_stages(rec.load(path), base, fixed, threshold=threshold, settle=settle, say=say)
    # 5. joint fit
    names = list(prep.estimates)
    fit, result, dropped = _joint_stage(base, names, dict(fixed), prep.segments, prep.obs, prep.params,
                                        prep.estimates, prep.lasers, prep.motor, prep.reading.detected["start"],
                                        prep.length, say, log)
    windows = prep.windows + dropped
    segments = fit.segments
    say(f"joint fit: {'converged' if result.converged else 'NOT converged'} after {result.jacobians} iterations "
        f"({fit.evaluations} model runs): {result.message}; displacement chi2 {result.chi2['displacement']:.3g}")
    # 6. uncertainty and verdict
    estimates = uncertainty(fit, result, prep.estimates, prep.motor, resamples)
    force = prep.data.channels.get(rec.FORCE)
    verdict = _verdict(estimates, result, prep.contact, force, prep.obs)
    say(verdict.line())
    # 7. validation
    parts = fit.parts(result.x)
    obs = prep.obs
    resid = {
        "displacement_rms_um": float(np.sqrt(np.mean((parts["displacement"] * obs.sigma_y) ** 2)) * 1e6)
        if parts["displacement"].size else None,
        "laser_noise_um": obs.sigma_y * 1e6,
        "cart_rms_um": float(np.sqrt(np.mean((parts["cart"] * obs.sigma_c) ** 2)) * 1e6)
        if parts["cart"].size else None,
        "chi2": result.chi2, "counts": result.counts, "cost": result.cost,
        "evaluations": fit.evaluations, "iterations": result.jacobians, "converged": result.converged,
        "status": result.message, "starts": result.starts, "segments": len(fit.segments),
    }
    contact = prep.contact
    info = {
        "samples_displacement": int(obs.y.size), "impacts_seen": int(prep.reading.detected["start"].size),
        "impacts_fitted": int(obs.onsets.size),
        "pulse": None if contact is None else {
            "source": contact.source, "sigma_per_s": contact.pulse.sigma, "w0_rad_s": contact.pulse.w0,
            "contact_damping_ratio": contact.pulse.sigma / contact.pulse.w0, "noise_n": contact.pulse.noise,
            "samples_per_contact": float(np.pi / contact.pulse.w0 * force.rate) if force is not None else None},
        "kicks": [{"time_s": t, "velocity_m_s": v} for t, v in result.kicks],
        "segments": [{"t0_s": s.t0, "t1_s": s.t1, "initial_frequency_hz": s.schedule.f0,
                      "commands": [{"time_s": s.t0 + t, "setpoint_hz": f, "ramp_rate_hz_s": rr}
                                   for t, f, rr in s.schedule.commands]} for s in segments],
        "schedule_source": prep.schedule_source,
        "left_out": [w.as_dict() for w in windows],
        "recording_loss": prep.data.loss(),
    }
    ident = Identification(base.with_parameters(result.values), estimates, dict(fixed), list(result.kicks),
                           result.states[0], info, resid, verdict, windows, log=notes)
    ident.validation, ident.series = validate(prep.reading, ident, segments, result, prep.motor)
    return ident


def uncertainty(fit: JointFit, result: JointResult, local: dict[str, Estimate], motor: dict[str, np.ndarray],
                resamples: int = 400) -> dict[str, Estimate]:
    """The estimates with their standard errors.

    The largest of the Jacobian's, the cluster bootstrap's over the excitation cycles (the data's noise and the
    misfit's structure within a cycle) and the delete-a-segment jackknife's (how far the segments disagree), with
    the forward model's numerical error in quadrature: how far the solution moves when the integrator's
    tolerances are a hundred times tighter (one Gauss-Newton step from the solution with the tighter model's
    residuals). A simulated rig integrates at its tolerance; its impacts then differ from the exact model's by a
    few micrometres, which the data cannot tell from a parameter's shift. Every one of them uses the Jacobian at the
    solution taken from both sides (:meth:`JointFit.two_sided_jacobian`): a residual that jumps within the step is
    not read as a slope that pins a parameter (docs/identification.md, "Judging the result").
    """
    runs = fit.run(result.x)
    r = fit.residuals(result.x, runs)
    jac = fit.two_sided_jacobian(result.x, runs, r)
    cov_j = fit.covariance(jac, r)
    cov_b, _ = fit.bootstrap(jac, r, fit.clusters(motor["time"], loc.unwrapped_phase(motor)), resamples=resamples)
    cov_k = fit.jackknife(jac, r, fit.segment_ids())
    integ = fit.base.integrator
    tighter = fit.base.with_parameters({"integrator.rtol": integ.rtol / 100, "integrator.atol": integ.atol / 100})
    tight = JointFit(tighter, fit.names, fit.fixed, fit.segments, fit.obs)
    shift = np.linalg.lstsq(jac, -(tight.residuals(result.x) - r), rcond=None)[0]
    out = {}
    for i, p in enumerate(fit.names):
        e = local[p]
        sj = float(math.sqrt(max(cov_j[i, i], 0.0))) * SCALES[p]
        sb = float(math.sqrt(max(cov_b[i, i], 0.0))) * SCALES[p]
        sk = float(math.sqrt(max(cov_k[i, i], 0.0))) * SCALES[p]
        sn = abs(float(shift[i])) * SCALES[p]
        out[p] = Estimate(result.values[p], math.hypot(max(sj, sb, sk), sn), "joint fit with the core's integrator "
                          "(starting from: " + e.source + ")", e.local_value, e.local_std_error, sj, sb, sn, sk)
        if p in ("gap", "damping_ratio") and result.values[p] <= 1e-12:
            out[p].source += "; at its bound 0 (the interval is one-sided)"
    return out


def _split(seg: Segment, motor: dict, avoid: np.ndarray, lasers: Lasers, length: float) -> list[Segment] | None:
    """``seg`` cut into shots of about :data:`SHORT_SEGMENT` s; None when it is already that short.

    The cuts are motor cycle starts clear of impacts.
    """
    if seg.t1 - seg.t0 < 2 * MIN_SEGMENT:
        return None
    n = max(2, int(round((seg.t1 - seg.t0) / SHORT_SEGMENT)))
    cuts = [seg.t0]
    for k in range(1, n):
        z = loc.cycle_start(motor, seg.t0 + k * (seg.t1 - seg.t0) / n - 0.2, avoid, clear=0.02,
                            before=seg.t1 - MIN_SEGMENT)
        if z is not None and z - cuts[-1] >= MIN_SEGMENT:
            cuts.append(z)
    if len(cuts) == 1:
        return None
    bounds = [*cuts, seg.t1]
    return [Segment(a, b, loc.motor_schedule(motor, a, b), seg.initial if a == seg.t0 else
                    _initial_state(lasers, a, length), [k for k in seg.kicks if a + 0.02 < k[0] < b - 0.02])
            for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _joint_stage(base: SimConfig, names: list[str], fixed: dict[str, float], segments: list[Segment],
                 obs: Observations, params: dict[str, float], estimates: dict[str, Estimate], lasers: Lasers,
                 motor: dict, avoid: np.ndarray, length: float, say: Callable[[str], None],
                 log: Callable[[str], None]) -> tuple[JointFit, JointResult, list[Window]]:
    """The joint fit from the local estimates; the fit, its result and the windows it left out.

    A robust loss first with adaptive multiple shooting (shots the model does not follow are cut shorter; those it
    cannot follow even when short, a chaotic transient, are left out), then least squares; when that does not
    reach the data, more starts.
    """
    dropped: list[Window] = []

    def build(segs: list[Segment], values: dict[str, float], states: list[tuple[float, float]],
              kicks: list[tuple[float, float]]) -> tuple[JointFit, np.ndarray]:
        fit = JointFit(base, names, fixed, segs, obs)
        return fit, fit.pack(values, states, kicks)

    fit, x0 = build(segments, params, [s.initial for s in segments], [k for s in segments for k in s.kicks])
    say(f"joint fit: {fit.n} unknowns ({len(names)} parameters, {len(segments)} segments, "
        f"{len(fit.kick_owner)} kick(s)), {obs.y.size} displacement samples, {len(obs.impacts)} impacts")
    # Robust loss first (each scaled residual counts linearly beyond 3): a shot the trial parameters put on another
    # motion, or one the model cannot follow at all (a chaotic transient), does not steer the fit.
    result = fit.solve(x0, loss="soft_l1", log=log)
    for _ in range(6):   # shots the model does not follow: cut them shorter (multiple shooting, adaptively)
        chi2 = fit.segment_chi2(result.x)
        typical = float(np.median(chi2))   # a shot much worse than the others
        bad = [s for s, c in enumerate(chi2) if c > SEGMENT_CHI2 and c > 3 * typical]
        if not bad:
            break
        values, states, kicks = result.values, result.states, result.kicks
        new_segs, new_states = [], []
        for s, seg in enumerate(fit.segments):
            seg = Segment(seg.t0, seg.t1, seg.schedule, states[s],
                          [k for k, owner in zip(kicks, fit.kick_owner, strict=True) if owner == s])
            if s not in bad:
                new_segs.append(seg)
                new_states.append(states[s])
                continue
            parts = _split(seg, motor, avoid, lasers, length)
            if parts is None:
                dropped.append(Window("all", "not followed", seg.t0, seg.t1, "identify",
                                      f"the twin cannot follow this stretch (displacement residual "
                                      f"{math.sqrt(chi2[s]):.0f} times the laser noise): a chaotic transient"))
                continue
            new_segs += parts
            new_states += [p.initial for p in parts]
        say(f"joint fit: {len(bad)} segment(s) not followed (displacement chi2 "
            + ", ".join(f"{chi2[s]:.3g}" for s in bad) + "): cut shorter")
        fit, x0 = build(new_segs, {**params, **values}, new_states, [k for s in new_segs for k in s.kicks])
        result = fit.solve(x0, loss="soft_l1", log=log)
    # then least squares from there: the estimates and their errors are those of the Gaussian likelihood
    result = fit.solve(result.x, log=log)
    tried = [result]
    if not _good(result):
        # Still not at the lasers' noise: more starts, every parameter moved by +-3 of its local standard errors
        # (at least 5 %); the best fit is kept.
        _, states, kicks = fit.unpack(x0)
        for (k,) in STARTS:
            shifted = dict(params)
            for p in names:
                e = estimates[p]
                spread = max(abs(e.local_std_error or 0.0), 0.05 * abs(e.local_value or e.value))
                shifted[p] = max(e.value + k * spread, 0.0 if p in ("gap", "damping_ratio") else 1e-6 * SCALES[p])
            trial = fit.solve(fit.pack(shifted, states, kicks), log=log)
            tried.append(trial)
            say(f"joint fit from another start (every parameter {k:+g} local errors): misfit {trial.cost:.6g}")
        result = min(tried, key=lambda r: r.cost)
    result.starts = len(tried)
    return fit, result, dropped


def _good(result: JointResult) -> bool:
    chi2 = result.chi2.get("displacement")
    return bool(result.converged and chi2 is not None and chi2 <= GOOD_FIT_CHI2)


def _verdict(estimates: dict[str, Estimate], result: JointResult, contact: loc.ContactEstimate | None,
             force: rec.Channel | None, obs: Observations) -> Verdict:
    """Each parameter against its target (:data:`TARGETS`), with the reason and the experiment that would help."""
    verdict = Verdict()
    if not result.converged:
        verdict.poorly.append(("all", f"the joint fit did not converge ({result.message})",
                               "a longer recording with steady impacts, or --fix what is known"))
    chi2 = result.chi2.get("displacement")
    if chi2 is not None and chi2 > 4 * GOOD_FIT_CHI2:
        verdict.poorly.append(("all", f"the twin does not follow the lasers (displacement residual "
                                      f"{math.sqrt(chi2):.1f} times the laser noise)",
                               "check the recording for faults the scan did not see, or the contact law"))
    # how many samples the contact spans at the rate of the samples its shape came from (captures: their own)
    rate = None if contact is None else (1.0 / min(p.dt for p in contact.samples) if "captures" in contact.source
                                         and contact.samples else force.rate if force is not None else None)
    samples = (math.pi / contact.pulse.w0 * rate) if rate and contact is not None else None
    for p, e in estimates.items():
        kind, target = TARGETS[p]
        hw = e.half_width_95
        if hw is None or not math.isfinite(hw):
            verdict.poorly.append((p, "no error estimate", "more data"))
            continue
        size = hw / abs(e.value) if kind == "relative" and e.value else hw
        if size <= target:
            continue
        shown = f"+-{size * 100:.2g} % at 95 %" if kind == "relative" else f"+-{hw * 1e3:.3g} mm at 95 %"
        if p in ("contact.stiffness", "contact.damping"):
            src = contact.source if contact is not None else "no pulse"
            why = f"{shown}; the pulse ({src}) spans ~{samples:.1f} samples" if samples else shown
            what = "record the triggered captures (capture.enabled: true): the 1 MHz pulse pins k and c" \
                if contact is not None and "captures" not in contact.source else "more impacts (longer steps in band A)"
        elif p in ("natural_frequency", "damping_ratio"):
            why = f"{shown} from the free flight between impacts"
            what = "a step without impacts below the resonance, or a perturbation (/rig/perturb) in free flight: " \
                   "its free decay separates f_n and zeta (rimd experiment --for-identification)"
        elif p == "mass":
            why = f"{shown} from {obs.onsets.size} impacts' scale over the impact velocity"
            what = "more impacts at different velocities (steps across band A)"
        elif p == "gap":
            why = f"{shown} from {obs.onsets.size} impact onsets"
            what = "more impacts (longer steps in band A)"
        else:
            why, what = shown, "a longer recording"
        verdict.poorly.append((p, why, what))
    return verdict


# ---- validation ----------------------------------------------------------------------------------------------

def twin_reading(reading: Reading, ident: Identification, segments: list[Segment], result: JointResult,
                 motor: dict[str, np.ndarray]) -> tuple[list[dict], dict]:
    """The twin under the recorded schedule, from the first segment's fitted start, read like the recording."""
    data = reading.data
    seg0 = segments[0]
    t_end = segments[-1].t1
    schedule = loc.motor_schedule(motor, seg0.t0, t_end)
    force = data.channels.get(rec.FORCE)
    rate = force.rate if force is not None else 100.0
    config = model_config(ident.config, {}, schedule, result.states[0], force_rate=rate)
    run, fch = run_schedule(config, schedule, [(t - seg0.t0, v) for t, v in result.kicks], t_end - seg0.t0, force=True)
    assert fch is not None   # force=True
    t_f, v_f = fch
    twin_force = rec.Channel(rec.FORCE, rate, np.arange(v_f.size), t_f, v_f)
    pulse = None
    if reading.pulse is not None:
        from rimd_sim.analysis.recordings.contact_pulse import pulse_of

        rig = ident.config.rig
        cos_t = math.sqrt(max(1.0 - (rig.gap / rig.length) ** 2, 0.0))
        pulse = pulse_of(rig.mass, rig.contact.stiffness, rig.contact.damping, cos_theta=cos_t,
                         sigma_free=rig.damping_ratio * 2 * math.pi * rig.natural_frequency)
    detected = rec.detect_impacts(twin_force, reading.threshold, pulse)
    events = {"time": run.onsets, "peak_force": run.peaks}
    rows = step_rows(reading.steps, events, detected, twin_force, reading.windows)
    return rows, {"run": run, "detected": detected}


def validate(reading: Reading, ident: Identification, segments: list[Segment], result: JointResult,
             motor: dict[str, np.ndarray]) -> tuple[list[dict], dict]:
    """Per motor step: the recording (``rimd analyze``'s step table) against the twin read the same way."""
    twin_rows, twin = twin_reading(reading, ident, segments, result, motor)
    run = twin["run"]
    lasers_t, lasers_y = (rec.phase_plane(reading.data.channels[rec.RIMD_X], reading.data.channels[rec.CART_X])[:2]
                          if rec.RIMD_X in reading.data.channels and rec.CART_X in reading.data.channels
                          else (np.empty(0), np.empty(0)))
    fin = np.isfinite(lasers_t)
    ty, yy = lasers_t[fin], lasers_y[fin]
    inside = (ty >= run.t[0]) & (ty <= run.t[-1])
    ym = np.interp(ty, run.t, run.y)
    rows = []
    for rr, tr in zip(reading.rows, twin_rows, strict=True):
        if rr["steady_from_s"] is None:
            continue
        lo, hi = rr["steady_from_s"], rr["end_s"]
        ysel = inside & (ty >= lo) & (ty < hi)

        def diff(a: float | None, b: float | None) -> float | None:
            return (b / a - 1.0) if (a and b is not None) else None

        # the difference: of the events' exact peaks where the recording has events, else of the channel's readings
        events = rr["peak_force_events_n"] is not None and tr["peak_force_events_n"] is not None
        rows.append({
            "step": rr["step"], "frequency_hz": rr["frequency_hz"], "steady_from_s": lo, "end_s": hi,
            "settled": rr.get("settled"),
            "peak_force_recorded_n": rr["peak_force_channel_n"], "peak_force_twin_n": tr["peak_force_channel_n"],
            "peak_force_difference": diff(rr["peak_force_events_n"], tr["peak_force_events_n"]) if events else
            diff(rr["peak_force_channel_n"], tr["peak_force_channel_n"]),
            "peak_force_difference_of": "events" if events else "channel",
            "peak_force_events_recorded_n": rr["peak_force_events_n"],
            "peak_force_events_twin_n": tr["peak_force_events_n"],
            "impacts_per_cycle_recorded": rr["impacts_per_cycle_channel"],
            "impacts_per_cycle_twin": tr["impacts_per_cycle_channel"],
            "impacts_per_cycle_events_recorded": rr["impacts_per_cycle_events"],
            "impacts_per_cycle_events_twin": tr["impacts_per_cycle_events"],
            "displacement_rms_difference_um": float(np.sqrt(np.mean((ym[ysel] - yy[ysel]) ** 2)) * 1e6)
            if ysel.any() else None,
        })
    det = reading.detected
    series = {"t": ty, "y": yy, "y_twin": ym, "r_on": det["start"], "r_peak": det["peak_force"],
              "m_on": run.onsets, "m_peak": run.peaks, "steps": reading.steps, "windows": reading.windows}
    return rows, series
