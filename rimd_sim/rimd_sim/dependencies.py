"""What rimd_sim needs at run time, in one table: pure data, read by ``setup.py`` by its path.

Every third-party module the package imports is a row of :data:`DEPENDENCIES`: the Python distribution that
provides it (with the range the wheel's metadata declares), the extra that brings it when it is not part of the
base install, and the rosdep key that installs it on a ROS 2 system (``None`` when no rosdep key provides a
recent enough version: the module is *pip-only* there, installed into a venv made with
``--system-site-packages``, docs/ros-install.md). ``package.xml`` declares the rosdep keys; the wheel declares
the distributions; tests check both against the package's imports.

Each rosdep key is a key of the public rosdep database (``rosdep/python.yaml`` and ``rosdep/base.yaml`` of
ros/rosdistro, and ``jazzy/distribution.yaml`` for the ROS packages) that resolves on Ubuntu 24.04 (noble), and
noble's apt version lies in the row's range (docs/ros-install.md lists those versions and what runs against
them). ``zstandard`` and ``lz4`` have no rosdep key;
``numba`` has one (``python3-numba``) but noble's is older than the range; ``pytest``'s (``python3-pytest``) is
7.4 on noble, below the plugin's range: those are pip-only.

Nothing here imports anything beyond the standard library: ``setup.py`` loads this file by its path, where the
package's dependencies are not installed yet (``tests/test_packaging.py`` checks it).
"""

from __future__ import annotations

import importlib.util
from typing import NamedTuple

__all__ = ["DEPENDENCIES", "DISTRIBUTION", "EXTRAS", "ROS_EXEC_DEPENDS", "Dependency", "distribution",
           "extras_require", "install_requires", "installed", "missing_extra", "pip_only"]


class Dependency(NamedTuple):
    """One third-party module the package imports and where it comes from."""

    module: str             #: the top-level module imported (``import yaml``)
    requirement: str        #: the pip requirement with its range (``PyYAML>=6.0``)
    extra: str | None       #: the extra that installs it (``None``: the base install)
    rosdep: str | None      #: the rosdep key for package.xml (``None``: pip-only on a ROS system)
    why: str                #: what uses it


#: The ROS 2 distribution the package targets, and the rimd_msgs distribution it needs (same version).
ROS_DISTRO = "jazzy"

#: The package's name for pip (``pip install 'rimd-sim[rerun]'``).
DISTRIBUTION = "rimd-sim"

DEPENDENCIES: tuple[Dependency, ...] = (
    # --- ROS 2 (from the ros-jazzy-* wheels with pip; from apt and rosdep on a ROS system) ---
    Dependency("rclpy", "ros-jazzy-rclpy[fastrtps]>=7.1,<8", None, "rclpy", "the nodes and clients"),
    Dependency("rcl_interfaces", "ros-jazzy-rcl-interfaces>=2.0,<3", None, "rcl_interfaces",
               "parameter services of the nodes"),
    Dependency("ament_index_python", "ros-jazzy-ament-index-python>=1.8,<2", None, "ament_index_python",
               "finding the installed share/rimd_sim"),
    Dependency("std_msgs", "ros-jazzy-std-msgs>=5.3,<6", None, "std_msgs", "message headers"),
    Dependency("std_srvs", "ros-jazzy-std-srvs>=5.3,<6", None, "std_srvs", "pause, resume, reset services"),
    Dependency("builtin_interfaces", "ros-jazzy-builtin-interfaces>=2.0,<3", None, "builtin_interfaces",
               "time stamps"),
    Dependency("diagnostic_msgs", "ros-jazzy-diagnostic-msgs>=5.3,<6", None, "diagnostic_msgs", "/diagnostics"),
    Dependency("rosgraph_msgs", "ros-jazzy-rosgraph-msgs>=2.0,<3", None, "rosgraph_msgs", "/clock"),
    Dependency("rimd_msgs", "ros-jazzy-rimd-msgs", None, "rimd_msgs", "the rig's messages and services"),
    # --- the physics, data and plots (base install) ---
    # The lower bounds are versions the package's tests ran with (docs/ros-install.md): Ubuntu 24.04's apt versions
    # for the rows with a rosdep key, the oldest tried for the pip-only ones (mcap before 1.5 has no Writer.flush).
    Dependency("numpy", "numpy>=1.26.4", None, "python3-numpy", "everything numeric"),
    Dependency("scipy", "scipy>=1.11.4", None, "python3-scipy", "fits, filters, the reference integrator"),
    Dependency("yaml", "PyYAML>=6.0.1", None, "python3-yaml", "configuration and parameter files"),
    Dependency("matplotlib", "matplotlib>=3.6.3", None, "python3-matplotlib", "the analyses' plots"),
    Dependency("tqdm", "tqdm>=4.66.2", None, "python3-tqdm", "progress of long analyses"),
    Dependency("numba", "numba>=0.60", None, None, "the compiled physics kernels"),
    Dependency("mcap", "mcap>=1.5,<2", None, None, "recordings (MCAP files)"),
    Dependency("zstandard", "zstandard>=0.22", None, None, "zstd-compressed recordings"),
    Dependency("lz4", "lz4>=4.0", None, None, "lz4-compressed recordings"),
    # --- extras ---
    Dependency("rerun", "rerun-sdk>=0.41,<0.42", "rerun", None, "the Rerun bridge and .rrd files"),
    Dependency("rerun_cli", "rerun-sdk>=0.41,<0.42", "rerun", None, "the Rerun viewer binary"),
    Dependency("pyarrow", "pyarrow>=18", "rerun", None, "columns logged to Rerun"),
    Dependency("foxglove", "foxglove-sdk>=0.30,<0.31", "foxglove", None, "the Foxglove WebSocket server"),
    Dependency("distributed", "distributed>=2024.1", "dask", None, "maps and sweeps on a Dask cluster"),
    Dependency("dask", "dask>=2024.1", "dask", None, "maps and sweeps on a Dask cluster"),
    Dependency("pytest", "pytest>=8.0", "testing", None, "the rimd_rig fixture (pytest plugin)"),
)

#: package.xml's exec_depends that no imported module explains: what a ROS install runs the package with.
ROS_EXEC_DEPENDS: dict[str, str] = {
    "ros2launch": "ros2 launch rimd_sim rig.launch.xml (launch/rig.launch.xml)",
}

#: The extras, each with what it adds; ``all`` is every one of them.
EXTRAS: dict[str, str] = {
    "rerun": "stream to the Rerun viewer and save .rrd files (rimd rig without --no-rerun)",
    "foxglove": "serve the rig to Foxglove (rimd rig --foxglove)",
    "dask": "run maps and sweeps on a Dask cluster (--scheduler dask)",
    "testing": "the pytest plugin and its fixture rimd_rig",
}


def install_requires(version: str) -> list[str]:
    """Return the base install's requirements (``version``: rimd_sim's, which rimd_msgs must equal)."""
    requirements: list[str] = []
    for dependency in DEPENDENCIES:
        if dependency.extra is None:
            requirement = dependency.requirement
            if dependency.module == "rimd_msgs":
                requirement = f"{requirement}=={version}"
            if requirement not in requirements:
                requirements.append(requirement)
    return requirements


def extras_require() -> dict[str, list[str]]:
    """Return every extra's requirements, and ``all``."""
    extras: dict[str, list[str]] = {name: [] for name in EXTRAS}
    for dependency in DEPENDENCIES:
        if dependency.extra is not None and dependency.requirement not in extras[dependency.extra]:
            extras[dependency.extra].append(dependency.requirement)
    extras["all"] = sorted({requirement for values in extras.values() for requirement in values})
    return extras


def distribution(dependency: Dependency) -> str:
    """The name of the distribution a row installs (``rerun-sdk`` of ``rerun-sdk>=0.41,<0.42``)."""
    name = dependency.requirement
    for stop in "[<>=~!; ":
        name = name.split(stop, 1)[0]
    return name


def pip_only() -> list[Dependency]:
    """The rows a ROS system installs with pip (no rosdep key), one per distribution, in table order."""
    seen: dict[str, Dependency] = {}
    for dependency in DEPENDENCIES:
        if dependency.rosdep is None:
            seen.setdefault(distribution(dependency), dependency)
    return list(seen.values())


def installed(module: str) -> bool:
    """Whether the top-level ``module`` can be imported here (found, without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):   # a parent that fails, or a module without a spec
        return False


def missing_extra(module: str, feature: str, alternative: str = "") -> str:
    """The message of a feature whose extra is not installed: what it needs and the pip command.

    ``missing_extra("rerun", "the Rerun bridge", "or run with --no-rerun")`` is "the Rerun bridge needs
    rerun-sdk: pip install 'rimd-sim[rerun]' (or run with --no-rerun)".

    Raises:
        KeyError: ``module`` is no row of an extra.
    """
    for dependency in DEPENDENCIES:
        if dependency.module == module and dependency.extra is not None:
            text = f"{feature} needs {distribution(dependency)}: pip install '{DISTRIBUTION}[{dependency.extra}]'"
            return f"{text} ({alternative})" if alternative else text
    raise KeyError(f"{module} is not the module of an extra")
