"""One entry shape for every node: build, start, spin until SIGINT/SIGTERM, close cleanly.

rclpy's own signal handling lost a SIGINT here when the executor was saturated (a recorder
taking 1000 messages/s kept spinning), and a supervisor then had to SIGKILL it, truncating
the bag. So nodes install plain Python handlers that set an event, and spin in bounded steps
that check it: a stop request is always seen within ``poll_s``.
"""

from __future__ import annotations

import gc
import os
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from types import FrameType

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from catheter_models.errors import CatheterError
from catheter_ros.dds_profile import use_loopback_profile
from catheter_ros.params import refuse_undeclared_overrides


def install_stop_handlers() -> threading.Event:
    """SIGINT and SIGTERM set the returned event (instead of raising in random places)."""
    stop = threading.Event()

    def handler(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


GC_FREEZE_ENV = "CATHETER_GC_FREEZE"
"""'0' leaves start-up's objects to the garbage collector (for comparison only)."""

PARENT_PID_ENV = "CATHETER_PARENT_PID"
"""Set by a launcher (catheter_control.bringup) to its pid: its nodes stop when it dies."""


def _parent_to_follow() -> int | None:
    value = os.environ.get(PARENT_PID_ENV, "")
    if not value.isdigit() or int(value) != os.getppid():
        return None  # not started by that launcher (an inherited variable): nothing to follow
    return int(value)


_SWITCH_INTERVAL_S = 0.0001
"""GIL hand-over interval for processes with deadline loops. Python's default (5 ms) is longer
than a 250 Hz period: a loop thread waiting for the GIL behind a busy executor missed most of
its deadlines (71 Hz instead of 250 Hz with three nodes in one process). At 1 kHz a tick may
wait for the GIL several times (every publish hands it over), so 0.5 ms still cost about one
missed deadline per /diagnostics report; 0.1 ms bounds each wait to a tenth of a period."""


def run_nodes(
    factories: Sequence[Callable[[], Node]],
    args: list[str] | None = None,
    *,
    until: Callable[[list[Node]], bool] | None = None,
    poll_s: float = 0.1,
    events_executor: bool = False,
) -> int:
    """Run nodes in one process until a stop signal (or ``until(nodes)``); returns an exit code.

    ``events_executor`` spins rclpy's EventsExecutor instead of the SingleThreadedExecutor, for
    nodes whose work is taking many messages: it costs about a quarter of the CPU per message
    (319 against 65 us at 1,250 messages/s, 219 against 57 us at 5,000:
    bench/bench_executor_intake.py), which decides whether a recorder keeps up on a busy
    2-core machine. It is
    rclpy's experimental executor, so only the recorder uses it.

    The nodes are built inside one rclpy context, in order; a :class:`CatheterError` while
    building one (a refused parameter, a model that fails its hash check) is logged as fatal
    and gives exit code 2, as does a parameter of the wrong type (``params._declare`` takes an
    integer for a double and names any other mismatch; rclpy's own refusal for a parameter
    declared without it is caught here too); so is an override a node does not declare (``params.
    refuse_undeclared_overrides``). Nodes with ``start()`` are started once all are built (a
    lifecycle node configures and activates itself there only with ``autostart``). On the way
    out every node is closed (``close()``, then ``destroy_node()``, which stops its loops) in
    reverse order, inside the context, so no loop thread publishes into a dead context.
    """
    stop = install_stop_handlers()
    sys.setswitchinterval(_SWITCH_INTERVAL_S)
    use_loopback_profile()  # under LOCALHOST, the node's sockets on 127.0.0.1 only
    nodes: list[Node] = []
    with rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO):
        executor: Executor = EventsExecutor() if events_executor else SingleThreadedExecutor()
        try:
            for factory in factories:
                nodes.append(factory())
                # Every node, whatever it is: a misspelt override must not leave a safety
                # limit at its default without a word.
                refuse_undeclared_overrides(nodes[-1])
                executor.add_node(nodes[-1])
            # What start-up built lives as long as the process: collect once, then freeze it
            # out of the collector's sight. A full collection over it holds the GIL, and so
            # stops a loop thread, for 26 ms in the compensator (90,000 objects with the
            # c-LSTM loaded): 26 missed deadlines at 1 kHz. Frozen, it takes microseconds.
            # CATHETER_GC_FREEZE=0 turns this off (bench/bench_graph_timing.py's baseline).
            if os.environ.get(GC_FREEZE_ENV, "1") != "0":
                gc.collect()
                gc.freeze()
            for node in nodes:
                if hasattr(node, "start"):
                    node.start()
            parent_pid = _parent_to_follow()
            while not stop.is_set() and rclpy.ok():
                executor.spin_once(timeout_sec=poll_s)
                if until is not None and until(nodes):
                    break
                if parent_pid is not None and os.getppid() != parent_pid:
                    # The launcher died without stopping us (kill -9): shut down cleanly
                    # (loops stopped, bag closed, drivers vented) rather than run orphaned.
                    rclpy.logging.get_logger("catheter").warning(
                        f"launcher (pid {parent_pid}) is gone: shutting down"
                    )
                    break
        except CatheterError as exc:
            rclpy.logging.get_logger("catheter").fatal(str(exc))
            return 2
        except ParameterException as exc:
            # A parameter a node declares with rclpy directly, given with the wrong type or
            # value: rclpy's message names it and both types; one line, no traceback.
            rclpy.logging.get_logger("catheter").fatal(f"parameter refused: {exc}")
            return 2
        except ExternalShutdownException:
            pass
        finally:
            for node in reversed(nodes):
                if hasattr(node, "close"):
                    node.close()
                executor.remove_node(node)
                node.destroy_node()
    return 0


def run_node(
    factory: Callable[[], Node],
    args: list[str] | None = None,
    *,
    until: Callable[[Node], bool] | None = None,
    poll_s: float = 0.1,
    events_executor: bool = False,
) -> int:
    """Run one node: :func:`run_nodes` for a single factory."""
    return run_nodes(
        [factory],
        args,
        until=None if until is None else (lambda nodes: until(nodes[0])),
        poll_s=poll_s,
        events_executor=events_executor,
    )


def run_node_as_main(
    factory: Callable[[], Node],
    args: list[str] | None = None,
    *,
    until: Callable[[Node], bool] | None = None,
    poll_s: float = 0.1,
    events_executor: bool = False,
) -> None:
    """A node's ``main``: :func:`run_node`, and a non-zero exit code leaves as ``SystemExit``.

    Every node's entry point ended the same way; one helper keeps their exit codes alike
    (0 returns normally, so a console script exits 0; 2 for a refused start-up).
    """
    code = run_node(factory, args, until=until, poll_s=poll_s, events_executor=events_executor)
    if code:
        raise SystemExit(code)
