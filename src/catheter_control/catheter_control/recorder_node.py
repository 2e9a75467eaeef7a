"""``recorder``: write the contract's topics to an MCAP rosbag2 bag.

Messages are taken raw (serialized CDR) and written as they came, stamped with receive time as
log time; the header stamps inside carry the time each value was true. The writer closes a
chunk and flushes every ``flush_period_s``, so a killed recorder leaves a bag that
``catheter-lab bag repair`` recovers up to its last chunk.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from rclpy.node import Node
from rclpy.subscription import Subscription

from catheter_control import qos
from catheter_driver import diagnostics
from catheter_driver.messages import message_class
from catheter_driver.node_main import run_node
from catheter_driver.params import declare_plain
from catheter_models import __version__
from catheter_models.bag import LATCHED_QOS, SENSOR_DATA_QOS, BagRecorder
from catheter_models.contract import RECORDED_TOPICS, TRAJECTORY, TopicSpec
from catheter_models.errors import ParameterError


class RecorderNode(Node):
    """Thin ROS shell over :class:`BagRecorder`."""

    def __init__(self) -> None:
        super().__init__("recorder")
        bag_path = str(
            declare_plain(self, "bag_path", "", "bag directory to create (must not exist)")
        )
        if not bag_path:
            raise ParameterError("recorder: parameter bag_path is required (a new directory)")
        custom = json.loads(
            str(declare_plain(self, "custom_data", "{}", "experiment metadata as a JSON object"))
        )
        flush_period_s = float(
            declare_plain(self, "flush_period_s", 0.5, "close a chunk and flush this often [s]")
        )
        compression = str(
            declare_plain(self, "compression", "none", "MCAP chunk compression: none, zstd or lz4")
        )
        custom.setdefault("software_version", __version__)
        custom.setdefault("recorder", self.get_fully_qualified_name())
        self.bag_path = Path(bag_path)
        self.writer = BagRecorder(
            self.bag_path,
            custom_data={k: str(v) for k, v in custom.items()},
            flush_period_s=flush_period_s,
            compression=compression,  # type: ignore[arg-type]
        )
        self.counts: dict[str, int] = {}
        self._subscriptions_by_topic: dict[str, Subscription[Any]] = {}
        for spec in RECORDED_TOPICS:
            self._record(spec)
        self._pub_diag = diagnostics.create_diagnostics_publisher(self)
        self.create_timer(1.0, self._publish_diagnostics)
        self.get_logger().info(f"recording to {self.bag_path}")

    def _record(self, spec: TopicSpec) -> None:
        # The bag names topics as they were on the wire, namespace and remapping applied.
        topic = self.resolve_topic_name(spec.name)
        # Offered QoS goes into the bag so that `ros2 bag play` republishes `trajectory`
        # transient-local, as the contract requires, and the streams best-effort.
        latched = spec == TRAJECTORY
        self.writer.add_topic(
            topic, spec.msgtype, offered_qos=[LATCHED_QOS if latched else SENSOR_DATA_QOS]
        )
        self.counts[topic] = 0

        def on_message(data: bytes) -> None:
            now_ns = self.get_clock().now().nanoseconds
            self.writer.write(topic, data, now_ns, now_ns)
            self.counts[topic] += 1

        profile = qos.TRAJECTORY if latched else qos.KEEP_EVERY_SAMPLE
        self._subscriptions_by_topic[topic] = self.create_subscription(
            message_class(spec.msgtype), spec.name, on_message, profile, raw=True
        )

    def _publish_diagnostics(self) -> None:
        values: dict[str, object] = {"bag_path": str(self.bag_path)}
        values.update({f"count {t}": n for t, n in self.counts.items()})
        # Matched publishers per topic: a tool about to start a run waits until the recorder
        # hears every publisher, or the bag would miss the run's start (discovery takes seconds).
        values.update(
            {
                f"publishers {t}": s.get_publisher_count()
                for t, s in self._subscriptions_by_topic.items()
            }
        )
        diagnostics.publish_status(
            self._pub_diag, self, level=diagnostics.OK, message="recording", values=values
        )

    def close(self) -> None:
        """Finish the bag (idempotent)."""
        self.writer.close()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_control recorder``."""
    code = run_node(RecorderNode, args)
    if code:
        raise SystemExit(code)


if __name__ == "__main__":
    main()
