"""The rig as a DAQ sees it: the model, its instruments and a schedule of commands in simulation time.

:class:`RigSimulator` is what the simulator node drives. ``advance(t)`` returns, for ``[time, t)``, one
block per channel (noisy, quantised, clipped readings on the channel's exact sample grid), the truth
block, the impacts that completed, stroboscopic points and the log of commands applied. Commands are
validated when they are scheduled (a refused command raises and changes nothing) and take effect at
their stated simulation time, between two samples. Same configuration (seed included) and same command
schedule give bit-identical output, however ``advance`` calls cut the time.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from rimd_sim.errors import CommandError, ConfigError
from rimd_sim.instruments.capture import CaptureRecord, TriggeredCapture
from rimd_sim.instruments.faults import FaultEvent, FaultLayer, FaultSpec, validate_fault
from rimd_sim.instruments.sensors import Instrument
from rimd_sim.model.rig_model import (
    Impact,
    ModelOutput,
    MotorState,
    RigModel,
    StroboPoint,
    as_time,
    model_for,
    samples_before_ratio,
)
from rimd_sim.settings.capture import ACC_CHANNEL, FORCE_CHANNEL, CaptureConfig
from rimd_sim.settings.config import CHANNEL_NAMES, SimConfig

__all__ = ["RESTING_VELOCITY", "AppliedCommand", "ChannelBlock", "RigSimulator", "SimBlock"]

#: A contact that starts with the hammer placed at rest (the run's start, a reset) and closes at less than this
#: relative velocity (m/s) is a resting contact, not an impact: at gap 0 the hammer starts on the stop, and the cart
#: pressing it away is no collision. The model's impact list keeps it; the rig does not report it, and numbers the
#: impacts after it from 0 on, so that ``index`` counts the impacts a DAQ sees.
RESTING_VELOCITY = 1e-6

#: Parameters that only concern the node's pacing: accepted at run time, ignored by the core.
NODE_ONLY_PARAMETERS = {"real_time_factor", "block_rate"}


@dataclass(frozen=True)
class ChannelBlock:
    """Readings of one channel over one block.

    Attributes:
        name: Channel name.
        first_index: Index of ``samples[0]`` since the channel started.
        sample_rate: Hz.
        samples: Readings (SI).
        saturated: Samples clipped at a range end.
    """

    name: str
    first_index: int
    sample_rate: float
    samples: np.ndarray
    saturated: int


@dataclass(frozen=True)
class AppliedCommand:
    """A command as applied: when, what, and its outcome."""

    time: Fraction
    kind: str
    detail: str


@dataclass
class SimBlock:
    """Everything produced over ``[t_start, t_stop)`` of simulation time."""

    t_start: Fraction
    t_stop: Fraction
    channels: dict[str, ChannelBlock]
    truth: tuple[int, np.ndarray] | None
    impacts: list[Impact]
    strobe: list[StroboPoint]
    motor: MotorState
    commands: list[AppliedCommand] = field(default_factory=list)
    #: Channel -> the blocks the DAQ receives at the end of this block, after the block-level faults
    #: (dropout, block_loss, delay); without faults ``[channels[name]]``.
    deliveries: dict[str, list[ChannelBlock]] = field(default_factory=dict)
    #: Faults that started or ended in this block.
    fault_events: list[FaultEvent] = field(default_factory=list)
    #: Triggered captures completed in this block.
    captures: list[CaptureRecord] = field(default_factory=list)


class RigSimulator:
    """The rig model with instruments and scheduled commands.

    Args:
        config: Validated configuration.
        truth: Produce the ground-truth stream.
        strobe: Produce stroboscopic points.
    """

    def __init__(self, config: SimConfig, *, truth: bool = True, strobe: bool = False,
                 capture: CaptureConfig | None = None) -> None:
        self._config = config
        self._rates_cache: tuple[SimConfig, dict[str, Fraction], Fraction] | None = None
        capture = capture if capture is not None and capture.enabled else None
        if capture is not None and not model_for(config).capture:
            raise ConfigError("capture.enabled", True, "not supported with structure.model "
                              f"'{config.rig.structure.model}' yet (the triggered capture samples the hammer's "
                              "acceleration in contact only); use structure.model: rigid")
        self._model = RigModel(config, channels=True, truth=truth, strobe=strobe,
                               extra_channels=capture.extra_channels() if capture else ())
        self._capture = (TriggeredCapture(capture, config.channel("impact_force"),
                                          config.channel("rimd_acceleration"), config.seed,
                                          noise=config.noise_enabled) if capture else None)
        self._instruments = {ch.name: Instrument(ch, noise=config.noise_enabled, seed=config.seed)
                             for ch in config.channels}
        self._queue: list[tuple[Fraction, int, str, Any]] = []
        self._counter = itertools.count()
        self._faults = FaultLayer(config.channels, config.seed)
        #: When the hammer was placed at rest (the start, each reset): a contact starting there may be resting.
        self._placed: list[float] = [float(self._model.time)]
        self._resting = 0   # resting contacts left out so far (the impacts after them are numbered on)

    @property
    def config(self) -> SimConfig:
        """Configuration in force."""
        return self._config

    @property
    def time(self) -> Fraction:
        """Simulation time reached (s)."""
        return self._model.time

    @property
    def model(self) -> RigModel:
        """The underlying model."""
        return self._model

    # ---- scheduling ------------------------------------------------------------------------------

    def _at(self, at: float | Fraction | None) -> Fraction:
        when = self.time if at is None else as_time(at)
        if when < self.time:
            raise CommandError(f"time {float(when)} s is in the past (simulation time is {float(self.time)} s)")
        return when

    def _push(self, at: Fraction, kind: str, arg: Any) -> Fraction:
        heapq.heappush(self._queue, (at, next(self._counter), kind, arg))
        return at

    def set_motor_frequency(self, frequency_hz: float, ramp_rate: float = 0.0, *,
                            at: float | Fraction | None = None, kind: str = "set_motor_frequency") -> Fraction:
        """Schedule a motor setpoint (see :meth:`RigModel.set_motor_frequency` for the rules).

        ``kind`` names it in the applied commands' log: ``set_motor_frequency`` (the service) or ``motor_command``
        (the command topic, whose applications the node counts rather than logs one by one).

        Returns:
            The simulation time at which it takes effect.

        Raises:
            CommandError: For a refused value or a time in the past; nothing is scheduled.
        """
        when = self._at(at)
        max_f = self._config.motor.max_frequency
        _check_frequency(frequency_hz, ramp_rate, max_f)
        if kind not in ("set_motor_frequency", "motor_command"):
            raise ValueError(f"kind = {kind!r}: must be set_motor_frequency or motor_command")
        return self._push(when, kind, (float(frequency_hz), float(ramp_rate)))

    def perturb(self, velocity: float, *, at: float | Fraction | None = None) -> Fraction:
        """Schedule a velocity kick of the hammer (m/s)."""
        when = self._at(at)
        if isinstance(velocity, bool) or not isinstance(velocity, (int, float)) or not np.isfinite(velocity) \
                or abs(velocity) > 10.0:
            raise CommandError(f"velocity = {velocity!r} refused: must be a finite number within +-10 m/s")
        return self._push(when, "perturb", float(velocity))

    def reset(self, *, at: float | Fraction | None = None) -> Fraction:
        """Schedule a reset of the hammer to its initial state (the motor keeps running)."""
        return self._push(self._at(at), "reset", None)

    def set_parameters(self, params: Mapping[str, Any], *, at: float | Fraction | None = None) -> Fraction:
        """Schedule a change of configuration parameters (flat ROS names).

        Raises:
            ConfigError: For an unknown key or a refused value (nothing is scheduled).
            CommandError: For a sample-rate change or a time in the past.
        """
        when = self._at(at)
        config = self._config.with_parameters(params)  # validates now
        for key in params:
            if key.endswith(".sample_rate"):
                raise CommandError(f"parameter '{key}' cannot change while the rig runs; restart with the new rate")
            if key == "structure.model" and params[key] != self._config.rig.structure.model:
                raise CommandError("parameter 'structure.model' cannot change while the rig runs; restart with "
                                   "the other model")
            if key == "seed":
                raise CommandError("parameter 'seed' cannot change while the rig runs; restart with the new seed")
        del config
        return self._push(when, "set_parameters", dict(params))

    def inject_fault(self, channel: str, kind: str, start: float = 0.0, duration: float = 0.0,
                     magnitude: float = 0.0, after: float = 0.0) -> FaultSpec:
        """Schedule a fault (see :mod:`rimd_sim.instruments.faults`).

        ``start``: simulation time, 0 = now (the next block boundary); or ``after``: seconds from now.

        Raises:
            CommandError: Naming the field and its rule; nothing is scheduled.
        """
        channel, kind, t_start, duration_t, magnitude = validate_fault(
            channel, kind, start, duration, magnitude, now=self.time,
            channels={c.name: c for c in self._config.channels}, after=after)
        if kind == "motor_slip":
            if self._config.rig.structure.model != "rigid":
                raise CommandError("kind = 'motor_slip' refused: not supported with structure.model "
                                   f"'{self._config.rig.structure.model}' yet (use structure.model: rigid)")
            spec = self._faults.add(channel, kind, t_start, duration_t, magnitude)
            self._push(t_start, "motor_slip", float(magnitude))
            if spec.end is not None:
                self._push(spec.end, "motor_slip", 0.0)
            return spec
        return self._faults.add(channel, kind, t_start, duration_t, magnitude)

    def clear_faults(self) -> tuple[int, int]:
        """End every fault in force now and cancel the scheduled ones; returns ``(ended, cancelled)``."""
        slipping = any(f.kind == "motor_slip" for f in self._faults.active(self.time))
        result = self._faults.clear(self.time)
        if any(kind == "motor_slip" for _, _, kind, _ in self._queue) or slipping:
            self._queue = [c for c in self._queue if c[2] != "motor_slip"]
            heapq.heapify(self._queue)
            self._push(self.time, "motor_slip", 0.0)
        return result

    def active_faults(self) -> list[FaultSpec]:
        """Faults in force now."""
        return self._faults.active(self.time)

    def pending_commands(self) -> int:
        """Number of commands scheduled but not applied yet."""
        return len(self._queue)

    # ---- running ---------------------------------------------------------------------------------

    def _apply(self, kind: str, arg: Any) -> tuple[list[Impact], str]:
        model = self._model
        if kind in ("set_motor_frequency", "motor_command"):
            f, rate = arg
            done = model.set_motor_frequency(f, rate)
            return done, f"setpoint {f:g} Hz, ramp {rate or self._config.motor.ramp_rate:g} Hz/s"
        if kind == "perturb":
            return model.perturb(arg), f"hammer velocity {arg:+g} m/s"
        if kind == "motor_slip":
            return model.set_motor_slip(arg), f"motor slip {arg:g} of the frequency per impact"
        if kind == "reset":
            self._placed.append(float(model.time))
            return model.reset_hammer(), "hammer reset to its initial state"
        config = self._config.with_parameters(arg)
        done = model.reconfigure(config)
        for ch in config.channels:
            self._instruments[ch.name].reconfigure(ch, noise=config.noise_enabled)
        self._faults.configure(config.channels)
        self._config = config
        return done, ", ".join(f"{k}={v!r}" for k, v in arg.items())

    def advance(self, t_stop: float | Fraction) -> SimBlock:
        """Simulate to ``t_stop`` (s), applying due commands, and return the block of data.

        Raises:
            CommandError: If ``t_stop`` is in the past.
            IntegrationError: If the model cannot continue.
        """
        t_stop = as_time(t_stop)
        if t_stop < self.time:
            raise CommandError(f"cannot advance to {float(t_stop)} s: already at {float(self.time)} s")
        return self.advance_blocks([t_stop])[0]

    def _exact_rates(self) -> tuple[dict[str, Fraction], Fraction]:
        """The channels' and the truth's sample rates as exact fractions (cached per configuration)."""
        cached = self._rates_cache
        if cached is None or cached[0] is not self._config:
            config = self._config
            cached = self._rates_cache = (config, {ch.name: Fraction(repr(ch.sample_rate)) for ch in config.channels},
                                          Fraction(repr(config.truth_rate)))
        return cached[1], cached[2]

    def advance_blocks(self, boundaries: Sequence[float | Fraction]) -> list[SimBlock]:
        """Simulate to the last of ``boundaries`` in one pass and return one block per interval.

        The result is bit for bit what ``[advance(b) for b in boundaries]`` returns, at a fraction of the
        per-block overhead (one model pass and one instrument pass per call).

        Raises:
            CommandError: If the boundaries are not increasing or start in the past.
            IntegrationError: If the model cannot continue.
        """
        bounds = [as_time(b) for b in boundaries]
        t_start = self.time
        if not bounds or bounds[0] < t_start or any(b2 <= b1 for b1, b2 in zip(bounds, bounds[1:], strict=False)):
            raise CommandError("block boundaries must be increasing and not in the past")
        parts: list[ModelOutput] = []
        motor: list[MotorState | None] = [None] * len(bounds)   # per boundary
        applied: list[AppliedCommand] = []
        extra: list[Impact] = []

        def run_to(t: Fraction) -> None:
            # Under a motor slip the motor changes at every impact: block by block, so that the motor state
            # of each block end is read at the end of an advance (RigModel.motor_state).
            steps = [b for b in bounds if self.time < b < t] if self._model.motor_slipping else []
            for stop in (*steps, t):
                start = self.time
                parts.append(self._model.advance(stop))
                for j, b in enumerate(bounds):
                    if motor[j] is None and start < b <= stop:
                        motor[j] = self._model.motor_state(float(b))

        while self._queue and self._queue[0][0] < bounds[-1]:
            when, _, kind, arg = heapq.heappop(self._queue)
            run_to(when)
            try:
                done, detail = self._apply(kind, arg)
            except (CommandError, ConfigError) as exc:
                applied.append(AppliedCommand(when, kind, f"refused at application: {exc}"))
                continue
            extra.extend(done)
            applied.append(AppliedCommand(when, kind, detail))
        run_to(bounds[-1])
        motor_at: list[MotorState] = []
        for j, b in enumerate(bounds):
            state = motor[j]
            motor_at.append(state if state is not None  # else a boundary equal to the start of the pass
                            else self._model.motor_state(float(b)))

        rates, truth_rate = self._exact_rates()
        ratios = [b.as_integer_ratio() for b in bounds]
        readings = {}
        for name in CHANNEL_NAMES:
            first = parts[0].channels[name][0]
            raw = _joined([p.channels[name][1] for p in parts])
            rate = rates[name]
            x, clipped = self._instruments[name].measure_mask(self._faults.pre(name, first, raw))
            x, clipped = self._faults.post(name, first, x, clipped)
            reading = [((lo, hi), x[lo:hi], int(np.count_nonzero(clipped[lo:hi])) if clipped is not None else 0)
                       for lo, hi in _split_index(first, raw.size, _cuts(ratios, rate))]
            readings[name] = (first, rate, reading)
        captures: list[CaptureRecord] = []
        if self._capture is not None:
            captures = self._capture.process(parts[0].channels[FORCE_CHANNEL][0],
                                             np.concatenate([p.channels[FORCE_CHANNEL][1] for p in parts]),
                                             np.concatenate([p.channels[ACC_CHANNEL][1] for p in parts]),
                                             parts[0].channels["rimd_acceleration"][0],
                                             self._config.channel("rimd_acceleration").sample_rate,
                                             np.concatenate([p.channels["rimd_acceleration"][1] for p in parts]),
                                             np.concatenate([p.channels["impact_force"][1] for p in parts])
                                             if self._config.channel("impact_force").sample_rate
                                             == self._config.channel("rimd_acceleration").sample_rate
                                             else np.zeros(sum(p.channels["rimd_acceleration"][1].size
                                                               for p in parts)))
            cap_rate = Fraction(repr(self._capture.config.sample_rate))
        truth_all = None
        if parts[0].truth is not None:
            truth_all = (parts[0].truth[0], _joined([_truth(p)[1] for p in parts], axis=1))
            truth_cuts = _split_index(truth_all[0], truth_all[1].shape[1],
                                      _cuts(ratios, truth_rate))
        impacts = self._reported(sorted([i for p in parts for i in p.impacts] + extra, key=lambda i: i.index))
        strobe = [s for p in parts for s in p.strobe]
        blocks = []
        prev = t_start
        for j, b in enumerate(bounds):
            channels = {}
            for name, (first, _rate, reading) in readings.items():
                lo, hi = reading[j][0]
                channels[name] = ChannelBlock(name, first + lo, self._config.channel(name).sample_rate,
                                              reading[j][1], reading[j][2])
            truth = None
            if truth_all is not None:
                lo, hi = truth_cuts[j]
                truth = (truth_all[0] + lo, truth_all[1][:, lo:hi])
            fb, fp = float(b), float(prev)
            deliveries = {name: self._faults.deliver(name, cb, prev, b) for name, cb in channels.items()}
            blocks.append(SimBlock(
                prev, b, channels, truth,
                [i for i in impacts if (fp <= i.t_end or j == 0) and i.t_end < fb],
                [s for s in strobe if fp <= s.t < fb],
                motor_at[j],
                [c for c in applied if prev <= c.time < b],
                deliveries,
                self._faults.events(prev, b),
                [c for c in captures
                 if (j == 0 or prev < Fraction(c.trigger_index + c.force.size - c.pre_trigger_samples, 1) / cap_rate)
                 and Fraction(c.trigger_index + c.force.size - c.pre_trigger_samples) / cap_rate <= b],
            ))
            prev = b
        return blocks


    def _reported(self, impacts: list[Impact]) -> list[Impact]:
        """The impacts the rig reports: resting contacts (:data:`RESTING_VELOCITY`) left out, the rest renumbered."""
        out = []
        for imp in impacts:
            if abs(imp.impact_velocity) < RESTING_VELOCITY and any(abs(imp.t_start - t) < 1e-9 for t in self._placed):
                self._resting += 1
                continue
            out.append(imp._replace(index=imp.index - self._resting) if self._resting else imp)
        del self._placed[:-1]   # only the last placement can still start a contact
        return out


def _joined(arrays: list[np.ndarray], axis: int = 0) -> np.ndarray:
    """The model's arrays of a pass end to end: the only one itself (the model made it for this pass alone)."""
    return arrays[0] if len(arrays) == 1 else np.concatenate(arrays, axis=axis)


def _truth(part: ModelOutput) -> tuple[int, np.ndarray]:
    """The truth of an advance of a model that gives it (every advance does when the first does)."""
    assert part.truth is not None
    return part.truth


def _cuts(bounds: list[tuple[int, int]], rate: Fraction) -> list[int]:
    """``samples_before(b, rate)`` of each boundary ``b``, given as its integer ratio."""
    rate_num, rate_den = rate.as_integer_ratio()
    return [samples_before_ratio(num, den, rate_num, rate_den) for num, den in bounds]


def _split_index(first: int, n: int, cuts: list[int]) -> list[tuple[int, int]]:
    """Column ranges of ``n`` samples starting at index ``first`` cut before the indices ``cuts``."""
    ranges = []
    lo = 0
    for cut in cuts:
        hi = min(max(cut - first, lo), n)
        ranges.append((lo, hi))
        lo = hi
    return ranges


def _check_frequency(frequency_hz: Any, ramp_rate: Any, max_frequency: float) -> None:
    for name, value in (("frequency_hz", frequency_hz), ("ramp_rate", ramp_rate)):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CommandError(f"{name} = {value!r} refused: must be a number")
        if not np.isfinite(value):
            raise CommandError(f"{name} = {value!r} refused: must be finite")
        if value < 0:
            raise CommandError(f"{name} = {value!r} refused: must be >= 0")
    if frequency_hz > max_frequency:
        raise CommandError(f"frequency_hz = {frequency_hz!r} refused: above motor.max_frequency = {max_frequency:g} Hz")
