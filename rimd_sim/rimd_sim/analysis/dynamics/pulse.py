"""One impact at a given velocity, seen by the instruments at a high sample rate (``rimd pulse``; docs/physics.md).

The cart is at rest and the hammer arrives at the force sensor with the given velocity; the force sensor and
the accelerometer are sampled (noise-free) at ``rate`` from just before contact. The summary reads the pulse
as a DAQ team would: its largest force, the second force peak (the structure's impulse back), the contact
duration and the frequency of the accelerometer's ringing after the impact.

The run is checked against the model's valid domain (:mod:`rimd_sim.model.validity`): its largest contact
force against the force sensor's range, its largest ``|theta|``; the summary carries ``valid``,
``invalid_rule`` and the ``validity`` entry. Impacts per cycle do not apply (the motor is at rest), and a pulse
the chattering guard stops has nothing to show: it stays an error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rimd_sim.errors import ConfigError
from rimd_sim.model.rig_model import RigModel
from rimd_sim.model.validity import PointMeasures, domain
from rimd_sim.settings.config import SimConfig

__all__ = ["PulseResult", "force_peaks", "pulse", "ring_frequency"]

#: Time simulated after the contact starts (s): the ringing decays within it.
PULSE_SPAN = 0.02
#: Distance (m) before the stop at which the pulse starts.
LEAD_GAP = 1e-6
#: Window after the impact in which the accelerometer's ringing is analysed (s).
RING_WINDOW = 0.005


@dataclass
class PulseResult:
    """Samples and summary of one pulse.

    Attributes:
        t: Sample times (s) from the contact start.
        force: Force sensor reading (N).
        acceleration: Accelerometer reading (m/s^2, inertial).
        summary: ``peak_force_n``, ``second_peak_force_n``, ``duration_s``, ``ring_frequency_hz`` and more.
    """

    t: np.ndarray
    force: np.ndarray
    acceleration: np.ndarray
    summary: dict


def force_peaks(force: np.ndarray, prominence: float = 0.02) -> list[int]:
    """Indices of the force's local maxima with a prominence of at least ``prominence`` x its maximum."""
    from scipy.signal import find_peaks

    top = float(np.max(force)) if force.size else 0.0
    if top <= 0.0:
        return []
    idx, _ = find_peaks(np.concatenate(([0.0], force, [0.0])), prominence=prominence * top)
    return [int(i) - 1 for i in idx]


def ring_frequency(acc: np.ndarray, rate: float, floor: float = 0.05) -> float:
    """Dominant frequency (Hz) of a ringing signal, 0 when its RMS is below ``floor`` (m/s^2).

    The spectrum of the signal less its quadratic trend (the slow pendulum motion), Hann window, zero-padded
    8x, and a parabola through its peak bin.
    """
    if acc.size < 16:
        return 0.0
    tt = np.linspace(-1.0, 1.0, acc.size)
    x = acc - np.polyval(np.polyfit(tt, acc, 2), tt)
    if float(np.sqrt(np.mean(x * x))) < floor:
        return 0.0
    n = 8 * x.size
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size), n))
    spec[0] = 0.0
    i = int(np.argmax(spec))
    peak: float = i
    if 0 < i < spec.size - 1:
        a, b, c = spec[i - 1], spec[i], spec[i + 1]
        den = a - 2 * b + c
        peak = i + (0.5 * (a - c) / den if den != 0 else 0.0)
    return float(peak * rate / n)


def pulse(config: SimConfig, velocity: float, rate: float = 1e6, span: float = PULSE_SPAN) -> PulseResult:
    """Simulate one impact at ``velocity`` (m/s, towards the sensor) and sample it at ``rate`` (Hz).

    Raises:
        ConfigError: For a velocity that is not finite and > 0 (at most 10 m/s) or a rate out of range.
    """
    if isinstance(velocity, bool) or not isinstance(velocity, (int, float)) or not math.isfinite(velocity) \
            or not 0.0 < velocity <= 10.0:
        raise ConfigError("velocity", velocity, "must be > 0 and <= 10 m/s")
    if not 1e3 <= rate <= 1e7:
        raise ConfigError("rate", rate, "must be >= 1000 and <= 1e+07 Hz")
    length = config.rig.length
    x0 = config.rig.gap - LEAD_GAP
    theta0 = math.asin(x0 / length)
    params = {
        "motor.initial_frequency": 0.0, "motor.initial_setpoint": 0.0,
        "initial.theta": theta0, "initial.theta_dot": velocity / (length * math.cos(theta0)),
        "channels.impact_force.sample_rate": float(min(rate, 1e6)),
        "channels.rimd_acceleration.sample_rate": float(min(rate, 1e6)),
        "integrator.max_step": min(config.integrator.max_step, 1e-4),
    }
    cfg = config.with_parameters(params)
    model = RigModel(cfg, channels=True, truth=False)
    t_lead = LEAD_GAP / velocity
    out = model.advance(t_lead + span)
    rate = float(cfg.channel("impact_force").sample_rate)
    first, force = out.channels["impact_force"]
    _, acc = out.channels["rimd_acceleration"]
    t = (first + np.arange(force.size)) / rate
    if not out.impacts:
        raise ConfigError("velocity", velocity, "gave no impact within the simulated span")
    imp = out.impacts[0]
    t = t - imp.t_start
    during = (t >= 0.0) & (t <= imp.duration)
    f_imp = np.where(during, force, 0.0)
    peaks = force_peaks(f_imp)
    values = sorted((float(force[i]) for i in peaks), reverse=True)
    valley = 0.0
    if len(peaks) > 1:  # the lowest force between the two largest peaks
        i0, i1 = sorted(sorted(peaks, key=lambda i: -force[i])[:2])
        valley = float(np.min(force[i0:i1 + 1]))
    # The ringing after the impact: RING_WINDOW from its end. The ring itself can push the front mass back
    # onto the sensor (small re-contacts at gap 0); the window starts after the last of those within it.
    ring_start = imp.t_end
    for later in out.impacts[1:]:
        if later.t_start < ring_start + RING_WINDOW:
            ring_start = later.t_end
    after = (t > ring_start - imp.t_start) & (t <= ring_start - imp.t_start + RING_WINDOW)
    summary = {
        "velocity_m_s": float(velocity),
        "sample_rate_hz": rate,
        "peak_force_n": float(np.max(f_imp)),
        "second_peak_force_n": values[1] if len(values) > 1 else 0.0,
        "second_to_first": (values[1] / values[0]) if len(values) > 1 and values[0] > 0 else 0.0,
        "valley_force_n": valley,
        "force_peaks_n": values,
        "force_peak_times_s": [float(t[i]) for i in peaks],
        "duration_s": float(imp.duration),
        "impulse_n_s": float(imp.impulse),
        "contacts": int(imp.contacts),
        "ring_frequency_hz": ring_frequency(acc[after], rate) if np.count_nonzero(after) > 16 else 0.0,
        "impacts_in_span": len(out.impacts),
        "model": cfg.rig.structure.model,
    }
    dom = domain(cfg)
    verdict = dom.check(PointMeasures(out.max_abs_theta, max(i.peak_force for i in out.impacts)))
    summary.update({"max_abs_theta_rad": out.max_abs_theta, "max_force_n": max(i.peak_force for i in out.impacts),
                    "valid": verdict.valid, "invalid_rule": verdict.invalid_rule,
                    "validity": dom.report([verdict])})
    return PulseResult(t, force, acc, summary)


def plot_pulse(result: PulseResult, path, title: str = ""):
    """Force and acceleration of one pulse over time (ms), as Fig. 3 of the paper shows them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = result.summary
    end = 1e3 * (s["duration_s"] + RING_WINDOW)
    keep = (result.t >= -1e-4) & (1e3 * result.t <= end)
    t_ms = 1e3 * result.t[keep]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    ax1.plot(t_ms, result.force[keep], lw=1.0)
    for tp in s["force_peak_times_s"]:
        ax1.axvline(1e3 * tp, color="0.7", lw=0.6, ls="--")
    ax1.set_xlim(-0.1, 1e3 * s["duration_s"] * 1.5 + 0.05)
    ax1.set_xlabel("time from contact (ms)")
    ax1.set_ylabel("impact force (N)")
    ax1.set_title(f"peak {s['peak_force_n']:.1f} N, second {s['second_peak_force_n']:.1f} N")
    ax2.plot(t_ms, result.acceleration[keep], lw=0.8)
    ax2.set_xlabel("time from contact (ms)")
    ax2.set_ylabel("RIMD acceleration (m/s²)")
    ring = s["ring_frequency_hz"]
    ax2.set_title(f"ringing {ring:.0f} Hz" if ring > 0 else "no ringing")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.suptitle(title or f"one impact at {s['velocity_m_s']:g} m/s ({s['model']} model, "
                          f"{s['sample_rate_hz'] / 1e6:g} MHz)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
