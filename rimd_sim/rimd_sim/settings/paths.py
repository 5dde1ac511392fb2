"""Where the project's files are: the repository's config/ first, then the installed share directory.

The installed ``share/rimd_sim`` is found through the ament index (``AMENT_PREFIX_PATH``: a colcon workspace or
a ROS 2 install), else under the interpreter's prefix or the prefix this package is installed in: a plain ``pip
install`` of the wheel into a venv puts it in ``<venv>/share/rimd_sim`` and sets no environment variable (the ROS
wheels' bootstrapper sets only ``LD_LIBRARY_PATH``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

PACKAGE_NAME = "rimd_sim"


def source_root() -> Path | None:
    """Return the repository root when this package runs from a source checkout, else None.

    The checkout is recognised by ``<root>/rimd_sim/package.xml`` next to ``<root>/rimd_sim/rimd_sim``
    (this package, with symlinks resolved, as colcon --symlink-install and editable installs leave it).
    """
    package_dir = Path(__file__).resolve().parent.parent  # rimd_sim/ (this file is rimd_sim/settings/paths.py)
    root = package_dir.parent.parent
    if (package_dir.parent / "package.xml").is_file() and (root / "rimd_msgs").is_dir():
        return root
    return None


def _ament_share_dir() -> Path | None:
    """Return ``share/rimd_sim`` of the prefix on AMENT_PREFIX_PATH that has the package, or None."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:
        return None
    try:
        return Path(get_package_share_directory(PACKAGE_NAME))
    except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset or empty (a plain pip venv)
        return None


def install_prefixes() -> list[Path]:
    """Return the prefixes a pip install may have put ``share/rimd_sim`` in.

    The interpreter's (a venv), then the one above the site-packages this package is in
    (``<prefix>/lib/python3.X/site-packages``: ``pip install --prefix`` or ``--user``, Debian's ``dist-packages``).
    """
    prefixes = [Path(sys.prefix)]
    site = Path(__file__).resolve().parent.parent.parent  # <site>/rimd_sim/settings/paths.py
    if site.name in ("site-packages", "dist-packages"):
        prefixes.append(site.parent.parent.parent)
    unique: list[Path] = []
    for prefix in prefixes:
        if prefix not in unique:
            unique.append(prefix)
    return unique


def installed_share_dir() -> Path | None:
    """Return the installed ``share/rimd_sim``: the ament index's, else a pip install's (install_prefixes), or None.

    A pip install's is recognised by the package.xml the wheel installs there.
    """
    share = _ament_share_dir()
    if share is not None:
        return share
    for prefix in install_prefixes():
        candidate = prefix / "share" / PACKAGE_NAME
        if (candidate / "package.xml").is_file():
            return candidate
    return None


def config_dirs() -> list[Path]:
    """Where shipped configurations are looked for, in order.

    ``$RIMD_CONFIG_DIR`` when set, the source checkout's ``config/`` when this package runs from one, the installed
    ``share/rimd_sim/config``. Only these: a ``config/`` directory that happens to be above the package (a lab's
    own repository holding the venv) is not the twin's.
    """
    given = [Path(os.environ["RIMD_CONFIG_DIR"])] if os.environ.get("RIMD_CONFIG_DIR") else []
    return given + _shipped_config_dirs()


def _shipped_config_dirs() -> list[Path]:
    """The source checkout's ``config/`` (when this package runs from one), then the installed share's."""
    dirs = []
    root = source_root()
    if root is not None:
        dirs.append(root / "config")
    share = installed_share_dir()
    if share is not None:
        dirs.append(share / "config")
    return dirs


def config_dir() -> Path:
    """Return the directory of the ROS parameter YAML files.

    The repository's ``config/`` wins, so an edit there takes effect without a rebuild; otherwise the
    installed ``share/rimd_sim/config``.

    Raises:
        FileNotFoundError: Neither exists.
    """
    candidates = _shipped_config_dirs()
    for candidate in candidates:
        if candidate.is_dir():
            return candidate
    searched = ", ".join(str(c) for c in candidates) or "no source checkout and no installed rimd_sim"
    raise FileNotFoundError(f"no config directory found (searched: {searched})")
