"""``rimd warmup`` fills numba's on-disk cache, so that later processes load the physics instead of compiling it.

Hypothesis: after ``rimd warmup --all`` (in the cache the set-up filled, ``__pycache__`` beside the sources), a new
process that runs both models through the simulator and one cell of a map for each loads everything it needs
from that cache: it adds and rewrites no cache file. Were warmup to leave a compiled function out, that process
would compile it and write it, and the test would name the file. (``rimd warmup --all`` runs in the set-up of every
fresh clone: ``scripts/setup.sh``, step ``warmup``.)
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import rimd_sim

PROBE = """
from rimd_sim.analysis.dynamics.peterka import peterka
from rimd_sim.instruments.rig_simulator import RigSimulator
from rimd_sim.settings.config import SimConfig, find_config_file, load_config
two_mass = load_config(find_config_file("structural.yaml"))
for config in (SimConfig(), two_mass):
    RigSimulator(config, strobe=True).advance(0.3)
    peterka(config, [0.0], [5.0], transient_cycles=3, measure_cycles=6, workers=1)
print("ran")
"""


def _cache_files() -> dict[Path, int]:
    package = Path(rimd_sim.__file__).resolve().parent
    return {path: path.stat().st_mtime_ns for path in package.rglob("__pycache__/*.nb[ci]")}


@pytest.mark.process
def test_after_warmup_a_new_process_compiles_nothing():
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    run = subprocess.run([sys.executable, "-m", "rimd_sim.cli", "warmup", "--all"], capture_output=True, text=True,
                         env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    for step in ("rigid model and instruments", "two-mass model and instruments", "rigid ensemble",
                 "two-mass ensemble"):
        assert f"rimd warmup: {step}: " in run.stderr
    assert "cached in __pycache__ beside the sources" in run.stdout
    before = _cache_files()
    names = {path.name for path in before}
    for function in ("build_driver.rigid.advance", "build_driver.two_mass.advance", "sensors._sos_filter",
                     "ensemble._loop.rigid.run_cells", "ensemble._loop.two_mass.run_cells"):
        assert any(function in name for name in names), function
    probe = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=env, timeout=600)
    assert probe.returncode == 0 and probe.stdout.strip() == "ran", probe.stderr
    after = _cache_files()
    written = sorted(str(path.name) for path, mtime in after.items() if before.get(path) != mtime)
    assert written == [], f"compiled again after rimd warmup: {written}"


@pytest.mark.process
def test_warmup_compiles_what_the_rig_runs_and_not_the_maps_nor_the_two_mass_model():
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    run = subprocess.run([sys.executable, "-m", "rimd_sim.cli", "warmup"], capture_output=True, text=True,
                         env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    assert "rimd warmup: rigid model and instruments: " in run.stderr
    assert "rimd warmup: the composed rig's DDS batch writer: " in run.stderr
    assert "two-mass" not in run.stderr and "ensemble" not in run.stderr
