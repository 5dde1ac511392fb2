"""Latency of what a user waits for: ``rimd --help``, one ``rimd sweep`` point, and a ``rimd_rig`` ready to answer.

Three measurements, each a fresh process, each repeated ``--repeats`` times, all on the warm numba cache:

* ``help``: ``python -m rimd_sim.cli --help`` (wall seconds of the process);
* ``sweep``: ``python -m rimd_sim.cli sweep --f-min 3 --f-max 3`` into a temporary directory (the whole
  process: imports, the cached kernel's load, the point, the plot and the files);
* ``sweep-files``: the same with ``--no-plot`` (the files without the figure: a study scripting its points);
* ``rig``: a fresh interpreter makes the ``rimd_rig`` fixture's call (``rimd_sim.ros.testing.RigFactory``:
  ``consumers=["bench_daq"]``, the fixture's defaults) and then ``rig.motor(4.0)``; the figure is the seconds
  from the call to the motor command answered (the interpreter's own start and imports are not in it: a pytest
  session has them already). The readiness stamps (``ready_after``) are printed too.

``--compare DIR`` runs the same commands from another checkout (for example ``git worktree add /tmp/base HEAD~1``
then ``make setup`` there, or at least one ``rimd warmup`` so that its numba cache is warm) in the same run,
alternately (this tree, then DIR, repeat by repeat), and prints the median ratio DIR/this tree per measurement
(> 1: this tree is faster). The other checkout's package is put first on ``PYTHONPATH`` (its ``rimd_sim``
directory); everything else (the venv, the ROS workspace's messages) is this environment's. A first untimed
round warms each tree's caches. The load average is printed before and after: on a shared machine only the
ratios of one run are comparable; absolute figures want an idle machine (docs/benchmarks.md, "Latency").

Run after ``source env.sh``:
    python benchmarks/bench_latency.py [--repeats 5] [--only help,sweep,sweep-files,rig] [--compare DIR]
                                       [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
KINDS = ("help", "sweep", "sweep-files", "rig")

RIG_PROBE = r"""
import json, sys, tempfile, time
from pathlib import Path
from rimd_sim.ros.testing import RigFactory
with tempfile.TemporaryDirectory(prefix="bench_latency_rig_") as tmp:
    factory = RigFactory(Path(tmp))
    started = time.monotonic()
    try:
        rig = factory(consumers=["bench_daq"])
        returned = time.monotonic() - started
        answer = rig.motor(4.0)
        answered = time.monotonic() - started
        if not answer.success:
            sys.exit(f"the rig refused the motor command: {answer.message}")
    finally:
        factory.stop_all()
print(json.dumps({"returned_s": returned, "answered_s": answered, "ready_after_s": rig.ready_after}))
"""


def environment(tree: Path) -> dict[str, str]:
    """This environment with ``tree``'s package first on the import path."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tree / "rimd_sim"), env.get("PYTHONPATH")]))
    return env


def check_tree(tree: Path) -> None:
    """Fail early when ``tree`` is not a checkout of the project, or its package is not the one imported."""
    out = subprocess.run([sys.executable, "-c", "import rimd_sim; print(rimd_sim.__file__)"], env=environment(tree),
                         capture_output=True, text=True, check=True).stdout.strip()
    if not Path(out).resolve().is_relative_to((tree / "rimd_sim").resolve()):
        sys.exit(f"bench_latency: {tree} does not provide the rimd_sim imported (got {out})")


def run_once(kind: str, tree: Path, work: Path) -> dict:
    """One repeat of ``kind`` from ``tree``: its seconds (and the rig's stamps)."""
    env = environment(tree)
    if kind == "rig":
        proc = subprocess.run([sys.executable, "-c", RIG_PROBE], env=env, capture_output=True, text=True,
                              timeout=300)
        if proc.returncode != 0:
            sys.exit(f"bench_latency: the rig probe failed in {tree}:\n{proc.stderr[-2000:]}")
        stamps = json.loads(proc.stdout.strip().splitlines()[-1])
        return {"seconds": stamps["answered_s"], **stamps}
    argv = ["--help"] if kind == "help" else ["sweep", "--f-min", "3", "--f-max", "3", "--out", str(work / "sweep")]
    if kind == "sweep-files":
        argv.append("--no-plot")
    started = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "rimd_sim.cli", *argv], env=env, cwd=work, capture_output=True,
                          text=True, timeout=300)
    seconds = time.monotonic() - started
    if proc.returncode != 0:
        sys.exit(f"bench_latency: {kind} failed in {tree} (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    return {"seconds": seconds}


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


#: Per measurement: the figure's name in docs/benchmarks.md and its target.
LATENCY_FIGURES = {
    "help": ("`rimd --help`", "<= 0.3"),
    "sweep": ("one `rimd sweep` point with its figure", "<= 0.5"),
    "sweep-files": ("the same with `--no-plot`", "<= 0.5"),
    "rig": ("`rimd_rig` call to its first answered `rig.motor`", "<= 1.5"),
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats per measurement and tree (default 5)")
    parser.add_argument("--only", default=",".join(KINDS), help=f"comma-separated subset of {','.join(KINDS)}")
    parser.add_argument("--compare", type=Path, default=None, help="another checkout, run alternately with this")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    kinds = [k for k in args.only.split(",") if k]
    if unknown := set(kinds) - set(KINDS):
        parser.error(f"--only: unknown {sorted(unknown)}")
    trees = {"this": ROOT} | ({"compare": args.compare.resolve()} if args.compare else {})
    for tree in trees.values():
        check_tree(tree)
    print(f"load average before: {load()}", flush=True)
    results: dict[str, dict[str, list[dict]]] = {kind: {name: [] for name in trees} for kind in kinds}
    with tempfile.TemporaryDirectory(prefix="bench_latency_") as tmp:
        work = Path(tmp)
        for kind in kinds:
            for tree in trees.values():   # warm-up, untimed: the OS's file cache, numba's index files
                run_once(kind, tree, work)
            for i in range(args.repeats):
                for name, tree in trees.items():
                    r = run_once(kind, tree, work)
                    results[kind][name].append(r)
                    extra = (f" (fixture returned {r['returned_s']:.2f} s, ready_after {r['ready_after_s']:.2f} s)"
                             if kind == "rig" else "")
                    print(f"{kind} {name} {i + 1}/{args.repeats}: {r['seconds']:.3f} s{extra}  [load {load()}]",
                          flush=True)
    print()
    for kind in kinds:
        for name in trees:
            values = [r["seconds"] for r in results[kind][name]]
            print(f"{kind:5s} {name:7s}: median {statistics.median(values):.3f} s, min {min(values):.3f} s, "
                  f"max {max(values):.3f} s ({len(values)} runs)")
        if "compare" in trees:
            pairs = zip(results[kind]["this"], results[kind]["compare"], strict=True)
            ratios = [c["seconds"] / t["seconds"] for t, c in pairs]
            print(f"{kind:5s} ratio compare/this: median {statistics.median(ratios):.2f} "
                  f"(min {min(ratios):.2f}, max {max(ratios):.2f}; > 1: this tree is faster)")
    if "compare" not in trees:   # the headline figures for report.py: this tree alone
        from _figures import record

        for kind in kinds:
            what, target = LATENCY_FIGURES[kind]
            record("latency", what, statistics.median(r["seconds"] for r in results[kind]["this"]), "s", target)
    print(f"load average after: {load()}", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"trees": {k: str(v) for k, v in trees.items()}, "results": results},
                                        indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
