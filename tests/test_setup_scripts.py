"""The set-up script's failure path and the test runner's handling of "no test collected".

Hypothesis: a missing build tool stops the set-up at the step 'preflight' with one line that names the
tool and how to install it, and a non-zero exit status; ``scripts/run_tests.sh`` fails when pytest
collects nothing (pytest exit status 5).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

# External commands the preflight step itself needs besides the tools it checks.
SHELL_TOOLS = ("dirname", "date", "awk", "sed", "sort", "head", "cat", "tr", "sha256sum", "cut")

pytestmark = pytest.mark.process  # every test here starts a process


def _base_python() -> str:
    """The real interpreter behind the venv (pyenv shims need pyenv on PATH)."""
    return os.path.realpath(getattr(sys, "_base_executable", sys.executable))


def _run_preflight(repo_root: Path, path_dir: Path, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [shutil.which("bash") or "/bin/bash", str(repo_root / "scripts" / "setup.sh"), "--only", "preflight"],
        env={"PATH": str(path_dir), "HOME": os.environ.get("HOME", "/tmp"), "PYTHON": _base_python(), **env},
        capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL,
    )


def _tool_dir(tmp_path: Path, tools: tuple[str, ...]) -> Path:
    """A directory of symlinks to ``tools``, to be the whole PATH."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in tools:
        location = shutil.which(tool)
        assert location is not None, f"{tool} is needed to run this test"
        (bin_dir / tool).symlink_to(location)
    return bin_dir


def test_preflight_passes_on_this_machine(repo_root, tmp_path):
    bin_dir = _tool_dir(tmp_path, (*SHELL_TOOLS, "cmake", "gcc", "g++", "make"))
    result = _run_preflight(repo_root, bin_dir)
    assert result.returncode == 0, result.stderr
    assert "set-up done" in result.stdout


@pytest.mark.parametrize(("missing", "hint"), [
    ("cmake", "apt-get install cmake"),
    ("g++", "apt-get install build-essential"),
])
def test_preflight_names_a_missing_tool(repo_root, tmp_path, missing, hint):
    tools = tuple(tool for tool in (*SHELL_TOOLS, "cmake", "gcc", "g++", "make") if tool != missing)
    result = _run_preflight(repo_root, _tool_dir(tmp_path, tools))
    assert result.returncode != 0
    expected = f"set-up step 'preflight' failed: {missing} not found on PATH; install it with {hint}"
    assert expected in result.stderr
    assert "set-up done" not in result.stdout


def test_preflight_refuses_another_python(repo_root, tmp_path):
    fake = tmp_path / "python3.12"
    fake.write_text("#!/bin/sh\necho 3.12\n")
    fake.chmod(0o755)
    bin_dir = _tool_dir(tmp_path, (*SHELL_TOOLS, "cmake", "gcc", "g++", "make"))
    result = _run_preflight(repo_root, bin_dir, PYTHON=str(fake))
    assert result.returncode != 0
    assert "set-up step 'preflight' failed:" in result.stderr and "is Python 3.12" in result.stderr


def test_unknown_step_is_a_usage_error(repo_root):
    result = subprocess.run(["bash", str(repo_root / "scripts" / "setup.sh"), "--only", "deploy"],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert "unknown step 'deploy'" in result.stderr


def test_run_tests_fails_when_no_test_is_collected(repo_root, tmp_path):
    result = subprocess.run(
        ["bash", str(repo_root / "scripts" / "run_tests.sh"), "-p", "no:cacheprovider",
         "-k", "this_selects_no_test_at_all", "--timeout", "120",
         str(repo_root / "tests" / "test_setup_scripts.py")],
        capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL,
    )
    assert result.returncode == 1, result.stdout + result.stderr
    assert "pytest collected no test (exit status 5)" in result.stderr


def test_env_sh_works_in_a_strict_script_and_keeps_its_options(repo_root):
    # colcon's setup.sh reads the unset COLCON_TRACE: under `set -u` the caller used to exit silently.
    script = (
        "set -euo pipefail\n"
        f"cd {repo_root}\n"
        "source ./env.sh\n"
        'echo "options $- pipefail $(set -o | grep -E "^pipefail" | tr -s " \\t" " ")"\n'
        'python -c "import rclpy, rimd_msgs.msg; print(\'imports ok\')"\n'
        "command -v rimd\n"
        'echo "$RIMD_SURELY_UNSET_VARIABLE"\n'
        "echo not reached\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "AMENT_PREFIX_PATH", "COLCON_TRACE")}
    result = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=60,
                            stdin=subprocess.DEVNULL, env=env)
    lines = result.stdout.splitlines()
    assert lines[0].startswith("options ") and "e" in lines[0].split()[1] and "u" in lines[0].split()[1], lines
    assert lines[0].endswith("pipefail on"), lines
    assert lines[1] == "imports ok" and lines[2].endswith("/rimd"), (result.stdout, result.stderr)
    # -u is back in force: the unset variable ends the script, as the caller asked.
    assert result.returncode == 1 and "RIMD_SURELY_UNSET_VARIABLE: unbound variable" in result.stderr
    assert "not reached" not in result.stdout
