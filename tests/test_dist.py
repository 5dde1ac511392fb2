"""The pip distribution: how make dist packs the wheels, how make test-dist checks them, and the CI recipe's docs.

The wheels themselves are built and run from outside by ``make test-dist`` (scripts/checks.py; ``.ci/run``
runs it): building them takes minutes, so no test here needs dist/. Here, in process: the rimd_msgs wheel's
layout (the registry's: the package at the root, the install prefix as wheel data), RECORD, the constraints of a
build venv, the checks make test-dist applies (each shown to fail on a bad wheel), and the recipe of
docs/testing.md: the script and the workflow are the files of docs/ci, verbatim, and name the same commands.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest
import yaml

import rimd_sim

ROOT = Path(__file__).resolve().parent.parent
TESTING_MD = ROOT / "docs" / "testing.md"
RECIPE = ROOT / "docs" / "ci" / "run-daq-tests.sh"
WORKFLOW = ROOT / "docs" / "ci" / "daq-tests.yml"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"_scripts_{name}", ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module   # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


build_dist = _load("build_dist")
checks = _load("test_dist")   # scripts/test_dist.py: what make test-dist checks and runs


# ---- the rimd_msgs wheel's layout ----------------------------------------------------------------------------
def _fake_stage(root: Path, python: str = "3.11") -> Path:
    """A staging prefix as CMake installs rimd_msgs: the package, its egg-info and caches, libs, share, include."""
    stage = root / "stage"
    site = stage / "lib" / f"python{python}" / "site-packages"
    files = {
        site / "rimd_msgs" / "__init__.py": "",
        site / "rimd_msgs" / "msg" / "__init__.py": "from ._sample_block import SampleBlock\n",
        site / "rimd_msgs" / "msg" / "__pycache__" / "__init__.cpython-311.pyc": "compiled",
        site / "rimd_msgs" / "rimd_msgs_s__rosidl_typesupport_c.so": "elf",
        site / "rimd_msgs-0.4.0-py3.11.egg-info" / "PKG-INFO": "Name: rimd_msgs\n",
        stage / "lib" / "librimd_msgs__rosidl_generator_c.so": "elf",
        stage / "share" / "ament_index" / "resource_index" / "packages" / "rimd_msgs": "",
        stage / "share" / "ament_index" / "resource_index" / "parent_prefix_path" / "rimd_msgs": "/build/venv",
        stage / "share" / "rimd_msgs" / "msg" / "SampleBlock.msg": "uint64 first_index\n",
        stage / "include" / "rimd_msgs" / "rimd_msgs" / "msg" / "sample_block.h": "/* header */\n",
    }
    for path, text in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return stage


def test_the_package_goes_to_the_wheel_root_and_the_rest_of_the_prefix_to_its_data(tmp_path):
    stage = _fake_stage(tmp_path)
    data = "ros_jazzy_rimd_msgs-0.4.0.data"
    names = {arcname for arcname, _ in build_dist.msgs_wheel_files(stage, "3.11", data)}
    assert names == {
        "rimd_msgs/__init__.py", "rimd_msgs/msg/__init__.py", "rimd_msgs/rimd_msgs_s__rosidl_typesupport_c.so",
        f"{data}/data/lib/librimd_msgs__rosidl_generator_c.so",
        f"{data}/data/share/ament_index/resource_index/packages/rimd_msgs",
        f"{data}/data/share/ament_index/resource_index/parent_prefix_path/rimd_msgs",
        f"{data}/data/share/rimd_msgs/msg/SampleBlock.msg",
        f"{data}/data/include/rimd_msgs/rimd_msgs/msg/sample_block.h",
    }   # no __pycache__, no egg-info, nothing of lib/python3.11 in the data


def test_a_stray_file_in_the_staged_site_packages_stops_the_build(tmp_path):
    stage = _fake_stage(tmp_path)
    (stage / "lib" / "python3.11" / "site-packages" / "other.py").write_text("")
    with pytest.raises(build_dist.BuildError, match="other.py"):
        build_dist.msgs_wheel_files(stage, "3.11", "x.data")


def test_the_parent_prefix_path_of_the_build_machine_is_emptied(tmp_path):
    stage = _fake_stage(tmp_path)
    build_dist.fix_staged_text(stage)
    assert (stage / "share/ament_index/resource_index/parent_prefix_path/rimd_msgs").read_text() == ""


def test_the_wheel_record_lists_every_file_with_its_hash(tmp_path):
    source = tmp_path / "a.py"
    source.write_text("x = 1\n")
    wheel = tmp_path / "demo-1.0-py3-none-any.whl"
    build_dist.write_wheel(wheel, [("demo/a.py", source)], {"demo-1.0.dist-info/METADATA": "Name: demo\n",
                                                             "demo-1.0.dist-info/WHEEL": "Wheel-Version: 1.0\n"})
    files = checks.wheel_files(wheel)
    assert set(files) == {"demo/a.py", "demo-1.0.dist-info/METADATA", "demo-1.0.dist-info/WHEEL",
                          "demo-1.0.dist-info/RECORD"}
    assert checks.record_problems(files) == []
    files["demo/a.py"] = b"x = 2\n"   # a file changed after RECORD was written
    assert checks.record_problems(files) == ["RECORD: wrong hash or size of demo/a.py"]


def test_the_rimd_msgs_wheel_requires_the_ros_packages_it_was_built_against_with_the_same_minor():
    assert build_dist.msgs_requirements({"std_msgs": "5.3.6", "rosidl_default_runtime": "1.6.0"}) == [
        "ros-jazzy-rosidl-default-runtime~=1.6.0", "ros-jazzy-std-msgs~=5.3.6"]


def test_a_build_venv_of_another_python_than_the_locks_drops_its_pip_and_setuptools_pins():
    lock = "# header\npip==23.2.1\nsetuptools==65.5.0\nnumpy==2.4.6  # comment\n"
    assert build_dist.build_constraints(lock, "3.11") == "pip==23.2.1\nsetuptools==65.5.0\nnumpy==2.4.6\n"
    assert build_dist.build_constraints(lock, "3.12") == "numpy==2.4.6\n"


# ---- the checks of make test-dist fail on a bad wheel --------------------------------------------------------
def _sim_wheel(tmp_path: Path, requires: list[str]) -> Path:
    version = rimd_sim.__version__
    wheel = tmp_path / f"rimd_sim-{version}-py3-none-any.whl"
    dist_info = f"rimd_sim-{version}.dist-info"
    data = tmp_path / "data"
    data.write_text("x")
    files = [(f"rimd_sim-{version}.data/data/{name}", data) for name in checks.sim_data_files()]
    metadata = "\n".join(["Name: rimd_sim", f"Version: {version}", "Provides-Extra: testing",
                          *(f"Requires-Dist: {r}" for r in requires)]) + "\n"
    build_dist.write_wheel(wheel, files, {
        f"{dist_info}/METADATA": metadata,
        f"{dist_info}/entry_points.txt": "[console_scripts]\nrimd = rimd_sim.cli:entry\n\n[pytest11]\nrimd_sim = x\n"})
    return wheel


def test_the_rimd_sim_wheel_check_names_a_development_tool_among_its_requirements(tmp_path):
    version = rimd_sim.__version__
    good = [f"ros-jazzy-rimd-msgs=={version}", "numpy>=1.26", 'pytest>=8.0; extra == "testing"']
    assert checks.sim_wheel_problems(_sim_wheel(tmp_path, good), version) == []
    problems = checks.sim_wheel_problems(_sim_wheel(tmp_path, [*good, "ruff>=0.5", "pytest>=8.0"]), version)
    assert problems == ["METADATA: requires a development tool: ruff>=0.5",
                        "METADATA: requires a development tool: pytest>=8.0"]


def test_the_rimd_msgs_wheel_check_names_what_is_missing(tmp_path):
    version = rimd_sim.__version__
    source = tmp_path / "init.py"
    source.write_text("")
    wheel = tmp_path / f"ros_jazzy_rimd_msgs-{version}-cp311-cp311-manylinux_2_28_x86_64.whl"
    dist_info = f"ros_jazzy_rimd_msgs-{version}.dist-info"
    build_dist.write_wheel(wheel, [("rimd_msgs/__init__.py", source), ("rimd_msgs/__pycache__/x.pyc", source)], {
        f"{dist_info}/METADATA": f"Name: ros-jazzy-rimd-msgs\nVersion: {version}\n",
        f"{dist_info}/WHEEL": "Root-Is-Purelib: true\nTag: cp311-cp311-manylinux_2_28_x86_64\n"})
    problems = checks.msgs_wheel_problems(wheel, version, "3.11")
    assert "WHEEL: Root-Is-Purelib is not false (a platform wheel: site-packages is platlib)" in problems
    assert "METADATA: does not require ros-jazzy-std-msgs" in problems
    assert f"missing ros_jazzy_rimd_msgs-{version}.data/data/lib/librimd_msgs__rosidl_typesupport_c.so" in problems
    assert "missing rimd_msgs/rimd_msgs_s__rosidl_typesupport_fastrtps_c.so" in problems
    assert any(p.startswith("unexpected rimd_msgs/__pycache__/x.pyc") for p in problems)
    assert checks.msgs_wheel_problems(wheel, version, "3.12")[0].endswith("-cp312-cp312-<platform>.whl")


def test_the_steps_run_without_the_callers_project_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("PYTHONPATH", str(ROOT / "rimd_sim"))
    monkeypatch.setenv("AMENT_PREFIX_PATH", "/some/venv")
    monkeypatch.setenv("VIRTUAL_ENV", "/some/venv")
    monkeypatch.setenv("LD_LIBRARY_PATH", "/some/venv/lib")
    monkeypatch.setenv("PIP_FIND_LINKS", "/opt/wheels")
    monkeypatch.setenv("PATH", f"{ROOT}/ros_ws/install/rimd_sim/lib/rimd_sim:/some/venv/bin:/usr/bin:/bin")
    env = checks.clean_environment(tmp_path / "venv")
    assert env["PATH"] == f"{tmp_path / 'venv' / 'bin'}:/usr/bin:/bin"
    assert env["PIP_FIND_LINKS"] == "/opt/wheels"
    assert not {"PYTHONPATH", "AMENT_PREFIX_PATH", "VIRTUAL_ENV", "LD_LIBRARY_PATH"} & set(env)


# ---- the CI recipe of docs/testing.md ------------------------------------------------------------------------
def _embedded(name: str, language: str) -> str:
    match = re.search(rf"<!-- BEGIN EXAMPLE: {name} -->\n```{language}\n(.*?)```\n<!-- END EXAMPLE: {name} -->",
                      TESTING_MD.read_text(), re.S)
    assert match, f"docs/testing.md has no example {name}"
    return match.group(1)


def test_the_documented_recipe_and_workflow_are_the_files_make_test_dist_runs():
    assert _embedded("ci-script", "sh") == RECIPE.read_text()
    assert _embedded("ci-workflow", "yaml") == WORKFLOW.read_text()


def _recipe_commands() -> list[str]:
    """The script's commands as the workflow writes them (its variables at their default values)."""
    values = {'"$RIMD_VENV': ".venv-rimd", '"$RIMD_WHEELS"': "wheels", "$RIMD_VERSION": rimd_sim.__version__,
              '"$PYTHON"': "python", '"$@"': "tests"}
    commands = []
    for line in RECIPE.read_text().splitlines():
        line = line.split(" || ", 1)[-1]
        if line.startswith(('"$RIMD_VENV/bin/', '"$PYTHON"')):
            for variable, value in values.items():
                line = line.replace(variable, value)
            commands.append(line.replace('/bin/python"', "/bin/python").replace('/bin/rimd"', "/bin/rimd")
                            .replace('.venv-rimd"', ".venv-rimd"))
    return commands


def test_the_workflow_is_valid_and_runs_the_scripts_commands():
    workflow = yaml.safe_load(WORKFLOW.read_text())
    (job,) = workflow["jobs"].values()
    assert job["runs-on"] == "ubuntu-24.04"
    assert job["strategy"]["matrix"]["python"] == list(build_dist.DEFAULT_PYTHONS)
    setup = [step for step in job["steps"] if step.get("uses", "").startswith("actions/setup-python@")]
    assert setup and setup[0]["with"]["python-version"] == "${{ matrix.python }}"
    run = [line.strip() for step in job["steps"] for line in step.get("run", "").splitlines()]
    commands = _recipe_commands()
    assert commands == [
        "python -m venv .venv-rimd",
        f'.venv-rimd/bin/python -m pip install --find-links wheels "rimd_sim[testing]=={rimd_sim.__version__}"',
        ".venv-rimd/bin/rimd info", ".venv-rimd/bin/rimd warmup", ".venv-rimd/bin/python -m pytest tests"]
    assert [line for line in run if line in commands] == commands
    assert any(f"gh release download v{rimd_sim.__version__} " in line for line in run)


def test_the_recipe_installs_this_version():
    assert f'RIMD_VERSION="${{RIMD_VERSION:-{rimd_sim.__version__}}}"' in RECIPE.read_text()


def test_the_rimd_msgs_wheel_takes_its_version_and_run_dependencies_from_package_xml():
    """Its version is package.xml's, which is rimd_sim's (rimd_sim requires exactly it); it requires every run
    dependency of package.xml."""
    info = build_dist.package_xml(ROOT / "rimd_msgs" / "package.xml")
    assert info["version"] == rimd_sim.__version__
    assert info["license"] and info["maintainer_email"]
    assert set(info["depends"]) <= set(build_dist.MSGS_RUNTIME_PACKAGES)


@pytest.mark.process
def test_the_project_venv_holds_the_lock_as_make_dist_reads_it():
    """The project venv builds the interfaces for `make dist` when it holds every pin of the lock, markers
    evaluated (setuptools is pinned per Python), instead of a build venv installed for it."""
    version = "{}.{}".format(*sys.version_info[:2])
    assert build_dist.venv_matches_lock(Path(sys.prefix), version) is None
