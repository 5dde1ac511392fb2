"""A copy of ``rimd_sim`` builds in a fresh colcon workspace and installs what docs/ros-install.md promises.

Hypotheses: ``rimd_sim/`` carries everything it needs (no link out of it is followed: the copy keeps links as
links); ``colcon build`` without ``--symlink-install`` (a plain install, as on a lab machine) against the project
venv and the set-up's ``rimd_msgs`` as underlays installs the configuration and the launch file in
``share/rimd_sim``, the node executables in ``lib/rimd_sim``, and, once ``install/setup.sh`` is sourced, a ``rimd``
on PATH that runs from the workspace and names the workspace's ``share/rimd_sim/config``, not the repository's
``config/``. (``rimd_msgs`` is built from a clean tree by the set-up of every fresh clone, ``scripts/setup.sh``:
the interfaces' generation is the build's long part, and repeating it here proved nothing more.)
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rimd_sim.ros.nodes.registry import NODES

#: Variables a sourced env.sh leaves that would point the build at the repository's workspace (setup.sh unsets them).
UNSET = ("PYTHONPATH", "COLCON_PREFIX_PATH", "AMENT_CURRENT_PREFIX", "LD_LIBRARY_PATH",
         "_ROS_WHEELS_BOOTSTRAP_COMPLETE", "CMAKE_PREFIX_PATH", "AMENT_PREFIX_PATH", "VIRTUAL_ENV")


def _build_environment(venv: Path, repo_root: Path) -> dict[str, str]:
    """scripts/setup.sh's build_environment: the venv as the only underlay, nothing of the repository's ros_ws."""
    env = {name: value for name, value in os.environ.items() if name not in UNSET}
    path = [p for p in env.get("PATH", "").split(os.pathsep) if p and not p.startswith(str(repo_root / "ros_ws"))]
    env.update(VIRTUAL_ENV=str(venv), PATH=os.pathsep.join([str(venv / "bin"), *path]),
               AMENT_PREFIX_PATH=str(venv), CMAKE_PREFIX_PATH=str(venv))
    return env


@pytest.mark.process
@pytest.mark.timeout(600)
def test_a_copy_of_rimd_sim_builds_and_runs_from_a_colcon_workspace(repo_root, tmp_path):
    venv = Path(sys.prefix)
    assert (venv / "bin" / "colcon").is_file(), "the project venv has colcon (requirements.txt)"
    workspace = tmp_path / "ws"
    shutil.copytree(repo_root / "rimd_sim", workspace / "src" / "rimd_sim", symlinks=True,
                    ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    msgs = repo_root / "ros_ws" / "install" / "rimd_msgs"
    assert (msgs / "share" / "rimd_msgs" / "package.xml").is_file(), "the set-up built rimd_msgs (make setup)"
    env = _build_environment(venv, repo_root)
    env.update(AMENT_PREFIX_PATH=f"{msgs}{os.pathsep}{venv}", CMAKE_PREFIX_PATH=f"{msgs}{os.pathsep}{venv}")
    build = subprocess.run(
        [str(venv / "bin" / "colcon"), "build", "--event-handlers", "console_direct+",
         "--cmake-args", f"-DCMAKE_PROJECT_INCLUDE={repo_root / 'cmake' / 'drop_missing_includes.cmake'}",
         f"-DPython3_EXECUTABLE={venv / 'bin' / 'python'}", "-DBUILD_TESTING=OFF"],
        cwd=workspace, env=env, capture_output=True, text=True, timeout=800, stdin=subprocess.DEVNULL)
    assert build.returncode == 0, build.stdout[-4000:] + build.stderr[-2000:]

    prefix = workspace / "install" / "rimd_sim"
    share = prefix / "share" / "rimd_sim"
    assert {p.name for p in (share / "config").glob("*.yaml")} == \
        {p.name for p in (repo_root / "rimd_sim" / "config").glob("*.yaml")}
    assert not (share / "config" / "rimd.yaml").is_symlink(), "a plain install copies the files"
    assert (share / "launch" / "rig.launch.xml").is_file()
    assert (share / "package.xml").is_file()
    for executable in ["rimd", *(node.executable for node in NODES)]:
        assert os.access(prefix / "lib" / "rimd_sim" / executable, os.X_OK), executable
    assert os.access(prefix / "bin" / "rimd", os.X_OK)

    # A new shell: the venv's underlay, then the workspace's setup.sh; `rimd` comes from PATH.
    script = ('. "$1/install/setup.sh" && command -v rimd && rimd info --json')
    run = subprocess.run(["sh", "-c", script, "sh", str(workspace)], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert run.returncode == 0, run.stdout + run.stderr
    found, _, facts_text = run.stdout.partition("\n")
    assert Path(found) == prefix / "bin" / "rimd"
    facts = json.loads(facts_text)
    assert Path(facts["config_dir"]) == share / "config", facts
    assert Path(facts["rimd_sim_location"]).is_relative_to(prefix), facts
    assert facts["source_root"] is None, "the installed copy is not taken for a checkout"
