"""The deadline loop keeps absolute deadlines and counts misses instead of bursting."""

import itertools
import time

import pytest

from catheter_ros.rt_loop import DeadlineLoop, LatencyWindow, set_realtime


def test_ticks_at_rate_on_absolute_deadlines() -> None:
    deadlines: list[float] = []
    loop = DeadlineLoop(200.0, lambda k, d: deadlines.append(d), name="t")
    loop.start()
    time.sleep(0.5)
    loop.stop()
    assert 0 < len(deadlines) <= 101
    # Every deadline is t0 + k*period exactly. On a busy machine a tick can start after the
    # next deadline has passed; that deadline is skipped (and counted), never shifted.
    steps = [(b - a) / 0.005 for a, b in itertools.pairwise(deadlines)]
    assert all(abs(n - round(n)) < 1e-6 and round(n) >= 1 for n in steps), steps
    assert sum(round(n) - 1 for n in steps) <= loop.stats().missed


def test_overrun_skips_missed_deadlines() -> None:
    ks: list[int] = []

    def slow(k: int, _d: float) -> None:
        ks.append(k)
        if k == 3:
            time.sleep(0.055)  # overrun by ~10 periods

    loop = DeadlineLoop(200.0, slow, name="t")
    loop.start()
    time.sleep(0.2)
    loop.stop()
    stats = loop.stats()
    assert stats.missed >= 9
    assert ks[3] - ks[2] >= 10, "the loop resumes at the next future deadline, no burst"
    # The overrun left the loop at least 50 ms behind its schedule; the report says so once.
    assert loop.take_worst_behind_s() >= 0.05
    assert loop.take_worst_behind_s() == 0.0, "forgotten once taken (the loop has stopped)"


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_an_exception_is_kept_for_the_owner() -> None:
    def boom(k: int, _d: float) -> None:
        raise RuntimeError("tick failed")

    loop = DeadlineLoop(100.0, boom, name="t")
    loop.start()
    time.sleep(0.1)
    assert isinstance(loop.error, RuntimeError)
    assert not loop.running


def test_latency_window_reports_percentiles_in_ms_and_nothing_before_data() -> None:
    window = LatencyWindow(window=100)
    assert window.summary_ms()["command_latency_p99_ms"] == ""
    for k in range(1000):  # only the last 100 count: 0.9 ms .. 0.999 ms
        window.add(k * 1e-6)
    summary = window.summary_ms()
    assert summary["command_latency_max_ms"] == "0.999"
    assert summary["command_latency_p50_ms"] == "0.950"
    assert float(summary["command_latency_p99_ms"]) == pytest.approx(0.998, abs=1e-3)


def test_a_real_time_loop_runs_whether_or_not_the_os_allows_it() -> None:
    assert set_realtime(0) == "off (rt_priority 0)"
    ticks: list[int] = []
    loop = DeadlineLoop(200.0, lambda k, d: ticks.append(k), name="rt", rt_priority=10)
    loop.start()
    time.sleep(0.3)
    loop.stop()
    assert len(ticks) > 30
    # Root or CAP_SYS_NICE: SCHED_FIFO; otherwise the reason, never an exception.
    assert loop.realtime == "SCHED_FIFO 10" or loop.realtime.startswith("unavailable: "), (
        loop.realtime
    )
