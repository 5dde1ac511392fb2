"""A base install has none of the extras (rerun, foxglove, dask, testing: rimd_sim/dependencies.py).

Hypotheses, for each extra hidden in turn (its modules made unimportable in this process, the package imported
afresh): every module of the package imports, but the pytest plugin without pytest (it is loaded by pytest only,
through the entry point ``pytest11``); the base commands work (``rimd --help``, ``rimd info``, the bring-up of
``rimd rig --no-rerun``, a local executor of the analyses); and the feature that needs the extra refuses with an
error of the family (:class:`rimd_sim.errors.UnavailableError`) naming what to install: ``pip install
'rimd-sim[EXTRA]'``.

In-process: ``sys.modules[name] = None`` makes ``import name`` fail as if it were not installed, and
``importlib.util.find_spec(name)`` answer None; the package's modules are removed first, so they import again under
that condition, and they are put back afterwards.
"""

from __future__ import annotations

import importlib
import pkgutil
import re
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from rimd_sim.dependencies import DEPENDENCIES, EXTRAS

#: The modules each extra brings (the table's rows of that extra).
HIDDEN = {extra: tuple(d.module for d in DEPENDENCIES if d.extra == extra) for extra in EXTRAS}
#: The module that needs pytest by nature: the rimd_rig fixture's plugin.
PYTEST_PLUGIN = "rimd_sim.ros.testing"


@contextmanager
def without(*modules: str) -> Iterator[None]:
    """``modules`` (and their submodules) cannot be imported, and rimd_sim imports afresh; all put back after."""
    saved = dict(sys.modules)

    def hidden(name: str) -> bool:
        return any(name == m or name.startswith(m + ".") for m in (*modules, "rimd_sim"))

    try:
        for name in [name for name in sys.modules if hidden(name)]:
            del sys.modules[name]
        for module in modules:
            sys.modules[module] = None  # type: ignore[assignment]
        importlib.invalidate_caches()
        yield
    finally:
        # The package's fresh modules and the hidden ones go; a third-party module imported meanwhile stays (an
        # extension module cannot be loaded twice in a process).
        for name in [name for name in sys.modules if hidden(name) and name not in saved]:
            del sys.modules[name]
        sys.modules.update(saved)


def _package_modules() -> list[str]:
    import rimd_sim

    return [info.name for info in pkgutil.walk_packages(rimd_sim.__path__, "rimd_sim.")
            if not info.name.endswith("__main__")]


def test_hiding_works():
    """The test's own premise: a hidden module is not importable, and find_spec does not find it."""
    with without("yaml"):
        with pytest.raises(ImportError):
            import yaml  # noqa: F401
        from rimd_sim.dependencies import installed

        assert not installed("yaml")
    import yaml  # noqa: F401, F811 - back


@pytest.mark.parametrize("extra", sorted(HIDDEN))
def test_every_module_imports_without_the_extra(extra):
    assert HIDDEN[extra], extra
    with without(*HIDDEN[extra]):
        failed = []
        for name in _package_modules():
            try:
                importlib.import_module(name)
            except ImportError as exc:
                failed.append(f"{name}: {exc}")
    expected = [f"{PYTEST_PLUGIN}: import of pytest halted; None in sys.modules"] if extra == "testing" else []
    assert failed == expected, "modules that need the extra " + extra + ":\n" + "\n".join(failed)


@pytest.mark.parametrize("extra", sorted(HIDDEN))
def test_the_base_commands_work_without_the_extra(extra, repo_root, tmp_path, capsys):
    with without(*HIDDEN[extra]):
        import rimd_sim
        from rimd_sim.analysis.executor import run_tasks
        from rimd_sim.cli import main
        from rimd_sim.ros.bringup import plan_rig
        from rimd_sim.ros.nodes.registry import by_name

        with pytest.raises(SystemExit) as help_exit:
            main(["--help"])
        assert help_exit.value.code == 0
        assert main(["info"]) == 0
        # rimd rig --no-rerun: the recorder and the simulator (the bring-up's plan; starting them is a process test),
        # whose modules import (the processes' entry).
        plan = plan_rig(repo_root / "config" / "rimd.yaml", output_dir=tmp_path / "rec", rerun=False)
        assert plan.names == ["rimd_recorder", "rimd_simulator"]
        for node in plan.nodes:
            importlib.import_module(by_name(node.entry).target.split(":")[0])
        # The analyses run their tasks on the local executor (one worker: in this process).
        assert run_tasks(abs, [-1, -2], workers=1)[0] == [1, 2]
        version = rimd_sim.__version__
    out = capsys.readouterr().out
    assert "usage: rimd" in out and version in out


def test_rerun_features_name_the_extra(repo_root, tmp_path, capsys):
    with without(*HIDDEN["rerun"]):
        from rimd_sim.cli import main
        from rimd_sim.errors import RimdError, UnavailableError
        from rimd_sim.ros.bringup import plan_rig
        from rimd_sim.viz.rerun_map import RigMapper, blueprint
        from rimd_sim.viz.rrd_data import load_rrd
        from rimd_sim.viz.sinks import RerunStream, SinkError, SinkSpec

        # rimd rig with Rerun on (the default configuration): refused before anything starts.
        with pytest.raises(RimdError) as refused:
            plan_rig(repo_root / "config" / "rimd.yaml", output_dir=tmp_path / "rec")
        assert ("the Rerun bridge needs rerun-sdk: pip install 'rimd-sim[rerun]' (or run with --no-rerun)"
                in str(refused.value))
        with pytest.raises(SinkError, match=r"needs rerun-sdk: pip install 'rimd-sim\[rerun\]'"):
            RerunStream(SinkSpec("save", path=str(tmp_path / "x.rrd")))
        assert issubclass(SinkError, UnavailableError)
        for call in (lambda: RigMapper(None), blueprint, lambda: load_rrd(tmp_path / "x.rrd")):
            with pytest.raises(SinkError, match=r"pip install 'rimd-sim\[rerun\]'"):
                call()
        assert main(["rerun", str(tmp_path / "none.mcap")]) == 1
    err = capsys.readouterr().err
    assert "rimd rerun: the Rerun view of a recording needs rerun-sdk: pip install 'rimd-sim[rerun]'" in err


def test_foxglove_features_name_the_extra(repo_root, tmp_path, capsys):
    with without(*HIDDEN["foxglove"]):
        from rimd_sim.cli import main
        from rimd_sim.errors import RimdError
        from rimd_sim.ros.bringup import plan_rig
        from rimd_sim.viz.foxglove_sink import FoxgloveError, FoxgloveSink, check_address

        check_address("127.0.0.1", 8765)   # the settings' checks need no SDK
        with pytest.raises(FoxgloveError, match=r"^the Foxglove server needs foxglove-sdk: "
                                                r"pip install 'rimd-sim\[foxglove\]'$"):
            FoxgloveSink(port=0)
        assert main(["rig", "--foxglove", "--no-rerun", "--no-record"]) == 1
        # Asked by the configuration (the bridge's foxglove.enabled) instead of --foxglove: refused by the plan.
        config = tmp_path / "foxglove.yaml"
        config.write_text((repo_root / "config" / "rimd.yaml").read_text().replace(
            "    foxglove:\n      enabled: false\n", "    foxglove:\n      enabled: true\n", 1))
        assert "      enabled: true\n" in config.read_text()
        with pytest.raises(RimdError, match=r"needs foxglove-sdk: pip install 'rimd-sim\[foxglove\]' "
                                            r"\(or set foxglove.enabled: false\)"):
            plan_rig(config, output_dir=tmp_path / "rec", rerun=False)
        assert main(["replay", str(tmp_path / "none.mcap"), "--foxglove"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert "rimd rig: the Foxglove server needs foxglove-sdk: pip install 'rimd-sim[foxglove]' " \
           "(or run without --foxglove)" in err
    assert "rimd replay: the Foxglove server needs foxglove-sdk: pip install 'rimd-sim[foxglove]' " \
           "(or replay without --foxglove)" in err


def test_a_dask_scheduler_names_the_extra():
    with without(*HIDDEN["dask"]):
        from rimd_sim.analysis.executor import SchedulerError, open_executor

        # Named before the address is probed (nothing listens on port 9 here either).
        with pytest.raises(SchedulerError, match=r"^the Dask scheduler tcp://127.0.0.1:9 needs distributed: "
                                                 r"pip install 'rimd-sim\[dask\]'"):
            with open_executor(scheduler="tcp://127.0.0.1:9"):
                pass


def test_the_pytest_plugin_is_loaded_by_pytest_only(repo_root):
    """The one module that needs pytest is reached through pytest's entry point group, never imported by another."""
    assert '"pytest11": ["rimd_sim = rimd_sim.ros.testing"]' in (repo_root / "rimd_sim" / "setup.py").read_text()
    package = repo_root / "rimd_sim" / "rimd_sim"
    importers = [str(path.relative_to(package)) for path in package.rglob("*.py")
                 if re.search(r"^\s*(from rimd_sim\.ros\.testing import|import rimd_sim\.ros\.testing|"
                              r"from rimd_sim\.ros import testing)", path.read_text(), re.MULTILINE)]
    assert not importers
