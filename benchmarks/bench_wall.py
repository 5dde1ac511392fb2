"""Wall time of each analysis verb as a user runs it, against the time the verb prints (docs/analyses.md, "Progress").

Each verb runs as ``rimd VERB ... --out DIR`` in a new process (a temporary DIR), timed from the process's start to
its exit: the interpreter, the imports, the computation, the files and the exit. Its last line gives its own times
(``..., files written in B s, C s in all``: ``rimd_sim.cli.verbs._analysis_io.VerbClock``); the table prints, per
verb and size:

* ``wall s``: the process, start to exit;
* ``computed s``: the computation as the verb prints it (the sum of the ``in N s`` before ``files written``:
  ``rimd continue`` counts its brute-force diagram there too);
* ``files s``: ``files written in``, from the end of the computation to its files written, figure included;
* ``in all s``: ``in all``, from the verb's start (its ``main``) to its files written;
* ``wall/in all``: what the process adds (interpreter, imports before the verb, exit) as a ratio; the seconds
  themselves in ``outside s``.

Sizes, in one run: ``default``: each verb's defaults (``rimd map`` has none: the Peterka map's default grid, 61
frequencies x 31 gaps, from rest; ``rimd identify``: a 60 s recording of the default rig, the 6 steps of
``rimd experiment --for-identification`` written by the core, as benchmarks/bench_identify.py ``--time`` does);
``--large`` adds a large size per verb (Peterka and the map 200 x 200, basins 200 x 200, sweeps at 0.01 Hz,
the continuation's diagram at 300 frequencies, a 180 s recording), minutes each; ``--quick`` runs small sizes
instead of the defaults (seconds each: to check that the benchmark works). An exit status of 3 (points outside
the model's valid domain, its files written) counts as a run. The recordings for ``rimd identify`` are written
before the clock starts.

The machine is shared: the load average is printed at the start and at the end, and with each row; absolute times
want an idle machine. Run after ``source env.sh``:
    python benchmarks/bench_wall.py [--quick] [--large] [--only peterka,map,basins,sweep,bifurcation,continue,identify]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "rimd_sim"))
sys.path.insert(0, str(ROOT / "tests"))

VERBS = ("peterka", "map", "basins", "sweep", "bifurcation", "continue", "identify")
#: The last line's times: the computation's clause, then the files' and the whole verb's.
TIMES = re.compile(r"(?P<computed>[^:;]*), files written in (?P<files>[\d.]+) s, (?P<all>[\d.]+) s in all")
SECONDS = re.compile(r"in ([\d.]+) s\b")
#: Seconds of each step of the recordings ``rimd identify`` reads, per size.
DWELL = {"quick": 5.0, "default": 10.0, "large": 30.0}


@dataclass(frozen=True)
class Case:
    """One verb at one size: its label and its arguments (``--out`` added)."""

    verb: str
    size: str
    label: str
    args: tuple[str, ...]


def cases(recordings: dict[str, Path]) -> list[Case]:
    """Every verb at every size: ``quick``, ``default`` and ``large`` (the module docstring)."""
    rec = {size: str(path) for size, path in recordings.items()}
    out = [
        Case("peterka", "quick", "6 x 6", ("--gaps", "6", "--freqs", "6")),
        Case("peterka", "default", "31 x 61", ()),
        Case("peterka", "large", "200 x 200", ("--gaps", "200", "--freqs", "200")),
        Case("map", "quick", "6 x 6, frequency x gap", ("--x", "frequency", "--x-range", "3", "8", "6", "--y", "gap",
                                                       "--y-range", "0", "0.002", "6")),
        Case("map", "default", "61 x 31, frequency x gap", ("--x", "frequency", "--x-range", "1.82", "9.1", "61",
                                                           "--y", "gap", "--y-range", "0", "0.003", "31")),
        Case("map", "large", "200 x 200, frequency x gap", ("--x", "frequency", "--x-range", "1.82", "9.1", "200",
                                                           "--y", "gap", "--y-range", "0", "0.003", "200")),
        Case("basins", "quick", "8 x 8", ("--size", "8")),
        Case("basins", "default", "40 x 40", ()),
        Case("basins", "large", "200 x 200", ("--size", "200")),
        Case("sweep", "quick", "3 frequencies", ("--f-min", "3", "--f-max", "4", "--f-step", "0.5")),
        Case("sweep", "default", "31 frequencies", ()),
        Case("sweep", "large", "751 frequencies", ("--f-step", "0.01")),
        Case("bifurcation", "quick", "3 frequencies, both", ("--f-min", "4.8", "--f-max", "5.0", "--f-step", "0.1")),
        Case("bifurcation", "default", "151 frequencies, both", ()),
        Case("bifurcation", "large", "751 frequencies, both", ("--f-step", "0.01")),
        Case("continue", "quick", "3-3.5 Hz, diagram 5", ("--f-start", "3", "--f-end", "3.5",
                                                         "--diagram-points", "5")),
        Case("continue", "default", "3-6 Hz, diagram 60", ()),
        Case("continue", "large", "3-6 Hz, diagram 300", ("--diagram-points", "300")),
    ]
    for size, path in rec.items():
        out.append(Case("identify", size, f"{6 * DWELL[size]:.0f} s recording", (path,)))
    return out


def write_recordings(work: Path, sizes: list[str]) -> dict[str, Path]:
    """A recording of the default rig per size: the 6 identification steps, ``DWELL[size]`` s each, by the core."""
    from harness.ident_rigs import Schedule, write_core_recording
    from rimd_sim.analysis.identification.design import identification_steps
    from rimd_sim.settings.config import SimConfig

    out = {}
    for size in sizes:
        design = identification_steps(SimConfig(), dwell=DWELL[size], settle=3.0)
        path = work / f"identify_{size}.mcap"
        write_core_recording(path, {}, Schedule(design.frequencies, dwell=DWELL[size], start=0.0))
        out[size] = path
    return out


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (5 min {five:.2f}) on {os.cpu_count()} cores"


def run(case: Case, out: Path) -> dict:
    """``rimd VERB ARGS --out OUT`` in a new process: its exit status, wall seconds and printed times."""
    load = os.getloadavg()[0]
    argv = [shutil.which("rimd") or "rimd", case.verb, *case.args, "--out", str(out)]
    start = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True)
    wall = time.perf_counter() - start
    found = next((m for line in reversed(proc.stdout.splitlines()) if (m := TIMES.search(line))), None)
    row = {"case": case, "status": proc.returncode, "wall": wall, "load": load}
    if found is None:
        last = (proc.stderr.strip() or proc.stdout.strip() or "no output").splitlines()[-1]
        return {**row, "error": last}
    computed = sum(float(s) for s in SECONDS.findall(found["computed"]))
    return {**row, "computed": computed, "files": float(found["files"]), "all": float(found["all"])}


def table(rows: list[dict]) -> None:
    print(f"{'verb':<12} {'size':<32} {'exit':>4} {'wall s':>8} {'computed s':>10} {'files s':>8} {'in all s':>8} "
          f"{'wall/in all':>11} {'outside s':>9} {'load':>5}")
    for r in rows:
        c = r["case"]
        head = f"{c.verb:<12} {c.size + ': ' + c.label:<32} {r['status']:>4} {r['wall']:8.1f}"
        if "error" in r:
            print(f"{head}  no times printed: {r['error']}")
            continue
        ratio = r["wall"] / r["all"] if r["all"] > 0 else float("inf")
        print(f"{head} {r['computed']:10.1f} {r['files']:8.1f} {r['all']:8.1f} {ratio:11.2f} "
              f"{r['wall'] - r['all']:9.1f} {r['load']:5.2f}")


def record_figures(rows: list[dict]) -> None:
    """The headline figures for report.py (benchmarks/_figures.py).

    Every verb at its default size but ``rimd sweep`` and ``rimd identify`` (bench_analysis.py's Table 1 run and
    bench_identify.py ``--time`` give theirs); the Peterka map at its large size too, against its target of at
    most 35 s.
    """
    from _figures import record

    for r in rows:
        c = r["case"]
        if "error" in r or c.size == "quick" or c.verb in ("sweep", "identify"):
            continue
        if c.size == "default":
            record("analyses", f"`rimd {c.verb}`, {c.label}", r["wall"], "s")
        elif c.verb == "peterka":
            record("maps", f"`rimd peterka`, {c.label}", r["wall"], "s", "<= 35")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes instead of the defaults (seconds each)")
    parser.add_argument("--large", action="store_true", help="also the large sizes (minutes each)")
    parser.add_argument("--only", default=",".join(VERBS), metavar="VERB,...",
                        help=f"these verbs only (default all: {','.join(VERBS)})")
    args = parser.parse_args()
    only = [v.strip() for v in args.only.split(",") if v.strip()]
    unknown = sorted(set(only) - set(VERBS))
    if unknown:
        parser.error(f"--only: unknown verb(s) {', '.join(unknown)}; known: {', '.join(VERBS)}")
    sizes = ["quick" if args.quick else "default"] + (["large"] if args.large else [])
    print(f"rimd verbs end to end (process start to exit), sizes {', '.join(sizes)}; {_load()}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_wall_") as tmp:
        work = Path(tmp)
        recordings = write_recordings(work, sizes) if "identify" in only else {}
        for case in cases(recordings):
            if case.verb in only and case.size in sizes:
                rows.append(run(case, work / f"{case.verb}_{case.size}"))
                r = rows[-1]
                print(f"  {case.verb} {case.size} ({case.label}): {r['wall']:.1f} s, exit {r['status']}", flush=True)
    print()
    table(rows)
    record_figures(rows)
    print(f"\n{_load()} at the end")


if __name__ == "__main__":
    main()
