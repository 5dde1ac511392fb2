"""Packaging of rimd_sim: an ament_python ROS 2 package (colcon build) with the `rimd` command.

Executables (console scripts) are installed to ``lib/rimd_sim/`` (see setup.cfg) so that a full ROS 2
install can ``ros2 run rimd_sim <name>`` them; ``env.sh`` also puts that directory on ``PATH`` for the
``rimd`` command. The node executables come from the registry of nodes, ``rimd_sim/ros/nodes/registry.py``,
read here by its path (pure data: nothing of ROS is imported at build time); a node added there is installed by
the next ``make setup``.

Installed with them (``share/rimd_sim``): package.xml, the configuration (``config/``) and the launch file
(``launch/rig.launch.xml``). A colcon build also installs ``bin/rimd``, a launcher of ``lib/rimd_sim/rimd``: colcon
puts ``install/rimd_sim/bin`` on PATH, so ``rimd`` works after ``source install/setup.bash``. A pip build
(:data:`PIP_BUILD_COMMANDS`) leaves it out (pip makes ``rimd`` itself) and declares the requirements instead.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE_NAME = "rimd_sim"
HERE = Path(__file__).resolve().parent


def _read_version() -> str:
    """Read ``__version__`` from the package without importing it (no ROS needed at build time)."""
    for line in (HERE / PACKAGE_NAME / "__init__.py").read_text(encoding="utf-8").splitlines():
        if line.startswith("__version__"):
            return line.split("=", 1)[1].strip().strip("\"'")
    raise RuntimeError("rimd_sim/__init__.py defines no __version__")


def _config_files() -> list[str]:
    """List the ROS parameter YAML files and the tables (CSV) of config/, relative to this file.

    The files live in the package (``rimd_sim/config``; the repository's ``config/`` is a link to it), so a copy
    of the package into another workspace builds; they are installed to ``share/rimd_sim/config``.
    """
    return sorted(str(path.relative_to(HERE)) for pattern in ("*.yaml", "*.csv")
                  for path in (HERE / "config").glob(pattern))


def _foxglove_layouts() -> list[str]:
    """The Foxglove layouts (``config/foxglove/*.json``), installed to ``share/rimd_sim/config/foxglove``."""
    return sorted(str(path.relative_to(HERE)) for path in (HERE / "config" / "foxglove").glob("*.json"))


def _launch_files() -> list[str]:
    """The launch files (``launch/*.launch.xml``), relative to this file; installed to ``share/rimd_sim/launch``."""
    return sorted(str(path.relative_to(HERE)) for path in (HERE / "launch").glob("*.launch.xml"))


def _load_by_path(name: str, *parts: str):
    """Load a pure-data module of the package by its path (the package itself may not be importable yet)."""
    path = HERE.joinpath(PACKAGE_NAME, *parts)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module   # NamedTuple and annotations look their module up while the class is made
    spec.loader.exec_module(module)
    return module


def _node_executables() -> list[str]:
    """``"executable = module:function"`` of every node of the registry (loaded by path, without the package)."""
    return _load_by_path("_rimd_node_registry", "ros", "nodes", "registry.py").console_scripts()


#: The commands of a PEP 517 build (pip install, python -m build): only these declare the dependencies.
PIP_BUILD_COMMANDS = {"bdist_wheel", "dist_info", "editable_wheel", "sdist"}


def _pip_build() -> bool:
    """Whether this run of setup.py is a pip (PEP 517) build: one of :data:`PIP_BUILD_COMMANDS` is asked."""
    return bool(PIP_BUILD_COMMANDS.intersection(sys.argv[1:]))


def _colcon_launchers() -> list[tuple[str, list[str]]]:
    """The data files of ``bin/``: the ``rimd`` launcher for a colcon build, none for a pip build.

    A colcon build runs ``setup.py develop`` or ``install`` (and reads the data files with ``--dry-run``); a pip
    build's installer writes ``rimd`` into its own ``bin``.
    """
    return [] if _pip_build() else [("bin", ["bin/rimd"])]


def _requirements(version: str) -> tuple[list[str], dict[str, list[str]]]:
    """Return ``install_requires`` and ``extras_require`` (rimd_sim/dependencies.py) for a pip build.

    A colcon build (``setup.py develop`` / ``install``) declares none: its dependencies are package.xml's, and
    console scripts of a develop install check the declared requirements against pip's distributions, which an
    apt ROS 2 install does not have (``ros-jazzy-rclpy`` would be "not found" while rclpy imports fine).
    """
    if not _pip_build():
        return ["setuptools"], {}
    dependencies = _load_by_path("_rimd_dependencies", "dependencies.py")
    return dependencies.install_requires(version), dependencies.extras_require()


# ros2-run compatible node executables, "name = module:function"; installed to lib/rimd_sim/.
NODE_EXECUTABLES: list[str] = _node_executables()
VERSION = _read_version()
INSTALL_REQUIRES, EXTRAS_REQUIRE = _requirements(VERSION)

setup(
    name=PACKAGE_NAME,
    version=VERSION,
    packages=find_packages(exclude=["test", "tests"]),
    package_data={"rimd_sim.ros.nodes": ["fastdds_profiles.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE_NAME]),
        ("share/" + PACKAGE_NAME, ["package.xml"]),
        ("share/" + PACKAGE_NAME + "/config", _config_files()),
        ("share/" + PACKAGE_NAME + "/config/foxglove", _foxglove_layouts()),
        ("share/" + PACKAGE_NAME + "/launch", _launch_files()),
        *_colcon_launchers(),
    ],
    install_requires=INSTALL_REQUIRES,
    extras_require=EXTRAS_REQUIRE,
    python_requires=">=3.11,<3.13",
    zip_safe=False,
    maintainer="RIMD twin maintainers",
    maintainer_email="maintainers@users.noreply.github.com",
    description="Digital twin of the RIMD vibro-impact test rig (physics core, ROS 2 nodes, rimd command).",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "rimd = rimd_sim.cli:entry",
            *NODE_EXECUTABLES,
        ],
        # The rimd_rig fixture for users' own test suites (rimd_sim/ros/testing.py, docs/testing.md).
        "pytest11": ["rimd_sim = rimd_sim.ros.testing"],
    },
)
