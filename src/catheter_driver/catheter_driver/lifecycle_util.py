"""Helpers shared by the lifecycle-managed driver nodes."""

from __future__ import annotations

from typing import Any

from rclpy.lifecycle import LifecycleNode
from rclpy.parameter import Parameter

from catheter_models.errors import ParameterError


def device_options(node: LifecycleNode, prefix: str) -> tuple[str, dict[str, Any]]:
    """``(backend, options)`` from the parameters under ``prefix.`` (e.g. ``valve.backend``).

    Each backend takes its own options (a serial port and baud rate, a CAN channel and node
    id, ...), so they are not declared one by one: the node accepts any ``prefix.*`` override
    and hands the lot to the device factory, which refuses unknown names by name.
    """
    params: dict[str, Parameter[Any]] = node.get_parameters_by_prefix(prefix)
    options = {name: p.value for name, p in params.items()}
    backend = options.pop("backend", None)
    if not backend:
        raise ParameterError(
            f"parameter {prefix}.backend is required (e.g. --ros-args -p {prefix}.backend:=...)"
        )
    return str(backend), options
