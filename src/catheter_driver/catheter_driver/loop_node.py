"""A node that owns one deadline loop: start and stop with the node, and stamps for ticks."""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node

from catheter_driver.rt_loop import DeadlineLoop, MonotonicStamper


class LoopNode(Node):
    """Base for nodes whose work runs on a :class:`DeadlineLoop` (not an rclpy timer).

    Deadlines are on the monotonic clock; messages are stamped in ROS time through one
    :class:`MonotonicStamper` taken at construction.
    """

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self._loop: DeadlineLoop | None = None
        self._stamper = MonotonicStamper(self.get_clock().now().nanoseconds)

    def create_loop(self, rate_hz: float, tick: Callable[[int, float], None]) -> DeadlineLoop:
        """Create the node's loop (started by :meth:`start`)."""
        self._loop = DeadlineLoop(rate_hz, tick, name=self.get_name())
        return self._loop

    @property
    def loop(self) -> DeadlineLoop:
        """The node's loop; RuntimeError if :meth:`create_loop` was not called."""
        if self._loop is None:
            raise RuntimeError(f"{self.get_name()}: create_loop() was not called")
        return self._loop

    def stamp_ns(self, mono_s: float) -> int:
        """ROS time [ns] of a monotonic instant [s], e.g. a tick's deadline."""
        return self._stamper.ns(mono_s)

    def start(self) -> None:
        """Start the loop."""
        self.loop.start()

    def destroy_node(self) -> None:
        """Stop the loop before the publishers go away.

        A constructor that failed (a parameter refused) may have left no loop, and rclpy
        still destroys the half-built node when its context shuts down.
        """
        if self._loop is not None:
            self._loop.stop()
        super().destroy_node()
