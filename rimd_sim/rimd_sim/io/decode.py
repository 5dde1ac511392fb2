"""Decoding recorded messages from CDR bytes into plain Python objects, from their ``.msg`` definitions, without ROS.

Every reader of a recording (``rimd analyze`` and its fault report, ``rimd identify``, ``rimd rerun``) decodes its
messages here, from the full definition the MCAP file carries with each topic (the ``ros2msg`` schema: the
type's ``.msg`` text, then ``MSG: pkg/Type`` sections for its dependencies; :mod:`rimd_sim.io.msgdefs`), or,
when the file carries none, from the installed definition (:func:`rimd_sim.io.msgdefs.message_definition`).
Neither rclpy nor the built message packages are imported.

The decoder of a type is generated once from its definition (Python source compiled with :func:`exec`, cached):
consecutive primitive fields are read with one ``struct`` call wherever their alignment is known when the
decoder is generated (the pad bytes then are part of the format); arrays of numbers are NumPy views over the
bytes (``numpy.frombuffer``: no copy, read-only, in the data's byte order); nested messages are built inline.
``rosbags`` (and ``mcap_ros2``) could decode the same files; they stay the tests' independent references
(``tests/io/test_decode.py``) rather than the readers' decoder, because a reference that is also the
implementation checks nothing, and because the readers need one error (``ValueError``) for bytes that do not
decode and one shape of message, which a decoder of the package's own gives without a further dependency.

The layout is XCDR1 as ROS 2 publishes it (the same rules as :class:`rimd_sim.io.cdr.CdrReader`): a 4-byte
encapsulation header giving the byte order (both are read), then the body, each primitive aligned to its own
size counted from the body's start; a ``string`` is a ``uint32`` length counting its terminating NUL, then the
bytes; a sequence (``T[]``, ``T[<=N]``) a ``uint32`` count, then the elements (no padding before the elements
of an empty one); a fixed array (``T[N]``) its elements only; a message without fields one ``uint8``.

What a message decodes to: an instance of a generated class per type (slotted dataclass: attribute access as on
an rclpy message, ``__msgtype__`` its full type name ``pkg/msg/Type``), with

* ``bool``: ``bool``; integers (``byte``, ``char`` and ``uint8`` included: rclpy gives a ``byte`` as a one-byte
  ``bytes``): ``int``; ``float32``/``float64``: ``float``; ``string``: ``str`` (UTF-8);
* arrays of those numbers and of ``bool``, fixed or not: a NumPy array (rclpy: ``array.array``, lists, or NumPy
  for fixed arrays); arrays of strings or of messages: a ``list``.

``wstring`` is refused when the decoder is built (no rig message uses it, and ROS 2 serializers differ on it).
Bytes that do not decode with the definition (too short, a length past the end, not UTF-8) raise ``ValueError``.
"""

from __future__ import annotations

import keyword
import re
import struct
from collections.abc import Callable
from dataclasses import dataclass, make_dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from rimd_sim.io.msgdefs import MessageDefinitionError, message_definition, service_definitions

__all__ = ["SEQUENCE", "Field", "decode_message", "installed_definition", "message_decoder", "parse_definition",
           "topic_decoder"]

#: Primitive type: (struct code, size in bytes, NumPy dtype code of an array of it).
_PRIMITIVES = {
    "bool": ("?", 1, "?"), "byte": ("B", 1, "u1"), "char": ("B", 1, "u1"), "uint8": ("B", 1, "u1"),
    "int8": ("b", 1, "i1"), "int16": ("h", 2, "i2"), "uint16": ("H", 2, "u2"), "int32": ("i", 4, "i4"),
    "uint32": ("I", 4, "u4"), "int64": ("q", 8, "i8"), "uint64": ("Q", 8, "u8"), "float32": ("f", 4, "f4"),
    "float64": ("d", 8, "f8"),
}
_STRINGS = frozenset({"string", "wstring"})
#: The field line of a ``.msg``: type (with a string bound, an array suffix), name, then a default value, a
#: constant's ``= value`` or a comment (told apart by the first character of ``rest``).
_FIELD_LINE = re.compile(r"^(?P<type>[A-Za-z][A-Za-z0-9_/]*)(?:<=(?P<bound>\d+))?(?P<array>\[(?:<=)?(?P<size>\d*)\])?"
                         r"\s+(?P<name>[A-Za-z][A-Za-z0-9_]*)\s*(?P<rest>.*)$")
_SEPARATOR_LINE = re.compile(r"^=+[ \t]*$", re.MULTILINE)
_TYPE_NAME = re.compile(r"^(?P<pkg>[A-Za-z][A-Za-z0-9_]*)/(?:(?P<kind>msg|srv|action)/)?"
                        r"(?P<name>[A-Za-z][A-Za-z0-9_]*)$")
#: An array field's length: a fixed array's element count, or SEQUENCE (``T[]``, ``T[<=N]``).
SEQUENCE = -1


@dataclass(frozen=True)
class Field:
    """One field of a message definition.

    Attributes:
        name: The field's name.
        type: A primitive type name (``float64``, ``string``, ...) or a message type's full name ``pkg/msg/Type``.
        array: None for a single value, :data:`SEQUENCE` for ``T[]`` and ``T[<=N]``, N for ``T[N]``.
        bound: N of a bounded sequence ``T[<=N]`` (None: unbounded or not a sequence); not checked when decoding.
        string_bound: N of a bounded string ``string<=N``; not checked when decoding.
    """

    name: str
    type: str
    array: int | None = None
    bound: int | None = None
    string_bound: int | None = None


def _full_name(name: str, where: str) -> tuple[str, str]:
    """``(pkg, pkg/kind/Type)`` of ``pkg/Type`` or ``pkg/kind/Type`` (kind ``msg`` when not given).

    Raises:
        MessageDefinitionError: Not a type name.
    """
    match = _TYPE_NAME.match(name.strip())
    if match is None:
        raise MessageDefinitionError(f"{where}: '{name}' is not a message type name (expected pkg/msg/Type)")
    return match["pkg"], f"{match['pkg']}/{match['kind'] or 'msg'}/{match['name']}"


def _parse_fields(pkg: str, text: str, where: str) -> tuple[Field, ...]:
    """The fields of one ``.msg`` text (constants and comments left out); bare type names are ``pkg``'s."""
    fields = []
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        match = _FIELD_LINE.match(line)
        if match is None:
            raise MessageDefinitionError(f"{where}, line {number}: cannot read {line!r} as a field or a constant")
        if match["rest"].startswith("="):
            continue    # a constant: not serialized
        base = match["type"]
        if base in _PRIMITIVES or base in _STRINGS:
            field_type = base
        elif base == "Header":
            field_type = "std_msgs/msg/Header"
        elif "/" in base:
            field_type = _full_name(base, where)[1]
        else:
            field_type = f"{pkg}/msg/{base}"
        if match["bound"] is not None and field_type not in _STRINGS:
            raise MessageDefinitionError(f"{where}, line {number}: only strings take a bound (<=N): {line!r}")
        array = bound = None
        if match["array"] is not None:
            bounded = match["array"].startswith("[<=")
            array = int(match["size"]) if match["size"] and not bounded else SEQUENCE
            bound = int(match["size"]) if bounded else None
        name = match["name"] + "_" if keyword.iskeyword(match["name"]) else match["name"]
        string_bound = int(match["bound"]) if match["bound"] is not None else None
        fields.append(Field(name, field_type, array, bound, string_bound))
    return tuple(fields)


def parse_definition(type_name: str, text: str) -> dict[str, tuple[Field, ...]]:
    """The fields of ``type_name`` and of every message type its full definition ``text`` carries.

    ``text`` is an MCAP ``ros2msg`` schema (rosbag2 layout): the type's ``.msg`` text, then for each dependency
    a line of ``=``, a line ``MSG: pkg/Type`` and its ``.msg`` text.

    Returns:
        Full type name (``pkg/msg/Type``) to fields, the root first.

    Raises:
        MessageDefinitionError: A line that is neither a field nor a constant, a section without its ``MSG:``
            line, or a type name that is not one.
    """
    pkg, root = _full_name(type_name, type_name)
    sections = _SEPARATOR_LINE.split(text)
    specs = {root: _parse_fields(pkg, sections[0], root)}
    for section in sections[1:]:
        head, _, body = section.lstrip("\n").partition("\n")
        if not head.startswith("MSG:"):
            raise MessageDefinitionError(f"{root}: a dependency's section starts with {head!r}, not 'MSG: pkg/Type'")
        dep_pkg, dep = _full_name(head[4:], root)
        specs.setdefault(dep, _parse_fields(dep_pkg, body, dep))
    return specs


# ---- code generation -----------------------------------------------------------------------------------------------

#: The generated message classes, one per (type name, field names): the same type decodes to the same class
#: whichever definition carried it.
_CLASSES: dict[tuple[str, tuple[str, ...]], type] = {}


def _message_class(type_name: str, fields: tuple[Field, ...]) -> type:
    key = (type_name, tuple(f.name for f in fields))
    cls = _CLASSES.get(key)
    if cls is None:
        cls = make_dataclass(type_name.rsplit("/", 1)[-1], [(f.name, Any) for f in fields], slots=True, eq=False,
                             namespace={"__msgtype__": type_name})
        cls.__module__ = __name__
        cls.__qualname__ = f"{type_name.replace('/', '.')}"
        _CLASSES[key] = cls
    return cls


def _too_short(data: bytes, pos: int, length: int) -> None:
    raise ValueError(f"{len(data)} bytes: a string or sequence of {length} bytes at offset {pos - 4} of the body "
                     "does not fit")


class _Generator:
    """Writes the Python source of the decoders of one definition in one byte order.

    Within a function, ``b`` is the message's bytes, ``L`` their length and ``p`` the position (from the start of
    the bytes: the body starts at 4). The alignment of ``p`` known at each point is ``p - 4 == off`` modulo
    ``mod``: primitives read while it is known enough are gathered into one ``struct`` call (``fmt``, ``group``),
    and the statements that use what they read (building a nested message) wait in ``later`` until it is made.
    """

    #: What describes the function being written (saved while an element function is written).
    _STATE = ("lines", "indent", "fmt", "group", "size", "later", "mod", "off")

    def __init__(self, specs: dict[str, tuple[Field, ...]], order: str, where: str) -> None:
        self.specs, self.order, self.where = specs, order, where
        self.names: dict[str, Any] = {"frombuffer": np.frombuffer, "_too_short": _too_short}
        self.sources: list[str] = []
        self.elements: dict[str, str] = {}     # type name -> name of its element function (arrays of it)
        self.counter = 0

    # -- one function ------------------------------------------------------------------------------------------
    def function(self, name: str, type_name: str, *, top: bool) -> None:
        """Write ``name``: the top-level decoder ``name(b)``, or the element decoder ``name(b, p, L) -> (msg, p)``."""
        saved = {key: self.__dict__.get(key) for key in self._STATE}
        self.lines: list[str] = []
        self.indent = 1
        self.fmt: list[str] = []
        self.group: list[str] = []
        self.size = 0
        self.later: list[str] = []
        # The body starts 8-aligned; an element of an array may start anywhere.
        self.mod, self.off = (8, 0) if top else (1, 0)
        result = self.message(type_name)
        self.flush()
        head = f"def {name}(b):\n    L = len(b)\n    p = 4\n" if top else f"def {name}(b, p, L):\n"
        tail = f"    return {result}\n" if top else f"    return {result}, p\n"
        self.sources.append(head + "\n".join(self.lines) + "\n" + tail)
        self.__dict__.update(saved)   # back to the function that needed this one

    def var(self) -> str:
        self.counter += 1
        return f"v{self.counter}"

    def constant(self, value: Any, prefix: str) -> str:
        name = f"{prefix}{len(self.names)}"
        self.names[name] = value
        return name

    def emit(self, line: str) -> None:
        self.lines.append("    " * self.indent + line)

    def flush(self) -> None:
        """Read the gathered primitives, then run the statements that waited for them."""
        if self.group:
            unpack = self.constant(struct.Struct(self.order + "".join(self.fmt)).unpack_from, "u")
            self.emit(f"{', '.join(self.group)}, = {unpack}(b, p)")
            self.emit(f"p += {self.size}")
        self.fmt, self.group, self.size = [], [], 0
        for line in self.later:
            self.emit(line)
        self.later = []

    def align(self, size: int) -> int | None:
        """The pad bytes before a primitive of ``size`` if known here, else None (aligned at run time)."""
        if size == 1:
            return 0
        return (-self.off) % size if size <= self.mod else None

    def advance(self, length: int) -> None:
        self.off = (self.off + length) % self.mod

    # -- fields --------------------------------------------------------------------------------------------------
    def primitive(self, code: str, size: int) -> str:
        pad = self.align(size)
        if pad is None:
            self.flush()
            self.emit(f"p += (4 - p) & {size - 1}")
            self.mod, self.off, pad = size, 0, 0
        self.fmt.append("x" * pad + code)
        self.size += pad + size
        self.advance(pad + size)
        name = self.var()
        self.group.append(name)
        return name

    def string(self) -> str:
        length = self.primitive("I", 4)
        self.flush()
        name = self.var()
        self.emit(f"e = p + {length}")
        self.emit(f"if e > L: _too_short(b, p, {length})")
        self.emit(f"{name} = b[p:e - 1].decode()")
        self.emit("p = e")
        self.mod, self.off = 1, 0
        return name

    def number_array(self, field_type: str, count: int | None) -> str:
        """An array of numbers or bools: ``count`` elements, or (None) a sequence."""
        _, size, dtype = _PRIMITIVES[field_type]
        dtype = self.constant(np.dtype(self.order + dtype if size > 1 else dtype), "t")
        if count is None:
            n = self.primitive("I", 4)
            self.flush()
            pad = self.align(size)
            if pad is None:
                self.emit(f"if {n}: p += (4 - p) & {size - 1}")
            elif pad:
                self.emit(f"if {n}: p += {pad}")
            name = self.var()
            self.emit(f"{name} = frombuffer(b, {dtype}, {n}, p)")
            self.emit(f"p += {n} * {size}" if size > 1 else f"p += {n}")
            # After the count p is 4-aligned; the elements keep it aligned to min(4, size) whether or not there
            # are any.
            self.mod, self.off = min(4, size), 0
            return name
        self.flush()
        pad = self.align(size)
        if pad is None:
            self.emit(f"p += (4 - p) & {size - 1}")
            self.mod, self.off, pad = size, 0, 0
        elif pad:
            self.emit(f"p += {pad}")
        name = self.var()
        self.emit(f"{name} = frombuffer(b, {dtype}, {count}, p)")
        self.emit(f"p += {count * size}")
        self.advance(pad + count * size)
        return name

    def loop(self, count: int | None, body: list[str], item: str) -> str:
        """A list of ``count`` (None: a sequence's count) items, each read by ``body`` into ``item``."""
        n = str(count) if count is not None else self.primitive("I", 4)
        self.flush()
        name = self.var()
        self.emit(f"{name} = []")
        self.emit(f"for _ in range({n}):")
        for line in body:
            self.emit("    " + line)
        self.emit(f"    {name}.append({item})")
        self.mod, self.off = 1, 0
        return name

    def string_array(self, count: int | None) -> str:
        u32 = self.constant(struct.Struct(self.order + "I").unpack_from, "u")
        return self.loop(count, ["p += (4 - p) & 3", f"m, = {u32}(b, p)", "e = p + 4 + m",
                                 "if e > L: _too_short(b, p, m)", "s = b[p + 4:e - 1].decode()", "p = e"], "s")

    def message_array(self, type_name: str, count: int | None) -> str:
        function = self.elements.get(type_name)
        if function is None:
            function = self.elements[type_name] = f"_element_{len(self.elements)}"
            self.function(function, type_name, top=False)
        return self.loop(count, [f"o, p = {function}(b, p, L)"], "o")

    def message(self, type_name: str) -> str:
        """Read a message of ``type_name`` here; the name of the variable that will hold it."""
        fields = self.specs.get(type_name)
        if fields is None:
            raise MessageDefinitionError(f"{self.where}: the definition does not carry {type_name} (no 'MSG: "
                                         f"{type_name.replace('/msg/', '/')}' section)")
        values = []
        for f in fields:
            count = None if f.array == SEQUENCE else f.array
            if f.type == "wstring":
                raise MessageDefinitionError(f"{self.where}: {type_name}.{f.name} is a wstring: not decoded")
            if f.type in _PRIMITIVES:
                values.append(self.primitive(*_PRIMITIVES[f.type][:2]) if f.array is None
                              else self.number_array(f.type, count))
            elif f.type == "string":
                values.append(self.string() if f.array is None else self.string_array(count))
            elif f.array is None:
                values.append(self.message(f.type))
            else:
                values.append(self.message_array(f.type, count))
        if not fields:
            self.primitive("B", 1)   # an empty message is serialized as one uint8
        cls = self.constant(_message_class(type_name, fields), "C")
        name = self.var()
        statement = f"{name} = {cls}({', '.join(values)})"
        if self.group:
            self.later.append(statement)
        else:
            self.emit(statement)
        return name


def _compile(root: str, specs: dict[str, tuple[Field, ...]], order: str) -> Callable[[bytes], Any]:
    generator = _Generator(specs, order, root)
    generator.function("decode", root, top=True)
    source = "\n".join(reversed(generator.sources))   # the element functions, then the top-level one
    exec(compile(source, f"<decoder of {root} ({'little' if order == '<' else 'big'}-endian)>", "exec"),
         generator.names)
    return generator.names["decode"]


def installed_definition(type_name: str) -> str:
    """The installed full definition of a message type or of a service's ``_Request``/``_Response``.

    Raises:
        MessageDefinitionError: Not installed (see :mod:`rimd_sim.io.msgdefs`), or not such a type name.
    """
    pkg, full = _full_name(type_name, type_name)
    kind, name = full.split("/")[1:]
    if kind == "srv":
        base, _, part = name.rpartition("_")
        if part not in ("Request", "Response"):
            raise MessageDefinitionError(f"{type_name}: a service type decodes as its _Request or _Response")
        request, response = service_definitions(f"{pkg}/srv/{base}")
        return (request if part == "Request" else response).text
    return message_definition(full).text


@lru_cache(maxsize=256)
def message_decoder(type_name: str, definition: str = "") -> Callable[[bytes], Any]:
    """The decoder of ``type_name``'s serialized (CDR) messages: ``decoder(data) -> message``.

    Args:
        type_name: ``pkg/msg/Type`` (or ``pkg/Type``; ``pkg/srv/Name_Request`` and ``_Response`` too).
        definition: Its full ``ros2msg`` definition, as an MCAP file carries it; "" for the installed one
            (:func:`rimd_sim.io.msgdefs.message_definition`, found in the ament index).

    The decoder raises ``ValueError`` on bytes that do not decode with the definition.

    Raises:
        MessageDefinitionError: The definition cannot be read, lacks a type it uses, uses ``wstring``, or ("")
            is not installed.
    """
    text = definition or installed_definition(type_name)
    specs = parse_definition(type_name, text)
    root = next(iter(specs))
    little, big = _compile(root, specs, "<"), _compile(root, specs, ">")

    def decode(data: bytes) -> Any:
        b = data if type(data) is bytes else bytes(data)
        if len(b) < 4:
            raise ValueError(f"{len(b)} bytes: too short for a CDR encapsulation header")
        try:
            return little(b) if b[1] & 1 else big(b)
        except struct.error as exc:
            raise ValueError(f"{len(b)} bytes: too short for a {root}: {exc}") from None

    decode.__doc__ = f"Decode a serialized {root} (either byte order)."
    decode.__qualname__ = decode.__name__ = f"decode_{root.rsplit('/', 1)[-1]}"
    return decode


def decode_message(data: bytes, type_name: str, definition: str = "") -> Any:
    """Decode one serialized message (see :func:`message_decoder`).

    Raises:
        MessageDefinitionError: See :func:`message_decoder`.
        ValueError: The bytes do not decode with the definition.
    """
    return message_decoder(type_name, definition)(data)


def topic_decoder(topic: Any, type_name: str = "") -> Callable[[bytes], Any]:
    """The decoder of a recorded topic's messages (see :func:`message_decoder`), from the definition its file carries.

    Args:
        topic: The :class:`rimd_sim.io.reader.RecordedTopic` (None: not in the recording).
        type_name: The type to decode as when the file carries no schema for the topic; then, as when a schema
            carries no definition text, the installed definition is used.

    Raises:
        MessageDefinitionError: The messages are not CDR, the schema is not ``ros2msg``, or no definition can be
            read (see :func:`message_decoder`).
    """
    if topic is None or not topic.type_name:
        if not type_name:
            raise MessageDefinitionError(f"{getattr(topic, 'name', 'the topic')}: no message type recorded")
        return message_decoder(type_name)
    if topic.message_encoding != "cdr":
        raise MessageDefinitionError(f"{topic.name}: message encoding {topic.message_encoding!r}, not 'cdr'")
    if topic.schema_encoding not in ("ros2msg", ""):
        raise MessageDefinitionError(f"{topic.name}: schema encoding {topic.schema_encoding!r}, not 'ros2msg'")
    return message_decoder(topic.type_name, topic.definition)
