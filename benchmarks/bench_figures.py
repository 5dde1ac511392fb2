"""What the figure worker buys: one ``rimd sweep`` point with its figure, the worker on and off, alternately.

``rimd`` draws a command's figures in a worker process started before the computation
(:mod:`rimd_sim.analysis.figures`), so that matplotlib's import overlaps the computation on the other core. This
benchmark runs the same command as ``rimd`` does (its cycle collector set, :func:`rimd_sim.cli.entry`) once with
the worker and once drawing in the command's process, alternating the order round by round, and prints each
variant's median wall time from process start to exit and what the worker buys: ``1 - on / off``.

Run: .venv/bin/python benchmarks/bench_figures.py [--rounds 6]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

from _figures import record

#: The command of one variant: ``rimd sweep`` of one point, the worker on (``on``) or off, as ``rimd`` runs it.
SCRIPT = """
import sys
from rimd_sim import cli
from rimd_sim.analysis import figures
from rimd_sim.runtime import collector
collector.configure()
if sys.argv[1] == "on":
    figures.use_own_process()
try:
    status = cli.main(["sweep", "--f-min", "3", "--f-max", "3", "--out", sys.argv[2]])
finally:
    collector.keep_what_exists()
sys.exit(status)
"""


def run(variant: str) -> float:
    """Wall time (s) of one run of ``variant``, from process start to exit."""
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", SCRIPT, variant, out], check=True, capture_output=True)
        return time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=6, help="runs of each variant (default 6)")
    args = parser.parse_args()
    print(f"bench_figures: load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    run("on")   # the numba and page caches warm before anything is timed
    times: dict[str, list[float]] = {"on": [], "off": []}
    for round_ in range(args.rounds):
        for variant in ("on", "off") if round_ % 2 == 0 else ("off", "on"):
            times[variant].append(run(variant))
    on, off = statistics.median(times["on"]), statistics.median(times["off"])
    for variant, values in times.items():
        print(f"  worker {variant:3s}: median {statistics.median(values):.3f} s  "
              f"({', '.join(f'{v:.2f}' for v in values)})")
    print(f"the worker buys {100 * (1 - on / off):.0f} % of the point's wall time")
    record("analyses", "one `rimd sweep` point, figure worker on", on, "s")
    record("analyses", "one `rimd sweep` point, figure drawn in the command", off, "s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
