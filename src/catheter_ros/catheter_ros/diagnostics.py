"""Small helpers to publish node health on /diagnostics (diagnostic_msgs/DiagnosticArray)."""

from __future__ import annotations

from collections.abc import Mapping

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.publisher import Publisher

from catheter_models import __version__
from catheter_models.contract import DIAGNOSTICS

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR


def create_diagnostics_publisher(node: Node) -> Publisher[DiagnosticArray]:
    """The /diagnostics publisher (absolute name, as diagnostic aggregators expect)."""
    return node.create_publisher(DiagnosticArray, DIAGNOSTICS.name, 10)


def publish_status(
    publisher: Publisher[DiagnosticArray],
    node: Node,
    *,
    level: bytes,
    message: str,
    values: Mapping[str, object],
    hardware_id: str = "",
) -> None:
    """Publish one DiagnosticStatus named after the node's fully qualified name."""
    status = DiagnosticStatus()
    status.level = level
    status.name = node.get_fully_qualified_name().lstrip("/")
    status.message = message
    status.hardware_id = hardware_id
    # Every status says which software produced it, so a log from the rig can be matched
    # to a release.
    stamped = {**values, "software_version": __version__}
    status.values = [KeyValue(key=str(k), value=str(v)) for k, v in stamped.items()]
    array = DiagnosticArray()
    array.header.stamp = node.get_clock().now().to_msg()
    array.status = [status]
    publisher.publish(array)
