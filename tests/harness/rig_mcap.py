"""Write a real ROS 2 MCAP recording of the rig from the physics core, without ROS running.

The file is what a recorder writes: profile ``ros2``, ``ros2msg`` schemas with the full definitions of the
installed ``rimd_msgs`` (dependencies included), ``cdr`` messages on the ``/rig/...`` topics, log time =
the message stamp. The data are the core's own output (:class:`rimd_sim.instruments.rig_simulator.RigSimulator`), in
100 blocks per second as the simulator node publishes them. Used until a recording made by
``rimd_recorder`` is available to the tests: :func:`write_rig_mcap` returns what it wrote, so a test can
compare a conversion with it either way.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

from ament_index_python.packages import get_package_share_directory

SEPARATOR = "=" * 80
TOPIC_OF_CHANNEL = {"cart_displacement": "/rig/cart/displacement", "rimd_displacement": "/rig/rimd/displacement",
                    "rimd_acceleration": "/rig/rimd/acceleration", "impact_force": "/rig/impact/force"}
TRUTH_FIELDS = ("theta", "theta_dot", "cart_position", "rimd_position", "rimd_velocity", "rimd_acceleration",
                "penetration", "contact_force", "motor_phase", "motor_frequency")


def message_definition(package: str, name: str) -> str:
    """The ``ros2msg`` text of ``package/msg/name`` followed by its dependencies (Header, Time)."""
    def text(pkg: str, msg: str) -> str:
        return (Path(get_package_share_directory(pkg)) / "msg" / f"{msg}.msg").read_text()

    parts = [text(package, name)]
    for pkg, msg in (("std_msgs", "Header"), ("builtin_interfaces", "Time")):
        parts.append(f"{SEPARATOR}\nMSG: {pkg}/{msg}\n{text(pkg, msg)}")
    return "\n".join(parts)


@dataclass
class WrittenRecording:
    """What was written: samples per channel, first index per channel, impacts, phase-0 crossings."""

    path: Path
    samples: dict[str, int] = field(default_factory=dict)
    first_index: dict[str, int] = field(default_factory=dict)
    impacts: int = 0
    truth_blocks: int = 0
    motor_states: int = 0


def write_rig_mcap(path: Path, seconds: float = 3.0, frequency_hz: float = 3.75, *, overrides: dict | None = None,
                   skip: tuple[str, ...] = (), commands: tuple[tuple[float, float], ...] = (),
                   sessions: tuple[tuple[str, str], ...] = ()) -> WrittenRecording:
    """Run the core for ``seconds`` with the motor at ``frequency_hz`` from t = 0 and record it to ``path``.

    ``overrides``: parameters over the defaults; ``skip``: topics not written; ``commands``: motor setpoints
    ``(time s, frequency Hz)`` at the configured ramp rate; ``sessions``: ``/rig/session`` messages
    ``(run_id, reason)`` at t = 0, as the simulator publishes at its start (simulation time base).
    """
    from mcap_ros2.writer import Writer

    from rimd_sim.instruments.rig_simulator import RigSimulator
    from rimd_sim.settings.config import SimConfig

    config = SimConfig().with_parameters({"motor.initial_frequency": frequency_hz,
                                          "motor.initial_setpoint": frequency_hz, **(overrides or {})})
    sim = RigSimulator(config)
    for at, f in commands:
        sim.set_motor_frequency(f, at=at)
    blocks = sim.advance_blocks([Fraction(i + 1, 100) for i in range(round(seconds * 100))])
    rates = {ch.name: ch for ch in config.channels}
    out = WrittenRecording(path)

    def stamp(ns: int) -> dict:
        return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}

    def sample_ns(n: int, rate: float) -> int:
        r = int(rate)
        return (2 * n * 1_000_000_000 + r) // (2 * r)

    with open(path, "wb") as fh:
        writer = Writer(fh)
        schemas = {name: writer.register_msgdef(f"rimd_msgs/msg/{name}", message_definition("rimd_msgs", name))
                   for name in ("SampleBlock", "ImpactEvent", "MotorState", "RigState", "RigSession")}
        for sequence, (run_id, reason) in enumerate(sessions):
            msg = {"header": {"stamp": stamp(0), "frame_id": ""}, "run_id": run_id, "reason": reason,
                   "sequence": sequence, "start_stamp": stamp(0), "simulation_time": 0.0, "time_base": "simulation",
                   "real_time_factor": 0.0, "lockstep": False, "seed": config.seed, "config_hash": "",
                   "node": "/rig/rimd_simulator"}
            writer.write_message("/rig/session", schemas["RigSession"], msg, log_time=0, publish_time=0)
        for block in blocks:
            for name, ch in block.channels.items():
                if TOPIC_OF_CHANNEL[name] in skip:
                    continue
                cfg = rates[name]
                ns = sample_ns(ch.first_index, cfg.sample_rate)
                msg = {"header": {"stamp": stamp(ns), "frame_id": cfg.frame_id}, "first_index": ch.first_index,
                       "sample_rate": cfg.sample_rate, "samples": ch.samples.tolist(), "unit": cfg.unit,
                       "range_min": cfg.range_min, "range_max": cfg.range_max, "saturated_count": ch.saturated}
                writer.write_message(TOPIC_OF_CHANNEL[name], schemas["SampleBlock"], msg, log_time=ns,
                                     publish_time=ns)
                out.samples[name] = out.samples.get(name, 0) + ch.samples.size
                out.first_index.setdefault(name, ch.first_index)
            if block.truth is not None and "/rig/truth" not in skip:
                first, rows = block.truth
                ns = sample_ns(first, config.truth_rate)
                msg = {"header": {"stamp": stamp(ns), "frame_id": "truth"}, "first_index": first,
                       "sample_rate": config.truth_rate, "in_contact": (rows[10] != 0.0).tolist(),
                       **{f: rows[i].tolist() for i, f in enumerate(TRUTH_FIELDS)}}
                writer.write_message("/rig/truth", schemas["RigState"], msg, log_time=ns, publish_time=ns)
                out.truth_blocks += 1
            for imp in ([] if "/rig/impact/events" in skip else block.impacts):
                ns = round(imp.t_start * 1e9)
                msg = {"header": {"stamp": stamp(ns), "frame_id": "impact_force_sensor"}, "duration": imp.duration,
                       "peak_force": imp.peak_force, "impulse": imp.impulse, "impact_velocity": imp.impact_velocity,
                       "max_penetration": imp.max_penetration, "excitation_frequency": imp.excitation_frequency,
                       "excitation_phase": imp.excitation_phase, "cycle_index": imp.cycle_index, "index": imp.index}
                end = round(float(block.t_stop) * 1e9)
                writer.write_message("/rig/impact/events", schemas["ImpactEvent"], msg, log_time=end,
                                     publish_time=end)
                out.impacts += 1
            m = block.motor
            ns = round(float(block.t_stop) * 1e9)
            msg = {"header": {"stamp": stamp(ns), "frame_id": "motor"}, "frequency_setpoint": m.frequency_setpoint,
                   "frequency": m.frequency, "phase": m.phase, "cycle_index": max(m.cycle_index, 0),
                   "ramp_rate": m.ramp_rate, "cart_position": m.cart_position}
            if "/rig/motor/state" not in skip:
                writer.write_message("/rig/motor/state", schemas["MotorState"], msg, log_time=ns, publish_time=ns)
                out.motor_states += 1
        writer.finish()
    return out
