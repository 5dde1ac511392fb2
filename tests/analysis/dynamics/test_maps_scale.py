"""Maps at scale (docs/analyses.md): early stopping, the ensemble kernel, and the Dask executor seam.

* The ensemble kernel without early stopping is the fixed-length ``steady_orbit`` run, cell for cell (class
  and final state), so the agreement test's fixed-length reference is ``steady_orbit``'s computation.
* Early stopping classifies the Peterka map as the fixed-length run to its cap (192 cycles) does, in
  >= 99 % of the cells, every differing cell listed in ``summary.json`` with both classes and a much longer
  run's. The test runs every sixth gap row of the default 31 x 61 map (6 x 61 = 366 cells, 0 to 3 mm, the three
  named starts each: ``--starts 0``; the extra start looks for coexisting attractors and neither the class from
  rest nor the cycles of the named starts depend on it), to stay fast; ``benchmarks/bench_maps.py`` runs the whole
  map.
* Through a real ``dask scheduler`` and two ``dask worker`` processes on loopback (started here, always
  stopped): ``peterka.csv`` equals the local one byte for byte, also when a worker is killed (SIGKILL) in the
  middle of the map; ``sweep``, ``bifurcation`` and ``basins`` give the same files as locally; an
  unreachable scheduler is refused within 10 s naming the address and the reason.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import rimd_sim
from harness.outputs import read_json
from harness.presets import SINGLE_MASS_ARGS, SINGLE_MASS_SET
from rimd_sim import cli
from rimd_sim.analysis.dynamics.steady import steady_orbit
from rimd_sim.errors import ConfigError
from rimd_sim.model.ensemble import StopRule, run_cells
from rimd_sim.model.rig_model import model_for
from rimd_sim.settings.config import load_config

SRC = str(Path(rimd_sim.__file__).resolve().parent.parent)
DASK = str(Path(sys.executable).with_name("dask"))


def test_ensemble_without_early_stop_is_the_fixed_length_run():
    """Nine cells (three gaps x three frequencies, from rest and from a kick): same class and bit-identical
    final stroboscopic state as ``steady_orbit`` with ``RigModel``. A cell that ran to the cap reports the cap
    + 1 cycles (the ensemble's documented count: the points of cycles 0 .. cap were used)."""
    base = load_config(None)
    gaps, freqs = [0.0, 1e-3, 2.4e-3], [3.75, 5.0, 7.25]
    cfgs = [base.with_parameters({"gap": g}) for g in gaps]
    params = np.array([model_for(c).params(c) for c in cfgs])
    gi = np.repeat(np.arange(3), 3)
    ff = np.tile(freqs, 3)
    rule = StopRule(early=False, max_cycles=60 + 36, measure_cycles=36)
    for theta_dot0 in (0.0, 0.8):
        res = run_cells("rigid", params, gi, ff, np.zeros(9), np.full(9, theta_dot0), rule)
        for i, label in enumerate(res.labels()):
            orbit = steady_orbit(cfgs[gi[i]], ff[i], theta_dot0=theta_dot0, transient_cycles=60, measure_cycles=36)
            assert label == orbit.label, (gaps[gi[i]], ff[i])
            assert tuple(res.final[i]) == orbit.final_state
            assert res.cycles[i] == rule.max_cycles + 1  # ran to the cap


def test_early_stop_stops_settled_motions_early_and_runs_chaos_to_the_cap():
    """Gap 0: 3.75 Hz (1/1) stops at the first chance (the default rule: after at least 30 cycles, a period-1
    repetition over its 24-cycle window, so by cycle 40 at the latest); 8.5 Hz (non-periodic) runs to the cap
    and reports the cap + 1 cycles."""
    cfg = load_config(None, {"gap": 0.0})
    rule = StopRule()
    res = run_cells("rigid", model_for(cfg).params(cfg)[None, :], np.zeros(2, dtype=np.int64), np.array([3.75, 8.5]),
                    np.zeros(2), np.zeros(2), rule)
    assert res.labels() == ["1/1", "chaotic/non-periodic"]
    assert rule.min_cycles <= res.cycles[0] <= 40 and res.cycles[1] == rule.max_cycles + 1


def test_the_contraction_stop_classifies_as_a_run_ten_times_the_cap():
    """The default stop (``contraction``) on a 4 x 7 grid of the default rig: the class from rest of every cell
    (1/1, 3/1, 2/2, 1/2, 5/12, 1/3, no impact and chaotic among them) equals that of a fixed run of 1920 cycles
    (ten times the cap), with far fewer cycles than the ``window`` rule; ``stop="window"`` gives, cell for cell,
    the ensemble run with that rule (``StopRule()``: the 24-cycle window after at least 30 cycles)."""
    from rimd_sim.analysis.dynamics.peterka import peterka, rest_classes

    config = load_config(None)
    gaps, freqs = [0.0, 0.8e-3, 1.6e-3, 2.4e-3], np.linspace(2.0, 8.0, 7)
    new = peterka(config, gaps, freqs, starts=0, rest_cycles=192, workers=1)   # the stop rule at the common cap
    old = peterka(config, gaps, freqs, starts=0, stop="window", rest_cycles=192, workers=1)
    reference = rest_classes(config, gaps, freqs, cycles=1920, workers=1)
    assert new.stop == "contraction" and old.stop == "window"
    assert new.primary.tolist() == reference.tolist()
    assert len(set(reference.ravel().tolist())) >= 7
    settled = new.cycles[0] <= 192
    assert new.cycles[0][settled].mean() < 0.6 * old.cycles[0][settled].mean()
    assert new.cycles[0].min() < 30 <= old.cycles[0].min()   # no 30-cycle floor
    for i, g in enumerate(gaps):
        cfg = config.with_parameters({"gap": g})
        res = run_cells("rigid", model_for(cfg).params(cfg)[None, :], np.zeros(7, dtype=np.int64), freqs,
                        np.zeros(7), np.zeros(7), StopRule())
        assert old.labels[0, i].tolist() == res.labels() and old.cycles[0, i].tolist() == res.cycles.tolist()
    with pytest.raises(ConfigError, match="stop"):
        peterka(config, gaps, freqs, stop="confirm", workers=1)


def test_rimd_peterka_writes_the_default_rule_map(tmp_path):
    """``rimd peterka`` writes the map of the API's default stop rule (its classes and cycles) and names the rule,
    ``contraction``, in ``summary.json``."""
    from rimd_sim.analysis.dynamics.peterka import peterka

    grid = ["--gap-min-mm", "0", "--gap-max-mm", "2.4", "--gaps", "2", "--f-min", "3", "--f-max", "8", "--freqs", "3",
            "--starts", "0", "--workers", "1"]
    assert cli.main(["peterka", *grid, "--out", str(tmp_path / "c")]) == 0
    assert read_json(tmp_path / "c" / "summary.json")["stop"] == "contraction"
    api = peterka(load_config(None), [0.0, 2.4e-3], [3.0, 5.5, 8.0], starts=0, workers=1)
    with np.load(tmp_path / "c" / "peterka.npz") as npz:
        assert npz["cycles"].tolist() == api.cycles.tolist()
        assert npz["classes"][npz["codes"][0]].tolist() == api.primary.tolist()


@pytest.mark.process
def test_early_stop_agrees_with_twice_the_cycles(tmp_path):
    """Every sixth gap row of the default map: >= 99 % of the cells (class from rest) as the fixed-length run
    with the same caps (192 cycles, 640 from rest); every differing cell listed in the summary with
    both classes and the class of a run ten times the cap (1920 cycles), which is ``steady_orbit``'s over the same
    cycles (its last 72)."""
    out = tmp_path / "pk"
    assert cli.main(["peterka", "--gaps", "6", "--starts", "0", "--compare-fixed", "--out", str(out)]) == 0
    summary = read_json(out / "summary.json")
    comp = summary["comparison"]
    assert comp["fixed_cycles"] == 192 and summary["cells"] == 6 * 61
    assert comp["agreement_from_rest"] >= 0.99, comp
    listed = [c for c in comp["differing_cells"] if c["start"] == "rest"]
    assert len(listed) == round((1 - comp["agreement_from_rest"]) * summary["cells"])
    rows = {(round(float(r.split(",")[0]), 6), round(float(r.split(",")[2]), 6)): r.split(",")[4]
            for r in (out / "peterka.csv").read_text().splitlines()[1:]}
    base = load_config(None)
    for cell in listed:
        assert cell["early_stop"] != cell["fixed_length"]
        assert rows[(round(cell["gap_mm"], 6), round(cell["frequency_hz"], 6))] == cell["early_stop"]
        assert cell["long_run_cycles"] == 10 * 192
        long_run = steady_orbit(base.with_parameters({"gap": cell["gap_mm"] * 1e-3}), cell["frequency_hz"],
                                transient_cycles=10 * 192 - 72, measure_cycles=72)
        assert cell["long_run"] == long_run.label, cell
    # Most trajectories stopped well before the cap.
    assert summary["cycles_run"]["mean"] < 0.6 * 192 and summary["rest_cycles"] == 640


# ---- Dask ---------------------------------------------------------------------------------------------


def _free_port() -> int:
    """A port nothing listens on now (for a refusal test: nothing need bind it later)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """A ``dask scheduler`` and ``dask worker`` processes on loopback, each in its own process group."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.procs: list[subprocess.Popen] = []
        self.workers: list[subprocess.Popen] = []
        self.env = {**os.environ, "PYTHONPATH": os.pathsep.join([SRC, os.environ.get("PYTHONPATH", "")]),
                    "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
        self.env.pop("RIMD_DASK_SCHEDULER", None)
        # The scheduler picks its own free port and writes its address to a file: a port chosen here and bound
        # later could be taken in between by another test's server (the client would then hang on a foreign socket).
        scheduler_file = tmp / "scheduler.json"
        self._start("scheduler", [DASK, "scheduler", "--host", "127.0.0.1", "--port", "0", "--scheduler-file",
                                  str(scheduler_file), "--no-dashboard", "--no-show"])
        self.address = self._read_address(scheduler_file, deadline_s=60.0)

    def _read_address(self, scheduler_file: Path, deadline_s: float) -> str:
        deadline = time.monotonic() + deadline_s
        while time.monotonic() < deadline:
            try:
                return json.loads(scheduler_file.read_text())["address"]
            except (FileNotFoundError, json.JSONDecodeError, KeyError):
                if self.procs[0].poll() is not None:
                    raise RuntimeError(f"dask scheduler exited with status {self.procs[0].returncode}") from None
                time.sleep(0.05)
        raise TimeoutError(f"dask scheduler wrote no address to {scheduler_file} within {deadline_s} s")

    def _start(self, name: str, argv: list[str]) -> subprocess.Popen:
        log = open(self.tmp / f"{name}-{len(self.procs)}.log", "wb")  # closed with the process
        proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, env=self.env, start_new_session=True,
                                cwd=self.tmp)
        self.procs.append(proc)
        return proc

    def add_worker(self) -> subprocess.Popen:
        proc = self._start("worker", [DASK, "worker", self.address, "--nworkers", "1", "--nthreads", "1",
                                      "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"])
        self.workers.append(proc)
        return proc

    def wait_for_workers(self, n: int, deadline_s: float = 60.0) -> None:
        from distributed import Client

        with Client(self.address, timeout=deadline_s, set_as_default=False) as client:
            client.wait_for_workers(n, timeout=deadline_s)

    def stop(self) -> None:
        """SIGTERM to every process group, SIGKILL to what still runs after 3 s."""
        for proc in reversed(self.procs):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        deadline = time.monotonic() + 3.0
        for proc in self.procs:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)


@pytest.fixture
def cluster(tmp_path):
    c = Cluster(tmp_path)
    try:
        c.add_worker()
        c.add_worker()
        c.wait_for_workers(2)
        yield c
    finally:
        c.stop()


PETERKA = ["peterka", "--gap-min-mm", "0", "--gap-max-mm", "2.4", "--gaps", "6", "--f-min", "3.5", "--f-max", "8.5",
           "--freqs", "12", "--transient-cycles", "60", "--measure-cycles", "36"]


def test_rimd_peterka_mirrors_the_largest_rest_cycles():
    """The verb mirrors the largest --rest-cycles without importing the analysis to build its parser."""
    from rimd_sim.analysis.dynamics.peterka import MAX_REST_CYCLES
    from rimd_sim.cli.verbs import peterka as verb

    assert verb.MAX_REST_CYCLES == MAX_REST_CYCLES


@pytest.mark.process
def test_dask_peterka_is_the_local_map_even_when_a_worker_dies(cluster, tmp_path):
    """``peterka.csv`` through the cluster equals the local one byte for byte; then again with one of the two
    workers killed (SIGKILL) after the first row came back: Dask resubmits its tasks, the map is identical."""
    local, remote = tmp_path / "local", tmp_path / "remote"
    assert cli.main([*PETERKA, "--out", str(local)]) == 0
    assert cli.main([*PETERKA, "--scheduler", cluster.address, "--out", str(remote)]) == 0
    assert (remote / "peterka.csv").read_bytes() == (local / "peterka.csv").read_bytes()
    assert read_json(remote / "summary.json")["where"] == cluster.address

    from rimd_sim.analysis.dynamics.peterka import peterka, peterka_table

    config = load_config(None)
    gaps = np.linspace(0, 2.4, 6) * 1e-3
    freqs = np.linspace(3.5, 8.5, 12)
    victim = cluster.workers[0]
    killed_at = []

    def progress(done: int, total: int) -> None:
        if not killed_at:
            os.killpg(victim.pid, signal.SIGKILL)
            killed_at.append((done, total))

    result = peterka(config, gaps, freqs, transient_cycles=60, measure_cycles=36, scheduler=cluster.address,
                     progress=progress)
    assert killed_at and killed_at[0][0] < killed_at[0][1]  # killed while rows were still to come
    assert victim.wait(timeout=10) == -signal.SIGKILL
    reference = peterka(config, gaps, freqs, transient_cycles=60, measure_cycles=36, workers=1)
    assert peterka_table(result) == peterka_table(reference)


@pytest.mark.process
def test_dask_sweep_bifurcation_basins_equal_local(cluster, tmp_path):
    """The other three verbs accept --scheduler and write the same CSV as locally."""
    cases = [
        (["sweep", "--gap-mm", "1", "--f-min", "3", "--f-max", "7", "--f-step", "0.5", "--cycles", "40",
          "--measure-cycles", "10"], "sweep.csv"),
        (["sweep", "--gap-mm", "1", "--f-min", "3", "--f-max", "4", "--f-step", "0.5", "--cycles", "40",
          "--measure-cycles", "10", "--direction", "up"], "sweep.csv"),
        (["bifurcation", "--f-min", "4.8", "--f-max", "5.0", "--f-step", "0.1", "--transient-cycles", "30",
          "--sample-cycles", "12"], "bifurcation.csv"),
        (["basins", "--size", "5", "--transient-cycles", "60", "--measure-cycles", "24"], "basins.csv"),
    ]
    for i, (argv, name) in enumerate(cases):
        local, remote = tmp_path / f"l{i}", tmp_path / f"r{i}"
        assert cli.main([*argv, "--out", str(local)]) == 0
        assert cli.main([*argv, "--scheduler", cluster.address, "--out", str(remote)]) == 0
        assert (remote / name).read_bytes() == (local / name).read_bytes(), argv[0]


@pytest.mark.parametrize("how", ["option", "environment"])
def test_unreachable_scheduler_is_refused_within_10s(tmp_path, how, capsys, monkeypatch):
    """The refusal is timed in this process (imports done), so the 10 s bound judges the probe of the scheduler
    and not the start-up of an interpreter on a loaded machine (the probe itself gives up after 3 s)."""
    address = f"tcp://127.0.0.1:{_free_port()}"  # nothing listens there
    argv = [*PETERKA, "--out", str(tmp_path / "pk")]
    if how == "option":
        argv[-2:-2] = ["--scheduler", address]
    else:
        monkeypatch.setenv("RIMD_DASK_SCHEDULER", address)
    status = cli.main(argv)
    assert status == 1
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and address in lines[0] and "cannot reach the Dask scheduler" in lines[0], lines
    assert lines[0].split(address, 1)[1].strip(": ")  # a reason follows the address
    assert not (tmp_path / "pk").exists()


def test_malformed_scheduler_address_is_refused(tmp_path, capsys):
    assert cli.main([*PETERKA, "--scheduler", "localhost8786", "--out", str(tmp_path / "pk")]) == 1
    err = capsys.readouterr().err.strip()
    assert "localhost8786" in err and "tcp://HOST:PORT" in err


def test_big_map_outputs_npz_and_a_png_with_a_pixel_per_cell(tmp_path, monkeypatch):
    """A 600 x 700 map (classes drawn from a pattern, not simulated): the .npz holds the classes and codes that
    give back the labels, and the PNG is drawn as an image with at least one pixel per cell in the plot area (the
    map's axes as laid out for the save, in the PNG's pixels; that area of the PNG is coloured throughout)."""
    from matplotlib.figure import Figure
    from matplotlib.image import imread

    from rimd_sim.analysis.dynamics.peterka import PeterkaResult, save_peterka_npz
    from rimd_sim.analysis.plots import plot_peterka

    rows, cols = 600, 700
    names = np.array(["1/1", "1/2", "no impact", "chaotic/non-periodic", "2/6", "3/7"], dtype=object)
    i, j = np.mgrid[0:rows, 0:cols]
    labels = np.stack([names[(i // 40 + j // 50) % 6], names[(i // 40 + j // 50) % 6],
                       names[(i // 20 + j // 25) % 6]])
    result = PeterkaResult(np.linspace(0, 3, rows), np.linspace(1.82, 9.1, cols), np.linspace(0, 3, rows),
                           np.linspace(1, 5, cols), labels, 0.0, 1, 192, np.full(labels.shape, 40), True)
    save_peterka_npz(result, tmp_path / "pk.npz")
    data = np.load(tmp_path / "pk.npz")
    assert data["codes"].shape == (3, rows, cols) and data["codes"].dtype == np.int16
    assert (data["classes"][data["codes"]] == labels.astype(str)).all()
    assert data["coexisting"].sum() == result.coexisting.sum() > 0
    areas = []
    save = Figure.savefig

    def spy(fig, fname, *args, **kwargs):
        """The axes that hold the map's image, in the saved PNG's pixels (after the figure's layout)."""
        width, height = fig.get_size_inches() * (kwargs.get("dpi") or fig.dpi)
        areas.extend((ax.get_position(), width, height) for ax in fig.axes if ax.images)
        return save(fig, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", spy)
    plot_peterka(result, tmp_path / "pk.png", "dense")
    image = imread(tmp_path / "pk.png")
    ((box, width, height),) = areas
    assert image.shape[:2] == (round(height), round(width))
    left, right = box.x0 * width, box.x1 * width
    top, bottom = (1.0 - box.y1) * height, (1.0 - box.y0) * height  # PNG rows count from the top
    assert right - left >= cols and bottom - top >= rows  # at least a pixel per cell
    plot_area = image[int(top) + 1:int(bottom) - 1, int(left) + 1:int(right) - 1, :3]
    assert (plot_area < 0.99).any(axis=2).mean() > 0.99  # the map fills it


def test_rest_cycles_classifies_each_cell_as_the_run_of_that_many_cycles_from_rest():
    """``rest_cycles=1920``: the starts from rest still unsettled at the cap of 192 run on, so the class of every
    cell of a 4 x 5 grid (chaotic, 2/4, 1/3 read at 1920 cycles, no impact among them) equals the fixed run of 1920
    cycles from rest (``rest_classes``), where the map with the common cap (192) differs in at least 2 cells. The
    default is 640 (at least the common cap; the common cap without early stopping). A start from rest that
    settled before the cap is untouched (class and cycles), one that ran to it goes on past it; the other starts
    are the default map's, class and cycles."""
    from rimd_sim.analysis.dynamics.peterka import peterka, rest_classes

    config = load_config(None, SINGLE_MASS_SET)
    gaps, freqs = [0.0, 0.7e-3, 1.3e-3, 2.3e-3], [4.25, 5.37, 7.23, 8.54, 9.1]
    default = peterka(config, gaps, freqs, starts=0, rest_cycles=192, workers=1)   # the common cap
    long = peterka(config, gaps, freqs, starts=0, rest_cycles=1920, workers=1)
    reference = rest_classes(config, gaps, freqs, cycles=1920, workers=1)
    assert (default.rest_cap, long.rest_cap) == (192, 1920)
    assert peterka(config, gaps[:1], freqs[:1], starts=0, workers=1).rest_cap == 640   # the default
    assert peterka(config, gaps[:1], freqs[:1], starts=0, transient_cycles=700, workers=1).rest_cap == 772
    assert peterka(config, gaps[:1], freqs[:1], starts=0, early_stop=False, workers=1).rest_cap == 192
    assert long.primary.tolist() == reference.tolist()
    assert (default.primary != reference).sum() >= 2
    settled = default.cycles[0] <= 192
    assert long.cycles[0][settled].tolist() == default.cycles[0][settled].tolist()
    assert long.primary[settled].tolist() == default.primary[settled].tolist()
    assert (~settled).sum() >= 4 and (long.cycles[0][~settled] > 193).all()
    assert (long.cycles[0] == 1921).any()   # a chaotic cell runs to the new cap
    assert long.labels[1:].tolist() == default.labels[1:].tolist()
    assert long.cycles[1:].tolist() == default.cycles[1:].tolist()
    for bad in (100, 1920.0, True, 2_000_000):
        with pytest.raises(ConfigError, match="rest_cycles"):
            peterka(config, gaps[:1], freqs[:1], starts=0, rest_cycles=bad, workers=1)


def test_a_motion_converging_near_a_period_doubling_is_classified_by_its_limit_at_the_cap():
    """Two pairs of neighbouring cells of the paper's rig across a period doubling (1/3 to 2/6 at 8.29 Hz, 1/2 to
    2/4 at 4.76 Hz), each start from rest reaching the default cap of 640 cycles unsettled: the map classifies the
    cell on the period-1 side by the orbit its period-doubled window converges to (1/3, 1/2), as the run of 1920
    cycles does, and keeps the period-doubled one (2/6, 2/4). The plain classification of the same 640 cycles
    gives the period-doubled class to both, so the limit is what tells them apart."""
    from rimd_sim.analysis.dynamics.peterka import peterka, rest_classes

    config = load_config(None)
    gaps, freqs = np.linspace(0.0, 3e-3, 100), np.linspace(1.82, 9.1, 100)
    for rows, column, doubled, limit in (([41, 42], 88, "2/6", "1/3"), ([34, 35], 40, "2/4", "1/2")):
        cells = (gaps[rows], freqs[[column]])
        result = peterka(config, *cells, starts=0, workers=1)
        assert result.cycles[0].ravel().tolist() == [641, 641]   # both ran to the cap from rest
        assert result.primary.ravel().tolist() == [doubled, limit]
        assert rest_classes(config, *cells, cycles=640, workers=1).ravel().tolist() == [doubled, doubled]
        assert rest_classes(config, *cells, cycles=1920, workers=1).ravel().tolist() == [doubled, limit]


@settings(max_examples=60, deadline=None)
@given(q=st.floats(0.3, 0.995), amplitude=st.floats(2e-3, 1.0), distance=st.floats(0.0, 1.0),
       phase=st.integers(0, 5))
def test_the_limit_of_a_period_doubled_window_is_its_geometric_extrapolation(q, amplitude, distance, phase):
    """``_limit_period`` on stroboscopic points ``u_i = x + (-1)^i (distance / 2 + amplitude q^(i / 10))`` (an impact
    every cycle): the repetition at period 1 shrinks geometrically towards ``distance``, that at period 2 is 0. It
    returns 1 (the motion converges to a period-1 orbit) exactly when ``distance`` is within the tolerance,
    2 otherwise; a repetition that grows instead is left at period 2."""
    from rimd_sim.model.ensemble import _limit_period

    tol = 1e-3
    assume(distance <= 0.5 * tol or distance >= 2 * tol)
    cycles = np.arange(300 + phase)
    sign = np.where(cycles % 2 == 0, 1.0, -1.0)
    u = 0.3 + sign * (distance / 2 + amplitude * q ** (cycles / 10))
    v = np.full(cycles.size, -0.2)
    counts = np.ones(cycles.size, dtype=np.int64)
    expected = 1 if distance <= 0.5 * tol else 2
    assert _limit_period(u, v, counts, cycles.size, 2, 72, tol) == expected
    growing = 0.3 + sign * (distance / 2 + amplitude * q ** ((cycles.size - cycles) / 10))
    assert _limit_period(growing, v, counts, cycles.size, 2, 72, tol) == 2
    counts[::7] = 2   # impacts that do not repeat at period 1 keep period 2
    assert _limit_period(u, v, counts, cycles.size, 2, 72, tol) == 2


def test_rimd_peterka_rest_cycles_writes_its_cap_and_how_many_ran_to_it(tmp_path, capsys):
    """``--rest-cycles 1920``: ``summary.json`` gives the cap of the start from rest and the fraction of the cells
    whose start from rest ran to it; the default gives its cap, 640. Both say how many cells were classified at
    the cap without having settled, the default with the option that runs them on (ten times the common cap)."""
    grid = ["--gap-min-mm", "0", "--gap-max-mm", "0", "--gaps", "1", "--f-min", "5.37", "--f-max", "8.54",
            "--freqs", "2", "--starts", "0", "--workers", "1", *SINGLE_MASS_ARGS]
    assert cli.main(["peterka", *grid, "--rest-cycles", "1920", "--out", str(tmp_path / "long")]) == 0
    out = capsys.readouterr().out
    assert "1 cell(s) (50.0 %) classified at the cap of 1920 cycles from rest without having settled" in out
    assert "--rest-cycles" not in out
    assert cli.main(["peterka", *grid, "--out", str(tmp_path / "default")]) == 0
    out = capsys.readouterr().out
    assert ("1 cell(s) (50.0 %) classified at the cap of 640 cycles from rest without having settled (chaotic, or a "
            "transient longer than the cap); --rest-cycles 1920 runs their start from rest on") in out
    long, default = read_json(tmp_path / "long" / "summary.json"), read_json(tmp_path / "default" / "summary.json")
    assert (long["rest_cycles"], default["rest_cycles"]) == (1920, 640)
    assert long["cycles_run"]["rest_cap"] == 1920 and default["cycles_run"]["rest_cap"] == 640
    # Gap 0: 5.37 Hz is chaotic at 1920 cycles from rest (it runs to each cap), 8.54 Hz settles (2/4) after more
    # than the common cap of 192 and before 640.
    assert default["cycles_run"]["rest_ran_to_cap"] == 0.5 and long["cycles_run"]["rest_ran_to_cap"] == 0.5
    assert default["classes_from_rest"] == long["classes_from_rest"]
    assert long["classes_from_rest"] == {"chaotic/non-periodic": 1, "2/4": 1}
