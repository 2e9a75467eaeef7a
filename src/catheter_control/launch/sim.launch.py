"""The simulated graph: ``sim_hardware``, ``compensator`` and ``recorder`` in one namespace.

    ros2 launch catheter_control sim.launch.py
    ros2 launch catheter_control sim.launch.py compensator:=idrdpi control_rate_hz:=1000.0
    ros2 launch catheter_control sim.launch.py model_dir:=runs/idrdpi feedback:=pi
    ros2 launch catheter_control sim.launch.py plant:=my_lab.rod:make_plant
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

The arguments and nodes this file shares with ``rig.launch.py`` are in
catheter_control/launch_common.py.
"""

from launch import LaunchDescription
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode
from launch_ros.parameter_descriptions import ParameterValue

from catheter_control.launch_common import (
    compensator_arguments,
    compensator_node,
    configure_then_activate,
    graph_arguments,
    namespace_argument,
    plant_argument,
    recorder_node,
    rt_priority_parameter,
    tip_tf_node,
)


def generate_launch_description() -> LaunchDescription:
    """Arguments, then the recorder, the simulated rig and the compensator, in start order."""
    namespace = LaunchConfiguration("namespace")
    rt_priority = rt_priority_parameter()
    arguments = [
        namespace_argument(),
        *compensator_arguments(
            model_dir_description="model directory for the compensator ('' = the shipped one); "
            "hash-checked on load",
            require_tip_angle_default="true",
            require_tip_angle_description="compensator stops when tip/angle goes stale (the "
            "simulated rig has a laser)",
            accept_trajectories_description="false: the compensator does not subscribe to "
            "trajectory",
        ),
        plant_argument(),
        *graph_arguments("sim"),
    ]
    recorder = recorder_node(
        namespace, "sim.launch.py", "simulated thesis rig (catheter_driver sim_hardware)"
    )
    sim_hardware = LifecycleNode(
        package="catheter_driver",
        executable="sim_hardware",
        name="sim_hardware",
        namespace=namespace,
        parameters=[
            {
                "rt_priority": rt_priority,
                "plant": ParameterValue(LaunchConfiguration("plant"), value_type=str),
            }
        ],
        output="screen",
    )
    compensator = compensator_node(namespace, rt_priority)
    tip_tf = tip_tf_node(namespace)
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
