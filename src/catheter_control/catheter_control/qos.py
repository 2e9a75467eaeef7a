"""QoS profiles of the interface contract (docs/interfaces.md)."""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

SENSOR = qos_profile_sensor_data
"""Sensor and command streams: best effort, keep last, shallow queue."""

TRAJECTORY = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""``trajectory``: reliable and transient-local, so a late subscriber still gets it."""


KEEP_EVERY_SAMPLE = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=500,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
"""Best-effort streams with a deep queue (2 s at 250 Hz), for listeners that keep every sample.

The recorder and follow_trajectory's tracking report use it.

A subscriber's depth is its own business (it does not affect matching), and a controller
wants only the newest sample, but a recorder must keep every one: a rig that falls behind
publishes its backlog in a burst, and this process may itself be descheduled for a moment;
``qos_profile_sensor_data``'s depth of 5 (20 ms) lost runs of samples from the bag then.
"""
