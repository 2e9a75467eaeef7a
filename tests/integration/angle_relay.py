"""A stand-in laser driver for the tests: relays the rig's ``tip/angle_raw`` to ``tip/angle``.

A test that must silence ``tip/angle`` while the rig runs on puts this between the two and
stops it with SIGSTOP (a laser driver that hangs) and SIGCONT. It runs in its own process,
real time like the driver it stands for: relayed from the pytest process, which handles a
thousand messages a second at normal priority, the stream stalled for over 100 ms often
enough that the compensator (rightly) stopped before the fault was injected.

    python tests/integration/angle_relay.py --ros-args -r __ns:=/catheter
"""

from __future__ import annotations

from rclpy.node import Node
from sensor_msgs.msg import JointState

from catheter_driver.node_main import run_node
from catheter_driver.qos import RECORD, STREAM
from catheter_driver.rt_loop import set_process_realtime
from catheter_models.contract import TIP_ANGLE

RAW_ANGLE = "tip/angle_raw"
RT_PRIORITY = 40
"""Below the loops (50), above their nodes' other threads (20): it is the laser's driver."""


class AngleRelay(Node):
    """Republish every raw-angle message, bytes as they came, on ``tip/angle``."""

    def __init__(self) -> None:
        super().__init__("angle_relay")
        pub = self.create_publisher(JointState, TIP_ANGLE.name, STREAM)
        self.create_subscription(JointState, RAW_ANGLE, pub.publish, RECORD, raw=True)
        refused = set_process_realtime(RT_PRIORITY, background_offset=0)
        if refused:
            self.get_logger().warning(f"real-time scheduling {refused}")


def main() -> None:
    raise SystemExit(run_node(AngleRelay))


if __name__ == "__main__":
    main()
