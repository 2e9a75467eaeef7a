"""What one message costs a subscriber: rclpy's SingleThreadedExecutor against its EventsExecutor.

The recorder takes every message of the contract's streams (5 topics; 1,250 messages/s at
250 Hz, 5,000 at 1 kHz). A publisher process sends raw ``JointState`` messages on 5 topics at
the given rate for ``--duration-s``; a subscriber process takes them raw (as the recorder does)
with one executor or the other and reports its own CPU time (``time.process_time``) and the
messages it got. CPU per message is that CPU time over the messages: the figure that decides
whether a recorder keeps up on a 2-core machine. The SingleThreadedExecutor is the baseline
(what every node used); the EventsExecutor is what the recorder spins now.

    .venv/bin/python bench/bench_executor_intake.py            # 250 Hz and 1 kHz, ~1.5 min
    .venv/bin/python bench/bench_executor_intake.py --quick    # 3 s each

Writes ``bench/results/executor_intake.json``. Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "bench" / "results"
TOPICS = 5

_PUBLISHER = """
import sys, time, rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
from sensor_msgs.msg import JointState
rate, reliable, duration = float(sys.argv[1]), sys.argv[2] == "reliable", float(sys.argv[3])
rclpy.init()
node = rclpy.create_node("bench_pub")
best_effort = ReliabilityPolicy.BEST_EFFORT
qos = QoSProfile(depth=500, history=HistoryPolicy.KEEP_LAST,
                 reliability=ReliabilityPolicy.RELIABLE if reliable else best_effort)
pubs = [node.create_publisher(JointState, f"bench/t{i}", qos) for i in range(TOPICS_N)]
deadline = time.monotonic() + 20.0
while any(p.get_subscription_count() == 0 for p in pubs) and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(0.5)
msg = JointState(); msg.name = ["bend"]
t0 = time.monotonic(); k = 0
while True:
    k += 1
    due = t0 + k / rate
    if due > t0 + duration:
        break
    wait = due - time.monotonic()
    if wait > 0:
        time.sleep(wait)
    for p in pubs:
        msg.position = [float(k)]
        p.publish(msg)
print(k - 1, flush=True)
time.sleep(1.0)
""".replace("TOPICS_N", str(TOPICS))

_SUBSCRIBER = """
import sys, time, rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
from sensor_msgs.msg import JointState
kind, reliable, duration = sys.argv[1], sys.argv[2] == "reliable", float(sys.argv[3])
rclpy.init()
node = rclpy.create_node("bench_sub")
best_effort = ReliabilityPolicy.BEST_EFFORT
qos = QoSProfile(depth=500, history=HistoryPolicy.KEEP_LAST,
                 reliability=ReliabilityPolicy.RELIABLE if reliable else best_effort)
got = [0]
def take(data):
    got[0] += 1
subs = [node.create_subscription(JointState, f"bench/t{i}", take, qos, raw=True)
        for i in range(TOPICS_N)]
if kind == "events":
    from rclpy.experimental.events_executor import EventsExecutor
    executor = EventsExecutor()
else:
    from rclpy.executors import SingleThreadedExecutor
    executor = SingleThreadedExecutor()
executor.add_node(node)
cpu0, t0 = time.process_time(), time.monotonic()
while time.monotonic() - t0 < duration:
    executor.spin_once(timeout_sec=0.1)
print(got[0], time.process_time() - cpu0, flush=True)
""".replace("TOPICS_N", str(TOPICS))


def run_pair(executor: str, rate_hz: float, duration_s: float, domain: int) -> dict[str, Any]:
    """One publisher and one subscriber process; the subscriber's count and CPU time."""
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
    }
    listen_s = duration_s + 8.0  # discovery, the publisher's wait, and the tail
    sub = subprocess.Popen(
        [sys.executable, "-c", _SUBSCRIBER, executor, "reliable", str(listen_s)],
        env=env,
        stdout=subprocess.PIPE,
        text=True,
    )
    pub = subprocess.run(
        [sys.executable, "-c", _PUBLISHER, str(rate_hz), "reliable", str(duration_s)],
        env=env,
        capture_output=True,
        text=True,
        timeout=duration_s + 60,
        check=True,
    )
    out, _ = sub.communicate(timeout=listen_s + 30)
    got, cpu_s = out.split()
    sent = int(pub.stdout.split()[0]) * TOPICS
    return {
        "executor": executor,
        "rate_hz": rate_hz,
        "messages_per_s": rate_hz * TOPICS,
        "sent": sent,
        "received": int(got),
        "cpu_s": float(cpu_s),
        "cpu_us_per_message": 1e6 * float(cpu_s) / max(1, int(got)),
    }


def main(argv: list[str] | None = None) -> int:
    from bench_plant import _machine

    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 s per run")
    parser.add_argument("--duration-s", type=float, default=10.0)
    args = parser.parse_args(argv)
    duration_s = 3.0 if args.quick else args.duration_s
    rows = []
    for i, (rate_hz, executor) in enumerate(
        [(250.0, "single"), (250.0, "events"), (1000.0, "single"), (1000.0, "events")]
    ):
        row = run_pair(executor, rate_hz, duration_s, 70 + i)
        rows.append(row)
        print(
            f"{rate_hz:>6g} Hz x {TOPICS} topics  {executor:<7} received {row['received']:>6} "
            f"of {row['sent']:>6}  CPU {row['cpu_us_per_message']:6.1f} us/message",
            flush=True,
        )
    out = RESULTS / ("executor_intake.quick.json" if args.quick else "executor_intake.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "benchmark": "executor_intake",
                "command": " ".join(["bench/bench_executor_intake.py", *(argv or sys.argv[1:])]),
                "baseline": "single (rclpy SingleThreadedExecutor)",
                "duration_s": duration_s,
                "rows": rows,
                "machine": _machine(),
            },
            indent=2,
        )
        + "\n"
    )
    print(f"Results: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
