"""QoS profiles of the interface contract, for every node of the graph.

Why these (docs/interfaces.md, "QoS"): a stream's publisher offers reliable delivery with a
deep history, and each subscriber asks for what it needs. Best-effort subscribers (controllers,
which want the newest sample) still match a reliable publisher and never slow it; a reliable
subscriber (the recorder) gets every sample re-sent if the wire or its own busy process lost
one. With best-effort publishers, a recorder on a busy 2-core machine lost 88 ms runs of a
sensor stream, and nothing could ask for them again.

The numbers (depths, reliability, durability) are the contract's (``catheter_models.contract``,
``QOS_*``), where a bag's ``metadata.yaml`` reads them too; this module only turns them into
rclpy's profile objects.
"""

from __future__ import annotations

import copy
from typing import Any

from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.qos_overriding_options import InvalidQosOverridesError, QoSOverridingOptions

from catheter_models.contract import (
    QOS_KEEP_EVERY_SAMPLE,
    QOS_RECORD,
    QOS_STREAM,
    QOS_TRAJECTORY,
    STREAM_DEPTH,  # noqa: F401  (re-exported: importable beside the profiles it sizes)
    QosSpec,
)
from catheter_models.errors import ParameterError


def profile_of(spec: QosSpec) -> QoSProfile:
    """The rclpy profile of one of the contract's QoS specs (history keep-last, as they all are)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=spec.depth,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local else DurabilityPolicy.VOLATILE
        ),
    )


STREAM = profile_of(QOS_STREAM)
"""What every sensor and command stream offers: reliable, keep last ``STREAM_DEPTH``.

Keep-last, not keep-all: a publisher never blocks on a slow subscriber (a real-time loop must
not wait on a recorder); a subscriber more than ``STREAM_DEPTH`` samples behind loses the
oldest, and the recorder counts that from the stamps."""

KEEP_EVERY_SAMPLE = profile_of(QOS_KEEP_EVERY_SAMPLE)
"""Best-effort with a deep queue, for listeners that must see every sample that reaches them
and must also match a best-effort publisher (a user's own controller): the drivers count and
refuse every bad command. With the sensor profile's depth of 5 (20 ms), a listener whose
thread was busy for a moment lost runs of messages, uncounted."""

RECORD = profile_of(QOS_RECORD)
"""The recorder's request: every sample, re-sent if lost. It matches reliable publishers only,
so the recorder falls back to ``KEEP_EVERY_SAMPLE`` on a topic where a publisher offers best
effort (and says so)."""


SENSOR = qos_profile_sensor_data
"""What a controller asks of a stream: best effort, the newest few samples.

rclpy's own profile object, not one built from ``contract.QOS_SENSOR_DATA``: it is the ROS
convention this name stands for; ``tests/test_one_source.py`` checks the two agree."""

TRAJECTORY = profile_of(QOS_TRAJECTORY)
"""``trajectory``: reliable and transient-local, so a late subscriber still gets it."""


def _valid_depth(profile: QoSProfile) -> Any:
    from rcl_interfaces.msg import SetParametersResult

    result = SetParametersResult(successful=True)
    if profile.history == HistoryPolicy.KEEP_LAST and profile.depth < 1:
        result.successful = False
        result.reason = f"depth must be >= 1 with history keep_last, got {profile.depth}"
    return result


def overridable_publisher(
    node: Node, msg_type: Any, topic: str, profile: QoSProfile
) -> Publisher[Any]:
    """A publisher whose history, depth and reliability REP 2003 parameters may override.

    ``-p qos_overrides./catheter/pressure/measured.publisher.depth:=1000`` (the topic's full
    name; rclpy's naming). The profile is copied: rclpy writes the overrides into the profile
    it is given, and ours are shared module constants. A bad value is refused at start-up
    with the parameter's name (ParameterError, exit code 2).
    """
    name = f"qos_overrides.{node.resolve_topic_name(topic)}.publisher"
    try:
        return node.create_publisher(
            msg_type,
            topic,
            copy.copy(profile),
            qos_overriding_options=QoSOverridingOptions.with_default_policies(
                callback=_valid_depth
            ),
        )
    except (
        InvalidParameterTypeException,
        InvalidParameterValueException,
        InvalidQosOverridesError,
        RuntimeError,
        ValueError,
    ) as exc:
        raise ParameterError(
            f"QoS override refused ({name}.history/depth/reliability): {exc}"
        ) from None
