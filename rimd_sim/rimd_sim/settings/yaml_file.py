"""Reading the files a user gives: YAML with line and column in every error, and configs found where expected.

Every YAML file the product reads (the rig's parameter files, fault scenarios, identification bases) goes
through :func:`read_yaml`: a syntax error names the file, the line and the column (``rig.yaml:12:7: mapping
values are not allowed here``), as a compiler would. :func:`resolve_config` finds a configuration named on the
command line: as given (relative to the working directory), else in the package's configuration directory,
and otherwise says where it looked.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rimd_sim.errors import InputError

__all__ = ["config_dirs", "read_yaml", "resolve_config"]


def read_yaml(path: str | Path, *, what: str = "file") -> Any:
    """The document of a YAML file.

    Raises:
        InputError: The file cannot be read, or is not valid YAML (file, line and column named).
    """
    import yaml

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{what} {path} is not text (UTF-8): {exc.reason} at byte {exc.start}") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark is not None else str(path)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        context = getattr(exc, "context", None)
        raise InputError(f"{what} is not valid YAML: {where}: {problem}"
                         + (f" ({context})" if context else "")) from None


def config_dirs() -> list[Path]:
    """Where shipped configurations live: :func:`rimd_sim.settings.paths.config_dirs`."""
    from rimd_sim.settings import paths

    return paths.config_dirs()


def resolve_config(path: str | Path, *, what: str = "--config") -> Path:
    """A configuration file named by a user: as given, else by its name in the shipped configuration directory.

    ``config/paper_model.yaml`` typed outside the repository finds the shipped ``paper_model.yaml``.

    Raises:
        InputError: Found nowhere; the message lists where it looked.
    """
    given = Path(path).expanduser()
    candidates = [given if given.is_absolute() else Path.cwd() / given]
    if not given.is_absolute():
        candidates += [directory / given.name for directory in config_dirs()]
    seen: list[Path] = []
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
        place = candidate.parent.resolve() / candidate.name
        if place not in seen:
            seen.append(place)
    raise InputError(f"{what} {path}: not found; looked in " + ", ".join(str(c) for c in seen))
