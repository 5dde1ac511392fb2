"""CPU of the simulator's pacing loop per pass, without ROS: what the rig's ``rimd-pacing`` thread spends per block.

The runtime (``rimd_sim.runtime.simulator.SimulatorRuntime``, the default configuration, seed 0) on a fake clock,
one 10 ms block per pass as at real time, its messages handed to a function that hashes them (as the node hands
them to the recorder, the bridge and DDS). Printed: the thread's CPU time per pass, best of --rounds runs of
--passes passes each, and a digest of every message but the diagnostics and the session (which carry wall-clock
figures): two trees whose digests agree sent the same bytes.

Back to back, a pass costs a third of what it costs at real time (a pass every 10 ms finds its caches cold:
``bench_rig.py``'s per-thread figures), so the figure is a ratio's figure: compare trees with ``--compare DIR``
(another checkout, its package first on PYTHONPATH, run alternately with this one in the same run).

Run (after ``source env.sh``):
    python benchmarks/bench_pass.py [--passes 3000] [--rounds 3] [--compare DIR [--alternations 3]]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
S = 1_000_000_000
#: Keys left out of the digest: their messages carry wall-clock figures (CPU, lateness) or ids.
NOT_DIGESTED = ("diagnostics", "session")


def one_run(passes: int) -> tuple[float, int, str]:
    """``(CPU seconds per pass, messages, digest)`` of ``passes`` passes after 50 unmeasured ones."""
    sys.path.insert(0, str(ROOT / "tests"))
    from harness.clock import FakeClock
    from rimd_sim.runtime.simulator import SimulatorRuntime, load_settings

    clock = FakeClock()
    digest = hashlib.sha256()
    count = [0]

    def send(key: str, data: bytes) -> None:
        count[0] += 1
        if key not in NOT_DIGESTED:
            digest.update(key.encode())
            digest.update(data)

    config, settings = load_settings({"seed": 0})
    rt = SimulatorRuntime(config, settings, send=send, clock=clock,
                          wall_ns=lambda: 1_790_000_000 * S + round((clock.now - 100.0) * S), warm_up=True)
    rt.start()

    def passes_of(n: int) -> None:
        done = 0
        while done < n:
            step = rt.step()
            if step.wait:
                clock.advance(step.wait)
            else:
                done += 1

    passes_of(50)
    t = time.thread_time()
    passes_of(passes)
    return (time.thread_time() - t) / passes, count[0], digest.hexdigest()[:16]


def measure(passes: int, rounds: int) -> dict:
    runs = [one_run(passes) for _ in range(rounds)]
    return {"best_us": 1e6 * min(r[0] for r in runs), "runs_us": [1e6 * r[0] for r in runs],
            "messages": runs[0][1], "digest": runs[0][2], "digests_agree": len({r[2] for r in runs}) == 1}


def other_tree(tree: Path, passes: int, rounds: int) -> dict:
    """:func:`measure` in a process of its own with ``tree``'s package first on the import path."""
    from bench_latency import environment

    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--passes", str(passes), "--rounds",
                          str(rounds), "--json-only"], env=environment(tree), capture_output=True, text=True,
                         timeout=600, cwd=tree)
    if out.returncode:
        raise SystemExit(f"bench_pass: the run of {tree} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--passes", type=int, default=3000)
    parser.add_argument("--rounds", type=int, default=3, help="runs per measurement; the best counts")
    parser.add_argument("--compare", type=Path, default=None, metavar="DIR", help="another checkout, alternately")
    parser.add_argument("--alternations", type=int, default=3, help="with --compare: measurements of each tree")
    parser.add_argument("--json-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.json_only:
        print(json.dumps(measure(args.passes, args.rounds)))
        return
    print(f"bench_pass: {args.passes} passes of one 10 ms block, best of {args.rounds}; load "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if args.compare is None:
        r = measure(args.passes, args.rounds)
        print(f"  {r['best_us']:.1f} us of CPU per pass ({', '.join(f'{x:.1f}' for x in r['runs_us'])}), "
              f"{r['messages']} messages, digest {r['digest']}")
        return
    from bench_latency import check_tree

    check_tree(args.compare.resolve())   # a checkout whose package is the one its runs import
    this_runs, other_runs, digests = [], [], set()
    for i in range(args.alternations):
        r = other_tree(ROOT, args.passes, args.rounds)   # this tree in a process of its own too, as the other
        o = other_tree(args.compare.resolve(), args.passes, args.rounds)
        this_runs.append(r["best_us"])
        other_runs.append(o["best_us"])
        digests |= {("this", r["digest"]), ("other", o["digest"])}
        print(f"  {i + 1}: this {r['best_us']:.1f} us, {args.compare} {o['best_us']:.1f} us per pass "
              f"(ratio {o['best_us'] / r['best_us']:.2f})")
    ratios = [o / t for o, t in zip(other_runs, this_runs, strict=True)]
    same = len({d for _, d in digests}) == 1
    print(f"  median: this {statistics.median(this_runs):.1f} us, other {statistics.median(other_runs):.1f} us; "
          f"ratio other / this {statistics.median(ratios):.2f} (> 1: this tree is faster); the messages "
          f"{'identical' if same else 'DIFFER: ' + str(sorted(digests))}; load "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
