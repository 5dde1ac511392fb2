"""Compare this working tree with another revision: bit-identity, first-call compile time, and the benchmarks.

What a change of the physics drivers is held to against the revision it changes: the rigid model bit-identical on
the reference runs, the two-mass model giving the same pulses and maps, no slowdown of ``bench_core.py`` and
``bench_structural.py`` beyond 5 %, and no more compile time.

The other revision is exported with ``git archive REV`` into a temporary directory (no worktree, no change to
the repository). Each part runs both trees in separate interpreters, each importing its own ``rimd_sim``:

* ``identity``: a probe runs the same public calls in both trees (``RigModel`` on the reference points of
  ``tests/model/test_physics.py``, ``RigSimulator`` with commands and noise for both models and with the
  triggered capture, ``pulse``,
  ``steady_orbit``, ``sweep``, ``bifurcation``, ``peterka``, ``basins``, ``largest_lyapunov``) and prints a
  SHA-256 digest of every output (arrays by their bytes, impacts by their repr); the table says which differ.
* ``compile``: with an empty numba cache (``NUMBA_CACHE_DIR``), the time of each first call (import, rigid
  model, two-mass model, rigid ensemble), then the same again with the cache filled (cache hits).
* ``bench``: ``bench_core.py`` and ``bench_structural.py`` of each tree (each measures its own code), run
  alternately, base first then head, ``--rounds`` times; every real-time factor they print is paired with the
  same figure of the same round, and the median ratio head/base per figure is printed (> 1: head is faster).
  ``--clock cpu`` (the default) runs both benchmarks with ``time.perf_counter`` replaced by
  ``time.thread_time``, the CPU time of the benchmark's thread (the core runs in it), so that a machine shared
  with other work disturbs the figures less; ``--clock wall`` leaves them as they are. The load average is
  printed with each round: on a shared machine the figures are preliminary.

``--head REV`` compares an exported revision instead of this working tree (so the tree can change meanwhile).

Run: .venv/bin/python benchmarks/compare_revisions.py [--base REV] [--head REV] [--parts identity,compile,bench]
[--rounds 3] [--seconds 10] [--clock cpu|wall]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# A revision from before the package's layers (rimd_sim.core, rimd_sim.analysis.sweep, ...) runs the same probe:
# the layered names the probe imports are aliases of the old modules there.
LAYOUT_ALIASES = r"""
import importlib, importlib.util, sys
if importlib.util.find_spec("rimd_sim.settings") is None:
    aliases = {
        "rimd_sim.settings": "rimd_sim.core", "rimd_sim.settings.config": "rimd_sim.core.config",
        "rimd_sim.settings.capture": "rimd_sim.core.capture", "rimd_sim.model": "rimd_sim.core",
        "rimd_sim.model.rig_model": "rimd_sim.core.model", "rimd_sim.instruments": "rimd_sim.core",
        "rimd_sim.instruments.rig_simulator": "rimd_sim.core.simulator",
        "rimd_sim.analysis.dynamics": "rimd_sim.analysis",
        "rimd_sim.analysis.dynamics.pulse": "rimd_sim.analysis.pulse",
        "rimd_sim.analysis.dynamics.steady": "rimd_sim.analysis.dynamics",
        "rimd_sim.analysis.dynamics.sweep": "rimd_sim.analysis.sweep",
        "rimd_sim.analysis.dynamics.bifurcation": "rimd_sim.analysis.bifurcation",
        "rimd_sim.analysis.dynamics.peterka": "rimd_sim.analysis.peterka",
        "rimd_sim.analysis.dynamics.lyapunov": "rimd_sim.analysis.lyapunov",
    }
    sys.modules.update({new: importlib.import_module(old) for new, old in aliases.items()})
if importlib.util.find_spec("rimd_sim.analysis.dynamics.basins") is None:   # basins in the Peterka map's module
    sys.modules["rimd_sim.analysis.dynamics.basins"] = importlib.import_module("rimd_sim.analysis.dynamics.peterka")
"""

IDENTITY_PROBE = LAYOUT_ALIASES + r"""
import hashlib, json, math, sys
from fractions import Fraction
import numpy as np
from rimd_sim.model.rig_model import RigModel
from rimd_sim.settings.config import SimConfig, load_config
from rimd_sim.settings.config import find_config_file
from rimd_sim.instruments.rig_simulator import RigSimulator

only = set(sys.argv[1:])
out = {}

def digest(*parts):
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(str(part.dtype).encode() + str(part.shape).encode())
            h.update(np.ascontiguousarray(part).tobytes())
        else:
            h.update(repr(part).encode())
    return h.hexdigest()[:16]

def points(strobe):
    # The fields both revisions have (a point may carry the model's modes too).
    return [tuple(s)[:4] for s in strobe]

def want(name):
    return not only or any(name.startswith(o) for o in only)

def at(cfg, f, **kw):
    return cfg.with_parameters({"motor.initial_frequency": f, "motor.initial_setpoint": f, **kw})

rigid = SimConfig()
two = load_config(find_config_file("structural.yaml"))

for gap, f in [(0.0, 3.75), (0.0, 7.25), (1.0e-3, 3.0), (2.4e-3, 5.25), (0.0, 5.5)]:
    name = f"rigid RigModel gap {gap * 1e3:g} mm {f} Hz 16 s"
    if want(name):
        o = RigModel(at(rigid, f, gap=gap), strobe=True).advance(16.0)
        out[name] = digest(o.impacts, points(o.strobe), o.truth[1], *[c[1] for c in o.channels.values()])

def commands(cfg, seconds):
    sim = RigSimulator(cfg, strobe=True)
    sim.set_motor_frequency(7.25, 4.0, at=Fraction(3, 2))
    sim.perturb(0.05, at=Fraction(13, 5))
    sim.reset(at=Fraction(17, 4))
    parts = []
    t = Fraction(0)
    while t < seconds:
        t += Fraction(1, 7)
        b = sim.advance(t)
        parts += [b.impacts, points(b.strobe), b.truth[1] if b.truth else None]
        parts += [c.samples for c in b.channels.values()]
    return digest(*parts)

for label, cfg in (("rigid", rigid), ("two_mass", two)):
    name = f"{label} RigSimulator ramp, perturb, reset, noise 6 s"
    if want(name):
        out[name] = commands(at(cfg, 3.75), 6)
name = "rigid RigSimulator with the triggered capture (1 MHz), 3 s"
if want(name):
    from rimd_sim.settings.capture import CaptureConfig
    sim = RigSimulator(at(rigid, 3.75), capture=CaptureConfig(enabled=True))
    b = sim.advance(3)
    out[name] = digest(b.impacts, [(c.number, c.trigger_index, c.force, c.acceleration) for c in b.captures],
                       *[c.samples for c in b.channels.values()])
for gap, f in [(0.0, 3.75), (0.0, 7.25), (1.0e-3, 6.5), (0.0, 9.0)]:
    name = f"two_mass RigSimulator gap {gap * 1e3:g} mm {f} Hz 8 s"
    if want(name):
        b = RigSimulator(at(two, f, gap=gap), strobe=True).advance(8)
        out[name] = digest(b.impacts, points(b.strobe), b.truth[1], *[c.samples for c in b.channels.values()])
name = "two_mass reconfigured to rigid link and mount while ringing"
if want(name):
    sim = RigSimulator(at(two, 3.75, **{"noise.enabled": False}))
    sim.set_parameters({"structure.axial_stiffness": 0.0, "structure.mount_stiffness": 0.0}, at=Fraction(4001, 1000))
    b = sim.advance(6)
    out[name] = digest(b.impacts, *[c.samples for c in b.channels.values()])

from rimd_sim.analysis.dynamics.pulse import pulse
for label, cfg, v in (("rigid", rigid, 0.07), ("two_mass", two, 0.066), ("two_mass", two, 0.3)):
    name = f"{label} pulse {v} m/s"
    if want(name):
        r = pulse(cfg, v)
        # The keys both revisions have (the summary may carry the valid domain's marks too).
        summary = {k: v for k, v in r.summary.items()
                   if k not in ("max_abs_theta_rad", "max_force_n", "valid", "invalid_rule", "validity")}
        out[name] = digest(json.dumps(summary, sort_keys=True), r.force, r.acceleration)

from rimd_sim.analysis.dynamics.steady import steady_orbit
for label, cfg in (("rigid", rigid), ("two_mass", two)):
    for gap, f in [(0.0, 3.75), (1.0e-3, 4.6), (2.4e-3, 5.25)]:
        name = f"{label} steady_orbit gap {gap * 1e3:g} mm {f} Hz"
        if want(name):
            o = steady_orbit(cfg.with_parameters({"gap": gap}), f, transient_cycles=60, measure_cycles=24)
            out[name] = digest(o.label, o.u, o.v, o.theta, o.theta_dot, o.peak_forces)

from rimd_sim.analysis.dynamics.sweep import sweep
from rimd_sim.analysis.dynamics.bifurcation import bifurcation
for label, cfg in (("rigid", rigid), ("two_mass", two)):
    name = f"{label} sweep up gap 2.4 mm"
    if want(name):
        r = sweep(cfg.with_parameters({"gap": 2.4e-3}), np.arange(2.0, 3.51, 0.5), "up", cycles=60, measure_cycles=20)
        # The fields both revisions have (a point may carry the valid domain's marks too).
        out[name] = digest([tuple(getattr(p, f) for f in ("frequency_hz", "frequency_ratio", "peak_force_n",
                                                        "force_ratio", "impacts_per_cycle", "simulated_seconds"))
                            for p in r.points])
    name = f"{label} bifurcation both gap 0"
    if want(name):
        br, _, _ = bifurcation(cfg, [4.6, 4.8, 5.0], "both", transient_cycles=30, sample_cycles=12, workers=1)
        out[name] = digest([(b.direction, [(p.frequency_hz, p.label, p.u) for p in b.points]) for b in br])

from rimd_sim.analysis.dynamics.basins import basins
from rimd_sim.analysis.dynamics.peterka import peterka
name = "rigid peterka 3 x 6"
if want(name):
    r = peterka(rigid, [0.0, 1.2e-3, 2.4e-3], np.linspace(3.0, 8.0, 6), transient_cycles=60, measure_cycles=36,
                workers=1)
    out[name] = digest(r.labels.tolist(), r.cycles)
name = "rigid basins 4 x 3, 2.4 mm, 5.25 Hz"
if want(name):
    r = basins(rigid.with_parameters({"gap": 2.4e-3}), 5.25, (-0.1, 0.02), (-1.0, 1.0), size=(4, 3), workers=1)
    out[name] = digest(r.labels.tolist(), r.cycles)

from rimd_sim.analysis.dynamics.lyapunov import largest_lyapunov
for gap, f in [(1.0e-3, 4.6), (0.0, 3.75)]:
    name = f"rigid largest_lyapunov gap {gap * 1e3:g} mm {f} Hz"
    if want(name):
        r = largest_lyapunov(rigid.with_parameters({"gap": gap}), f, transient_cycles=40, cycles=40)
        out[name] = digest(r.exponent.hex(), r.running)

print(json.dumps(out))
"""

COMPILE_PROBE = """
import time
t0 = time.perf_counter()
""" + LAYOUT_ALIASES + r"""
import numpy as np
from rimd_sim.settings.config import SimConfig, load_config
from rimd_sim.settings.config import find_config_file
from rimd_sim.instruments.rig_simulator import RigSimulator
steps = [("import", time.perf_counter() - t0)]
def timed(name, fn):
    t = time.perf_counter()
    fn()
    steps.append((name, time.perf_counter() - t))
cfg = SimConfig().with_parameters({"motor.initial_frequency": 3.75, "motor.initial_setpoint": 3.75})
timed("rigid RigSimulator (driver, instruments), 1 s", lambda: RigSimulator(cfg, strobe=True).advance(1))
two = load_config(find_config_file("structural.yaml"))
timed("two_mass RigSimulator (driver), 1 s", lambda: RigSimulator(two, strobe=True).advance(1))
from rimd_sim.analysis.dynamics.peterka import peterka
timed("rigid ensemble (a 1 x 1 Peterka map)", lambda: peterka(SimConfig(), [0.0], [3.75], transient_cycles=30,
      measure_cycles=12, workers=1))
try:
    timed("two_mass ensemble (a 1 x 1 Peterka map)", lambda: peterka(two, [0.0], [3.75], transient_cycles=30,
          measure_cycles=12, workers=1))
except Exception as exc:
    steps.append(("two_mass ensemble (a 1 x 1 Peterka map)", None))
for name, s in steps:
    print(f"{name}\t{'' if s is None else f'{s:.2f}'}")
"""


def export(rev: str, into: Path) -> Path:
    """``git archive REV`` of the code, the interface package, configuration, benchmarks and tests into ``into``."""
    # rimd_msgs too: without it the tree is not a source checkout (settings.paths.source_root) and finds no config.
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "rimd_sim", "rimd_msgs", "config", "benchmarks",
                              "tests"],
                             check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into


#: Runs a benchmark script (argv[1]) with its arguments, ``time.perf_counter`` replaced by the thread's CPU time.
CPU_CLOCK = ("import os, runpy, sys, time; time.perf_counter = time.thread_time; sys.argv = sys.argv[1:]; "
             "sys.path.insert(0, os.path.dirname(sys.argv[0])); runpy.run_path(sys.argv[0], run_name='__main__')")


def run(tree: Path, argv: list[str], env: dict | None = None) -> str:
    full = {**os.environ, "PYTHONPATH": str(tree / "rimd_sim"), "NUMBA_NUM_THREADS": "1", **(env or {})}
    proc = subprocess.run([sys.executable, *argv], cwd=tree, env=full, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{tree}: {' '.join(argv[:2])} failed:\n{proc.stderr[-3000:]}")
    return proc.stdout


def identity(base: Path, head: Path, only: list[str]) -> bool:
    print("== bit-identity of the outputs (SHA-256 of each, first 16 hex digits)")
    results = {}
    for name, tree in (("base", base), ("head", head)):
        t = time.perf_counter()
        results[name] = json.loads(run(tree, ["-c", textwrap.dedent(IDENTITY_PROBE), *only]).splitlines()[-1])
        print(f"  {name}: {len(results[name])} outputs in {time.perf_counter() - t:.0f} s")
    same = True
    for key in sorted(set(results["base"]) | set(results["head"])):
        a, b = results["base"].get(key), results["head"].get(key)
        verdict = "identical" if a == b else "DIFFERENT"
        same &= a == b
        print(f"  {verdict:9} {key}: {a} {b if a != b else ''}")
    print(f"  => {'every output bit-identical' if same else 'outputs differ'}")
    return same


def compile_times(base: Path, head: Path) -> None:
    print("== first-call time with an empty numba cache (cold), then with the cache filled (warm), seconds")
    table: dict[str, dict[str, str]] = {}
    for name, tree in (("base", base), ("head", head)):
        with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache:
            for when in ("cold", "warm"):
                text = run(tree, ["-c", COMPILE_PROBE], {"NUMBA_CACHE_DIR": cache})
                for line in text.splitlines():
                    step, _, seconds = line.partition("\t")
                    table.setdefault(step, {})[f"{name} {when}"] = seconds or "-"
    cols = ["base cold", "head cold", "base warm", "head warm"]
    print(f"  {'step':52} " + " ".join(f"{c:>9}" for c in cols))
    for step, row in table.items():
        print(f"  {step:52} " + " ".join(f"{row.get(c, '-'):>9}" for c in cols))
    print(f"  load average {os.getloadavg()[0]:.2f}")


_ROW = re.compile(r"^\s*(\d+\.\d)\s+(\d+\.\d\d)\s+(.*)$")
_FACTOR = re.compile(r"(\d+)x")


def figures(bench: str, text: str) -> dict[str, float]:
    """Every real-time factor (``NNNx``) the benchmark printed, keyed by bench, row and column."""
    found = {}
    for line in text.splitlines():
        m = _ROW.match(line)
        if m:
            for i, value in enumerate(_FACTOR.findall(m.group(3))):
                found[f"{bench} gap {m.group(1)} mm {m.group(2)} Hz col {i}"] = float(value)
        elif "instrument chain" in line or "median real-time factor" in line:
            head = line.split(":")[0][:40]
            for i, value in enumerate(_FACTOR.findall(line)):
                found[f"{bench} {head} #{i}"] = float(value)
    return found


def benches(base: Path, head: Path, rounds: int, seconds: float, clock: str) -> None:
    print(f"== benchmarks, {rounds} rounds, base then head in each round, --seconds {seconds:g}, clock: "
          f"{'CPU time of the thread' if clock == 'cpu' else 'wall (perf_counter)'}")
    ratios: dict[str, list[float]] = {}
    for r in range(rounds):
        for bench in ("bench_core.py", "bench_structural.py"):
            got = {}
            for name, tree in (("base", base), ("head", head)):
                load = os.getloadavg()[0]
                script = [str(tree / "benchmarks" / bench), "--seconds", str(seconds)]
                got[name] = figures(bench, run(tree, ["-c", CPU_CLOCK, *script] if clock == "cpu" else script))
                print(f"  round {r + 1} {bench:20} {name}: {len(got[name])} figures (load average {load:.2f})",
                      flush=True)
            for key in got["base"].keys() & got["head"].keys():
                ratios.setdefault(key, []).append(got["head"][key] / got["base"][key])
    print("  median ratio head/base per figure (> 1: head faster), and its rounds:")
    for key in sorted(ratios):
        print(f"  {statistics.median(ratios[key]):6.3f}  {key}  {[round(x, 3) for x in ratios[key]]}")
    allr = [statistics.median(v) for v in ratios.values()]
    print(f"  median over the figures {statistics.median(allr):.3f}, lowest {min(allr):.3f}, highest {max(allr):.3f}; "
          f"load average now {os.getloadavg()[0]:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default=None,
                        help="revision to compare with (default: git merge-base HEAD main)")
    parser.add_argument("--head", default=None, help="revision to compare (default: this working tree)")
    parser.add_argument("--parts", default="identity,compile,bench", help="identity, compile, bench")
    parser.add_argument("--clock", choices=("cpu", "wall"), default="cpu",
                        help="benchmark clock: the thread's CPU time (default) or the wall clock")
    parser.add_argument("--rounds", type=int, default=3, help="alternating benchmark rounds")
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per benchmark figure")
    parser.add_argument("--only", nargs="*", default=[], help="identity: only the outputs whose name starts so")
    args = parser.parse_args()
    parts = set(args.parts.split(","))
    if args.base is None:
        args.base = subprocess.run(["git", "-C", str(ROOT), "merge-base", "HEAD", "main"], capture_output=True,
                                   text=True, check=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="rimd-base-") as tmp, \
            tempfile.TemporaryDirectory(prefix="rimd-head-") as tmp_head:
        base = export(args.base, Path(tmp))
        tree = ROOT if args.head is None else export(args.head, Path(tmp_head))
        rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.base], capture_output=True,
                             text=True).stdout.strip()
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.head or "HEAD"],
                              capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "rimd_sim"], capture_output=True,
                               text=True).stdout.strip()
        what = (f"this tree (HEAD {head}{', with uncommitted changes' if dirty else ''})" if args.head is None
                else f"{args.head} ({head})")
        print(f"base {args.base} ({rev}) against {what}; load average {os.getloadavg()[0]:.2f}")
        if "identity" in parts:
            identity(base, tree, args.only)
        if "compile" in parts:
            compile_times(base, tree)
        if "bench" in parts:
            benches(base, tree, args.rounds, args.seconds, args.clock)


if __name__ == "__main__":
    main()
