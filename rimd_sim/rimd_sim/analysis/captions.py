"""The caption of a configuration: which design a figure shows, in one line (ROS-free).

:func:`describe` names the structure model and the contact law, then every mechanical parameter (those of
:class:`~rimd_sim.settings.config.RigParams` and its groups ``contact.*`` and ``structure.*``; not the
instruments, the motor or the integrator) whose value differs from its declared default, with its unit::

    rigid model, spring_dashpot contact; mass 1 kg, natural_frequency 10.5 Hz, damping_ratio 0.02, gap 0.25 mm

Values are ``%g``; units are the declarations' SI units, except the lengths of :data:`SHOWN_IN_MM` (gap and
amplitude), shown in mm and said so. With the defaults only: ``rigid model, spring_dashpot contact; default
parameters``. The parameters come from the declarations (:func:`rimd_sim.settings.params.parameters`), so one
added to ``RigParams`` later appears without an edit here.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from rimd_sim.settings.config import RigParams
from rimd_sim.settings.params import Param, parameters, to_flat

__all__ = ["DEFAULTS", "SHOWN_IN_MM", "describe", "describe_parameters"]

#: Parameters (declared in m) shown in mm in a caption.
SHOWN_IN_MM = ("gap", "amplitude")

#: The words of a caption when every mechanical parameter has its default.
DEFAULTS = "default parameters"

#: The parameters named in the caption's head (the models), not in its list.
_HEAD = ("structure.model", "contact.model")


def describe(config: Any, *, omit: Iterable[str] = ()) -> str:
    """The caption of ``config`` (a :class:`~rimd_sim.settings.config.SimConfig` or a ``RigParams``).

    ``omit``: parameters left out of the list (the one a figure varies along an axis, e.g. ``gap`` for a map
    over gap/A0).
    """
    rig = getattr(config, "rig", config)
    return describe_parameters(to_flat(rig), omit=omit)


def describe_parameters(values: Mapping[str, Any], *, omit: Iterable[str] = ()) -> str:
    """The caption of flat parameter values (names as in the configuration file: ``contact.stiffness``).

    Values may be strings (a recording's metadata holds them so): each is read as its parameter's type. Names
    that are not mechanical parameters are ignored; a missing one counts as its default.
    """
    table = parameters(RigParams)
    skip = set(omit) | set(_HEAD)
    head = ", ".join(f"{_value(table[name], values.get(name, table[name].default))} {word}"
                     for name, word in zip(_HEAD, ("model", "contact"), strict=True))
    changed = []
    for name, p in table.items():
        if name in skip or name not in values:
            continue
        value = _value(p, values[name])
        if value != p.default:
            changed.append(_show(p, value))
    return f"{head}; {', '.join(changed) if changed else DEFAULTS}"


def _value(p: Param, value: Any) -> Any:
    """``value`` as the parameter's type (a string from a recording's metadata read as a number, a boolean)."""
    if not isinstance(value, str) or p.kind == "str":
        return value
    try:
        if p.kind == "float":
            return float(value)
        if p.kind == "int":
            return int(value)
        if p.kind == "bool":
            return value.strip().lower() in ("true", "1", "yes")
    except ValueError:
        pass
    return value


def _show(p: Param, value: Any) -> str:
    """``name value unit``, compact: ``gap 0.25 mm``, ``damping_ratio 0.02``, ``contact.stiffness 5e+06 N/m``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"{p.name} {value}"
    unit = p.unit
    if p.name in SHOWN_IN_MM and unit == "m":
        value, unit = value * 1e3, "mm"
    return f"{p.name} {value:g}" + (f" {unit}" if unit else "")
