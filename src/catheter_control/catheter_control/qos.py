"""QoS profiles of the interface contract (docs/interfaces.md)."""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

import catheter_driver.qos as _driver_qos

SENSOR = qos_profile_sensor_data
"""What a controller asks of a stream: best effort, the newest few samples."""

TRAJECTORY = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""``trajectory``: reliable and transient-local, so a late subscriber still gets it."""


# Defined with the drivers, which need them too (control may import driver, not back).
STREAM = _driver_qos.STREAM
KEEP_EVERY_SAMPLE = _driver_qos.KEEP_EVERY_SAMPLE
RECORD = _driver_qos.RECORD
overridable_publisher = _driver_qos.overridable_publisher
