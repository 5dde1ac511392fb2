"""A DAQ reader on Eclipse Cyclone DDS gets every block of the rig, on its exact time grid (docs/rig.md, "Readers
on other DDS implementations").

A lab's reader may be no ROS 2 node on Fast DDS: rmw_cyclonedds_cpp, or a program on the ``cyclonedds`` package
with the message types written from ``rimd_msgs/msg``. The reader here is such a program
(``tests/harness/cyclone_reader.py``: no rclpy, reliable, keep last 200, its own process, loopback) and the rig is
``rimd node simulator`` with it as the only reader.

Hypotheses:

1. at real time, a Cyclone reader that joins the running rig gets each of the four channels without a hole in
   ``first_index`` from its first block on, every stamp ``t0 + first_index / sample_rate`` with ``t0`` the run's
   ``start_stamp`` (``/rig/session``). A Cyclone reader delivers nothing from a Fast DDS writer until that writer's
   first heartbeat after their match and keeps only the first 128 samples meanwhile, so with Fast DDS's default
   heartbeat (3 s) the 2 kHz channels would lose a second's worth of blocks soon after the reader's first block;
2. in lockstep, as fast as the consumer allows, a Cyclone consumer that publishes its own
   ``rimd_msgs/msg/ConsumerProgress`` (as a client in another language does) joins, gets every block of the four
   channels from sample 0 with stamps ``first_index / sample_rate``, and its leave is heard.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.timeout(180)]

READER = str(Path(__file__).resolve().parents[1] / "harness" / "cyclone_reader.py")
RATES = {"/rig/cart/displacement": 2000, "/rig/rimd/displacement": 2000, "/rig/rimd/acceleration": 20000,
         "/rig/impact/force": 20000}


def start_simulator(ros_processes, repo_root: Path, *parameters: str):
    """``rimd node simulator`` with the default configuration and ``parameters`` (``name:=value``)."""
    args = ["-m", "rimd_sim.cli", "node", "simulator", "--ros-args", "--params-file",
            str(repo_root / "config" / "rimd.yaml")]
    for parameter in parameters:
        args += ["-p", parameter]
    return ros_processes.start_python(*args, name="rimd_node_simulator")


def read(ros_processes, out: Path, seconds: float, *extra: str) -> dict:
    """Run the Cyclone reader until each channel has delivered ``seconds`` s of samples; what it got."""
    reader = ros_processes.start_python(READER, str(out), "--seconds", str(seconds), "--timeout", "100", *extra,
                                        name="cyclone_reader")
    assert reader.wait(120) == 0, reader.tail()
    return json.loads(out.read_text())


def stamp_ns(t0_ns: int, first_index: int, rate: int) -> int:
    """The stamp of sample ``first_index``: ``t0 + first_index / rate`` in integer ns, rounded half up."""
    return t0_ns + (2 * first_index * 1_000_000_000 + rate) // (2 * rate)


def assert_contiguous_on_the_grid(got: dict, t0_ns: int) -> None:
    """Per channel: each block starts where the previous ended, each stamp is on the grid from ``t0_ns``."""
    for topic, rate in RATES.items():
        blocks = got["blocks"][topic]
        assert blocks and all(b[3] == rate for b in blocks), (topic, blocks[:1])
        holes = [(a[0] + a[1], b[0]) for a, b in zip(blocks, blocks[1:], strict=False) if b[0] != a[0] + a[1]]
        assert not holes, f"{topic}: {len(holes)} holes (expected first_index, got): {holes[:5]}"
        off = [(b[0], b[2]) for b in blocks if b[2] != stamp_ns(t0_ns, b[0], rate)]
        assert not off, f"{topic}: {len(off)} stamps off the grid from {t0_ns} (first_index, stamp): {off[:5]}"
        assert got["lost"][topic] == 0, (topic, got["lost"])


def test_a_cyclone_reader_joining_the_rig_at_real_time_misses_no_block(ros_processes, repo_root, tmp_path):
    sim = start_simulator(ros_processes, repo_root)
    sim.wait_for_output(r"rig ready: .* stamps: wall clock", timeout=90)
    got = read(ros_processes, tmp_path / "cyclone.json", 4.0)
    assert sim.stop() == 0, sim.tail()
    (session,) = got["sessions"]
    assert (session["reason"], session["time_base"]) == ("start", "wall_clock"), session
    assert_contiguous_on_the_grid(got, session["start_stamp_ns"])


def test_a_cyclone_consumer_in_lockstep_gets_every_block_from_sample_0(ros_processes, repo_root, tmp_path):
    sim = start_simulator(ros_processes, repo_root, "lockstep.enabled:=true", "lockstep.consumers:=[cyclone_daq]",
                          "real_time_factor:=0.0")
    sim.wait_for_output(r"rig ready: .* lockstep with cyclone_daq", timeout=90)
    got = read(ros_processes, tmp_path / "cyclone.json", 3.0, "--lockstep", "cyclone_daq")
    sim.wait_for_output(r"consumer 'cyclone_daq' left", timeout=30)   # its last report, leaving, was heard
    assert sim.stop() == 0, sim.tail()
    (session,) = got["sessions"]
    assert (session["time_base"], session["lockstep"], session["start_stamp_ns"]) == ("simulation", True, 0), session
    assert all(got["blocks"][topic][0][0] == 0 for topic in RATES), {t: b[0] for t, b in got["blocks"].items()}
    assert_contiguous_on_the_grid(got, 0)
