"""One declaration per parameter: the frozen settings class of a node *is* its parameter table.

Every parameter of every node (simulator, recorder, replay, Rerun bridge, capture, lockstep) is a field of a
frozen dataclass declared with :func:`param`: its default, unit, range or choices, description and any extra
rule, in one place. From that one declaration come

* the validated frozen settings (:func:`build`, and ``with_parameters`` on the classes that offer it): every
  value is checked with :meth:`Param.validate`, which names the key, the value and the rule
  (:class:`~rimd_sim.errors.ConfigError`);
* the ROS parameter descriptors and the set-time validation of the nodes (``rimd_sim.ros.nodes.base``);
* the tables of ``docs/configuration.md`` and the node pages (``scripts/gen_docs.py``);
* the cases of the bad-input tests (``tests/ros/test_bad_input.py`` reads :func:`parameters`).

Groups of parameters nest: a field declared with :func:`group` holds another settings class whose parameter
names take a prefix (``contact.stiffness``); :func:`keyed` holds a tuple of one settings class per key, each
with its own defaults (``channels.impact_force.sample_rate``). Rules that tie several fields together
(``range_min < range_max``) are the class's ``__post_init__``, raising ``ConfigError`` too; each such rule is
declared in words on the parameter it refuses (``relation``), so that its rule, as the documentation shows it,
is whole (``tests/settings/test_parameter_declarations.py`` finds the parameters a ``__post_init__`` refuses and
checks that each declares its relation).

Adding a parameter is one edit: a field with :func:`param` in the settings class of its node.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, cast

from rimd_sim.errors import ConfigError

__all__ = ["BAD_REGEX_LISTS", "Param", "build", "defaults", "group", "keyed", "param", "parameters",
           "regex_list_problem", "to_flat", "validate_all"]

_PARAM, _GROUP, _KEYED = "rimd.param", "rimd.group", "rimd.keyed"

#: Smallest positive normal float; smaller non-zero values (subnormal) are refused for every real number.
SMALLEST_NORMAL = sys.float_info.min

#: ``kind`` of a parameter, from its default: the ROS parameter types the nodes use.
KINDS = {bool: "bool", int: "int", float: "float", str: "str", tuple: "str[]"}


@dataclass(frozen=True)
class Param:
    """One parameter: name, default, type, unit, rule and description.

    Attributes:
        name: Full ROS parameter name (``contact.stiffness``).
        default: Default value (a tuple for a list of strings).
        description: What it is.
        unit: SI unit ('' when none), shown with the description and in the documentation.
        ge, gt, le, lt: Bounds of a number (>=, >, <=, <).
        zero: A number may also be exactly 0, outside the bounds; a string names what 0 means ("rigid").
        choices: Allowed strings.
        extra_rule: Words of a rule that :attr:`check` tests besides the bounds.
        check: Test of the converted value: True (or None) passes; False breaks :attr:`extra_rule`; a string
            breaks it and says how.
        read_only: Read at start only: refused at run time.
        breaks: Values that break :attr:`extra_rule` (for the generated bad-input tests; the bounds and choices
            give theirs by themselves).
        relation: Words of a rule between this parameter and others, checked by the settings class's
            ``__post_init__`` (not by :meth:`validate`, which sees one value): shown in :attr:`rule`.
        attr: Attribute path from the root settings object.
    """

    name: str
    default: Any
    description: str
    unit: str = ""
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    zero: bool | str = False
    choices: tuple[str, ...] = ()
    extra_rule: str = ""
    check: Callable[[Any], bool | str | None] | None = None
    read_only: bool = False
    breaks: tuple[Any, ...] = ()
    attr: tuple[str, ...] = ()
    relation: str = ""

    @property
    def kind(self) -> str:
        """``bool``, ``int``, ``float``, ``str`` or ``str[]`` (from the default's type)."""
        return KINDS[type(self.default)]

    @property
    def low(self) -> float | None:
        """Lower bound of the range (None: none)."""
        return self.ge if self.ge is not None else self.gt

    @property
    def high(self) -> float | None:
        """Upper bound of the range (None: none)."""
        return self.le if self.le is not None else self.lt

    @property
    def rule(self) -> str:
        """The rule in words, as refusals, descriptors and the documentation show it."""
        parts = []
        for op, bound in ((">=", self.ge), (">", self.gt), ("<=", self.le), ("<", self.lt)):
            if bound is not None:
                parts.append(f"{op} {bound:g}" if isinstance(bound, float) else f"{op} {bound}")
        words = []
        if parts:
            zero = f"0 ({self.zero}) or " if isinstance(self.zero, str) else "0 or " if self.zero else ""
            words.append(zero + " and ".join(parts) + (f" {self.unit}" if _unit_ok(
                self.unit) else ""))
        if self.choices:
            words.append("one of: " + ", ".join(self.choices))
        if self.extra_rule:
            words.append(self.extra_rule)
        if self.relation:
            words.append(self.relation)
        if not words or words == [self.relation]:
            words.insert(0, {"bool": "true or false", "int": "an integer", "float": "a number", "str": "a string",
                          "str[]": "a list of strings"}[self.kind])
        return "must be " + "; ".join(words)

    def validate(self, value: Any) -> Any:
        """The value converted to the parameter's type (an integer for a real number is fine), checked.

        Raises:
            ConfigError: Naming the parameter, the value and the rule it breaks.
        """
        kind = self.kind
        if kind == "float":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                hint = ""
                if isinstance(value, str):
                    try:
                        float(value)
                        hint = " (YAML read it as text: write exponents with a sign and a dot, e.g. 5.5e+6)"
                    except ValueError:
                        pass
                raise ConfigError(self.name, value, "must be a number" + hint)
            value = float(value)
            if not math.isfinite(value):
                raise ConfigError(self.name, value, f"must be finite; {self.rule}")
            if value != 0.0 and abs(value) < SMALLEST_NORMAL:
                # A subnormal number has lost its precision, and the kernels' products of such values underflow
                # to 0 (amplitude = 5e-324 divided by zero inside the integrator).
                raise ConfigError(self.name, value, f"must be 0 or at least {SMALLEST_NORMAL:.3g} in magnitude "
                                                    f"(not a subnormal number); {self.rule}")
        elif kind == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(self.name, value, "must be an integer; " + self.rule)
        elif kind == "bool":
            if not isinstance(value, bool):
                raise ConfigError(self.name, value, "must be true or false")
        elif kind == "str":
            if not isinstance(value, str):
                raise ConfigError(self.name, value, "must be a string; " + self.rule)
        elif not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise ConfigError(self.name, value, "must be a list of strings")
        else:
            value = tuple(v for v in value if v)   # empty entries mean nothing (ROS has no empty string list)
        if not self._in_range(value) or (self.choices and value not in self.choices):
            raise ConfigError(self.name, value, self.rule)
        verdict = True if self.check is None else self.check(value)
        if verdict is False:
            raise ConfigError(self.name, value, self.rule)
        if isinstance(verdict, str):   # the check says what is wrong
            raise ConfigError(self.name, value, f"{self.rule} ({verdict})")
        return value

    def _in_range(self, value: Any) -> bool:
        if self.kind not in ("int", "float") or (self.zero and value == 0):
            return True
        return ((self.ge is None or value >= self.ge) and (self.gt is None or value > self.gt)
                and (self.le is None or value <= self.le) and (self.lt is None or value < self.lt))

    def described(self) -> str:
        """The description with the unit, as a descriptor shows it."""
        return f"{self.description} [{self.unit}]" if self.unit else self.description


def _unit_ok(unit: str) -> bool:
    """Whether a unit reads well after a bound (``>= 0 m``); composite notes do not."""
    return bool(unit) and " " not in unit


# ---- declaring -----------------------------------------------------------------------------------------------


def regex_list_problem(patterns: tuple[str, ...]) -> bool | str:
    """A ``check`` for a list of regular expressions: True, or which one is not and why."""
    import re

    for pattern in patterns:
        if pattern:
            try:
                re.compile(pattern)
            except re.error as exc:
                return f"'{pattern}' is not a regular expression: {exc}"
    return True


#: Values that break :func:`regex_list_problem` (for the generated bad-input tests).
BAD_REGEX_LISTS = (("(",), ("[z-a]",), ("*",), ("ok", "?+"))


def param(default: Any, description: str, *, unit: str = "", ge: float | None = None, gt: float | None = None,
          le: float | None = None, lt: float | None = None, zero: bool | str = False, choices: tuple[str, ...] = (),
          rule: str = "", check: Callable[[Any], bool | str | None] | None = None, read_only: bool = False,
          breaks: tuple[Any, ...] = (), name: str | None = None, relation: str = "") -> Any:
    """A dataclass field that is a parameter (see :class:`Param` for the arguments).

    ``name``: the parameter's name within its group when it is not the field's name (``truth.sample_rate``).
    A list of strings is declared and held as a tuple; its empty entries are dropped (a ROS parameter file
    cannot give an empty list of strings: ``[""]`` says "none").
    """
    if isinstance(default, list):
        default = tuple(default)
    decl = Param(name or "", default, description, unit, ge, gt, le, lt, zero, tuple(choices), rule, check,
                 read_only, tuple(breaks), relation=relation)
    return dataclasses.field(default=default, metadata={_PARAM: decl})


def group(cls: type, prefix: str) -> Any:
    """A dataclass field holding the settings class ``cls``, whose parameter names take ``prefix``."""
    return dataclasses.field(default_factory=cls, metadata={_GROUP: prefix})


def keyed(prefix: str, instances: tuple[Any, ...], key: str = "name") -> Any:
    """A field holding one settings object per key (``instances``, their defaults), names ``prefix.format(key)``."""
    return dataclasses.field(default=instances, metadata={_KEYED: (prefix, key)})


# ---- the table -----------------------------------------------------------------------------------------------

_TABLES: dict[type, dict[str, Param]] = {}


def _group_class(f: dataclasses.Field[Any]) -> type:
    """The settings class of a :func:`group` field: its default factory."""
    return cast(type, f.default_factory)


def _keyed_defaults(f: dataclasses.Field[Any]) -> tuple[Any, ...]:
    """The default instances of a :func:`keyed` field: its default."""
    return cast(tuple[Any, ...], f.default)


def parameters(cls: type) -> dict[str, Param]:
    """Every parameter of the settings class ``cls`` (nested groups included), by full name, in declaration order."""
    table = _TABLES.get(cls)
    if table is None:
        table = _TABLES[cls] = {p.name: p for p in _walk(cls, "", (), None)}
    return table


def _walk(cls: type, prefix: str, path: tuple[str, ...], instance: Any) -> Iterator[Param]:
    for f in dataclasses.fields(cls):
        meta = f.metadata
        if _PARAM in meta:
            decl: Param = meta[_PARAM]
            default = getattr(instance, f.name) if instance is not None else decl.default
            yield dataclasses.replace(decl, name=prefix + (decl.name or f.name), default=default,
                                      attr=(*path, f.name))
        elif _GROUP in meta:
            yield from _walk(_group_class(f), prefix + meta[_GROUP], (*path, f.name),
                             None if instance is None else getattr(instance, f.name))
        elif _KEYED in meta:
            fmt, key = meta[_KEYED]
            items = _keyed_defaults(f) if instance is None else getattr(instance, f.name)
            for i, item in enumerate(items):
                yield from _walk(type(item), prefix + fmt.format(getattr(item, key)), (*path, f.name, str(i)), item)


def defaults(cls: type) -> dict[str, Any]:
    """The default of every parameter of ``cls``."""
    return {name: p.default for name, p in parameters(cls).items()}


def to_flat(settings: Any) -> dict[str, Any]:
    """The parameters of a settings object as flat ROS names and values."""
    out = {}
    for name, p in parameters(type(settings)).items():
        value = settings
        for step in p.attr:
            value = value[int(step)] if step.isdigit() else getattr(value, step)
        out[name] = value
    return out


def unknown_name(name: str, known) -> str:
    """The rule of an unknown parameter name: the closest known names, else where every name is listed."""
    import difflib

    close = difflib.get_close_matches(name, list(known), n=3, cutoff=0.6)
    if close:
        return "unknown parameter; did you mean " + " or ".join(close) + "? (every parameter: docs/configuration.md)"
    return "unknown parameter (every parameter: docs/configuration.md)"


def validate_all(cls: type, values: Mapping[str, Any], *, ignore: Callable[[str], bool] | None = None
                 ) -> dict[str, Any]:
    """Check every value of ``values`` against its parameter of ``cls``; return them converted.

    Raises:
        ConfigError: For an unknown name (unless ``ignore(name)``) or a refused value.
    """
    table = parameters(cls)
    out = {}
    for name, value in values.items():
        p = table.get(name)
        if p is None:
            if ignore is not None and ignore(name):
                continue
            raise ConfigError(name, value, unknown_name(str(name), table))
        out[name] = p.validate(value)
    return out


def build(cls: type, values: Mapping[str, Any] | None = None, *, base: Any = None,
          ignore: Callable[[str], bool] | None = None) -> Any:
    """A settings object of ``cls`` from flat ROS values over ``base`` (default: the defaults), every value checked.

    Raises:
        ConfigError: For an unknown name (unless ``ignore(name)``), a refused value, or a broken rule between
            fields (the classes' ``__post_init__``).
    """
    flat = to_flat(base) if base is not None else defaults(cls)
    flat.update(validate_all(cls, values or {}, ignore=ignore))
    return _construct(cls, "", flat, None)


def _construct(cls: type, prefix: str, flat: Mapping[str, Any], template: Any) -> Any:
    kwargs = {}
    for f in dataclasses.fields(cls):
        meta = f.metadata
        if _PARAM in meta:
            kwargs[f.name] = flat[prefix + (meta[_PARAM].name or f.name)]
        elif _GROUP in meta:
            kwargs[f.name] = _construct(_group_class(f), prefix + meta[_GROUP], flat, None)
        elif _KEYED in meta:
            fmt, key = meta[_KEYED]
            kwargs[f.name] = tuple(_construct(type(item), prefix + fmt.format(getattr(item, key)), flat, item)
                                   for item in _keyed_defaults(f))
        elif template is not None:   # a field of a keyed item that is not a parameter (its key)
            kwargs[f.name] = getattr(template, f.name)
    return cls(**kwargs)
