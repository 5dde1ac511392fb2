"""The set-up script's failure paths, its Pythons, env.sh's venv, the lock check, and the test runner.

Hypotheses: a missing build tool stops the set-up at the step 'preflight' with one line that names the
tool and how to install it, and a non-zero exit status; Python 3.11 and 3.12 are accepted and any other is
refused naming both supported versions; a pythonX.Y that is not callable is taken from pyenv's versions; an
existing venv of another Python than PYTHON asks for is refused naming both; ``source env.sh`` without VENV
uses the venv ros_ws was built with; ``scripts/lock_requirements.py --check`` names every difference between
pip's resolution and the lock; ``scripts/run_tests.sh`` fails when pytest collects nothing (pytest exit
status 5).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

# External commands the preflight step itself needs besides the tools it checks (ls, grep, tail: pyenv's lookup).
SHELL_TOOLS = ("dirname", "date", "awk", "sed", "sort", "head", "cat", "tr", "sha256sum", "cut", "ls", "grep", "tail")
BUILD_TOOLS = ("cmake", "gcc", "g++", "make")
BASH = shutil.which("bash") or "/bin/bash"


def _base_python() -> str:
    """The real interpreter behind the venv (pyenv shims need pyenv on PATH)."""
    return os.path.realpath(getattr(sys, "_base_executable", sys.executable))


def _run_preflight(repo_root: Path, path_dir: Path, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [BASH, str(repo_root / "scripts" / "setup.sh"), "--only", "preflight"],
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


@pytest.mark.process
def test_preflight_passes_on_this_machine(repo_root, tmp_path):
    bin_dir = _tool_dir(tmp_path, (*SHELL_TOOLS, *BUILD_TOOLS))
    result = _run_preflight(repo_root, bin_dir)
    assert result.returncode == 0, result.stderr
    assert "set-up done" in result.stdout


@pytest.mark.process
@pytest.mark.parametrize(("missing", "hint"), [
    ("cmake", "apt-get install cmake"),
    ("g++", "apt-get install build-essential"),
])
def test_preflight_names_a_missing_tool(repo_root, tmp_path, missing, hint):
    tools = tuple(tool for tool in (*SHELL_TOOLS, *BUILD_TOOLS) if tool != missing)
    result = _run_preflight(repo_root, _tool_dir(tmp_path, tools))
    assert result.returncode != 0
    expected = f"set-up step 'preflight' failed: {missing} not found on PATH; install it with {hint}"
    assert expected in result.stderr
    assert "set-up done" not in result.stdout


def _fake_python(directory: Path, version: str, name: str | None = None) -> Path:
    """A stand-in interpreter that answers every ``-c`` with ``version`` (and succeeds)."""
    directory.mkdir(parents=True, exist_ok=True)
    fake = directory / (name or f"python{version}")
    fake.write_text(f"#!/bin/sh\necho {version}\n")
    fake.chmod(0o755)
    return fake


@pytest.mark.process
def test_preflight_refuses_another_python_naming_the_supported_ones(repo_root, tmp_path):
    fake = _fake_python(tmp_path / "py", "3.13")
    bin_dir = _tool_dir(tmp_path, (*SHELL_TOOLS, *BUILD_TOOLS))
    result = _run_preflight(repo_root, bin_dir, PYTHON=str(fake), VENV=str(tmp_path / "venv"))
    assert result.returncode != 0
    assert f"set-up step 'preflight' failed: {fake} is Python 3.13; the project supports Python 3.11 and 3.12" \
        in result.stderr


@pytest.mark.process
@pytest.mark.parametrize("version", ["3.11", "3.12"])
def test_preflight_accepts_python_3_11_and_3_12(repo_root, tmp_path, version):
    fake = _fake_python(tmp_path / "py", version)
    bin_dir = _tool_dir(tmp_path, (*SHELL_TOOLS, *BUILD_TOOLS))
    result = _run_preflight(repo_root, bin_dir, PYTHON=str(fake), VENV=str(tmp_path / "venv"))
    assert result.returncode == 0, result.stderr
    assert "set-up done" in result.stdout


@pytest.mark.process
def test_a_python_not_on_path_is_taken_from_pyenv(repo_root, tmp_path):
    pyenv_root = tmp_path / "pyenv"
    for version in ("3.12.1", "3.12.10", "3.11.7"):
        minor = version.rsplit(".", 1)[0]
        _fake_python(pyenv_root / "versions" / version / "bin", minor, name=f"python{minor}")
    bin_dir = _tool_dir(tmp_path, (*SHELL_TOOLS, *BUILD_TOOLS))
    result = _run_preflight(repo_root, bin_dir, PYTHON="python3.12", PYENV_ROOT=str(pyenv_root),
                            VENV=str(tmp_path / "venv"))
    assert result.returncode == 0, result.stderr
    # The newest 3.12 (sorted as versions: 3.12.10 after 3.12.1).
    assert f"using pyenv's {pyenv_root}/versions/3.12.10/bin/python3.12" in result.stderr
    missing = _run_preflight(repo_root, bin_dir, PYTHON="python3.10", PYENV_ROOT=str(pyenv_root),
                             VENV=str(tmp_path / "venv"))
    assert missing.returncode != 0
    assert "python3.10 not found on PATH nor in pyenv's versions; install Python 3.11 or 3.12" in missing.stderr


@pytest.mark.process
def test_a_venv_of_another_python_is_refused_naming_both(repo_root, tmp_path):
    venv = tmp_path / "venv"
    _fake_python(venv / "bin", "3.11", name="python")
    fake = _fake_python(tmp_path / "py", "3.12")
    bin_dir = _tool_dir(tmp_path, (*SHELL_TOOLS, *BUILD_TOOLS))
    result = subprocess.run(
        [BASH, str(repo_root / "scripts" / "setup.sh"), "--only", "preflight", "--only", "venv"],
        env={"PATH": str(bin_dir), "HOME": os.environ.get("HOME", "/tmp"), "PYTHON": str(fake), "VENV": str(venv)},
        capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert result.returncode != 0
    assert (f"set-up step 'venv' failed: {venv} is a Python 3.11 venv but PYTHON={fake} is Python 3.12"
            in result.stderr), result.stderr
    # PYTHON not given: the venv's own Python is the one asked for.
    same = subprocess.run(
        [BASH, str(repo_root / "scripts" / "setup.sh"), "--only", "preflight", "--only", "venv"],
        env={"PATH": str(bin_dir), "HOME": os.environ.get("HOME", "/tmp"), "VENV": str(venv)},
        capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert same.returncode == 0, same.stderr
    assert "venv present (Python 3.11)" in same.stdout


@pytest.mark.process
def test_unknown_step_is_a_usage_error(repo_root):
    result = subprocess.run(["bash", str(repo_root / "scripts" / "setup.sh"), "--only", "deploy"],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert "unknown step 'deploy'" in result.stderr


@pytest.mark.process
def test_run_tests_fails_when_no_test_is_collected(repo_root, tmp_path):
    result = subprocess.run(
        ["bash", str(repo_root / "scripts" / "run_tests.sh"), "-p", "no:cacheprovider",
         "-k", "this_selects_no_test_at_all", "--timeout", "120",
         str(repo_root / "tests" / "test_setup_scripts.py")],
        capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL,
        env={**os.environ, "RIMD_TEST_WORKERS": "0"},   # one process: the exit status is the same with workers
    )
    assert result.returncode == 1, result.stdout + result.stderr
    assert "pytest collected no test (exit status 5)" in result.stderr


def test_the_runner_starts_one_worker_per_free_core_plus_one(repo_root):
    spec = importlib.util.spec_from_file_location("test_workers", repo_root / "scripts" / "test_workers.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    # 2 cores: idle 3; one kept busy (scripts/test_under_load.sh) 2; both busy still 2; a rounding at half a core
    assert [module.workers(2, b) for b in (0.0, 0.3, 0.8, 1.2, 2.0, 3.5)] == [3, 3, 2, 2, 2, 2]
    assert module.workers(8, 0.0) == 9 and module.workers(1, 0.0) == 2
    # the machine's own reading: a fraction of its cores, and a count the runner can pass to pytest -n
    busy = module.busy_cores(0.05)
    assert 0.0 <= busy <= (os.cpu_count() or 1) + 1e-9
    cores = len(os.sched_getaffinity(0))
    assert 2 <= module.workers(cores, busy) <= cores + 1


@pytest.mark.process
def test_env_sh_works_in_a_strict_script_and_keeps_its_options(repo_root):
    # colcon's setup.sh reads the unset COLCON_TRACE: under `set -u` the caller would exit silently.
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


# ---- env.sh: the venv of the build --------------------------------------------------------------------------


def _fake_checkout(tmp_path: Path, repo_root: Path) -> tuple[Path, Path, Path]:
    """A checkout with env.sh, a built ros_ws (an empty setup.sh) and two venvs whose activate says which."""
    root = tmp_path / "checkout"
    (root / "ros_ws" / "install").mkdir(parents=True)
    shutil.copy(repo_root / "env.sh", root / "env.sh")
    (root / "ros_ws" / "install" / "setup.sh").write_text("")
    venvs = []
    for venv in (root / ".venv", tmp_path / "elsewhere"):
        (venv / "bin").mkdir(parents=True)
        (venv / "bin" / "activate").write_text(f'VIRTUAL_ENV="{venv}"; export VIRTUAL_ENV\n')
        venvs.append(venv)
    return root, venvs[0], venvs[1]


def _source_env(root: Path, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["bash", "-c", '. ./env.sh && echo "venv $VIRTUAL_ENV"'], cwd=root,
                          env={"PATH": os.environ["PATH"], "HOME": os.environ.get("HOME", "/tmp"), **env},
                          capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL)


@pytest.mark.process
def test_env_sh_uses_the_venv_ros_ws_was_built_with(repo_root, tmp_path):
    root, default, elsewhere = _fake_checkout(tmp_path, repo_root)
    (root / "ros_ws" / "install" / ".rimd-venv").write_text(f"{elsewhere}\n")   # VENV=elsewhere make setup
    built = _source_env(root)
    assert built.returncode == 0, built.stderr
    assert built.stdout.splitlines()[-1] == f"venv {elsewhere}" and "warning" not in built.stderr
    # VENV set wins, with the warning that ros_ws was built with another venv.
    chosen = _source_env(root, VENV=str(default))
    assert chosen.stdout.splitlines()[-1] == f"venv {default}"
    assert f"env.sh: warning: ros_ws was built with another venv ({elsewhere}), not {default}" in chosen.stderr
    # No record of the build's venv: .venv, the default.
    (root / "ros_ws" / "install" / ".rimd-venv").unlink()
    unrecorded = _source_env(root)
    assert unrecorded.stdout.splitlines()[-1] == f"venv {default}"


# ---- scripts/lock_requirements.py --check -------------------------------------------------------------------


def _lock_script():
    spec = importlib.util.spec_from_file_location("lock_requirements", Path(__file__).resolve().parent.parent
                                                  / "scripts" / "lock_requirements.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_lock_check_names_every_difference_from_pip_s_resolution():
    lock = _lock_script()
    locked = {"numpy": "2.4.6", "scipy": "1.17.1", "pyyaml": "6.0.3"}

    def report(**versions: str) -> dict:
        return {"install": [{"metadata": {"name": name, "version": version}} for name, version in versions.items()]}

    assert lock.report_problems(locked, report(numpy="2.4.6", scipy="1.17.1", PyYAML="6.0.3")) == []
    problems = lock.report_problems(locked, report(numpy="2.4.6", scipy="1.16.0", PyYAML="6.0.3", tomli="2.0"))
    assert problems == ["tomli==2.0 would be installed, the lock does not pin it",
                        "scipy: resolved 1.16.0, locked 1.17.1"]
    assert lock.report_problems(locked, report(numpy="2.4.6", scipy="1.17.1")) == [
        "pyyaml==6.0.3 is not part of the resolution"]


def test_the_lock_pins_every_line_exactly(repo_root):
    pins = _lock_script().pins(repo_root / "requirements.txt")
    assert pins["numpy"] and pins["ros-jazzy-rclpy"].startswith("7.")
    assert all(version and not set(version) & set("<>=~; ") for version in pins.values())
