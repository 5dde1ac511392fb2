"""How fast the rig runs in lockstep with its recorder and Rerun bridge, against the open-loop rig, in one run.

Rigs one after the other, each the product's own bring-up (``rimd_sim.ros.bringup``, as ``rimd rig`` starts
it) with the default configuration, the recorder (into a temporary directory) and the Rerun bridge (sink
``save``, an .rrd in the same directory), on a ROS domain of its own:

* **lockstep**: ``--lockstep --real-time-factor 0``: the simulator waits for the recorder and the bridge;
* **free**: ``--real-time-factor 0`` without lockstep: the simulator as fast as it can (open loop).

Each in both layouts: the composed rig (the default: the recorder and the bridge in the simulator's process) and
separate processes (``--separate``). And the lockstep rig with an **external consumer**, in both layouts: a process
of its own (``benchmarks/_consumer.py``) that subscribes to the five block topics, counts them and reports its
progress on /rig/progress as a lockstep consumer (``bench_consumer``, named among the rig's consumers as
``rimd rig --lockstep --consumer bench_consumer`` does), with a ``ProgressReporter`` and ``done()`` after each
message (``--consumer batched``: a timer takes every waiting message and reports once per topic).

For each, after --warmup s of wall time, --seconds of wall time are measured: simulated seconds per wall second
(from the rig's /clock), CPU of each process in % of one core (utime + stime from /proc over the window), and
then, from the recording, whether anything was lost (every channel's first_index contiguous from sample 0); with the
external consumer, what it counted too (messages per topic, from sample 0, holes) and how many reports it sent.

The external consumer's hold-back of the rig: the fraction of wall time the rig waits on it, taken from the speeds
of the same layout with and without it in this one run, 1 - speed(with) / speed(without). It includes the CPU the
consumer takes from the rig on this 2-core machine, not only the waits for its reports (the simulator's diagnostics
say who holds the run only once a hold lasts a second). So the composed lockstep rig runs a third time with the
same process subscribed only (not a lockstep consumer: the rig does not wait for it; what it got is counted as
well): the speed lost from alone to subscribed is what its data costs (the DDS writes to another process, its
CPU), the speed lost from subscribed to reporting is what the waits for its reports cost.

``--compare DIR [--rounds 2]`` instead: this tree's composed rig in lockstep with the external consumer against
DIR's lockstep rig (another checkout, e.g. a worktree of the commit before the composed rig, whose lockstep rig
is the recorder and the bridge as processes), each with its own defaults, alternately (ABBA) in one run: the
ratio of goal 2 (at least twice). DIR's rig is started by its own benchmark's ``run`` with its package first on
PYTHONPATH (its numba cache warmed first: a cold one compiles during the warm-up). With ``--same-rig`` DIR's rig
has the external consumer too: a before/after of a change (DIR a checkout from the composed rig on).

Goals (docs/benchmarks.md, Lockstep): lockstep >= 20x real time on a 2-core
machine, and within 15 % of the free-running rate when the consumers keep up (the ratio is taken in this one run).
Goal of the external consumer: hold-back <= 5 % in the composed rig.
Run on an otherwise idle machine:
    python benchmarks/bench_lockstep.py [--seconds 30] [--warmup 8] [--json out.json] [--consumer batched]
                                        [--compare DIR [--rounds 2] [--same-rig]]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHANNELS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force",
            "/rig/truth")
TICKS = os.sysconf("SC_CLK_TCK")
HERE = Path(__file__).resolve().parent
CONSUMER = "bench_consumer"   # the external consumer's lockstep name
READER = "reader"   # the same process subscribed only: not a lockstep consumer, the rig does not wait for it
GOAL_HOLD_BACK = 0.05


def cpu_seconds(pid: int) -> float:
    """Utime + stime of a process (s), 0 when it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / TICKS


def loss(recording: Path) -> dict[str, str]:
    """Per channel: 'complete from 0' or what is missing."""
    from rimd_sim.io.cdr import block_span
    from rimd_sim.io.reader import open_recording

    out = {}
    rec = open_recording(recording)
    for topic in CHANNELS:
        spans = [block_span(m.data) for m in rec.messages([topic])]
        holes = [(a[0] + a[1], b[0], i) for i, (a, b) in enumerate(zip(spans, spans[1:], strict=False))
                 if b[0] != a[0] + a[1]]
        start = spans[0][0] if spans else None
        out[topic] = ("complete from sample 0" if start == 0 and not holes else
                      f"{len(holes)} holes (expected, got, block) {holes[:3]}, first index {start}, "
                      f"{len(spans)} blocks")
    return out


def start_consumer(run_dir: Path, env: dict, how: str) -> subprocess.Popen:
    """The external process (benchmarks/_consumer.py) in the rig's domain.

    Lockstep as ``bench_consumer``, or (``how`` ``reader``) a plain subscriber that the rig does not wait for.
    """
    cmd = [sys.executable, str(HERE / "_consumer.py"), "--out", str(run_dir / "consumer.json")]
    if how != READER:
        cmd += ["--lockstep", CONSUMER]
    if how == "batched":
        cmd.append("--batched")
    log = (run_dir / "consumer.log").open("wb")
    return subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            start_new_session=True)


def stop_consumer(proc: subprocess.Popen, run_dir: Path) -> dict:
    """SIGINT, its counts (or why there are none)."""
    from rimd_sim.ros.bringup import stop_process

    status = stop_process(proc)
    try:
        counts = json.loads((run_dir / "consumer.json").read_text())
    except (OSError, ValueError):
        tail = (run_dir / "consumer.log").read_text(errors="replace")[-2000:]
        return {"exit_status": status, "error": f"no counts; its log ends:\n{tail}"}
    return {"exit_status": status, **counts}


def consumer_loss(counts: dict, recording: dict[str, int]) -> dict[str, str]:
    """Per block topic: what the external consumer got against what the recorder recorded."""
    if "error" in counts:
        return {"all": counts["error"]}
    out = {}
    for topic, c in counts["topics"].items():
        ok = c["first_index"] == 0 and c["holes"] == 0 and c["messages"] == recording.get(topic)
        short = c["first_index"] == 0 and c["holes"] == 0 and c["messages"] > (recording.get(topic) or 0)
        out[topic] = ("all from sample 0, as many as recorded" if ok else
                      f"{c['messages']} messages (recorded {recording.get(topic)}), first index {c['first_index']}, "
                      f"{c['holes']} holes" + ("; the recording's tail is the shorter" if short else ""))
    return out


def run(mode: str, seconds: float, warmup: float, base: Path, window: float | None = None,
        separate: bool = False, consumer: str | None = None) -> dict:
    from rimd_sim.ros.bringup import Rig, plan_rig
    from rimd_sim.ros.clients.rig import RigClient
    from rimd_sim.ros.testing import lease_domain_id, ros_environment

    run_dir = Path(tempfile.mkdtemp(prefix=f"{mode}_{window}_", dir=base))   # a recording of its own
    external = None
    sim = {} if window is None or mode != "lockstep" else {"lockstep.window": window}
    with lease_domain_id() as lease:
        plan = plan_rig(None, output_dir=run_dir / "recording", lockstep=mode == "lockstep", real_time_factor=0.0,
                        parameters={"rimd_rerun": {"sink": "save", "save_path": str(run_dir / "rig.rrd")},
                                    "rimd_simulator": sim},
                        run_dir=run_dir, separate=separate,
                        consumers=[CONSUMER] if consumer and consumer != READER else [])
        env = ros_environment(lease.domain_id, run_dir / "ros_log")
        rig = Rig(plan, env=env, log_dir=run_dir / "logs")
        if consumer:   # the rig waits for it from its first block
            external = start_consumer(run_dir, dict(env), consumer)
        rig.start()
        try:
            from rclpy.qos import QoSProfile, ReliabilityPolicy
            from rosgraph_msgs.msg import Clock

            with RigClient(domain_id=lease.domain_id, name="bench_lockstep") as client:
                clock = [0]
                client.node.create_subscription(Clock, "/clock", lambda m: clock.__setitem__(
                    0, m.clock.sec * 1_000_000_000 + m.clock.nanosec), QoSProfile(
                    depth=10, reliability=ReliabilityPolicy.RELIABLE))
                if not plan.lockstep_consumers:   # open loop: resumed once the consumers subscribe
                    rig.resume_when_connected()
                if not client.spin_until(lambda: clock[0] > 0, 60):
                    logs = "\n".join(f"--- {f.name}\n" + "\n".join(f.read_text().splitlines()[-6:])
                                     for f in sorted((run_dir / "logs").glob("*.log")))
                    raise RuntimeError(f"the {mode} rig did not start (domain {lease.domain_id}):\n{logs}")
                client.spin_until(lambda: False, warmup)
                pids = {name: proc.pid for name, proc in rig.processes.items()}
                if external is not None:
                    pids[CONSUMER] = external.pid
                t0, s0, c0 = time.monotonic(), clock[0], {n: cpu_seconds(p) for n, p in pids.items()}
                client.spin_until(lambda: False, seconds)
                t1, s1, c1 = time.monotonic(), clock[0], {n: cpu_seconds(p) for n, p in pids.items()}
        finally:
            status = rig.stop()
            counts = stop_consumer(external, run_dir) if external is not None else None
    wall = t1 - t0
    result = {"mode": mode, "layout": "separate" if separate else "composed", "consumer": consumer,
              "speed": (s1 - s0) / 1e9 / wall, "wall_s": wall, "simulated_s": (s1 - s0) / 1e9,
              "cpu_percent": {n: 100 * (c1[n] - c0[n]) / wall for n in pids}, "exit_status": status,
              "loss": loss(plan.recording_dir)}
    if counts is not None:
        result["external"] = counts
        result["external_loss"] = consumer_loss(counts, recorded_blocks(plan.recording_dir))
    return result


#: Another checkout's lockstep rig with its own defaults, by its own benchmark's ``run`` (whose first four arguments
#: are the same in every checkout with lockstep): argv = its benchmarks directory, seconds, warm-up, the external
#: consumer or "-"; one JSON line out.
_OTHER_RUN = """
import json, sys, tempfile
from pathlib import Path
sys.path.insert(0, sys.argv[1])
import bench_lockstep
extra = {} if sys.argv[4] == "-" else {"consumer": sys.argv[4]}   # trees since the composed rig take it
with tempfile.TemporaryDirectory(prefix="bench_lockstep_other_") as tmp:
    r = bench_lockstep.run("lockstep", float(sys.argv[2]), float(sys.argv[3]), Path(tmp), **extra)
print(json.dumps({k: r.get(k) for k in ("speed", "cpu_percent", "loss", "layout", "external_loss")}))
"""


def run_other(tree: Path, seconds: float, warmup: float, consumer: str | None = None) -> dict:
    """``tree``'s lockstep rig (its package first on PYTHONPATH, its nodes started by its own bring-up)."""
    from bench_latency import environment

    out = subprocess.run([sys.executable, "-c", _OTHER_RUN, str(tree / "benchmarks"), str(seconds), str(warmup),
                          consumer or "-"],
                         env=environment(tree), capture_output=True, text=True, timeout=600 + seconds + warmup)
    if out.returncode:
        raise RuntimeError(f"{tree}'s lockstep rig failed (exit {out.returncode}):\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def compare(args: argparse.Namespace) -> dict:
    """This tree's composed rig in lockstep with the external consumer against ``args.compare``'s lockstep rig.

    DIR's rig with its defaults and no external consumer; alternately (ABBA), ``args.rounds`` each: goal 2's ratio.
    """
    import statistics

    other = args.compare.resolve()
    speeds: dict[str, list[float]] = {"this": [], "other": []}
    results: dict[str, list[dict]] = {"this": [], "other": []}
    with tempfile.TemporaryDirectory(prefix="bench_lockstep_") as tmp:
        for round_ in range(args.rounds):
            for name in (("this", "other") if round_ % 2 == 0 else ("other", "this")):
                load = " ".join(f"{x:.2f}" for x in os.getloadavg())
                if name == "this":
                    r = run("lockstep", args.seconds, args.warmup, Path(tmp), args.window, False, args.consumer)
                else:
                    r = run_other(other, args.seconds, args.warmup, args.consumer if args.same_rig else None)
                lost = [f"recording {t}" for t, v in r["loss"].items() if v != "complete from sample 0"]
                lost += [f"external {t}" for t, v in (r.get("external_loss") or {}).items()
                         if not v.startswith("all from sample 0")]
                speeds[name].append(r["speed"])
                results[name].append(r)
                cpu = ", ".join(f"{n} {c:.0f} %" for n, c in r["cpu_percent"].items())
                print(f"round {round_ + 1}, {name:>5}: {r['speed']:5.1f}x real time; CPU {cpu}; "
                      + (f"LOSS in {lost}" if lost else "nothing lost") + f" (load at its start {load})", flush=True)
    this, base = statistics.median(speeds["this"]), statistics.median(speeds["other"])
    ratios = [t / o for t, o in zip(speeds["this"], speeds["other"], strict=True)]
    external = "an external reader (not lockstep)" if args.consumer == READER else CONSUMER
    what = f"with {external} too" if args.same_rig else "no external consumer"
    print(f"this tree, composed lockstep with {external}: median {this:.1f}x; {other}'s lockstep rig (its defaults, "
          f"{what}): median {base:.1f}x; ratio median {statistics.median(ratios):.2f} (per round "
          f"{', '.join(f'{x:.2f}' for x in ratios)})")
    if not args.same_rig:
        print(f"goal at least twice that lockstep rig: {'met' if statistics.median(ratios) >= 2 else 'NOT met'}")
    return {"speeds": speeds, "ratios": ratios, "results": results}


def recorded_blocks(recording: Path) -> dict[str, int]:
    """Messages per block topic in the recording."""
    from rimd_sim.io.reader import open_recording

    rec = open_recording(recording)
    return {topic: sum(1 for _ in rec.messages([topic])) for topic in CHANNELS}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--warmup", type=float, default=8.0)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--window", type=float, default=None,
                        help="lockstep.window of the lockstep rig (s of simulation time; default: the rig's)")
    parser.add_argument("--compare-windows", type=float, nargs="+", default=None, metavar="W",
                        help="instead: only lockstep rigs, one per window, one after the other (their speeds)")
    parser.add_argument("--consumer", choices=("per-message", "batched", READER), default="per-message",
                        help="how the external consumer takes and reports (default: done() after each message; "
                             "reader: subscribed only, not a lockstep consumer)")
    parser.add_argument("--compare", type=Path, default=None, metavar="DIR",
                        help="instead: the composed rig with the external consumer against DIR's lockstep rig "
                             "(another checkout, its defaults), alternately")
    parser.add_argument("--rounds", type=int, default=2, help="with --compare: runs of each (default 2)")
    parser.add_argument("--same-rig", action="store_true",
                        help="with --compare: DIR's rig with the external consumer too (a before/after of a change; "
                             "DIR from the composed rig on)")
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    if args.compare is not None:
        from bench_latency import check_tree

        check_tree(args.compare)
        result = compare(args)
        print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
        if args.json:
            args.json.write_text(json.dumps(result, indent=1))
        return 0
    if args.compare_windows:
        with tempfile.TemporaryDirectory(prefix="bench_lockstep_") as tmp:
            for w in args.compare_windows:
                r = run("lockstep", args.seconds, args.warmup, Path(tmp), w)
                cpu = ", ".join(f"{n} {c:.0f} %" for n, c in r["cpu_percent"].items())
                lost = {t: v for t, v in r["loss"].items() if v != "complete from sample 0"}
                print(f"window {w:g} s: {r['speed']:.1f}x real time; CPU {cpu}; "
                      + (f"LOSS {lost}" if lost else "nothing lost"), flush=True)
        print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
        return 0
    with tempfile.TemporaryDirectory(prefix="bench_lockstep_") as tmp:
        # The composed rig (the default: recorder and bridge in the simulator's process) and separate processes,
        # side by side; then each in lockstep with the external consumer too.
        runs = [(separate, mode, None) for separate in (False, True) for mode in ("lockstep", "free")]
        runs += [(separate, "lockstep", args.consumer) for separate in (False, True)]
        runs.append((False, "lockstep", READER))   # what serving the external process's data costs, no waits
        results = [run(mode, args.seconds, args.warmup, Path(tmp), args.window, separate, consumer)
                   for separate, mode, consumer in runs]
    for r in results:
        cpu = ", ".join(f"{n} {c:.0f} %" for n, c in r["cpu_percent"].items())
        cpu += f"; total {sum(r['cpu_percent'].values()):.0f} %"
        label = r["mode"] + (" + external reader" if r["consumer"] == READER else
                             f" + {CONSUMER}" if r["consumer"] else "")
        print(f"{r['layout']:>9} {label:>24}: {r['speed']:6.1f}x real time ({r['simulated_s']:.1f} s simulated in "
              f"{r['wall_s']:.1f} s); CPU {cpu}; exit {r['exit_status']}")
        for topic, verdict in r["loss"].items():
            print(f"{'':>11}{topic}: {verdict}")
        if r["consumer"]:
            ext = r["external"]
            print(f"{'':>11}{'the reader' if r['consumer'] == READER else CONSUMER} ({r['consumer']}): exit "
                  f"{ext.get('exit_status')}, {ext.get('reports', '?')} progress reports")
            for topic, verdict in r["external_loss"].items():
                print(f"{'':>13}{topic}: {verdict}")
    by = {(r["layout"], r["mode"], r["consumer"]): r for r in results}
    lock, free = by["composed", "lockstep", None], by["composed", "free", None]
    ratio = lock["speed"] / free["speed"] if free["speed"] else float("nan")
    print(f"composed lockstep / free: {ratio:.3f}")
    hold = {}
    for layout in ("composed", "separate"):
        alone, with_it = by[layout, "lockstep", None], by[layout, "lockstep", args.consumer]
        hold[layout] = 1 - with_it["speed"] / alone["speed"] if alone["speed"] else float("nan")
        print(f"{layout} lockstep with {CONSUMER}: {with_it['speed']:.1f}x against {alone['speed']:.1f}x without: "
              f"hold-back {100 * hold[layout]:.1f} % of wall time")
    alone, reader, with_it = (by["composed", "lockstep", c] for c in (None, READER, args.consumer))
    if reader["speed"] and alone["speed"]:
        print(f"composed lockstep, {alone['speed']:.1f}x alone, {reader['speed']:.1f}x with the external process "
              f"subscribed only (the rig does not wait for it), {with_it['speed']:.1f}x with it reporting: its data "
              f"(the DDS writes to it, its CPU) {100 * (1 - reader['speed'] / alone['speed']):.1f} %, its reports "
              f"(the waits for them) {100 * (1 - with_it['speed'] / reader['speed']):.1f} % of the speed with it "
              f"subscribed")
    composed_ext, separate_ext = by["composed", "lockstep", args.consumer], by["separate", "lockstep", args.consumer]
    print(f"composed / separate, lockstep with {CONSUMER}: {composed_ext['speed'] / separate_ext['speed']:.3f}")
    print(f"goal lockstep >= 20x real time: {'met' if lock['speed'] >= 20 else 'NOT met'} ({lock['speed']:.1f}x)")
    print(f"goal lockstep within 15 % of free running: {'met' if ratio >= 0.85 else 'NOT met'} ({ratio:.3f})")
    print(f"goal external consumer's hold-back <= {100 * GOAL_HOLD_BACK:g} % (composed): "
          f"{'met' if hold['composed'] <= GOAL_HOLD_BACK else 'NOT met'} ({100 * hold['composed']:.1f} %)")
    from _figures import record  # the headline figures for report.py

    record("lockstep", "composed rig in lockstep", lock["speed"], "×", ">= 20")
    record("lockstep", "lockstep / free running", ratio, "", ">= 0.85")
    record("lockstep", "hold-back by a lockstep consumer", 100 * hold["composed"], "%",
           f"<= {100 * GOAL_HOLD_BACK:g}")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"results": results, "ratio": ratio, "hold_back": hold}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
