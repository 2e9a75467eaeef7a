"""The contract's messages and SI values, both ways.

Writers build ``FluidPressure``/``JointState``/``Range`` messages from gauge pressure [Pa],
angle [rad] and distance [m]; the loader turns decoded messages back into those values. Both
directions live here so the conversions (absolute vs gauge pressure, the ``bend`` joint, the
``Range`` validity rule) are written once.

Message objects come from a ``rosbags`` typestore: the Kilted store for writing, or the store
``rosbags`` builds from a bag's own embedded definitions for reading. Their classes are generated
at run time, so they are typed ``Any`` at this boundary.
"""

from __future__ import annotations

import functools
import math
from typing import Any, Final, NamedTuple

import numpy as np
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from catheter_models.contract import BEND_JOINT
from catheter_models.errors import BagError
from catheter_models.units import NS_PER_S, absolute_to_gauge_pa, gauge_to_absolute_pa

FLUID_PRESSURE: Final = "sensor_msgs/msg/FluidPressure"
JOINT_STATE: Final = "sensor_msgs/msg/JointState"
RANGE: Final = "sensor_msgs/msg/Range"

LASER_FIELD_OF_VIEW_RAD: Final = 0.002
"""Arc a laser triangulation spot covers; a few mrad, i.e. a point measurement."""
LASER_RADIATION_TYPE: Final = 1
"""``Range.INFRARED``: the message's only optical type (the other is ULTRASOUND)."""


@functools.cache
def kilted_typestore() -> Typestore:
    """The ROS 2 Kilted type store, built once (building it takes tens of milliseconds)."""
    return get_typestore(Stores.ROS2_KILTED)


def split_stamp(stamp_ns: int) -> tuple[int, int]:
    """Nanoseconds since the epoch to ``builtin_interfaces/Time`` (sec, nanosec)."""
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return sec, nanosec


def stamp_ns_of(msg: Any) -> int:
    """``header.stamp`` of a decoded message, in nanoseconds since the epoch."""
    stamp = msg.header.stamp
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def _header(store: Typestore, stamp_ns: int, frame_id: str) -> Any:
    sec, nanosec = split_stamp(stamp_ns)
    time_cls = store.types["builtin_interfaces/msg/Time"]
    header_cls = store.types["std_msgs/msg/Header"]
    return header_cls(stamp=time_cls(sec=sec, nanosec=nanosec), frame_id=frame_id)


def fluid_pressure_cdr(
    stamp_ns: int,
    gauge_pa: float,
    *,
    ambient_pa: float,
    frame_id: str = "",
    variance_pa2: float = 0.0,
) -> bytes:
    """Serialized ``FluidPressure`` carrying ``gauge_pa`` [Pa gauge] as absolute pressure.

    Args:
        stamp_ns: Time the pressure was true (sampling or intended application) [ns, epoch].
        gauge_pa: Gauge pressure [Pa]; the message carries ``gauge_pa + ambient_pa``.
        ambient_pa: Ambient pressure [Pa absolute].
        frame_id: Header frame.
        variance_pa2: Variance [Pa^2]; 0 means unknown.
    """
    store = kilted_typestore()
    msg = store.types[FLUID_PRESSURE](
        header=_header(store, stamp_ns, frame_id),
        fluid_pressure=float(gauge_to_absolute_pa(float(gauge_pa), ambient_pa)),
        variance=float(variance_pa2),
    )
    return bytes(store.serialize_cdr(msg, FLUID_PRESSURE))


def joint_state_cdr(stamp_ns: int, position_rad: float, *, joint: str = BEND_JOINT) -> bytes:
    """Serialized ``JointState`` with one joint at ``position_rad`` [rad], no velocity/effort."""
    store = kilted_typestore()
    empty = np.zeros(0, dtype=np.float64)
    msg = store.types[JOINT_STATE](
        header=_header(store, stamp_ns, ""),
        name=[joint],
        position=np.array([position_rad], dtype=np.float64),
        velocity=empty,
        effort=empty,
    )
    return bytes(store.serialize_cdr(msg, JOINT_STATE))


def range_cdr(
    stamp_ns: int,
    distance_m: float,
    *,
    min_range_m: float,
    max_range_m: float,
    frame_id: str = "laser",
) -> bytes:
    """Serialized ``Range`` for a laser distance reading [m] (float32 on the wire)."""
    store = kilted_typestore()
    msg = store.types[RANGE](
        header=_header(store, stamp_ns, frame_id),
        radiation_type=LASER_RADIATION_TYPE,
        field_of_view=LASER_FIELD_OF_VIEW_RAD,
        min_range=float(min_range_m),
        max_range=float(max_range_m),
        range=float(distance_m),
        variance=0.0,
    )
    return bytes(store.serialize_cdr(msg, RANGE))


class Sample(NamedTuple):
    """One decoded value: header stamp [ns, epoch] and value in SI."""

    stamp_ns: int
    value: float


def gauge_pressure_of(msg: Any, ambient_pa: float) -> Sample:
    """Gauge pressure [Pa] of a decoded ``FluidPressure`` (which carries absolute pressure)."""
    return Sample(stamp_ns_of(msg), absolute_to_gauge_pa(float(msg.fluid_pressure), ambient_pa))


def joint_position_of(msg: Any, *, topic: str, joint: str = BEND_JOINT) -> Sample:
    """Position [rad] of ``joint`` in a decoded ``JointState``.

    Raises:
        BagError: The message has no joint of that name, or no position for it.
    """
    names = [str(n) for n in msg.name]
    try:
        index = names.index(joint)
    except ValueError:
        msg_text = (
            f"JointState on {topic} has joints {names}; expected one named {joint!r} "
            "(the contract's bending joint)"
        )
        raise BagError(msg_text) from None
    positions = msg.position
    if index >= len(positions):
        msg_text = (
            f"JointState on {topic} names joint {joint!r} at index {index} but carries only "
            f"{len(positions)} positions; expected one position per name"
        )
        raise BagError(msg_text)
    return Sample(stamp_ns_of(msg), float(positions[index]))


class RangeSample(NamedTuple):
    """One decoded ``Range``: stamp [ns, epoch], distance [m], and whether it is in range."""

    stamp_ns: int
    value: float
    in_range: bool


def distance_of(msg: Any) -> RangeSample:
    """Distance [m] of a decoded ``Range``, and whether it lies in [min_range, max_range].

    ``sensor_msgs/Range`` says readings outside that interval are to be discarded; REP 117 uses
    -Inf/+Inf for "too close"/"nothing detected". A non-finite value is never in range; the
    caller counts it as non-finite rather than out of range.
    """
    value = float(msg.range)
    in_range = math.isfinite(value) and float(msg.min_range) <= value <= float(msg.max_range)
    return RangeSample(stamp_ns_of(msg), value, in_range)
