"""A command's figures: drawn here by default, or in a worker process started before the computation."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from rimd_sim.analysis import figures
from rimd_sim.analysis.dynamics.sweep import sweep
from rimd_sim.analysis.figures import Figures
from rimd_sim.settings.config import load_config


@pytest.fixture(scope="module")
def one_point():
    """One sweep point (gap 0, 3 Hz, a short run): something to plot."""
    return sweep(load_config(), np.array([3.0]), "rest", cycles=20, measure_cycles=10, workers=1)


def test_by_default_a_figure_is_drawn_here_at_the_call(tmp_path, one_point):
    assert not figures.own_process()
    path = tmp_path / "sweep.png"
    with Figures() as figs:
        assert not figs.in_own_process
        figs.draw("plot_sweep", [one_point], path, "title", caption="caption")
        assert path.is_file()   # at once, before the block ends
    assert figs.results == [path]


@pytest.mark.process
def test_a_worker_draws_the_same_png_and_the_block_waits_for_it(tmp_path, one_point):
    here, there = tmp_path / "here.png", tmp_path / "there.png"
    with Figures(own=False) as figs:
        figs.draw("plot_sweep", [one_point], here, "title", caption="caption")
    with Figures(own=True) as figs:
        assert figs.in_own_process
        figs.draw("plot_sweep", [one_point], there, "title", caption="caption")
    assert figs.results == [there] and figs.in_own_process
    assert there.read_bytes() == here.read_bytes()


@pytest.mark.process
def test_the_worker_draws_a_sweep_without_loading_the_model(tmp_path, one_point):
    # What the worker imports to draw a sweep: the plots and the result's own module, not the model and numba
    # (its imports are the time it has before the command asks for the figure).
    import pickle

    (tmp_path / "result.pickle").write_bytes(pickle.dumps([one_point]))
    code = ("import json, pickle, sys; from rimd_sim.analysis import plots; "
            "result = pickle.loads(open(sys.argv[1], 'rb').read()); plots.plot_sweep(result, sys.argv[2]); "
            "print(json.dumps(sorted(m for m in ('numba', 'rimd_sim.model.rig_model', 'rimd_sim.model.kernel', "
            "'rimd_sim.analysis.dynamics.sweep') if m in sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "result.pickle"), str(tmp_path / "s.png")],
                         capture_output=True, text=True, timeout=120, check=True)
    assert json.loads(out.stdout) == []
    assert (tmp_path / "s.png").stat().st_size > 10_000


def test_the_warm_up_writes_nothing_and_leaves_matplotlib_as_it_was(tmp_path, monkeypatch):
    import matplotlib
    import matplotlib.pyplot as plt

    from rimd_sim.analysis import plots

    monkeypatch.chdir(tmp_path)
    settings, open_figures = dict(matplotlib.rcParams), plt.get_fignums()
    plots.warm_up()
    assert list(tmp_path.iterdir()) == []
    assert plt.get_fignums() == open_figures
    assert dict(matplotlib.rcParams) == settings


@pytest.mark.process
def test_a_failure_in_the_worker_is_raised_when_the_block_ends(tmp_path, one_point):
    with pytest.raises(AttributeError, match="no_such_plot"):
        with Figures(own=True) as figs:
            figs.draw("no_such_plot", [one_point], tmp_path / "x.png")
    with pytest.raises(TypeError):
        with Figures(own=True) as figs:
            figs.draw("plot_sweep", [one_point], tmp_path / "y.png", no_such_keyword=1)
    assert not (tmp_path / "y.png").exists()


@pytest.mark.process
def test_an_error_in_the_block_goes_through_not_a_figures(tmp_path, one_point):
    # The block does not wait for its figures then: the computation's error is the one raised.
    with pytest.raises(ValueError, match="the computation failed"):
        with Figures(own=True) as figs:
            figs.draw("no_such_plot", [one_point], tmp_path / "x.png")
            raise ValueError("the computation failed")


def test_a_process_with_other_threads_starts_its_worker_by_spawn_not_fork():
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, daemon=True)
    other.start()
    try:
        assert figures._start_method(["fork", "spawn", "forkserver"]) == "spawn"
    finally:
        stop.set()
        other.join(5)
    assert figures._start_method(["spawn"]) == "spawn"


def test_use_own_process_sets_what_a_new_block_does():
    try:
        figures.use_own_process(True)
        assert figures.own_process()
    finally:
        figures.use_own_process(False)
    assert not figures.own_process()


def rimd_sweep(argv: list[str], out: Path) -> tuple[int, bool, list[tuple[bool, int]]]:
    """``rimd sweep ARGV`` (20 cycles) through the executable's ``cli.entry()`` in a fresh interpreter.

    Returns its exit status, whether it imported matplotlib, and per :class:`Figures` it made: in a worker process
    or not, and its process's children just after (the worker, when started).
    """
    code = ("import json, sys, multiprocessing\n"
            "from rimd_sim import cli\n"
            "from rimd_sim.analysis import figures\n"
            "seen = []\n"
            "made = figures.Figures.__init__\n"
            "def spy(self, own=None):\n"
            "    made(self, own)\n"
            "    seen.append((self.in_own_process, len(multiprocessing.active_children())))\n"
            "figures.Figures.__init__ = spy\n"
            f"sys.argv = ['rimd', 'sweep', *{argv!r}, '--cycles', '20', '--measure-cycles', '10',"
            f" '--out', {str(out)!r}]\n"
            "status = cli.entry()\n"
            "print(json.dumps([status, 'matplotlib' in sys.modules, seen]))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                            stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr
    status, plotted_here, seen = json.loads(result.stdout.split("\n")[-2])
    return status, plotted_here, [tuple(s) for s in seen]


@pytest.mark.process
@pytest.mark.parametrize(("argv", "worker"), [
    (["--f-min", "3", "--f-max", "3"], True),                              # one point: the sweep runs here
    (["--f-min", "3", "--f-max", "3.5", "--f-step", "0.5", "--workers", "2"], False),   # a pool of its own
])
def test_the_rimd_executable_draws_a_one_point_sweeps_figure_in_a_worker(tmp_path, argv, worker):
    # entry() turns the worker on: the process that runs ``rimd sweep`` has a child while it computes (not beside
    # a pool of the sweep's own), and the files are all there when it returns.
    status, _, seen = rimd_sweep(argv, tmp_path / "out")
    assert status == 0 and seen == [(worker, int(worker))]
    out = Path(tmp_path / "out")
    assert {p.name for p in out.iterdir()} == {"summary.json", "sweep.csv", "sweep.png"}
    assert out.joinpath("sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.process
def test_a_sweep_without_its_plot_loads_no_plotting_library_starts_no_worker_and_leaves_no_old_figure(tmp_path):
    # What a study scripting many points through the CLI asks for: the files of the point, nothing else loaded.
    out = tmp_path / "out"
    out.mkdir()
    out.joinpath("sweep.png").write_bytes(b"a figure of an earlier run")
    status, plotted_here, seen = rimd_sweep(["--f-min", "3", "--f-max", "3", "--no-plot"], out)
    assert (status, plotted_here, seen) == (0, False, [(False, 0)])   # drawn neither here nor in a worker
    assert {p.name for p in out.iterdir()} == {"summary.json", "sweep.csv"}
    assert json.loads(out.joinpath("summary.json").read_text())["points"]


@pytest.mark.process
def test_the_worker_ends_when_its_command_is_killed(tmp_path):
    # SIGKILL leaves the pool unclosed; the worker asked the kernel for SIGTERM at its parent's death.
    code = ("import os, sys, time, multiprocessing\n"
            "from rimd_sim.analysis.figures import Figures\n"
            "figs = Figures(own=True)\n"
            "figs._loaded.result(timeout=60)\n"
            "print([p.pid for p in multiprocessing.active_children()], flush=True)\n"
            "time.sleep(60)\n")
    command = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True,
                               stdin=subprocess.DEVNULL)
    worker = None
    try:
        (worker,) = json.loads(command.stdout.readline())
        os.kill(command.pid, signal.SIGKILL)
        command.wait(10)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and _alive(worker):
            time.sleep(0.05)
        assert not _alive(worker), f"the figure worker {worker} outlived its killed command"
    finally:
        command.kill()
        command.wait(10)
        if worker is not None and _alive(worker):   # the test failed: stop what it started all the same
            os.kill(worker, signal.SIGKILL)


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"
