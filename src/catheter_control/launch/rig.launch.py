"""The real rig: ``valve_driver``, ``laser_angle``, ``compensator`` and ``recorder``.

    ros2 launch catheter_control rig.launch.py
    ros2 launch catheter_control rig.launch.py \
        valve_config:=$(ros2 pkg prefix --share catheter_driver)/config/valve_driver_dac_serial.yaml

The drivers read their device settings from the parameter files installed with
catheter_driver (``share/catheter_driver/config``, one per backend; docs/rig.md). Those files
are keyed by node name with the ``/catheter`` namespace (``/catheter/valve_driver:``): with
another ``namespace``, pass files keyed for it, or the drivers have no device and fail
configure, by name. The drivers and the compensator are lifecycle nodes: this file configures
each, and activates it once it is inactive (the standard launch_ros pattern); a driver whose
device does not answer stays unconfigured (its reason on /diagnostics), and
``ros2 lifecycle set /catheter/valve_driver configure`` retries. Zero the laser before the
first run (docs/rig.md).

On Ctrl-C, launch signals every node at once; the compensator ramps down if the valve driver
outlives it, and the valve driver vents on shutdown and by its watchdog whatever the order.
"""

import time
from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.conditions import IfCondition
from launch.events import matches_action
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare
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
    """Arguments, then the recorder, the two drivers and the compensator, in start order."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    default_bag = str(Path.cwd() / "runs" / f"{stamp}-rig" / "bag")
    config = PathJoinSubstitution([FindPackageShare("catheter_driver"), "config"])
    namespace = LaunchConfiguration("namespace")
    rt_priority = ParameterValue(LaunchConfiguration("rt_priority"), value_type=int)
    arguments = [
        DeclareLaunchArgument(
            "namespace",
            default_value="catheter",
            description="namespace of every node (the shipped driver configs are keyed for "
            "catheter)",
        ),
        DeclareLaunchArgument(
            "valve_config",
            default_value=PathJoinSubstitution([config, "valve_driver_canopen.yaml"]),
            description="valve_driver parameter file (valve_driver_canopen.yaml or "
            "valve_driver_dac_serial.yaml in share/catheter_driver/config, or your own)",
        ),
        DeclareLaunchArgument(
            "laser_config",
            default_value=PathJoinSubstitution([config, "laser_angle_adc_serial.yaml"]),
            description="laser_angle parameter file (laser_angle_adc_serial.yaml or "
            "laser_angle_adc_can.yaml in share/catheter_driver/config, or your own)",
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
            description="model directory for the compensator ('' = the shipped one, fitted "
            "on the simulated rig); hash-checked on load",
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
            default_value="false",
            choices=["true", "false"],
            description="compensator stops when the laser's tip/angle goes stale",
        ),
        DeclareLaunchArgument(
            "accept_trajectories",
            default_value="true",
            choices=["true", "false"],
            description="false: the compensator does not subscribe to trajectory, so nothing "
            "on the network can make it move the catheter",
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
                        '{"source": "rig.launch.py", "hardware": "rig (valve_driver, '
                        'laser_angle)", "compensator": "',
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
    valve_driver = LifecycleNode(
        package="catheter_driver",
        executable="valve_driver",
        name="valve_driver",
        namespace=namespace,
        parameters=[LaunchConfiguration("valve_config"), {"rt_priority": rt_priority}],
        output="screen",
    )
    laser_angle = LifecycleNode(
        package="catheter_driver",
        executable="laser_angle",
        name="laser_angle",
        namespace=namespace,
        parameters=[LaunchConfiguration("laser_config"), {"rt_priority": rt_priority}],
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
            valve_driver,
            laser_angle,
            compensator,
            tip_tf,
            *configure_then_activate(valve_driver),
            *configure_then_activate(laser_angle),
            *configure_then_activate(compensator),
        ]
    )
