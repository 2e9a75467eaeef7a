"""Writing a contract-conforming bag from sampled numpy arrays (sample bags, tests; no ROS).

``write_bag_from_arrays`` serializes each sample into the contract's messages and streams them
through ``BagRecorder``, so its bags have the recorder's layout, schemas and ``metadata.yaml``.
It is apart from ``bag.writer`` because it is a client of the recorder core, not part of it: it
knows the contract's topics and message types, the recorder only serialized bytes.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from catheter_models.bag.messages import fluid_pressure_cdr, joint_state_cdr, range_cdr
from catheter_models.bag.metadata import STREAM_QOS
from catheter_models.bag.writer import BagRecorder, Compression
from catheter_models.contract import (
    ANGLE_DESIRED,
    DEFAULT_NAMESPACE,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TIP_DISTANCE,
    qualify,
)
from catheter_models.errors import ParameterError
from catheter_models.units import AMBIENT_PRESSURE_PA, NS_PER_S

DEFAULT_DISTANCE_RANGE_M: Final = (0.0, 1.0)
"""``Range.min_range``/``max_range`` for synthetic laser data [m]: covers any plausible value."""


def _as_series(name: str, values: npt.ArrayLike, n: int) -> npt.NDArray[np.float64]:
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape != (n,):
        msg = f"{name} has shape {arr.shape}; expected ({n},) like t_s"
        raise ParameterError(msg)
    return arr


def write_bag_from_arrays(
    path: Path | str,
    t_s: npt.ArrayLike,
    pressure_command_pa_gauge: npt.ArrayLike,
    pressure_measured_pa_gauge: npt.ArrayLike,
    angle_rad: npt.ArrayLike,
    *,
    distance_m: npt.ArrayLike | None = None,
    angle_desired_rad: npt.ArrayLike | None = None,
    custom_data: Mapping[str, str] | None = None,
    ambient_pa: float = AMBIENT_PRESSURE_PA,
    namespace: str = DEFAULT_NAMESPACE,
    start_time_ns: int | None = None,
    distance_range_m: tuple[float, float] = DEFAULT_DISTANCE_RANGE_M,
    compression: Compression = "none",
) -> Path:
    """Write a contract-conforming bag from sampled arrays (sample bags, tests; no ROS).

    Every array holds one value per sample time. Each message's ``header.stamp`` is the time the
    value was true, ``start_time_ns + t_s``; its log and publish times are the same instant.
    Values are written as given, NaN included, so a test can build a faulty bag.

    Args:
        path: Bag directory to create (must not exist).
        t_s: Sample times [s] relative to ``start_time_ns``; finite and strictly increasing.
        pressure_command_pa_gauge: Valve set-point [Pa gauge], on ``pressure/command``.
        pressure_measured_pa_gauge: Line pressure [Pa gauge], on ``pressure/measured``.
        angle_rad: Bending angle [rad], on ``tip/angle`` (joint ``bend``).
        distance_m: Laser distance [m] on ``tip/distance``; None: topic not written.
        angle_desired_rad: Set-point angle [rad] on ``angle/desired``; None: not written.
        custom_data: Experiment description for ``metadata.yaml``.
        ambient_pa: Ambient pressure [Pa absolute] added to make ``FluidPressure`` absolute.
        namespace: Namespace of the contract's relative topics.
        start_time_ns: Epoch of ``t_s`` [ns since the Unix epoch]. None: now. Pass a fixed value
            for byte-identical files.
        distance_range_m: ``Range.min_range`` and ``max_range`` [m].
        compression: MCAP chunk compression.

    Returns:
        The bag directory.

    Raises:
        ParameterError: Arrays of unequal length, or ``t_s`` not finite and increasing.
        BagError: ``path`` already exists.
    """
    times_s = np.asarray(t_s, dtype=np.float64)
    if times_s.ndim != 1 or times_s.size == 0:
        msg = f"t_s has shape {times_s.shape}; expected a non-empty 1-D array of times [s]"
        raise ParameterError(msg)
    if not np.all(np.isfinite(times_s)):
        msg = "t_s holds non-finite times; every sample needs a finite time [s]"
        raise ParameterError(msg)
    if times_s.size > 1 and not np.all(np.diff(times_s) > 0.0):
        msg = "t_s is not strictly increasing; sample times must advance"
        raise ParameterError(msg)
    n = times_s.size
    command = _as_series("pressure_command_pa_gauge", pressure_command_pa_gauge, n)
    measured = _as_series("pressure_measured_pa_gauge", pressure_measured_pa_gauge, n)
    angle = _as_series("angle_rad", angle_rad, n)
    distance = None if distance_m is None else _as_series("distance_m", distance_m, n)
    desired = (
        None if angle_desired_rad is None else _as_series("angle_desired_rad", angle_desired_rad, n)
    )
    epoch_ns = time.time_ns() if start_time_ns is None else int(start_time_ns)
    # Integer ns per sample, rounded once, so stamps and log times agree exactly.
    stamps_ns = epoch_ns + np.round(times_s * NS_PER_S).astype(np.int64)
    min_range_m, max_range_m = distance_range_m

    topic_command = qualify(PRESSURE_COMMAND, namespace)
    topic_measured = qualify(PRESSURE_MEASURED, namespace)
    topic_angle = qualify(TIP_ANGLE, namespace)
    topic_distance = qualify(TIP_DISTANCE, namespace)
    topic_desired = qualify(ANGLE_DESIRED, namespace)

    with BagRecorder(
        path, custom_data=custom_data, flush_period_s=None, compression=compression
    ) as rec:
        rec.add_topic(topic_command, PRESSURE_COMMAND.msgtype, offered_qos=[STREAM_QOS])
        rec.add_topic(topic_measured, PRESSURE_MEASURED.msgtype, offered_qos=[STREAM_QOS])
        rec.add_topic(topic_angle, TIP_ANGLE.msgtype, offered_qos=[STREAM_QOS])
        if distance is not None:
            rec.add_topic(topic_distance, TIP_DISTANCE.msgtype, offered_qos=[STREAM_QOS])
        if desired is not None:
            rec.add_topic(topic_desired, ANGLE_DESIRED.msgtype, offered_qos=[STREAM_QOS])
        for i in range(n):
            stamp = int(stamps_ns[i])
            rec.write(
                topic_command,
                fluid_pressure_cdr(stamp, command[i], ambient_pa=ambient_pa, frame_id="valve"),
                stamp,
                stamp,
            )
            rec.write(
                topic_measured,
                fluid_pressure_cdr(
                    stamp, measured[i], ambient_pa=ambient_pa, frame_id="pressure_transmitter"
                ),
                stamp,
                stamp,
            )
            rec.write(topic_angle, joint_state_cdr(stamp, angle[i]), stamp, stamp)
            if distance is not None:
                rec.write(
                    topic_distance,
                    range_cdr(stamp, distance[i], min_range_m=min_range_m, max_range_m=max_range_m),
                    stamp,
                    stamp,
                )
            if desired is not None:
                rec.write(topic_desired, joint_state_cdr(stamp, desired[i]), stamp, stamp)
    return Path(path)
