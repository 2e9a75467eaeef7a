"""Helpers shared by the lifecycle-managed nodes (drivers and compensator).

Who drives the transitions: a launch file (``LifecycleNode`` with configure and activate
events), ``bringup`` (catheter_ros.lifecycle_client), or ``ros2 lifecycle set``. For a
node run alone, ``autostart:=true`` makes it configure and activate itself; by default it
waits, unconfigured, so nothing moves until whoever launched it says so.
"""

from __future__ import annotations

from typing import Any

from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.parameter import Parameter

from catheter_models.errors import CatheterError, ParameterError
from catheter_ros.params import declare_plain


def declare_autostart(node: LifecycleNode) -> bool:
    """The ``autostart`` parameter (default false): configure and activate without a manager."""
    return bool(
        declare_plain(
            node,
            "autostart",
            False,
            "configure and activate at start-up without a lifecycle manager (for a node run "
            "alone; launch files and bringup drive the transitions themselves)",
        )
    )


def autostart_once(node: LifecycleNode) -> None:
    """Configure then activate ``node`` now; raise CatheterError naming why if either fails.

    For nodes whose configure cannot succeed later by waiting (a model that fails its hash
    check stays failed): the process exits with code 2 and the reason (the node's
    ``transition_failure``, if it keeps one).
    """
    name = node.get_fully_qualified_name()
    for what, trigger in (
        ("configure", node.trigger_configure),
        ("activate", node.trigger_activate),
    ):
        if trigger() != TransitionCallbackReturn.SUCCESS:
            reason = getattr(node, "transition_failure", "") or f"{what} failed (see the log)"
            raise CatheterError(f"{name}: {reason}")


def declare_device_options(node: LifecycleNode, prefix: str) -> None:
    """Declare every ``prefix.*`` override (read-only), so the strict check accepts them.

    Each backend takes its own options (a serial port and baud rate, a CAN channel and node
    id, ...), so they are not declared one by one: the node takes any ``prefix.*`` override
    and hands the lot to the device factory at configure, which refuses unknown names by
    name. Options under other names are refused at start-up like any unknown parameter.
    """
    from rcl_interfaces.msg import ParameterDescriptor

    overrides: dict[str, Parameter[Any]] = getattr(node, "_parameter_overrides", {})
    for name, param in overrides.items():
        if name.startswith(f"{prefix}.") and not node.has_parameter(name):
            node.declare_parameter(
                name,
                param.value,
                ParameterDescriptor(
                    description=f"{prefix} device option (checked by the device factory)",
                    read_only=True,
                    dynamic_typing=True,
                ),
            )


def device_options(node: LifecycleNode, prefix: str) -> tuple[str, dict[str, Any]]:
    """``(backend, options)`` from the parameters under ``prefix.`` (e.g. ``valve.backend``)."""
    params: dict[str, Parameter[Any]] = node.get_parameters_by_prefix(prefix)
    options = {name: p.value for name, p in params.items()}
    backend = options.pop("backend", None)
    if not backend:
        raise ParameterError(
            f"parameter {prefix}.backend is required (e.g. --ros-args -p {prefix}.backend:=...)"
        )
    return str(backend), options
