"""The rig model as a streaming integrator: advance in simulation time, get exact samples and impacts.

:class:`RigModel` owns the state of one trajectory of the model the configuration selects
(``structure.model``: the paper's model or the structural one, docs/physics.md) and its compiled driver
(:mod:`rimd_sim.model.kernel`). It knows nothing of noise or ROS: it returns noise-free physical quantities on
exact sample grids (sample ``n`` of a channel at ``n / rate`` seconds of simulation time), the impacts
completed so far, stroboscopic (Poincare) points and the motor state.

The models are data: :data:`MODELS` is the one place that picks one. Each entry names the physics module
(the contract of :mod:`rimd_sim.model.kernel`) the driver is built from, once per model and process, at its
first use. ``RigModel``, the simulator, the ensemble of the maps and every analysis look the model up there.

Commands act *now*, at the model's current time :attr:`RigModel.time`: the current integration step is
ended exactly there (see :func:`~rimd_sim.model.kernel.truncate`).
:class:`~rimd_sim.instruments.rig_simulator.RigSimulator` schedules commands at stated simulation times on top of this.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from functools import cache
from types import ModuleType
from typing import NamedTuple

import numpy as np

import rimd_sim.model.kernel as k
import rimd_sim.model.rigid as rigid
import rimd_sim.model.structural as structural
from rimd_sim.errors import CommandError, ConfigError, IntegrationError
from rimd_sim.settings.config import CHANNEL_NAMES, STRUCTURE_MODELS, SimConfig

__all__ = [
    "MODELS", "ChatteringError", "Impact", "ModelOutput", "MotorState", "PhysicsModel", "RigModel", "StroboPoint",
    "as_time", "model_for", "samples_before", "samples_before_ratio",
]

#: Channel name -> quantity computed by the kernel.
CHANNEL_QUANTITY = {
    "cart_displacement": k.Q_CART,
    "rimd_displacement": k.Q_RIMD,
    "rimd_acceleration": k.Q_ACC,
    "impact_force": k.Q_FORCE,
}

#: Names of the rows of a truth block (:attr:`ModelOutput.truth`).
TRUTH_FIELDS = (
    "theta", "theta_dot", "cart_position", "rimd_position", "rimd_velocity", "rimd_acceleration",
    "penetration", "contact_force", "motor_phase", "motor_frequency", "in_contact",
)


class Impact(NamedTuple):
    """One completed impact: from ``delta`` rising through 0 until it falls back through 0.

    Attributes:
        t_start: Contact start (s, simulation time).
        duration: Time from contact start to the last instant the force vanished (s).
        peak_force: Largest contact force (N).
        impulse: Integral of the contact force (N s).
        impact_velocity: Relative velocity ``delta_dot`` at contact start (m/s).
        max_penetration: Largest ``delta`` (m).
        excitation_frequency: Motor frequency at contact start (Hz).
        excitation_phase: Motor phase at contact start (rad, in [0, 2 pi)).
        cycle_index: Excitation cycle (motor turn) in which the contact started.
        index: Running number of the impact since the model started.
        t_end: Time ``delta`` returned below 0 (s).
        contacts: Number of contact intervals in the impact (more than 1 after a dashpot release and
            re-contact).
    """

    t_start: float
    duration: float
    peak_force: float
    impulse: float
    impact_velocity: float
    max_penetration: float
    excitation_frequency: float
    excitation_phase: float
    cycle_index: int
    index: int  # type: ignore[assignment]  # the field's name shadows tuple.index on purpose (impact.index)
    t_end: float
    contacts: int


class StroboPoint(NamedTuple):
    """State when the motor phase crosses a multiple of 2 pi (the cart at 0, moving forward).

    ``modes`` holds the model's own modes at that instant (the two-mass model's ``u, u', s, s'``; none for the
    paper's model), so that a trajectory can be started again from the whole state (``RigModel(...,
    initial_modes=...)``).
    """

    t: float
    theta: float
    theta_dot: float
    cycle_index: int
    modes: tuple[float, ...] = ()


class MotorState(NamedTuple):
    """Motor state at an instant."""

    t: float
    frequency_setpoint: float
    frequency: float
    ramp_rate: float
    phase: float
    cycle_index: int
    cart_position: float


@dataclass
class ModelOutput:
    """What one :meth:`RigModel.advance` produced.

    Attributes:
        t_start: Simulation time the call started from (s).
        t_stop: Simulation time reached (s).
        channels: Channel name -> ``(first_index, samples)`` of noise-free values.
        truth: ``(first_index, array of shape (11, n))``, rows in :data:`TRUTH_FIELDS` order, or None.
        impacts: Impacts completed in ``[t_start, t_stop)``.
        strobe: Stroboscopic points in ``[t_start, t_stop)``.
        max_abs_theta: Largest ``|theta|`` (rad) at the ends of the integration steps of the call (the current
            step's end when it started included): the valid domain's ``pendulum_angle``
            (:mod:`rimd_sim.model.validity`).
    """

    t_start: float
    t_stop: float
    channels: dict[str, tuple[int, np.ndarray]]
    truth: tuple[int, np.ndarray] | None
    impacts: list[Impact]
    strobe: list[StroboPoint]
    max_abs_theta: float = math.nan


def samples_before(t: Fraction, rate: Fraction) -> int:
    """Number of samples ``n >= 0`` with ``n / rate < t`` (exact rational arithmetic)."""
    return samples_before_ratio(*t.as_integer_ratio(), *rate.as_integer_ratio())


def samples_before_ratio(t_num: int, t_den: int, rate_num: int, rate_den: int) -> int:
    """:func:`samples_before` of ``t = t_num / t_den`` and ``rate = rate_num / rate_den`` (positive denominators).

    For the callers that hold the integers already: a Fraction's numerator and denominator are properties, and
    the pacing loop asks for a dozen of these per pass.
    """
    num = t_num * rate_num
    if num <= 0:
        return 0
    return -((-num) // (t_den * rate_den))


def as_time(x: float | int | Fraction) -> Fraction:
    """A time in seconds as an exact fraction.

    A float is read as the decimal it prints as (0.1 is 1/10, not the binary 0.1000000000000000055...), so
    sample counts are what a user expects.
    """
    if isinstance(x, Fraction):
        return x
    if isinstance(x, float):  # numpy floats included
        if not math.isfinite(x):
            raise CommandError(f"time {x!r} refused: must be finite")
        return Fraction(repr(float(x)))
    return Fraction(int(x))


@dataclass(frozen=True)
class PhysicsModel:
    """One model of the hammer and its stop: an entry of :data:`MODELS`.

    Attributes:
        name: The ``structure.model`` value that selects it.
        summary: What it is, in words.
        physics: Its physics module (the contract of :mod:`rimd_sim.model.kernel`).
        sources: Further modules the physics compiles in (part of the compiled driver's cache key).
        capture: Whether the triggered capture (``capture.*``) can run on it.
    """

    name: str
    summary: str
    physics: ModuleType
    sources: tuple[ModuleType, ...] = ()
    capture: bool = True

    @property
    def n_state(self) -> int:
        """Components of the integrated state: ``theta``, ``theta_dot``, ``J`` and the model's modes."""
        return 3 + self.physics.N_MODES

    @property
    def n_modes(self) -> int:
        """The model's own modes (a stroboscopic point carries them)."""
        return self.physics.N_MODES

    @property
    def hammer_modes(self) -> tuple[int, ...]:
        """State indices a reset of the hammer puts at rest, beyond ``theta`` and ``theta_dot``."""
        return tuple(self.physics.HAMMER_MODES)

    def params(self, config: SimConfig) -> np.ndarray:
        """The parameter vector of ``config`` for this model's driver."""
        return self.physics.params(config)

    @property
    def driver(self) -> ModuleType:
        """The compiled driver (:func:`rimd_sim.model.kernel.build_driver`), built at the first use."""
        return _driver(self.name)


#: The registry of models: ``structure.model`` -> :class:`PhysicsModel`.
MODELS: dict[str, PhysicsModel] = {m.name: m for m in (
    PhysicsModel("rigid", "the paper's model: one rigid hammer against a rigid force sensor", rigid),
    PhysicsModel("two_mass", "the hammer as two masses joined by its axial stiffness, the force sensor on a "
                 "compliant mount (docs/physics.md, Structural model)", structural, sources=(rigid,),
                 # The capture samples the acceleration in contact only; this model's rings after it.
                 capture=False),
)}
assert tuple(MODELS) == STRUCTURE_MODELS, "every structure.model value has its entry in MODELS"


@cache
def _driver(name: str) -> ModuleType:
    spec = MODELS[name]
    return k.build_driver(spec.physics, name, spec.sources)


class ChatteringError(IntegrationError):
    """The integrator's chattering guard fired: a Zeno accumulation of contact switches.

    The valid domain's ``chattering`` rule (:mod:`rimd_sim.model.validity`).

    Attributes:
        t: Simulation time (s) where the guard fired (None when not given).
    """

    def __init__(self, message: str, t: float | None = None):
        super().__init__(message)
        self.t = t


def model_for(config: SimConfig) -> PhysicsModel:
    """The model ``config`` selects (``structure.model``).

    Args:
        config: The configuration.

    Returns:
        Its entry of :data:`MODELS`.
    """
    return MODELS[config.rig.structure.model]


_STATUS_MESSAGES = {
    k.ST_STEP_UNDERFLOW: "step size underflow: the integrator cannot make progress",
    k.ST_ZENO: (f"chattering contact: more than {k.ZENO_MAX_EVENTS} switches within {k.ZENO_WINDOW * 1e3:g} ms"
                " (Zeno behaviour); check the contact parameters"),
    k.ST_NONFINITE: "the state became non-finite (NaN or infinity)",
}


class RigModel:
    """One trajectory of the rig model ``config`` selects (:data:`MODELS`), advanced in simulation time.

    Args:
        config: The validated configuration; its rig (the model included), motor, integrator, channel rates,
            truth rate and initial state are used.
        channels: Produce the four DAQ channels (noise-free).
        truth: Produce the ground-truth block.
        strobe: Produce stroboscopic (Poincare) points.
        extra_channels: ``(name, rate, like)``: further channels (the triggered capture's fast signals).
        initial_modes: The model's modes at the start (default: at rest), as a stroboscopic point holds them.

    Example:
        >>> from rimd_sim.model.rig_model import RigModel, SimConfig
        >>> cfg = SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
        >>> model = RigModel(cfg, channels=False, truth=False)
        >>> out = model.advance(10.0)
        >>> len(out.impacts) > 0
        True
    """

    def __init__(self, config: SimConfig, *, channels: bool = True, truth: bool = True, strobe: bool = False,
                 extra_channels: tuple[tuple[str, Fraction, str], ...] = (), initial_modes=()):
        self._config = config
        self._physics = model_for(config)
        self._kernel = self._physics.driver
        if len(initial_modes) not in (0, self._physics.n_modes):
            raise ConfigError("initial_modes", tuple(initial_modes), f"the {self._physics.name} model has "
                              f"{self._physics.n_modes} modes")
        n_state = self._physics.n_state
        self._p = self._physics.params(config)
        self._fs = np.zeros(k.N_FSTATE)
        self._is = np.zeros(k.N_ISTATE, dtype=np.int64)
        self._ya = np.zeros(n_state)
        self._yb = np.zeros(n_state)
        self._fa = np.zeros(n_state)
        self._Q = np.zeros((n_state, 4))
        self._initial_modes = tuple(float(m) for m in initial_modes)
        self._time = Fraction(0)
        self._want_channels = channels
        self._want_truth = truth
        self._want_strobe = strobe
        self._rates = [Fraction(ch.sample_rate) for ch in config.channels] if channels else []
        qty = [CHANNEL_QUANTITY[ch.name] for ch in config.channels][: len(self._rates)]
        self._names = list(CHANNEL_NAMES[: len(self._rates)])
        # Extra channels (name, rate, quantity of the channel named): the triggered capture's fast signals.
        for name, rate, like in extra_channels:
            self._names.append(name)
            self._rates.append(Fraction(rate))
            qty.append(k.Q_ACC_CONTACT if like == "rimd_acceleration_in_contact" else CHANNEL_QUANTITY[like])
        self._ch_rate = np.array([float(r) for r in self._rates], dtype=np.float64)
        self._ch_qty = np.array(qty, dtype=np.int64)
        self._ch_next = np.zeros(len(self._rates), dtype=np.int64)
        self._truth_rate = Fraction(config.truth_rate)
        # The rates as integer pairs, for samples_before_ratio at every advance.
        self._rate_ratios = [r.as_integer_ratio() for r in self._rates]
        self._truth_ratio = self._truth_rate.as_integer_ratio()
        self._tr_next = np.zeros(1, dtype=np.int64)
        self._seg_prev: tuple[np.ndarray, int] | None = None
        self._init_state()

    def __deepcopy__(self, memo: dict) -> RigModel:
        """An independent copy that continues exactly as this model would (a trial run from the same state).

        The physics (its module and compiled driver) is shared: it holds no state of a run.
        """
        import copy

        clone = object.__new__(type(self))
        memo[id(self)] = clone
        for key, value in self.__dict__.items():
            shared = isinstance(value, ModuleType | PhysicsModel | SimConfig)
            setattr(clone, key, value if shared else copy.deepcopy(value, memo))
        return clone

    # ---- state -----------------------------------------------------------------------------------

    def _init_state(self) -> None:
        cfg = self._config
        fs, ist = self._fs, self._is
        fs[:] = 0.0
        ist[:] = 0
        self._ya[:] = 0.0
        self._ya[:3] = (cfg.initial_theta, cfg.initial_theta_dot, 0.0)
        if self._initial_modes:
            self._ya[3:] = self._initial_modes
        self._yb[:] = self._ya
        fs[k.F_H] = min(1e-4, cfg.integrator.max_step)
        fs[k.F_HFREE] = cfg.integrator.max_step
        fs[k.F_HCONT] = self._p[k.P_HCONT0]
        fs[k.F_VIMP] = self._p[k.P_VMIN]
        fs[k.F_ZT0] = -1.0
        fs[k.F_MW0] = cfg.motor.initial_frequency
        fs[k.F_MWSET] = fs[k.F_MW0]
        fs[k.F_MTEND] = np.inf
        ist[k.I_MODE] = k.FREE
        ist[k.I_NEEDF] = 1
        if cfg.motor.initial_setpoint != cfg.motor.initial_frequency:
            k.motor_command(fs, ist, 0.0, cfg.motor.initial_setpoint, cfg.motor.ramp_rate)
        ist[k.I_STRK] = 0  # phase starts at 0: the first crossing is at t = 0
        buf = np.zeros((1, k.N_RECORD))
        self._kernel.resync(self._p, fs, ist, self._ya, self._yb, buf)

    @property
    def config(self) -> SimConfig:
        """The configuration in force."""
        return self._config

    @property
    def physics_model(self) -> PhysicsModel:
        """The model integrated (the entry of :data:`MODELS` the configuration selects)."""
        return self._physics

    @property
    def time(self) -> Fraction:
        """Simulation time reached (s), exact."""
        return self._time

    @property
    def in_contact(self) -> bool:
        """Whether the hammer is in contact with the force sensor now."""
        return bool(self._is[k.I_MODE] == k.CONTACT)

    @property
    def stats(self) -> dict[str, int]:
        """Counters: accepted steps, rejected steps, switches, impacts."""
        return {
            "steps": int(self._is[k.I_NSTEP]),
            "rejected": int(self._is[k.I_NREJ]),
            "switches": int(self._is[k.I_NEV]),
            "impacts": int(self._is[k.I_NIMP]),
        }

    def motor_state(self, t: float | None = None) -> MotorState:
        """Motor state at ``t`` (default: now).

        ``t`` may lie anywhere in the span of the last :meth:`advance` call: the motor segment in force when
        that call started is kept, and within one call the segment changes at most once without a command
        (the end of a ramp).
        """
        fs = self._fs
        cycles = int(self._is[k.I_CYC])
        t = float(self._time) if t is None else t
        if t < fs[k.F_MT0] and self._seg_prev is not None:
            fs = fs.copy()
            fs[k.F_MT0:k.F_MWSET + 1] = self._seg_prev[0]
            cycles = self._seg_prev[1]
        phi = float(k.motor_phase(fs, t))
        turns = math.floor(phi)
        return MotorState(
            t=t,
            # During a slip's sag the kernel ramps to the sag's bottom: the setpoint is the one it returns to.
            frequency_setpoint=float(fs[k.F_SLIPBACK] if fs[k.F_SLIPBACK] > 0.0 else fs[k.F_MWSET]),
            frequency=float(k.motor_freq(fs, t)),
            ramp_rate=float(abs(fs[k.F_MALPHA])) if t < fs[k.F_MTEND] else 0.0,
            phase=2.0 * math.pi * (phi - turns),
            cycle_index=cycles + turns,
            cart_position=self._config.rig.amplitude * math.sin(2.0 * math.pi * phi),
        )

    # ---- integration -----------------------------------------------------------------------------

    def advance(self, t_stop: float | Fraction) -> ModelOutput:
        """Integrate to ``t_stop`` (s) and return what happened in ``[time, t_stop)``.

        Args:
            t_stop: Simulation time to reach (s).

        Returns:
            The channels, truth, impacts and stroboscopic points of ``[time, t_stop)``.

        Raises:
            CommandError: If ``t_stop`` is before the current time.
            IntegrationError: If the integrator cannot continue (the message says why).
        """
        t_stop = as_time(t_stop)
        if t_stop < self._time:
            raise CommandError(
                f"cannot advance to t = {float(t_stop)} s: the model is already at {float(self._time)} s")
        t_start = self._time
        self._seg_prev = (self._fs[k.F_MT0:k.F_MWSET + 1].copy(), int(self._is[k.I_CYC]))
        t_num, t_den = t_stop.as_integer_ratio()
        stop_list = [samples_before_ratio(t_num, t_den, *r) for r in self._rate_ratios]
        stops = np.array(stop_list, dtype=np.int64)
        first = self._ch_next.copy()
        ch_out = np.empty((len(stop_list), max((s - f for s, f in zip(stop_list, first.tolist(), strict=True)),
                                               default=0)))
        if self._want_truth:
            tr_stop = np.array([samples_before_ratio(t_num, t_den, *self._truth_ratio)], dtype=np.int64)
        else:
            tr_stop = self._tr_next.copy()
        tr_first = int(self._tr_next[0])
        tr_out = np.empty((k.N_TRUTH, int(tr_stop[0]) - tr_first))
        impacts: list[Impact] = []
        strobe: list[StroboPoint] = []
        imp_out = np.empty((64, k.N_RECORD))
        if self._want_strobe:
            cycles = float(t_stop - t_start) * max(self._fs[k.F_MW0], self._fs[k.F_MWSET])
            st_out = np.empty((int(min(cycles, 1e5)) + 8, k.N_STROBE + self._physics.n_modes))
        else:
            st_out = np.empty((0, k.N_STROBE + self._physics.n_modes))
        tr_base = np.array([tr_first], dtype=np.int64)
        self._fs[k.F_THMAX] = abs(self._yb[0])
        while True:
            self._is[k.I_IMPOUT] = 0
            self._is[k.I_STROUT] = 0
            status = self._kernel.advance(self._p, self._fs, self._is, self._ya, self._yb, self._fa, self._Q,
                                          float(t_stop), self._ch_rate, self._ch_qty, self._ch_next, stops, first,
                                          ch_out, float(self._truth_rate), self._tr_next, tr_stop, tr_base, tr_out,
                                          imp_out, st_out)
            n_imp, n_st = int(self._is[k.I_IMPOUT]), int(self._is[k.I_STROUT])
            if n_imp:
                impacts.extend(Impact(*_record(row)) for row in imp_out[:n_imp])
            if n_st:
                strobe.extend(StroboPoint(float(r[k.S_T]), float(r[k.S_THETA]), float(r[k.S_OMEGA]),
                                          int(r[k.S_CYCLE]), tuple(r[k.S_MODES:].tolist()))
                              for r in st_out[:n_st])
            if status == k.ST_OK:
                break
            if status == k.ST_IMPACTS_FULL:
                imp_out = np.empty((imp_out.shape[0] * 2, k.N_RECORD))
                continue
            if status == k.ST_STROBE_FULL:
                continue
            message = f"at t = {self._fs[k.F_TB]:.9f} s: {_STATUS_MESSAGES[status]}"
            if status == k.ST_ZENO:
                raise ChatteringError(message, float(self._fs[k.F_TB]))
            raise IntegrationError(message)
        self._time = t_stop
        channels = {
            name: (int(first[i]), ch_out[i, : int(stops[i] - first[i])].copy())
            for i, name in enumerate(self._names)
        }
        truth = (tr_first, tr_out) if self._want_truth else None
        return ModelOutput(float(t_start), float(t_stop), channels, truth, impacts, strobe,
                           float(self._fs[k.F_THMAX]))

    # ---- commands (act now) ----------------------------------------------------------------------

    def _truncate(self) -> list[Impact]:
        """End the current step at the current time; returns an impact completed exactly now, if any."""
        buf = np.empty((2, k.N_RECORD))
        self._is[k.I_IMPOUT] = 0
        if not self._kernel.truncate(self._p, self._fs, self._is, self._ya, self._yb, self._fa, self._Q,
                                     float(self._time), buf):
            raise ChatteringError(f"at t = {float(self._time):.9f} s: {_STATUS_MESSAGES[k.ST_ZENO]}", float(self._time))
        return [Impact(*_record(r)) for r in buf[: self._is[k.I_IMPOUT]]]

    def _resync(self) -> list[Impact]:
        buf = np.empty((2, k.N_RECORD))
        self._is[k.I_IMPOUT] = 0
        self._kernel.resync(self._p, self._fs, self._is, self._ya, self._yb, buf)
        return [Impact(*_record(r)) for r in buf[: self._is[k.I_IMPOUT]]]

    def set_motor_frequency(self, frequency_hz: float, ramp_rate: float | None = None) -> list[Impact]:
        """Set the motor setpoint now; the frequency ramps to it at ``ramp_rate`` (Hz/s).

        Args:
            frequency_hz: New setpoint (Hz), finite, >= 0 and <= ``motor.max_frequency``. 0 stops the cart.
            ramp_rate: Hz/s, finite and > 0; None or 0 for the configured ``motor.ramp_rate``. ``inf`` is
                refused: the motor cannot jump.

        Returns:
            Impacts that completed exactly at this instant (rare), so none is lost.

        Raises:
            CommandError: For a refused value; the model is unchanged.
        """
        motor = self._config.motor
        if not isinstance(frequency_hz, (int, float)) or not math.isfinite(frequency_hz):
            raise CommandError(f"frequency_hz = {frequency_hz!r} refused: must be a finite number")
        if frequency_hz < 0.0:
            raise CommandError(f"frequency_hz = {frequency_hz!r} refused: must be >= 0 Hz")
        if frequency_hz > motor.max_frequency:
            raise CommandError(f"frequency_hz = {frequency_hz!r} refused: above motor.max_frequency = "
                               f"{motor.max_frequency:g} Hz")
        if ramp_rate is None or ramp_rate == 0.0:
            ramp_rate = motor.ramp_rate
        if not isinstance(ramp_rate, (int, float)) or not math.isfinite(ramp_rate) or ramp_rate < 0.0:
            raise CommandError(f"ramp_rate = {ramp_rate!r} refused: must be finite and >= 0 Hz/s (0 = default)")
        done = self._truncate()
        k.motor_command(self._fs, self._is, float(self._time), float(frequency_hz), float(ramp_rate))
        return done

    @property
    def motor_slipping(self) -> bool:
        """A ``motor_slip`` is in force or a sag is in progress.

        The motor segment may then change several times within one :meth:`advance` call, so
        :meth:`motor_state` is exact only at the end of the call.
        """
        return bool(self._fs[k.F_SLIP] > 0.0 or self._fs[k.F_SLIPBACK] > 0.0)

    def set_motor_slip(self, fraction: float) -> list[Impact]:
        """From now on, the motor loses ``fraction`` of its frequency at each contact onset (0 = no more).

        The fault ``motor_slip`` (:mod:`rimd_sim.instruments.faults`): at each contact onset the frequency falls
        linearly by that fraction over ``SLIP_TIME`` (2 ms), then ramps back to its setpoint at
        ``motor.ramp_rate``. A sag in progress when the slip ends still ramps back. A new motor setpoint ends
        the way back of a sag (the command wins).

        Raises:
            CommandError: For a fraction outside [0, 1].
        """
        if not isinstance(fraction, (int, float)) or not 0.0 <= fraction <= 1.0:
            raise CommandError(f"fraction = {fraction!r} refused: must be a fraction within [0, 1]")
        done = self._truncate()
        self._fs[k.F_SLIP] = float(fraction)
        self._fs[k.F_SLIPRATE] = self._config.motor.ramp_rate
        return done + self._resync()

    def perturb(self, velocity: float) -> list[Impact]:
        """Add ``velocity`` (m/s, inertial, along the impact line) to the hammer now.

        Reproduces the paper's "energy inserted into the system" experiment (Fig. 12 right).

        Raises:
            CommandError: For a non-finite value or one above 10 m/s in magnitude.
        """
        if not isinstance(velocity, (int, float)) or not math.isfinite(velocity):
            raise CommandError(f"velocity = {velocity!r} refused: must be a finite number")
        if abs(velocity) > 10.0:
            raise CommandError(f"velocity = {velocity!r} refused: must be within +-10 m/s")
        done = self._truncate()
        theta = self._ya[0]
        self._ya[1] += velocity / (self._config.rig.length * math.cos(theta))
        return done + self._resync()

    def reset_hammer(self) -> list[Impact]:
        """Put the hammer back to its initial state now, its own modes at rest.

        The motor keeps running (and the two-mass model's sensor keeps ringing).
        """
        done = self._truncate()
        self._ya[0] = self._config.initial_theta
        self._ya[1] = self._config.initial_theta_dot
        for i in self._physics.hammer_modes:
            self._ya[i] = 0.0
        return done + self._resync()

    def reconfigure(self, config: SimConfig) -> list[Impact]:
        """Change the rig, motor limits and integrator settings now; the state (theta, theta_dot) is kept.

        Channel and truth sample rates cannot change on a running model (create a new one).

        Raises:
            CommandError: If a sample rate or the model (``structure.model``) differs.
        """
        old = self._config
        if [c.sample_rate for c in config.channels] != [c.sample_rate for c in old.channels] or \
                config.truth_rate != old.truth_rate:
            raise CommandError("sample rates cannot change while the model runs; restart it with the new rates")
        if model_for(config) is not self._physics:
            raise CommandError(f"structure.model cannot change while the model runs ({self._physics.name} to "
                               f"{config.rig.structure.model}); create a new one")
        done = self._truncate()
        self._config = config
        self._p = self._physics.params(config)
        return done + self._resync()


def _record(row: np.ndarray) -> tuple:
    r = row.tolist()
    r[k.R_CYCLE] = int(r[k.R_CYCLE])
    r[k.R_INDEX] = int(r[k.R_INDEX])
    r[k.R_NCONTACT] = int(r[k.R_NCONTACT])
    return tuple(r)
