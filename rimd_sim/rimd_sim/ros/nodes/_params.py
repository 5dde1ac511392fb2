"""Parameters on ROS: descriptors, declarations and refusals naming the parameter, for every node of the rig.

:func:`declare` turns a table of :class:`rimd_sim.settings.params.Param` (a node's settings classes) into
declared parameters with descriptors; the node builds its frozen settings from the values.

rclpy refuses an undeclared name with an empty list (``Invalid access to undeclared parameter(s): []``) and
lets an empty name through (a node then declared it), refuses a value of the wrong static type naming only
the two types, and an attempt to unset a parameter with no name at all. Each node overrides
``set_parameters_atomically`` (the path of rclpy's parameter services) with :func:`refuse_unnamed` first.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from rimd_sim.settings.params import Param

__all__ = ["declare", "descriptor", "refuse_unnamed"]


def refuse_unnamed(node: Node, parameters: list[Parameter]) -> SetParametersResult | None:
    """The refusals that rclpy's own checks would give without naming the parameter, with its name and rule.

    rclpy refuses an undeclared name with an empty list (``Invalid access to undeclared parameter(s): []``,
    and lets an empty name through: the recorder then declared it), a value of the wrong static type with
    the two types only, and an attempt to unset a parameter with no name at all. Returns None when none of
    these applies (rclpy's other refusals, read-only and out of range, name the parameter).
    """
    for p in parameters:
        if not p.name or not node.has_parameter(p.name):
            return SetParametersResult(successful=False, reason=(
                f"parameter '{p.name}' refused: not a parameter of {node.get_fully_qualified_name()} "
                "(list_parameters gives them)"))
        descriptor = node.describe_parameter(p.name)
        if descriptor.read_only or descriptor.dynamic_typing:
            continue  # rclpy names a read-only parameter; the node's callback checks a dynamically typed one
        expected = Parameter.Type(descriptor.type).name.lower()
        if p.type_ == Parameter.Type.NOT_SET:
            return SetParametersResult(successful=False, reason=(
                f"parameter '{p.name}' refused: cannot be unset (it must keep a value of type {expected})"))
        if p.type_.value != descriptor.type:
            return SetParametersResult(successful=False, reason=(
                f"parameter '{p.name}' = {p.value!r} refused: must be of type {expected}, "
                f"not {p.type_.name.lower()}"))
    return None


#: rcl_interfaces ParameterType of each parameter kind (rimd_sim.settings.params.Param.kind).
ROS_TYPES = {"bool": ParameterType.PARAMETER_BOOL, "int": ParameterType.PARAMETER_INTEGER,
             "float": ParameterType.PARAMETER_DOUBLE, "str": ParameterType.PARAMETER_STRING,
             "str[]": ParameterType.PARAMETER_STRING_ARRAY}


def descriptor(p: Param) -> ParameterDescriptor:
    """The ROS descriptor of a declared parameter: type, description with unit, rule, range, read-only.

    A real number is dynamically typed, so that an integer is accepted where a real number is meant
    (``-p rate:=2``, ``gap: 0`` in YAML); the node converts and checks it (:meth:`Param.validate`).
    """
    desc = ParameterDescriptor(name=p.name, type=ROS_TYPES[p.kind], description=p.described(),
                               additional_constraints=p.rule, read_only=p.read_only,
                               dynamic_typing=p.kind == "float")
    low, high = (0 if p.zero else p.low), p.high
    if p.kind == "int" and p.lt is not None:
        high = p.lt - 1
    if p.kind == "int" and p.gt is not None:
        low = p.gt + 1
    if low is not None and high is not None:
        if p.kind == "float":
            desc.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
        elif p.kind == "int":
            desc.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=0)]
    return desc


def declare(node: Node, table: Mapping[str, Param]) -> dict[str, Any]:
    """Declare every parameter of ``table`` on ``node`` (overrides from ``--ros-args`` apply); return the values.

    The values are as ROS holds them (a list for a list of strings, an integer where one was given for a real
    number): build the node's settings from them (:func:`rimd_sim.settings.params.build`), which checks each one.
    """
    values = {}
    for name, p in table.items():
        default = p.default
        if p.kind == "str[]":
            # rclpy types an empty list as a byte array (and then refuses a list of strings given for it), and
            # a parameter declared by its type alone stays unset, which breaks get_parameters for every name
            # asked with it: an empty list is declared as [""], and empty entries mean nothing (Param.validate).
            default = list(default) or [""]
        node.declare_parameter(name, default, descriptor(p))
        values[name] = node.get_parameter(name).value
    return values
