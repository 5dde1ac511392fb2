"""Configuration of the rig: one source of truth for the core and the ROS nodes.

The configuration is read from the same ROS 2 parameter YAML the simulator node reads::

    /**/rimd_simulator:
      ros__parameters:
        gap: 0.0
        contact:
          model: spring_dashpot
        ...

Nested mappings are flattened to the dotted ROS parameter names (``contact.model``). Every value is
validated when it is set: a refused value raises :class:`~rimd_sim.errors.ConfigError` naming the
key, the value and the rule. The result is a tree of frozen dataclasses (:class:`SimConfig`) whose field
values are SI (m, kg, s, Hz, N).

Defaults are the paper's identified values (Table 2, section 3: ``k = 5.5e6 N/m``, ``c = 1.2e3 N s/m``,
``A0 = 1 mm``, natural frequency 1.82 Hz) plus two values the paper does not give: the hammer mass 0.15 kg
and the structural damping ratio 0.08, chosen so that the model reproduces Table 1 (see README).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rimd_sim.errors import ConfigError
from rimd_sim.settings.capture import CaptureConfig
from rimd_sim.settings.lockstep import LockstepSettings
from rimd_sim.settings.params import Param, build, group, keyed, param, parameters, to_flat
from rimd_sim.settings.yaml_file import read_yaml

__all__ = [
    "CHANNEL_NAMES",
    "ChannelConfig",
    "ContactParams",
    "IntegratorParams",
    "MotorParams",
    "RigParams",
    "SimConfig",
    "SimulatorNodeSettings",
    "StructureParams",
    "check_simulator_section",
    "find_config_file",
    "flatten_parameters",
    "load_config",
    "misapplied_section",
    "misapplied_section_message",
    "read_ros_parameters",
]

#: Node name whose ``ros__parameters`` section holds the rig configuration.
NODE_NAME = "rimd_simulator"


#: The four DAQ channels, in publication order.
CHANNEL_NAMES = ("cart_displacement", "rimd_displacement", "rimd_acceleration", "impact_force")


#: Largest magnitude of an instrument's range, noise or resolution (SI units).
MAX_SI_MAGNITUDE = 1e9

#: Largest motor ramp rate (Hz/s), of ``motor.ramp_rate`` and of a ``set_motor_frequency`` request.
MAX_RAMP_RATE = 1e4

# Upper bounds (here and below) far beyond any instrument or rig refuse absurd values (1e300), which for some
# parameters would stop or hang the running rig's integrator; each lower bound that is not 0 says why.


#: The contact laws a configuration may name, in the order of their codes in the compiled kernel; the laws
#: themselves are :data:`rimd_sim.model.contact.CONTACT_LAWS`.
CONTACT_MODELS = ("spring_dashpot", "hertz", "hunt_crossley", "lankarani_nikravesh")

@dataclass(frozen=True)
class ContactParams:
    """Contact law between the hammer and the force sensor (paper Eq. 1); parameters ``contact.*``.

    ``min_impact_velocity`` floors the impact velocity that divides the Lankarani-Nikravesh damping term, so
    that a contact starting at rest has finite damping (an assumption).
    """

    model: str = param("spring_dashpot", "contact law (paper Eq. 1)", choices=CONTACT_MODELS)
    # k = 1e300 or c = 1e300 stops the rig at its first contact (step size underflow, non-finite state); the
    # bounds lie well inside what the integrator handles (k = 1e14, c = 1e7 at the defaults).
    stiffness: float = param(5.5e6, "contact stiffness k (N/m^n for the Hertz-type laws)", unit="N/m", gt=0,
                             le=1e12)
    damping: float = param(1.2e3, "contact damping c (N s/m^(n+1) for Hunt-Crossley)", unit="N s/m", ge=0, le=1e6)
    exponent: float = param(1.5, "exponent n of the Hertz-type laws", ge=1, le=3)
    restitution: float = param(0.8, "restitution e of the Lankarani-Nikravesh law", gt=0, le=1)
    # >= 1e-6 m/s: the floor divides the contact damping, and below ~1e-12 the integrator stalls or hangs.
    min_impact_velocity: float = param(1e-3, "floor of the Lankarani-Nikravesh impact velocity", unit="m/s",
                                       ge=1e-6, le=10)


#: Names of the contact models (``structure.model``).
STRUCTURE_MODELS = ("rigid", "two_mass")


@dataclass(frozen=True)
class StructureParams:
    """Optional structural contact model (docs/physics.md "Structural model"); ``structure.*``.

    ``model = "rigid"`` is the paper's single-mass hammer (the default). ``"two_mass"`` splits the hammer
    into the impact device (front, ``impactor_mass``) and the aluminium coupling that carries the
    accelerometer (rear, the rest of ``mass``), joined by the hammer's axial stiffness and damping, and puts
    the force sensor's top (``sensor_mass``) on a compliant mount. A stiffness of 0 means rigid. The upper
    bounds keep the fast modes within what the integrator resolves affordably (a 1e12 N/m link on 1 g would
    need sub-ns steps).
    """

    model: str = param("rigid", "contact model: rigid (the paper's single-mass hammer) or two_mass (axial mode "
                                "and sensor mount)", choices=STRUCTURE_MODELS)
    impactor_mass: float = param(0.06, "front (impact device) mass of the two-mass hammer, < mass", unit="kg",
                                 ge=1e-3, le=1000,
                                 relation="< mass when structure.model is two_mass and structure.axial_stiffness "
                                          "is not 0")
    axial_stiffness: float = param(0.0, "axial stiffness of the hammer, 0 = rigid", unit="N/m", zero="rigid",
                                   ge=1e3, le=1e10)
    axial_damping_ratio: float = param(0.05, "damping ratio of the hammer's axial mode", ge=0, lt=1)
    sensor_mass: float = param(0.01, "moving mass of the force sensor's top", unit="kg", ge=1e-4, le=10)
    mount_stiffness: float = param(0.0, "stiffness of the force sensor on its mount, 0 = rigid", unit="N/m",
                                   zero="rigid", ge=1e3, le=1e10)
    mount_damping_ratio: float = param(0.05, "damping ratio of the sensor-on-mount mode", ge=0, lt=1)


@dataclass(frozen=True)
class RigParams:
    """Mechanical parameters of the RIMD on its cart (SI units).

    Not in the paper: the hammer mass (0.15 kg) and the structural damping ratio (0.08), which reproduce
    Table 1 (README); the rest are the paper's.
    """

    gap: float = param(0.0, "gap between hammer at rest and force sensor", unit="m", ge=0, le=0.05,
                       relation="< l/2, half the pendulum length")
    # At least 1 g: a lighter hammer (1e-9 kg) makes the contact so stiff that the integrator hangs.
    mass: float = param(0.15, "hammer mass m", unit="kg", ge=1e-3, le=1000)
    amplitude: float = param(1.044e-3, "cart displacement amplitude A0", unit="m", ge=0, le=0.05)
    natural_frequency: float = param(1.763, "pendulum natural frequency without impact (sets l = g / (2 pi f)^2)",
                                     unit="Hz", gt=0, le=1000)
    damping_ratio: float = param(0.088, "structural damping ratio zeta", ge=0, le=2)
    gravity: float = param(9.81, "gravitational acceleration", unit="m/s^2", gt=0, le=100)
    # A hammer on wires is a gravity pendulum, l = g / omega_n^2: 18-22 Hz designs (f_n near 10 Hz) would need a
    # 2.5 mm pendulum. A longer pendulum with a torsional spring at its pivot keeps g real; the spring is not a
    # parameter of its own but what the declared length and natural frequency leave to it (``spring_stiffness``).
    pendulum_length: float = param(0.0, "pendulum length l apart from the natural frequency: a torsional spring at "
                                        "the pivot supplies the rest of the restoring stiffness, k_t = m l^2 "
                                        "(2 pi f_n)^2 - m g l >= 0; 0 = a gravity pendulum, l = g / (2 pi f_n)^2",
                                   unit="m", zero="gravity pendulum", ge=1e-3, le=10,
                                   relation="when not 0, >= g / (2 pi natural_frequency)^2 (a spring cannot have a "
                                            "negative stiffness)")
    contact: ContactParams = group(ContactParams, "contact.")
    structure: StructureParams = group(StructureParams, "structure.")

    def __post_init__(self) -> None:
        """Rules between the fields."""
        s = self.structure
        if s.model == "two_mass" and s.axial_stiffness > 0.0 and s.impactor_mass >= self.mass:
            raise ConfigError("structure.impactor_mass", s.impactor_mass,
                              f"must be < mass = {self.mass:g} kg (the rest of the hammer is the rear mass)")
        if self.pendulum_length > 0.0 and self.pendulum_length < self.gravity_length:
            raise ConfigError("pendulum_length", self.pendulum_length,
                              f"must be 0 (a gravity pendulum) or >= g / (2 pi natural_frequency)^2 = "
                              f"{self.gravity_length:.6g} m: a shorter pendulum at natural_frequency = "
                              f"{self.natural_frequency:g} Hz would need a spring of negative stiffness")
        if self.gap >= 0.5 * self.length:
            raise ConfigError("gap", self.gap, f"must be < half the pendulum length l/2 = {0.5 * self.length:.6g} m")

    @property
    def gravity_length(self) -> float:
        """Length of the gravity pendulum of the natural frequency, ``g / (2 pi f_n)^2`` (m)."""
        return self.gravity / (2.0 * math.pi * self.natural_frequency) ** 2

    @property
    def length(self) -> float:
        """Pendulum length ``l`` (m): ``pendulum_length``, or the gravity pendulum's ``g / (2 pi f_n)^2`` if 0."""
        return self.length_at(self.natural_frequency)

    def length_at(self, natural_frequency: float) -> float:
        """The pendulum length (m) these parameters give at another natural frequency (identification's trials)."""
        if self.pendulum_length > 0.0:
            return self.pendulum_length
        return self.gravity / (2.0 * math.pi * natural_frequency) ** 2

    @property
    def spring_stiffness(self) -> float:
        """Torsional stiffness of the pivot's spring, ``k_t = m l^2 omega_n^2 - m g l`` (N m/rad); 0 without one."""
        if self.pendulum_length <= 0.0:
            return 0.0
        return max(self.mass * self.length * (self.length * self.omega_n ** 2 - self.gravity), 0.0)

    @property
    def omega_n(self) -> float:
        """Natural angular frequency ``2 pi f_n`` in rad/s."""
        return 2.0 * math.pi * self.natural_frequency


@dataclass(frozen=True)
class MotorParams:
    """The AC motor that shakes the cart; parameters ``motor.*``.

    The motor starts at ``initial_frequency`` (reached without a ramp) and ramps to ``initial_setpoint``.
    """

    max_frequency: float = param(12.0, "highest motor frequency accepted", unit="Hz", gt=0, le=1000)
    ramp_rate: float = param(2.0, "default ramp rate of the motor frequency", unit="Hz/s", gt=0, le=MAX_RAMP_RATE)
    initial_frequency: float = param(0.0, "motor frequency at start", unit="Hz", ge=0,
                                     relation="<= motor.max_frequency")
    initial_setpoint: float = param(3.75, "motor setpoint at start", unit="Hz", ge=0,
                                    relation="<= motor.max_frequency")

    def __post_init__(self) -> None:
        """Rules between the fields."""
        for key, value in (("motor.initial_frequency", self.initial_frequency),
                           ("motor.initial_setpoint", self.initial_setpoint)):
            if value > self.max_frequency:
                raise ConfigError(key, value, f"must be <= motor.max_frequency = {self.max_frequency:g} Hz")


@dataclass(frozen=True)
class IntegratorParams:
    """Adaptive Dormand-Prince 5(4) integrator settings; parameters ``integrator.*``."""

    rtol: float = param(1e-7, "relative tolerance of the local error", ge=1e-13, le=1e-3)
    atol: float = param(1e-9, "absolute tolerance (rad for theta, rad/s for theta_dot)", gt=0, le=1e-3)
    # >= 1 us: a smaller cap makes each simulated second cost many seconds of CPU, and far smaller ones hang the rig.
    max_step: float = param(1e-2, "largest integration step", unit="s", ge=1e-6, le=0.05)
    event_tolerance: float = param(1e-12, "tolerance of the switch-time root finding on the dense output",
                                   unit="s", gt=0, le=1e-6)


@dataclass(frozen=True)
class ChannelConfig:
    """One DAQ channel: an instrument sampled at a fixed rate; parameters ``channels.<name>.*``.

    ``bandwidth``: -3 dB frequency of the instrument's 2nd-order low-pass; a value at or above
    0.45 x sample_rate cannot be represented at that rate and has no effect. ``highpass``: -3 dB frequency of
    the 1st-order high-pass of AC-coupled (piezoelectric) instruments. Ranges, noise and resolution are in the
    channel's unit (:attr:`unit`).
    """

    name: str
    sample_rate: float = param(1000.0, "samples per second", unit="Hz", gt=0, le=1e6)
    range_min: float = param(-1.0, "lower end of the measuring range (readings are clipped to it; the channel's "
                                   "unit)", ge=-MAX_SI_MAGNITUDE, le=MAX_SI_MAGNITUDE)
    range_max: float = param(1.0, "upper end of the measuring range (the channel's unit)", ge=-MAX_SI_MAGNITUDE,
                             le=MAX_SI_MAGNITUDE, relation="> range_min")
    noise_std: float = param(0.0, "white noise standard deviation (the channel's unit)", ge=0, le=MAX_SI_MAGNITUDE)
    resolution: float = param(0.0, "quantisation step, 0 = none (the channel's unit)", ge=0, le=MAX_SI_MAGNITUDE)
    bandwidth: float = param(0.0, "-3 dB low-pass frequency, 0 = none", unit="Hz", ge=0, le=1e6,
                             relation="> highpass when both are set")
    highpass: float = param(0.0, "-3 dB high-pass frequency, 0 = DC-coupled", unit="Hz", ge=0, le=1e6,
                            relation="< 0.45 x sample_rate when set")
    reliable: bool = param(True, "reliable QoS (else best effort); read at start")
    frame_id: str = param("", "sensor id in header.frame_id",
                          rule="a non-empty string without NUL characters (a ROS 2 string is a C string)",
                          check=lambda v: bool(v) and "\0" not in v, breaks=("", "force\0sensor"))

    def __post_init__(self) -> None:
        """Rules between the fields."""
        p = f"channels.{self.name}."
        if not self.range_min < self.range_max:
            raise ConfigError(p + "range_max", self.range_max, f"must be > {p}range_min = {self.range_min:g}")
        if self.highpass > 0 and self.highpass >= 0.45 * self.sample_rate:
            raise ConfigError(p + "highpass", self.highpass,
                              f"must be < 0.45 x sample_rate = {0.45 * self.sample_rate:g} Hz")
        if self.highpass > 0 and 0 < self.bandwidth <= self.highpass:
            raise ConfigError(p + "bandwidth", self.bandwidth, f"must be > {p}highpass = {self.highpass:g} Hz")

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
    """The whole simulator configuration: every parameter of the model, its instruments and its pacing.

    Build it from flat ROS parameters with :meth:`from_parameters` or :meth:`with_parameters`; each value
    is validated (:mod:`rimd_sim.settings.params`). ``seed``: same seed and commands give identical data.
    ``real_time_factor`` and ``block_rate`` concern the node's pacing only (the core ignores them).
    """

    rig: RigParams = group(RigParams, "")
    motor: MotorParams = group(MotorParams, "motor.")
    integrator: IntegratorParams = group(IntegratorParams, "integrator.")
    channels: tuple[ChannelConfig, ...] = keyed("channels.{}.", _DEFAULT_CHANNELS)
    truth_rate: float = param(1000.0, "sample rate of the noise-free ground truth (/rig/truth)", unit="Hz", gt=0,
                              le=1e6, name="truth.sample_rate")
    noise_enabled: bool = param(True, "add instrument noise (off: ideal, quantised, clipped readings)",
                                name="noise.enabled")
    seed: int = param(0, "seed of every random stream (read at start)", ge=0, lt=2**63)
    # 0 or >= 1e-3: a tiny factor (1e-300) put one block a near-infinite wall time away, and the pacing thread
    # died on the wait (OverflowError), leaving the rig silent.
    real_time_factor: float = param(1.0, "pacing: 1 = real time (wall-clock stamps), 0 = as fast as possible",
                                    zero="as fast as possible", ge=1e-3, le=1e6)
    # At least 1 block/s: a tiny rate made one block of a near-infinite span, computed at once (memory, time).
    block_rate: float = param(100.0, "sample blocks per second of simulation time (a block spans at most 1 s)",
                              unit="blocks/s", ge=1, le=10000)
    initial_theta: float = param(0.0, "pendulum angle at start", unit="rad", ge=-1.5, le=1.5, name="initial.theta")
    initial_theta_dot: float = param(0.0, "pendulum angular velocity at start", unit="rad/s", ge=-1000, le=1000,
                                     name="initial.theta_dot")

    def channel(self, name: str) -> ChannelConfig:
        """Return the channel called ``name``."""
        for ch in self.channels:
            if ch.name == name:
                return ch
        raise KeyError(name)

    def to_parameters(self) -> dict[str, Any]:
        """Return the configuration as flat ROS parameter names and values."""
        return to_flat(self)

    def with_parameters(self, overrides: Mapping[str, Any]) -> SimConfig:
        """Return a new validated configuration with some parameters changed.

        Args:
            overrides: Flat ROS parameter names and values, for example ``{"gap": 1e-3}``.

        Raises:
            ConfigError: For an unknown key, a value of the wrong type or out of range, or an
                inconsistent combination.
        """
        return build(SimConfig, overrides, base=self)

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> SimConfig:
        """Build a configuration from flat ROS parameters over the defaults (see :meth:`with_parameters`).

        The simulator node's own parameters (:func:`is_node_parameter`: ``start_paused``, the fault scenario
        ``faults``, ``capture.*``, ``lockstep.*``) may stand in the same file; the node reads and checks them.
        """
        return build(cls, params, ignore=is_node_parameter)


@dataclass(frozen=True)
class SimulatorNodeSettings:
    """The simulator node's own parameters, besides :class:`SimConfig`'s: read at start, not by the core."""

    start_paused: bool = param(False, "start paused: publish nothing until /rig/resume (at real time, t0 is then "
                                      "the time of that call)", read_only=True)
    faults: tuple[str, ...] = param((), "fault scenario loaded at start: one 'channel=NAME kind=KIND start=S "
                                        "duration=S magnitude=M' string per fault (\"\" entries are ignored); "
                                        "docs/faults.md", read_only=True)
    until: float = param(0.0, "simulation time at which the rig holds: it simulates up to the first block end at or "
                              "after it and then publishes nothing more", unit="s", gt=0.0,
                         zero="no end", read_only=True)
    capture: CaptureConfig = group(CaptureConfig, "capture.")
    lockstep: LockstepSettings = group(LockstepSettings, "lockstep.")


#: Every parameter of :class:`SimConfig`, by ROS name (the declarations of :mod:`rimd_sim.settings.params`).
PARAMETERS: dict[str, Param] = parameters(SimConfig)
#: The simulator node's own parameters (:class:`SimulatorNodeSettings`).
NODE_PARAMETERS: dict[str, Param] = parameters(SimulatorNodeSettings)


def check_simulator_section(values: Mapping[str, Any]) -> tuple[SimConfig, SimulatorNodeSettings]:
    """The simulator's configuration and node settings from a parameter-file section, each value checked.

    Raises:
        ConfigError: Naming the first refused parameter (an unknown one included) and its rule.
    """
    config = SimConfig.from_parameters(values)
    return config, build(SimulatorNodeSettings, {k: v for k, v in values.items() if is_node_parameter(k)})


def is_node_parameter(name: str) -> bool:
    """Whether ``name`` is a parameter of the simulator node's own, not of :class:`SimConfig` (the node checks it)."""
    return name in NODE_PARAMETERS


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
    path = Path(path)
    doc = read_yaml(path, what="config file")
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

    Returns:
        The validated configuration.

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
    from rimd_sim.settings.paths import config_dirs

    directories = config_dirs()
    candidates = [directory / name for directory in directories]
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    raise ConfigError("config file", name, "not found in " + (", ".join(str(d) for d in directories)
                                                             or "no source checkout and no installed rimd_sim"))
