"""One entry shape for every node: build, start, spin until SIGINT/SIGTERM, close cleanly.

rclpy's own signal handling lost a SIGINT here when the executor was saturated (a recorder
taking 1000 messages/s kept spinning), and a supervisor then had to SIGKILL it, truncating
the bag. So nodes install plain Python handlers that set an event, and spin in bounded steps
that check it: a stop request is always seen within ``poll_s``.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from types import FrameType
from typing import Protocol

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from catheter_models.errors import CatheterError


class _Startable(Protocol):
    def start(self) -> None: ...


def install_stop_handlers() -> threading.Event:
    """SIGINT and SIGTERM set the returned event (instead of raising in random places)."""
    stop = threading.Event()

    def handler(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def run_node(
    factory: Callable[[], Node],
    args: list[str] | None = None,
    *,
    until: Callable[[Node], bool] | None = None,
    poll_s: float = 0.1,
) -> int:
    """Run one node until a stop signal (or ``until(node)`` is true); returns an exit code.

    The node is built inside an rclpy context; a :class:`CatheterError` while building it
    (a refused parameter, a model that fails its hash check) is logged as fatal and gives
    exit code 2. If the node has ``start()`` it is called before spinning; ``close()`` and
    ``destroy_node()`` are always called on the way out, in that order.
    """
    stop = install_stop_handlers()
    code = 0
    with rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO):
        try:
            node = factory()
        except CatheterError as exc:
            rclpy.logging.get_logger("catheter").fatal(str(exc))
            return 2
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        try:
            if hasattr(node, "start"):
                node.start()
            while not stop.is_set() and rclpy.ok():
                executor.spin_once(timeout_sec=poll_s)
                if until is not None and until(node):
                    break
        except ExternalShutdownException:
            pass
        finally:
            if hasattr(node, "close"):
                node.close()
            executor.remove_node(node)
            node.destroy_node()
    return code
