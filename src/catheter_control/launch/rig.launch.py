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

The nodes, their order and their launch arguments are the graph description
(catheter_control/graph_description.py) that ``bringup`` starts too; the arguments this file
shares with ``sim.launch.py`` are in catheter_control/launch_common.py.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import PathJoinSubstitution
from launch_ros.substitutions import FindPackageShare

from catheter_control.launch_common import (
    compensator_arguments,
    graph_actions,
    graph_arguments,
    namespace_argument,
)


def generate_launch_description() -> LaunchDescription:
    """Arguments, then the rig graph's nodes (graph_description.GRAPH), in start order."""
    config = PathJoinSubstitution([FindPackageShare("catheter_driver"), "config"])
    arguments = [
        namespace_argument(
            "namespace of every node (the shipped driver configs are keyed for catheter)"
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
        *compensator_arguments(
            model_dir_description="model directory for the compensator ('' = the shipped one, "
            "fitted on the simulated rig); hash-checked on load",
            require_tip_angle_default="false",
            require_tip_angle_description="compensator stops when the laser's tip/angle goes stale",
            accept_trajectories_description="false: the compensator does not subscribe to "
            "trajectory, so nothing on the network can make it move the catheter",
        ),
        *graph_arguments("rig"),
    ]
    return LaunchDescription(
        [
            *arguments,
            *graph_actions(
                "rig", source="rig.launch.py", hardware="rig (valve_driver, laser_angle)"
            ),
        ]
    )
