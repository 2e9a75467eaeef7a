"""A stand-in laser driver for the tests: relays the rig's ``tip/angle_raw`` to ``tip/angle``.

A test that must silence ``tip/angle`` while the rig runs on puts this between the two and
stops it with SIGSTOP (a laser driver that hangs) and SIGCONT. SIGUSR1 freezes it instead:
it goes on publishing at the rig's rate, but always the last message it had (a laser that
freezes at a plausible value, which no staleness check can see). It runs in its own process,
real time like the driver it stands for: relayed from the pytest process, which handles a
thousand messages a second at normal priority, the stream stalled for over 100 ms often
enough that the compensator (rightly) stopped before the fault was injected.

It speaks DDS over UDP only, not Fast DDS's shared memory. A process stopped with SIGSTOP
cannot pop its shared-memory port; after Fast DDS's health-check timeout a writer marks the
port as broken and rebuilds it, and the relay, resumed, must find the new one. Once in a
clean-clone CI run (stop 43) it did not: 13.6 s after SIGCONT the compensator still had no
tip angle, the relay's log empty. Over UDP a stopped reader only lets its socket buffer
overflow, and the reliable protocol resumes. What the tests prove is the compensator's
handling of a silent laser, which is the same on either transport.

    python tests/integration/angle_relay.py --ros-args -r __ns:=/catheter
"""

from __future__ import annotations

import os
import signal

# Before rclpy: Fast DDS reads its transports when the participant is made (see above).
os.environ["FASTDDS_BUILTIN_TRANSPORTS"] = "UDPv4"

from rclpy.node import Node
from sensor_msgs.msg import JointState

from catheter_models.contract import TIP_ANGLE
from catheter_ros.node_main import run_node
from catheter_ros.qos import RECORD, STREAM
from catheter_ros.rt_loop import set_process_realtime

RAW_ANGLE = "tip/angle_raw"
RT_PRIORITY = 40
"""Below the loops (50), above their nodes' other threads (20): it is the laser's driver."""


class AngleRelay(Node):
    """Republish every raw-angle message, bytes as they came, on ``tip/angle``."""

    def __init__(self) -> None:
        super().__init__("angle_relay")
        self._pub = self.create_publisher(JointState, TIP_ANGLE.name, STREAM)
        self._frozen: bytes | None = None
        self._freeze = False
        self._last: bytes | None = None
        self.create_subscription(JointState, RAW_ANGLE, self._relay, RECORD, raw=True)
        signal.signal(signal.SIGUSR1, self._on_freeze)
        refused = set_process_realtime(RT_PRIORITY, background_offset=0)
        if refused:
            self.get_logger().warning(f"real-time scheduling {refused}")

    def _on_freeze(self, _signum: int, _frame: object) -> None:
        self._freeze = True

    def _relay(self, raw: bytes) -> None:
        if self._freeze and self._frozen is None:
            self._frozen = self._last if self._last is not None else raw
        self._last = raw
        self._pub.publish(self._frozen if self._frozen is not None else raw)


def main() -> None:
    raise SystemExit(run_node(AngleRelay))


if __name__ == "__main__":
    main()
