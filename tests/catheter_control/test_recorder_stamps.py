"""The recorder reads each stream's header stamp straight from the serialized message."""

from __future__ import annotations

import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure, JointState, Range

from catheter_models.gaps import header_stamp_ns
from catheter_ros import messages

pytestmark = pytest.mark.filterwarnings("ignore:module .sre_:DeprecationWarning")

STAMP_NS = 1_795_480_207_171_822_469


@pytest.mark.parametrize(
    "msg",
    [
        messages.fluid_pressure(1.5e5, STAMP_NS, "", 101325.0),
        messages.joint_state(0.1, STAMP_NS),
        messages.laser_range(0.06, STAMP_NS, 0.02, 0.07),
    ],
    ids=["FluidPressure", "JointState", "Range"],
)
def test_header_stamp_of_every_contract_stream(msg: FluidPressure | JointState | Range) -> None:
    assert header_stamp_ns(serialize_message(msg)) == STAMP_NS


def test_too_short_to_hold_a_stamp() -> None:
    assert header_stamp_ns(b"\x00\x01\x00\x00\x01") is None
