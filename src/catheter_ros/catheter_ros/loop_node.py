"""A node that owns one deadline loop: start and stop with the node, and stamps for ticks."""

from __future__ import annotations

from collections.abc import Callable

from rclpy.lifecycle import LifecycleNode
from rclpy.node import Node

from catheter_ros.lifecycle_node import autostart_once, declare_autostart
from catheter_ros.params import declare_int
from catheter_ros.rt_loop import (
    DEFAULT_RT_PRIORITY,
    DeadlineLoop,
    MonotonicStamper,
    set_process_realtime,
)


def declare_rt_priority(node: Node) -> int:
    """The ``rt_priority`` parameter of a node with deadline loops (0..98, default 50)."""
    return declare_int(
        node,
        "rt_priority",
        DEFAULT_RT_PRIORITY,
        low=0,
        high=98,
        doc="SCHED_FIFO priority of the loop threads; the node's other threads run 30 below "
        "(0: normal scheduling)",
    )


def make_process_realtime(node: Node, rt_priority: int) -> None:
    """Raise the node's threads below its loops; warn once, naming why, if the OS refuses."""
    if not rt_priority:
        return
    refused = set_process_realtime(rt_priority)
    if refused:
        node.get_logger().warning(
            f"real-time scheduling {refused}; the loops run at normal priority and may miss "
            "deadlines under load (docs/compensator.md)"
        )


class LoopNode(Node):
    """Base for nodes whose work runs on a :class:`DeadlineLoop` (not an rclpy timer).

    Deadlines are on the monotonic clock; messages are stamped in ROS time through one
    :class:`MonotonicStamper` taken at construction. Parameter ``rt_priority`` (default 50, 0
    for off) runs the loop under SCHED_FIFO and the node's other threads 30 below it; where
    the OS refuses, the node runs at normal priority, warns once and reports why.
    """

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self._loop: DeadlineLoop | None = None
        self._stamper = MonotonicStamper(self.get_clock().now().nanoseconds)
        self.rt_priority = declare_rt_priority(self)

    def create_loop(self, rate_hz: float, tick: Callable[[int, float], None]) -> DeadlineLoop:
        """Create the node's loop (started by :meth:`start`)."""
        self._loop = DeadlineLoop(rate_hz, tick, name=self.get_name(), rt_priority=self.rt_priority)
        return self._loop

    @property
    def realtime(self) -> str:
        """What the loop runs under (``SCHED_FIFO 50``), or why it is not real time."""
        return self.loop.realtime

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
        """Start the loop (and make the node's other threads real time below it)."""
        make_process_realtime(self, self.rt_priority)
        self.loop.start()

    def destroy_node(self) -> None:
        """Stop the loop before the publishers go away.

        A constructor that failed (a parameter refused) may have left no loop, and rclpy
        still destroys the half-built node when its context shuts down.
        """
        if self._loop is not None:
            self._loop.stop()
        super().destroy_node()


class LifecycleLoopNode(LifecycleNode):
    """Base for lifecycle nodes whose work runs on a :class:`DeadlineLoop`.

    The loop exists only while the node is active: :meth:`start_loop` (from ``on_activate``)
    makes a new one, :meth:`stop_loop` (from ``on_deactivate``) ends it; a thread cannot be
    restarted, and a re-activated node must not replay the ticks it missed while inactive.
    Parameters ``rt_priority`` (as :class:`LoopNode`) and ``autostart`` (default false).
    """

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self._loop: DeadlineLoop | None = None
        self._stamper = MonotonicStamper(self.get_clock().now().nanoseconds)
        self.rt_priority = declare_rt_priority(self)
        self.autostart = declare_autostart(self)
        self.transition_failure = ""
        """Why the last transition failed ('' if none did): logged, and raised by autostart."""

    def fail_transition(self, what: str, reason: str) -> None:
        """Log a failed transition by name with its reason, and keep the reason."""
        self.transition_failure = f"{what} failed: {reason}"
        self.get_logger().error(self.transition_failure)

    def start_loop(self, rate_hz: float, tick: Callable[[int, float], None]) -> DeadlineLoop:
        """Make and start the node's loop (the node's other threads real time below it)."""
        make_process_realtime(self, self.rt_priority)
        self._loop = DeadlineLoop(rate_hz, tick, name=self.get_name(), rt_priority=self.rt_priority)
        self._loop.start()
        return self._loop

    def stop_loop(self) -> None:
        """End the loop, if one runs (idempotent)."""
        if self._loop is not None:
            self._loop.stop()
            self._loop = None

    @property
    def active_loop(self) -> DeadlineLoop | None:
        """The running loop, or None while the node is not active."""
        return self._loop

    def stamp_ns(self, mono_s: float) -> int:
        """ROS time [ns] of a monotonic instant [s], e.g. a tick's deadline."""
        return self._stamper.ns(mono_s)

    def start(self) -> None:
        """Called once the process's nodes are built: with ``autostart``, configure+activate.

        A failure raises CatheterError (exit code 2 from ``run_nodes``) with the reason.
        """
        if self.autostart:
            autostart_once(self)

    def destroy_node(self) -> None:
        """Stop the loop before the publishers go away."""
        self.stop_loop()
        super().destroy_node()
