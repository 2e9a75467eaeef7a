"""Declare ROS parameters from the science core's BoundedParam tables, with ranges.

The range lives in one place (the BoundedParam); ROS gets it as a FloatingPointRange descriptor,
so ``ros2 param set`` and launch overrides out of range are refused by rclpy itself, and the
node re-checks at start-up to give a message that names the range.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from catheter_models.errors import ParameterError
from catheter_models.limits import BoundedParam


def declare_float(node: Node, name: str, spec: BoundedParam, read_only: bool = True) -> float:
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


_TYPE_NAMES = {
    Parameter.Type.BOOL: "a bool",
    Parameter.Type.INTEGER: "an integer",
    Parameter.Type.DOUBLE: "a double",
    Parameter.Type.STRING: "a string",
}


def _type_name(kind: Parameter.Type) -> str:
    return _TYPE_NAMES.get(kind, kind.name.lower().replace("_", " "))


def type_refusal(name: str, expected: Parameter.Type, given: Parameter[Any]) -> str:
    """One line for a parameter given with the wrong type: its name, the type, what was given."""
    return (
        f"parameter {name!r} refused: expects {_type_name(expected)}, "
        f"got {given.value!r} ({_type_name(given.type_)})"
    )


def _widen_integer_override(node: Node, name: str, default: Any) -> None:
    """Take an integer override of a double parameter as that double.

    ``-p control_rate_hz:=1000`` is what a person types for 1 kHz; ROS reads ``1000`` as an
    integer and rclpy refuses it for a double parameter. Every integer is exactly a double
    up to 2**53, far beyond any of our ranges, so nothing is lost. Nothing else is converted:
    a string, or a double for an integer parameter, is refused by the caller with its type.
    """
    overrides: dict[str, Parameter[Any]] = getattr(node, "_parameter_overrides", {})
    given = overrides.get(name)
    if given is not None and isinstance(default, float) and given.type_ == Parameter.Type.INTEGER:
        overrides[name] = Parameter(name, Parameter.Type.DOUBLE, float(given.value))


def _declare(node: Node, name: str, default: Any, descriptor: ParameterDescriptor) -> Any:
    """Declare, or adopt a parameter the node already declared from a command-line override.

    Driver nodes declare their ``<device>.*`` options from the overrides (see
    ``lifecycle_node.declare_device_options``), and rclpy declares ``qos_overrides.*`` as
    publishers are made, so a name may exist before we declare it. Its value is still checked
    against the range by the caller.

    Raises:
        ParameterError: the override has another type than the default's (an integer for a
            double is taken as the double); one line naming the parameter, the type it
            expects and what was given.
    """
    if node.has_parameter(name):
        value = node.get_parameter(name).value
        return default if value is None else value
    _widen_integer_override(node, name, default)
    try:
        return node.declare_parameter(name, default, descriptor).value
    except InvalidParameterTypeException:
        overrides: dict[str, Parameter[Any]] = getattr(node, "_parameter_overrides", {})
        expected = Parameter.Type.from_parameter_value(default)
        raise ParameterError(type_refusal(name, expected, overrides[name])) from None


ALWAYS_ALLOWED = ("use_sim_time",)
"""Parameters every rclpy node declares itself (an override may name them at any node)."""

QOS_OVERRIDES_PREFIX = "qos_overrides."
"""REP 2003's QoS parameters (``qos_overrides./ns/topic.publisher.depth``). rclpy declares
them for the topics a node makes overridable, and only when that topic is created; one for a
topic the node does not offer is left unused, as everywhere in ROS 2."""


def undeclared_overrides(node: Node, allowed_prefixes: Iterable[str] = ()) -> list[str]:
    """Names of command-line or params-file overrides the node never declared.

    A misspelt ``max_pressure_p`` would otherwise leave the safety limit at its default
    without a word: rclpy keeps undeclared overrides to itself.
    """
    prefixes = (QOS_OVERRIDES_PREFIX, *allowed_prefixes)
    overrides: dict[str, Any] = getattr(node, "_parameter_overrides", {})
    return sorted(
        name
        for name in overrides
        if not node.has_parameter(name)
        and name not in ALWAYS_ALLOWED
        and not name.startswith(prefixes)
    )


def refuse_undeclared_overrides(node: Node, allowed_prefixes: Iterable[str] = ()) -> None:
    """Raise ParameterError naming every override ``node`` does not declare, with a close match.

    Called once a node has declared everything it reads (``node_main.run_nodes`` does it for
    every node it builds), so it sees the node's full set.
    """
    unknown = undeclared_overrides(node, allowed_prefixes)
    if not unknown:
        return
    # rclpy has no public list of a node's declared names (list_parameters answers a service).
    declared = sorted(n for n in node._parameters if not n.startswith(QOS_OVERRIDES_PREFIX))
    parts = []
    for name in unknown:
        close = difflib.get_close_matches(name, declared, n=1, cutoff=0.6)
        parts.append(f"{name!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    plural = "s" if len(parts) > 1 else ""
    raise ParameterError(
        f"{node.get_fully_qualified_name()}: unknown parameter{plural} {', '.join(parts)} "
        "(refused: an override the node does not read would be silently ignored)"
    )
