"""The simulated graph: ``sim_hardware``, ``compensator`` and ``recorder`` in one namespace.

    ros2 launch catheter_control sim.launch.py
    ros2 launch catheter_control sim.launch.py compensator:=idrdpi control_rate_hz:=1000.0
    ros2 launch catheter_control sim.launch.py record:=false namespace:=catheter2

Then, from another shell on the same ROS_DOMAIN_ID, send a trajectory to the running graph
(without ``--sim``, ``follow_trajectory`` starts nothing and uses the nodes that are up):

    ros2 run catheter_control follow_trajectory --preset traj_up_chirp

The same graph as ``bringup --bag PATH`` (catheter_control/bringup.py), which needs no launch
package; tests/catheter_control/test_launch_files.py checks that both start the same nodes
with the same parameters. ``sim_hardware`` and ``compensator`` are lifecycle nodes: this file
configures each, and activates it once it is inactive (the standard launch_ros pattern).

One difference from ``bringup``: on Ctrl-C, launch signals every node at once, where
``bringup`` deactivates the compensator first (a ramp-down) and stops the recorder last. The
compensator still ramps down on SIGINT if the rig outlives it, and the safety does not depend
on it (the simulated driver vents by its own watchdog), but the bag may miss the last vent.
"""

import time
from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.conditions import IfCondition
from launch.events import matches_action
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.parameter_descriptions import ParameterValue
from lifecycle_msgs.msg import Transition


def configure_then_activate(node: LifecycleNode) -> list:
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


def generate_launch_description() -> LaunchDescription:
    """Arguments, then the recorder, the simulated rig and the compensator, in start order."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    default_bag = str(Path.cwd() / "runs" / f"{stamp}-sim" / "bag")
    namespace = LaunchConfiguration("namespace")
    rt_priority = ParameterValue(LaunchConfiguration("rt_priority"), value_type=int)
    arguments = [
        DeclareLaunchArgument(
            "namespace", default_value="catheter", description="namespace of every node"
        ),
        DeclareLaunchArgument(
            "compensator",
            default_value="clstm",
            choices=["clstm", "idrdpi", "none"],
            description="feedforward compensator (none: static inverse, no hysteresis model)",
        ),
        DeclareLaunchArgument(
            "model_dir",
            default_value="",
            description="model directory for the compensator ('' = the shipped one); "
            "hash-checked on load",
        ),
        DeclareLaunchArgument(
            "control_rate_hz", default_value="250.0", description="control loop rate [Hz]"
        ),
        DeclareLaunchArgument(
            "feedback",
            default_value="none",
            choices=["none", "pi"],
            description="feedback on tip/angle beside the compensator (pi: gains from "
            "feedback_gains; tip/angle is then required)",
        ),
        DeclareLaunchArgument(
            "feedback_gains",
            default_value="",
            description="feedback.json from catheter-lab tune ('' = the one in model_dir, or "
            "the shipped one, tuned on the simulated rig)",
        ),
        DeclareLaunchArgument(
            "require_tip_angle",
            default_value="true",
            choices=["true", "false"],
            description="compensator stops when tip/angle goes stale (the simulated rig has a "
            "laser)",
        ),
        DeclareLaunchArgument(
            "accept_trajectories",
            default_value="true",
            choices=["true", "false"],
            description="false: the compensator does not subscribe to trajectory",
        ),
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
    recorder = Node(
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
                        '{"source": "sim.launch.py", "hardware": "simulated thesis rig '
                        '(catheter_driver sim_hardware)", "compensator": "',
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
    sim_hardware = LifecycleNode(
        package="catheter_driver",
        executable="sim_hardware",
        name="sim_hardware",
        namespace=namespace,
        parameters=[{"rt_priority": rt_priority}],
        output="screen",
    )
    compensator = LifecycleNode(
        package="catheter_control",
        executable="compensator",
        name="compensator",
        namespace=namespace,
        parameters=[
            {
                "compensator": ParameterValue(LaunchConfiguration("compensator"), value_type=str),
                "model_dir": ParameterValue(LaunchConfiguration("model_dir"), value_type=str),
                "feedback": ParameterValue(LaunchConfiguration("feedback"), value_type=str),
                "feedback_gains": ParameterValue(
                    LaunchConfiguration("feedback_gains"), value_type=str
                ),
                "control_rate_hz": ParameterValue(
                    LaunchConfiguration("control_rate_hz"), value_type=float
                ),
                "require_tip_angle": ParameterValue(
                    LaunchConfiguration("require_tip_angle"), value_type=bool
                ),
                "accept_trajectories": ParameterValue(
                    LaunchConfiguration("accept_trajectories"), value_type=bool
                ),
                "rt_priority": rt_priority,
            }
        ],
        output="screen",
    )
    tip_tf = Node(
        package="catheter_control",
        executable="tip_tf",
        name="tip_tf",
        namespace=namespace,
        condition=IfCondition(LaunchConfiguration("tf")),
        output="screen",
    )
    return LaunchDescription(
        [
            *arguments,
            recorder,
            sim_hardware,
            compensator,
            tip_tf,
            *configure_then_activate(sim_hardware),
            *configure_then_activate(compensator),
        ]
    )
