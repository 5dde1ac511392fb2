"""Benchmark of the maps at scale (docs/analyses.md): early stopping, batching, Dask workers, big maps.

Prints, in one run (ratios are measured within the run; the machine is shared, so absolute times are noisy and
the load average is printed with each figure):

1. The steps, on an S x S Peterka map (default 60 x 60, 3 starts per cell), local pool on all cores:
   a. per trajectory: one ``RigModel`` per trajectory through ``steady_orbit``, fixed 60 + 36 cycles
      (no ensemble kernel);
   b. batching: the ensemble kernel (every trajectory of a gap row in one compiled call), same fixed cycles;
   c. early stop: the ensemble kernel stopping each trajectory when its motion is known (the ``window`` stop),
      cap 96 cycles;
   d. early stop with the cap at 192 cycles (120 + 72), the ``window`` stop;
   e. the default: the same cap, the ``contraction`` stop (docs/analyses.md, Maps at scale).
   Speed-up of each step against the one before, and of d and e against a.
2. The default 31 x 61 map: early stop (d) against the fixed-length run of 192 cycles: agreement
   per start and every differing cell, with a 10x longer run's class.
3. 200 x 200 with the default (the ``contraction`` stop, target <= 30 s on 2 workers) and, in the same run, with
   the ``window`` stop (the ratio); then an N x N map (default 400) to project 1000 x 1000 (measured there
   if --big 1000).
4. Scaling: the S x S map through a real Dask scheduler with 1 and then 2 ``dask worker`` processes (one thread
   each) on loopback: efficiency t1 / (2 t2) (target >= 90 %); the time per cell-cycle against one
   trajectory's own speed in the core.
6. Agreement with a reference ten times as long: on an R x R map (default 100, ``--reference-size``), the class
   from rest of the default map (``contraction``) and of the ``window`` stop against ``rest_classes``: every
   trajectory from rest run 1920 cycles (ten times the cap, no early stop), its last 72 classified (target
   >= 99.5 % of the cells); the cells each gets wrong where the other is right; the time of both maps (ratio).
7. How reproducible that reference is: on an N x N map (default 40, ``--tolerance-size``), the 1920-cycle class
   from rest at ``integrator.rtol`` 1e-7 (the default), 1e-8 and 1e-9, pairwise; and the default map and the map
   with ``rest_cycles=1920`` against each (sections 3 and 6 also run ``rest_cycles=1920``: its time against the
   default's, its agreement with the reference).
8. The start from rest's cap against the agreement (not in the default sections): the 1920-cycle reference on
   R x R, the map at each of ``--rest-caps`` (default 192,480,640,960,1920) against it with its time, and the
   200 x 200 map's time at each of ``--rest-caps-big`` (default 192,640).
5. The single-trajectory core as users meet it: ``rimd sweep --workers 1`` (gap 1 mm, 1.5-9 Hz at 0.05 Hz, 300
   cycles from rest) in real-time factor, and the scipy ``solve_ivp`` event-driven reference
   (tests/harness/reference.py, DOP853, rtol 1e-7 as the core) on a sample of its points; ratio (goal >= 1,000x).

Run: .venv/bin/python benchmarks/bench_maps.py [--steps-size 60] [--big 400] [--skip-big] [--skip-dask]
[--sections 1,2,3,4,5,6,7,8] [--workers 2] [--reference-size 100] [--tolerance-size 40] [--rest-caps 192,640]
[--rest-caps-big 192,640]. Sections 2 and 4 run the
default stop (``contraction``). ``--compare DIR [--compare-map-size 200] [--rounds 2]`` runs only the default map,
in this tree and in another checkout alternately (fresh processes), and prints the ratio and whether the classes
and cycles are identical.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "rimd_sim"))
sys.path.insert(0, str(ROOT / "tests"))

import numpy as np  # noqa: E402
from _figures import record  # noqa: E402 - benchmarks/_figures.py: the headline figures for report.py

from rimd_sim.analysis.dynamics import peterka as pk  # noqa: E402
from rimd_sim.analysis.dynamics.steady import steady_orbit  # noqa: E402
from rimd_sim.analysis.executor import run_tasks  # noqa: E402
from rimd_sim.errors import IntegrationError  # noqa: E402
from rimd_sim.model.rig_model import RigModel  # noqa: E402
from rimd_sim.settings.config import SimConfig  # noqa: E402


def load() -> str:
    return f"load {os.getloadavg()[0]:.1f}"


def grid(n: int, m: int | None = None):
    return np.linspace(0, 3e-3, n), np.linspace(1.82, 9.1, m or n)


def _classify(config, f, theta0, theta_dot0, transient, measure):
    """The class and final state of one trajectory through ``steady_orbit`` (one ``RigModel``, a fixed length)."""
    try:
        orbit = steady_orbit(config, f, theta0=theta0, theta_dot0=theta_dot0, transient_cycles=transient,
                             measure_cycles=measure)
    except IntegrationError:
        return "integration failed", (0.0, 0.0)
    return orbit.label, orbit.final_state


def per_trajectory_row(args):
    """One gap row of the Peterka map's three starts, one ``RigModel`` per trajectory, at a fixed length."""
    base, gap, freqs, transient, measure, continued_transient = args
    cfg = base.with_parameters({"gap": gap})
    rig = cfg.rig
    kick = rig.omega_n * (gap + 2.0 * rig.amplitude) / rig.length  # rad/s
    out = []
    state = (0.0, 0.0)
    for f in freqs:
        rest, final = _classify(cfg, f, 0.0, 0.0, transient, measure)
        kicked, _ = _classify(cfg, f, 0.0, kick, transient, measure)
        cont, state = _classify(cfg, f, state[0], state[1], continued_transient, measure)
        if cont == "integration failed":
            state = final
        out.append((rest, kicked, cont))
    return out


def legacy_map(config, gaps, freqs, workers=None):
    """Step a: the per-trajectory path, fixed 60 + 36 (continued 30 + 36) cycles."""
    jobs = [(config, float(g), list(freqs), 60, 36, 30) for g in gaps]
    t0 = time.perf_counter()
    rows, n, _ = run_tasks(per_trajectory_row, jobs, workers=workers)
    return time.perf_counter() - t0, np.array(rows, dtype=object).transpose(2, 0, 1)


def timed_map(config, gaps, freqs, **kw):
    t0 = time.perf_counter()
    res = pk.peterka(config, gaps, freqs, **kw)
    return time.perf_counter() - t0, res


def cycles_of(res) -> float:
    return float(res.cycles.sum())


def steps(config, size, workers):
    gaps, freqs = grid(size)
    cells = size * size
    print(f"\n1. Steps on a {size} x {size} map ({cells} cells x 3 starts), local pool, {load()}")
    ta, la = legacy_map(config, gaps, freqs, workers)
    print(f"  a. before (RigModel per trajectory, fixed 96 cycles):      {ta:7.1f} s   {load()}")
    tb, rb = timed_map(config, gaps, freqs, transient_cycles=60, measure_cycles=36, continued_transient_cycles=30,
                       early_stop=False, workers=workers)
    same = float((rb.labels == la).mean())
    print(f"  b. + batching (ensemble kernel, fixed 96 cycles):           {tb:7.1f} s   x{ta / tb:.2f} vs a "
          f"(classes identical to a in {100 * same:.2f} % of cell-starts)   {load()}")
    tc, rc = timed_map(config, gaps, freqs, transient_cycles=60, measure_cycles=36, continued_transient_cycles=30,
                       stop="window", workers=workers)
    print(f"  c. + early stop (cap 96 cycles):                            {tc:7.1f} s   x{tb / tc:.2f} vs b; "
          f"mean {rc.cycles.mean():.1f} cycles per trajectory, {100 * (rc.cycles <= 96).mean():.1f} % stopped "
          f"early   {load()}")
    td, rd = timed_map(config, gaps, freqs, stop="window", workers=workers)
    print(f"  d. early stop (window), cap 192 = 2 x 96:                   {td:7.1f} s   x{tc / td:.2f} vs c; "
          f"x{ta / td:.2f} vs a; mean {rd.cycles.mean():.1f} cycles, {100 * (rd.cycles <= 192).mean():.1f} % "
          f"stopped early   {load()}")
    te, re_ = timed_map(config, gaps, freqs, workers=workers)
    print(f"  e. default now (contraction stop, cap 192):                 {te:7.1f} s   x{td / te:.2f} vs d; "
          f"x{ta / te:.2f} vs a; mean {re_.cycles.mean():.1f} cycles   {load()}")
    return ta, td, rd


def agreement(config, workers, size=None):
    rows, cols = (31, 61) if size is None else (size, size)
    gaps, freqs = grid(rows, cols)
    print(f"\n2. {rows} x {cols} map: early stop vs fixed length with twice the former cycles, {load()}")
    te, early = timed_map(config, gaps, freqs, workers=workers)
    tf, fixed = timed_map(config, gaps, freqs, early_stop=False, workers=workers)
    comp = pk.compare_maps(early, fixed, config, 72)
    print(f"  early stop {te:.1f} s (mean {early.cycles.mean():.1f} cycles), fixed 192 cycles {tf:.1f} s: "
          f"x{tf / te:.2f}")
    for name, a in comp["agreement_per_start"].items():
        print(f"  agreement from {name}: {100 * a:.2f} %   (target >= 99 % from rest)")
    right = {"early": 0, "fixed": 0, "neither": 0}
    for c in comp["differing_cells"]:
        verdict = ""
        if c["long_run"] is not None:
            who = ("early" if c["long_run"] == c["early_stop"] else "fixed" if c["long_run"] == c["fixed_length"]
                   else "neither")
            right[who] += 1
            verdict = f"; {c['long_run_cycles']} cycles: {c['long_run']} ({who} right)"
        cap = 192 if c["start"] != "continued" else 132
        ran = (f"stopped at {c['early_stop_cycles']}" if c["early_stop_cycles"] <= cap
               else "ran to the cap: a different start from its neighbour")
        print(f"    {c['start']:9s} gap {c['gap_mm']:.1f} mm {c['frequency_hz']:.3f} Hz: early {c['early_stop']} "
              f"({ran}), fixed {c['fixed_length']}{verdict}")
    print(f"  differing rest/kick cells, which a 10x longer run confirms: {right}")


def big(config, workers, n_big, skip_big):
    gaps, freqs = grid(200)
    print(f"\n3. Big maps (early stop, cap 192, 640 from rest unless said), pool of {workers or os.cpu_count()}, "
          f"{load()}")
    t200, r200 = timed_map(config, gaps, freqs, workers=workers)
    print(f"  200 x 200, default (contraction stop): {t200:.1f} s on {r200.workers} processes (target <= 30 s on 2), "
          f"mean {r200.cycles.mean():.1f} cycles per trajectory   {load()}")
    record("maps", f"Peterka 200 × 200, pool of {r200.workers}", t200, "s", "<= 30")
    tw, rw = timed_map(config, gaps, freqs, stop="window", workers=workers)
    same = float((rw.primary == r200.primary).mean())
    print(f"  200 x 200, former (window stop):       {tw:.1f} s, mean {rw.cycles.mean():.1f} cycles: the default "
          f"x{tw / t200:.2f} faster; classes from rest the same in {100 * same:.2f} % of the cells   {load()}")
    tl, rl = timed_map(config, gaps, freqs, rest_cycles=1920, workers=workers)
    print(f"  200 x 200, --rest-cycles 1920:          {tl:.1f} s, mean {rl.cycles[0].mean():.1f} cycles from rest "
          f"(default {r200.cycles[0].mean():.1f}): x{tl / t200:.2f} the default's time; the starts from rest that "
          f"ran to 192: {100 * (r200.cycles[0] > 192).mean():.1f} %, to 1920: {100 * (rl.cycles[0] > 1920).mean():.1f} "
          f"%; classes from rest the same as the default's in {100 * (rl.primary == r200.primary).mean():.2f} % of "
          f"the cells   {load()}")
    if skip_big:
        return t200, r200
    gaps, freqs = grid(n_big)
    tb, rb = timed_map(config, gaps, freqs, workers=workers)
    line = f"  {n_big} x {n_big}: {tb:.1f} s, mean {rb.cycles.mean():.1f} cycles   {load()}"
    if n_big != 1000:
        line += f"; 1000 x 1000 projected (x{(1000 / n_big) ** 2:.2f} cells): {tb * (1000 / n_big) ** 2 / 60:.1f} min"
    print(line)
    return t200, r200


_ONE_MAP = """
import hashlib, sys, time
import numpy as np
from rimd_sim.analysis.dynamics import peterka as pk
from rimd_sim.settings.config import SimConfig
n, workers = int(sys.argv[1]), int(sys.argv[2])
gaps, freqs = np.linspace(0, 3e-3, n), np.linspace(1.82, 9.1, n)
pk.peterka(SimConfig(), gaps[:2], freqs[:3], workers=1)   # numba's cache, once per process
t0 = time.perf_counter()
res = pk.peterka(SimConfig(), gaps, freqs, workers=workers)
wall = time.perf_counter() - t0
digest = hashlib.sha256(np.asarray(res.labels, dtype=str).tobytes() + np.asarray(res.cycles).tobytes()).hexdigest()
print(wall, res.cycles.mean(), digest[:16])
"""


def compare_trees(other: Path, size: int, workers: int, rounds: int) -> None:
    """The default N x N map in this tree and in ``other`` (a checkout), alternately, each in a fresh process.

    Each process imports its own tree's package (PYTHONPATH, inherited by the pool's workers); the map's classes
    and cycles are digested, so that a change meant to leave the results alone shows that it did.
    """
    trees = {"this": ROOT, "other": other.resolve()}
    times: dict[str, list[float]] = {"this": [], "other": []}
    digests: dict[str, set[str]] = {"this": set(), "other": set()}
    print(f"\n{size} x {size}, the default map, pool of {workers}: this tree ({ROOT}) against {other}, "
          f"{rounds} round(s), alternately   {load()}")
    for r in range(rounds):
        for name in (("other", "this") if r % 2 == 0 else ("this", "other")):
            env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(trees[name] / "rimd_sim"),
                                                               os.environ.get("PYTHONPATH", "")]))
            out = subprocess.run([sys.executable, "-c", _ONE_MAP, str(size), str(workers)], env=env, check=True,
                                 capture_output=True, text=True).stdout.split()
            wall, cycles, digest = float(out[0]), float(out[1]), out[2]
            times[name].append(wall)
            digests[name].add(digest)
            print(f"  round {r + 1} {name:5s}: {wall:6.1f} s, mean {cycles:.1f} cycles, classes {digest}   {load()}")
    med = {name: float(np.median(v)) for name, v in times.items()}
    same = digests["this"] == digests["other"] and len(digests["this"]) == 1
    print(f"  median: this {med['this']:.1f} s, other {med['other']:.1f} s: x{med['other'] / med['this']:.2f} "
          f"(> 1: this tree is faster); classes and cycles {'identical' if same else 'DIFFERENT'}")


def reference_agreement(config, workers, size):
    """Section 6: the default and the ``window`` stop against 1920 cycles from rest, on a size x size map."""
    gaps, freqs = grid(size)
    print(f"\n6. {size} x {size} map against a reference ten times as long (1920 cycles from rest, last 72 "
          f"classified), {load()}")
    tc, new = timed_map(config, gaps, freqs, workers=workers)
    tw, old = timed_map(config, gaps, freqs, stop="window", workers=workers)
    tl, long = timed_map(config, gaps, freqs, rest_cycles=1920, workers=workers)
    print(f"  default (contraction) {tc:.1f} s, mean {new.cycles.mean():.1f} cycles; former (window) {tw:.1f} s, "
          f"mean {old.cycles.mean():.1f} cycles: x{tw / tc:.2f}; --rest-cycles 1920 {tl:.1f} s (x{tl / tc:.2f} the "
          f"default)   {load()}")
    t0 = time.perf_counter()
    ref = pk.rest_classes(config, gaps, freqs, cycles=1920, measure_cycles=72, workers=workers)
    print(f"  reference: {time.perf_counter() - t0:.1f} s   {load()}")
    ok_new, ok_old = new.primary == ref, old.primary == ref
    print(f"  agreement from rest: default {100 * ok_new.mean():.2f} %, former {100 * ok_old.mean():.2f} % "
          f"(target >= 99.5 %); the default wrong where the former is right: {int((~ok_new & ok_old).sum())} "
          f"cells, the reverse: {int((ok_new & ~ok_old).sum())}; both wrong: {int((~ok_new & ~ok_old).sum())}, of "
          f"which the former ran to the cap: {int((~ok_new & ~ok_old & (old.cycles[0] > 192)).sum())}")
    record("maps", f"{size} × {size} cells classed as by 1,920 cycles", 100 * ok_new.mean(), "%", ">= 99.5")
    wrong = Counter(zip(new.primary[~ok_new].tolist(), ref[~ok_new].tolist(), strict=True))
    print("  the default's differing cells (map, reference: cells): "
          + ", ".join(f"{a} vs {b}: {n}" for (a, b), n in wrong.most_common(8)))
    ok_long = long.primary == ref
    record("maps", "the same, `--rest-cycles 1920`", 100 * ok_long.mean(), "%", ">= 99.5")
    wrong = Counter(zip(long.primary[~ok_long].tolist(), ref[~ok_long].tolist(), long.cycles[0][~ok_long].tolist(),
                        strict=True))
    print(f"  --rest-cycles 1920: {100 * ok_long.mean():.2f} % of the cells (target >= 99.5 %); its differing cells "
          "(map, reference, cycles the map ran: cells): "
          + (", ".join(f"{a} vs {b} at {c}: {n}" for (a, b, c), n in wrong.most_common(8)) or "none"))


def rest_caps(config, workers, size, caps, big_caps):
    """Section 8: the cap of the start from rest against the agreement (size x size) and the 200 x 200 time."""
    gaps, freqs = grid(size)
    print(f"\n8. The start from rest's cap (--rest-cycles) against the agreement with 1920 cycles from rest on "
          f"{size} x {size} and the time of 200 x 200, pool of {workers or os.cpu_count()}, {load()}")
    t0 = time.perf_counter()
    ref = pk.rest_classes(config, gaps, freqs, cycles=1920, measure_cycles=72, workers=workers)
    print(f"  reference: {time.perf_counter() - t0:.1f} s   {load()}")
    for cap in caps:
        t, res = timed_map(config, gaps, freqs, rest_cycles=cap, workers=workers)
        ok = res.primary == ref
        print(f"  rest cap {cap:5d}: agreement {100 * ok.mean():6.2f} % (target >= 99.5 %), {size} x {size} in "
              f"{t:.1f} s, mean {res.cycles[0].mean():.1f} cycles from rest, at the cap "
              f"{100 * (res.cycles[0] > cap).mean():.1f} %   {load()}")
    gaps, freqs = grid(200)
    for cap in big_caps:
        t, res = timed_map(config, gaps, freqs, rest_cycles=cap, workers=workers)
        print(f"  rest cap {cap:5d}: 200 x 200 in {t:.1f} s (target <= 30 s on 2), mean {res.cycles[0].mean():.1f} "
              f"cycles from rest   {load()}")


def reproducibility(config, workers, size):
    """Section 7: how reproducible the reference itself is, against the integrator's tolerance."""
    gaps, freqs = grid(size)
    print(f"\n7. {size} x {size}: the 1920-cycle reference from rest at integrator.rtol 1e-7 (the default), 1e-8 and "
          f"1e-9 (atol 1e-9 each), {load()}")
    refs = {}
    for rtol in (1e-7, 1e-8, 1e-9):
        cfg = config.with_parameters({"integrator.rtol": rtol})
        t0 = time.perf_counter()
        refs[rtol] = pk.rest_classes(cfg, gaps, freqs, cycles=1920, measure_cycles=72, workers=workers)
        print(f"  rtol {rtol:g}: {time.perf_counter() - t0:.1f} s   {load()}")
    for a, b in ((1e-7, 1e-8), (1e-7, 1e-9), (1e-8, 1e-9)):
        same = refs[a] == refs[b]
        differ = Counter(zip(refs[a][~same].tolist(), refs[b][~same].tolist(), strict=True))
        print(f"  rtol {a:g} vs {b:g}: the same class in {100 * same.mean():.2f} % of the cells; differing "
              f"({a:g}, {b:g}: cells): " + (", ".join(f"{x} vs {y}: {n}" for (x, y), n in differ.most_common(6))
                                           or "none"))
    tl, long = timed_map(config, gaps, freqs, rest_cycles=1920, workers=workers)
    tc, new = timed_map(config, gaps, freqs, workers=workers)
    for rtol, ref in refs.items():
        print(f"  against the reference at rtol {rtol:g}: the default map {100 * (new.primary == ref).mean():.2f} %, "
              f"--rest-cycles 1920 {100 * (long.primary == ref).mean():.2f} %")


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def dask_scaling(config, size):
    gaps, freqs = grid(size)
    port = _port()
    address = f"tcp://127.0.0.1:{port}"
    dask = str(Path(sys.executable).with_name("dask"))
    env = {**os.environ, "PYTHONPATH": str(ROOT / "rimd_sim")}
    procs = []

    def start(argv):
        p = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
                             start_new_session=True)
        procs.append(p)
        return p

    from distributed import Client

    print(f"\n4. Dask scaling on the {size} x {size} map (loopback scheduler, workers of one thread), {load()}")
    try:
        start([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard", "--no-show"])
        times = {}
        for n in (1, 2):
            start([dask, "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"])
            with Client(address, timeout=60, set_as_default=False) as client:
                client.wait_for_workers(n, timeout=60)
            pk.peterka(config, gaps[:2], freqs[:4], scheduler=address)  # workers import and load the JIT cache
            times[n], res = timed_map(config, gaps, freqs, scheduler=address)
            print(f"  {n} worker(s): {times[n]:.1f} s   {load()}")
        eff = times[1] / (2 * times[2])
        print(f"  efficiency 1 -> 2 workers: {100 * eff:.0f} %   (target >= 90 %)")
        per_cycle = times[2] * 2 / cycles_of(res)
        # One trajectory's own speed in the core: 2000 cycles at gap 1 mm, 5 Hz, one RigModel.
        cfg = config.with_parameters({"gap": 1e-3, "motor.initial_frequency": 5.0, "motor.initial_setpoint": 5.0})
        RigModel(cfg, channels=False, truth=False).advance(1.0)
        t0 = time.perf_counter()
        RigModel(cfg, channels=False, truth=False).advance(2000 / 5.0)
        core = (time.perf_counter() - t0) / 2000
        print(f"  time per cell-cycle on the map: {per_cycle * 1e6:.1f} us per core; one long trajectory in the core "
              f"(gap 1 mm, 5 Hz): {core * 1e6:.1f} us per cycle: the map runs at {100 * core / per_cycle:.0f} % of "
              f"the core's own speed")
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)


def single_trajectory(config):
    from rimd_sim.analysis.dynamics.sweep import sweep

    print(f"\n5. rimd sweep --workers 1 (gap 1 mm, 1.5-9 Hz at 0.05 Hz, 300 cycles from rest), {load()}")
    cfg = config.with_parameters({"gap": 1e-3})
    freqs = np.round(np.arange(1.5, 9.0 + 0.025, 0.05), 6)
    res = sweep(cfg, freqs[:2], "rest", cycles=300, workers=1)  # JIT from cache
    t0 = time.perf_counter()
    res = sweep(cfg, freqs, "rest", cycles=300, measure_cycles=50, workers=1)
    wall = time.perf_counter() - t0
    simulated = res.simulated_seconds
    print(f"  {len(freqs)} points, {simulated:.0f} s simulated in {wall:.1f} s: {simulated / wall:.0f}x real time")
    from harness import reference

    sample = freqs[:: max(1, len(freqs) // 6)][:6]
    t0 = time.perf_counter()
    ref_sim = 0.0
    for f in sample:
        reference.simulate(frequency=float(f), gap=1e-3, duration=300 / f, rtol=1e-7, atol=1e-9)
        ref_sim += 300 / f
    ref_wall = time.perf_counter() - t0
    t0 = time.perf_counter()
    ours_sim = 0.0
    steps = rejected = 0
    for f in sample:
        c = cfg.with_parameters({"motor.initial_frequency": float(f), "motor.initial_setpoint": float(f)})
        model = RigModel(c, channels=False, truth=False)
        model.advance(300 / f)
        ours_sim += 300 / f
        steps += model.stats["steps"]
        rejected += model.stats["rejected"]
    ours_wall = time.perf_counter() - t0
    print(f"  the core at the default tolerances: {steps / (300 * len(sample)):.1f} accepted steps per cycle "
          f"({100 * rejected / max(1, steps):.1f} % rejected), {ours_wall / steps * 1e6:.2f} us per step")
    print(f"  scipy solve_ivp reference on {len(sample)} of the points: {ref_sim / ref_wall:.1f}x real time; "
          f"the core on the same points {ours_sim / ours_wall:.0f}x: ratio "
          f"{ref_wall / ours_wall * ours_sim / ref_sim:.0f}x; the whole sweep "
          f"{simulated / wall / (ref_sim / ref_wall):.0f}x the reference (goal >= 1,000x)   {load()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps-size", type=int, default=60, help="map size of the step-by-step figures")
    parser.add_argument("--big", type=int, default=400, help="map size for the 1000 x 1000 projection")
    parser.add_argument("--skip-big", action="store_true", help="no map beyond 200 x 200")
    parser.add_argument("--skip-dask", action="store_true", help="no Dask scaling")
    parser.add_argument("--workers", type=int, default=None, help="local processes (default: all cores)")
    parser.add_argument("--compare-size", type=int, default=None,
                        help="section 2 on an N x N map instead of the default 31 x 61")
    parser.add_argument("--sections", default="1,2,3,4,5,6,7", help="sections to run (default 1,2,3,4,5,6,7)")
    parser.add_argument("--reference-size", type=int, default=100,
                        help="section 6 on an N x N map (default 100; 200 is the full map, about 4x as long)")
    parser.add_argument("--tolerance-size", type=int, default=40,
                        help="section 7 on an N x N map (default 40: three references of 1920 cycles per cell)")
    parser.add_argument("--rest-caps", default="192,480,640,960,1920",
                        help="section 8: the caps of the start from rest measured on the reference's map")
    parser.add_argument("--rest-caps-big", default="192,640",
                        help="section 8: the caps whose 200 x 200 map is timed")
    parser.add_argument("--compare", type=Path, default=None, metavar="DIR",
                        help="only the default N x N map (--compare-map-size) in this tree and in the checkout DIR, "
                             "alternately in fresh processes, and the ratio")
    parser.add_argument("--compare-map-size", type=int, default=200, help="map size of --compare (default 200)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of --compare (default 2)")
    args = parser.parse_args()
    if args.compare is not None:
        print(f"RIMD maps benchmark on {os.cpu_count()} core(s), {load()}")
        compare_trees(args.compare, args.compare_map_size, args.workers or 2, args.rounds)
        return
    sections = {int(x) for x in args.sections.split(",")}
    config = SimConfig()
    print(f"RIMD maps benchmark on {os.cpu_count()} core(s), {load()}")
    pk.peterka(config, *grid(2, 3), workers=1)  # JIT from cache
    if 1 in sections:
        steps(config, args.steps_size, args.workers)
    if 2 in sections:
        agreement(config, args.workers, args.compare_size)
    if 3 in sections:
        big(config, args.workers, args.big, args.skip_big)
    if 4 in sections and not args.skip_dask:
        dask_scaling(config, args.steps_size)
    if 5 in sections:
        single_trajectory(config)
    if 6 in sections:
        reference_agreement(config, args.workers, args.reference_size)
    if 7 in sections:
        reproducibility(config, args.workers, args.tolerance_size)
    if 8 in sections:
        rest_caps(config, args.workers, args.reference_size, [int(x) for x in args.rest_caps.split(",")],
                  [int(x) for x in args.rest_caps_big.split(",") if x])


if __name__ == "__main__":
    main()
