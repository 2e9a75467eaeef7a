"""ROS conventions of every node, in-process: strict parameters, QoS overrides, lifecycle.

Each node is built on a private rclpy context with the overrides a user would pass after
``--ros-args``; nothing is spun and no loop starts unless a test activates the node.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import rclpy
from rclpy.context import Context
from rclpy.lifecycle import TransitionCallbackReturn
from trajectory_msgs.msg import JointTrajectory

from catheter_control.compensator_node import CompensatorNode
from catheter_driver.laser_angle_node import LaserAngleNode
from catheter_driver.sim_hardware_node import SimHardwareNode
from catheter_driver.valve_driver_node import ValveDriverNode
from catheter_models.errors import ParameterError
from catheter_ros.params import refuse_undeclared_overrides


@contextmanager
def built(cls: type, *ros_args: str) -> Iterator[Any]:
    """``cls()`` on a fresh context initialised with ``--ros-args -r __ns:=/catheter ...``."""
    context = Context()
    rclpy.init(args=["test", "--ros-args", "-r", "__ns:=/catheter", *ros_args], context=context)
    original = rclpy.node.Node.__init__

    def on_context(self: Any, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("context", context)
        original(self, *args, **kwargs)

    node = None
    try:
        with pytest.MonkeyPatch.context() as mp:
            # The node classes take no context argument (run_nodes gives them the default).
            mp.setattr(rclpy.node.Node, "__init__", on_context)
            node = cls()
        yield node
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.shutdown(context=context)


@pytest.mark.parametrize(
    ("cls", "override", "suggestion"),
    [
        (CompensatorNode, "max_pressure_p:=2.0e5", "max_pressure_pa"),
        (SimHardwareNode, "command_timeout:=0.5", "command_timeout_s"),
        (ValveDriverNode, "watchdog:=0.5", "watchdog_s"),
        (LaserAngleNode, "zero_duration:=2.0", "zero_duration_s"),
    ],
)
def test_a_misspelt_parameter_is_refused_by_name_with_the_close_match(
    cls: type, override: str, suggestion: str
) -> None:
    name = override.split(":=", maxsplit=1)[0]
    with built(cls, "-p", override) as node, pytest.raises(ParameterError) as err:
        refuse_undeclared_overrides(node)
    assert f"unknown parameter {name!r} (did you mean {suggestion!r}?)" in str(err.value)


def test_device_options_qos_overrides_and_use_sim_time_stay_allowed() -> None:
    with built(
        ValveDriverNode,
        "-p",
        "valve.backend:=dac_serial",
        "-p",
        "valve.port:=/dev/ttyX",
        "-p",
        "transmitter.baudrate:=115200",
        "-p",
        "use_sim_time:=false",
        "-p",
        "qos_overrides./catheter/pressure/measured.publisher.depth:=50",
    ) as node:
        refuse_undeclared_overrides(node)  # nothing refused
        assert node.get_parameter("valve.port").value == "/dev/ttyX"
    # A device option under a prefix the node does not own is as unknown as any other.
    with (
        built(ValveDriverNode, "-p", "vavle.port:=/dev/ttyX") as node,
        pytest.raises(ParameterError, match=r"'vavle\.port'"),
    ):
        refuse_undeclared_overrides(node)


def test_a_qos_override_changes_the_sensor_stream_and_the_default_stays() -> None:
    with built(SimHardwareNode) as node:
        assert node._pub_pressure.qos_profile.depth == 500
    with built(
        SimHardwareNode,
        "-p",
        "qos_overrides./catheter/pressure/measured.publisher.depth:=20",
        "-p",
        "qos_overrides./catheter/tip/angle.publisher.reliability:=best_effort",
    ) as node:
        assert node._pub_pressure.qos_profile.depth == 20
        assert node._pub_angle.qos_profile.reliability.name == "BEST_EFFORT"
        assert node._pub_distance.qos_profile.depth == 500  # only what was asked changes


@pytest.mark.parametrize(
    ("override", "named"),
    [
        ("qos_overrides./catheter/pressure/command.publisher.depth:=0", "depth must be >= 1"),
        ("qos_overrides./catheter/pressure/command.publisher.reliability:=sometimes", "sometimes"),
        ("qos_overrides./catheter/pressure/command.publisher.depth:=deep", "publisher.depth"),
    ],
)
def test_a_bad_qos_override_is_refused_by_name(override: str, named: str) -> None:
    with pytest.raises(ParameterError) as err, built(CompensatorNode, "-p", override):
        pass
    assert "qos_overrides./catheter/pressure/command.publisher" in str(err.value)
    assert named in str(err.value)


def _trajectory() -> JointTrajectory:
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectoryPoint

    msg = JointTrajectory()
    msg.joint_names = ["bend"]
    for t, angle in ((0, 0.0), (2, 0.1)):
        point = JointTrajectoryPoint()
        point.positions = [angle]
        point.time_from_start = Duration(sec=t)
        msg.points.append(point)
    return msg


def test_the_compensator_moves_nothing_until_activated_and_configure_names_a_bad_model(
    tmp_path: Any,
) -> None:
    with built(CompensatorNode, "-p", "rt_priority:=0") as node:
        # Built, not configured: no model loaded, and a trajectory is refused with why.
        assert node.core is None
        assert "not active" in str(node.plan_trajectory(_trajectory()))
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node.core is not None
        assert "not active" in str(node.plan_trajectory(_trajectory()))
        assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
        assert node.plan_trajectory(_trajectory()).duration_s == pytest.approx(2.0)
        # Rates on every point: the knots are joined by a cubic, as ros2_controllers does.
        with_rates = _trajectory()
        for point in with_rates.points:
            point.velocities = [0.0]
        cubic = node.plan_trajectory(with_rates)
        assert cubic.velocity_rad_s is not None
        assert cubic.desired_at(0.5) == pytest.approx(0.1 * (3 * 0.25**2 - 2 * 0.25**3))
        # On some points only: refused, naming the first point that differs.
        with_rates.points[1].velocities = []
        assert "point 1 lacks velocities" in str(node.plan_trajectory(with_rates))
        assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
        assert node.active_loop is None
    with built(CompensatorNode, "-p", f"model_dir:={tmp_path}") as node:
        assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
        assert "configure failed" in node.transition_failure
        assert str(tmp_path) in node.transition_failure
        assert node.core is None
