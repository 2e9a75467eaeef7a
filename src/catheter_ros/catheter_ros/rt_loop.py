"""A fixed-rate loop on its own thread, against absolute deadlines on the monotonic clock.

rclpy timers showed p99 period errors of several milliseconds at 250 Hz here
(docs/reliability.md), so real-time paths do not use them. Deadlines are absolute
(``t0 + k * period``): a late tick does not push every later tick back.
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from catheter_models.units import s_to_ns


@dataclass(frozen=True)
class LoopStats:
    """Timing of a deadline loop since start (or over the recent window for percentiles).

    Attributes:
        ticks: ticks run.
        missed: ticks that started after the *next* deadline had already passed.
        lateness_p50_s, lateness_p99_s: start time minus deadline, recent window [s].
        compute_p50_s, compute_p99_s: time spent in the tick body, recent window [s].
    """

    ticks: int
    missed: int
    lateness_p50_s: float
    lateness_p99_s: float
    compute_p50_s: float
    compute_p99_s: float


DEFAULT_RT_PRIORITY = 50
"""SCHED_FIFO priority of deadline loops, as ros2_control's controller manager uses: above
the kernel's threaded IRQs' default of 50 would starve them, so not higher."""

_BACKGROUND_OFFSET = 30
"""How far below a node's loop its other threads (executor, DDS) run when it is real time."""


def set_realtime(priority: int, tid: int = 0) -> str:
    """Put a thread (0: the calling one) under SCHED_FIFO at ``priority``; '' if it worked.

    On failure the reason is returned, not raised: without the right (CAP_SYS_NICE or an
    ``rtprio`` limit, see docs/compensator.md) the loop still runs, at normal priority, and
    the node reports why on /diagnostics.
    """
    if priority <= 0:
        return "off (rt_priority 0)"
    if not hasattr(os, "sched_setscheduler"):
        return "unavailable: no SCHED_FIFO on this platform"
    try:
        os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        return f"unavailable: {exc.strerror or exc} (needs CAP_SYS_NICE or an rtprio limit)"
    return ""


def set_process_realtime(priority: int, background_offset: int = _BACKGROUND_OFFSET) -> str:
    """Every current thread of this process (executor, DDS) to SCHED_FIFO below the loop.

    Python threads share one GIL: a loop thread that preempts everything still waits for the
    executor thread if the OS has descheduled it while it held the GIL. Raising the node's
    other threads (below its loop) keeps that wait to the GIL hand-over interval. Measured on
    the whole simulated graph at 1 kHz: 18 % of deadlines missed at normal priority, 0.95 %
    with only the loop real time, under 0.1 % with the process too (docs/benchmarks.md).
    ``background_offset`` 0 puts every thread at ``priority`` (a process with no loop).
    """
    background = max(1, priority - background_offset)
    tasks = Path("/proc/self/task")
    for tid in sorted(int(p.name) for p in tasks.iterdir()) if tasks.is_dir() else []:
        if not Path(tasks, str(tid)).exists():
            continue  # a thread that ended meanwhile
        reason = set_realtime(background, tid)
        if reason:
            return reason
    return ""


class DeadlineLoop:
    """Call ``tick(k, deadline_s)`` at ``rate_hz`` on a daemon thread until :meth:`stop`.

    If a tick overruns past the following deadline, the missed deadlines are counted and the
    loop resumes at the next future deadline rather than bursting to catch up: a controller
    must not fire a volley of stale commands.

    Args:
        rate_hz: tick rate [Hz].
        tick: the body; gets the tick index and its deadline on ``time.monotonic`` [s].
        name: thread name (shows in ``py-spy`` and crash reports).
        window: number of recent ticks kept for percentiles.
        rt_priority: SCHED_FIFO priority of the loop thread (0: normal scheduling). If the
            OS refuses, the loop runs anyway and :attr:`realtime` says why.
    """

    def __init__(
        self,
        rate_hz: float,
        tick: Callable[[int, float], None],
        name: str,
        window: int = 5000,
        rt_priority: int = 0,
    ) -> None:
        if not rate_hz > 0.0:
            raise ValueError(f"loop rate must be > 0 Hz, got {rate_hz!r}")
        self.period_s = 1.0 / rate_hz
        self._tick = tick
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._lateness: deque[float] = deque(maxlen=window)
        self._compute: deque[float] = deque(maxlen=window)
        self._ticks = 0
        self._missed = 0
        self._worst_behind_s = 0.0
        self.error: BaseException | None = None
        """An exception that ended the loop, kept for the owner to report."""
        self.rt_priority = rt_priority
        self.realtime = "not started"
        """``SCHED_FIFO <priority>`` once the loop runs real time, else why not."""

    def start(self) -> None:
        """Start ticking; the first deadline is one period from now."""
        self._thread.start()

    def stop(self, timeout_s: float = 1.0) -> None:
        """Ask the loop to end and wait for the thread."""
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout_s)

    @property
    def running(self) -> bool:
        """Whether the loop thread is alive."""
        return self._thread.is_alive()

    def _run(self) -> None:
        refused = set_realtime(self.rt_priority)
        self.realtime = refused or f"SCHED_FIFO {self.rt_priority}"
        t0 = time.monotonic()
        k = 1
        try:
            while not self._stop.is_set():
                deadline = t0 + k * self.period_s
                delay = deadline - time.monotonic()
                if delay > 0.0 and self._stop.wait(delay):
                    break
                start = time.monotonic()
                self._tick(k, deadline)
                end = time.monotonic()
                self._lateness.append(start - deadline)
                self._worst_behind_s = max(self._worst_behind_s, end - deadline)
                self._compute.append(end - start)
                self._ticks += 1
                # Skip deadlines already passed instead of bursting through them.
                behind = int((end - deadline) / self.period_s)
                if behind > 0:
                    self._missed += behind
                    k += behind
                k += 1
        except BaseException as exc:  # the owner decides; we must not die silently
            self.error = exc
            raise

    def take_worst_behind_s(self) -> float:
        """How far behind its schedule the loop fell since the previous call [s].

        The worst tick's end minus its deadline: a late wake-up and a long tick alike; then
        forgotten. A percentile over thousands of ticks hides the one stall that matters; a
        node reports this once a second, so a stall can be placed in time against other
        nodes' reports.
        """
        worst, self._worst_behind_s = self._worst_behind_s, 0.0
        return worst

    def stats(self) -> LoopStats:
        """Current statistics (percentiles over the recent window)."""
        lat = np.fromiter(self._lateness, float) if self._lateness else np.zeros(1)
        comp = np.fromiter(self._compute, float) if self._compute else np.zeros(1)
        return LoopStats(
            ticks=self._ticks,
            missed=self._missed,
            lateness_p50_s=float(np.percentile(lat, 50)),
            lateness_p99_s=float(np.percentile(lat, 99)),
            compute_p50_s=float(np.percentile(comp, 50)),
            compute_p99_s=float(np.percentile(comp, 99)),
        )


class MonotonicStamper:
    """ROS stamps for instants on the monotonic clock (deadlines, receive times).

    The offset between the two clocks is taken once, so instants one period apart get
    stamps exactly one period apart whatever the system clock does meanwhile.

    Args:
        ros_now_ns: the ROS clock's current time [ns] (``node.get_clock().now().nanoseconds``).
    """

    def __init__(self, ros_now_ns: int) -> None:
        self._offset_ns = ros_now_ns - s_to_ns(time.monotonic())

    def ns(self, mono_s: float) -> int:
        """ROS time [ns] of the monotonic instant ``mono_s`` [s]."""
        return self._offset_ns + s_to_ns(mono_s)


class LatencyWindow:
    """Recent latencies (receipt minus a message's stamp), for a node's diagnostics.

    Commands are stamped with their intended application time (the compensator's tick
    deadline), so receipt minus stamp at a driver is the command's age on arrival: tick to
    publish to DDS to this callback. Appending is cheap enough for a 1 kHz subscription.

    Args:
        window: number of recent samples kept for percentiles.
        name: prefix of the diagnostics keys (``<name>_p50_ms`` ...).
    """

    def __init__(self, window: int = 5000, name: str = "command_latency") -> None:
        self._samples: deque[float] = deque(maxlen=window)
        self.name = name

    def add(self, latency_s: float) -> None:
        """One message's latency [s]."""
        self._samples.append(latency_s)

    def summary_ms(self) -> dict[str, str]:
        """p50, p99, max and RMS over the window [ms], formatted for /diagnostics ('' if empty).

        The RMS is what a stamp uncertainty costs a signal (RMS error = rate x RMS timing
        error), which the percentiles do not give.
        """
        keys = [f"{self.name}_{k}_ms" for k in ("p50", "p99", "max", "rms")]
        if not self._samples:
            return dict.fromkeys(keys, "")
        ms = np.fromiter(self._samples, float) * 1e3
        values = (
            np.percentile(ms, 50),
            np.percentile(ms, 99),
            ms.max(),
            np.sqrt(np.mean(ms**2)),
        )
        return {k: f"{v:.3f}" for k, v in zip(keys, values, strict=True)}
