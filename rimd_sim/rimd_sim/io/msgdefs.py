"""Full ROS 2 message definitions (``ros2msg`` schemas) as rosbag2 writes them into MCAP files.

A reader that does not have the message packages installed (Foxglove, ``mcap-ros2-support``, ``rosbags``)
decodes a recording from its schema alone, so the schema must carry the message's ``.msg`` text followed by
every message it depends on, each once, in the layout rosbag2 uses::

    <text of pkg/msg/Type.msg>
    ================================================================================
    MSG: std_msgs/Header
    <text of std_msgs/msg/Header.msg>
    ...

The ``.msg`` and ``.json`` (type description, with the RIHS01 type hash) files are looked up in the
``share/<package>/msg`` directories of the prefixes on ``AMENT_PREFIX_PATH`` (then the interpreter's prefix):
the standard ament index layout, no rclpy needed.
"""

from __future__ import annotations

import json
import os
import re
import sys
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from rimd_sim.errors import UnavailableError

SEPARATOR = "=" * 80

PRIMITIVE_TYPES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
    "int64", "uint64", "string", "wstring",
})

_TYPE_NAME = re.compile(r"^(?P<pkg>[A-Za-z][A-Za-z0-9_]*)/(?:msg/)?(?P<name>[A-Za-z][A-Za-z0-9_]*)$")


class MessageDefinitionError(UnavailableError):
    """A message type's definition could not be found; the message names the type and where it looked."""


@dataclass(frozen=True)
class MessageDefinition:
    """The schema of one message type, ready for an MCAP ``ros2msg`` schema record.

    Attributes:
        type_name: Full name, ``pkg/msg/Type``.
        text: The ``.msg`` text with all dependencies appended (rosbag2 layout).
        type_hash: The ``RIHS01_...`` type hash of the type description, or "" when not installed.
    """

    type_name: str
    text: str
    type_hash: str


def normalize_type_name(type_name: str) -> tuple[str, str]:
    """Split ``pkg/msg/Type`` or ``pkg/Type`` into ``(pkg, Type)``.

    Raises:
        MessageDefinitionError: The name is not a ROS 2 message type name.
    """
    match = _TYPE_NAME.match(type_name.strip())
    if match is None:
        raise MessageDefinitionError(f"'{type_name}' is not a message type name (expected pkg/msg/Type)")
    return match["pkg"], match["name"]


def _search_prefixes() -> list[Path]:
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(Path(sys.prefix))
    return prefixes


def _find_file(pkg: str, name: str, suffix: str, kind: str = "msg") -> Path | None:
    for prefix in _search_prefixes():
        candidate = prefix / "share" / pkg / kind / f"{name}{suffix}"
        if candidate.is_file():
            return candidate
    return None


def _field_dependencies(pkg: str, text: str) -> list[tuple[str, str]]:
    """Return the (pkg, Type) of the non-primitive field types of a ``.msg`` text, in order of appearance."""
    found: list[tuple[str, str]] = []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        field_type = line.split()[0]
        if "=" in line.split(None, 1)[-1] and field_type in PRIMITIVE_TYPES:
            continue  # a constant
        base = re.sub(r"\[.*\]$", "", field_type)      # arrays: T[], T[3], T[<=3]
        base = re.sub(r"<=\d+$", "", base)             # bounded strings: string<=10
        if base in PRIMITIVE_TYPES:
            continue
        if "/" in base:
            dep = normalize_type_name(base)
        elif base == "Header":
            dep = ("std_msgs", "Header")
        else:
            dep = (pkg, base)
        if dep not in found:
            found.append(dep)
    return found


@cache
def _msg_text(pkg: str, name: str) -> str:
    path = _find_file(pkg, name, ".msg")
    if path is None:
        where = ", ".join(str(p / "share" / pkg / "msg") for p in _search_prefixes())
        raise MessageDefinitionError(f"no definition of {pkg}/msg/{name} found (looked for {name}.msg in {where})")
    return path.read_text(encoding="utf-8")


@cache
def message_definition(type_name: str) -> MessageDefinition:
    """Return the full definition (with dependencies) of a message type such as ``rimd_msgs/msg/SampleBlock``.

    Raises:
        MessageDefinitionError: The type or one of its dependencies is not installed.
    """
    pkg, name = normalize_type_name(type_name)
    return _full_definition(pkg, name, _msg_text(pkg, name), f"{pkg}/msg/{name}", _type_hash(pkg, name))


_SRV_NAME = re.compile(r"^(?P<pkg>[A-Za-z][A-Za-z0-9_]*)/(?:srv/)?(?P<name>[A-Za-z][A-Za-z0-9_]*)$")


@cache
def service_definitions(type_name: str) -> tuple[MessageDefinition, MessageDefinition]:
    """Return the full definitions of a service's request and response, as foxglove_bridge advertises them.

    ``pkg/srv/Name`` gives ``pkg/srv/Name_Request`` and ``pkg/srv/Name_Response``: the two halves of
    ``Name.srv`` (split at ``---``), each followed by the messages it depends on (rosbag2 layout). The type
    hashes are left empty (a service's halves have no ``.json`` of their own).

    Raises:
        MessageDefinitionError: The service or a message it uses is not installed, or the name is not a
            service type name.
    """
    match = _SRV_NAME.match(type_name.strip())
    if match is None:
        raise MessageDefinitionError(f"'{type_name}' is not a service type name (expected pkg/srv/Type)")
    pkg, name = match["pkg"], match["name"]
    path = _find_file(pkg, name, ".srv", kind="srv")
    if path is None:
        where = ", ".join(str(p / "share" / pkg / "srv") for p in _search_prefixes())
        raise MessageDefinitionError(f"no definition of {pkg}/srv/{name} found (looked for {name}.srv in {where})")
    halves = re.split(r"^---[ \t]*$", path.read_text(encoding="utf-8"), maxsplit=1, flags=re.MULTILINE)
    if len(halves) != 2:
        raise MessageDefinitionError(f"{path} has no '---' line between the request and the response")
    request, response = (
        _full_definition(pkg, f"{name}_{part}", text.strip("\n") + "\n", f"{pkg}/srv/{name}_{part}", "")
        for part, text in zip(("Request", "Response"), halves, strict=True))
    return request, response


def _full_definition(pkg: str, name: str, root: str, full_name: str, type_hash: str) -> MessageDefinition:
    """The definition ``root`` of ``pkg/name`` with every message it depends on appended, each once."""
    order: list[tuple[str, str]] = []
    pending = _field_dependencies(pkg, root)
    while pending:
        dep = pending.pop(0)
        if dep in order or dep == (pkg, name):
            continue
        order.append(dep)
        pending.extend(d for d in _field_dependencies(dep[0], _msg_text(*dep)) if d not in order)
    parts = [root.rstrip("\n")]
    for dep_pkg, dep_name in order:
        parts.append(f"{SEPARATOR}\nMSG: {dep_pkg}/{dep_name}\n{_msg_text(dep_pkg, dep_name).rstrip(chr(10))}")
    return MessageDefinition(full_name, "\n".join(parts) + "\n", type_hash)


def _type_hash(pkg: str, name: str) -> str:
    path = _find_file(pkg, name, ".json")
    if path is None:
        return ""
    try:
        hashes = json.loads(path.read_text(encoding="utf-8")).get("type_hashes", [])
    except (OSError, ValueError):
        return ""
    for entry in hashes:
        if entry.get("type_name") == f"{pkg}/msg/{name}":
            return str(entry.get("hash_string", ""))
    return ""
