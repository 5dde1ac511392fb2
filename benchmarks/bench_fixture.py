"""How long the ``rimd_rig`` fixture takes to bring up a ready rig, on an empty numba cache and on the warm one.

Each repeat is what a user's test does first: ``rimd_rig(consumers=["bench_daq"])`` (the product's plugin,
``rimd_sim.ros.testing.RigFactory``: simulator and recorder in lockstep, in a leased ROS domain, the fixture's
defaults), then ``rig.motor(4.0)``, then the rig is stopped. Two kinds of repeats:

* **cold**: the rig's processes get ``NUMBA_CACHE_DIR`` pointing at a new, empty directory (through the fixture's
  ``env``): the model is compiled as on a CI runner's first run;
* **warm**: the project's own cache (``__pycache__`` beside the sources, filled by ``make setup``).

For each repeat it prints the seconds from the call to the fixture returning (the rig ready:
docs/testing.md, "The fixture"), to the first ``rig.motor`` answered, and to the rig stopped; then
per kind the median, minimum and maximum. The fixture's default ready timeout (120 s) is meant to cover a cold
run on a slow 2-core runner with margin: compare with the cold figures.

Run on an otherwise idle machine (docs/benchmarks.md):
    python benchmarks/bench_fixture.py [--cold 1] [--warm 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path


def bring_up(base: Path, cold: bool) -> dict:
    """One repeat: the fixture's call, the first motor command, the stop (s from the call)."""
    from rimd_sim.ros.testing import RigFactory

    factory = RigFactory(base)
    env = {"NUMBA_CACHE_DIR": tempfile.mkdtemp(prefix="numba_", dir=base)} if cold else None
    started = time.monotonic()
    try:
        rig = factory(consumers=["bench_daq"], env=env)
        returned = time.monotonic() - started
        answer = rig.motor(4.0)
        answered = time.monotonic() - started
        if not answer.success:
            raise RuntimeError(f"the rig refused the motor command: {answer.message}")
    finally:
        factory.stop_all()
    return {"kind": "cold" if cold else "warm", "returned_s": returned, "motor_answered_s": answered,
            "stopped_s": time.monotonic() - started, "ready_after_s": rig.ready_after}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cold", type=int, default=1, help="repeats on an empty numba cache (default 1)")
    parser.add_argument("--warm", type=int, default=3, help="repeats on the project's warm cache (default 3)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    results = []
    with tempfile.TemporaryDirectory(prefix="bench_fixture_") as tmp:
        for cold, count in ((True, args.cold), (False, args.warm)):
            for i in range(count):
                r = bring_up(Path(tmp), cold)
                results.append(r)
                print(f"{r['kind']} {i + 1}/{count}: fixture returned after {r['returned_s']:.2f} s, first "
                      f"rig.motor answered after {r['motor_answered_s']:.2f} s, stopped after {r['stopped_s']:.2f} s",
                      flush=True)
    for kind in ("cold", "warm"):
        runs = [r for r in results if r["kind"] == kind]
        if not runs:
            continue
        for key, what in (("returned_s", "to the fixture returning"), ("motor_answered_s", "to the first motor")):
            values = [r[key] for r in runs]
            print(f"{kind} ({len(runs)} runs) {what}: median {statistics.median(values):.2f} s, min "
                  f"{min(values):.2f} s, max {max(values):.2f} s")
    from _figures import record  # the headline figures for report.py

    if cold := [r["returned_s"] for r in results if r["kind"] == "cold"]:   # warm: bench_latency.py's figure
        record("setup", "fixture ready, empty numba cache", statistics.median(cold), "s")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"results": results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
