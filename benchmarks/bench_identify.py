"""Benchmark of ``rimd identify`` (docs/identification.md): a battery of rigs with faults and captures; the time target.

**The battery.** ``--rigs N`` rigs (default 14) drawn with a fixed seed across the documented ranges
(``tests/harness/ident_rigs.py``: mass 0.08-0.30 kg, damping ratio 0.02-0.12, natural frequency 1.5-2.2 Hz,
amplitude 0.6-1.5 mm, gap 0-2 mm, stiffness 1e6-1e7 N/m, contact damping 300-3000 N s/m). For each: the six steps
``rimd experiment --for-identification`` picks for it (10 s each), recorded through the rig as a user records
it (the simulator node started paused from rest with the hidden rig's file, ``rimd experiment`` at 8x; ``--core``:
the same schedule run by the core in this process and written as the recorder writes it, a few times faster),
then ``rimd identify`` in a new process as a user runs it. Per rig the table prints each parameter's error and
its printed 95 % interval, whether it is within its target (1 %; the gap 0.02 mm) or named by the verdict, and
how many intervals cover the truth. The totals: rigs identified or refused by name (target: all), intervals
covering the truth (target: at least 95 %). Errors are in % (the gap: in um). ``--seed S`` draws another battery
(default 24): the coverage on a second draw says the uncertainty is not fitted to the first.

``--faults``: each rig also with a 0.3 s force dropout over an impact, block loss on the RIMD laser (30 % for 3 s)
and a stuck cart laser (0.5 s), recorded as the battery is (through the rig, or ``--core``), against the clean
answer (target: within 1 %). ``--captures``: each rig also with the 1 MHz triggered captures; the contact's
parameters against the truth (target: within 0.5 %); ``--captures-only``: that section alone.

**The time.** ``--time``: a 60 s recording of 6 steps of the default rig (the steps of ``--for-identification``)
identified by ``rimd identify`` in a new process: wall and CPU time (target: at most 60 s on an idle machine).

The machine is shared: every time printed comes with the load average at its start. Run: ``.venv/bin/python
benchmarks/bench_identify.py [--rigs N] [--seed S] [--core] [--faults] [--captures] [--captures-only] [--time]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "rimd_sim"))
sys.path.insert(0, str(ROOT / "tests"))

from harness.ident_rigs import Schedule, draw_rigs, impact_near, record_through_rig, write_core_recording  # noqa: E402

NAMES = ("amplitude", "natural_frequency", "damping_ratio", "gap", "mass", "contact.stiffness", "contact.damping")
SHORT = {"amplitude": "A0", "natural_frequency": "f_n", "damping_ratio": "zeta", "gap": "gap", "mass": "m",
         "contact.stiffness": "k", "contact.damping": "c"}
DWELL = 10.0
FAULTS = [{"channel": "rimd_displacement", "kind": "block_loss", "start": 30.0, "duration": 3.0, "magnitude": 0.3},
          {"channel": "cart_displacement", "kind": "stuck", "start": 20.0, "duration": 0.5}]


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (5 min {five:.2f}) on {os.cpu_count()} cores"


def _identify(recording: Path, out: Path) -> tuple[dict, float, float]:
    """``rimd identify`` as a user runs it: the report, wall and CPU seconds."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    proc = subprocess.run([shutil.which("rimd") or "rimd", "identify", str(recording), "--out", str(out)],
                          capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        return {"refused": proc.stderr.strip().splitlines()[-1]}, wall, 0.0
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return json.loads((out / "identification.json").read_text()), wall, cpu


def _error(name: str, value: float, truth: float) -> float:
    """Relative error in %, or for the gap the absolute error in um."""
    return (value - truth) * 1e6 if name == "gap" else (value / truth - 1) * 100


def _row(i: int, rig: dict, report: dict, wall: float) -> tuple[str, int, int, bool]:
    """One table line: the parameters' errors (%, gap mm) with their 95 % intervals; covered, total, accepted."""
    if "refused" in report:
        return f"{i:>3} REFUSED: {report['refused']}", 0, 0, True
    poorly = {p["parameter"] for p in report["verdict"]["poorly_determined"]}
    cells, covered, accepted = [], 0, True
    for name in NAMES:
        est = report["estimates"][name]
        err = _error(name, est["value"], rig[name])
        hw = (est["interval_95"] or 0.0) * (1e6 if name == "gap" else 100 / rig[name])
        within = abs(err) <= (20.0 if name == "gap" else 1.0)
        named = name in poorly or "all" in poorly
        accepted &= within or named
        covered += abs(err) <= hw
        cells.append(f"{err:+7.3f}±{hw:<6.3f}{'' if within else ('n' if named else '!')}")
    verdict = "identified" if report["verdict"]["identified"] else "poor: " + ",".join(sorted(SHORT.get(p, p)
                                                                                           for p in poorly))
    return (f"{i:>3} " + " ".join(cells) + f" {covered}/7 {wall:6.1f} s {verdict}"), covered, len(NAMES), accepted


def _header() -> str:
    cells = " ".join(f"{SHORT[n] + (' um' if n == 'gap' else ' %'):>14}" for n in NAMES)
    return f"rig {cells} cover   wall verdict"


def _how(factory) -> str:
    return "by the core in this process" if factory is None else "through the rig (simulator node, rimd experiment)"


def _record(factory, where: Path, rig: dict, schedule: Schedule) -> Path:
    """``schedule`` on ``rig`` recorded through the rig (``factory``) or, when None, by the core; the recording."""
    if factory is None:
        recording = where.with_suffix(".mcap")
        write_core_recording(recording, rig, schedule)
        return recording
    return record_through_rig(factory, where, rig, schedule)


def battery(args: argparse.Namespace, work: Path, factory) -> None:
    from rimd_sim.analysis.identification.design import identification_steps
    from rimd_sim.settings.config import SimConfig

    rigs = draw_rigs(args.rigs, seed=args.seed)
    print(f"battery: {len(rigs)} rigs (seed {args.seed}), 6 steps of {DWELL:g} s each, recorded {_how(factory)}; "
          f"{_load()}")
    for i, rig in enumerate(rigs):
        print(f"  rig {i:>2}: " + ", ".join(f"{SHORT[n]} {rig[n] * (1e3 if n in ('gap', 'amplitude') else 1):.4g}"
                                             for n in NAMES))
    print(_header())
    totals = {"covered": 0, "params": 0, "accepted": 0, "walls": []}
    clean: dict[int, dict] = {}
    for i, rig in enumerate(rigs):
        design = identification_steps(SimConfig().with_parameters(rig), dwell=DWELL, settle=3.0)
        schedule = Schedule(design.frequencies, dwell=DWELL, seed=100 + i)
        report, wall, _ = _identify(_record(factory, work / f"rig{i}", rig, schedule), work / f"id{i}")
        line, covered, params, accepted = _row(i, rig, report, wall)
        print(line, flush=True)
        clean[i] = report
        totals["covered"] += covered
        totals["params"] += params
        totals["accepted"] += accepted
        totals["walls"].append(wall)
    n = len(rigs)
    print(f"identified within target or the parameter named by the verdict: {totals['accepted']}/{n} rigs "
          f"(target: all)")
    print(f"95 % intervals covering the truth: {totals['covered']}/{totals['params']} "
          f"({100 * totals['covered'] / max(totals['params'], 1):.1f} %; target: >= 95 %)")
    print(f"rimd identify wall time per 62 s recording: median {sorted(totals['walls'])[n // 2]:.1f} s, "
          f"largest {max(totals['walls']):.1f} s ({_load()} now)")
    if args.faults:
        faults(rigs, clean, work, factory)
    if args.captures:
        captures(rigs, work, factory)


def _case(i: int, rig: dict, work: Path, case: str, schedule: Schedule, factory) -> tuple[dict | None, float]:
    """Rig ``i`` on ``schedule``, recorded through the rig (``factory``) or, when None, by the core, identified.

    Returns the report (None, said on a line, when refused) and the wall time.
    """
    report, wall, _ = _identify(_record(factory, work / f"rig{i}_{case}", rig, schedule), work / f"id{i}_{case}")
    if "refused" in report:
        print(f"{i:>3} REFUSED: {report['refused']}")
        return None, wall
    return report, wall


def faults(rigs: list[dict], clean: dict[int, dict], work: Path, factory) -> None:
    """Each rig with a force dropout over an impact, block loss and a stuck laser, against its clean answer."""
    from rimd_sim.analysis.identification.design import identification_steps
    from rimd_sim.settings.config import SimConfig

    print(f"\nfaults ({_how(factory)}): a 0.3 s force dropout over an impact near 40 s, block loss 30 % on the "
          f"RIMD laser 30-33 s, the cart laser stuck 20-20.5 s; the answer against the clean one; {_load()}")
    print("rig " + " ".join(f"{SHORT[n] + (' um' if n == 'gap' else ' %'):>9}" for n in NAMES)
          + "  within 1 % / 20 um  kicks in the hole  windows said")
    ok_all = 0
    for i, rig in enumerate(rigs):
        if "estimates" not in clean.get(i, {}):
            continue
        design = identification_steps(SimConfig().with_parameters(rig), dwell=DWELL, settle=3.0)
        hidden = impact_near(rig, design.frequencies, 40.0, DWELL)
        extra = [{"channel": "impact_force", "kind": "dropout", "start": round(hidden - 0.15, 3), "duration": 0.3},
                 *FAULTS]
        report, _ = _case(i, rig, work, "faults", Schedule(design.frequencies, dwell=DWELL, faults=extra,
                                                           seed=100 + i), factory)
        if report is None:
            continue
        diffs = [_error(n, report["estimates"][n]["value"], clean[i]["estimates"][n]["value"]) for n in NAMES]
        ok = all(abs(d) <= (20.0 if n == "gap" else 1.0) for n, d in zip(NAMES, diffs, strict=True))
        in_hole = [k for k in report["kicks"] if abs(k["time_s"] - hidden) < 0.3]
        kinds = sorted({(w["topic"].rsplit("/", 1)[-1], w["kind"]) for w in report["left_out"]})
        ok_all += ok
        print(f"{i:>3} " + " ".join(f"{d:+9.4f}" for d in diffs) + f"  {'yes' if ok else 'NO':>18}  "
              f"{len(in_hole):>17}  {len(report['left_out'])} ({', '.join(f'{t} {k}' for t, k in kinds)})")
    print(f"within 1 % (gap 20 um) of the clean answer: {ok_all}/{len(rigs)} rigs (target: all)")


def captures(rigs: list[dict], work: Path, factory, only: set[int] | None = None) -> None:
    """Each rig with the 1 MHz triggered captures: the contact's parameters against the truth."""
    from rimd_sim.analysis.identification.design import identification_steps
    from rimd_sim.settings.config import SimConfig

    print(f"\ncaptures ({_how(factory)}, 1 MHz): the contact's parameters against the truth; {_load()}")
    print("rig        m %        k %        c %  k and c within 0.5 %")
    ok_all = 0
    for i, rig in enumerate(rigs):
        if only is not None and i not in only:
            continue
        design = identification_steps(SimConfig().with_parameters(rig), dwell=DWELL, settle=3.0)
        report, wall = _case(i, rig, work, "captures", Schedule(design.frequencies, dwell=DWELL, capture=True,
                                                                seed=100 + i), factory)
        if report is None:
            continue
        errs = [_error(n, report["estimates"][n]["value"], rig[n]) for n in ("mass", "contact.stiffness",
                                                                            "contact.damping")]
        ok = all(abs(e) <= 0.5 for e in errs[1:])   # the contact's parameters: k and c
        ok_all += ok
        print(f"{i:>3} " + " ".join(f"{e:+10.4f}" for e in errs) + f"  {'yes' if ok else 'NO':>20}  ({wall:.0f} s)")
    n = len(rigs) if only is None else len(only)
    print(f"contact (k, c) within 0.5 % with captures: {ok_all}/{n} rigs (target: all)")


def timing(work: Path) -> None:
    """The default rig, 60 s of 6 steps, identified in a new process (target: <= 60 s on an idle machine)."""
    from rimd_sim.analysis.identification.design import identification_steps
    from rimd_sim.settings.config import SimConfig

    design = identification_steps(SimConfig(), dwell=DWELL, settle=3.0)
    recording = work / "default.mcap"
    write_core_recording(recording, {}, Schedule(design.frequencies, dwell=DWELL, start=0.0))
    load = _load()
    report, wall, cpu = _identify(recording, work / "id_default")
    print(f"\ntime: the default rig, {len(design.frequencies)} steps of {DWELL:g} s ({design.frequencies} Hz), "
          f"60 s: rimd identify {wall:.1f} s wall, {cpu:.1f} s CPU ({load} at the start); target <= 60 s on an "
          "idle machine: " + ("met here" if wall <= 60 else "NOT met here"))
    from _figures import record  # the headline figures for report.py

    record("analyses", "`rimd identify`, 60 s recording", wall, "s", "<= 60")
    res = report.get("residuals", {})
    print(f"  joint fit: {res.get('iterations')} iterations, {res.get('evaluations')} model runs, "
          f"{res.get('segments')} segments, converged {res.get('converged')}; {report.get('verdict', {}).get('line')}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rigs", type=int, default=14, help="rigs in the battery (default 14)")
    parser.add_argument("--seed", type=int, default=24, help="seed of the battery's draw (default 24)")
    parser.add_argument("--core", action="store_true", help="record in the core, not through the rig")
    parser.add_argument("--faults", action="store_true", help="also each rig with faults")
    parser.add_argument("--captures", action="store_true", help="also each rig with captures")
    parser.add_argument("--time", action="store_true", help="only the time target (default rig, 60 s)")
    parser.add_argument("--captures-only", action="store_true",
                        help="only the captures' section (it needs no clean answer)")
    parser.add_argument("--only", default="", metavar="I,J,...",
                        help="with --captures-only: only these rigs of the draw (to share the work between runs)")
    args = parser.parse_args()
    only = None
    if args.only:
        if not args.captures_only:
            parser.error("--only applies to --captures-only")
        try:
            only = {int(i) for i in args.only.split(",")}
        except ValueError:
            parser.error(f"--only {args.only!r}: must be rig indices separated by commas, e.g. 0,3,7")
        if not all(0 <= i < args.rigs for i in only):
            parser.error(f"--only {args.only!r}: each index must be in 0..{args.rigs - 1}")
    with tempfile.TemporaryDirectory(prefix="bench_identify_") as tmp:
        work = Path(tmp)
        if args.time:
            timing(work)
            return
        factory = None
        if not args.core:   # each rig in lockstep with the experiment's recorder, on a ROS domain of its own
            from rimd_sim.ros.testing import RigFactory

            factory = RigFactory(work)
        try:
            if args.captures_only:
                print(f"battery: {args.rigs} rigs (seed {args.seed}), 6 steps of {DWELL:g} s each; {_load()}")
                captures(draw_rigs(args.rigs, seed=args.seed), work, factory, only)
            else:
                battery(args, work, factory)
        finally:
            if factory is not None:
                factory.stop_all()


if __name__ == "__main__":
    main()
