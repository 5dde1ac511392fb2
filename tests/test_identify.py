"""``rimd identify``: the round trip through the real rig (simulator, recorder, experiment processes).

Hypothesis: a rig whose every physical value differs from the defaults, run as the simulator with instrument
noise on and recorded by ``rimd experiment`` (a stepped sweep through band A and a velocity kick), is
identified from the recording alone within 3 % per parameter (gap within 0.05 mm), and the twin re-run from
``identified.yaml`` under the same schedule reproduces the recording's steady peak forces within 2 % per step.
The code never sees the rig's file: ``rimd identify`` starts from ``config/rimd.yaml`` and reads only the
measured channels (it never reads the recording's metadata).
"""

from __future__ import annotations

import csv
import shutil
from fractions import Fraction
from pathlib import Path

import pytest
import yaml

from harness.outputs import read_json
from harness.ros import call_service

pytestmark = pytest.mark.ros

RTF = "8.0"
START = 2.0          # s: first step (the rig starts paused, from rest, and is resumed once scheduled)
DWELL = 4.0
SETTLE = 1.5
KICK_NEAR = 4.0      # s: a velocity kick of the hammer during the first step, in free flight

#: The hidden rig: every physical value changed from config/rimd.yaml.
CHANGED = {"mass": 0.2, "damping_ratio": 0.06, "natural_frequency": 1.95, "amplitude": 1.2e-3, "gap": 0.8e-3,
           "contact": {"stiffness": 7.0e6, "damping": 1.5e3}}


def _rimd(ros_processes, *args: str, name: str):  # noqa: ANN001
    executable = shutil.which("rimd")
    assert executable is not None, "rimd is not on PATH: source env.sh"
    return ros_processes.start([executable, *args], name=name)


def _flat(tree: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in tree.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _kick_time(rig: dict, freqs: list[float]) -> float:
    """A stamp near KICK_NEAR far from any impact (the core's run of the rig from rest; the test knows the rig)."""
    from rimd_sim.core import SimConfig
    from rimd_sim.core.model import RigModel

    config = SimConfig().with_parameters({**_flat(rig), "motor.initial_frequency": freqs[0],
                                          "motor.initial_setpoint": freqs[0]})
    starts = [i.t_start for i in RigModel(config, channels=False, truth=False).advance(KICK_NEAR + 1.0).impacts]
    candidates = [KICK_NEAR + k * 1e-3 for k in range(-300, 301)]
    return max(candidates, key=lambda t: min((abs(t - s) for s in starts), default=1.0))


def _record(ros_processes, ros_executor, tmp_path: Path, rig: dict, freqs: list[float], kick: float,
            kick_at: float) -> Path:
    """Run the rig from ``rig`` (parameters over the defaults) and record the experiment; return its directory."""
    import rclpy
    from builtin_interfaces.msg import Time

    from harness.rig import trigger
    from rimd_msgs.srv import Perturb

    params = {**rig, "real_time_factor": float(RTF), "start_paused": True,
              "motor": {"initial_frequency": freqs[0], "initial_setpoint": freqs[0]}}
    rig_file = tmp_path / "hidden_rig.yaml"
    rig_file.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    sim = ros_processes.start_node("rimd_simulator", "--ros-args", "--params-file", str(rig_file))
    sim.wait_for_output(r"rig ready", timeout=60)
    out = tmp_path / "exp"
    experiment = _rimd(ros_processes, "experiment", "--frequencies", *map(str, freqs), "--dwell", str(DWELL),
                       "--settle", str(SETTLE), "--ramp-rate", "2", "--out", str(out), "--start", str(START),
                       name="experiment")
    experiment.wait_for_output(r"steps scheduled from t = ", timeout=90)
    node = rclpy.create_node("driver", context=ros_executor.context)
    ros_executor.add_node(node)
    client = node.create_client(Perturb, "/rig/perturb")
    ns = round(kick_at * 1e9)
    request = Perturb.Request(velocity=kick, start_stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9))
    response = call_service(ros_executor, node, client, request, 10)
    assert response.success, response.message
    assert trigger(ros_executor, node, "/rig/resume").success
    assert experiment.wait(120) == 0, experiment.tail()
    return out


def _rerun_peaks(identified: Path, freqs: list[float], out: Path, kick: float, kick_at: float) -> dict[float, float]:
    """The core re-run from identified.yaml under the experiment's schedule: steady peak per step."""
    from rimd_sim.core import load_config
    from rimd_sim.core.simulator import RigSimulator

    schedule = read_json(out / "experiment.json")["steps"]
    config = load_config(identified, {"motor.initial_frequency": freqs[0], "motor.initial_setpoint": freqs[0]})
    core = RigSimulator(config, truth=False)
    for f, step in zip(freqs, schedule, strict=True):
        core.set_motor_frequency(f, 2.0, at=Fraction(step["effective_stamp_ns"], 10**9))
    core.perturb(kick, at=Fraction(round(kick_at * 1e9), 10**9))
    # The steady windows of the recording's analysis (steps.csv), in the rig's time base.
    origin = read_json(out / "summary.json")["origin_ns"] * 1e-9
    with open(out / "steps.csv") as fh:
        windows = {float(r["frequency_hz"]): (float(r["steady_from_s"]) + origin, float(r["end_s"]) + origin)
                   for r in csv.DictReader(fh) if r["steady_from_s"] not in ("", "None")}
    impacts = core.advance(max(hi for _, hi in windows.values()) + 0.1).impacts
    peaks = {}
    for f in freqs:
        lo, hi = windows[f]
        sel = [i.peak_force for i in impacts if lo <= i.t_start < hi]
        peaks[f] = max(sel) if sel else 0.0
    return peaks


def _recorded_peaks(out: Path, freqs: list[float]) -> dict[float, float]:
    """The recording's steady peak per step, as ``rimd analyze`` (run by the experiment) read it."""
    with open(out / "steps.csv") as fh:
        rows = [r for r in csv.DictReader(fh)]
    result = {}
    for r in rows:
        f = float(r["frequency_hz"])
        if f in freqs and r["peak_force_events_n"] not in ("", "None"):
            result[f] = float(r["peak_force_events_n"])
    return result


def _round_trip(ros_processes, ros_executor, tmp_path: Path, rig: dict, freqs: list[float], kick: float) -> None:
    from rimd_sim.core import SimConfig

    truth = SimConfig().with_parameters(_flat(rig))
    kick_at = _kick_time(rig, freqs)
    out = _record(ros_processes, ros_executor, tmp_path, rig, freqs, kick, kick_at)
    ident_dir = tmp_path / "ident"
    run = _rimd(ros_processes, "identify", str(out / "recording"), "--out", str(ident_dir), name="identify")
    assert run.wait(180) == 0, run.tail()
    report = read_json(ident_dir / "identification.json")
    expected = truth.to_parameters()
    lines = []
    for name in ("amplitude", "natural_frequency", "damping_ratio", "gap", "mass", "contact.stiffness",
                 "contact.damping"):
        est = report["estimates"][name]
        lines.append(f"{name}: {est['value']:.6g} +- {est['std_error'] or 0.0:.2g} (true {expected[name]:.6g}; local "
                     f"{est['local_value']:.6g})")
    print("\n".join(lines))
    for name, line in zip(("amplitude", "natural_frequency", "damping_ratio", "gap", "mass", "contact.stiffness",
                           "contact.damping"), lines, strict=True):
        value = report["estimates"][name]["value"]
        if name == "gap":
            assert abs(value - expected[name]) <= 0.05e-3, line
        else:
            assert abs(value / expected[name] - 1) <= 0.03, line
    # identified.yaml runs as it is: the core loads it, and it holds the identified values.
    from rimd_sim.core import load_config
    loaded = load_config(ident_dir / "identified.yaml")
    assert loaded.rig.mass == pytest.approx(report["estimates"]["mass"]["value"])
    for name in ("validation.png", "validation.csv"):
        assert (ident_dir / name).stat().st_size > 100
    # ... and the simulator node applies it as it is (--params-file, namespace /rig): its ready line shows the gap.
    node = ros_processes.start_node("rimd_simulator", "--ros-args", "--params-file", str(ident_dir / "identified.yaml"),
                                    "-r", "__ns:=/twin", "-p", "start_paused:=true", name="twin")
    ready = node.wait_for_output(r"rig ready: gap ([0-9.e+-]+) mm", timeout=60)
    assert float(ready.group(1)) == pytest.approx(loaded.rig.gap * 1e3, abs=1e-4)
    node.stop()
    # The twin from identified.yaml, re-run under the experiment's schedule, against the recording's peaks.
    recorded = _recorded_peaks(out, freqs)
    twin = _rerun_peaks(ident_dir / "identified.yaml", freqs, out, kick, kick_at)
    print("steady peaks, recorded vs twin:", {f: (recorded.get(f), twin[f]) for f in freqs})
    for f in freqs:
        if recorded.get(f, 0.0) > 1.0:
            assert abs(twin[f] / recorded[f] - 1) <= 0.02, (f, recorded[f], twin[f])
    assert sum(1 for f in freqs if recorded.get(f, 0.0) > 1.0) >= len(freqs) - 1


def test_identify_recovers_a_changed_rig(ros_processes, ros_executor, tmp_path):
    _round_trip(ros_processes, ros_executor, tmp_path, CHANGED, [1.0, 3.0, 3.5, 4.0], -0.03)


def test_identify_recovers_the_defaults(ros_processes, ros_executor, tmp_path):
    _round_trip(ros_processes, ros_executor, tmp_path, {}, [3.25, 3.75, 4.25], -0.03)


def _identify(tmp_path: Path, recording: Path, *extra: str) -> tuple[int, str, str]:
    """``rimd identify`` in this process (no ROS needed): status, stdout, stderr."""
    import contextlib
    import io

    from rimd_sim.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(["identify", str(recording), "--out", str(tmp_path / "id"), *extra])
    return status, out.getvalue(), err.getvalue()


def test_identify_refuses_what_the_recording_cannot_give(tmp_path):
    from harness.rig_mcap import write_rig_mcap

    # No force channel: the contact parameters, the mass and the gap cannot be identified; the line says which.
    no_force = tmp_path / "no_force.mcap"
    write_rig_mcap(no_force, 2.0, 3.75, skip=("/rig/impact/force",))
    status, _, err = _identify(tmp_path, no_force)
    line = err.strip().splitlines()[-1]
    assert status == 1 and line.startswith("rimd identify: the recording lacks channels"), err
    assert "gap, mass, contact.stiffness, contact.damping need /rig/impact/force" in line and "--fix" in line
    # No impact (a gap the hammer never reaches): contact parameters refused, --fix suggested.
    no_impact = tmp_path / "no_impact.mcap"
    write_rig_mcap(no_impact, 3.0, 1.0, overrides={"gap": 0.01})
    status, _, err = _identify(tmp_path, no_impact)
    line = err.strip().splitlines()[-1]
    assert status == 1 and "no impact in the recording" in line and "--fix gap=VALUE" in line, err
    # A --fix that is not a parameter, or not a number: one line.
    status, _, err = _identify(tmp_path, no_impact, "--fix", "colour=3")
    assert status == 1 and "--fix 'colour=3' refused" in err.strip().splitlines()[-1]
    # With the contact held fixed, the same recording gives A0, f_n and zeta (free flight from rest at 1 Hz).
    fixes = ["--fix", "gap=0.01", "--fix", "mass=0.15", "--fix", "contact.stiffness=5.5e6",
             "--fix", "contact.damping=1200"]
    status, out, err = _identify(tmp_path, no_impact, *fixes)
    assert status == 0, err
    report = read_json(tmp_path / "id" / "identification.json")
    assert set(report["estimates"]) == {"amplitude", "natural_frequency", "damping_ratio"}
    assert report["fixed"]["mass"] == 0.15
    assert abs(report["estimates"]["amplitude"]["value"] / 1e-3 - 1) < 0.01
    assert abs(report["estimates"]["natural_frequency"]["value"] / 1.82 - 1) < 0.01
    assert abs(report["estimates"]["damping_ratio"]["value"] / 0.08 - 1) < 0.05


def test_identify_uses_the_valid_part_of_a_damaged_recording_without_motor_states(tmp_path):
    """A file cut at 70 %, recorded without /rig/motor/state: the motor frequency comes from the cart laser."""
    from harness.rig_mcap import write_rig_mcap

    full = tmp_path / "full.mcap"
    write_rig_mcap(full, 6.0, 3.75, skip=("/rig/motor/state",))
    cut = tmp_path / "cut.mcap"
    data = full.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.7)])
    status, out, err = _identify(tmp_path, cut)
    assert status == 0, err
    assert out.startswith("LOSS: identified from the valid part"), out
    assert "no /rig/motor/state: one constant motor frequency fitted to the cart laser, 3.7500" in err, err
    report = read_json(tmp_path / "id" / "identification.json")
    assert not report["data"]["recording_loss"]["complete"]
    est = {k: v["value"] for k, v in report["estimates"].items()}
    truth = {"amplitude": 1e-3, "natural_frequency": 1.82, "damping_ratio": 0.08, "mass": 0.15,
             "contact.stiffness": 5.5e6, "contact.damping": 1.2e3}
    for name, value in truth.items():
        assert abs(est[name] / value - 1) < 0.03, (name, est[name], value)
    assert abs(est["gap"]) < 0.05e-3
