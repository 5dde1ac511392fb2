"""CPU budget of the default rig at real time, composed and in separate processes side by side, in one run.

What it runs, one after the other: ``rimd rig`` as ``make run`` starts it (the composed rig: the simulator, the
recorder and the Rerun bridge in one process, docs/rig.md "The composed rig"), then ``rimd rig --separate`` (one
process per node), each with the default config/rimd.yaml (simulator at real time, recorder, Rerun bridge with its
default sink serve_web, which starts a Rerun server with the web viewer), recording into a fresh temporary
directory, on a ROS domain of its own (the test suite's leases, ROS_AUTOMATIC_DISCOVERY_RANGE LOCALHOST). Beside
each rig runs an external subscriber (``benchmarks/_consumer.py``, not lockstep): a process of its own that takes
the five block topics over DDS and counts them, as another process's DAQ client would. The measurement starts when
the rig runs from sample 0, after --warmup s (default 10: start-up, JIT loading and discovery are not the steady
state), and lasts --seconds of wall time. The rig, the recording and the /proc sampling are :mod:`bench_soak`'s.

Printed for each layout (and written as JSON with --json):
  * per process (composed: the composed rig; separate: simulator, recorder, Rerun bridge; and the Rerun server,
    the ``rimd rig`` parent), from /proc, not from the nodes' own reports: CPU in % of one core (utime + stime
    over the measured wall time; the worst --period s window), resident memory at the start and end; the whole
    rig (every process the rig runs: the nodes, the Rerun server that holds the web viewer's data, the ``rimd
    rig`` parent); the external subscriber's CPU apart (it is not the rig); and the composed rig's CPU per thread
    (/proc/PID/task: its main thread, which runs the executor and with it the recorder's and the bridge's takes
    and the Rerun mapping; the threads the rig names, rimd_sim.runtime.threads.OS_NAMES; Fast DDS's; the Rerun
    SDK's; the others);
  * the traffic, from the recording: messages and bytes (serialized payload) per second per topic and in all;
  * loss: the recorder's count (every block topic from sample 0 with ``first_index``, impact events by index,
    motor states one per block: bench_soak's checks) and the external subscriber's (each block topic contiguous
    from its first message, and as many messages from there as the recording has);
  * the goals: the composed rig <= 12 % of one core in all, nothing lost; for separate processes, the goals of the
    light-rig changes (docs/benchmarks.md: simulator <= 5 %, recorder <= 10 %, Rerun bridge <= 10 %, the whole
    rig <= 25 %), each with "met" or "NOT met"; and the composed rig's CPU against the separate rig's.

With ``--rerun both``, each layout runs twice, its Rerun bridge sending the display stream (the default, as ``make
run``: each channel's min and max sample per 5 ms, docs/rerun.md) and then every sample (``rimd rig
--rerun-full-rate``), and the whole rig's CPU of the two is printed side by side (the display stream's figures are
the ones recorded for report.py); ``--rerun full`` measures full rate only.

With ``--block-rate R``, the composed rig runs once more after the default ones, with ``--set block_rate=R``
(every sample as before, in fewer and longer blocks), and its whole rig's CPU is printed against the default's:
most of the rig's CPU is paid per block, not per sample (a pass of Python code in the simulator, the recorder and the
bridge), so this is the lever for a lighter rig, at the cost of longer blocks (a consumer gets data later).

With ``--compare DIR`` (another checkout, set up: a worktree of an older commit), the rig of --only's layout
(default composed) of this tree and of DIR's package run alternately (ABBA...), --rounds times each, in one run, and the
whole rig's CPU is printed per run, as medians and as the median ratio DIR / this: on a shared machine whose speed
drifts within hours, a before/after figure that means something.

Run (after ``source env.sh``, from the repository root; the machine otherwise idle):
    python benchmarks/bench_rig.py [--seconds 120] [--json rig.json] [--keep] [--only composed|separate]
                                   [--rerun display|full|both] [--block-rate R] [--compare DIR [--rounds 3]]
The exit status is 0 whenever the rigs ran and were measured, whatever the verdicts.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_soak as soak  # noqa: E402 - the rig and /proc sampling of the soak bench

GOALS_PERCENT = {"simulator": 5.0, "recorder": 10.0, "rerun bridge": 10.0}
GOAL_RIG_PERCENT = 25.0
GOAL_COMPOSED_PERCENT = 12.0
EXTERNAL = "external subscriber"
LAYOUTS = {"composed": (), "separate": ("--separate",)}
#: The Rerun bridge's stream: the display stream (the default of ``rimd rig``) or every sample.
STREAMS = {"display": (), "full": ("--rerun-full-rate",)}


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


def rig_total(procs: dict) -> tuple[float, list[str]]:
    """The whole rig's CPU (% of a core) and its processes: all but this bench and the external subscriber."""
    rig = [n for n in soak.rig_names(procs) if n != EXTERNAL]
    return sum(procs[n].get("cpu_percent") or 0.0 for n in rig), rig


def composed_goals(procs: dict, nothing_lost: dict) -> dict:
    total, rig = rig_total(procs)
    measured = procs.get(soak.COMPOSED, {}).get("cpu_percent") is not None
    return {"rig": {"goal": f"the whole composed rig <= {GOAL_COMPOSED_PERCENT:g} % of one core",
                    "met": measured and total <= GOAL_COMPOSED_PERCENT, "detail": f"{total:.1f} % ({', '.join(rig)})"},
            "nothing_lost": nothing_lost}


def rig_goals(procs: dict, nothing_lost: dict) -> dict:
    out = {}
    for name, limit in GOALS_PERCENT.items():
        cpu = procs.get(name, {}).get("cpu_percent")
        out[name] = {"goal": f"{name} <= {limit:g} % of one core", "met": cpu is not None and cpu <= limit,
                     "detail": f"{soak._f(cpu)} %"}
    total, rig = rig_total(procs)
    nodes = sum(procs.get(n, {}).get("cpu_percent") or 0.0 for n in GOALS_PERCENT)
    measured = all(procs.get(n, {}).get("cpu_percent") is not None for n in GOALS_PERCENT)
    out["rig"] = {"goal": f"the whole rig <= {GOAL_RIG_PERCENT:g} % of one core",
                  "met": measured and total <= GOAL_RIG_PERCENT,
                  "detail": f"{total:.1f} % ({', '.join(rig)}); the three nodes alone {nodes:.1f} %"}
    out["nothing_lost"] = nothing_lost
    return out


def external_loss(counts: dict, recording: Path) -> dict:
    """The external subscriber's verdict: each block topic contiguous from its first message, as many as recorded."""
    if "error" in counts:
        return {"goal": "nothing lost, external subscriber", "met": False, "detail": counts["error"]}
    from rimd_sim.io.cdr import block_span
    from rimd_sim.io.reader import open_recording

    rec, details, ok = open_recording(recording), [], True
    for topic, c in counts["topics"].items():
        first = c["first_index"]
        recorded = (sum(1 for m in rec.messages([topic]) if block_span(m.data)[0] >= first)
                    if first is not None else None)
        good = first is not None and c["holes"] == 0 and c["messages"] == recorded
        ok = ok and good
        details.append(f"{topic.rsplit('/rig/', 1)[-1]} {c['messages']}/{recorded} from index {first}, "
                       f"{c['holes']} holes")
    return {"goal": "nothing lost, external subscriber (over DDS, from its first message)", "met": ok,
            "detail": "; ".join(details)}


def start_external(tmp: Path, domain_id: int) -> subprocess.Popen:
    """The external subscriber (benchmarks/_consumer.py, no lockstep) in the rig's domain."""
    import os

    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(tmp / "ros_log"))
    env.pop("ROS_STATIC_PEERS", None)
    return subprocess.Popen([sys.executable, str(Path(__file__).resolve().parent / "_consumer.py"),
                             "--out", str(tmp / "external.json")], env=env, stdout=(tmp / "external.log").open("wb"),
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)


def stop_external(proc: subprocess.Popen, tmp: Path) -> dict:
    from rimd_sim.ros.bringup import stop_process

    status = stop_process(proc)
    try:
        return {"exit_status": status, **json.loads((tmp / "external.json").read_text())}
    except (OSError, ValueError):
        return {"exit_status": status,
                "error": "no counts: " + (tmp / "external.log").read_text(errors="replace")[-1500:]}


def report(result: dict) -> None:
    run, procs, flow = result["run"], result["processes"], result["traffic"]
    options = " ".join((*LAYOUTS[run["layout"]], *STREAMS[run.get("rerun_stream", "display")],
                        *run.get("settings", ())))
    print(f"\n{run['layout']}, Rerun {run.get('rerun_stream', 'display')}: the "
          f"{'rig' if run.get('settings') else 'default rig'} (`rimd rig"
          f"{' ' + options if options else ''}`, "
          f"config/rimd.yaml) at real time: {run['seconds']:.1f} s measured after "
          f"{run['warmup']:g} s of warm-up, from sample 0 "
          f"({'every consumer connected first' if run['from_sample_0'] else 'resumed WITHOUT all consumers'}); "
          f"rig exit status {run['rig_exit_status']}")
    print(f"\n  {'process':<20} {'pid':>7} {'CPU % of a core':>16} {'worst ' + format(run['period'], 'g') + ' s':>9} "
          f"{'goal':>6} {'RSS start MB':>13} {'end MB':>8} {'growth MB/h':>12}")
    for name in soak.rig_names(procs):
        p = procs[name]
        goal = GOALS_PERCENT.get(name)
        print(f"  {name:<20} {p['pid']:>7} {soak._f(p.get('cpu_percent')):>16} "
              f"{soak._f(p.get('cpu_percent_worst_period')):>9} {'' if goal is None else format(goal, 'g'):>6} "
              f"{soak._f(p.get('rss_start_mb')):>13} {soak._f(p.get('rss_end_mb')):>8} "
              f"{soak._f(p.get('growth_mb_per_h'), '+.1f'):>12}")
    total, _ = rig_total(procs)
    goal = GOAL_COMPOSED_PERCENT if run["layout"] == "composed" else GOAL_RIG_PERCENT
    print(f"  {'whole rig':<20} {'':>7} {total:>16.1f} {'':>9} {goal:>6g}   (without the {EXTERNAL})")
    b = procs.get(soak.BENCH, {})
    print(f"  ({soak.BENCH}: {soak._f(b.get('cpu_percent'))} %; memory growth: least-squares slope of RSS "
          f"{'after the first minute' if run['seconds'] >= 180 else 'over the second half (a short run: noise)'})")
    if result.get("threads"):
        print(f"  the {soak.COMPOSED}'s threads, % of a core: "
              + ", ".join(f"{name} {cpu:.1f}" for name, cpu in result["threads"].items()))
    print(f"\ntraffic, from the recording ({flow['seconds_of_data']:.1f} s of data): "
          f"{flow['messages_per_s']:.1f} messages/s, {flow['bytes_per_s'] / 1e6:.3f} MB/s serialized")
    for topic, t in flow["topics"].items():
        print(f"  {topic:<26} {t['messages_per_s']:>8.1f} msg/s {t['bytes_per_s'] / 1e3:>9.1f} kB/s")
    print("\ngoals:")
    for goal in result["goals"].values():
        print(f"  {goal['goal']}: {soak._verdict(goal['met'])} ({goal['detail']})")


def measure(layout: str, args: argparse.Namespace, block_rate: float, tree: Path | None = None,
            stream: str = "display", settings: tuple[str, ...] = ()) -> dict:
    """One rig of ``layout`` (composed or separate) with the external subscriber, measured; its figures.

    ``tree``: the checkout whose package runs (default this one; :func:`bench_soak.start_rig`). ``stream``: the
    Rerun bridge's (:data:`STREAMS`). ``settings``: more options of ``rimd rig`` (``--set NAME=VALUE``).
    """
    options = (*LAYOUTS[layout], *STREAMS[stream], *settings)
    from rimd_sim.io.reader import RecordingError

    with soak.RigRun.open(f"bench_rig_{layout}_", args.keep) as run:
        tmp = run.tmp
        print(f"bench_rig: `rimd rig {' '.join(options)}` ({layout}{', ' + str(tree) if tree else ''}) "
              f"in {tmp}, ROS_DOMAIN_ID "
              f"{run.domain_id}; {args.warmup:g} s warm-up, then {args.seconds:g} s measured", flush=True)
        external = start_external(tmp, run.domain_id)
        try:
            from_sample_0, procs = run.start(args.warmup + args.seconds, args.startup_timeout, options, tree)
            procs[EXTERNAL] = external.pid
            started = time.monotonic()
            expected = [soak.COMPOSED] if layout == "composed" else list(soak.NODES.values())
            missing = [n for n in expected if n not in procs]
            if missing:
                print(f"bench_rig: NOT FOUND: {', '.join(missing)}", file=sys.stderr)
            time.sleep(args.warmup)
            composed = procs.get(soak.COMPOSED)
            threads_before = soak.thread_ticks(composed) if composed else {}
            t_threads = time.monotonic()
            series = soak.sample_run(run.rig, procs, args.seconds, args.period)
            threads = (soak.thread_cpu(composed, threads_before, soak.thread_ticks(composed),
                                       time.monotonic() - t_threads) if composed else {})
            if soak.RERUN_SERVER not in procs:   # config/rimd.yaml's sink serve_web starts one, when the bridge opens
                print(f"bench_rig: NOT FOUND: {soak.RERUN_SERVER} (the whole rig's figure is without it)",
                      file=sys.stderr)
            wall = max(s.t[-1] for s in series.values() if s.t)
            status = soak.stop_rig(run.rig, {n: p for n, p in procs.items() if n != EXTERNAL})
        finally:
            counts = stop_external(external, tmp)
        data_seconds = time.monotonic() - started   # about the simulated time recorded (real time)
        result: dict = {"run": {"layout": layout, "rerun_stream": stream, "settings": list(settings),
                                "seconds": wall, "warmup": args.warmup,
                                "period": args.period, "domain_id": run.domain_id, "rig_exit_status": status,
                                "from_sample_0": from_sample_0, "tmp": str(tmp)}}
        result["processes"] = {name: soak.process_figures(s) for name, s in series.items()}
        result["threads"] = threads
        result["logs"] = soak.log_reports((tmp / "rig.log").read_text(errors="replace"))
        result["external"] = counts
        try:
            result["recording"] = soak.analyse_recording(tmp / "rec", block_rate)
            ends = [t["ends_at_s"] for t in result["recording"]["topics"].values() if t.get("ends_at_s")]
            result["traffic"] = traffic(tmp / "rec", max(ends) if ends else data_seconds)
            external_verdict = external_loss(counts, tmp / "rec")
        except RecordingError as exc:
            raise SystemExit(f"bench_rig: no readable recording ({layout}): {exc}") from None
        nothing_lost = soak.goals(result)["nothing_lost"]
        goals = (composed_goals if layout == "composed" else rig_goals)(result["processes"], nothing_lost)
        result["goals"] = {**goals, "nothing_lost_external": external_verdict}
        report(result)
        return result


def record_figures(results: dict) -> None:
    """The headline figures for report.py (benchmarks/_figures.py): each layout's whole rig, the separate nodes."""
    from _figures import record

    for layout, result in results.items():
        procs, total = result["processes"], rig_total(result["processes"])[0]
        if layout == "composed":
            record("rig", "composed (`make run`): whole rig", total, "%", f"<= {GOAL_COMPOSED_PERCENT:g}")
            continue
        for name, limit in GOALS_PERCENT.items():
            record("rig", f"separate: {name}", procs.get(name, {}).get("cpu_percent"), "%", f"<= {limit:g}")
        record("rig", "separate: whole rig", total, "%", f"<= {GOAL_RIG_PERCENT:g}")


def compare(args: argparse.Namespace, block_rate: float) -> dict:
    """This tree's rig and ``args.compare``'s, alternately, ``args.rounds`` times each; the whole rig's CPU."""
    layout = args.only or "composed"
    trees = {"this": None, "compare": args.compare.resolve()}
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    for round_ in range(args.rounds):
        order = list(trees.items()) if round_ % 2 == 0 else list(trees.items())[::-1]   # ABBA: no side first
        for name, tree in order:
            print(f"\nbench_rig: round {round_ + 1}/{args.rounds}, {name} ({tree or soak.REPO}), load "
                  f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
            runs[name].append(measure(layout, args, block_rate, tree, args.rerun))
    totals = {name: [rig_total(r["processes"])[0] for r in results] for name, results in runs.items()}
    lost = {name: [not (r["goals"]["nothing_lost"]["met"] and r["goals"]["nothing_lost_external"]["met"])
                   for r in results] for name, results in runs.items()}
    print(f"\nthe whole rig ({layout}) at real time, % of one core, alternately in this run "
          f"(load after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}):")
    for name, tree in trees.items():
        values = ", ".join(f"{t:.1f}{' (LOSS)' if bad else ''}"
                           for t, bad in zip(totals[name], lost[name], strict=True))
        print(f"  {name:<8} {statistics.median(totals[name]):6.1f} median  ({values})  {tree or soak.REPO}")
    ratios = [c / t for t, c in zip(totals["this"], totals["compare"], strict=True)]
    print(f"  ratio compare/this: median {statistics.median(ratios):.2f} (per round: "
          f"{', '.join(f'{r:.2f}' for r in ratios)}; > 1: this tree costs less)")
    return {"layout": layout, "runs": runs, "totals": totals, "ratios": ratios}


def by_block_rate(args: argparse.Namespace, default_rate: float, default: dict | None) -> dict:
    """The composed rig at ``args.block_rate`` blocks/s, printed against ``default`` (the same at the config's rate)."""
    rate = args.block_rate
    result = measure("composed", args, rate, stream=args.rerun, settings=("--set", f"block_rate={rate:g}"))
    total = rig_total(result["processes"])[0]
    print(f"\nthe whole composed rig at {rate:g} blocks/s: {total:.1f} % of one core", end="")
    if default is not None:
        base = rig_total(default["processes"])[0]
        print(f" against {base:.1f} % at {default_rate:g} blocks/s, in this run (ratio {total / base:.2f})", end="")
    print()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=120.0, help="measured wall time per rig (default 120)")
    parser.add_argument("--warmup", type=float, default=10.0, help="s run before measuring (default 10)")
    parser.add_argument("--only", choices=tuple(LAYOUTS), default=None, help="measure one layout only")
    parser.add_argument("--compare", type=Path, default=None, metavar="DIR",
                        help="alternate the rig of --only's layout (default composed) with DIR's (another checkout)")
    parser.add_argument("--rounds", type=int, default=3, help="with --compare: runs of each tree (default 3)")
    parser.add_argument("--rerun", choices=(*STREAMS, "both"), default="display",
                        help="the Rerun bridge's stream: display (default, as make run), full (every sample: "
                             "rimd rig --rerun-full-rate), or both, one after the other, compared")
    parser.add_argument("--block-rate", type=float, default=None, metavar="R",
                        help="also measure the composed rig at R blocks/s (rimd rig --set block_rate=R), in this run")
    soak.add_rig_arguments(parser)
    args = parser.parse_args()
    if args.seconds <= 0 or args.period <= 0 or args.warmup < 0 or args.rounds < 1:
        parser.error("--seconds, --period and --rounds must be positive, --warmup not negative")
    if args.compare is not None and args.rerun == "both":
        parser.error("--compare measures one stream: --rerun display or full")
    if args.block_rate is not None and (args.compare is not None or args.rerun == "both"):
        parser.error("--block-rate goes with neither --compare nor --rerun both")
    if args.block_rate is not None and not 1 <= args.block_rate <= 10_000:
        parser.error(f"--block-rate must be 1 to 10000 blocks/s (as the config's block_rate), not {args.block_rate:g}")
    if args.compare is not None:
        from bench_latency import check_tree

        check_tree(args.compare)   # a checkout whose package is the one its runs import

    from rimd_sim.settings.config import find_config_file, load_config

    block_rate = load_config(find_config_file("rimd.yaml")).block_rate
    if args.compare is not None:
        soak.write_json(compare(args, block_rate), args.json)
        return
    layouts = [layout for layout in LAYOUTS if args.only in (None, layout)]
    if args.rerun == "both":
        streams = {layout: {stream: measure(layout, args, block_rate, stream=stream) for stream in STREAMS}
                   for layout in layouts}
        print("\nthe whole rig, the Rerun bridge sending the display stream against every sample, in this run:")
        for layout, by_stream in streams.items():
            display, full = (rig_total(by_stream[s]["processes"])[0] for s in ("display", "full"))
            print(f"  {layout:<9} {display:.1f} % against {full:.1f} % of one core ({display - full:+.1f} points)")
        record_figures({layout: by_stream["display"] for layout, by_stream in streams.items()})   # make run's
        soak.write_json(streams, args.json)
        return
    results = {layout: measure(layout, args, block_rate, stream=args.rerun) for layout in layouts}
    if len(results) == 2:
        composed, separate = (rig_total(results[n]["processes"])[0] for n in ("composed", "separate"))
        print(f"\nthe whole rig, composed against separate processes, in this run: {composed:.1f} % against "
              f"{separate:.1f} % of one core ({composed - separate:+.1f} points)")
    if args.block_rate is not None:
        results["block_rate"] = by_block_rate(args, block_rate, results.get("composed"))
    if args.rerun == "display":   # the rig as make run starts it, then the same at --block-rate
        record_figures({layout: results[layout] for layout in layouts})
        if args.block_rate is not None:
            from _figures import record

            record("rig", f"composed at {args.block_rate:g} blocks/s: whole rig",
                   rig_total(results["block_rate"]["processes"])[0], "%")
    soak.write_json(results, args.json)


if __name__ == "__main__":
    main()
