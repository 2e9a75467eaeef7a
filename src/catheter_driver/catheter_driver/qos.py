"""QoS profiles the driver side needs (the control side re-exports them)."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

KEEP_EVERY_SAMPLE = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=500,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
"""Best-effort streams with a deep queue (2 s at 250 Hz), for listeners that keep every sample.

Matching is unaffected (depth is the subscriber's own business). A controller only wants the
newest sample, but some listeners must see every one: the recorder and the tracking report
keep them, and the drivers count and refuse every bad command. With the sensor profile's
depth of 5 (20 ms), a listener whose thread was busy for a moment lost runs of messages,
uncounted.
"""
