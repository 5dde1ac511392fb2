"""Parameter refusals that name the parameter and its rule, shared by every node of the rig.

rclpy refuses an undeclared name with an empty list (``Invalid access to undeclared parameter(s): []``) and
lets an empty name through (a node then declared it), refuses a value of the wrong static type naming only
the two types, and an attempt to unset a parameter with no name at all. Each node overrides
``set_parameters_atomically`` (the path of rclpy's parameter services) with :func:`refuse_unnamed` first.
"""

from __future__ import annotations

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

__all__ = ["refuse_unnamed"]


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
