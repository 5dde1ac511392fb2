"""The built workspace, the venv, and the package's declared dependencies are what the README promises.

Hypotheses: ``import rimd_sim`` runs the source tree (edits need no rebuild); every console script of
rimd_sim is installed where ``ros2 run`` looks; the ament index knows both packages; config/ and the launch file
are installed; the venv holds exactly the pinned wheels of requirements.txt and only ROS 2 Jazzy.

The dependencies (docs/ros-install.md): every third-party module the package imports is a row of
``rimd_sim/dependencies.py``; every row with a rosdep key is an ``<exec_depend>`` of package.xml (and nothing else
is, but what ROS needs to run the package); every row's requirement is in the wheel's metadata, and a colcon
build declares none (its dependencies are package.xml's).
"""

from __future__ import annotations

import ast
import email
import importlib.metadata
import os
import re
import runpy
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import setuptools
from ament_index_python.packages import get_package_prefix, get_package_share_directory

import rimd_sim
from rimd_sim import dependencies
from rimd_sim.dependencies import DEPENDENCIES, ROS_EXEC_DEPENDS


def test_rimd_sim_is_imported_from_the_source_tree(repo_root):
    assert Path(rimd_sim.__file__).resolve() == repo_root / "rimd_sim" / "rimd_sim" / "__init__.py"


def test_rimd_msgs_comes_from_the_colcon_workspace(repo_root):
    import rimd_msgs

    assert Path(rimd_msgs.__file__).is_relative_to(repo_root / "ros_ws" / "install" / "rimd_msgs")


def test_every_console_script_is_installed_for_ros2_run():
    entry_points = importlib.metadata.distribution("rimd_sim").entry_points
    scripts = [ep for ep in entry_points if ep.group == "console_scripts"]
    assert "rimd" in {ep.name for ep in scripts}
    lib_dir = Path(get_package_prefix("rimd_sim")) / "lib" / "rimd_sim"
    for entry_point in scripts:
        executable = lib_dir / entry_point.name
        assert os.access(executable, os.X_OK), f"{entry_point.name} is not installed in {lib_dir}"


def test_ament_index_and_installed_files(repo_root):
    share = Path(get_package_share_directory("rimd_sim"))
    assert (share / "package.xml").is_file()
    assert (share / "config").is_dir()
    installed = {path.name for path in (share / "config").glob("*.yaml")}
    assert installed == {path.name for path in (repo_root / "config").glob("*.yaml")}
    assert (share / "launch" / "rig.launch.xml").is_file()
    # The launcher colcon puts on PATH (install/rimd_sim/bin), beside the console scripts of lib/rimd_sim.
    assert os.access(Path(get_package_prefix("rimd_sim")) / "bin" / "rimd", os.X_OK)
    msgs_share = Path(get_package_share_directory("rimd_msgs"))
    assert (msgs_share / "msg" / "SampleBlock.msg").is_file()


def test_workspace_links_are_relative(repo_root):
    for name in ("rimd_sim", "rimd_msgs"):
        link = repo_root / "ros_ws" / "src" / name
        assert link.is_symlink() and os.readlink(link) == f"../../{name}"
    # The configuration lives in the package (a copy of rimd_sim/ into another workspace takes it along); the
    # repository's config/ is a link to it.
    assert (repo_root / "rimd_sim" / "config").is_dir() and not (repo_root / "rimd_sim" / "config").is_symlink()
    assert os.readlink(repo_root / "config") == "rimd_sim/config"


def _pins(path: Path) -> dict[str, str]:
    """The exact pins of the lock that apply to this Python (a line may end with a ``python_version`` marker)."""
    from packaging.markers import Marker

    pins = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            match = re.fullmatch(r"([A-Za-z0-9_.-]+)==([A-Za-z0-9_.+!-]+)(?:; (python_version [<>=]+ \"3\.\d+\"))?",
                                 line)
            assert match, f"not an exact pin: {line!r}"
            if match.group(3) is None or Marker(match.group(3)).evaluate():
                name = match.group(1).lower().replace("_", "-")
                assert name not in pins, f"{name} pinned twice for this Python"
                pins[name] = match.group(2)
    return pins


def test_requirements_pin_every_wheel_and_only_jazzy(repo_root):
    pins = _pins(repo_root / "requirements.txt")
    assert not [name for name in pins if name.startswith("ros-kilted-")]
    assert pins["ros-jazzy-rclpy"].startswith("7.")
    assert pins["ros-rclpy"] == pins["ros-jazzy-rclpy"], "unprefixed ros-* must be the Jazzy versions"
    for line in (repo_root / "requirements.in").read_text(encoding="utf-8").splitlines():
        name = line.split("#", 1)[0].strip()
        if name.lower().startswith("ros-"):
            assert name.lower().startswith("ros-jazzy-"), f"requirements.in: {name} is not a Jazzy wheel"
        if name:
            base = re.split(r"[\[<>=~!; ]", name, maxsplit=1)[0].lower().replace("_", "-")
            assert base in pins, f"{base} of requirements.in is not pinned in requirements.txt"


def test_venv_holds_the_pinned_versions(repo_root):
    pins = _pins(repo_root / "requirements.txt")
    installed = {}
    for dist in importlib.metadata.distributions():
        if (dist.read_text("INSTALLER") or "").strip() == "pip":
            installed[dist.metadata["Name"].lower().replace("_", "-")] = dist.version
    wrong = {name: (version, installed.get(name))
             for name, version in pins.items() if installed.get(name) != version}
    assert not wrong, f"pinned vs installed: {wrong}"
    assert not [name for name in installed if name.startswith("ros-kilted-")]


# ---- the dependencies ------------------------------------------------------------------------------------------

PACKAGE_DIR = Path(rimd_sim.__file__).resolve().parent


#: A string that is a ROS type's name (``"std_msgs/msg/Header"``): its package is imported by that name (importlib).
ROS_TYPE_NAME = re.compile(r"([a-z][a-z0-9_]*)/(?:msg|srv)/[A-Z]\w*")


def _top_level_imports(path: Path, *, type_names: bool = False) -> set[str]:
    """Top-level modules of the import statements of ``path`` (and, with ``type_names``, of ROS type names)."""
    modules = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            modules.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            modules.add(node.module.split(".")[0])
        elif type_names and isinstance(node, ast.Constant) and isinstance(node.value, str):
            match = ROS_TYPE_NAME.fullmatch(node.value)
            if match:
                modules.add(match.group(1))
    return modules


def _third_party_imports() -> dict[str, list[str]]:
    """Top-level modules imported by the package, outside the standard library and the package: module -> files."""
    found: dict[str, list[str]] = {}
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        modules = _top_level_imports(path, type_names=True)
        for module in modules - set(sys.stdlib_module_names) - {"rimd_sim", "__future__"}:
            found.setdefault(module, []).append(str(path.relative_to(PACKAGE_DIR)))
    return found


def test_every_third_party_import_is_a_row_of_the_dependency_table():
    imported = _third_party_imports()
    assert {"numpy", "rclpy", "rerun", "yaml"} <= set(imported), "the walk finds the package's imports"
    rows = {d.module for d in DEPENDENCIES}
    missing = {module: files for module, files in imported.items() if module not in rows}
    assert not missing, f"imported but not in rimd_sim/dependencies.py: {missing}"
    # A row nobody imports is stale, unless it comes with an imported row of its extra (dask with distributed).
    imported_extras = {d.extra for d in DEPENDENCIES if d.module in imported and d.extra is not None}
    stale = [d.module for d in DEPENDENCIES if d.module not in imported and d.extra not in imported_extras]
    assert not stale, f"rows of rimd_sim/dependencies.py that no module imports: {stale}"


def test_the_dependency_table_imports_only_the_standard_library():
    """setup.py loads it by its path, where nothing of the package (nor its dependencies) may be importable."""
    modules = _top_level_imports(PACKAGE_DIR / "dependencies.py") - {"__future__"}
    assert modules <= set(sys.stdlib_module_names), modules


def _manifest(repo_root: Path, package: str) -> ET.Element:
    return ET.parse(repo_root / package / "package.xml").getroot()


def test_package_xml_exec_depends_on_every_rosdep_key_and_nothing_else(repo_root):
    root = _manifest(repo_root, "rimd_sim")
    exec_depends = [element.text for element in root.iter("exec_depend")]
    assert len(exec_depends) == len(set(exec_depends)), "an exec_depend twice"
    wanted = {d.rosdep for d in DEPENDENCIES if d.rosdep is not None} | set(ROS_EXEC_DEPENDS)
    assert set(exec_depends) == wanted, (
        f"missing: {sorted(wanted - set(exec_depends))}, unexplained: {sorted(set(exec_depends) - wanted)}")
    assert not list(root.iter("depend")) and not list(root.iter("build_depend")), "an ament_python package"
    assert root.findtext("export/build_type") == "ament_python"
    assert root.findtext("version") == rimd_sim.__version__ == _manifest(repo_root, "rimd_msgs").findtext("version")


def test_pip_only_rows_are_what_the_ros_install_page_lists(repo_root):
    """docs/ros-install.md's list of the pip-only packages is generated from the table (scripts/gen_docs.py)."""
    text = (repo_root / "docs" / "ros-install.md").read_text(encoding="utf-8")
    begin, end = "<!-- BEGIN GENERATED: pip-only -->", "<!-- END GENERATED: pip-only -->"
    assert begin in text and end in text
    section = text[text.index(begin):text.index(end)]
    listed = set(re.findall(r"^\| `([^`]+)` \|", section, flags=re.MULTILINE))
    assert listed == {d.requirement for d in dependencies.pip_only()}


def _setup_arguments(repo_root: Path, monkeypatch: pytest.MonkeyPatch, *argv: str) -> dict:
    """What setup.py passes to setuptools.setup() when run as ``setup.py ARGV`` (nothing is built)."""
    captured: dict = {}
    monkeypatch.setattr(setuptools, "setup", lambda **kwargs: captured.update(kwargs))
    monkeypatch.setattr(sys, "argv", ["setup.py", *argv])
    monkeypatch.chdir(repo_root / "rimd_sim")
    loaded = ("_rimd_node_registry", "_rimd_dependencies")
    try:
        runpy.run_path(str(repo_root / "rimd_sim" / "setup.py"), run_name="__main__")
    finally:
        for name in loaded:
            sys.modules.pop(name, None)
    return captured


@pytest.mark.parametrize("command", ["bdist_wheel", "dist_info", "editable_wheel", "sdist"])
def test_a_pip_build_declares_every_row_and_installs_no_launcher(repo_root, monkeypatch, command):
    arguments = _setup_arguments(repo_root, monkeypatch, command)
    version = rimd_sim.__version__
    assert arguments["version"] == version
    assert arguments["install_requires"] == dependencies.install_requires(version)
    assert arguments["extras_require"] == dependencies.extras_require()
    declared = {*arguments["install_requires"], *(r for rs in arguments["extras_require"].values() for r in rs)}
    for row in DEPENDENCIES:
        wanted = row.requirement + (f"=={version}" if row.module == "rimd_msgs" else "")
        assert wanted in (arguments["install_requires"] if row.extra is None
                          else arguments["extras_require"][row.extra]), row
        assert wanted in declared
    data = dict(arguments["data_files"])
    assert "bin" not in data, "pip makes rimd itself"
    assert data["share/rimd_sim/launch"] == ["launch/rig.launch.xml"]


@pytest.mark.parametrize("argv", [("--dry-run",), ("develop", "--editable"), ("egg_info", "build", "install")])
def test_a_colcon_build_declares_no_requirement_and_installs_the_launcher(repo_root, monkeypatch, argv):
    """A colcon build reads the data files (``--dry-run``), then runs ``develop`` (symlink install) or ``install``."""
    arguments = _setup_arguments(repo_root, monkeypatch, *argv)
    assert arguments["install_requires"] == ["setuptools"] and arguments["extras_require"] == {}
    data = dict(arguments["data_files"])
    assert data["bin"] == ["bin/rimd"] and os.access(repo_root / "rimd_sim" / "bin" / "rimd", os.X_OK)
    assert data["share/rimd_sim/launch"] == ["launch/rig.launch.xml"]
    assert sorted(Path(f).name for f in data["share/rimd_sim/config"]) == sorted(
        p.name for pattern in ("*.yaml", "*.csv") for p in (repo_root / "rimd_sim" / "config").glob(pattern))


#: setup.py run as for a pip build (its command line says ``dist_info``), and setuptools writing the metadata with
#: ``egg_info`` (``dist_info`` itself needs the ``wheel`` package, which pip's isolated build has and the venv has not).
EGG_INFO_AS_A_PIP_BUILD = """
import runpy, sys, setuptools
real_setup, out = setuptools.setup, sys.argv[1]
setuptools.setup = lambda **kwargs: real_setup(**kwargs, script_args=["-q", "egg_info", "--egg-base", out])
sys.argv = ["setup.py", "dist_info"]
runpy.run_path("setup.py", run_name="__main__")
"""


def _requires_txt(path: Path) -> dict[str | None, set[str]]:
    """``requires.txt`` of an egg-info: the base requirements (key None) and each extra's."""
    sections: dict[str | None, set[str]] = {None: set()}
    current = None
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("[") and line.endswith("]"):
            current = line[1:-1]
            sections[current] = set()
        elif line.strip():
            sections[current].add(line.strip())
    return sections


@pytest.mark.process
def test_the_wheel_metadata_requires_every_row(repo_root, tmp_path):
    """The metadata setuptools writes for a pip build, from a copy of the package (nothing written in the tree)."""
    copy = tmp_path / "rimd_sim"
    shutil.copytree(repo_root / "rimd_sim", copy, symlinks=True, ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "out").mkdir()
    result = subprocess.run([sys.executable, "-c", EGG_INFO_AS_A_PIP_BUILD, str(tmp_path / "out")],
                            cwd=copy, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr
    (egg_info,) = (tmp_path / "out").glob("rimd_sim.egg-info")
    from packaging.requirements import Requirement

    requires = _requires_txt(egg_info / "requires.txt")
    version = rimd_sim.__version__
    for row in DEPENDENCIES:
        wanted = Requirement(row.requirement + (f"=={version}" if row.module == "rimd_msgs" else ""))
        assert wanted in {Requirement(r) for r in requires[row.extra]}, (
            f"{wanted} ({row.extra or 'base'}) is not in the metadata: {requires}")
    assert set(requires) == {None, *dependencies.EXTRAS, "all"}
    metadata = email.message_from_string((egg_info / "PKG-INFO").read_text(encoding="utf-8"))
    assert set(metadata.get_all("Provides-Extra")) == {*dependencies.EXTRAS, "all"}
    assert metadata["Version"] == version
