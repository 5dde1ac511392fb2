"""Where rimd finds its installed files: the ament index, else a pip install's prefix (no environment variable).

A plain ``pip install`` of the wheel puts ``share/rimd_sim`` (package.xml, config/) under the venv's prefix and
sets no ``AMENT_PREFIX_PATH`` (the ROS wheels' bootstrapper sets only ``LD_LIBRARY_PATH``); ``make test-dist`` runs
``rimd info`` and a rig in such a venv. Here, in process, with the prefixes and the environment replaced.
"""

from __future__ import annotations

import sys
from pathlib import Path

from rimd_sim.settings import paths


def _share(prefix: Path) -> Path:
    share = prefix / "share" / "rimd_sim"
    (share / "config").mkdir(parents=True)
    (share / "package.xml").write_text("<package/>")
    return share


def test_without_ament_prefix_path_the_share_of_the_interpreters_prefix_is_found(monkeypatch, tmp_path):
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.setattr(sys, "prefix", str(tmp_path))
    share = _share(tmp_path)
    assert paths.installed_share_dir() == share
    monkeypatch.setattr(paths, "source_root", lambda: None)   # as in an installed venv
    assert paths.config_dir() == share / "config"


def test_a_prefix_without_the_packages_share_is_not_taken(monkeypatch, tmp_path):
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.setattr(sys, "prefix", str(tmp_path))
    (tmp_path / "share" / "rimd_sim" / "config").mkdir(parents=True)   # no package.xml: not an install of rimd_sim
    monkeypatch.setattr(paths, "install_prefixes", lambda: [tmp_path])
    assert paths.installed_share_dir() is None


def test_the_ament_index_wins_over_the_interpreters_prefix(monkeypatch, tmp_path):
    workspace, venv = tmp_path / "install", tmp_path / "venv"
    ament_share = _share(workspace)
    (workspace / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (workspace / "share" / "ament_index" / "resource_index" / "packages" / "rimd_sim").write_text("")
    _share(venv)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(workspace))
    monkeypatch.setattr(sys, "prefix", str(venv))
    assert paths.installed_share_dir() == ament_share


def test_the_prefix_of_the_site_packages_the_package_is_in_is_a_candidate(monkeypatch, tmp_path):
    site = tmp_path / "prefix" / "lib" / "python3.11" / "site-packages"
    monkeypatch.setattr(paths, "__file__", str(site / "rimd_sim" / "settings" / "paths.py"))
    monkeypatch.setattr(sys, "prefix", str(tmp_path / "venv"))
    assert paths.install_prefixes() == [tmp_path / "venv", tmp_path / "prefix"]


def test_a_config_directory_above_an_installed_package_is_not_the_twins(monkeypatch, tmp_path):
    """A lab's repository holding its venv has a config/ of its own: the twin's configurations come only from
    RIMD_CONFIG_DIR, a source checkout and the installed share, so a lab's rimd.yaml never shadows the shipped one."""
    from rimd_sim.settings.config import find_config_file
    from rimd_sim.settings.yaml_file import config_dirs

    lab = tmp_path / "lab"
    (lab / "config").mkdir(parents=True)
    (lab / "config" / "rimd.yaml").write_text("not the twin's\n")
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.delenv("RIMD_CONFIG_DIR", raising=False)
    venv = lab / ".venv"
    monkeypatch.setattr(sys, "prefix", str(venv))
    share = _share(venv)
    (share / "config" / "rimd.yaml").write_text("the twin's\n")
    monkeypatch.setattr(paths, "source_root", lambda: None)   # installed, in lab/.venv
    monkeypatch.chdir(lab)
    assert config_dirs() == [share / "config"]
    assert find_config_file("rimd.yaml") == (share / "config" / "rimd.yaml").resolve()
    monkeypatch.setenv("RIMD_CONFIG_DIR", str(lab / "config"))   # unless the lab asks for it
    assert find_config_file("rimd.yaml") == (lab / "config" / "rimd.yaml").resolve()
