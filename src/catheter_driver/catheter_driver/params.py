"""Declare ROS parameters from the science core's ParamSpec tables, with ranges.

The range lives in one place (the ParamSpec); ROS gets it as a FloatingPointRange descriptor,
so ``ros2 param set`` and launch overrides out of range are refused by rclpy itself, and the
node re-checks at start-up to give a message that names the range.
"""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node

from catheter_models.errors import ParameterError
from catheter_models.plant.config import ParamSpec


def declare_float(node: Node, name: str, spec: ParamSpec, read_only: bool = True) -> float:
    """Declare a float parameter with the spec's range and return its (validated) value."""
    descriptor = ParameterDescriptor(
        description=spec.doc,
        read_only=read_only,
        floating_point_range=[FloatingPointRange(from_value=spec.low, to_value=spec.high)],
    )
    try:
        value: float = _declare(node, name, float(spec.default), descriptor)
    except InvalidParameterValueException as exc:
        raise ParameterError(
            f"parameter {name!r} refused: must lie in [{spec.low:g}, {spec.high:g}] "
            f"({spec.doc}); rclpy said: {exc}"
        ) from None
    return spec.check(float(value), node.get_name())


def declare_int(
    node: Node, name: str, default: int, *, low: int, high: int, doc: str, read_only: bool = True
) -> int:
    """Declare an integer parameter with a range and return its value."""
    descriptor = ParameterDescriptor(
        description=doc,
        read_only=read_only,
        integer_range=[IntegerRange(from_value=low, to_value=high, step=1)],
    )
    try:
        value = int(_declare(node, name, default, descriptor))
    except InvalidParameterValueException as exc:
        raise ParameterError(
            f"parameter {name!r} refused: must lie in [{low}, {high}] ({doc}); rclpy said: {exc}"
        ) from None
    return value


def declare_plain(node: Node, name: str, default: Any, doc: str, read_only: bool = True) -> Any:
    """Declare a bool or string parameter (no range) and return its value."""
    descriptor = ParameterDescriptor(description=doc, read_only=read_only)
    return _declare(node, name, default, descriptor)


def _declare(node: Node, name: str, default: Any, descriptor: ParameterDescriptor) -> Any:
    """Declare, or adopt a parameter the node already declared from a command-line override.

    Driver nodes accept arbitrary ``<device>.*`` options, so they let rclpy declare every
    override automatically; a named parameter given on the command line then exists before
    we declare it. Its value is still checked against the range by the caller.
    """
    if node.has_parameter(name):
        value = node.get_parameter(name).value
        return default if value is None else value
    return node.declare_parameter(name, default, descriptor).value
