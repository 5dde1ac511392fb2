"""Where the project's files are: the repository's config/ first, then the installed share directory."""

from __future__ import annotations

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


def installed_share_dir() -> Path | None:
    """Return ``share/rimd_sim`` of the install prefix found on AMENT_PREFIX_PATH, or None."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:
        return None
    try:
        return Path(get_package_share_directory(PACKAGE_NAME))
    except PackageNotFoundError:
        return None


def config_dir() -> Path:
    """Return the directory of the ROS parameter YAML files.

    The repository's ``config/`` wins, so an edit there takes effect without a rebuild; otherwise the
    installed ``share/rimd_sim/config``.

    Raises:
        FileNotFoundError: Neither exists.
    """
    candidates = []
    root = source_root()
    if root is not None:
        candidates.append(root / "config")
    share = installed_share_dir()
    if share is not None:
        candidates.append(share / "config")
    for candidate in candidates:
        if candidate.is_dir():
            return candidate
    searched = ", ".join(str(c) for c in candidates) or "no source checkout and no installed rimd_sim"
    raise FileNotFoundError(f"no config directory found (searched: {searched})")
