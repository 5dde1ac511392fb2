"""Benchmark of ``rimd identify`` (issue 14): a 60 s recording of 6 frequency steps, target <= 60 s.

The recording is the core's run of the default rig (gap 0, noise on) with the motor stepped every 10 s through
3.0, 3.25, 3.5, 3.75, 4.0, 4.25 Hz (band A) at 2 Hz/s, written as the recorder writes it (rosbag2 MCAP, the rig
topics, 100 blocks/s): the same data the running rig gives for that schedule (tests/test_experiment.py shows the
recorded data equal the core's offline run sample for sample). Then ``rimd identify REC`` runs as a user runs
it (a new process: imports, reading, local estimates, the joint refinement, the outputs) and its wall time, CPU
time and the recovered parameters are printed. The machine is shared: the figures vary with its load, which is
printed with them. Run: .venv/bin/python benchmarks/bench_identify.py
"""

from __future__ import annotations

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

from harness.rig_mcap import write_rig_mcap  # noqa: E402

FREQS = (3.0, 3.25, 3.5, 3.75, 4.0, 4.25)
DWELL = 10.0
TARGET_S = 60.0


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="bench_identify_") as tmp:
        rec = Path(tmp) / "rec.mcap"
        t = time.perf_counter()
        write_rig_mcap(rec, DWELL * len(FREQS), FREQS[0],
                       commands=tuple((DWELL * k, f) for k, f in enumerate(FREQS) if k))
        print(f"recording: {DWELL * len(FREQS):.0f} s, {len(FREQS)} steps, {rec.stat().st_size / 1e6:.1f} MB, "
              f"written in {time.perf_counter() - t:.1f} s")
        out = Path(tmp) / "id"
        load = os.getloadavg()
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        proc = subprocess.run([shutil.which("rimd") or "rimd", "identify", str(rec), "--out", str(out)],
                              capture_output=True, text=True)
        wall = time.perf_counter() - t
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode != 0:
            sys.exit(f"rimd identify failed: {proc.stderr.strip().splitlines()[-1]}")
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        report = json.loads((out / "identification.json").read_text())
        truth = {"amplitude": 1e-3, "natural_frequency": 1.82, "damping_ratio": 0.08, "gap": 0.0, "mass": 0.15,
                 "contact.stiffness": 5.5e6, "contact.damping": 1.2e3}
        for name, est in report["estimates"].items():
            err = est["value"] - truth[name] if name == "gap" else est["value"] / truth[name] - 1
            unit = " m" if name == "gap" else ""
            print(f"  {name:<18} {est['value']:.6g} (true {truth[name]:g}; error {err:+.2e}{unit})")
        print(f"rimd identify: {wall:.1f} s wall, {cpu:.1f} s CPU (load average before: "
              f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores); target <= {TARGET_S:.0f} s: "
              + ("met" if wall <= TARGET_S else "NOT met"))
        print(f"  joint refinement: {report['residuals']['evaluations']} evaluations; steps of the validation: "
              + ", ".join(f"{r['frequency_hz']:g} Hz {r['peak_force_difference'] * 100:+.2f} %"
                          for r in report["validation"] if r["peak_force_difference"] is not None))


if __name__ == "__main__":
    main()
