"""Rigs for the identification battery (docs/identification.md) and the two ways of recording them.

* :func:`draw_rigs`: seeded rigs drawn across the documented ranges of :data:`RANGES`.
* :func:`record_through_rig`: the rig as a user runs it: the simulator node started paused from rest with the
  hidden rig's parameters, in lockstep with ``rimd experiment``'s recorder, which records the stepped schedule;
  then the rig resumed. The one place the tests and the battery record through the rig.
* :func:`write_core_recording`: the same schedule run by the physics core in this process and written as the
  recorder writes it (rosbag2 MCAP through :class:`rimd_sim.io.bag.McapFile`, the simulator node's
  messages: the channels' blocks after the block-level faults, impact events, motor states, ``/rig/faults``,
  the triggered captures, the rig's parameters as metadata). For the cases where the point is the
  identification, not the wiring (faults, captures, many rigs): ``tests/ros/test_experiment.py`` shows that a
  recording through the rig equals the core's run of the same schedule sample for sample.

Both follow the timeline of ``rimd experiment --start START``: the rig runs from rest at ``frequencies[0]``;
step ``k`` takes effect at ``START + k * dwell``; the recording runs from sample 0 to the end of the last step.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

#: Ranges of the battery's rigs: a lab's own hammer may lie anywhere in them.
RANGES = {
    "mass": (0.08, 0.30),                  # kg, log-uniform
    "damping_ratio": (0.02, 0.12),
    "natural_frequency": (1.5, 2.2),       # Hz
    "amplitude": (0.6e-3, 1.5e-3),         # m
    "gap": (0.0, 2.0e-3),                  # m
    "contact.stiffness": (1.0e6, 1.0e7),   # N/m, log-uniform
    "contact.damping": (300.0, 3000.0),    # N s/m, log-uniform
}
LOG_UNIFORM = ("mass", "contact.stiffness", "contact.damping")
TOPICS = {"/rig/cart/displacement": "cart_displacement", "/rig/rimd/displacement": "rimd_displacement",
          "/rig/rimd/acceleration": "rimd_acceleration", "/rig/impact/force": "impact_force"}


def draw_rigs(n: int, seed: int = 24) -> list[dict[str, float]]:
    """``n`` rigs (flat parameter dicts), each value drawn over :data:`RANGES` from ``seed``."""
    rng = np.random.default_rng(seed)
    rigs = []
    for _ in range(n):
        rig = {}
        for name, (lo, hi) in RANGES.items():
            u = rng.uniform()
            rig[name] = float(math.exp(math.log(lo) + u * math.log(hi / lo)) if name in LOG_UNIFORM
                              else lo + u * (hi - lo))
        rigs.append(rig)
    return rigs


@dataclass
class Schedule:
    """What the experiment does: the steps, when the first takes effect, and the extras of the run."""

    frequencies: Sequence[float]
    dwell: float = 10.0
    start: float = 2.0
    ramp_rate: float = 2.0
    kicks: Sequence[tuple[float, float]] = ()          # (stamp s, velocity m/s) through /rig/perturb
    faults: Sequence[Mapping] = ()                      # inject_fault keyword arguments
    capture: bool = False
    seed: int = 0

    @property
    def end(self) -> float:
        """Stamp of the end of the last step (s)."""
        return self.start + len(self.frequencies) * self.dwell


@dataclass
class Written:
    """What :func:`write_core_recording` wrote."""

    path: Path
    impacts: int = 0
    captures: int = 0
    fault_events: int = 0
    blocks: dict[str, int] = field(default_factory=dict)


def rig_config(params: Mapping[str, float], schedule: Schedule):  # SimConfig
    """The simulator's configuration for ``params`` (flat names over the defaults) run under ``schedule``."""
    from rimd_sim.settings.config import SimConfig

    f0 = schedule.frequencies[0]
    return SimConfig().with_parameters({**params, "motor.initial_frequency": f0, "motor.initial_setpoint": f0,
                                        "seed": schedule.seed})


def write_core_recording(path: Path, params: Mapping[str, float], schedule: Schedule) -> Written:
    """Run ``schedule`` on the rig ``params`` in the core and write it as the recorder does (see the module doc)."""
    from rclpy.serialization import serialize_message

    from rimd_msgs.msg import Capture, FaultEvent, ImpactEvent, MotorState
    from rimd_sim.instruments.rig_simulator import RigSimulator
    from rimd_sim.io.bag import McapFile, TopicInfo
    from rimd_sim.io.cdr import SampleBlockEncoder
    from rimd_sim.io.msgdefs import message_definition
    from rimd_sim.settings.capture import CaptureConfig

    config = rig_config(params, schedule)
    sim = RigSimulator(config, truth=False, capture=CaptureConfig(enabled=schedule.capture))
    for k, f in enumerate(schedule.frequencies):
        sim.set_motor_frequency(f, schedule.ramp_rate, at=Fraction(repr(schedule.start + k * schedule.dwell)))
    for at, v in schedule.kicks:
        sim.perturb(v, at=Fraction(round(at * 1e9), 10**9))
    for fault in schedule.faults:
        sim.inject_fault(**fault)
    types = {**{t: "rimd_msgs/msg/SampleBlock" for t in TOPICS}, "/rig/impact/events": "rimd_msgs/msg/ImpactEvent",
             "/rig/motor/state": "rimd_msgs/msg/MotorState", "/rig/faults": "rimd_msgs/msg/FaultEvent"}
    if schedule.capture:
        types.update({"/rig/capture/force": "rimd_msgs/msg/Capture",
                      "/rig/capture/acceleration": "rimd_msgs/msg/Capture"})
    encoders = {name: SampleBlockEncoder(ch.frame_id, ch.sample_rate, ch.unit, ch.range_min, ch.range_max)
                for name, ch in ((c.name, c) for c in config.channels)}
    rates = {ch.name: Fraction(repr(ch.sample_rate)) for ch in config.channels}
    out = Written(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mcap = McapFile(path, compression="zstd", chunk_size=1 << 20, library="rimd test harness",
                    metadata={"rimd_rig_parameters": {k: str(v) for k, v in sorted(config.to_parameters().items())}})
    for topic, type_name in types.items():
        mcap.add_topic(TopicInfo(topic, type_name, [], message_definition(type_name)))

    def ns_of(t: Fraction) -> int:
        return round(t * 10**9)

    def stamp(msg, ns: int) -> None:
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)

    n_blocks = round(schedule.end * 100)
    done = 0
    while done < n_blocks:   # in passes of 10 s: bounded memory
        upto = min(n_blocks, done + 1000)
        blocks = sim.advance_blocks([Fraction(i + 1, 100) for i in range(done, upto)])
        done = upto
        for block in blocks:
            end_ns = ns_of(block.t_stop)
            for topic, name in TOPICS.items():
                for ch in block.deliveries[name]:
                    ns = ns_of(Fraction(ch.first_index) / rates[name])
                    sec, nsec = divmod(ns, 1_000_000_000)
                    mcap.write(topic, encoders[name].encode(sec, nsec, ch.first_index, ch.samples, ch.saturated),
                               end_ns, end_ns)
                    out.blocks[topic] = out.blocks.get(topic, 0) + 1
            for cap in block.captures:
                for which, values, channel in (("force", cap.force, "impact_force"),
                                               ("acceleration", cap.acceleration, "rimd_acceleration")):
                    msg = Capture(index=cap.number, sample_rate=cap.sample_rate,
                                  pre_trigger_samples=cap.pre_trigger_samples, samples=values.tolist(),
                                  unit=config.channel(channel).unit, trigger_level=cap.threshold)
                    stamp(msg, ns_of(cap.trigger_time))
                    msg.header.frame_id = config.channel(channel).frame_id
                    mcap.write(f"/rig/capture/{which}", serialize_message(msg), end_ns, end_ns)
                out.captures += 1
            for event in block.fault_events:
                spec = event.fault
                msg = FaultEvent(event=event.event, id=spec.number, channel=spec.channel, kind=spec.kind,
                                 start=float(spec.start), duration=float(spec.duration), magnitude=spec.magnitude,
                                 detail=event.detail)
                stamp(msg, ns_of(event.time))
                mcap.write("/rig/faults", serialize_message(msg), end_ns, end_ns)
                out.fault_events += 1
            for imp in block.impacts:
                msg = ImpactEvent(duration=imp.duration, peak_force=imp.peak_force, impulse=imp.impulse,
                                  impact_velocity=imp.impact_velocity, max_penetration=imp.max_penetration,
                                  excitation_frequency=imp.excitation_frequency,
                                  excitation_phase=imp.excitation_phase, cycle_index=imp.cycle_index,
                                  index=imp.index)
                stamp(msg, round(imp.t_start * 1e9))
                msg.header.frame_id = "impact_force_sensor"
                mcap.write("/rig/impact/events", serialize_message(msg), end_ns, end_ns)
                out.impacts += 1
            m = block.motor
            msg = MotorState(frequency_setpoint=m.frequency_setpoint, frequency=m.frequency, phase=m.phase,
                             cycle_index=max(m.cycle_index, 0), ramp_rate=m.ramp_rate, cart_position=m.cart_position)
            stamp(msg, end_ns)
            msg.header.frame_id = "motor"
            mcap.write("/rig/motor/state", serialize_message(msg), end_ns, end_ns)
    mcap.finish()
    return out


def record_through_rig(rigs, out: Path, params: Mapping[str, float], schedule: Schedule, *,
                       timeout: float = 240.0) -> Path:
    """Record ``schedule`` on the running rig ``params`` as a user would; return the recording directory.

    ``rigs``: a :class:`rimd_sim.ros.testing.RigFactory` (the tests' ``rimd_rig`` fixture). The simulator node starts
    paused from rest with the hidden rig's parameters, in lockstep with ``rimd experiment``'s recorder (as fast as
    it records, nothing lost however loaded the machine); ``rimd experiment --start`` schedules the steps (its
    recorder joins before the rig runs); the kicks go through ``/rig/perturb`` on their stamps; then
    ``/rig/resume``. Faults ride in the rig's ``faults`` list; captures through ``capture.enabled``.
    """
    from harness.processes import ProcessManager
    from rimd_sim.ros.clients.experiment import RECORDER_NODE

    f0 = schedule.frequencies[0]
    parameters = {**params, "start_paused": True, "motor.initial_frequency": f0, "motor.initial_setpoint": f0}
    if schedule.capture:
        parameters["capture.enabled"] = True
    rig = rigs(consumers=[RECORDER_NODE], record=False, seed=schedule.seed, parameters=parameters,
               faults=list(schedule.faults))
    out.mkdir(parents=True, exist_ok=True)
    exp_dir = out / "exp"
    rimd = shutil.which("rimd")
    assert rimd is not None, "rimd is not on PATH: source env.sh"
    processes = ProcessManager(rig.env, out / "processes")
    try:
        experiment = processes.start([rimd, "experiment", "--frequencies", *map(str, schedule.frequencies),
                                      "--dwell", str(schedule.dwell), "--settle", "2", "--ramp-rate",
                                      str(schedule.ramp_rate), "--out", str(exp_dir), "--start", str(schedule.start)],
                                     name="experiment")
        experiment.wait_for_output(r"steps scheduled from t = ", timeout=90)
        for at, v in schedule.kicks:
            response = rig.perturb(float(v), at=at)
            assert response.success, response.message
        assert rig.resume().success
        assert experiment.wait(timeout) == 0, experiment.tail()
    finally:
        processes.stop_all()
        rig.stop()
    return exp_dir / "recording"


def impact_near(rig: Mapping[str, float], freqs: Sequence[float], near: float, dwell: float,
                start: float = 2.0) -> float:
    """The start (s) of the impact nearest ``near`` in the core's run of ``rig`` on the experiment's timeline (from
    rest at ``freqs[0]``, step ``k`` from ``start + k * dwell``, ramps at 2 Hz/s): where to put a fault over one."""
    from rimd_sim.model.rig_model import RigModel
    from rimd_sim.settings.config import SimConfig

    config = SimConfig().with_parameters({**rig, "motor.initial_frequency": freqs[0],
                                          "motor.initial_setpoint": freqs[0]})
    model = RigModel(config, channels=False, truth=False)
    impacts = list(model.advance(Fraction(repr(start))).impacts)
    for k, f in enumerate(freqs):
        if k:
            impacts += model.set_motor_frequency(f, 2.0)
        impacts += model.advance(Fraction(repr(start + (k + 1) * dwell))).impacts
    return min((i.t_start for i in impacts), key=lambda t: abs(t - near))
