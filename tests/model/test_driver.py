"""The one driver built per model (docs/physics.md): its contract, the registry, and numba's cache across processes.

Each test says its hypothesis. The cache tests run the compiled functions in fresh interpreters on a numba cache
directory of their own (``NUMBA_CACHE_DIR``), so they see what a user sees from the second run on.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import textwrap
import types
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rimd_sim
import rimd_sim.model.kernel as kernel
import rimd_sim.model.rigid as rigid
from rimd_sim.model.rig_model import MODELS, RigModel
from rimd_sim.settings.config import STRUCTURE_MODELS, SimConfig

SRC = Path(rimd_sim.__file__).resolve().parent.parent

#: Runs ``track_contact_extremes`` of the models named on the command line (a small compiled function that calls
#: two more of the driver's) and prints what it finds, with numba's cache statistics.
PROBE = textwrap.dedent("""
    import json, sys
    import numpy as np
    from rimd_sim.settings.config import load_config
    from rimd_sim.model import kernel as k
    from rimd_sim.settings.config import find_config_file
    from rimd_sim.model.rig_model import MODELS
    cfg = load_config(find_config_file("structural.yaml"))
    out = {}
    for name in sys.argv[1:]:
        spec = MODELS[name]
        p = spec.params(cfg.with_parameters({"structure.model": name}))
        fs = np.zeros(k.N_FSTATE)
        fs[k.F_MW0] = 3.75
        fs[k.F_VIMP] = 0.1
        n = spec.n_state
        ya = np.array([1e-6, 0.5, 0.0, 1e-7, 0.01, 2e-8, -0.02][:n])
        q = np.arange(4 * n, dtype=float).reshape(n, 4) * 1e-3
        spec.driver.track_contact_extremes(fs, p, ya, q, 1e-5)
        stats = spec.driver.track_contact_extremes.stats
        out[name] = {"peak": fs[k.F_RPEAK], "penetration": fs[k.F_RPEN], "hits": sum(stats.cache_hits.values()),
                     "misses": sum(stats.cache_misses.values())}
    print(json.dumps(out))
""")


def probe(src: Path, cache: Path, *models: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(src), "NUMBA_CACHE_DIR": str(cache)}
    env.pop("RIMD_NO_JIT", None)
    proc = subprocess.run([sys.executable, "-c", PROBE, *models], capture_output=True, text=True, timeout=240,
                          env=env, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout)


@pytest.mark.process
def test_two_models_loaded_from_the_cache_keep_their_own_code(tmp_path):
    """Compiled in two processes (each caches its model's functions), then both loaded from the cache into a third:
    each model computes what it computed when compiled. (Before the fix, the functions of the two models shared
    their compiled symbols' names, and the two-mass model ran the rigid model's code without an error.) The third
    process compiles nothing."""
    rigid_alone = probe(SRC, tmp_path, "rigid")["rigid"]
    two_alone = probe(SRC, tmp_path, "two_mass")["two_mass"]
    assert rigid_alone["misses"] == two_alone["misses"] == 1  # each compiled its model's function once
    both = probe(SRC, tmp_path, "rigid", "two_mass")
    for name, alone in (("rigid", rigid_alone), ("two_mass", two_alone)):
        assert (both[name]["peak"], both[name]["penetration"]) == (alone["peak"], alone["penetration"]), name
        assert both[name]["hits"] == 1 and both[name]["misses"] == 0, name
    assert two_alone["peak"] != rigid_alone["peak"]


#: Builds the two-mass driver and reports whether its fused step was loaded before any caller ran, then runs the
#: model for 0.2 s (which compiles it into the cache when the cache is empty).
STEP_FIRST = textwrap.dedent("""
    import json
    from rimd_sim.model.rig_model import MODELS, RigModel
    from rimd_sim.settings.config import find_config_file, load_config
    step = MODELS["two_mass"].driver.rk_step
    before = {"overloads": len(step.overloads), "hits": sum(step.stats.cache_hits.values())}
    RigModel(load_config(find_config_file("structural.yaml")), channels=False, truth=False).advance(0.2)
    print(json.dumps(before))
""")


@pytest.mark.process
def test_the_fused_step_is_loaded_before_its_callers_so_a_warm_process_runs_the_cold_ones_code():
    """Hypothesis: with the step in the cache, building a driver loads it before anything that calls it.

    Each caller holds its own copy of the step, and LLVM optimises that copy again inside the caller. With FMA
    contraction, the copy may fuse other pairs of operations than the step's own code does. A process runs the
    first copy it loads. A cold process compiles the step before its callers and so runs the step's own code; a
    warm one must load it first to run the same code, and so give the same trajectory to the last bit. The first
    process fills the cache if it is empty; the second builds the driver on the filled cache.
    """
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    env.pop("RIMD_NO_JIT", None)
    for _ in range(2):
        proc = subprocess.run([sys.executable, "-c", STEP_FIRST], capture_output=True, text=True, timeout=240,
                              env=env, check=False)
        assert proc.returncode == 0, proc.stderr[-3000:]
    before = json.loads(proc.stdout)
    # every specialisation the cache holds (the loops of the analyses call the step with other array types), each
    # loaded, none compiled
    assert before["overloads"] >= 1 and before["hits"] == before["overloads"], before


@pytest.mark.process
def test_an_edit_of_the_physics_is_not_served_from_the_cache(tmp_path):
    """The cache key holds the digest of the physics sources: after an edit of the rigid model's physics (the
    sensor reads twice the law's force), a process with the same cache directory does not load the old entry: it
    recompiles and computes the new physics (a copy of the package is edited, with its own cache)."""
    copy = tmp_path / "src"
    shutil.copytree(SRC / "rimd_sim", copy / "rimd_sim", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(SRC.parent / "config", copy / "config")  # find_config_file looks in the parents' config/
    cache = tmp_path / "cache"
    before = probe(copy, cache, "rigid")["rigid"]
    physics = copy / "rimd_sim" / "model" / "rigid.py"
    text = physics.read_text()
    line = '    """The sensor is rigid: it reads the law\'s force."""\n    return force\n'
    assert text.count(line) == 1
    physics.write_text(text.replace(line, line.replace("return force", "return 2.0 * force")))
    after = probe(copy, cache, "rigid")["rigid"]
    assert after["misses"] == 1 and after["hits"] == 0
    assert after["peak"] == 2.0 * before["peak"]


def test_the_drivers_cache_key_holds_the_kernels_own_source():
    """The driver's namespace, whose name is its compiled code's cache key, is named after the digest of every
    module of the kernel too (``kernel.py``, ``integration.py``, ``layout.py``, ...), not only of the physics: a
    cached caller in another file (the ensemble loop) holds the driver's compiled code, numba checks only that
    caller's file, so with the physics alone in the key an edit of the kernel would be served stale through it.
    Every model's driver."""
    from rimd_sim.model import integration, layout

    assert {kernel, integration, layout} <= set(kernel.DRIVER_MODULES)
    for name, spec in MODELS.items():
        key = kernel.source_key(*kernel.DRIVER_MODULES, spec.physics, *spec.sources)
        assert spec.driver.__name__ == f"{kernel.__name__}.driver_{name}_{key}", name
        assert key != kernel.source_key(spec.physics, *spec.sources)


#: Calls a module-level compiled function of the kernel that compiles in constants of another module (``motor_freq``
#: reads the float state's layout from ``layout.py``) and prints numba's cache statistics.
LAYOUT_PROBE = textwrap.dedent("""
    import json
    import numpy as np
    from rimd_sim.model import kernel as k
    fs = np.zeros(k.N_FSTATE)
    fs[k.F_MW0] = 3.75
    k.motor_freq(fs, 1.0)
    stats = k.motor_freq.stats
    print(json.dumps({"hits": sum(stats.cache_hits.values()), "misses": sum(stats.cache_misses.values())}))
""")


@pytest.mark.process
@pytest.mark.skipif(not kernel.JIT, reason="RIMD_NO_JIT=1: nothing is compiled")
def test_an_edit_of_another_kernel_module_is_not_served_from_the_cache(tmp_path):
    """The kernel's module-level functions are cached under the digest of all the kernel's modules, as numba checks
    a cached function against its own file only: after an edit of ``layout.py`` alone, ``motor_freq`` (in
    ``motor.py``, reading the layout's indices) is recompiled, not loaded from the cache."""
    copy = tmp_path / "src"
    shutil.copytree(SRC / "rimd_sim", copy / "rimd_sim", ignore=shutil.ignore_patterns("__pycache__"))
    env = {**os.environ, "PYTHONPATH": str(copy), "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("RIMD_NO_JIT", None)

    def run() -> dict:
        proc = subprocess.run([sys.executable, "-c", LAYOUT_PROBE], capture_output=True, text=True, timeout=240,
                              env=env, check=False)
        assert proc.returncode == 0, proc.stderr[-3000:]
        return json.loads(proc.stdout)

    assert run() == {"hits": 0, "misses": 1}
    assert run() == {"hits": 1, "misses": 0}
    layout = copy / "rimd_sim" / "model" / "layout.py"
    layout.write_text(layout.read_text() + "# an edit\n")
    assert run() == {"hits": 0, "misses": 1}


#: The compiled functions that create arrays (their workspace): the only ones compiled with numba's reference counting.
ALLOCATING = {"advance", "truncate", "run_cells", "map_one", "map_many"}


@pytest.mark.skipif(not kernel.JIT, reason="RIMD_NO_JIT=1: nothing is compiled")
def test_the_compiled_functions_borrow_their_arrays():
    """Hypothesis: every compiled function of the kernel, of each model's driver and physics, of the maps' ensemble
    and of the shooting maps runs without numba's reference counting (``_nrt`` off), but for the few that create
    arrays, which keep it explicitly (a caller's setting would otherwise be inherited and refuse their ``np.empty``).
    With the counting, every call incremented and decremented each array's count atomically: half a Peterka map's
    time (docs/benchmarks.md). Functions inlined into their callers take the callers' setting and are not listed."""
    from numba.core.registry import CPUDispatcher

    from rimd_sim.model import ensemble, shooting

    spaces = [kernel, ensemble]
    for name, spec in MODELS.items():
        spaces += [spec.physics, spec.driver, ensemble._loop(name), shooting._loop(name)]
    seen = {}
    for space in spaces:
        for attr, fn in vars(space).items():
            if isinstance(fn, CPUDispatcher) and fn.targetoptions.get("inline", "never") == "never":
                seen[f"{space.__name__}.{attr}"] = fn.targetoptions.get("_nrt")
    named = {key.rsplit(".", 1)[1] for key in seen}
    assert {"rk_step", "detect_event", "dense_coeffs", "emit_samples", "run_one", "_converged", "motor_phase",
            "advance", "run_cells", "map_one"} <= named
    wrong = {key: nrt for key, nrt in seen.items() if nrt is not (key.rsplit(".", 1)[1] in ALLOCATING)}
    assert not wrong, f"reference counting where it should not be (True) or missing where arrays are made: {wrong}"


@pytest.mark.skipif(not kernel.JIT, reason="RIMD_NO_JIT=1: nothing is compiled")
def test_only_the_runge_kutta_step_fuses_multiply_adds():
    """The step is compiled with FMA contraction (``fastmath={"contract"}``) and nothing else is: a function fused
    in one caller and not in another would make a trajectory depend on where a run is cut (with every kernel
    function fused, tests/instruments/test_streaming.py's bit-identity across cuts fails)."""
    from numba.core.registry import CPUDispatcher

    from rimd_sim.model import ensemble, shooting

    spaces = [kernel, ensemble]
    for name, spec in MODELS.items():
        spaces += [spec.physics, spec.driver, ensemble._loop(name), shooting._loop(name)]
    fused, plain = set(), set()
    for space in spaces:
        for attr, fn in vars(space).items():
            if isinstance(fn, CPUDispatcher):
                flags = fn.targetoptions.get("fastmath")
                (fused if flags else plain).add(f"{space.__name__}.{attr}")
                assert not flags or set(flags) == {"contract"}, (space.__name__, attr, flags)
    assert {key.rsplit(".", 1)[1] for key in fused} == {"rk_step"}, fused
    assert len(fused) == len(MODELS) and "advance" in {key.rsplit(".", 1)[1] for key in plain}


@settings(max_examples=300, deadline=None)
@given(st.floats(min_value=1e-300, max_value=1e300))
def test_the_step_controls_fifth_root_is_pow_to_2e_5(x):
    """``inv_fifth_root`` (the step control's factor without ``pow``) against ``x ** -0.2``, compiled and not."""
    expected = x ** -0.2
    for fn in (kernel.inv_fifth_root, getattr(kernel.inv_fifth_root, "py_func", kernel.inv_fifth_root)):
        assert abs(fn(x) - expected) <= 2e-5 * expected, fn


def test_the_step_controls_fifth_root_of_an_overflowed_error_is_0_as_pow_gives():
    """An infinite error norm (a step that overflowed): 0, so the step is cut by the most allowed, as with pow."""
    for fn in (kernel.inv_fifth_root, getattr(kernel.inv_fifth_root, "py_func", kernel.inv_fifth_root)):
        assert fn(math.inf) == 0.0 == math.inf ** -0.2, fn


def test_a_physics_module_is_checked_against_the_contract():
    """A physics module that lacks part of the contract is refused, naming what it lacks; a ringing one must
    also give the ring hooks."""
    lacking = types.ModuleType("lacking")
    for attr in kernel.CONTRACT:
        setattr(lacking, attr, getattr(rigid, attr))
    del lacking.sample
    with pytest.raises(TypeError, match=r"lacking is not a physics module .* it lacks sample$"):
        kernel.build_driver(lacking, "lacking")
    lacking.sample = rigid.sample
    lacking.RINGS = True
    with pytest.raises(TypeError, match=r"it lacks ring_amplitude, ring_period, settle$"):
        kernel.build_driver(lacking, "lacking")
    kernel.check_physics(rigid)


def test_the_registry_holds_every_structure_model():
    """MODELS is the one place that picks a model: one entry per value ``structure.model`` accepts, each with its
    physics module and state size."""
    assert tuple(MODELS) == STRUCTURE_MODELS
    assert [MODELS[m].n_state for m in MODELS] == [3, 7]


def test_a_running_model_keeps_its_model_and_its_modes_count():
    """RigModel refuses to be reconfigured to another model (its state would not fit), and a start whose modes do
    not fit the model, each with a message naming what was wrong."""
    from rimd_sim.errors import CommandError, ConfigError
    from rimd_sim.model.rig_model import RigModel
    from rimd_sim.settings.config import SimConfig

    model = RigModel(SimConfig(), channels=False, truth=False)
    with pytest.raises(CommandError, match=r"structure.model cannot change while the model runs \(rigid to two_mass\)"):
        model.reconfigure(SimConfig().with_parameters({"structure.model": "two_mass"}))
    with pytest.raises(ConfigError, match=r"'initial_modes' = \(0.0,\) refused: the rigid model has 0 modes"):
        RigModel(SimConfig(), initial_modes=(0.0,))
    two = RigModel(SimConfig().with_parameters({"structure.model": "two_mass"}), initial_modes=(1e-9, 0, 0, 0))
    assert two._ya[3:].tolist() == [1e-9, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("name", STRUCTURE_MODELS)
def test_a_copied_model_continues_exactly_as_the_original_and_alone(name):
    """``copy.deepcopy`` of a running model (the experiment design's trial runs) shares the physics module and
    driver, not the state: the copy, driven like the original, gives the same impacts and samples bit for bit, and
    driving it leaves the original where it was."""
    import copy
    from fractions import Fraction

    import numpy as np

    from rimd_sim.model.rig_model import RigModel
    from rimd_sim.settings.config import SimConfig

    config = SimConfig().with_parameters({"structure.model": name})
    original = RigModel(config)
    original.advance(Fraction(1))
    trial = copy.deepcopy(original)
    assert trial.time == original.time == 1 and trial.physics_model is original.physics_model
    trial.set_motor_frequency(5.5, 2.0)
    ahead = trial.advance(Fraction(2))
    assert original.time == 1   # the trial left the original alone
    original.set_motor_frequency(5.5, 2.0)
    again = original.advance(Fraction(2))
    assert [i.t_start for i in ahead.impacts] == [i.t_start for i in again.impacts] and ahead.impacts
    assert list(ahead.channels) == list(again.channels)
    for name, (first, values) in ahead.channels.items():
        assert first == again.channels[name][0] and np.array_equal(values, again.channels[name][1]), name


@pytest.mark.parametrize("name", list(MODELS))
def test_slow_samples_do_not_depend_on_where_the_calls_end(name):
    """The driver computes a step's dense output only when something needs it (a free step of a map needs it once
    a cycle); the next call draws first from the step the last one ended in, so a call must leave the caller's
    dense output current whatever it skipped. Hypothesis: a model with one slow channel (40 Hz, several steps
    between samples) and its stroboscopic points gives the same samples, points and impacts in one call as in calls
    that each end just before a sample (which then falls in the step the call ended in, unsampled by it)."""
    cfg = SimConfig().with_parameters({"gap": 1e-3, "motor.initial_frequency": 4.6, "motor.initial_setpoint": 4.6,
                                       "structure.model": name})
    slow = (("slow", Fraction(40), "rimd_displacement"),)

    def model() -> RigModel:
        return RigModel(cfg, channels=False, truth=False, strobe=True, extra_channels=slow)

    one = model().advance(8)
    cut = model()
    parts = [cut.advance(Fraction(n, 40) - Fraction(1, 10_000)) for n in range(1, 320)] + [cut.advance(8)]
    np.testing.assert_array_equal(one.channels["slow"][1], np.concatenate([p.channels["slow"][1] for p in parts]))
    assert len(one.channels["slow"][1]) == 320
    assert one.strobe == [s for p in parts for s in p.strobe] and len(one.strobe) >= 36
    assert [repr(i) for i in one.impacts] == [repr(i) for p in parts for i in p.impacts]
    assert one.impacts, "the orbit impacts: contact steps are in the comparison too"
