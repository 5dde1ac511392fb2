"""The built workspace and the venv are what the README promises.

Hypotheses: ``import rimd_sim`` runs the source tree (edits need no rebuild); every console script of
rimd_sim is installed where ``ros2 run`` looks; the ament index knows both packages; config/ is installed;
the venv holds exactly the pinned wheels of requirements.txt and only ROS 2 Jazzy.
"""

from __future__ import annotations

import importlib.metadata
import os
import re
from pathlib import Path

from ament_index_python.packages import get_package_prefix, get_package_share_directory

import rimd_sim


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
    pins = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            match = re.fullmatch(r"([A-Za-z0-9_.-]+)==([A-Za-z0-9_.+!-]+)", line)
            assert match, f"not an exact pin: {line!r}"
            pins[match.group(1).lower().replace("_", "-")] = match.group(2)
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
