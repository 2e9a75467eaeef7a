"""Builders and readers for the contract's messages (docs/interfaces.md), in one place.

Pressures on topics are absolute (FluidPressure says so); the code around them works in gauge
pascal, so the conversion happens here and nowhere else.
"""

from __future__ import annotations

import math

from builtin_interfaces.msg import Time
from sensor_msgs.msg import FluidPressure, JointState, Range

from catheter_models.contract import BEND_JOINT
from catheter_models.units import AMBIENT_PRESSURE_PA, NS_PER_S


def time_from_ns(stamp_ns: int) -> Time:
    """builtin_interfaces/Time from integer nanoseconds."""
    return Time(sec=stamp_ns // NS_PER_S, nanosec=stamp_ns % NS_PER_S)


def ns_from_time(stamp: Time) -> int:
    """Integer nanoseconds from builtin_interfaces/Time."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def fluid_pressure(
    gauge_pa: float, stamp_ns: int, frame_id: str = "", ambient_pa: float = AMBIENT_PRESSURE_PA
) -> FluidPressure:
    """FluidPressure (absolute, as the message defines) from gauge pressure [Pa]."""
    msg = FluidPressure()
    msg.header.stamp = time_from_ns(stamp_ns)
    msg.header.frame_id = frame_id
    msg.fluid_pressure = float(gauge_pa) + ambient_pa
    msg.variance = 0.0
    return msg


def gauge_pa_from(msg: FluidPressure, ambient_pa: float = AMBIENT_PRESSURE_PA) -> float:
    """Gauge pressure [Pa] carried by a FluidPressure (which is absolute)."""
    return float(msg.fluid_pressure) - ambient_pa


def joint_state(angle_rad: float, stamp_ns: int, joint: str = BEND_JOINT) -> JointState:
    """JointState for the bend joint at ``angle_rad``."""
    msg = JointState()
    msg.header.stamp = time_from_ns(stamp_ns)
    msg.name = [joint]
    msg.position = [float(angle_rad)]
    return msg


def angle_rad_from(msg: JointState, joint: str = BEND_JOINT) -> float:
    """The bend joint's position [rad]; ValueError names the joints present if it is absent."""
    try:
        index = list(msg.name).index(joint)
    except ValueError:
        raise ValueError(f"JointState has no joint {joint!r}; it has {list(msg.name)!r}") from None
    if index >= len(msg.position):
        raise ValueError(f"JointState names {joint!r} but carries no position for it")
    return float(msg.position[index])


def laser_range(
    distance_m: float, stamp_ns: int, min_m: float, max_m: float, frame_id: str = "laser"
) -> Range:
    """sensor_msgs/Range for the laser distance to the tip marker [m]."""
    msg = Range()
    msg.header.stamp = time_from_ns(stamp_ns)
    msg.header.frame_id = frame_id
    msg.radiation_type = Range.INFRARED
    # A laser spot, not a cone: the field of view is effectively zero.
    msg.field_of_view = 0.0
    msg.min_range = float(min_m)
    msg.max_range = float(max_m)
    msg.range = float(distance_m) if math.isfinite(distance_m) else math.nan
    return msg


def message_class(msgtype: str) -> type:
    """The rclpy message class for a ROS type name like ``sensor_msgs/msg/FluidPressure``."""
    import importlib

    package, kind, name = msgtype.split("/")
    try:
        return getattr(importlib.import_module(f"{package}.{kind}"), name)  # type: ignore[no-any-return]
    except (ImportError, AttributeError):
        raise ValueError(f"message type {msgtype!r} is not installed") from None
