"""How late a bare real-time thread wakes on this machine: the floor under every loop here.

The graph's loops sometimes stall for tens of milliseconds (a compensator seeing ``tip/angle``
silent for 100 ms, ``excite`` skipping six 4 ms ticks on an idle machine). Before blaming the
nodes, measure what the platform gives a thread that does nothing but wake: a SCHED_FIFO
thread (priority above every loop in the graph) sleeps to absolute 1 ms deadlines, as
``cyclictest`` does, and records how late each wake-up is. Beside it, the hypervisor's steal
time from /proc/stat (CPU time the host gave to someone else while this guest wanted it).
Conditions: idle, and beside N busy loops at normal priority (a lab PC doing other work).

A stall that a bare real-time thread also sees comes from the platform (hypervisor, kernel),
not from the nodes; one it does not see is ours to find.

    .venv/bin/python bench/bench_platform_latency.py [--seconds 60] [--hogs 2] [--priority 60]

Writes bench/results/platform_latency.json.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results" / "platform_latency.json"
PERIOD_S = 0.001
STALL_THRESHOLDS_MS = (1.0, 5.0, 10.0, 50.0, 100.0)


def _steal_ticks() -> int:
    """Steal time of all CPUs so far, in USER_HZ ticks (the 8th field of /proc/stat's cpu)."""
    fields = Path("/proc/stat").read_text().splitlines()[0].split()
    return int(fields[8]) if len(fields) > 8 else 0


def _probe(seconds: float, priority: int, out: Any) -> None:
    """Runs in a child process: sleep to each deadline, record lateness [s]."""
    realtime = "off"
    if priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            realtime = f"SCHED_FIFO {priority}"
        except PermissionError as exc:
            realtime = f"refused ({exc})"
    n = int(seconds / PERIOD_S)
    late = np.empty(n)
    start = time.monotonic() + 0.01
    for k in range(n):
        deadline = start + k * PERIOD_S
        delay = deadline - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        late[k] = time.monotonic() - deadline
    out.send((late.tolist(), realtime))
    out.close()


def measure(seconds: float, priority: int, hogs: int) -> dict[str, Any]:
    """One condition: the probe for ``seconds`` beside ``hogs`` busy loops."""
    hog_procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(hogs)]
    try:
        ctx = multiprocessing.get_context("spawn")
        recv, send = ctx.Pipe(duplex=False)
        child = ctx.Process(target=_probe, args=(seconds, priority, send))
        steal0, t0 = _steal_ticks(), time.monotonic()
        child.start()
        late_list, realtime = recv.recv()
        child.join()
        steal_s = (_steal_ticks() - steal0) / os.sysconf("SC_CLK_TCK")
        wall_s = time.monotonic() - t0
    finally:
        for p in hog_procs:
            p.kill()
            p.wait()
    late_ms = np.asarray(late_list) * 1e3
    worst = np.argsort(late_ms)[-5:][::-1]
    return {
        "hogs": hogs,
        "seconds": seconds,
        "realtime": realtime,
        "wakeups": int(late_ms.size),
        "lateness_p50_ms": round(float(np.percentile(late_ms, 50)), 3),
        "lateness_p99_ms": round(float(np.percentile(late_ms, 99)), 3),
        "lateness_p99_9_ms": round(float(np.percentile(late_ms, 99.9)), 3),
        "lateness_max_ms": round(float(late_ms.max()), 3),
        "worst_at_s": [round(float(i) * PERIOD_S, 3) for i in worst],
        "worst_ms": [round(float(late_ms[i]), 3) for i in worst],
        **{f"wakeups_later_than_{t:g}_ms": int((late_ms > t).sum()) for t in STALL_THRESHOLDS_MS},
        "steal_s": round(steal_s, 3),
        "steal_share": round(steal_s / (wall_s * (os.cpu_count() or 1)), 5),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="per condition")
    parser.add_argument("--hogs", type=int, default=2, help="busy loops in the loaded condition")
    parser.add_argument("--priority", type=int, default=60, help="SCHED_FIFO priority (0: off)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    rows = []
    for hogs in (0, args.hogs):
        print(f"probe: {args.seconds:g} s beside {hogs} busy loop(s)...", flush=True)
        row = measure(args.seconds, args.priority, hogs)
        rows.append(row)
        print(
            f"  {row['realtime']}: lateness p50 {row['lateness_p50_ms']} ms, "
            f"p99.9 {row['lateness_p99_9_ms']} ms, max {row['lateness_max_ms']} ms; "
            f">10 ms {row['wakeups_later_than_10_ms']}, >50 ms {row['wakeups_later_than_50_ms']}; "
            f"steal {row['steal_s']} s",
            flush=True,
        )
    result = {
        "benchmark": "platform_latency",
        "command": " ".join(["bench/bench_platform_latency.py", *sys.argv[1:]]),
        "period_s": PERIOD_S,
        "rows": rows,
        "machine": {
            "cpus": os.cpu_count(),
            "kernel": platform.release(),
            "python": platform.python_version(),
            "rt_runtime_us": Path("/proc/sys/kernel/sched_rt_runtime_us").read_text().strip(),
        },
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
