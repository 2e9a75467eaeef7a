"""The compensator's ``trajectory`` intake in-process: a message is judged by its length before
it is deserialised, then by its point count before any per-point work (no DDS; the same over
DDS mid-run, through the intake process: tests/integration/test_trajectory_limits_live.py),
and the intake process's pipe framing."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
import rclpy
from builtin_interfaces.msg import Duration
from rclpy.context import Context
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.serialization import serialize_message
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from catheter_control import compensator_node, trajectory_intake
from catheter_control.compensator_node import CompensatorNode
from catheter_models.contract import (
    BEND_JOINT,
    MAX_TRAJECTORY_MESSAGE_BYTES,
    MAX_TRAJECTORY_POINTS,
)


class _NoIntakeProcess:
    pid = 0

    def __init__(self, *_args: object, **_kwargs: object) -> None:
        pass

    def close(self) -> None:
        pass


@pytest.fixture
def node() -> Iterator[Any]:
    """An active compensator on a private context (its loop runs; nothing is spun)."""
    context = Context()
    rclpy.init(
        args=["test", "--ros-args", "-r", "__ns:=/catheter", "-p", "rt_priority:=0"],
        context=context,
    )
    original = rclpy.node.Node.__init__

    def on_context(self: Any, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("context", context)
        original(self, *args, **kwargs)

    built = None
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(rclpy.node.Node, "__init__", on_context)
            # The intake process is DDS's side (tests/integration/test_trajectory_limits_live.py);
            # here the node's own checks are fed directly.
            mp.setattr(compensator_node, "TrajectoryIntake", _NoIntakeProcess)
            built = CompensatorNode()
        assert built.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert built.trigger_activate() == TransitionCallbackReturn.SUCCESS
        yield built
        built.trigger_deactivate()
    finally:
        if built is not None:
            built.destroy_node()
        rclpy.shutdown(context=context)


def _message(n_points: int, step_s: float = 0.02) -> JointTrajectory:
    msg = JointTrajectory(joint_names=[BEND_JOINT])
    for i in range(n_points):
        t_ns = round((i + 1) * step_s * 1e9)
        msg.points.append(
            JointTrajectoryPoint(
                positions=[0.0],
                time_from_start=Duration(sec=t_ns // 10**9, nanosec=t_ns % 10**9),
            )
        )
    return msg


def test_a_message_over_the_byte_limit_is_refused_without_deserialising_it(
    node: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    def deserialise(*_args: object) -> None:
        raise AssertionError("deserialised a message over the byte limit")

    monkeypatch.setattr(compensator_node, "deserialize_message", deserialise)
    node._on_trajectory(b"\0" * (MAX_TRAJECTORY_MESSAGE_BYTES + 1))
    assert node._refusals == 1
    assert f"{MAX_TRAJECTORY_MESSAGE_BYTES + 1} bytes" in node._last_refusal
    assert "MAX_TRAJECTORY_MESSAGE_BYTES" in node._last_refusal
    assert node._pending is None


def test_a_message_within_the_bytes_but_over_the_points_is_refused_naming_the_limit(
    node: Any,
) -> None:
    # Points with no position are the smallest on the wire: many fit under the byte limit.
    msg = JointTrajectory(joint_names=[BEND_JOINT])
    msg.points = [JointTrajectoryPoint() for _ in range(MAX_TRAJECTORY_POINTS + 1)]
    data = serialize_message(msg)
    assert len(data) <= MAX_TRAJECTORY_MESSAGE_BYTES
    node._on_trajectory(data)
    assert node._refusals == 1
    assert f"{MAX_TRAJECTORY_POINTS + 1} points" in node._last_refusal
    assert "MAX_TRAJECTORY_POINTS" in node._last_refusal
    assert node._pending is None


def test_a_message_at_the_limits_is_accepted(node: Any) -> None:
    data = serialize_message(_message(MAX_TRAJECTORY_POINTS))
    assert len(data) <= MAX_TRAJECTORY_MESSAGE_BYTES
    node._on_trajectory(data)
    assert node._refusals == 0, node._last_refusal
    assert node._accepted == 1
    assert node._pending is not None


def test_the_pipe_carries_a_message_its_publisher_and_a_refusal_whole() -> None:
    import os

    cdr = serialize_message(_message(3))
    gid = bytes(range(16))
    read_fd, write_fd = os.pipe()
    frames = [
        trajectory_intake.encode(trajectory_intake.READY),
        trajectory_intake.encode(
            trajectory_intake.MESSAGE, trajectory_intake.message_payload(gid, cdr)
        ),
        trajectory_intake.encode(
            trajectory_intake.REFUSED, trajectory_intake.oversize_refusal(32_000_040).encode()
        ),
    ]
    os.write(write_fd, b"".join(frames))
    os.close(write_fd)
    assert trajectory_intake.read_frame(read_fd) == (trajectory_intake.READY, b"")
    kind, payload = trajectory_intake.read_frame(read_fd) or (b"", b"")
    assert kind == trajectory_intake.MESSAGE
    assert trajectory_intake.split_message(payload) == (gid, cdr)
    kind, payload = trajectory_intake.read_frame(read_fd) or (b"", b"")
    assert kind == trajectory_intake.REFUSED
    assert payload.decode().startswith("the message is 32000040 bytes, over the limit of")
    assert trajectory_intake.read_frame(read_fd) is None  # the writer has gone
    os.close(read_fd)


def test_a_frame_longer_than_any_message_is_refused_unread() -> None:
    import os
    import struct

    read_fd, write_fd = os.pipe()
    os.write(write_fd, struct.pack("<cI", trajectory_intake.MESSAGE, 32_000_000))
    os.close(write_fd)
    with pytest.raises(trajectory_intake.IntakeError, match="32000000 bytes"):
        trajectory_intake.read_frame(read_fd)
    os.close(read_fd)


def test_within_the_byte_limit_nothing_is_refused_by_size() -> None:
    assert trajectory_intake.oversize_refusal(MAX_TRAJECTORY_MESSAGE_BYTES) == ""
    assert "MAX_TRAJECTORY_MESSAGE_BYTES" in trajectory_intake.oversize_refusal(
        MAX_TRAJECTORY_MESSAGE_BYTES + 1
    )
