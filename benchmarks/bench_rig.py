"""CPU budget of the default rig at real time: ``rimd rig`` as ``make run`` starts it, for --seconds.

What it runs: exactly ``rimd rig`` with the default config/rimd.yaml (simulator at real time, recorder, Rerun
bridge with its default sink serve_web, which starts a Rerun server with the web viewer), recording into a
fresh temporary directory, on a ROS domain of its own (the test suite's leases, ROS_AUTOMATIC_DISCOVERY_RANGE
LOCALHOST). The measurement starts when the rig runs from sample 0, after --warmup s (default 10: start-up,
JIT loading and discovery are not the steady state), and lasts --seconds of wall time. The rig, the recording
and the /proc sampling are :mod:`bench_soak`'s, so both benches measure the same thing.

Printed (and written as JSON with --json):
  * per process (simulator, recorder, Rerun bridge, the Rerun server, the ``rimd rig`` parent), from /proc,
    not from the nodes' own reports: CPU in % of one core (utime + stime over the measured wall time; the
    worst --period s window), resident memory at the start and end of the measurement;
  * the traffic, from the recording: messages and bytes (serialized payload) per second per topic and in all;
  * loss: every block topic checked from sample 0 with ``first_index``, impact events by index, motor states
    one per block (bench_soak's checks);
  * the goals of the light-rig changes (docs/benchmarks.md): simulator <= 5 %, recorder <= 10 %, Rerun bridge
    <= 10 %, the whole rig <= 25 % of one core, nothing lost; each with "met" or "NOT met".
    "The whole rig" is every process the rig runs: the three nodes, the Rerun server that holds the web
    viewer's data (Rerun's own binary), and the ``rimd rig`` parent; the sum of the three nodes is printed too.

Run (after ``source env.sh``, from the repository root; the machine otherwise idle):
    python benchmarks/bench_rig.py [--seconds 120] [--json rig.json] [--keep]
The exit status is 0 whenever the rig ran and was measured, whatever the verdicts.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_soak as soak  # noqa: E402 - the rig and /proc sampling of the soak bench

GOALS_PERCENT = {"simulator": 5.0, "recorder": 10.0, "rerun bridge": 10.0}
GOAL_RIG_PERCENT = 25.0


def traffic(path: Path, seconds_of_data: float) -> dict:
    """Messages and serialized bytes per topic of the recording, and their rates over ``seconds_of_data``."""
    from rimd_sim.io.reader import open_recording

    counts: dict[str, list[int]] = {}
    for msg in open_recording(path).messages():
        c = counts.setdefault(msg.topic, [0, 0])
        c[0] += 1
        c[1] += len(msg.data)
    topics = {t: {"messages": n, "bytes": b, "messages_per_s": n / seconds_of_data,
                  "bytes_per_s": b / seconds_of_data} for t, (n, b) in sorted(counts.items())}
    return {"seconds_of_data": seconds_of_data, "topics": topics,
            "messages_per_s": sum(t["messages_per_s"] for t in topics.values()),
            "bytes_per_s": sum(t["bytes_per_s"] for t in topics.values())}


def rig_goals(procs: dict, nothing_lost: dict) -> dict:
    out = {}
    for name, limit in GOALS_PERCENT.items():
        cpu = procs.get(name, {}).get("cpu_percent")
        out[name] = {"goal": f"{name} <= {limit:g} % of one core", "met": cpu is not None and cpu <= limit,
                     "detail": f"{soak._f(cpu)} %"}
    rig = soak.rig_names(procs)
    total = sum(procs[n].get("cpu_percent") or 0.0 for n in rig)
    nodes = sum(procs.get(n, {}).get("cpu_percent") or 0.0 for n in GOALS_PERCENT)
    measured = all(procs.get(n, {}).get("cpu_percent") is not None for n in GOALS_PERCENT)
    out["rig"] = {"goal": f"the whole rig <= {GOAL_RIG_PERCENT:g} % of one core",
                  "met": measured and total <= GOAL_RIG_PERCENT,
                  "detail": f"{total:.1f} % ({', '.join(rig)}); the three nodes alone {nodes:.1f} %"}
    out["nothing_lost"] = nothing_lost
    return out


def report(result: dict) -> None:
    run, procs, flow = result["run"], result["processes"], result["traffic"]
    print(f"\nthe default rig (`rimd rig`, config/rimd.yaml) at real time: {run['seconds']:.1f} s measured after "
          f"{run['warmup']:g} s of warm-up, from sample 0 "
          f"({'every consumer connected first' if run['from_sample_0'] else 'resumed WITHOUT all consumers'}); "
          f"rig exit status {run['rig_exit_status']}")
    print(f"\n  {'process':<20} {'pid':>7} {'CPU % of a core':>16} {'worst ' + format(run['period'], 'g') + ' s':>9} "
          f"{'goal':>6} {'RSS start MB':>13} {'end MB':>8} {'growth MB/h':>12}")
    rig = soak.rig_names(procs)
    for name in rig:
        p = procs[name]
        goal = GOALS_PERCENT.get(name)
        print(f"  {name:<20} {p['pid']:>7} {soak._f(p.get('cpu_percent')):>16} "
              f"{soak._f(p.get('cpu_percent_worst_period')):>9} {'' if goal is None else format(goal, 'g'):>6} "
              f"{soak._f(p.get('rss_start_mb')):>13} {soak._f(p.get('rss_end_mb')):>8} "
              f"{soak._f(p.get('growth_mb_per_h'), '+.1f'):>12}")
    total = sum(procs[n].get("cpu_percent") or 0.0 for n in rig)
    print(f"  {'whole rig':<20} {'':>7} {total:>16.1f} {'':>9} {GOAL_RIG_PERCENT:>6g}")
    b = procs.get(soak.BENCH, {})
    print(f"  ({soak.BENCH}: {soak._f(b.get('cpu_percent'))} %; memory growth: least-squares slope of RSS "
          f"{'after the first minute' if run['seconds'] >= 180 else 'over the second half (a short run: noise)'})")
    print(f"\ntraffic, from the recording ({flow['seconds_of_data']:.1f} s of data): "
          f"{flow['messages_per_s']:.1f} messages/s, {flow['bytes_per_s'] / 1e6:.3f} MB/s serialized")
    for topic, t in flow["topics"].items():
        print(f"  {topic:<26} {t['messages_per_s']:>8.1f} msg/s {t['bytes_per_s'] / 1e3:>9.1f} kB/s")
    print("\ngoals:")
    for goal in result["goals"].values():
        print(f"  {goal['goal']}: {soak._verdict(goal['met'])} ({goal['detail']})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=120.0, help="measured wall time (default 120)")
    parser.add_argument("--warmup", type=float, default=10.0, help="s run before measuring (default 10)")
    soak.add_rig_arguments(parser)
    args = parser.parse_args()
    if args.seconds <= 0 or args.period <= 0 or args.warmup < 0:
        parser.error("--seconds and --period must be positive, --warmup not negative")

    from rimd_sim.io.reader import RecordingError
    from rimd_sim.settings.config import find_config_file, load_config

    block_rate = load_config(find_config_file("rimd.yaml")).block_rate
    with soak.RigRun.open("bench_rig_", args.keep) as run:
        tmp = run.tmp
        print(f"bench_rig: `rimd rig` in {tmp}, ROS_DOMAIN_ID {run.domain_id}; {args.warmup:g} s warm-up, then "
              f"{args.seconds:g} s measured", flush=True)
        from_sample_0, procs = run.start(args.warmup + args.seconds, args.startup_timeout)
        started = time.monotonic()
        missing = [n for n in soak.NODES.values() if n not in procs]
        if missing:
            print(f"bench_rig: NOT FOUND: {', '.join(missing)}", file=sys.stderr)
        time.sleep(args.warmup)
        series = soak.sample_run(run.rig, procs, args.seconds, args.period)
        wall = max(s.t[-1] for s in series.values() if s.t)
        status = soak.stop_rig(run.rig, procs)
        data_seconds = time.monotonic() - started   # about the simulated time recorded (real time)
        result: dict = {"run": {"seconds": wall, "warmup": args.warmup, "period": args.period,
                                "domain_id": run.domain_id, "rig_exit_status": status,
                                "from_sample_0": from_sample_0, "tmp": str(tmp)}}
        result["processes"] = {name: soak.process_figures(s) for name, s in series.items()}
        result["logs"] = soak.log_reports((tmp / "rig.log").read_text(errors="replace"))
        try:
            result["recording"] = soak.analyse_recording(tmp / "rec", block_rate)
            ends = [t["ends_at_s"] for t in result["recording"]["topics"].values() if t.get("ends_at_s")]
            result["traffic"] = traffic(tmp / "rec", max(ends) if ends else data_seconds)
        except RecordingError as exc:
            raise SystemExit(f"bench_rig: no readable recording: {exc}") from None
        result["goals"] = rig_goals(result["processes"], soak.goals(result)["nothing_lost"])
        report(result)
        soak.write_json(result, args.json)


if __name__ == "__main__":
    main()
