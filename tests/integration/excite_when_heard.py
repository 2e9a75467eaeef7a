"""``excite``'s node in a process of its own, started only once every subscriber hears it.

A test helper (``python excite_when_heard.py --subscribers N --heard-before H --timeout-s T
--ros-args ...``), not a product tool. The ``excite`` executable starts its signal as soon as
its *first* subscriber on pressure/command matches, and the others may match seconds later
(see test_hardware_graph.py), so the rig or the recorder would miss the start of the signal.
Here the node is built, then started only when its publisher has matched ``--subscribers``
subscriptions and the recorder says on /diagnostics that it hears more command publishers than
``--heard-before`` (it counted the ones there before this process).

Why a process and not the test's own: the pytest process holds the objects and threads of a
thousand tests by the time the hardware test runs, and its deadline loop skipped 51 of 3515
ticks (1.5 %) in a clean-clone CI run, with its objects frozen and collection off. A fresh
process is also how a person runs ``excite``.

Prints one JSON line, ``{"published": n, "samples": m, "failure": "..."}``; exit 0 when the
signal went out, 3 when it could not start or finish.
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from catheter_control.excite_node import ExciteNode
from catheter_models.contract import DIAGNOSTICS, PRESSURE_COMMAND, qualify

RECORDER_STATUS = "catheter/recorder"
LINGER_S = 0.5
"""After the last sample: best-effort messages still in flight die with the participant."""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subscribers", type=int, required=True)
    parser.add_argument("--heard-before", type=int, required=True)
    parser.add_argument("--timeout-s", type=float, required=True)
    args, ros_args = parser.parse_known_args()
    rclpy.init(args=["excite", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    command = qualify(PRESSURE_COMMAND)
    heard = [0]

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == RECORDER_STATUS:
                values = {kv.key: kv.value for kv in status.values}
                heard[0] = int(values.get(f"publishers {command}", "0"))

    node = ExciteNode()
    node.create_subscription(DiagnosticArray, DIAGNOSTICS.name, on_diagnostics, 10)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    result: dict[str, object] = {"published": 0, "samples": int(node.values_pa.size)}
    # As run_nodes does for every process with a deadline loop.
    sys.setswitchinterval(0.0005)
    gc.collect()
    gc.freeze()
    try:
        end_s = time.monotonic() + 20.0
        while not (
            node._pub.get_subscription_count() >= args.subscribers
            and node.count_subscribers(command) >= args.subscribers
            and heard[0] > args.heard_before
        ):
            if time.monotonic() > end_s:
                result["failure"] = (
                    f"not heard within 20 s: {node._pub.get_subscription_count()} of "
                    f"{args.subscribers} subscribers matched, the recorder hears {heard[0]} "
                    f"command publishers (before: {args.heard_before})"
                )
                return 3
            executor.spin_once(timeout_sec=0.05)
        node.start()
        end_s = time.monotonic() + args.timeout_s
        while not node.done.is_set():
            if time.monotonic() > end_s:
                result["failure"] = f"excite not done within {args.timeout_s:g} s"
                return 3
            executor.spin_once(timeout_sec=0.05)
        linger_s = time.monotonic() + LINGER_S
        while time.monotonic() < linger_s:
            executor.spin_once(timeout_sec=0.05)
        if node.failure:
            result["failure"] = node.failure
            return 3
        return 0
    finally:
        result["published"] = node.published
        print(json.dumps(result), flush=True)
        node.close()
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    raise SystemExit(main())
