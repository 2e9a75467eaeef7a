"""The node graph, described once: which nodes, in what order, how each is run and managed.

``bringup``, ``follow_trajectory --sim``, ``commission`` (through :mod:`catheter_control.bringup`)
and both launch files (through :mod:`catheter_control.launch_common`) build their graph from
:data:`GRAPH`. A node added here, a node made a lifecycle node, or a start order changed, is
changed for every launcher at once; tests/catheter_control/test_launch_files.py checks that
what the launch files start is what ``bringup`` starts, parameter for parameter.

Two graphs share the recorder, the compensator and ``tip_tf``: ``sim`` puts the simulated rig
(``sim_hardware``) under them, ``rig`` the real drivers (``valve_driver``, ``laser_angle``).
Nothing here imports ROS: the description is data, read by the launchers that import it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

GraphName = Literal["sim", "rig"]

ParamType = Literal["str", "float", "bool", "int"]


@dataclass(frozen=True)
class GraphNode:
    """One node of the graph.

    Attributes:
        name: the ROS node name (in the graph's namespace).
        package: the ament package that installs it.
        executable: its ``ros2 run`` name (a console script of ``package``).
        module: the Python module whose ``main`` runs it (what ``bringup`` starts).
        graphs: the graphs it is part of.
        lifecycle: a lifecycle node: it waits, unconfigured, until its launcher configures
            and activates it (in start order).
        launch_condition: the launch argument (``true``/``false``) that runs it, if optional.
        launch_params: parameter -> (launch argument, type) that the launch files pass it;
            ``bringup`` passes the same through its own flags.
        param_files: launch arguments naming parameter files it reads (the rig's drivers).
        rt_priority: it has a deadline loop and takes the ``rt_priority`` argument.
    """

    name: str
    package: str
    executable: str
    module: str
    graphs: frozenset[str]
    lifecycle: bool = False
    launch_condition: str | None = None
    launch_params: Mapping[str, tuple[str, ParamType]] = field(default_factory=dict)
    param_files: tuple[str, ...] = ()
    rt_priority: bool = False


COMPENSATOR_LAUNCH_PARAMS: Mapping[str, tuple[str, ParamType]] = {
    "compensator": ("compensator", "str"),
    "model_dir": ("model_dir", "str"),
    "feedback": ("feedback", "str"),
    "feedback_gains": ("feedback_gains", "str"),
    "feedforward_shaping": ("feedforward_shaping", "str"),
    "control_rate_hz": ("control_rate_hz", "float"),
    "require_tip_angle": ("require_tip_angle", "bool"),
    "accept_trajectories": ("accept_trajectories", "bool"),
}
"""The compensator's parameters that are launch arguments of the same name."""

BOTH = frozenset({"sim", "rig"})

GRAPH: tuple[GraphNode, ...] = (
    # The recorder first: it must hear every stream from the first sample on.
    GraphNode(
        "recorder",
        "catheter_control",
        "recorder",
        "catheter_control.recorder_node",
        BOTH,
        launch_condition="record",
    ),
    GraphNode(
        "sim_hardware",
        "catheter_driver",
        "sim_hardware",
        "catheter_driver.sim_hardware_node",
        frozenset({"sim"}),
        lifecycle=True,
        launch_params={"plant": ("plant", "str")},
        rt_priority=True,
    ),
    GraphNode(
        "valve_driver",
        "catheter_driver",
        "valve_driver",
        "catheter_driver.valve_driver_node",
        frozenset({"rig"}),
        lifecycle=True,
        param_files=("valve_config",),
        rt_priority=True,
    ),
    GraphNode(
        "laser_angle",
        "catheter_driver",
        "laser_angle",
        "catheter_driver.laser_angle_node",
        frozenset({"rig"}),
        lifecycle=True,
        param_files=("laser_config",),
        rt_priority=True,
    ),
    # After the drivers: it is activated once the rig it commands is.
    GraphNode(
        "compensator",
        "catheter_control",
        "compensator",
        "catheter_control.compensator_node",
        BOTH,
        lifecycle=True,
        launch_params=COMPENSATOR_LAUNCH_PARAMS,
        rt_priority=True,
    ),
    GraphNode(
        "tip_tf",
        "catheter_control",
        "tip_tf",
        "catheter_control.tip_tf",
        BOTH,
        launch_condition="tf",
    ),
)
"""Every node of both graphs, in start order (stopped in reverse)."""

DEACTIVATE_FIRST = ("compensator",)
"""Deactivated before any process is stopped: the compensator ramps the pressure down."""

SIM_COMPENSATOR_PARAMS: dict[str, object] = {"require_tip_angle": True}
"""What the simulated graph gives the compensator beyond its defaults: the simulated rig has a
laser, so a run stops if tip/angle goes quiet (a patient's catheter would not)."""

BY_NAME: Mapping[str, GraphNode] = {node.name: node for node in GRAPH}
"""Each node by its ROS name."""

LIFECYCLE_MODULES = frozenset(node.module for node in GRAPH if node.lifecycle)
"""Modules of the nodes that wait, unconfigured, for a manager to configure and activate them."""

GRAPH_NODES = frozenset(BY_NAME)
"""The names of the nodes a launcher starts: another graph's are what clash."""


def graph_nodes(graph: GraphName) -> list[GraphNode]:
    """The nodes of ``graph`` in start order."""
    return [node for node in GRAPH if graph in node.graphs]
