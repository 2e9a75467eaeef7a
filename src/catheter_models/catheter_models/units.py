"""Unit conversions, in one place.

Topics and internal arrays are SI (REP 103): pascal, radian, metre, second.
People read bar (gauge) and degrees, so CLI output, reports and plots convert here.
``sensor_msgs/FluidPressure`` carries *absolute* pressure; gauge = absolute - ambient.
"""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np
import numpy.typing as npt

PA_PER_BAR = 1.0e5
AMBIENT_PRESSURE_PA = 101_325.0
"""Standard atmosphere; the default for the ``ambient_pressure_pa`` parameter everywhere."""

FloatOrArray = TypeVar("FloatOrArray", float, npt.NDArray[np.float64])


def bar_to_pa(pressure_bar: FloatOrArray) -> FloatOrArray:
    """Convert bar to pascal (same reference: gauge stays gauge)."""
    return pressure_bar * PA_PER_BAR


def pa_to_bar(pressure_pa: FloatOrArray) -> FloatOrArray:
    """Convert pascal to bar (same reference: gauge stays gauge)."""
    return pressure_pa / PA_PER_BAR


def gauge_to_absolute_pa(
    gauge_pa: FloatOrArray, ambient_pa: float = AMBIENT_PRESSURE_PA
) -> FloatOrArray:
    """Gauge pressure [Pa] to absolute pressure [Pa], as FluidPressure carries it."""
    return gauge_pa + ambient_pa


def absolute_to_gauge_pa(
    absolute_pa: FloatOrArray, ambient_pa: float = AMBIENT_PRESSURE_PA
) -> FloatOrArray:
    """Absolute pressure [Pa] (FluidPressure) to gauge pressure [Pa]."""
    return absolute_pa - ambient_pa


def deg_to_rad(angle_deg: FloatOrArray) -> FloatOrArray:
    """Degrees to radians."""
    return angle_deg * (math.pi / 180.0)


def rad_to_deg(angle_rad: FloatOrArray) -> FloatOrArray:
    """Radians to degrees."""
    return angle_rad * (180.0 / math.pi)


MM_PER_M = 1000.0


def mm_to_m(length_mm: FloatOrArray) -> FloatOrArray:
    """Millimetres to metres."""
    return length_mm / MM_PER_M


def m_to_mm(length_m: FloatOrArray) -> FloatOrArray:
    """Metres to millimetres."""
    return length_m * MM_PER_M


NS_PER_S = 1_000_000_000


def s_to_ns(time_s: float) -> int:
    """Seconds to integer nanoseconds (bag and message stamps)."""
    return round(time_s * NS_PER_S)


def ns_to_s(time_ns: float) -> float:
    """Integer nanoseconds to seconds."""
    return time_ns / NS_PER_S
