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

The nodes, their order and their launch arguments are the graph description
(catheter_control/graph_description.py) that ``bringup`` starts too; the arguments this file
shares with ``rig.launch.py`` are in catheter_control/launch_common.py.
"""

from launch import LaunchDescription

from catheter_control.launch_common import (
    compensator_arguments,
    graph_actions,
    graph_arguments,
    namespace_argument,
    plant_argument,
)


def generate_launch_description() -> LaunchDescription:
    """Arguments, then the simulated graph's nodes (graph_description.GRAPH), in start order."""
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
    return LaunchDescription(
        [
            *arguments,
            *graph_actions(
                "sim",
                source="sim.launch.py",
                hardware="simulated thesis rig (catheter_driver sim_hardware)",
            ),
        ]
    )
