"""Reading the files a user gives: YAML with line and column in every error, and configs found where expected.

Every YAML file the product reads (the rig's parameter files, fault scenarios, identification bases) goes
through :func:`read_yaml`: a syntax error names the file, the line and the column (``rig.yaml:12:7: mapping
values are not allowed here``), as a compiler would. A key given twice in one mapping is refused the same way:
YAML forbids it, and PyYAML and ROS's own parser would both take the last value in silence.
:func:`resolve_config` finds a configuration named on the command line: as given (relative to the working
directory), else in the package's configuration directory, and otherwise says where it looked.
"""

from __future__ import annotations

from collections.abc import Hashable
from functools import cache
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
        return yaml.load(text, Loader=_unique_keys_loader())  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark is not None else str(path)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        context = getattr(exc, "context", None)
        raise InputError(f"{what} is not valid YAML: {where}: {problem}"
                         + (f" ({context})" if context else "")) from None


@cache
def _unique_keys_loader() -> type:
    """PyYAML's safe loader, refusing a mapping that gives a key twice (at the second one, naming the first)."""
    import yaml

    class UniqueKeysLoader(yaml.SafeLoader):
        def construct_mapping(self, node: Any, deep: bool = False) -> Any:
            if isinstance(node, yaml.MappingNode):
                seen: dict[Any, Any] = {}
                for key_node, _ in node.value:
                    key = self.construct_object(key_node, deep=True)
                    if not isinstance(key, Hashable):
                        continue   # the base class refuses it, with its own message
                    if key in seen:
                        raise yaml.constructor.ConstructorError(
                            None, None, f"key {key!r} given twice (first on line {seen[key].line + 1})",
                            key_node.start_mark)
                    seen[key] = key_node.start_mark
            return super().construct_mapping(node, deep=deep)

    return UniqueKeysLoader


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
