"""Soak benchmark of the rig of ``make run``: ``rimd rig`` for --minutes, then the whole recording checked.

What it runs: exactly ``rimd rig`` (the default config/rimd.yaml: recorder, Rerun bridge with its default sink
serve_web on loopback, simulator at real time), recording into a fresh temporary directory, on a ROS domain of
its own: a ROS_DOMAIN_ID leased with the test suite's lock files (tests/harness/domains.py, so a concurrent
``make test`` never shares it), ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, ROS_LOG_DIR in the temporary
directory. The run starts when the rig says it runs from sample 0 and lasts --minutes of wall time; then the
rig is stopped with SIGINT, as Ctrl-C on ``make run`` does, and must exit 0. Ctrl-C on the bench ends the
soak early: the rig is stopped the same way and the figures cover the time run.

Goals: nothing lost; resident memory growth <= 5 MB per hour per process; block lateness
p99 <= 5 ms. Each goal gets a verdict line, "met" or "NOT met".

Figures printed (and written as JSON with --json; MB = 10^6 bytes, ms = 10^-3 s):
  * per process of the rig (the composed rig, which runs the simulator, the recorder and the Rerun bridge in
    one process; with --separate the simulator, the recorder and the Rerun bridge each in its own; the Rerun
    server that the bridge starts for its serve_web sink, the ``rimd rig`` parent; found as descendants of the
    rig's process), their sum, and this bench, from /proc every --period s (default 5), from sample 0 to the
    stop (start-up excluded): CPU in % of one core (utime + stime over wall time: mean over the run, and the
    worst period), resident memory (VmRSS) at the start, the end, the peak, at nine points in time, and its
    growth in MB per hour: the least-squares slope (numpy.polyfit) of RSS over the samples after the first
    minute (runs of less than two minutes: over their second half, said in the printout; so short a fit is
    noise, not a verdict). The memory goal is judged for every process of the rig. The Rerun server keeps the
    data a viewer that connects later receives, up to the bridge's server_memory_limit (config/rimd.yaml), so it
    grows until that is full, by design; it is judged all the same, with that note. Beside it, the slope over
    the run's second half (the steady state, once such a history is full), not judged;
  * loss, from the recording, every message read: each block topic (SampleBlock / RigState) must start at
    first_index 0 and be contiguous (each block's first_index = the previous one's + its sample count):
    messages, samples, holes, lost samples, and the simulated time where it ends (all topics end at the same
    block: otherwise the tail of one was lost); /rig/impact/events: ``index`` contiguous from 0;
    /rig/motor/state: one per block, stamped at the block's end, counted against the blocks since sample 0;
    whether every file of the recording is complete; the recorder's own loss report (its final summary) and
    the Rerun bridge's gap count (informational: the rig does not wait for the bridge at start);
  * lateness, two kinds, never mixed:
      - simulator pacing lateness, from the simulator's own /diagnostics (recorded by the recorder): how late
        each block was published behind its due time (monotonic clock). Each 1 s report holds p50 and p99
        over the last <= 1000 blocks (10 s at 100 blocks/s); printed: the median of the reported p50s, the
        median and the maximum of the reported p99s, and the overruns (blocks later than one block period);
      - per topic, from the recording, every block: due = header.stamp + samples / sample_rate (at real time
        the stamps are wall clock: the stamp of the block's first sample, so stamp + duration is when the
        block's last sample period ends); "publish" = the DDS source timestamp (MCAP publish_time) - due,
        "delivery" = the recorder's receive time (MCAP log_time) - due; p50, p99 and max. Both include a
        constant 0..1 ms (the simulator's wall-clock t0 is the time of its resume floored to the millisecond)
        and the time spent publishing the topics before it in the same block (cart first, truth last).
    The lateness goal is judged on both: the worst 10 s window of the simulator's p99, and the worst topic's
    delivery p99 over every block.

Run (after ``source env.sh``, from the repository root):
    python benchmarks/bench_soak.py --minutes 60 [--separate] [--json soak.json] [--keep] [--period 5]
The exit status is 0 whenever the soak ran and was analysed, whatever the verdicts (read the goal lines);
a short run (--minutes 1) checks the bench and the loss, its memory growth figures are noise.
--keep (or BENCH_KEEP=1) keeps the temporary directory (recording, rig.log, ROS logs). It needs about 1.5 GB
of disk per hour in the temporary directory (TMPDIR). The analysis reads about 2.2 million messages per hour
of recording (its time is printed).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import signal
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from array import array
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent

BLOCK_TOPICS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force",
                "/rig/truth")
EVENTS_TOPIC = "/rig/impact/events"
MOTOR_TOPIC = "/rig/motor/state"
DIAG_TOPIC = "/diagnostics"

#: ``python -m rimd_sim.ros.nodes._entry NAME`` of the rig's children -> name in the report, in report order.
NODES = {"simulator": "simulator", "recorder": "recorder", "rerun": "rerun bridge"}
#: The composed rig's process (``rimd rig`` by default): the three nodes in one.
COMPOSED = "composed rig"
PARENT = "rimd rig (parent)"
RERUN_SERVER = "rerun server"
BENCH = "this bench"

GOAL_GROWTH_MB_PER_H = 2.0   # MB/h: flat memory over a long run
GOAL_P99_MS = 5.0
WARMUP_S = 60.0

CLK_TCK = os.sysconf("SC_CLK_TCK")
RUNNING = "the rig runs from sample 0"
RESUMED_ANYWAY = "the rig runs anyway"


# ---- processes ---------------------------------------------------------------------------------------------

def read_stat(pid: int) -> tuple[int, int] | None:
    """``(ppid, utime + stime in clock ticks)`` of a process, None if it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()   # fields 3.. of proc(5); comm may hold spaces
    return int(fields[1]), int(fields[11]) + int(fields[12])


def thread_ticks(pid: int) -> dict[int, tuple[str, int]]:
    """``{tid: (kernel name, utime + stime in clock ticks)}`` of every thread of a process (empty if it is gone)."""
    out = {}
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for tid in tids:
        try:
            text = Path(f"/proc/{pid}/task/{tid}/stat").read_text()
        except OSError:
            continue   # the thread ended meanwhile
        fields = text[text.rindex(")") + 2:].split()
        out[int(tid)] = (text[text.index("(") + 1:text.rindex(")")], int(fields[11]) + int(fields[12]))
    return out


#: How the per-thread CPU of a rig process is grouped: the rig's own threads by their name
#: (rimd_sim.runtime.threads.OS_NAMES), the libraries' by their prefixes.
THREAD_GROUPS = (("Fast DDS", ("dds.",)), ("Rerun SDK", ("ChunkBatcher", "RecordingStream", "message_proxy",
                                                         "tokio-", "jemalloc", "re_")))


def thread_cpu(pid: int, before: dict[int, tuple[str, int]], after: dict[int, tuple[str, int]],
               seconds: float) -> dict[str, float]:
    """CPU per thread group of process ``pid`` between two :func:`thread_ticks`, in % of one core.

    The main thread is ``main``; a thread named by the rig (``rimd-*``) is its own group; the libraries' threads
    are grouped (:data:`THREAD_GROUPS`); the rest (unnamed Python threads, ROS's) is ``other``. A thread that
    ended between the two readings is missing from both sums (its CPU is not counted).
    """
    groups: dict[str, float] = {}
    for tid, (name, ticks) in after.items():
        used = ticks - before.get(tid, (name, 0))[1]
        if tid == pid:
            group = "main"
        elif name.startswith("rimd-"):
            group = name
        else:
            group = next((g for g, prefixes in THREAD_GROUPS if name.startswith(prefixes)), "other")
        groups[group] = groups.get(group, 0.0) + 100.0 * used / CLK_TCK / seconds
    return dict(sorted(groups.items(), key=lambda kv: -kv[1]))


def read_rss_kb(pid: int) -> int | None:
    """VmRSS of a process in kB (KiB), None if it is gone."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return 0   # a zombie has no VmRSS line


def descendants(root: int) -> list[int]:
    """Every process below ``root`` (children, grandchildren, ...)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            stat = read_stat(int(entry))
            if stat is not None:
                children.setdefault(stat[0], []).append(int(entry))
    found, todo = [], [root]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def rig_processes(rig_pid: int) -> dict[str, int]:
    """The rig's processes by report name: the parent, the nodes (by their command line) and their children.

    The Rerun bridge's sink serve_web runs a Rerun server (``rerun --serve-web``) as a child process: it holds
    the data a viewer that connects later receives, up to the bridge's ``server_memory_limit``
    (config/rimd.yaml).
    """
    found = {PARENT: rig_pid}
    for pid in descendants(rig_pid):
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
        except OSError:
            continue
        if "rimd_sim.ros.nodes._entry" in argv:
            entry = argv[argv.index("rimd_sim.ros.nodes._entry") + 1]
            found[{**NODES, "composed": COMPOSED}.get(entry, entry)] = pid
        elif "--serve-web" in argv:
            found[RERUN_SERVER] = pid
        else:
            found[f"{Path(argv[0]).name[:13]} ({pid})"] = pid
    return found


@dataclass
class Series:
    """Samples of one process: time since the start (s), CPU time (s), RSS (MB)."""

    pid: int
    t: list[float] = field(default_factory=list)
    cpu: list[float] = field(default_factory=list)
    rss: list[float] = field(default_factory=list)

    def sample(self, now: float) -> None:
        stat, rss = read_stat(self.pid), read_rss_kb(self.pid)
        if stat is not None and rss is not None:
            self.t.append(now)
            self.cpu.append(stat[1] / CLK_TCK)
            self.rss.append(rss * 1024 / 1e6)


def sample_run(rig: subprocess.Popen, procs: dict[str, int], seconds: float, period: float) -> dict[str, Series]:
    """Sample every process each ``period`` s for ``seconds`` (or until Ctrl-C or the rig ends).

    The rig's processes are looked for again at every sample: one started after ``procs`` was taken (the composed
    rig opens its Rerun sink, and so starts the Rerun server, after it runs) is sampled from the first sample that
    finds it, and added to ``procs``.
    """
    series = {name: Series(pid) for name, pid in procs.items()}
    t0 = time.monotonic()
    self_cpu0 = _self_cpu()
    tick = 0
    try:
        while True:
            now = time.monotonic() - t0
            for name, pid in rig_processes(rig.pid).items():
                if name not in series and pid not in procs.values():
                    procs[name] = pid
                    series[name] = Series(pid)
            for s in series.values():
                s.sample(now)
            if now >= seconds or rig.poll() is not None:
                break
            tick += 1
            time.sleep(max(0.0, min(tick * period, seconds) - (time.monotonic() - t0)))
    except KeyboardInterrupt:
        print(f"bench_soak: interrupted after {time.monotonic() - t0:.0f} s; stopping the rig and analysing "
              "the time run", flush=True)
    wall = time.monotonic() - t0
    bench = Series(os.getpid(), [0.0, wall], [0.0, _self_cpu() - self_cpu0],
                   [read_rss_kb(os.getpid()) * 1024 / 1e6] * 2)
    series[BENCH] = bench
    return series


def _self_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _slope(s: Series, picks: list[int]) -> float:
    """The least-squares slope of RSS over the samples ``picks``, in MB per hour."""
    t_h = np.array([s.t[i] for i in picks]) / 3600.0
    return float(np.polyfit(t_h, np.array([s.rss[i] for i in picks]), 1)[0])


def process_figures(s: Series) -> dict:
    """CPU and memory figures of one process's samples."""
    out: dict = {"pid": s.pid, "samples": len(s.t)}
    if len(s.t) < 2:
        return out
    span = s.t[-1] - s.t[0]
    out["cpu_percent"] = 100.0 * (s.cpu[-1] - s.cpu[0]) / span if span > 0 else None
    windows = [100.0 * (c1 - c0) / (t1 - t0)
               for t0, t1, c0, c1 in zip(s.t, s.t[1:], s.cpu, s.cpu[1:], strict=False) if t1 > t0]
    out["cpu_percent_worst_period"] = max(windows) if windows else None
    out["rss_start_mb"], out["rss_end_mb"], out["rss_peak_mb"] = s.rss[0], s.rss[-1], max(s.rss)
    half = [i for i, t in enumerate(s.t) if t - s.t[0] >= span / 2]
    after = [i for i, t in enumerate(s.t) if t - s.t[0] >= WARMUP_S]
    if len(after) >= 3 and s.t[after[-1]] - s.t[after[0]] >= WARMUP_S:
        out["fit"] = f"samples after the first {WARMUP_S:.0f} s"
    else:   # a short run: fit its second half
        after = half
        out["fit"] = f"second half of a short run ({span / 2:.0f} s on)"
    if len(after) >= 2:
        out["growth_mb_per_h"] = _slope(s, after)
        out["fit_window_s"] = [s.t[after[0]], s.t[after[-1]]]
    if len(half) >= 2:
        out["growth_second_half_mb_per_h"] = _slope(s, half)
    out["rss_series"] = [[round(t, 1), round(r, 3)] for t, r in zip(s.t, s.rss, strict=True)]
    return out


# ---- the rig -----------------------------------------------------------------------------------------------

def lease_domain():  # harness.domains.DomainLease
    """A ROS_DOMAIN_ID no test run on this machine uses while we hold it (the test suite's leases)."""
    sys.path.insert(0, str(REPO / "tests"))
    from harness.domains import lease_domain_id

    return lease_domain_id()


def start_rig(tmp: Path, domain_id: int, seconds: float, options: tuple[str, ...] = (),
              tree: Path | None = None) -> subprocess.Popen:
    """``rimd rig OPTIONS`` recording into ``tmp/rec``, its output in ``tmp/rig.log``.

    ``tree``: another checkout of the project (set up, e.g. a worktree of an older commit) whose package runs
    instead, as ``python -m rimd_sim.cli`` with that tree's package first on the import path (its nodes are
    started the same way: they inherit the path).
    """
    if tree is None:
        rimd = shutil.which("rimd")
        if rimd is None:
            raise SystemExit("rimd not on PATH: run `source env.sh` first")
        command, env = [rimd], dict(os.environ)
    else:
        from bench_latency import environment

        command, env = [sys.executable, "-m", "rimd_sim.cli"], environment(tree)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(tmp / "ros_log"), PYTHONUNBUFFERED="1")
    env.pop("ROS_STATIC_PEERS", None)
    # --duration is only a backstop (the bench stops the rig with SIGINT after --minutes): should the bench
    # die, the rig stops by itself 5 minutes later.
    cmd = [*command, "rig", "--output-dir", str(tmp / "rec"), "--duration", f"{seconds + 300:.0f}", *options]
    log = (tmp / "rig.log").open("wb")
    return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
                            cwd=tmp, start_new_session=True)


def wait_running(rig: subprocess.Popen, log: Path, timeout: float) -> bool:
    """Wait for the rig to resume the simulator; True when it says every consumer connected first."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = log.read_text(errors="replace")
        if RUNNING in text:
            return True
        if RESUMED_ANYWAY in text:
            return False
        if rig.poll() is not None:
            raise SystemExit(f"rimd rig exited with {rig.returncode} before running:\n{text[-3000:]}")
        time.sleep(0.5)
    raise SystemExit(f"rimd rig did not start within {timeout:.0f} s:\n{log.read_text(errors='replace')[-3000:]}")


def stop_rig(rig: subprocess.Popen, procs: dict[str, int]) -> int:
    """SIGINT to ``rimd rig`` (it stops its nodes: simulator first, recorder last); return its exit status."""
    from rimd_sim.ros.bringup import stop_process

    stop_process(rig, ((signal.SIGINT, 120.0), (signal.SIGTERM, 30.0), (signal.SIGKILL, 10.0)),
                 on_timeout=lambda sig: print(f"bench_soak: rimd rig did not stop on {signal.Signals(sig).name}",
                                              file=sys.stderr))
    for name, pid in procs.items():   # only if the rig could not stop them: its own children, by pid
        if name != PARENT and read_stat(pid) is not None:
            print(f"bench_soak: {name} ({pid}) still runs after the rig: SIGKILL", file=sys.stderr)
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    return rig.returncode


@dataclass
class RigRun:
    """One bench run of ``rimd rig``: a temporary directory, a leased ROS domain, the rig once started.

    A context manager: on leaving, the rig (when still running) is stopped, the domain released and the
    directory removed unless kept (``keep``, or BENCH_KEEP=1 in the environment).
    """

    tmp: Path
    lease: object   # harness.domains.DomainLease
    keep: bool
    rig: subprocess.Popen | None = None

    @classmethod
    def open(cls, prefix: str, keep: bool) -> RigRun:
        return cls(Path(tempfile.mkdtemp(prefix=prefix)), lease_domain(), keep or bool(os.environ.get("BENCH_KEEP")))

    @property
    def domain_id(self) -> int:
        return self.lease.domain_id

    def start(self, seconds: float, startup_timeout: float, options: tuple[str, ...] = (),
              tree: Path | None = None) -> tuple[bool, dict[str, int]]:
        """Start ``rimd rig OPTIONS`` for ``seconds``; wait until it runs: (from sample 0, its processes).

        ``tree``: another checkout whose package runs (:func:`start_rig`).
        """
        self.rig = start_rig(self.tmp, self.domain_id, seconds, options, tree)
        from_sample_0 = wait_running(self.rig, self.tmp / "rig.log", startup_timeout)
        return from_sample_0, rig_processes(self.rig.pid)

    def __enter__(self) -> RigRun:
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self.rig is not None and self.rig.poll() is None:
            stop_rig(self.rig, rig_processes(self.rig.pid))
        self.lease.release()
        if self.keep:
            print(f"kept {self.tmp}")
        else:
            shutil.rmtree(self.tmp, ignore_errors=True)


def add_rig_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of both rig benches (this one and bench_rig) after their length."""
    parser.add_argument("--period", type=float, default=5.0, help="s between /proc samples (default 5)")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures to this JSON file")
    parser.add_argument("--keep", action="store_true", help="keep the temporary directory (also: BENCH_KEEP=1)")
    parser.add_argument("--startup-timeout", type=float, default=180.0, help="s for the rig to start (default 180)")


def write_json(result: dict, path: Path | None) -> None:
    """Write the figures to ``path`` (--json), when given."""
    if path is not None:
        path.write_text(json.dumps(result, indent=1) + "\n")
        print(f"\nfigures written to {path}")


# ---- the recording -----------------------------------------------------------------------------------------

_I32 = {True: struct.Struct("<iI"), False: struct.Struct(">iI")}


def stamp_ns(data: bytes) -> int:
    """header.stamp of a serialized message (CDR: sec int32 and nanosec uint32 first), in ns."""
    sec, nsec = _I32[bool(data[1] & 1)].unpack_from(data, 4)
    return sec * 1_000_000_000 + nsec


@dataclass
class BlockTopic:
    """Loss and lateness of one block topic, message by message."""

    messages: int = 0
    samples: int = 0
    first_index: int | None = None
    expected: int = 0
    holes: int = 0
    lost_samples: int = 0
    backwards: int = 0
    rate: float = 0.0
    first_stamp_ns: int = 0
    delivery_ns: array = field(default_factory=lambda: array("q"))
    publish_ns: array = field(default_factory=lambda: array("q"))

    def observe(self, first: int, count: int, stamp: int, log_time: int, publish_time: int) -> None:
        if self.first_index is None:
            self.first_index, self.first_stamp_ns = first, stamp
        elif first > self.expected:
            self.holes += 1
            self.lost_samples += first - self.expected
        elif first < self.expected:
            self.backwards += 1
        self.expected = first + count
        self.messages += 1
        self.samples += count
        due = stamp + round(count * 1e9 / self.rate)
        self.delivery_ns.append(log_time - due)
        self.publish_ns.append(publish_time - due if publish_time else 0)


def percentiles(values_ns: array) -> dict | None:
    if not values_ns:
        return None
    ms = np.frombuffer(values_ns, dtype=np.int64) / 1e6
    p50, p99 = np.percentile(ms, [50, 99])
    return {"p50_ms": float(p50), "p99_ms": float(p99), "max_ms": float(ms.max()), "min_ms": float(ms.min())}


def analyse_recording(path: Path, block_rate: float) -> dict:
    """Read every message of the recording: loss per topic, lateness per block topic, the simulator's reports."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message

    from rimd_msgs.msg import ImpactEvent, RigState, SampleBlock
    from rimd_sim.io.cdr import block_span
    from rimd_sim.io.reader import open_recording

    start = time.monotonic()
    recording = open_recording(path)
    types = {"rimd_msgs/msg/SampleBlock": SampleBlock, "rimd_msgs/msg/RigState": RigState}
    blocks = {topic: BlockTopic() for topic in BLOCK_TOPICS}
    events: list[int] = []
    motor = array("q")
    pacing: list[dict[str, str]] = []
    recorder_diag: dict[str, str] = {}
    counts: dict[str, int] = {}
    for msg in recording.messages():
        counts[msg.topic] = counts.get(msg.topic, 0) + 1
        topic = blocks.get(msg.topic)
        if topic is not None:
            first, count = block_span(msg.data)
            if topic.first_index is None:   # the sample rate, and a check of the fast path, from a full decode
                full = deserialize_message(msg.data, types[msg.type_name])
                topic.rate = full.sample_rate
                full_count = len(full.samples if isinstance(full, SampleBlock) else full.theta)
                full_stamp = full.header.stamp.sec * 1_000_000_000 + full.header.stamp.nanosec
                if (full.first_index, full_count, full_stamp) != (first, count, stamp_ns(msg.data)):
                    raise SystemExit(f"the fast path disagrees with the full decode on {msg.topic}")
            topic.observe(first, count, stamp_ns(msg.data), msg.log_time, msg.publish_time)
        elif msg.topic == MOTOR_TOPIC:
            motor.append(stamp_ns(msg.data))
        elif msg.topic == EVENTS_TOPIC:
            events.append(deserialize_message(msg.data, ImpactEvent).index)
        elif msg.topic == DIAG_TOPIC:
            for status in deserialize_message(msg.data, DiagnosticArray).status:
                values = {kv.key: kv.value for kv in status.values}
                if status.name.endswith(": pacing"):
                    pacing.append(values)
                elif status.name.endswith(": recording"):
                    recorder_diag = values
    read_s = time.monotonic() - start

    topics: dict[str, dict] = {}
    for name, b in blocks.items():
        end_s = b.expected / b.rate if b.rate else None
        topics[name] = {"messages": b.messages, "samples": b.samples, "starts_at_0": b.first_index == 0,
                        "first_index": b.first_index, "holes": b.holes, "lost_samples": b.lost_samples,
                        "backwards": b.backwards, "ends_at_s": end_s, "sample_rate": b.rate,
                        "lateness_publish": percentiles(b.publish_ns) if any(b.publish_ns) else None,
                        "lateness_delivery": percentiles(b.delivery_ns)}
    ends = [t["ends_at_s"] for t in topics.values() if t["ends_at_s"] is not None]
    period_ns = round(1e9 / block_rate)
    tails_agree = bool(ends) and max(ends) - min(ends) < 0.5 / block_rate

    # Motor states: one per block, stamped at the block's end: t0 + k / block_rate for block k = 1, 2, ...
    t0 = blocks["/rig/truth"].first_stamp_ns
    ks = sorted({round((s - t0) / period_ns) for s in motor}) if motor and t0 else []
    motor_expected = round(max(ends) * block_rate) if ends else 0
    motor_lost = max(0, motor_expected - len(ks)) + sum(1 for k in ks if k < 1 or k > motor_expected)
    topics[MOTOR_TOPIC] = {"messages": len(motor), "expected": motor_expected, "lost": motor_lost,
                           "starts_at_first_block": bool(ks) and ks[0] == 1, "duplicates": len(motor) - len(ks)}
    unique = sorted(set(events))
    topics[EVENTS_TOPIC] = {"messages": len(events), "first_index": unique[0] if unique else None,
                            "last_index": unique[-1] if unique else None,
                            "lost": (unique[-1] + 1 - len(unique)) if unique else 0,
                            "starts_at_0": not unique or unique[0] == 0, "duplicates": len(events) - len(unique)}

    pacing = [p for p in pacing if p.get("paused") != "true" and p.get("blocks_published", "0") != "0"]
    simulator: dict = {"reports": len(pacing)}
    if pacing:
        p50 = [float(p["lateness_p50_ms"]) for p in pacing]
        p99 = [float(p["lateness_p99_ms"]) for p in pacing]
        simulator.update({"p50_median_ms": statistics.median(p50), "p99_median_ms": statistics.median(p99),
                          "p99_max_ms": max(p99), "overruns": int(pacing[-1]["overruns"]),
                          "blocks_published": int(pacing[-1]["blocks_published"]),
                          "real_time_factor_achieved": float(pacing[-1]["real_time_factor_achieved"])})
    return {"files": [str(f) for f in recording.files], "complete": recording.complete,
            "file_reports": [r.describe() for r in recording.reports], "messages": sum(counts.values()),
            "messages_per_topic": counts, "bytes": sum(f.stat().st_size for f in recording.files),
            "read_seconds": read_s, "topics": topics, "tails_agree": tails_agree, "simulator": simulator,
            "recorder_last_diagnostics": recorder_diag}


def log_reports(log: str) -> dict:
    """The recorder's final loss summary and the Rerun bridge's last gap count, from the rig's output."""
    recorder = re.findall(r"^\s+(/\S+): (\d+) messages written; (.*)$", log, re.MULTILINE)
    bridge = re.findall(r"rimd_rerun: closed .*, (\d+) impacts, (\d+) gaps", log)
    status = re.findall(r"status: .*?(\d+) gaps; (.*)$", log, re.MULTILINE)
    return {"recorder_summary": {t: {"written": int(n), "report": r} for t, n, r in recorder},
            "recorder_summary_found": "recording finished:" in log,
            "recorder_reports_loss": "LOSS" in log,
            "bridge_gaps": int(bridge[-1][1]) if bridge else (int(status[-1][0]) if status else None),
            "bridge_last_status": status[-1][1] if status else None}


# ---- report ------------------------------------------------------------------------------------------------

def rig_names(procs: dict) -> list[str]:
    """The rig's processes in report order: the nodes' (or the composed rig's), then the others (Rerun server, ...)."""
    nodes = [n for n in (COMPOSED, *NODES.values()) if n in procs]
    return nodes + [n for n in procs if n not in nodes and n != BENCH]


def node_processes(separate: bool) -> list[str]:
    """The report names of the processes that run the nodes: the composed rig's one (the default), else one each."""
    return list(NODES.values()) if separate else [COMPOSED]


def rerun_memory_limit() -> str:
    from rimd_sim.settings.config import find_config_file, read_ros_parameters

    try:
        section = read_ros_parameters(find_config_file("rimd.yaml"), node="rimd_rerun")
        return str(section.get("server_memory_limit", "?"))
    except Exception:  # only a note in the report
        return "?"


def _f(value: float | None, fmt: str = ".1f") -> str:
    return "n/a" if value is None else format(value, fmt)


def _verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


def report(result: dict) -> None:
    run, procs, rec, logs = result["run"], result["processes"], result["recording"], result["logs"]
    print()
    layout = "one process each, --separate" if run.get("separate") else "composed in one process"
    print(f"soak of `rimd rig` (recorder, Rerun bridge, simulator at real time, {layout}; config/rimd.yaml): "
          f"{run['seconds']:.1f} s of wall time from sample 0 "
          f"({'every consumer connected first' if run['from_sample_0'] else 'resumed WITHOUT all consumers'}), "
          f"ROS_DOMAIN_ID {run['domain_id']} on localhost; rig exit status {run['rig_exit_status']}")

    print(f"\nprocesses: CPU in % of one core (mean over the run; worst {run['period']:g} s period); RSS in MB "
          f"(10^6 bytes); growth = least-squares slope of RSS in MB per hour (judged), and over the run's "
          f"second half")
    print(f"  {'process':<20} {'pid':>7} {'CPU mean':>9} {'worst':>7} {'RSS start':>10} {'end':>8} {'peak':>8} "
          f"{'growth MB/h':>12} {'2nd half':>9}  fit over")
    rig = rig_names(procs)
    for name in [*rig, BENCH]:
        p = procs[name]
        if "cpu_percent" not in p:
            print(f"  {name:<20} {p['pid']:>7}  (too few samples)")
            continue
        print(f"  {name:<20} {p['pid']:>7} {_f(p['cpu_percent']):>8}% {_f(p['cpu_percent_worst_period']):>6}% "
              f"{_f(p['rss_start_mb']):>10} {_f(p['rss_end_mb']):>8} {_f(p['rss_peak_mb']):>8} "
              f"{_f(p.get('growth_mb_per_h'), '+.1f'):>12} {_f(p.get('growth_second_half_mb_per_h'), '+.1f'):>9}"
              f"  {p.get('fit', '') if name != BENCH else ''}")
        if name == rig[-1]:
            known = [procs[n] for n in rig if procs[n].get("cpu_percent") is not None]
            print(f"  {'all rig processes':<20} {'':>7} {_f(sum(q['cpu_percent'] for q in known)):>8}% {'':>7} "
                  f"{_f(sum(q['rss_start_mb'] for q in known)):>10} {_f(sum(q['rss_end_mb'] for q in known)):>8}")
    series = {n: procs[n]["rss_series"] for n in rig if procs[n].get("rss_series")}
    if series:
        times = max(series.values(), key=len)
        picks = sorted({round(i * (len(times) - 1) / 8) for i in range(9)})
        print("  RSS over time, MB:     t = " + " ".join(f"{times[i][0]:>7.0f}s" for i in picks))
        for name, s in series.items():
            print(f"    {name:<24}" + " ".join(f"{s[i][1]:>8.1f}" for i in picks if i < len(s)))

    print(f"\nrecording: {len(rec['files'])} file(s), {rec['bytes'] / 1e6:.1f} MB, {rec['messages']} messages, "
          f"every file complete: {rec['complete']}; read and checked in {rec['read_seconds']:.1f} s")
    for line in rec["file_reports"]:
        if "complete," not in line:
            print(f"  {line}")
    print("loss (every block checked from sample 0 with first_index):")
    print(f"  {'topic':<24} {'messages':>9} {'samples':>11} {'from 0':>7} {'holes':>6} {'lost samples':>13} "
          f"{'ends at (simulated s)':>22}")
    for name in BLOCK_TOPICS:
        t = rec["topics"][name]
        print(f"  {name:<24} {t['messages']:>9} {t['samples']:>11} {'yes' if t['starts_at_0'] else 'NO':>7} "
              f"{t['holes']:>6} {t['lost_samples']:>13} {_f(t['ends_at_s'], '.3f'):>22}"
              + (f"  ({t['backwards']} blocks went backwards)" if t["backwards"] else ""))
    print(f"  block topics end at the same block: {'yes' if rec['tails_agree'] else 'NO (a tail was lost)'}")
    e = rec["topics"][EVENTS_TOPIC]
    print(f"  {EVENTS_TOPIC:<24} {e['messages']:>9} events, index {e['first_index']}..{e['last_index']}, "
          f"lost {e['lost']}, from 0: {'yes' if e['starts_at_0'] else 'NO'}, duplicates {e['duplicates']}")
    m = rec["topics"][MOTOR_TOPIC]
    print(f"  {MOTOR_TOPIC:<24} {m['messages']:>9} states, expected {m['expected']} (one per block since sample 0), "
          f"lost {m['lost']}, duplicates {m['duplicates']}")
    summary = ("not found in its output" if not logs["recorder_summary_found"] else
               ("LOSS reported" if logs["recorder_reports_loss"] else "no loss"))
    print(f"  the recorder's own final summary: {summary}; the Rerun bridge's gaps (dropped blocks, informational; "
          f"the rig does not wait for the bridge at start): {logs['bridge_gaps']}")

    sim = rec["simulator"]
    print("\nlateness (ms):")
    if sim.get("reports"):
        print(f"  simulator pacing, its /diagnostics ({sim['reports']} reports at 1 s, each over its last <= 1000 "
              f"blocks): p50 median {sim['p50_median_ms']:.3f}; p99 median {sim['p99_median_ms']:.3f}, "
              f"worst {sim['p99_max_ms']:.3f}; overruns {sim['overruns']} of {sim['blocks_published']} blocks; "
              f"achieved real-time factor {sim['real_time_factor_achieved']:.3f}")
    else:
        print("  simulator pacing: no /diagnostics report of the simulator in the recording")
    print("  every block, from the recording: due = stamp + samples/rate; publish = DDS source time - due, "
          "delivery = recorder receive time - due")
    print(f"  {'topic':<24} {'publish p50':>12} {'p99':>8} {'max':>8}   {'delivery p50':>12} {'p99':>8} {'max':>8}")
    for name in BLOCK_TOPICS:
        t = rec["topics"][name]
        pub, dlv = t["lateness_publish"] or {}, t["lateness_delivery"] or {}
        print(f"  {name:<24} {_f(pub.get('p50_ms'), '.3f'):>12} {_f(pub.get('p99_ms'), '.3f'):>8} "
              f"{_f(pub.get('max_ms'), '.1f'):>8}   {_f(dlv.get('p50_ms'), '.3f'):>12} "
              f"{_f(dlv.get('p99_ms'), '.3f'):>8} {_f(dlv.get('max_ms'), '.1f'):>8}")

    print("\ngoals:")
    for goal in result["goals"].values():
        print(f"  {goal['goal']}: {_verdict(goal['met'])} ({goal['detail']})")


def goals(result: dict) -> dict:
    rec, logs, procs = result["recording"], result["logs"], result["processes"]
    t = rec["topics"]
    lost = {name: t[name]["lost_samples"] for name in BLOCK_TOPICS}
    nothing_lost = (all(t[n]["starts_at_0"] and not t[n]["holes"] and not t[n]["backwards"] for n in BLOCK_TOPICS)
                    and rec["tails_agree"] and t[EVENTS_TOPIC]["lost"] == 0 and t[EVENTS_TOPIC]["starts_at_0"]
                    and t[MOTOR_TOPIC]["lost"] == 0 and rec["complete"] and not logs["recorder_reports_loss"]
                    and logs["recorder_summary_found"] and all(t[n]["messages"] for n in BLOCK_TOPICS))
    out = {"nothing_lost": {
        "goal": "nothing lost", "met": bool(nothing_lost),
        "detail": f"lost samples per block topic {lost}, events lost {t[EVENTS_TOPIC]['lost']}, motor states lost "
                  f"{t[MOTOR_TOPIC]['lost']}, tails agree {rec['tails_agree']}, recording complete {rec['complete']}, "
                  f"recorder reports loss {logs['recorder_reports_loss']}"}}
    expected = node_processes(result["run"].get("separate", False))
    for name in dict.fromkeys([*expected, *rig_names(procs)]):   # every node process, found or not, and the rest
        growth = procs.get(name, {}).get("growth_mb_per_h")
        steady = procs.get(name, {}).get("growth_second_half_mb_per_h")
        note = (f"; it holds the data for viewers that connect later up to the bridge's server_memory_limit "
                f"({rerun_memory_limit()}), so it grows until then by design; over the run's second half "
                f"{_f(steady, '+.1f')} MB/h" if name == RERUN_SERVER else "")
        out[f"memory {name}"] = {
            "goal": f"memory growth <= {GOAL_GROWTH_MB_PER_H:g} MB/h, {name}",
            "met": growth is not None and growth <= GOAL_GROWTH_MB_PER_H,
            "detail": f"{_f(growth, '+.1f')} MB/h, {procs.get(name, {}).get('fit', 'process not found')}{note}"}
    sim = rec["simulator"]
    worst = sim.get("p99_max_ms")
    out["lateness_simulator"] = {
        "goal": f"p99 lateness <= {GOAL_P99_MS:g} ms, simulator pacing (/diagnostics, worst 10 s window)",
        "met": worst is not None and worst <= GOAL_P99_MS,
        "detail": f"worst p99 {_f(worst, '.3f')} ms, median p99 {_f(sim.get('p99_median_ms'), '.3f')} ms"}
    delivery = {n: (t[n]["lateness_delivery"] or {}).get("p99_ms") for n in BLOCK_TOPICS}
    known = [v for v in delivery.values() if v is not None]
    out["lateness_delivery"] = {
        "goal": f"p99 lateness <= {GOAL_P99_MS:g} ms, delivery to the recorder (every block, worst topic)",
        "met": bool(known) and len(known) == len(delivery) and max(known) <= GOAL_P99_MS,
        "detail": f"worst topic p99 {_f(max(known) if known else None, '.3f')} ms"}
    out["rig_exit"] = {"goal": "rimd rig exits 0 on SIGINT", "met": result["run"]["rig_exit_status"] == 0,
                       "detail": f"exit status {result['run']['rig_exit_status']}"}
    return out


def record_figures(result: dict) -> None:
    """The headline figures for report.py (benchmarks/_figures.py): loss, each node process's memory, lateness."""
    from _figures import record

    minutes, t = result["run"]["minutes"], result["recording"]["topics"]
    lost = sum(t[name]["lost_samples"] for name in BLOCK_TOPICS) + t[EVENTS_TOPIC]["lost"] + t[MOTOR_TOPIC]["lost"]
    record("soak", f"data lost in {minutes:g} min", lost, "", "<= 0")
    for name in node_processes(result["run"]["separate"]):
        growth = result["processes"].get(name, {}).get("growth_mb_per_h")
        record("soak", f"{name}: memory growth", growth, "MB/h", f"<= {GOAL_GROWTH_MB_PER_H:g}")
    sim = result["recording"]["simulator"]
    record("soak", "simulator pacing p99, worst 10 s window", sim.get("p99_max_ms"), "ms", f"<= {GOAL_P99_MS:g}")
    server = result["processes"].get(RERUN_SERVER, {})
    if server.get("rss_end_mb") is not None:
        record("soak", "Rerun server: memory growth", server.get("growth_mb_per_h"), "MB/h",
               f"<= {GOAL_GROWTH_MB_PER_H:g}")
        record("soak", "the same, second half",
               server.get("growth_second_half_mb_per_h"), "MB/h")
        record("soak", "Rerun server's memory at the end", server["rss_end_mb"], "MB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0, help="wall time of the soak from sample 0 (default 60)")
    parser.add_argument("--separate", action="store_true",
                        help="`rimd rig --separate`: each node in a process of its own (default: composed, one)")
    add_rig_arguments(parser)
    args = parser.parse_args()
    if args.minutes <= 0 or args.period <= 0:
        parser.error("--minutes and --period must be positive")
    seconds = args.minutes * 60.0

    from rimd_sim.settings.config import find_config_file, load_config

    block_rate = load_config(find_config_file("rimd.yaml")).block_rate
    with RigRun.open("bench_soak_", args.keep) as run:
        tmp = run.tmp
        print(f"bench_soak: {args.minutes:g} min of `rimd rig` in {tmp}, ROS_DOMAIN_ID {run.domain_id}; "
              f"sampling /proc every {args.period:g} s", flush=True)
        from_sample_0, procs = run.start(seconds, args.startup_timeout, ("--separate",) if args.separate else ())
        rig = run.rig
        missing = [n for n in node_processes(args.separate) if n not in procs]
        print(f"bench_soak: running from sample 0: {', '.join(f'{n} {p}' for n, p in procs.items())}"
              + (f"; NOT FOUND: {', '.join(missing)}" if missing else ""), flush=True)
        series = sample_run(rig, procs, seconds, args.period)
        wall = max(s.t[-1] for s in series.values() if s.t)
        early_exit = rig.poll()
        print("bench_soak: stopping the rig (SIGINT)", flush=True)
        status = stop_rig(rig, procs)
        if early_exit is not None:
            print(f"bench_soak: the rig ended by itself during the run (status {early_exit})", file=sys.stderr)
        print("bench_soak: reading the recording", flush=True)
        result: dict = {"run": {"minutes": args.minutes, "seconds": wall, "period": args.period,
                                "domain_id": run.domain_id, "rig_exit_status": status,
                                "from_sample_0": from_sample_0, "separate": args.separate, "tmp": str(tmp)}}
        result["processes"] = {name: process_figures(s) for name, s in series.items()}
        result["logs"] = log_reports((tmp / "rig.log").read_text(errors="replace"))
        from rimd_sim.io.reader import RecordingError

        try:
            result["recording"] = analyse_recording(tmp / "rec", block_rate)
        except RecordingError as exc:
            raise SystemExit(f"bench_soak: no readable recording: {exc}\nrig output (end):\n"
                             f"{(tmp / 'rig.log').read_text(errors='replace')[-3000:]}") from None
        result["goals"] = goals(result)
        report(result)
        record_figures(result)
        write_json(result, args.json)


if __name__ == "__main__":
    main()
