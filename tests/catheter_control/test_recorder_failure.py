"""A recorder whose writer cannot write says so at once, closes the bag and counts the rest.

In-process, no executor spinning: the ERROR status seen here was published by the writer
thread at the failure, not by the 1 Hz timer. The disk's refusal is injected by a file object
that takes part of a write and raises ENOSPC (as a disk that just filled up does); the real
full tmpfs is in tests/integration/test_recorder_watched_live.py.
"""

from __future__ import annotations

import errno
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from catheter_control.recorder_node import RecorderNode
from catheter_models.bag import repair_bag
from catheter_models.bag.messages import fluid_pressure_cdr, joint_state_cdr
from catheter_models.units import AMBIENT_PRESSURE_PA

pytestmark = pytest.mark.filterwarnings("ignore:module .sre_:DeprecationWarning")

PERIOD_NS = 4_000_000


class RefusingFile:
    """Writes through until ``refuse`` is set; then takes half and raises that OSError."""

    def __init__(self, inner: IO[bytes]) -> None:
        self.inner = inner
        self.refuse: int | None = None

    def write(self, data: Any) -> int:
        if self.refuse is not None:
            view = memoryview(data)
            self.inner.write(view[: len(view) // 2])
            self.inner.flush()
            raise OSError(self.refuse, os.strerror(self.refuse))
        return self.inner.write(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


class Published:
    """Stands in for the /diagnostics publisher: keeps what the node publishes."""

    def __init__(self) -> None:
        self.statuses: list[DiagnosticStatus] = []

    def publish(self, msg: DiagnosticArray) -> None:
        self.statuses.extend(msg.status)


@pytest.fixture
def recorder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[RecorderNode]:
    """A recorder on tmp_path/bag whose .mcap file is a RefusingFile (``node.file``)."""
    real_open = Path.open
    opened: list[RefusingFile] = []

    def fake_open(self: Path, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        stream = real_open(self, mode, *args, **kwargs)
        if mode == "xb" and self.suffix == ".mcap":
            opened.append(RefusingFile(stream))
            return opened[-1]
        return stream

    monkeypatch.setattr(Path, "open", fake_open)
    args = ["recorder", "--ros-args", "-p", f"bag_path:={tmp_path / 'bag'}"]
    with rclpy.init(args=args):
        node = RecorderNode()
        node.file = opened[0]
        node.published = Published()
        node._pub_diag = node.published
        try:
            yield node
        finally:
            node.close()
            node.destroy_node()


def _feed(node: RecorderNode, n: int, start: int = 0) -> bool:
    """``n`` samples of pressure/command and tip/angle, 4 ms apart, through the intake."""
    command = node.resolve_topic_name("pressure/command")
    angle = node.resolve_topic_name("tip/angle")
    t0 = time.time_ns()
    for i in range(start, start + n):
        stamp = t0 + (i - start) * PERIOD_NS
        on_command: Any = node._subscriptions_by_topic[command].callback
        on_angle: Any = node._subscriptions_by_topic[angle].callback
        on_command(fluid_pressure_cdr(stamp, 1.0e5, ambient_pa=AMBIENT_PRESSURE_PA))
        on_angle(joint_state_cdr(stamp, 0.1))
    return False


def _wait(predicate: Any, timeout_s: float = 10.0) -> bool:
    until = time.monotonic() + timeout_s
    while time.monotonic() < until:
        if predicate():
            return True
        time.sleep(0.01)
    return bool(predicate())


def test_a_full_disk_stops_the_recorder_says_why_at_once_and_keeps_the_bag(
    recorder: RecorderNode,
) -> None:
    node = recorder
    # The writer flushes every 0.5 s (at a write): feed until something is on disk.
    assert _wait(lambda: _feed(node, 5) or node.writer._good_summary.message_count > 0)
    before_ns = time.time_ns()
    node.file.refuse = errno.ENOSPC
    assert _wait(lambda: _feed(node, 5) or node.outcome is not None), "no stop on ENOSPC"
    failure, outcome = node.failure, node.outcome
    assert failure is not None and outcome is not None
    assert failure.errno == errno.ENOSPC and failure.at_ns >= before_ns
    assert not outcome.finished and node.writer.closed
    # /diagnostics ERROR, published by the writer thread at the failure (nothing spins here).
    published = node.published.statuses
    assert _wait(lambda: bool(published)), "no status was published at the failure"
    status = published[-1]
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == DiagnosticStatus.ERROR
    for said in ("No space left on device", "ENOSPC", str(node.writer.mcap_path), "bag repair"):
        assert said in status.message, (said, status.message)
    assert values["state"] == "failed"
    assert values["errno"] == "ENOSPC"
    assert values["bag_file"] == "repairable"
    assert int(values["recorded_until_ns"]) == outcome.until_ns
    # What arrives after the failure is counted per topic, never queued.
    queued = len(node._queue)
    _feed(node, 50, start=400)
    assert len(node._queue) == queued == 0
    angle = node.resolve_topic_name("tip/angle")
    level, _message, status_values = node.status()
    assert level == DiagnosticStatus.ERROR
    not_written = int(str(status_values[f"not_written {angle}"]))
    assert not_written >= 50
    assert int(str(status_values[f"lost {angle}"])) >= not_written
    # The bag holds its last complete flush: a repair recovers what the recorder says it kept,
    # and its counts say the same (what was cut off with the half-written chunk is lost).
    report = repair_bag(node.bag_path)
    assert report.message_count == outcome.messages > 0
    assert node.counts[angle] == report.messages_per_topic[angle]
    assert sum(node.counts.values()) == outcome.messages


def test_any_error_in_the_writer_thread_finishes_the_bag_and_says_so(
    recorder: RecorderNode, monkeypatch: pytest.MonkeyPatch
) -> None:
    node = recorder
    _feed(node, 100)
    assert _wait(lambda: node.writer.message_count >= 200)

    def broken(*_args: Any) -> None:
        raise RuntimeError("a bug in the writer")

    monkeypatch.setattr(node.writer, "write", broken)
    _feed(node, 10, start=100)
    assert _wait(lambda: node.outcome is not None), "the writer did not stop on the error"
    assert node.outcome is not None and node.outcome.finished  # whole: summary and footer
    assert node.outcome.messages == 200
    assert _wait(lambda: bool(node.published.statuses)), "no status at the failure"
    status = node.published.statuses[-1]
    assert status.level == DiagnosticStatus.ERROR
    assert "RuntimeError('a bug in the writer')" in status.message
    assert "finished" in status.message
