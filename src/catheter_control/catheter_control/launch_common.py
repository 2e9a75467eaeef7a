"""What ``sim.launch.py`` and ``rig.launch.py`` share: arguments, nodes, lifecycle wiring.

The two launch files start the same recorder, compensator and ``tip_tf`` beside different
drivers (the simulated rig, or the real valve driver and laser). Which nodes, in what order,
which are lifecycle nodes and which launch arguments each takes is the graph description
(:mod:`catheter_control.graph_description`), which ``bringup`` builds from too;
:func:`graph_actions` turns it into launch actions. The arguments live here so the two files
cannot drift apart, and so the compensator's choices and rate come from the code that defines
them (:mod:`catheter_control.models`, :mod:`catheter_models.contract`) rather than from a copy
typed into each file.

It is its own module because it imports the ROS ``launch`` packages at its top, which only a
launch process has: nothing else in catheter_control imports it.
tests/catheter_control/test_launch_files.py runs both launch files, and so this module,
against stand-ins for ``launch`` and ``launch_ros``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.conditions import IfCondition
from launch.events import matches_action
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.parameter_descriptions import ParameterValue
from lifecycle_msgs.msg import Transition

from catheter_control.graph_description import GraphName, GraphNode, graph_nodes
from catheter_control.models import COMPENSATORS, DEFAULT_COMPENSATOR, FEEDBACKS
from catheter_models.contract import CONTROL_RATE_HZ
from catheter_models.shaping import SHAPERS


def configure_then_activate(node: LifecycleNode) -> list[Any]:
    """Configure ``node`` at launch, and activate it when it reaches inactive from configuring.

    ``start_state`` matters: a later deactivate (active -> inactive) must not re-activate it.
    """
    return [
        RegisterEventHandler(
            OnStateTransition(
                target_lifecycle_node=node,
                start_state="configuring",
                goal_state="inactive",
                entities=[
                    EmitEvent(
                        event=ChangeState(
                            lifecycle_node_matcher=matches_action(node),
                            transition_id=Transition.TRANSITION_ACTIVATE,
                        )
                    )
                ],
            )
        ),
        EmitEvent(
            event=ChangeState(
                lifecycle_node_matcher=matches_action(node),
                transition_id=Transition.TRANSITION_CONFIGURE,
            )
        ),
    ]


def namespace_argument(description: str = "namespace of every node") -> DeclareLaunchArgument:
    """``namespace``: where every node of the graph lives (``catheter``)."""
    return DeclareLaunchArgument("namespace", default_value="catheter", description=description)


def compensator_arguments(
    *,
    model_dir_description: str,
    require_tip_angle_default: str,
    require_tip_angle_description: str,
    accept_trajectories_description: str,
) -> list[DeclareLaunchArgument]:
    """The compensator's arguments, in the order ``--show-args`` lists them.

    The defaults that differ between the simulated and the real rig (whether the laser is
    required) and the descriptions that say so are the caller's.
    """
    return [
        DeclareLaunchArgument(
            "compensator",
            # '': the kind model_dir's manifest names, else the default; a kind given beside a
            # model_dir of another kind fails the compensator's configure with both named.
            default_value="",
            # Alphabetical, as the launch files have always listed them.
            choices=["", *sorted(COMPENSATORS)],
            description="feedforward compensator (none: static inverse, no hysteresis model; "
            f"'' = the kind model_dir holds, else {DEFAULT_COMPENSATOR})",
        ),
        DeclareLaunchArgument("model_dir", default_value="", description=model_dir_description),
        DeclareLaunchArgument(
            "control_rate_hz",
            default_value=str(CONTROL_RATE_HZ),
            description="control loop rate [Hz]",
        ),
        DeclareLaunchArgument(
            "feedback",
            default_value="",
            choices=["", *FEEDBACKS],
            description="feedback on tip/angle beside the compensator (pi: gains from "
            "feedback_gains; tip/angle is then required); '' = what a commissioned model_dir "
            "was verified with, else none",
        ),
        DeclareLaunchArgument(
            "feedback_gains",
            default_value="",
            description="feedback.json from catheter-lab tune ('' = the one in model_dir, or "
            "the shipped one, tuned on the simulated rig)",
        ),
        DeclareLaunchArgument(
            "feedforward_shaping",
            default_value="",
            choices=["", *SHAPERS],
            description="input shaping of the feedforward (zvd: does not ring the tip mode "
            "that feedback_gains' tuning identified); '' = what a commissioned model_dir was "
            "verified with, else none",
        ),
        DeclareLaunchArgument(
            "require_tip_angle",
            default_value=require_tip_angle_default,
            choices=["true", "false"],
            description=require_tip_angle_description,
        ),
        DeclareLaunchArgument(
            "accept_trajectories",
            default_value="true",
            choices=["true", "false"],
            description=accept_trajectories_description,
        ),
    ]


def graph_arguments(run_label: str) -> list[DeclareLaunchArgument]:
    """Scheduling, what else runs, and where the bag goes (``runs/<time>-<run_label>/bag``)."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    default_bag = str(Path.cwd() / "runs" / f"{stamp}-{run_label}" / "bag")
    return [
        DeclareLaunchArgument(
            "rt_priority",
            default_value="50",
            description="SCHED_FIFO priority of the loops (0: normal scheduling)",
        ),
        DeclareLaunchArgument(
            "record", default_value="true", choices=["true", "false"], description="run recorder"
        ),
        DeclareLaunchArgument(
            "tf",
            default_value="true",
            choices=["true", "false"],
            description="run tip_tf: robot_description, joint_states and /tf from tip/angle",
        ),
        DeclareLaunchArgument(
            "bag_path",
            default_value=default_bag,
            description="new bag directory (must not exist)",
        ),
    ]


def plant_argument() -> DeclareLaunchArgument:
    """``plant``: a lab's own plant (``module:factory``) behind ``sim_hardware``."""
    return DeclareLaunchArgument(
        "plant",
        default_value="",
        description="the simulated catheter as module:factory (docs/simulated_rig.md); "
        "'' = the shipped thesis plant",
    )


def rt_priority_parameter() -> ParameterValue:
    """The ``rt_priority`` argument as the integer parameter the loop nodes declare."""
    return ParameterValue(LaunchConfiguration("rt_priority"), value_type=int)


def recorder_node(namespace: LaunchConfiguration, source: str, hardware: str) -> Node:
    """The recorder, if ``record``; the bag's metadata names the launch file and the rig.

    ``source`` and ``hardware`` are plain text (no quotes) spliced into a JSON object.
    """
    return Node(
        package="catheter_control",
        executable="recorder",
        name="recorder",
        namespace=namespace,
        condition=IfCondition(LaunchConfiguration("record")),
        parameters=[
            {
                "bag_path": ParameterValue(LaunchConfiguration("bag_path"), value_type=str),
                # A JSON object as a string parameter: typed, or launch would parse it as YAML.
                "custom_data": ParameterValue(
                    [
                        f'{{"source": "{source}", "hardware": "{hardware}", "compensator": "',
                        LaunchConfiguration("compensator"),
                        '", "model_dir": "',
                        LaunchConfiguration("model_dir"),
                        '"}',
                    ],
                    value_type=str,
                ),
            }
        ],
        output="screen",
    )


_VALUE_TYPES: dict[str, type] = {"str": str, "float": float, "bool": bool, "int": int}


def launch_node(
    spec: GraphNode, namespace: LaunchConfiguration, rt_priority: ParameterValue
) -> Any:
    """One node of the graph description as a ``Node`` or ``LifecycleNode`` action.

    Its parameter files come first, then its launch arguments as typed parameters (a string
    argument stays a string, so ``''`` and JSON are not read as YAML), then ``rt_priority``.
    """
    values: dict[str, Any] = {
        param: ParameterValue(LaunchConfiguration(argument), value_type=_VALUE_TYPES[kind])
        for param, (argument, kind) in spec.launch_params.items()
    }
    if spec.rt_priority:
        values["rt_priority"] = rt_priority
    parameters: list[Any] = [LaunchConfiguration(name) for name in spec.param_files]
    if values:
        parameters.append(values)
    kwargs: dict[str, Any] = {
        "package": spec.package,
        "executable": spec.executable,
        "name": spec.name,
        "namespace": namespace,
        "output": "screen",
    }
    if parameters:
        kwargs["parameters"] = parameters
    if spec.launch_condition:
        kwargs["condition"] = IfCondition(LaunchConfiguration(spec.launch_condition))
    return (LifecycleNode if spec.lifecycle else Node)(**kwargs)


def graph_actions(graph: GraphName, *, source: str, hardware: str) -> list[Any]:
    """Every node of ``graph`` in start order, then each lifecycle node's configure/activate.

    ``source`` and ``hardware`` go into the bag's metadata (see :func:`recorder_node`).
    """
    namespace = LaunchConfiguration("namespace")
    rt_priority = rt_priority_parameter()
    nodes: list[Any] = []
    transitions: list[Any] = []
    for spec in graph_nodes(graph):
        if spec.name == "recorder":
            node = recorder_node(namespace, source, hardware)
        else:
            node = launch_node(spec, namespace, rt_priority)
        nodes.append(node)
        if spec.lifecycle:
            transitions += configure_then_activate(node)
    return nodes + transitions
