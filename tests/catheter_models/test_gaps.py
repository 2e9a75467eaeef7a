"""Gaps in stamped streams: what the recorder and the bag readers count as lost samples."""

from __future__ import annotations

import numpy as np
import pytest

from catheter_models.gaps import PAUSE_S, StreamGaps, find_gaps, missing_samples

PERIOD_NS = 4_000_000  # 250 Hz


def _stamps(n: int, period_ns: int = PERIOD_NS, start_ns: int = 10**18) -> list[int]:
    return [start_ns + k * period_ns for k in range(n)]


def test_a_complete_stream_has_no_gap() -> None:
    gaps = StreamGaps(pauses=False)
    for s in _stamps(2000):
        gaps.add(s)
    assert (gaps.lost, gaps.gap_count, gaps.out_of_order) == (0, 0, 0)
    assert gaps.period_s == pytest.approx(0.004)


@pytest.mark.parametrize("rate_hz", [100.0, 250.0, 1000.0])
def test_lost_runs_are_counted_sample_for_sample_at_any_rate(rate_hz: float) -> None:
    period_ns = round(1e9 / rate_hz)
    stamps = _stamps(3000, period_ns)
    # 22 in a row (the loss the issue saw), one single, and one early, before the period
    # is learned: every one counted.
    lost = set(range(5, 8)) | set(range(1000, 1022)) | {2500}
    gaps = StreamGaps(pauses=False)
    for k, s in enumerate(stamps):
        if k not in lost:
            gaps.add(s)
    assert gaps.lost == len(lost)
    assert gaps.gap_count == 3
    assert [g.missing for g in gaps.gaps] == [3, 22, 1]
    assert gaps.longest_s == pytest.approx(23 * period_ns * 1e-9)


def test_jitter_is_not_a_gap() -> None:
    rng = np.random.default_rng(0)
    # A polled sensor stamped mid round trip: +-1 ms around a 4 ms period.
    stamps = np.cumsum(rng.uniform(3.0e6, 5.0e6, 5000)).astype(np.int64) + 10**18
    gaps = StreamGaps(pauses=False)
    for s in stamps:
        gaps.add(int(s))
    assert gaps.lost == 0


def test_a_command_stream_pauses_between_runs_but_its_losses_count() -> None:
    run1 = _stamps(500)
    run2 = _stamps(500, start_ns=run1[-1] + round(2.0e9))  # 2 s idle between runs
    stamps = run1 + [s for k, s in enumerate(run2) if not 100 <= k < 110]
    commands = StreamGaps(pauses=True)
    sensor = StreamGaps(pauses=False)
    for s in stamps:
        commands.add(s)
        sensor.add(s)
    assert commands.lost == 10 and commands.gap_count == 1
    # The same silence in a sensor stream is lost data: about 2 s of it.
    assert sensor.lost == 10 + round(2.0 / 0.004) - 1


def test_out_of_order_stamps_are_counted_not_judged() -> None:
    gaps = StreamGaps(pauses=False)
    stamps = _stamps(100)
    stamps[50], stamps[51] = stamps[51], stamps[50]
    for s in stamps:
        gaps.add(s)
    assert gaps.out_of_order == 1
    assert gaps.lost == 0


def test_the_offline_rule_agrees_with_the_online_one() -> None:
    stamps = np.array(_stamps(3000), dtype=np.int64)
    keep = np.ones(stamps.size, bool)
    keep[[10, 11, 12, 2000]] = False
    period_s, found = find_gaps((stamps[keep] - stamps[0]) * 1e-9, pauses=False)
    assert period_s == pytest.approx(0.004)
    assert [m for _, _, m in found] == [3, 1]
    online = StreamGaps(pauses=False)
    for s in stamps[keep]:
        online.add(int(s))
    assert online.lost == sum(m for _, _, m in found)


def test_missing_samples_rule() -> None:
    assert missing_samples(0.0059, 0.004, pause_s=None) == 0
    assert missing_samples(0.0081, 0.004, pause_s=None) == 1
    assert missing_samples(0.092, 0.004, pause_s=None) == 22
    assert missing_samples(PAUSE_S + 0.1, 0.004, pause_s=PAUSE_S) == 0


def test_the_gaps_can_be_read_while_another_thread_adds_stamps() -> None:
    """The recorder adds stamps from its writer thread while its /diagnostics timer reads the
    longest gap: that read once raised "deque mutated during iteration" and killed it."""
    import sys
    import threading

    from catheter_models.gaps import StreamGaps

    gaps = StreamGaps(pauses=False, keep=100)
    stop = threading.Event()
    errors: list[BaseException] = []

    def writer() -> None:
        stamp, n = 0, 0
        while not stop.is_set():
            n += 1
            stamp += 12_000_000 if n % 3 == 0 else 4_000_000  # two samples lost every third
            gaps.add(stamp)

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads as often as the interpreter can
    thread = threading.Thread(target=writer)
    thread.start()
    try:
        for _ in range(20_000):
            try:
                gaps.longest_s  # noqa: B018 - the read is the test
            except RuntimeError as exc:
                errors.append(exc)
                break
    finally:
        stop.set()
        thread.join()
        sys.setswitchinterval(interval)
    assert not errors, errors
    assert gaps.gap_count > 100 and gaps.longest_s > 0.0
