"""The Rerun bridge: live (simulator node + ``rimd_rerun`` over DDS) and offline (``rimd rerun REC.mcap``).

Hypotheses:
* live at full rate (``display_interval`` 0): every sample a channel published while the bridge listened is in
  the ``.rrd`` exactly once, at its exact sample time ``first_index / rate`` on ``sim_time``, with the published
  value (bit for bit); impacts are there as markers, log lines and table rows at their contact-start stamps;
  the file passes ``rerun rrd verify`` after a SIGTERM;
* live by default (the display stream): each channel holds, per 5 ms, the smallest and the largest of the
  samples published in it, at their own times and values (at most two points per interval, whatever the
  rate), so every impact's peak force sample is there exactly; the impacts as at full rate;
* a recording converted offline gives the same entities, with counts equal to what the recording holds;
* bad input (missing or garbage MCAP, unwritable --save, unknown sink) is one clear line and exit 1;
* the web sink listens on loopback only, and Rerun's usage reporting is off unless asked for.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy

from harness.rig_mcap import write_rig_mcap
from harness.ros import spin_until
from rimd_msgs.msg import ImpactEvent, SampleBlock
from rimd_sim.settings.config import read_ros_parameters
from rimd_sim.viz.rerun_map import CHANNELS, sample_times_ns, stamp_ns
from rimd_sim.viz.rrd_data import load_rrd

RATES = {"cart_displacement": 2000.0, "rimd_displacement": 2000.0, "rimd_acceleration": 20000.0,
         "impact_force": 20000.0}
#: Entities with temporal data that every run with impacts and a spinning motor must produce.
ENTITIES = {*(ch.entity for ch in CHANNELS), "channels/impact_force/impacts", "impacts/log", "impacts/table",
            "phase_plane/trajectory", "poincare/points", "motor/frequency"}


def _rerun_cli() -> str:
    exe = shutil.which("rerun")
    assert exe, "the rerun CLI of rerun-sdk is not on PATH"
    return exe


def verify_rrd(path: Path) -> None:
    """The real ``rerun rrd verify`` accepts the file."""
    result = subprocess.run([_rerun_cli(), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr


def check_channels(data, counts: dict[str, int] | None = None) -> dict[str, tuple[int, int]]:
    """Each channel is one contiguous run of samples on its exact grid; returns name -> (first, count)."""
    runs = {}
    for ch in CHANNELS:
        rate = RATES[ch.name]
        times = data[ch.entity].times
        first = int(times[0]) * int(rate) // 1_000_000_000
        assert np.array_equal(times, sample_times_ns(first, times.size, rate)), f"{ch.name}: not the sample grid"
        assert data[ch.entity].scalars().size == times.size
        if counts is not None:
            assert times.size == counts[ch.name], ch.name
        runs[ch.name] = (first, int(times.size))
    return runs


def envelope(times: np.ndarray, values: np.ndarray, interval_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """The display stream by a plain scan, interval by interval: the first min and first max sample, time order."""
    ids = times // interval_ns
    index: list[int] = []
    for k in np.unique(ids):
        where = np.flatnonzero(ids == k)
        index += sorted({int(where[np.argmin(values[where])]), int(where[np.argmax(values[where])])})
    return times[index], values[index]


def run_live_bridge(ros_processes, ros_executor, tmp_path, runs_of, *bridge_args: str):
    """The simulator (motor at 3.75 Hz, gap 0), a probe that hears every channel and the impacts, and the bridge
    saving an .rrd (``bridge_args`` more) until it has logged a few impacts; SIGTERM. ``runs_of(data, closed)``
    gives each channel's (first index, count) the bridge logged; the probe then takes every block and impact up
    to the bridge's last, and the rig stops. Returns (data, heard blocks, events, closing line, origin ns, runs).
    """
    import rclpy

    rig = ros_processes.start_node("rimd_simulator", "--ros-args", "-p", "motor.initial_frequency:=3.75")
    rig.wait_for_output(r"rig ready", timeout=30)
    probe = rclpy.create_node("probe_rerun", context=ros_executor.context)
    ros_executor.add_node(probe)
    qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
    heard: dict[str, list[SampleBlock]] = {ch.name: [] for ch in CHANNELS}
    for ch in CHANNELS:
        probe.create_subscription(SampleBlock, "/rig/" + ch.topic, heard[ch.name].append, qos)
    events: list[ImpactEvent] = []
    probe.create_subscription(ImpactEvent, "/rig/impact/events", events.append, qos)
    # The probe is the truth the file is checked against, so it must hear every block the bridge will hear:
    # the bridge starts only once the probe receives every channel and the impact events (volatile topics,
    # so the bridge cannot be given anything older). Under load the test process can match its readers after
    # a bridge started at the same time, and would then miss the bridge's first blocks.
    assert spin_until(ros_executor, lambda: all(heard.values()) and bool(events), timeout=30), \
        {name: len(blocks) for name, blocks in heard.items()} | {"impact events": len(events)}

    out = tmp_path / "live.rrd"
    bridge = ros_processes.start_node("rimd_rerun", "--ros-args", "-p", "sink:=save", "-p", f"save_path:={out}",
                                      "-p", "status_period:=1.0", *bridge_args)
    bridge.wait_for_output(r"rerun bridge ready: sink save", timeout=30)
    # Run until the bridge has logged a few impacts (the motor runs at 3.75 Hz from the start, gap 0).
    assert spin_until(ros_executor, lambda: re.search(r"status: .*, [3-9]\d* impacts|status: .*, \d{2,} impacts",
                                                      bridge.output()) is not None, timeout=30), bridge.tail()
    bridge.send_signal(signal.SIGTERM)
    assert bridge.wait(20) == 0, bridge.tail()
    closed = re.search(r"rimd_rerun: closed .*", bridge.output())
    assert closed, bridge.tail()
    assert closed.group(0).endswith(", 0 gaps"), closed.group(0)

    verify_rrd(out)
    data = load_rrd(out)
    assert ENTITIES <= set(data), sorted(ENTITIES - set(data))
    runs = runs_of(data, closed.group(0))
    origin = stamp_ns(heard["impact_force"][0].header.stamp) - int(
        sample_times_ns(heard["impact_force"][0].first_index, 1, 20000.0)[0])
    markers = data["channels/impact_force/impacts"]
    # The rig still runs: let the probe take every block and impact up to the bridge's last before it stops.
    heard_to = {name: lambda name=name: max((b.first_index + len(b.samples) for b in heard[name]), default=0)
                for name in heard}
    last_impact = int(markers.times[-1]) if markers.times.size else 0
    assert spin_until(ros_executor, lambda: all(heard_to[n]() >= sum(runs[n]) for n in runs) and any(
        stamp_ns(e.header.stamp) - origin >= last_impact for e in events), timeout=20), \
        {n: (heard_to[n](), sum(runs[n])) for n in runs}
    assert rig.stop() == 0, rig.tail()
    return data, heard, events, closed.group(0), origin, runs


def published(heard: dict, name: str, first: int, count: int) -> np.ndarray:
    """The samples the probe heard on channel ``name`` with indices ``first .. first + count - 1``, in order."""
    blocks = [b for b in heard[name] if first <= b.first_index < first + count]
    assert blocks and blocks[0].first_index == first, name
    samples = np.concatenate([np.asarray(b.samples) for b in blocks])
    assert samples.size == count, (name, samples.size, count)
    return samples


def check_impacts(data, events, origin: int) -> None:
    """Markers, table and log of the impacts are the events the probe heard, at their contact-start stamps."""
    markers = data["channels/impact_force/impacts"]
    assert markers.times.size >= 3
    by_time = {stamp_ns(e.header.stamp) - origin: e for e in events}
    for t, peak in zip(markers.times, markers.scalars(), strict=True):
        assert int(t) in by_time and by_time[int(t)].peak_force == peak
    table = data["impacts/table"]
    assert np.array_equal(table.times, markers.times)
    assert np.array_equal(table.scalars("impulse_Ns"), [by_time[int(t)].impulse for t in table.times])
    assert len(data["impacts/log"].texts()) == markers.times.size
    # One Poincare point per completed motor cycle at 3.75 Hz while the bridge listened (within one).
    span = (data["phase_plane/trajectory"].times[-1] - data["phase_plane/trajectory"].times[0]) / 1e9
    assert abs(data["poincare/points"].times.size - 3.75 * span) <= 1.5


@pytest.mark.ros
@pytest.mark.timeout(90)
def test_live_bridge_at_full_rate_logs_every_published_sample_at_its_time(ros_processes, ros_executor, tmp_path):
    """``display_interval`` 0 (``rimd rig --rerun-full-rate``): every sample, bit for bit, at its time."""
    data, heard, events, closed, origin, runs = run_live_bridge(
        ros_processes, ros_executor, tmp_path, lambda data, closed: check_channels(data), "-p", "display_interval:=0.0")
    assert "display points" not in closed
    for ch in CHANNELS:
        first, count = runs[ch.name]
        assert f"{ch.name} {count} samples," in closed  # what the bridge counted is what is in the file
        # What was published in that index range, as heard by the probe: same samples, same values.
        assert np.array_equal(data[ch.entity].scalars(), published(heard, ch.name, first, count)), ch.name
        first_block = next(b for b in heard[ch.name] if b.first_index == first)
        assert stamp_ns(first_block.header.stamp) - data[ch.entity].times[0] == origin, "one origin for all channels"
    check_impacts(data, events, origin)


@pytest.mark.ros
@pytest.mark.timeout(90)
def test_live_bridge_logs_the_display_stream_by_default(ros_processes, ros_executor, tmp_path):
    """The default: each channel's min and max sample per 5 ms of what was published, each at its own time (at most
    two points per interval whatever the rate); every impact's peak force sample among them, value and time."""
    interval = 5_000_000

    def runs_of(data, closed: str) -> dict[str, tuple[int, int]]:
        # The bridge's first block starts an interval (10 ms blocks): its first index from its first point's
        # interval; its sample count from its closing line.
        runs = {}
        for ch in CHANNELS:
            count = re.search(rf"{ch.name} (\d+) samples \((\d+) display points\)", closed)
            assert count, closed
            first = int(data[ch.entity].times[0]) // interval * interval * int(RATES[ch.name]) // 1_000_000_000
            runs[ch.name] = (first, int(count.group(1)))
        return runs

    data, heard, events, closed, origin, runs = run_live_bridge(ros_processes, ros_executor, tmp_path, runs_of)
    for ch in CHANNELS:
        first, count = runs[ch.name]
        times = sample_times_ns(first, count, RATES[ch.name])
        samples = published(heard, ch.name, first, count)
        want_t, want_v = envelope(times, samples, interval)
        assert np.array_equal(data[ch.entity].times, want_t), ch.name
        assert np.array_equal(data[ch.entity].scalars(), want_v), ch.name
        assert f"{ch.name} {count} samples ({want_t.size} display points)" in closed
        assert want_t.size <= 2 * np.unique(times // interval).size, ch.name   # 400 points/s, at 2 or 20 kHz
        if ch.name == "impact_force":
            shown = dict(zip(want_t.tolist(), want_v.tolist(), strict=True))
            impacts = [e for e in events if times[0] <= stamp_ns(e.header.stamp) - origin
                       and stamp_ns(e.header.stamp) - origin + e.duration * 1e9 <= times[-1]]
            assert len(impacts) >= 3
            for e in impacts:
                start = stamp_ns(e.header.stamp) - origin
                inside = np.flatnonzero((times >= start) & (times <= start + e.duration * 1e9))
                top = inside[np.argmax(samples[inside])]
                assert shown.get(int(times[top])) == samples[top], e.index   # the peak sample, time and value
    check_impacts(data, events, origin)


@pytest.mark.process
def test_offline_recording_gives_the_same_entities_and_its_counts(tmp_path, repo_root):
    rec = write_rig_mcap(tmp_path / "rec.mcap", seconds=3.0)
    out = tmp_path / "offline.rrd"
    result = subprocess.run(["rimd", "rerun", str(rec.path), "--save", str(out)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    # The counts the writer of the file reports (harness.rig_mcap counts what it wrote): 3 s of the four
    # channels at 20, 20, 2 and 2 kHz: 132000 samples; 11 impacts (one per cycle) in 3 s at 3.75 Hz.
    assert f"{sum(rec.samples.values())} samples" in result.stdout and f"{rec.impacts} impacts" in result.stdout, (
        result.stdout, rec.samples, rec.impacts)
    verify_rrd(out)
    data = load_rrd(out)
    assert ENTITIES <= set(data), sorted(ENTITIES - set(data))
    runs = check_channels(data, rec.samples)
    assert all(runs[name][0] == rec.first_index[name] for name in runs)
    assert data["impacts/table"].times.size == rec.impacts == data["channels/impact_force/impacts"].times.size
    assert data["phase_plane/trajectory"].times.size == rec.truth_blocks
    strips = data["phase_plane/trajectory"].strips()
    assert len(strips) == rec.truth_blocks and sum(len(s) for s in strips) == 3000 + rec.truth_blocks - 1
    assert all(np.array_equal(a[-1], b[0]) for a, b in zip(strips, strips[1:], strict=False)), "one unbroken line"
    assert data["motor/frequency"].times.size == rec.truth_blocks
    # 3 s at 3.75 Hz from phase 0: 11 completed cycles (t = k / 3.75 s, k = 1..11).
    assert np.allclose(data["poincare/points"].times / 1e9, np.arange(1, 12) / 3.75, atol=1e-3)


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_a_recording_of_rimd_recorder_gives_the_same_view(ros_processes, ros_executor, tmp_path):
    """The offline path on a file of the real recorder: every recorded sample and impact is in the
    .rrd at its time, with the same entities as the live bridge."""
    from harness.bags import read_with_mcap_ros2
    from harness.rig import record_rig

    out = tmp_path / "rec"
    recorder, _, _ = record_rig(ros_processes, ros_executor, out, 5.0)  # motor ramps 0 -> 3.75 Hz at 2 Hz/s
    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(30) == 0, recorder.tail()
    (path,) = out.glob("*.mcap")
    recorded = read_with_mcap_ros2(path)
    samples: dict[str, int] = {}
    for topic, _, _, msg in recorded:
        for ch in CHANNELS:
            if topic == "/rig/" + ch.topic:
                samples[ch.name] = samples.get(ch.name, 0) + len(msg.samples)
    events = [msg for topic, _, _, msg in recorded if topic == "/rig/impact/events"]
    truth = [msg for topic, _, _, msg in recorded if topic == "/rig/truth"]
    rrd = tmp_path / "from_recorder.rrd"
    result = subprocess.run(["rimd", "rerun", str(out), "--save", str(rrd)], capture_output=True, text=True,
                            timeout=60)  # the recording directory
    assert result.returncode == 0, result.stderr
    verify_rrd(rrd)
    data = load_rrd(rrd)
    assert ENTITIES <= set(data), sorted(ENTITIES - set(data))
    runs = check_channels(data, samples)
    assert all(first == 0 for first, _ in runs.values())  # the rig started paused: recorded from sample 0
    assert events and data["impacts/table"].times.size == len(events)
    assert np.array_equal(data["impacts/table"].scalars("peak_force_N"), [e.peak_force for e in events])
    assert data["phase_plane/trajectory"].times.size == len(truth)


@pytest.mark.filterwarnings("ignore:RRD file has no footer")
@pytest.mark.process
def test_offline_to_a_viewer_at_a_url(ros_processes, tmp_path):
    """Sink connect: the data reach what listens at the URL (here ``rerun --save``, a Rerun endpoint that
    writes what it receives); a URL where nothing listens is refused at once."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    received = tmp_path / "received.rrd"
    endpoint = ros_processes.start([_rerun_cli(), "--save", str(received), "--bind", "127.0.0.1", "--port", str(port)],
                                   name="rerun_save_endpoint")
    endpoint.wait_for_output(rf"127\.0\.0\.1:{port}", timeout=30)
    rec = write_rig_mcap(tmp_path / "rec.mcap", seconds=1.0)
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    result = subprocess.run(["rimd", "rerun", str(rec.path), "--connect", url], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    import time

    def everything_arrived() -> bool:
        """The endpoint writes as it receives: the file holds every sample and impact sent (read chunk by chunk:
        streamed, it has no footer; a frame still being written fails to decode, RuntimeError: not yet)."""
        try:
            data = load_rrd(received)
            check_channels(data, rec.samples)
            return data["impacts/table"].times.size == rec.impacts > 0
        except (AssertionError, KeyError, OSError, ValueError, IndexError, RuntimeError):
            return False

    deadline = time.monotonic() + 30
    while not everything_arrived():
        assert time.monotonic() < deadline, "the endpoint did not receive every sample and impact in 30 s"
        time.sleep(0.2)   # a poll of an observable condition, bounded by the deadline
    endpoint.send_signal(signal.SIGTERM)
    endpoint.wait(20)
    data = load_rrd(received)
    check_channels(data, rec.samples)
    assert data["impacts/table"].times.size == rec.impacts > 0

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        closed = s.getsockname()[1]
    result = subprocess.run(["rimd", "rerun", str(rec.path), "--connect", f"rerun+http://127.0.0.1:{closed}/proxy"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1 and "no Rerun viewer or server at" in result.stderr, result.stderr


@pytest.mark.parametrize("case", ["missing", "garbage", "no_rig_topics", "save_is_directory", "save_under_file"])
@pytest.mark.process
def test_offline_bad_input_is_one_clear_line(tmp_path, case):
    mcap = tmp_path / "rec.mcap"
    save = tmp_path / "out.rrd"
    expect = {"missing": "no such file", "garbage": "not a readable MCAP file", "no_rig_topics": "no rig topic",
              "save_is_directory": "cannot write", "save_under_file": "cannot create"}[case]
    if case == "garbage":
        mcap.write_bytes(b"this is not an mcap file\n" * 100)
    elif case == "no_rig_topics":
        from mcap_ros2.writer import Writer

        with open(mcap, "wb") as fh:
            writer = Writer(fh)
            schema = writer.register_msgdef("std_msgs/msg/String", "string data\n")
            writer.write_message("/chatter", schema, {"data": "hello"}, log_time=0, publish_time=0)
            writer.finish()
    elif case != "missing":
        write_rig_mcap(mcap, seconds=0.1)
        save = tmp_path if case == "save_is_directory" else mcap / "out.rrd"
    result = subprocess.run(["rimd", "rerun", str(mcap), "--save", str(save)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 1, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rimd rerun: ") and expect in lines[0], result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.ros
@pytest.mark.timeout(60)
def test_node_refuses_an_unknown_sink(ros_processes):
    bridge = ros_processes.start_node("rimd_rerun", "--ros-args", "-p", "sink:=carrier_pigeon")
    assert bridge.wait(30) == 1
    assert ("rimd_rerun: parameter 'sink' = 'carrier_pigeon' refused: must be one of: save, spawn, connect, "
            "serve_web") in bridge.output()
    assert "Traceback" not in bridge.output()


@pytest.mark.ros
@pytest.mark.timeout(60)
def test_web_sink_serves_on_loopback_with_usage_reporting_off(ros_processes, tmp_path, repo_root):
    """``rimd node rerun`` with the default config: the serve_web sink."""
    cache = tmp_path / "cache"
    bridge = ros_processes.start_python("-m", "rimd_sim.cli", "node", "rerun", "--ros-args", "--params-file",
                                        str(repo_root / "config" / "rimd.yaml"), name="rimd_node_rerun",
                                        env={"XDG_CACHE_HOME": str(cache)})
    match = bridge.wait_for_output(r"sink serve_web -> (http://127\.0\.0\.1:(\d+)/\?url=rerun\+http://127\.0\.0\.1:"
                                   r"(\d+)/proxy)", timeout=30)
    with urllib.request.urlopen(f"http://127.0.0.1:{match.group(2)}/", timeout=10) as response:
        assert response.status == 200
    # A node process returns its heap's free pages from a thread of its own (rimd_sim.runtime.heap).
    threads = [Path(task, "comm").read_text().strip() for task in Path(f"/proc/{bridge.pid}/task").iterdir()]
    assert "rimd-heap" in threads, threads
    # The server keeps the config's history for viewers that connect later, not the viewer's memory limit.
    section = read_ros_parameters(repo_root / "config" / "rimd.yaml", node="rimd_rerun")
    assert section["server_memory_limit"] != section["memory_limit"]
    servers = [pid for pid in os.listdir("/proc") if pid.isdigit()
               and f"--port\0{match.group(3)}\0" in _cmdline(pid)]
    assert len(servers) == 1, servers
    argv = _cmdline(servers[0]).split("\0")
    assert argv[argv.index("--server-memory-limit") + 1] == section["server_memory_limit"], argv
    listening = subprocess.run(["ss", "-ltnH"], capture_output=True, text=True).stdout
    for port in (match.group(2), match.group(3)):
        addresses = {line.split()[3] for line in listening.splitlines() if line.split()[3].endswith(f":{port}")}
        assert addresses == {f"127.0.0.1:{port}"}, addresses
    # The Rerun configuration the bridge and its viewer read says: no usage reporting.
    config = cache / "rimd" / "rerun_config"
    shown = subprocess.run([_rerun_cli(), "analytics", "config"], capture_output=True, text=True, timeout=30,
                           env={"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "XDG_CONFIG_HOME": str(config)})
    assert json.loads(shown.stdout)["analytics_enabled"] is False, shown.stdout
    assert bridge.stop() == 0, bridge.tail()
    after = subprocess.run(["ss", "-ltnH"], capture_output=True, text=True).stdout
    assert f":{match.group(3)} " not in after, "the Rerun server the bridge started is stopped with it"


def test_sample_times_are_the_simulators_stamps_exactly():
    """``n / rate`` in integer ns, rounded half up like the simulator's stamps, without overflow far out
    (10^7 s: 116 days of samples, where ``n * 10^9`` no longer fits in int64 at 20 kHz)."""
    from fractions import Fraction

    for rate in (2000.0, 20000.0, 1000.0, 3.0, 1234.5):
        for first in (0, 7, int(rate * 1e7) + 3):
            got = sample_times_ns(first, 50, rate)
            r = Fraction(repr(rate))
            want = [(2 * n * 1_000_000_000 * r.denominator + r.numerator) // (2 * r.numerator)
                    for n in range(first, first + 50)]
            tolerance = 0 if rate.is_integer() else 2_000  # float64 fallback for non-integer rates
            assert np.max(np.abs(got - np.array(want, dtype=np.int64))) <= tolerance, (rate, first)


@pytest.mark.process
def test_mapping_and_offline_path_import_without_ros():
    code = ("import sys; sys.modules['rclpy'] = None; sys.modules['rimd_msgs'] = None\n"
            "import rimd_sim.viz.rerun_map, rimd_sim.viz.sinks, rimd_sim.viz.mcap_source, rimd_sim.viz.rrd_data\n"
            "import rimd_sim.cli.verbs.rerun\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr


def test_a_batch_of_blocks_gets_the_times_each_block_would_get_alone():
    """The bridge times a batch of consecutive blocks in one call; across a hole or a rate change, block by block:
    the same times either way."""
    from rimd_sim.viz.rerun_map import _block_times

    def alone(blocks):
        return np.concatenate([sample_times_ns(f, n, r) for f, r, n in blocks])

    for blocks in ([(0, 2000.0, 20)], [(40, 2000.0, 20), (60, 2000.0, 20), (80, 2000.0, 7)],
                   [(0, 3.0, 5), (5, 3.0, 5)],            # a rate whose sample times round
                   [(0, 2000.0, 20), (40, 2000.0, 20)],   # a hole (a dropped block)
                   [(0, 2000.0, 20), (20, 1000.0, 10)]):  # another rate
        assert np.array_equal(_block_times(blocks), alone(blocks)), blocks


@pytest.mark.process
@pytest.mark.timeout(120)
def test_a_memory_limit_is_refused_exactly_when_the_rerun_server_would_refuse_it():
    """The bridge checks ``memory_limit`` and ``server_memory_limit`` before it starts a viewer or server, where
    Rerun would refuse a bad one out of sight: its verdict is the server's own, on the forms users write."""
    from rimd_sim.viz.sinks import BAD_MEMORY_LIMITS, memory_limit_problem

    values = ("16MiB", "1GiB", "500MB", "1.5GiB", "12kB", "100B", "64 MiB", "10%", "0", "unlimited",
              *BAD_MEMORY_LIMITS, "1GB ", "2.5%", "16mb", "1.5B")
    for value in values:
        server = subprocess.Popen([_rerun_cli(), "--serve-web", "--bind", "127.0.0.1", "--port", "0",
                                   "--web-viewer-port", "0", f"--server-memory-limit={value}"],
                                  stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                  text=True, start_new_session=True)
        try:
            # The server says it listens once it has read its limit, or exits saying the limit is bad.
            said = ""
            for line in server.stderr:
                said += line
                if "Listening for gRPC connections" in line or "Bad --server-memory-limit" in line:
                    break
        finally:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait(30)
        assert ("Listening for gRPC connections" in said) != ("Bad --server-memory-limit" in said), (value, said)
        accepted = "Listening for gRPC connections" in said
        assert (memory_limit_problem(value) is True) == accepted, (value, said)
    # The bridge's refusal names the parameter, the value and what is wrong with it.
    from rimd_sim.viz.sinks import SinkError, SinkSpec

    for value, why in (("1G", "must be a Rerun memory limit (64MiB"), ("150%", "at most 100%")):
        with pytest.raises(SinkError) as refused:
            SinkSpec("serve_web", server_memory_limit=value).validate()
        assert str(refused.value).startswith(f"server_memory_limit '{value}' is not a memory limit: "), refused.value
        assert why in str(refused.value) and "must be a percentage" not in str(refused.value), refused.value


def _cmdline(pid: str) -> str:
    """A process's command line, arguments separated by NUL ("" when it is gone)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_text(errors="replace")
    except OSError:
        return ""
