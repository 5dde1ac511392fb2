"""The package's layers hold: import-linter's contracts pass, and everything outside ``rimd_sim.ros`` runs
without ROS.

Hypotheses: (1) the contracts of pyproject.toml (each layer imports only the layers below it; rclpy and the
message packages only in ``rimd_sim.ros``) are kept, as ``lint-imports`` checks them; (2) every module outside
``rimd_sim.ros`` imports in an interpreter where rclpy and every ROS message package are made unimportable (a
finder placed first on ``sys.meta_path`` refuses them), so the physics, the recordings' readers, the analyses,
the viewers' mappings and the CLI's verbs work in an environment with no ROS at all.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIR = ROOT / "rimd_sim"

#: The top-level names a ROS install brings that the layers below rimd_sim.ros may not import.
ROS_PACKAGES = ("rclpy", "rimd_msgs", "std_msgs", "std_srvs", "builtin_interfaces", "diagnostic_msgs",
                "rosgraph_msgs", "rcl_interfaces", "rosidl_runtime_py", "rpyutils")

PROBE = textwrap.dedent("""
    import importlib, json, pkgutil, sys
    blocked = set(sys.argv[1].split(","))
    class Refuse:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in blocked:
                raise ImportError("blocked for this test: " + name)
    sys.meta_path.insert(0, Refuse())
    import rimd_sim
    imported, failed = [], {}
    for info in pkgutil.walk_packages(rimd_sim.__path__, "rimd_sim."):
        if info.name == "rimd_sim.ros" or info.name.startswith("rimd_sim.ros."):
            continue
        if info.name.endswith(".__main__"):
            continue  # runs the command when imported
        try:
            importlib.import_module(info.name)
            imported.append(info.name)
        except Exception as exc:  # every failure is reported, named
            failed[info.name] = f"{type(exc).__name__}: {exc}"
    leaked = sorted(m for m in sys.modules if m.split(".")[0] in blocked)
    print(json.dumps({"imported": imported, "failed": failed, "leaked": leaked}))
""")


def _clean_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(PACKAGE_DIR) + os.pathsep + env.get("PYTHONPATH", "")
    return env


@pytest.mark.process
def test_every_module_outside_the_ros_layer_imports_without_ros():
    proc = subprocess.run([sys.executable, "-c", PROBE, ",".join(ROS_PACKAGES)], capture_output=True, text=True,
                          env=_clean_env(), timeout=240, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report["failed"] == {}, report["failed"]
    assert report["leaked"] == []
    # The walk saw the layers (a walk that found nothing would pass the two checks above).
    layers = {name.split(".")[1] for name in report["imported"]}
    assert {"errors", "settings", "model", "instruments", "io", "runtime", "analysis", "viz", "cli"} <= layers
    assert len(report["imported"]) >= 80


@pytest.mark.process
def test_the_layer_contracts_are_kept():
    exe = Path(sys.executable).with_name("lint-imports")
    proc = subprocess.run([str(exe), str(ROOT / "pyproject.toml"), "--no-cache"], capture_output=True,
                          text=True, env=_clean_env(), timeout=240, cwd=PACKAGE_DIR)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout
    assert "ros-only-in-ros" in (ROOT / "pyproject.toml").read_text()
