"""Configuration of the rig: one source of truth for the core and the ROS nodes.

The configuration is read from the same ROS 2 parameter YAML the simulator node reads::

    /**/rimd_simulator:
      ros__parameters:
        gap: 0.0
        contact:
          model: spring_dashpot
        ...

Nested mappings are flattened to the dotted ROS parameter names (``contact.model``). Every value is
validated when it is set: a refused value raises :class:`~rimd_sim.core.errors.ConfigError` naming the
key, the value and the rule. The result is a tree of frozen dataclasses (:class:`SimConfig`) whose field
values are SI (m, kg, s, Hz, N).

Defaults are the paper's identified values (Table 2, section 3: ``k = 5.5e6 N/m``, ``c = 1.2e3 N s/m``,
``A0 = 1 mm``, natural frequency 1.82 Hz) plus two values the paper does not give: the hammer mass 0.15 kg
and the structural damping ratio 0.08, chosen so that the model reproduces Table 1 (see README).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .contact import CONTACT_LAWS
from .errors import ConfigError

__all__ = [
    "CHANNEL_NAMES",
    "ChannelConfig",
    "ContactParams",
    "IntegratorParams",
    "MotorParams",
    "RigParams",
    "SimConfig",
    "StructureParams",
    "find_config_file",
    "flatten_parameters",
    "load_config",
    "misapplied_section",
    "misapplied_section_message",
    "read_ros_parameters",
]

#: Node name whose ``ros__parameters`` section holds the rig configuration.
NODE_NAME = "rimd_simulator"

#: Parameters of the simulator node's own (read at start by the node, not part of the model's configuration),
#: besides ``capture.*`` (rimd_sim.core.capture).
NODE_PARAMETERS = frozenset({"start_paused", "faults"})

#: The four DAQ channels, in publication order.
CHANNEL_NAMES = ("cart_displacement", "rimd_displacement", "rimd_acceleration", "impact_force")


@dataclass(frozen=True)
class ContactParams:
    """Contact law between the hammer and the force sensor (paper Eq. 1).

    Attributes:
        model: Name in :data:`~rimd_sim.core.contact.CONTACT_LAWS`.
        stiffness: ``k`` (N/m for the spring-dashpot; N/m^n for the others).
        damping: ``c`` (N s/m for the spring-dashpot; N s/m^(n+1) for Hunt-Crossley).
        exponent: ``n`` of the Hertz-type laws (ignored by the spring-dashpot law).
        restitution: ``e`` of the Lankarani-Nikravesh law.
        min_impact_velocity: Floor (m/s) on the impact velocity that divides the Lankarani-Nikravesh
            damping term, so that a contact starting at rest has finite damping. Assumption.
    """

    model: str = "spring_dashpot"
    stiffness: float = 5.5e6
    damping: float = 1.2e3
    exponent: float = 1.5
    restitution: float = 0.8
    min_impact_velocity: float = 1e-3


@dataclass(frozen=True)
class StructureParams:
    """Optional structural contact model (issue 15, docs/physics.md "Structural model").

    ``model = "rigid"`` is the paper's single-mass hammer (the default). ``"two_mass"`` splits the hammer
    into the impact device (front, ``impactor_mass``) and the aluminium coupling that carries the
    accelerometer (rear, the rest of ``mass``), joined by the hammer's axial stiffness and damping, and puts
    the force sensor's top (``sensor_mass``) on a compliant mount. A stiffness of 0 means rigid.

    Attributes:
        model: ``rigid`` or ``two_mass``.
        impactor_mass: Front mass (kg), less than ``mass``.
        axial_stiffness: Axial stiffness of the hammer between its two masses (N/m); 0 = rigid link.
        axial_damping_ratio: Damping ratio of the hammer's axial mode (< 1).
        sensor_mass: Moving mass of the force sensor's top and impact cap (kg).
        mount_stiffness: Stiffness of the force sensor and its mount on the cart (N/m); 0 = rigid mount.
        mount_damping_ratio: Damping ratio of the sensor-on-mount mode (< 1).
    """

    model: str = "rigid"
    impactor_mass: float = 0.06
    axial_stiffness: float = 0.0
    axial_damping_ratio: float = 0.05
    sensor_mass: float = 0.01
    mount_stiffness: float = 0.0
    mount_damping_ratio: float = 0.05


#: Names of the contact models (``structure.model``).
STRUCTURE_MODELS = ("rigid", "two_mass")


@dataclass(frozen=True)
class RigParams:
    """Mechanical parameters of the RIMD on its cart (SI units).

    Attributes:
        gap: Distance (m) between the hammer at rest and the force sensor.
        mass: Hammer (RIMD) mass ``m`` in kg. Not in the paper: 0.15 kg reproduces Table 1.
        amplitude: Cart displacement amplitude ``A0`` (m).
        natural_frequency: Pendulum natural frequency without impact (Hz); sets ``l = g / (2 pi f)^2``.
        damping_ratio: Structural damping ratio of the pendulum (not in the paper's model).
        gravity: ``g`` in m/s^2.
        contact: The contact law.
    """

    gap: float = 0.0
    mass: float = 0.15
    amplitude: float = 1e-3
    natural_frequency: float = 1.82
    damping_ratio: float = 0.08
    gravity: float = 9.81
    contact: ContactParams = field(default_factory=ContactParams)
    structure: StructureParams = field(default_factory=StructureParams)

    @property
    def length(self) -> float:
        """Equivalent pendulum length ``l = g / (2 pi f_n)^2`` in m."""
        return self.gravity / (2.0 * math.pi * self.natural_frequency) ** 2

    @property
    def omega_n(self) -> float:
        """Natural angular frequency ``2 pi f_n`` in rad/s."""
        return 2.0 * math.pi * self.natural_frequency


@dataclass(frozen=True)
class MotorParams:
    """The AC motor that shakes the cart.

    Attributes:
        max_frequency: Highest setpoint accepted (Hz).
        ramp_rate: Default ramp rate of the frequency towards a new setpoint (Hz/s).
        initial_frequency: Frequency at simulation start (Hz), reached without a ramp.
        initial_setpoint: Setpoint at simulation start (Hz); the motor ramps to it from
            ``initial_frequency``.
    """

    max_frequency: float = 12.0
    ramp_rate: float = 2.0
    initial_frequency: float = 0.0
    initial_setpoint: float = 3.75


@dataclass(frozen=True)
class IntegratorParams:
    """Adaptive Dormand-Prince 5(4) integrator settings.

    Attributes:
        rtol: Relative tolerance of the local error.
        atol: Absolute tolerance (rad for theta, rad/s for theta_dot).
        max_step: Largest step (s).
        event_tolerance: Tolerance (s) of the switch-time root finding on the dense output.
    """

    rtol: float = 1e-7
    atol: float = 1e-9
    max_step: float = 1e-2
    event_tolerance: float = 1e-12


@dataclass(frozen=True)
class ChannelConfig:
    """One DAQ channel: an instrument sampled at a fixed rate.

    Attributes:
        name: Channel name, one of :data:`CHANNEL_NAMES`.
        sample_rate: Samples per second (Hz).
        range_min: Lower end of the instrument's measuring range (SI); readings are clipped to it.
        range_max: Upper end of the measuring range (SI).
        noise_std: Standard deviation of the additive white noise (SI), when noise is enabled.
        resolution: Quantisation step of the reading (SI), 0 for none.
        bandwidth: -3 dB frequency (Hz) of the instrument's 2nd-order low-pass, 0 for none. A value at or
            above 0.45 x sample_rate cannot be represented at that rate and has no effect.
        highpass: -3 dB frequency (Hz) of the 1st-order high-pass of AC-coupled (piezoelectric)
            instruments, 0 for DC-coupled.
        reliable: Publish with reliable QoS (default) or best effort.
        frame_id: Sensor id placed in ``header.frame_id``.
    """

    name: str
    sample_rate: float
    range_min: float
    range_max: float
    noise_std: float = 0.0
    resolution: float = 0.0
    bandwidth: float = 0.0
    highpass: float = 0.0
    reliable: bool = True
    frame_id: str = ""

    @property
    def unit(self) -> str:
        """SI unit of the channel's samples."""
        return CHANNEL_UNITS[self.name]


CHANNEL_UNITS = {
    "cart_displacement": "m",
    "rimd_displacement": "m",
    "rimd_acceleration": "m/s^2",
    "impact_force": "N",
}

_DEFAULT_CHANNELS = (
    ChannelConfig("cart_displacement", 2000.0, -0.010, 0.010, 2.0e-6, 0.3e-6, 0.0, 0.0, True, "cart_laser"),
    ChannelConfig("rimd_displacement", 2000.0, -0.050, 0.050, 10.0e-6, 1.5e-6, 0.0, 0.0, True, "rimd_laser"),
    ChannelConfig("rimd_acceleration", 20000.0, -4903.0, 4903.0, 0.05, 0.0, 0.0, 0.5, True, "rimd_accelerometer"),
    ChannelConfig("impact_force", 20000.0, -444.8, 2224.0, 0.01, 0.0, 0.0, 0.0, True, "impact_force_sensor"),
)


@dataclass(frozen=True)
class SimConfig:
    """The whole simulator configuration.

    Attributes:
        rig: Mechanical parameters.
        motor: Motor parameters.
        integrator: Integrator settings.
        channels: The four DAQ channels, in :data:`CHANNEL_NAMES` order.
        truth_rate: Sample rate (Hz) of the noise-free ground-truth stream.
        noise_enabled: Add instrument noise (off gives the ideal, quantised, clipped readings).
        seed: Seed of every random stream; same seed and commands give identical data.
        real_time_factor: Pacing of the node (1 = real time, 0 = as fast as possible).
        block_rate: Sample blocks published per second of simulation time.
        initial_theta: Pendulum angle at start (rad).
        initial_theta_dot: Pendulum angular velocity at start (rad/s).
    """

    rig: RigParams = field(default_factory=RigParams)
    motor: MotorParams = field(default_factory=MotorParams)
    integrator: IntegratorParams = field(default_factory=IntegratorParams)
    channels: tuple[ChannelConfig, ...] = _DEFAULT_CHANNELS
    truth_rate: float = 1000.0
    noise_enabled: bool = True
    seed: int = 0
    real_time_factor: float = 1.0
    block_rate: float = 100.0
    initial_theta: float = 0.0
    initial_theta_dot: float = 0.0

    def channel(self, name: str) -> ChannelConfig:
        """Return the channel called ``name``."""
        for ch in self.channels:
            if ch.name == name:
                return ch
        raise KeyError(name)

    def to_parameters(self) -> dict[str, Any]:
        """Return the configuration as flat ROS parameter names and values."""
        return {key: spec.get(self) for key, spec in PARAMETERS.items()}

    def with_parameters(self, overrides: Mapping[str, Any]) -> SimConfig:
        """Return a new validated configuration with some parameters changed.

        Args:
            overrides: Flat ROS parameter names and values, for example ``{"gap": 1e-3}``.

        Raises:
            ConfigError: For an unknown key, a value of the wrong type or out of range, or an
                inconsistent combination.
        """
        values = self.to_parameters()
        for key, value in overrides.items():
            if key not in PARAMETERS:
                raise ConfigError(key, value, "unknown parameter (known: " + ", ".join(PARAMETERS) + ")")
            values[key] = PARAMETERS[key].check(key, value)
        return _build(values)

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> SimConfig:
        """Build a configuration from flat ROS parameters over the defaults (see :meth:`with_parameters`).

        The simulator node's own parameters (:data:`NODE_PARAMETERS`: ``start_paused``, the fault scenario
        ``faults``, the capture's ``capture.*``) may stand in the same file; the node reads and checks them.
        """
        return cls().with_parameters({k: v for k, v in params.items()
                                      if k not in NODE_PARAMETERS and not k.startswith("capture.")})


# --------------------------------------------------------------------------------------------------
# Parameter table: name -> type, rule, getter. The table is what the node declares (with descriptors).
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ParameterSpec:
    """One ROS parameter: its type, its rule in words, how to check it and where it lives.

    Attributes:
        kind: ``float``, ``int``, ``bool`` or ``str``.
        rule: The rule, in words, shown in refusals and descriptors.
        description: What the parameter is, with its unit.
        ok: Predicate on the converted value.
        get: Reads the value from a :class:`SimConfig`.
        low: Lower bound for a ROS range descriptor, if any.
        high: Upper bound for a ROS range descriptor, if any.
        choices: Allowed strings, if any.
    """

    kind: str
    rule: str
    description: str
    ok: Callable[[Any], bool]
    get: Callable[[SimConfig], Any]
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()

    def check(self, key: str, value: Any) -> Any:
        """Convert ``value`` to the parameter's type and check its rule.

        Raises:
            ConfigError: When the type is wrong or the rule is broken.
        """
        if self.kind == "float":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                hint = ""
                if isinstance(value, str):
                    try:
                        float(value)
                        hint = " (YAML read it as text: write exponents with a sign and a dot, e.g. 5.5e+6)"
                    except ValueError:
                        pass
                raise ConfigError(key, value, "must be a number" + hint)
            value = float(value)
            if not math.isfinite(value):
                raise ConfigError(key, value, "must be finite; " + self.rule)
            if value != 0.0 and abs(value) < SMALLEST_NORMAL:
                # A subnormal number has lost its precision, and the kernels' products of such values
                # underflow to 0 (amplitude = 5e-324 divided by zero inside the integrator).
                raise ConfigError(key, value, f"must be 0 or at least {SMALLEST_NORMAL:.3g} in magnitude "
                                              f"(not a subnormal number); {self.rule}")
        elif self.kind == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(key, value, "must be an integer")
        elif self.kind == "bool":
            if not isinstance(value, bool):
                raise ConfigError(key, value, "must be true or false")
        elif self.kind == "str" and not isinstance(value, str):
            raise ConfigError(key, value, "must be a string")
        if not self.ok(value):
            raise ConfigError(key, value, self.rule)
        return value


def _positive(desc: str, get: Callable[[SimConfig], Any], high: float | None = None) -> ParameterSpec:
    if high is None:
        return ParameterSpec("float", "must be > 0", desc, lambda v: v > 0, get, low=0.0)
    return ParameterSpec("float", f"must be > 0 and <= {high:g}", desc, lambda v: 0 < v <= high, get, 0.0, high)


def _nonneg(desc: str, get: Callable[[SimConfig], Any], high: float | None = None) -> ParameterSpec:
    if high is None:
        return ParameterSpec("float", "must be >= 0", desc, lambda v: v >= 0, get, low=0.0)
    return ParameterSpec("float", f"must be >= 0 and <= {high:g}", desc, lambda v: 0 <= v <= high, get, 0.0, high)


def _between(desc: str, get: Callable[[SimConfig], Any], low: float, high: float) -> ParameterSpec:
    return ParameterSpec("float", f"must be >= {low:g} and <= {high:g}", desc, lambda v: low <= v <= high, get,
                         low, high)


def _channel_specs() -> Iterator[tuple[str, ParameterSpec]]:
    for index, name in enumerate(CHANNEL_NAMES):

        def getter(attr: str, i: int = index) -> Callable[[SimConfig], Any]:
            return lambda c: getattr(c.channels[i], attr)

        prefix = f"channels.{name}."
        yield prefix + "sample_rate", _positive("samples per second (Hz)", getter("sample_rate"), 1e6)
        # Upper bounds (here and below): far beyond any instrument or rig, they refuse the absurd (1e300), which
        # was accepted and, for some parameters, stopped or hung the running rig's integrator.
        yield prefix + "range_min", _between("lower end of the measuring range (SI)", getter("range_min"),
                                             -MAX_SI_MAGNITUDE, MAX_SI_MAGNITUDE)
        yield prefix + "range_max", _between("upper end of the measuring range (SI)", getter("range_max"),
                                             -MAX_SI_MAGNITUDE, MAX_SI_MAGNITUDE)
        yield prefix + "noise_std", _nonneg("white noise standard deviation (SI)", getter("noise_std"),
                                            MAX_SI_MAGNITUDE)
        yield prefix + "resolution", _nonneg("quantisation step (SI), 0 = none", getter("resolution"),
                                             MAX_SI_MAGNITUDE)
        yield prefix + "bandwidth", _nonneg("-3 dB low-pass frequency (Hz), 0 = none", getter("bandwidth"), 1e6)
        yield prefix + "highpass", _nonneg("-3 dB high-pass frequency (Hz), 0 = DC-coupled", getter("highpass"))
        yield prefix + "reliable", ParameterSpec(
            "bool", "must be true or false", "reliable QoS (else best effort)", lambda v: True, getter("reliable")
        )
        yield prefix + "frame_id", ParameterSpec(
            "str", "must be a non-empty string without NUL characters (a ROS 2 string is a C string)",
            "sensor id in header.frame_id", lambda v: bool(v) and "\0" not in v, getter("frame_id")
        )


#: Largest magnitude of an instrument's range, noise or resolution (SI units).
MAX_SI_MAGNITUDE = 1e9

#: Largest motor ramp rate (Hz/s), of ``motor.ramp_rate`` and of a ``set_motor_frequency`` request.
MAX_RAMP_RATE = 1e4

#: Smallest positive normal float; smaller non-zero values (subnormal) are refused.
SMALLEST_NORMAL = sys.float_info.min

PARAMETERS: dict[str, ParameterSpec] = {
    "gap": _nonneg("gap between hammer at rest and force sensor (m)", lambda c: c.rig.gap, 0.05),
    # At least 1 g: a lighter hammer (1e-9 kg) made the contact so stiff that the integrator hung.
    "mass": ParameterSpec("float", "must be > 0 and <= 1000 (at least 0.001 kg)", "hammer mass (kg)",
                          lambda v: 1e-3 <= v <= 1000.0, lambda c: c.rig.mass, 1e-3, 1000.0),
    "amplitude": _nonneg("cart displacement amplitude A0 (m)", lambda c: c.rig.amplitude, 0.05),
    "natural_frequency": _positive(
        "pendulum natural frequency without impact (Hz)", lambda c: c.rig.natural_frequency, 1000.0),
    "damping_ratio": _nonneg("structural damping ratio zeta", lambda c: c.rig.damping_ratio, 2.0),
    "gravity": _positive("gravitational acceleration (m/s^2)", lambda c: c.rig.gravity, 100.0),
    "contact.model": ParameterSpec(
        "str",
        "must be one of: " + ", ".join(CONTACT_LAWS),
        "contact law (paper Eq. 1)",
        lambda v: v in CONTACT_LAWS,
        lambda c: c.rig.contact.model,
        choices=tuple(CONTACT_LAWS),
    ),
    # k = 1e300 or c = 1e300 stopped the rig at its first contact (step size underflow, non-finite state); the
    # bounds are well inside what the integrator was checked to handle (k = 1e14, c = 1e7 at the defaults).
    "contact.stiffness": _positive("contact stiffness k (N/m^n)", lambda c: c.rig.contact.stiffness, 1e12),
    "contact.damping": _nonneg(
        "contact damping c (N s/m, N s/m^(n+1) for Hunt-Crossley)", lambda c: c.rig.contact.damping, 1e6),
    "contact.exponent": ParameterSpec(
        "float", "must be >= 1 and <= 3", "exponent n of the Hertz-type laws", lambda v: 1.0 <= v <= 3.0,
        lambda c: c.rig.contact.exponent, 1.0, 3.0,
    ),
    "contact.restitution": ParameterSpec(
        "float", "must be > 0 and <= 1", "restitution e of the Lankarani-Nikravesh law", lambda v: 0 < v <= 1,
        lambda c: c.rig.contact.restitution, 0.0, 1.0,
    ),
    # >= 1e-6 m/s: the floor divides the contact damping, and below ~1e-12 the integrator stalled or hung.
    "contact.min_impact_velocity": _between(
        "floor of the Lankarani-Nikravesh impact velocity (m/s)", lambda c: c.rig.contact.min_impact_velocity,
        1e-6, 10.0),
    # Structural contact model (issue 15). Stiffness 0 = rigid; the upper bounds keep the fast modes within
    # what the integrator resolves affordably (a 1e12 N/m link on 1 g would need sub-ns steps).
    "structure.model": ParameterSpec(
        "str", "must be one of: " + ", ".join(STRUCTURE_MODELS),
        "contact model: rigid (the paper's single-mass hammer) or two_mass (axial mode and sensor mount)",
        lambda v: v in STRUCTURE_MODELS, lambda c: c.rig.structure.model, choices=STRUCTURE_MODELS),
    "structure.impactor_mass": _between(
        "front (impact device) mass of the two-mass hammer (kg), < mass", lambda c: c.rig.structure.impactor_mass,
        1e-3, 1000.0),
    "structure.axial_stiffness": ParameterSpec(
        "float", "must be 0 (rigid) or >= 1000 and <= 1e+10", "axial stiffness of the hammer (N/m), 0 = rigid",
        lambda v: v == 0.0 or 1e3 <= v <= 1e10, lambda c: c.rig.structure.axial_stiffness, 0.0, 1e10),
    "structure.axial_damping_ratio": ParameterSpec(
        "float", "must be >= 0 and < 1", "damping ratio of the hammer's axial mode", lambda v: 0.0 <= v < 1.0,
        lambda c: c.rig.structure.axial_damping_ratio, 0.0, 0.999),
    "structure.sensor_mass": _between(
        "moving mass of the force sensor's top (kg)", lambda c: c.rig.structure.sensor_mass, 1e-4, 10.0),
    "structure.mount_stiffness": ParameterSpec(
        "float", "must be 0 (rigid) or >= 1000 and <= 1e+10", "stiffness of the force sensor on its mount (N/m), "
        "0 = rigid", lambda v: v == 0.0 or 1e3 <= v <= 1e10, lambda c: c.rig.structure.mount_stiffness, 0.0, 1e10),
    "structure.mount_damping_ratio": ParameterSpec(
        "float", "must be >= 0 and < 1", "damping ratio of the sensor-on-mount mode", lambda v: 0.0 <= v < 1.0,
        lambda c: c.rig.structure.mount_damping_ratio, 0.0, 0.999),
    "motor.max_frequency": _positive("highest motor frequency accepted (Hz)", lambda c: c.motor.max_frequency, 1000.0),
    "motor.ramp_rate": _positive("default ramp rate of the motor frequency (Hz/s)", lambda c: c.motor.ramp_rate,
                                 MAX_RAMP_RATE),
    "motor.initial_frequency": _nonneg("motor frequency at start (Hz)", lambda c: c.motor.initial_frequency),
    "motor.initial_setpoint": _nonneg("motor setpoint at start (Hz)", lambda c: c.motor.initial_setpoint),
    "integrator.rtol": ParameterSpec(
        "float", "must be >= 1e-13 and <= 1e-3", "relative tolerance", lambda v: 1e-13 <= v <= 1e-3,
        lambda c: c.integrator.rtol, 1e-13, 1e-3,
    ),
    "integrator.atol": _positive("absolute tolerance (rad, rad/s)", lambda c: c.integrator.atol, 1e-3),
    # >= 1 us: 1e-7 s already took 17 s of CPU per simulated second, smaller values hang the rig.
    "integrator.max_step": _between("largest integration step (s)", lambda c: c.integrator.max_step, 1e-6, 0.05),
    "integrator.event_tolerance": _positive(
        "switch time tolerance (s)", lambda c: c.integrator.event_tolerance, 1e-6
    ),
    "initial.theta": ParameterSpec(
        "float", "must be in [-1.5, 1.5] rad", "pendulum angle at start (rad)", lambda v: abs(v) <= 1.5,
        lambda c: c.initial_theta, -1.5, 1.5,
    ),
    "initial.theta_dot": _between("pendulum angular velocity at start (rad/s)", lambda c: c.initial_theta_dot,
                                  -1000.0, 1000.0),
    "truth.sample_rate": _positive("ground-truth sample rate (Hz)", lambda c: c.truth_rate, 1e6),
    "noise.enabled": ParameterSpec(
        "bool", "must be true or false", "add instrument noise", lambda v: True, lambda c: c.noise_enabled
    ),
    "seed": ParameterSpec(
        "int", "must be >= 0 and < 2**63", "seed of the noise streams", lambda v: 0 <= v < 2**63, lambda c: c.seed,
        0, 2**63 - 1,
    ),
    # 0 or >= 1e-3: a tiny factor (1e-300) put one block a near-infinite wall time away, and the pacing thread
    # died on the wait (OverflowError), leaving the rig silent.
    "real_time_factor": ParameterSpec(
        "float", "must be 0 (as fast as possible) or >= 0.001 and <= 1e+06",
        "pacing: 1 = real time, 0 = as fast as possible", lambda v: v == 0 or 1e-3 <= v <= 1e6,
        lambda c: c.real_time_factor, 0.0, 1e6,
    ),
    # At least 1 block/s: a tiny rate made one block of a near-infinite span, computed at once (memory, time).
    "block_rate": ParameterSpec(
        "float", "must be > 0 and <= 10000 (at least 1: a block spans at most 1 s)",
        "sample blocks per second of simulation time", lambda v: 1.0 <= v <= 10000.0, lambda c: c.block_rate,
        1.0, 10000.0,
    ),
}
PARAMETERS.update(dict(_channel_specs()))


def _build(v: Mapping[str, Any]) -> SimConfig:
    """Assemble a :class:`SimConfig` from checked flat values and check the cross-field rules."""
    contact = ContactParams(
        model=v["contact.model"],
        stiffness=v["contact.stiffness"],
        damping=v["contact.damping"],
        exponent=v["contact.exponent"],
        restitution=v["contact.restitution"],
        min_impact_velocity=v["contact.min_impact_velocity"],
    )
    structure = StructureParams(
        model=v["structure.model"],
        impactor_mass=v["structure.impactor_mass"],
        axial_stiffness=v["structure.axial_stiffness"],
        axial_damping_ratio=v["structure.axial_damping_ratio"],
        sensor_mass=v["structure.sensor_mass"],
        mount_stiffness=v["structure.mount_stiffness"],
        mount_damping_ratio=v["structure.mount_damping_ratio"],
    )
    rig = RigParams(
        gap=v["gap"],
        mass=v["mass"],
        amplitude=v["amplitude"],
        natural_frequency=v["natural_frequency"],
        damping_ratio=v["damping_ratio"],
        gravity=v["gravity"],
        contact=contact,
        structure=structure,
    )
    if structure.model == "two_mass" and structure.axial_stiffness > 0.0 and structure.impactor_mass >= rig.mass:
        raise ConfigError("structure.impactor_mass", structure.impactor_mass,
                          f"must be < mass = {rig.mass:g} kg (the rest of the hammer is the rear mass)")
    if rig.gap >= 0.5 * rig.length:
        raise ConfigError("gap", rig.gap, f"must be < half the pendulum length l/2 = {0.5 * rig.length:.6g} m")
    motor = MotorParams(
        max_frequency=v["motor.max_frequency"],
        ramp_rate=v["motor.ramp_rate"],
        initial_frequency=v["motor.initial_frequency"],
        initial_setpoint=v["motor.initial_setpoint"],
    )
    for key in ("motor.initial_frequency", "motor.initial_setpoint"):
        if v[key] > motor.max_frequency:
            raise ConfigError(key, v[key], f"must be <= motor.max_frequency = {motor.max_frequency:g} Hz")
    integrator = IntegratorParams(
        rtol=v["integrator.rtol"],
        atol=v["integrator.atol"],
        max_step=v["integrator.max_step"],
        event_tolerance=v["integrator.event_tolerance"],
    )
    channels = []
    for name in CHANNEL_NAMES:
        p = f"channels.{name}."
        ch = ChannelConfig(
            name=name,
            sample_rate=v[p + "sample_rate"],
            range_min=v[p + "range_min"],
            range_max=v[p + "range_max"],
            noise_std=v[p + "noise_std"],
            resolution=v[p + "resolution"],
            bandwidth=v[p + "bandwidth"],
            highpass=v[p + "highpass"],
            reliable=v[p + "reliable"],
            frame_id=v[p + "frame_id"],
        )
        if not ch.range_min < ch.range_max:
            raise ConfigError(p + "range_max", ch.range_max, f"must be > {p}range_min = {ch.range_min:g}")
        if ch.highpass > 0 and ch.highpass >= 0.45 * ch.sample_rate:
            raise ConfigError(p + "highpass", ch.highpass,
                              f"must be < 0.45 x sample_rate = {0.45 * ch.sample_rate:g} Hz")
        if ch.highpass > 0 and 0 < ch.bandwidth <= ch.highpass:
            raise ConfigError(p + "bandwidth", ch.bandwidth, f"must be > {p}highpass = {ch.highpass:g} Hz")
        channels.append(ch)
    return SimConfig(
        rig=rig,
        motor=motor,
        integrator=integrator,
        channels=tuple(channels),
        truth_rate=v["truth.sample_rate"],
        noise_enabled=v["noise.enabled"],
        seed=v["seed"],
        real_time_factor=v["real_time_factor"],
        block_rate=v["block_rate"],
        initial_theta=v["initial.theta"],
        initial_theta_dot=v["initial.theta_dot"],
    )


# --------------------------------------------------------------------------------------------------
# YAML
# --------------------------------------------------------------------------------------------------


def flatten_parameters(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Flatten nested parameter mappings to dotted ROS parameter names."""
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten_parameters(value, name + "."))
        else:
            flat[name] = value
    return flat


def read_ros_parameters(path: str | Path, node: str = NODE_NAME) -> dict[str, Any]:
    """Read the flat ``ros__parameters`` of ``node`` from a ROS 2 parameter YAML file.

    Sections named ``node``, ``/node`` and the wildcards ``/**`` and ``/**/node`` (the node in any namespace:
    the form the nodes, in namespace ``/rig``, apply) are merged, the node's own last.

    Raises:
        ConfigError: When the file cannot be read or parsed, or has no section for the node.
    """
    import yaml

    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ConfigError("config file", str(path), f"cannot be read: {exc.strerror}") from exc
    except yaml.YAMLError as exc:
        raise ConfigError("config file", str(path), f"is not valid YAML: {exc}") from exc
    if not isinstance(doc, Mapping):
        raise ConfigError("config file", str(path), "must be a mapping of node names to 'ros__parameters'")
    flat: dict[str, Any] = {}
    found = False
    for section in ("/**", "/**/" + node, node, "/" + node):
        body = doc.get(section)
        if body is None:
            continue
        params = body.get("ros__parameters") if isinstance(body, Mapping) else None
        if not isinstance(params, Mapping):
            raise ConfigError(f"{section}.ros__parameters", params, "must be a mapping")
        flat.update(flatten_parameters(params))
        found = True
    if not found:
        raise ConfigError("config file", str(path), f"has no '{node}: ros__parameters:' section")
    return flat


def misapplied_section(doc: Any, node: str, fqn: str) -> str | None:
    """The key of a section of a parameter-file document meant for ``node`` that ROS does not apply to ``fqn``.

    ROS applies a section to the node whose fully qualified name it matches (``/**``, ``/**/NAME``,
    ``/NS/NAME``); a key without a leading slash is in the root namespace. So a plain ``rimd_simulator:``
    section does not reach the simulator node, which runs in ``/rig``, and ROS says nothing: the node would run
    with its defaults. Keys with wildcards are not judged. Returns the first such key, or None.
    """
    if not isinstance(doc, Mapping):
        return None
    for key in doc:
        if not isinstance(key, str) or "*" in key:
            continue
        full = key if key.startswith("/") else "/" + key
        if full.rsplit("/", 1)[-1] == node and full != fqn:
            return key
    return None


def misapplied_section_message(path: str | Path, key: str, node: str, fqn: str) -> str:
    """The refusal for :func:`misapplied_section`: what is wrong and the two keys that work."""
    full = key if key.startswith("/") else "/" + key
    return (f"parameter file {path}: section '{key}' is meant for {node} but ROS applies it only to a node "
            f"named {full}, not to {fqn}; name the section '/**/{node}' (any namespace) or '{fqn}'")


def load_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> SimConfig:
    """Load and validate a configuration file (default: ``config/rimd.yaml``).

    Args:
        path: A ROS 2 parameter YAML file, or None for the default configuration file.
        overrides: Flat parameters applied on top of the file.

    Raises:
        ConfigError: For the first refused value, naming key, value and rule.
    """
    params = read_ros_parameters(find_config_file() if path is None else path)
    if overrides:
        params.update(overrides)
    return SimConfig.from_parameters(params)


def find_config_file(name: str = "rimd.yaml") -> Path:
    """Locate a configuration file shipped with the project.

    Looks in ``$RIMD_CONFIG_DIR``, the repository's ``config/``, then the installed
    ``share/rimd_sim/config``.

    Raises:
        ConfigError: When no such file exists.
    """
    import os
    import sys

    candidates = []
    if os.environ.get("RIMD_CONFIG_DIR"):
        candidates.append(Path(os.environ["RIMD_CONFIG_DIR"]) / name)
    here = Path(__file__).resolve()
    candidates += [parent / "config" / name for parent in here.parents]
    candidates.append(Path(sys.prefix) / "share" / "rimd_sim" / "config" / name)
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    raise ConfigError("config file", name, "not found in " + ", ".join(str(c.parent) for c in candidates[:3]))
