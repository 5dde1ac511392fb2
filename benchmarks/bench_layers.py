"""What each piece of the rig's tuning buys: the composed rig's CPU with every piece on, each piece plain, all plain.

The pieces, and what plain means for each, are those of the benchmarking switch ``RIMD_PLAIN``
(:mod:`rimd_sim.runtime.plain`): ``outbox``, ``polling``, ``executor``, ``collector``, ``threads``. Each run is
``rimd rig`` as ``make run`` starts it (the composed rig with the recorder and the Rerun bridge sending its
display stream, config/rimd.yaml, at real time) with the external subscriber of the block topics beside it, on
a ROS domain of its own, recording into a fresh temporary directory: bench_rig's run, with its helpers and
bench_soak's. The variants: ``on`` (``RIMD_PLAIN`` unset), one per piece (``RIMD_PLAIN=PIECE``), ``all``
(``RIMD_PLAIN=all``). Each round runs every variant once; the order alternates from round to round (forward,
then backward), so that a drift of the machine's speed falls on all variants alike. A run measures --seconds of
wall time after --warmup s from the moment the rig runs from sample 0: the whole rig's CPU (every process the
rig runs: the composed rig, the Rerun server, the ``rimd rig`` parent; utime + stime from /proc, in % of one
core) and whether anything was lost (the recording's checks and the external subscriber's, as bench_rig's).

Printed: the load average before the runs (a warning above 1: the figures then hold other work) and after them,
one line per run, then per variant: the median over rounds of the whole rig's CPU, the ratio to ``on`` (the
median over rounds of plain / on, each round's pair run close in time), and what the piece buys,
(plain - on) / plain = 1 - 1 / ratio: the share of the rig's CPU without the piece that the piece saves. A
variant that lost anything in some round is marked LOSS; one whose rig had recorded no block when it was
stopped (too short a run for the rig's start) is marked NO DATA, its loss unchecked.

Run (after ``source env.sh``, from the repository root; the machine otherwise idle; about
``rounds x (pieces + 2) x (seconds + warmup + 30)`` s):
    python benchmarks/bench_layers.py [--rounds 3] [--seconds 60] [--warmup 10] [--pieces outbox,polling]
                                      [--json layers.json] [--keep] [--period 5]
The exit status is 0 whenever every run was measured, whatever the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import sys
import time
from collections.abc import Iterator
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_rig as rig  # noqa: E402 - the external subscriber, its loss check, the whole rig's CPU
import bench_soak as soak  # noqa: E402 - the rig, the /proc sampling, the recording's loss check

from rimd_sim.runtime.plain import PIECES, PLAIN_ENV  # noqa: E402

#: The variable that would override the executor piece (rimd_sim.ros.nodes.base.EXECUTOR_ENV).
EXECUTOR_ENV = "RIMD_EXECUTOR"
#: A piece that buys less than this share of the rig's CPU (%) is a candidate for removal.
BAR_PERCENT = 10.0


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


@contextlib.contextmanager
def plain_env(value: str | None) -> Iterator[None]:
    """``RIMD_PLAIN=value`` in this process's environment (unset for None), which the rig started inside inherits."""
    before = os.environ.pop(PLAIN_ENV, None)
    if value is not None:
        os.environ[PLAIN_ENV] = value
    try:
        yield
    finally:
        os.environ.pop(PLAIN_ENV, None)
        if before is not None:
            os.environ[PLAIN_ENV] = before


def run_variant(variant: str, args: argparse.Namespace, block_rate: float) -> dict:
    """One run of the rig with ``RIMD_PLAIN=variant`` (``on``: unset), measured; its figures and loss verdicts."""
    from rimd_sim.io.reader import RecordingError

    with soak.RigRun.open(f"bench_layers_{variant}_", args.keep) as run:
        external = rig.start_external(run.tmp, run.domain_id)   # started outside the switch: not part of the rig
        try:
            with plain_env(None if variant == "on" else variant):
                from_sample_0, procs = run.start(args.warmup + args.seconds, args.startup_timeout)
            procs[rig.EXTERNAL] = external.pid
            time.sleep(args.warmup)
            series = soak.sample_run(run.rig, procs, args.seconds, args.period)
            status = soak.stop_rig(run.rig, {n: p for n, p in procs.items() if n != rig.EXTERNAL})
        finally:
            counts = rig.stop_external(external, run.tmp)
        result: dict = {"run": {"variant": variant, "seconds": args.seconds, "warmup": args.warmup,
                                "rig_exit_status": status, "from_sample_0": from_sample_0, "tmp": str(run.tmp)},
                        "processes": {name: soak.process_figures(s) for name, s in series.items()},
                        "logs": soak.log_reports((run.tmp / "rig.log").read_text(errors="replace"))}
        try:
            result["recording"] = soak.analyse_recording(run.tmp / "rec", block_rate)
            verdicts = {"recording": soak.goals(result)["nothing_lost"],
                        "external": rig.external_loss(counts, run.tmp / "rec")}
            no_data = not any(result["recording"]["topics"][t]["messages"] for t in soak.BLOCK_TOPICS)
        except RecordingError as exc:
            verdicts, no_data = {"recording": {"met": False, "detail": f"no readable recording: {exc}"}}, True
    for figures in result["processes"].values():
        figures.pop("rss_series", None)
    total, names = rig.rig_total(result["processes"])
    result.update(rig_cpu_percent=total, rig_processes=names, loss=verdicts, no_data=no_data,
                  nothing_lost=all(v["met"] for v in verdicts.values()) and from_sample_0 and status == 0)
    return result


def run_line(result: dict) -> str:
    run, procs = result["run"], result["processes"]
    composed = procs.get(soak.COMPOSED, {}).get("cpu_percent")
    if result["no_data"]:   # the rig had not published a block when it was stopped: nothing to check
        return (f"{run['variant']:<10} whole rig {result['rig_cpu_percent']:5.1f} %  NO DATA: no block recorded "
                "(a run too short for the rig's start on this machine)")
    problems = [name for name, v in result["loss"].items() if not v["met"]]
    if not run["from_sample_0"]:
        problems.append("not from sample 0")
    if run["rig_exit_status"] != 0:
        problems.append(f"exit status {run['rig_exit_status']}")
    return (f"{run['variant']:<10} whole rig {result['rig_cpu_percent']:5.1f} %  (composed rig "
            f"{soak._f(composed)} %)  {'nothing lost' if not problems else 'LOSS: ' + ', '.join(problems)}")


def summary(runs: dict[str, list[dict]]) -> dict:
    """Per variant: median CPU, median per-round ratio to ``on``, what the piece buys; printed."""
    cpu = {v: [r["rig_cpu_percent"] for r in results] for v, results in runs.items()}
    out: dict = {}
    print(f"\nthe whole rig at real time, % of one core, median over {len(cpu['on'])} round(s) "
          f"(load after: {load()}):")
    print(f"  {'variant':<10} {'CPU %':>6} {'ratio to on':>12} {'buys':>7}   per round")
    for variant, values in cpu.items():
        ratios = [v / on for v, on in zip(values, cpu["on"], strict=True) if on > 0]
        ratio = statistics.median(ratios) if ratios else None
        buys = None if variant == "on" or not ratio else 100.0 * (1.0 - 1.0 / ratio)
        lossy = not all(r["nothing_lost"] for r in runs[variant] if not r["no_data"])
        empty = any(r["no_data"] for r in runs[variant])
        note = "" if buys is None else ("  (below the bar)" if buys < BAR_PERCENT else "")
        print(f"  {variant:<10} {statistics.median(values):6.1f} {soak._f(ratio, '.2f'):>12} "
              f"{soak._f(buys, '+.1f') + ' %' if buys is not None else '':>7}   "
              f"{', '.join(f'{v:.1f}' for v in values)}{'  LOSS' if lossy else ''}{'  NO DATA' if empty else ''}"
              f"{note}")
        out[variant] = {"cpu_percent": values, "median": statistics.median(values), "ratio_to_on": ratio,
                        "buys_percent": buys, "nothing_lost": not lossy, "no_data": empty}
    print(f"  buys: (plain - on) / plain, the share of the rig's CPU without the piece that the piece saves; "
          f"the bar for keeping a piece is {BAR_PERCENT:g} %. `all`: every piece plain at once.")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="runs of each variant (default 3)")
    parser.add_argument("--seconds", type=float, default=60.0, help="measured wall time per run (default 60)")
    parser.add_argument("--warmup", type=float, default=10.0, help="s run before measuring (default 10)")
    parser.add_argument("--pieces", default=",".join(PIECES),
                        help=f"comma-separated pieces to make plain one at a time (default all: {','.join(PIECES)})")
    soak.add_rig_arguments(parser)
    args = parser.parse_args()
    if args.seconds <= 0 or args.period <= 0 or args.warmup < 0 or args.rounds < 1:
        parser.error("--seconds, --period and --rounds must be positive, --warmup not negative")
    pieces = [p.strip() for p in args.pieces.split(",") if p.strip()]
    unknown = [p for p in pieces if p not in PIECES]
    if unknown or not pieces:
        parser.error(f"--pieces: {', '.join(unknown) or 'none given'}; the pieces are {', '.join(PIECES)}")
    for name in (PLAIN_ENV, EXECUTOR_ENV):   # the variants set the one, and the other would override them
        if os.environ.pop(name, None) is not None:
            print(f"bench_layers: {name} unset for the runs (the variants choose the pieces)")

    one_min = os.getloadavg()[0]
    print(f"bench_layers: load average {load()} (1, 5, 15 min)")
    if one_min > 1.0:
        print(f"bench_layers: WARNING: load average {one_min:.2f} > 1: other work shares the machine, and the "
              "figures hold it", file=sys.stderr)

    from rimd_sim.settings.config import find_config_file, load_config

    block_rate = load_config(find_config_file("rimd.yaml")).block_rate
    variants = ["on", *pieces, "all"]
    runs: dict[str, list[dict]] = {v: [] for v in variants}
    for round_ in range(args.rounds):
        order = variants if round_ % 2 == 0 else variants[::-1]
        for variant in order:
            print(f"bench_layers: round {round_ + 1}/{args.rounds}, {variant}: `rimd rig`"
                  f"{'' if variant == 'on' else f' with {PLAIN_ENV}={variant}'}, {args.warmup:g} s warm-up, "
                  f"{args.seconds:g} s measured (load {load()})", flush=True)
            result = run_variant(variant, args, block_rate)
            runs[variant].append(result)
            print("  " + run_line(result), flush=True)
    soak.write_json({"runs": runs, "summary": summary(runs), "load_before": one_min}, args.json)


if __name__ == "__main__":
    main()
