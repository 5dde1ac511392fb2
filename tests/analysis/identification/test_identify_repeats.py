"""``rimd identify`` gives the same answer to the last digit every time it reads the same recording.

The recording: the core's run of battery rig 5 of ``tests/harness/ident_rigs.py``, two steps of 2.5 s, written as
the recorder writes it. What could make two identifications differ, and why it does not: the cluster bootstrap
draws from a generator with a fixed seed (``JointFit.bootstrap``, seed 0); the Jacobian's forward runs go to a
thread pool, but ``pool.map`` gives the columns back in order and every residual and sum is computed on the
calling thread, so the number of workers does not change a bit; the fit stops by its tolerances and a count of
iterations, never by a clock; no estimate is read from a set or a dict whose order could change.

Hypotheses: the same recording identified twice in one process, the second time with one worker instead of
several, gives equal estimates, standard errors (each kind), intervals, residuals, validation rows and verdict,
compared as exact floats; and a second process gives the same printed numbers.

The first identification (this process, several workers) is made once, by the module's ``first`` fixture: the
second in this process and the one of the second process are each compared with it.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from harness.ident_rigs import Schedule, draw_rigs, write_core_recording
from rimd_sim.settings.config import SimConfig

RIG = draw_rigs(14)[5]


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("repeat") / "rig5.mcap"
    write_core_recording(path, RIG, Schedule([2.5, 2.25], dwell=2.5, seed=5))
    return path


@pytest.fixture(scope="module")
def first(recording) -> str:
    """The recording's first identification in this process, with the Jacobian's workers one per core."""
    return _answer(recording)


def _answer(path: Path) -> str:
    """Everything the identification reports, as exact text (``repr`` of every float)."""
    from rimd_sim.analysis.identification.identify import identify

    ident = identify(path, SimConfig(), {}, resamples=100)

    def exact(value):
        if isinstance(value, dict):
            return {str(k): exact(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [exact(v) for v in value]
        return repr(value)

    return json.dumps(exact({"estimates": {p: e.as_dict() for p, e in ident.estimates.items()},
                             "config": ident.config.to_parameters(), "residuals": ident.residuals,
                             "validation": ident.validation, "verdict": ident.verdict.as_dict(),
                             "kicks": ident.kicks, "initial": ident.initial}), sort_keys=True)


def test_the_same_recording_identified_twice_gives_the_same_answer(recording, first, monkeypatch):
    from rimd_sim.analysis.identification import joint_fit

    monkeypatch.setattr(joint_fit.os, "cpu_count", lambda: 1)   # one worker for the Jacobian's forward runs
    second = _answer(recording)
    assert first == second
    estimates = json.loads(first)["estimates"]
    assert set(estimates) >= {"mass", "gap", "contact.stiffness"}
    assert all(e["std_error"] != "None" for e in estimates.values())


@pytest.mark.process
def test_another_process_gives_the_same_answer(recording, first):
    tests = Path(__file__).resolve().parents[2]
    code = ("import sys, importlib.util; from pathlib import Path; sys.path.insert(0, sys.argv[3]); "
            "spec = importlib.util.spec_from_file_location('repeats', sys.argv[2]); "
            "module = importlib.util.module_from_spec(spec); spec.loader.exec_module(module); "
            "print(module._answer(Path(sys.argv[1])))")
    done = subprocess.run([sys.executable, "-c", code, str(recording), __file__, str(tests)], capture_output=True,
                          text=True, timeout=300, cwd=tests)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == first
